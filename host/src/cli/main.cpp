// The `corofem` command: run a scene headless, inspect a mesh, convert between mesh formats.
//
//   corofem run SCENE [--out DIR] [--set key.path=value ...] [--quiet]
//   corofem run SCENE --plan [--json] [--set ...]
//   corofem info MESH [--json]
//   corofem convert IN OUT
//   corofem warmup [SCENE] [--set ...]
//
// Every command takes the input limits (corofem::InputLimits): --max-input-bytes, --max-scene-bytes,
// --max-box-tets.
//
// Exit status: 0 success, 2 bad input (message on stderr), 3 a solve failed (outputs written so
// far stay readable), 1 anything else (device error, i/o error, internal error). A run whose steps
// completed with linear solves short of the tolerance exits 0 with a warning, and its summary.json
// says "ok_unconverged".
#include "device/registry.hpp"
#include "mesh/input_file.hpp"
#include "mesh/locality_order.hpp"
#include "output/run_outputs.hpp"
#include "util/error.hpp"

#include <corofem/corofem.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

namespace {

using namespace corofem;

constexpr int kExitOk = 0;
constexpr int kExitOther = 1;
constexpr int kExitBadInput = 2;
constexpr int kExitSolveFailed = 3;

int exitCodeFor(const Status& s) {
  switch (s.code()) {
    case ErrorCode::Ok: return kExitOk;
    case ErrorCode::BadInput:
    case ErrorCode::NotCompiledIn: return kExitBadInput;
    case ErrorCode::SolveFailed: return kExitSolveFailed;
    default: return kExitOther;
  }
}

int report(const Status& s) {
  std::cerr << "corofem: error (" << toString(s.code()) << "): " << s.message() << '\n';
  return exitCodeFor(s);
}

void usage(std::ostream& os) {
  os << "usage:\n"
        "  corofem run SCENE.json [--out DIR] [--set key.path=value ...] [--quiet]\n"
        "      Runs a scene headless. Writes DIR/probes.csv (one row per step or load increment),\n"
        "      DIR/<body>.pvd + DIR/vtk/*.vtu (ParaView) and DIR/summary.json.\n"
        "      DIR defaults to out/<scene name>. --set overrides any scene value, e.g.\n"
        "      --set bodies.0.material.youngs_modulus=2e5 --set analysis.integrator=backward_euler\n"
        "  corofem run SCENE.json --plan [--json]\n"
        "      Prints the plan without running the scene: per body the backend/device chosen (and\n"
        "      why), the terms and kernels in use, buffers with their sizes and the estimated bytes\n"
        "      moved per step. COROFEM_DEVICE=reference|opencl|vulkan, or BACKEND:INDEX|BACKEND:NAME,\n"
        "      overrides \"backend\": \"auto\".\n"
        "  corofem info MESH [--json]\n"
        "      Counts, bounding box, volume, element quality and orientation of a tet mesh\n"
        "      (.msh .node/.ele .mesh .vtk .veg) or a surface mesh (.obj).\n"
        "  corofem convert IN OUT\n"
        "      Converts a tet mesh (to .vtu .vtk .msh .mesh .node .veg) or a surface (.obj .vtk).\n"
        "  corofem warmup [SCENE.json] [--set key.path=value ...]\n"
        "      Compiles and caches the kernels the scene's plan uses (without a scene: the default\n"
        "      kernels in float and double on every OpenCL device: the diagonal preconditioner's;\n"
        "      large slender bodies get the multigrid's), so that the first run of an\n"
        "      application does not wait for them. The cache: COROFEM_CACHE_DIR, else\n"
        "      %LOCALAPPDATA%\\corofem on Windows, $XDG_CACHE_HOME/corofem or\n"
        "      ~/.cache/corofem; on PoCL, PoCL's own\n"
        "      (POCL_CACHE_DIR, else ~/.cache/pocl).\n"
        "limits (every command; a larger input is bad input naming the limit):\n"
        "  --max-input-bytes SIZE   the largest mesh, surface or .bou file read (default 1G)\n"
        "  --max-scene-bytes SIZE   the largest scene file read (default 16M)\n"
        "  --max-box-tets COUNT     the largest generated box, in tetrahedra (default 50000000)\n"
        "      A whole number > 0, optionally with K, M, G or T (powers of 1024), e.g.\n"
        "      --max-input-bytes 4G --max-box-tets 100M; also --max-input-bytes=4G.\n"
        "exit status: 0 ok (summary.json \"status\": \"ok\", or \"ok_unconverged\" when linear solves\n"
        "      stopped short of solver.tolerance), 2 bad input, 3 solve failed, 1 other errors\n";
}

/// The input limits' flags (the fields of InputLimits).
struct LimitFlag {
  const mesh::LimitName& name;
  std::uint64_t InputLimits::*field;
};
const LimitFlag kLimitFlags[] = {{mesh::kMaxInputBytes, &InputLimits::maxInputBytes},
                                 {mesh::kMaxSceneBytes, &InputLimits::maxSceneBytes},
                                 {mesh::kMaxBoxTets, &InputLimits::maxBoxTets}};
constexpr const char* kLimitOptions = "--max-input-bytes SIZE, --max-scene-bytes SIZE, --max-box-tets COUNT";

/// When args[i] is a limit flag ("--max-input-bytes 4G" or "--max-input-bytes=4G"), sets the limit
/// (moving i to its value) and returns true; `error` then says what was wrong with the value, if
/// anything. False for any other argument.
bool limitFlag(const std::vector<std::string>& args, std::size_t& i, InputLimits& limits, Status& error) {
  const std::string& a = args[i];
  for (const LimitFlag& f : kLimitFlags) {
    const std::string flag = f.name.flag;
    std::string value;
    if (a == flag) {
      if (i + 1 >= args.size()) {
        error = Status(ErrorCode::BadInput, flag + " needs a value, e.g. " + flag + " " + f.name.example);
        return true;
      }
      value = args[++i];
    } else if (a.rfind(flag + "=", 0) == 0) {
      value = a.substr(flag.size() + 1);
    } else {
      continue;
    }
    error = detail::guard([&] { limits.*f.field = mesh::parseSize(value, flag, f.name.example); });
    return true;
  }
  return false;
}

bool isSurfacePath(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".obj";
}

// ------------------------------------------------------------------------------------ run
std::string humanBytes(double b) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (b >= 1024 && u < 4) {
    b /= 1024;
    ++u;
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, u ? "%.1f %s" : "%.0f %s", b, units[u]);
  return buf;
}

/// `corofem run --plan`: the scene's plan (Simulation::planReport), as JSON or as text.
int printPlan(const Simulation& sim, bool asJson) {
  const nlohmann::json plan = nlohmann::json::parse(sim.planReport());
  if (asJson) {
    std::cout << plan.dump(2) << '\n';
    return kExitOk;
  }
  auto printBuffers = [](const nlohmann::json& list) {  // [{"name", "bytes"}], one per line
    for (const auto& buf : list)
      std::cout << "    " << buf["name"].get<std::string>() << ' ' << humanBytes(buf["bytes"].get<double>()) << '\n';
  };
  std::cout << "plan of scene '" << plan["scene"].get<std::string>() << "': " << plan["analysis"].get<std::string>()
            << ", " << plan["steps"] << (plan["analysis"] == "static" ? " increment(s)" : " step(s)") << '\n';
  for (const auto& b : plan["bodies"]) {
    std::cout << "body '" << b["body"].get<std::string>() << "' (" << b["elements"] << " elements, " << b["nodes"]
              << " nodes) on " << b["choice"].get<std::string>() << "\n  why: " << b["reason"].get<std::string>()
              << "\n  features:";
    for (auto it = b["features"].begin(); it != b["features"].end(); ++it) {
      const std::string v = it.value().is_string() ? it.value().get<std::string>() : it.value().dump();
      std::cout << ' ' << it.key() << '=' << v;
    }
    std::cout << "\n  terms:";
    for (const auto& t : b["terms"]) std::cout << " [" << t.get<std::string>() << ']';
    std::cout << "\n  kernels:\n";
    for (const auto& k : b["kernels"]) std::cout << "    " << k.get<std::string>() << '\n';
    std::cout << "  buffers (" << humanBytes(b["buffer_bytes_total"].get<double>()) << " in all):\n";
    for (const auto& buf : b["buffers"])
      std::cout << "    " << buf["name"].get<std::string>() << " [" << buf["where"].get<std::string>() << "] "
                << humanBytes(buf["bytes"].get<double>()) << '\n';
    if (b.contains("device_bytes_allocated")) {
      std::cout << "  device buffers allocated (" << humanBytes(b["device_bytes_allocated"].get<double>())
                << " in all):\n";
      printBuffers(b["device_buffers_allocated"]);
    }
    if (b.contains("surface")) {
      const auto& sf = b["surface"];
      std::cout << "  render surface: " << sf["vertices"] << " vertices, " << sf["triangles"] << " triangles, updated on the "
                << sf["where"].get<std::string>() << "; " << sf["output"].get<std::string>() << '\n';
      if (sf.contains("device_bytes_allocated")) {
        std::cout << "  surface device buffers allocated (" << humanBytes(sf["device_bytes_allocated"].get<double>())
                  << " in all):\n";
        printBuffers(sf["device_buffers_allocated"]);
      }
    }
    const auto& m = b["bytes_moved"];
    std::cout << "  bytes moved (estimate): " << humanBytes(m["per_pcg_iteration"].get<double>()) << " per PCG iteration, "
              << humanBytes(m["per_newton_iteration_without_pcg"].get<double>()) << " per Newton iteration besides PCG, "
              << "at most " << humanBytes(m["per_step_upper_bound"].get<double>()) << " per step ("
              << m["newton_iterations"] << " Newton iteration(s), " << m["newton_iterations_is"].get<std::string>()
              << ", PCG cap " << m["pcg_iteration_cap"] << ")\n";
  }
  for (const auto& g : plan["batches"]) {
    if (g["backend"] == "reference") {  // no device buffers: the host's threads run the bodies of each call
      std::cout << "batch on " << g["device"].get<std::string>() << " (" << g["bodies"].size()
                << " bodies, one call per operation, the bodies across the host's threads)\n";
      continue;
    }
    std::cout << "batch on " << g["device"].get<std::string>() << " (" << g["bodies"].size() << " bodies, one set of "
              << "launches): device buffers allocated " << humanBytes(g["allocated_bytes"].get<double>()) << '\n';
    printBuffers(g["buffers"]);
  }
  return kExitOk;
}

int cmdRun(const std::vector<std::string>& args) {
  std::string scenePath, outDir;
  std::vector<std::string> overrides;
  bool quiet = false, plan = false, asJson = false;
  InputLimits limits;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    Status limitError;
    if (limitFlag(args, i, limits, limitError)) {
      if (!limitError) return report(limitError);
    } else if (a == "--plan") {
      plan = true;
    } else if (a == "--json") {
      asJson = true;
    } else if (a == "--out" || a == "--set") {
      if (i + 1 >= args.size()) return report(Status(ErrorCode::BadInput, a + " needs a value"));
      (a == "--out" ? outDir : overrides.emplace_back()) = args[++i];
    } else if (a.rfind("--out=", 0) == 0) {
      outDir = a.substr(6);
    } else if (a.rfind("--set=", 0) == 0) {
      overrides.push_back(a.substr(6));
    } else if (a == "--quiet" || a == "-q") {
      quiet = true;
    } else if (!a.empty() && a[0] == '-') {
      return report(Status(ErrorCode::BadInput, "run: unknown option " + a +
                                                    " (options: --out DIR, --set key=value, --quiet, --plan, --json, " +
                                                    kLimitOptions + ")"));
    } else if (scenePath.empty()) {
      scenePath = a;
    } else {
      return report(Status(ErrorCode::BadInput, "run: more than one scene given (" + scenePath + ", " + a + ")"));
    }
  }
  if (scenePath.empty()) return report(Status(ErrorCode::BadInput, "run: no scene file given; usage: corofem run SCENE.json"));

  auto scene = loadScene(scenePath, overrides, limits);
  if (!scene) return report(scene.status());
  if (scene->analysis.kind == AnalysisDesc::Kind::Dynamic && scene->analysis.dynamics.steps == 0 && !plan)
    return report(Status(ErrorCode::BadInput, "run: scene '" + scene->name + "' is open-ended (analysis.steps = 0, "
                                              "for an application's frame loop); give the run a step count, e.g. "
                                              "--set analysis.steps=100"));
  if (outDir.empty()) outDir = (std::filesystem::path("out") / scene->name).string();

  SimulationOptions options;
  options.inputLimits = limits;
  auto sim = Simulation::create(scene.value(), options);
  if (!sim) return report(sim.status());
  if (plan) return printPlan(sim.value(), asJson);

  const auto t0 = std::chrono::steady_clock::now();
  Status status;
  std::unique_ptr<detail::RunOutputs> outputs;
  status = detail::guard([&] { outputs = std::make_unique<detail::RunOutputs>(sim.value(), outDir, limits); });
  if (!status) return report(status);
  if (!quiet)
    std::cout << "corofem: scene '" << scene->name << "': " << sim->bodyCount() << " body(ies), backend "
              << sim->backendName() << " on " << sim->deviceName() << ", " << sim->stepCount()
              << (scene->analysis.kind == AnalysisDesc::Kind::Static ? " load increment(s)" : " step(s)")
              << ", outputs in " << outDir << std::endl;
  if (!quiet) {
    const nlohmann::json sched = nlohmann::json::parse(sim->schedulerReport());
    for (const auto& b : sched["bodies"])
      std::cout << "corofem: scheduler: body '" << b["body"].get<std::string>() << "' on "
                << b["current"].get<std::string>() << ": " << b["reason"].get<std::string>()
                << (b["from_cache"].get<bool>() ? " [from cache]" : "") << std::endl;
  }
  for (int b = 0; !quiet && b < sim->bodyCount(); ++b)
    if (const BindingStatistics* st = sim->surfaceBinding(b))
      std::cout << "corofem: body '" << scene->bodies[static_cast<std::size_t>(b)].name << "': surface "
                << scene->bodies[static_cast<std::size_t>(b)].surface << " bound: " << st->insideCount
                << " vertices inside, " << st->outsideCount << " outside (largest distance "
                << st->largestDistance << " m, allowed " << st->maxDistanceUsed << " m)" << std::endl;

  status = detail::guard([&] { outputs->record(sim.value(), StepReport{}); });
  const int every = std::max(1, sim->stepCount() / 10);
  while (status && !sim->finished()) {
    StepReport r;
    status = sim->step(&r);
    // A failed step left the bodies at the last step recorded: no row for it (its report has no
    // step number); summary.json says why the run stopped.
    if (!status) break;
    status = detail::guard([&] { outputs->record(sim.value(), r); });
    if (!quiet && status && (r.step % every == 0 || sim->finished())) {
      std::cout << "  step " << r.step << "/" << sim->stepCount() << "  t=" << r.time
                << "  newton=" << r.newtonIterations << "  pcg=" << r.linearIterations
                << "  residual=" << r.residual << "  " << r.wallSeconds * 1e3 << " ms";
      if (!r.converged) std::cout << "  unconverged (linear residual " << r.linearResidual << ")";
      std::cout << std::endl;
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Status finished = detail::guard([&] { outputs->finish(sim.value(), status, wall); });
  const std::string nonFinite = outputs->nonFiniteNote();
  if (!nonFinite.empty()) std::cerr << "corofem: warning: " << nonFinite << '\n';
  const std::string unconverged = outputs->convergenceNote(sim.value());
  if (!unconverged.empty()) std::cerr << "corofem: warning: " << unconverged << '\n';
  if (!status) {
    if (!finished) report(finished);  // the summary was lost too: say so, then why the run stopped
    return report(status);
  }
  if (!finished) return report(finished);
  if (!quiet) std::cout << "corofem: done in " << wall << " s; summary in " << outDir << "/summary.json" << std::endl;
  return kExitOk;
}

// ------------------------------------------------------------------------------------ info
int cmdInfo(const std::vector<std::string>& args) {
  std::string path;
  bool asJson = false;
  InputLimits limits;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    Status limitError;
    if (limitFlag(args, i, limits, limitError)) {
      if (!limitError) return report(limitError);
    } else if (a == "--json") {
      asJson = true;
    } else if (!a.empty() && a[0] == '-') {
      return report(Status(ErrorCode::BadInput,
                           "info: unknown option " + a + " (options: --json, " + kLimitOptions + ")"));
    } else if (path.empty()) {
      path = a;
    } else {
      return report(Status(ErrorCode::BadInput, "info: more than one mesh given"));
    }
  }
  if (path.empty()) return report(Status(ErrorCode::BadInput, "info: no mesh given; usage: corofem info MESH"));

  nlohmann::json j;
  MeshReadReport rep;
  if (isSurfacePath(path)) {
    auto surf = readSurfaceMesh(path, &rep, limits);
    if (!surf) return report(surf.status());
    std::array<double, 3> lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (std::size_t i = 0; i < surf->vertexCount(); ++i)
      for (int c = 0; c < 3; ++c) {
        lo[c] = std::min(lo[c], surf->vertices[3 * i + c]);
        hi[c] = std::max(hi[c], surf->vertices[3 * i + c]);
      }
    j = {{"file", path}, {"format", rep.format}, {"vertices", surf->vertexCount()},
         {"triangles", surf->triangleCount()}, {"split_polygons", rep.splitPolygons},
         {"bbox_min", lo}, {"bbox_max", hi}};
  } else {
    auto mesh = readTetMesh(path, &rep, {}, limits);
    if (!mesh) return report(mesh.status());
    const MeshInfo info = computeMeshInfo(mesh.value());
    j = {{"file", path}, {"format", rep.format}, {"nodes", info.nodes}, {"tets", info.tets},
         {"boundary_faces", info.boundaryFaces}, {"unused_nodes", info.unusedNodes},
         {"bbox_min", info.bboxMin}, {"bbox_max", info.bboxMax}, {"volume", info.volume},
         {"min_element_volume", info.minVolume}, {"max_element_volume", info.maxVolume},
         {"min_aspect_ratio", info.minAspect}, {"max_aspect_ratio", info.maxAspect},
         {"negatively_oriented_in_file", rep.reorientedElements},
         {"skipped_elements", rep.skippedElements}, {"skipped_by_type", rep.skippedByType},
         {"has_regions", !mesh->regions.empty()}};
    // How local the numbering is for the OpenCL kernels (mesh/locality_order.hpp): the mean jump of
    // consecutive elements' lowest node, in the file's numbering and along a Morton curve, and the
    // numbering the OpenCL backend's device takes ("device_numbering", as in the plan).
    const detail::LocalityOrder morton = detail::mortonOrder(mesh.value());
    const double own = detail::meanNodeJump(mesh->tets);
    const double along = detail::meanNodeJump(mesh->tets, &morton.elements, &morton.nodeOf);
    j["node_jump"] = own;
    j["node_jump_morton"] = along;
    j["device_numbering"] = mesh->tetCount() >= 2 && detail::mortonIsMoreLocal(own, along) ? "morton" : "mesh";
  }
  if (asJson) {
    std::cout << j.dump(2) << '\n';
    return kExitOk;
  }
  for (auto it = j.begin(); it != j.end(); ++it) std::cout << it.key() << ": " << it.value().dump() << '\n';
  return kExitOk;
}

// ------------------------------------------------------------------------------------ convert
int cmdConvert(const std::vector<std::string>& args) {
  std::vector<std::string> paths;
  InputLimits limits;
  for (std::size_t i = 0; i < args.size(); ++i) {
    Status limitError;
    if (limitFlag(args, i, limits, limitError)) {
      if (!limitError) return report(limitError);
    } else if (args[i].size() > 1 && args[i][0] == '-') {
      return report(Status(ErrorCode::BadInput,
                           "convert: unknown option " + args[i] + " (options: " + kLimitOptions + ")"));
    } else {
      paths.push_back(args[i]);
    }
  }
  if (paths.size() != 2) return report(Status(ErrorCode::BadInput, "convert: usage: corofem convert IN OUT"));
  const std::string& in = paths[0];
  const std::string& out = paths[1];
  if (isSurfacePath(in)) {
    auto surf = readSurfaceMesh(in, nullptr, limits);
    if (!surf) return report(surf.status());
    Status st = writeSurfaceMesh(out, surf.value());
    if (!st) return report(st);
    std::cout << "corofem: wrote " << out << " (" << surf->vertexCount() << " vertices, " << surf->triangleCount()
              << " triangles)\n";
    return kExitOk;
  }
  MeshReadReport rep;
  auto mesh = readTetMesh(in, &rep, {}, limits);
  if (!mesh) return report(mesh.status());
  if (isSurfacePath(out))
    return report(Status(ErrorCode::BadInput, "convert: " + out + ": a tet mesh cannot be written as OBJ; use .vtu, .vtk, .msh, .mesh, .node or .veg"));
  Status st = writeTetMesh(out, mesh.value());
  if (!st) return report(st);
  std::cout << "corofem: wrote " << out << " (" << mesh->nodeCount() << " nodes, " << mesh->tetCount() << " tets";
  if (rep.reorientedElements) std::cout << ", " << rep.reorientedElements << " reoriented";
  std::cout << ")\n";
  return kExitOk;
}

/// corofem warmup [SCENE] [--set ...]: warmUp() on the scene, or on a small default scene in float
/// and double on every OpenCL device.
int cmdWarmup(const std::vector<std::string>& args) {
  std::string scenePath;
  std::vector<std::string> overrides;
  SimulationOptions options;
  for (std::size_t i = 0; i < args.size(); ++i) {
    Status limitError;
    if (limitFlag(args, i, options.inputLimits, limitError)) {
      if (!limitError) return report(limitError);
    } else if (args[i] == "--set") {
      if (i + 1 >= args.size()) return report(Status(ErrorCode::BadInput, "--set needs a value"));
      overrides.push_back(args[++i]);
    } else if (args[i].rfind("--set=", 0) == 0) {
      overrides.push_back(args[i].substr(6));
    } else if (!args[i].empty() && args[i][0] == '-') {
      return report(Status(ErrorCode::BadInput, "warmup: unknown option " + args[i] + " (options: --set key=value, " +
                                                  kLimitOptions + ")"));
    } else if (scenePath.empty()) {
      scenePath = args[i];
    } else {
      return report(Status(ErrorCode::BadInput, "warmup: more than one scene given (" + scenePath + ", " + args[i] + ")"));
    }
  }
  std::vector<std::pair<std::string, Scene>> scenes;
  if (!scenePath.empty()) {
    auto scene = loadScene(scenePath, overrides, options.inputLimits);
    if (!scene) return report(scene.status());
    scenes.emplace_back(scene->name, scene.value());
  } else {
    const auto opencl = detail::findBackend("opencl");
    const std::vector<detail::Candidate> devices = opencl ? opencl->candidates() : std::vector<detail::Candidate>{};
    if (devices.empty()) {
      std::cout << "corofem: warmup: no OpenCL device here; the reference backend compiles nothing\n";
      return kExitOk;
    }
    for (std::size_t d = 0; d < devices.size(); ++d)
      for (Precision p : {Precision::Float, Precision::Double}) {
        Scene s;
        s.name = "warmup";
        BodyDesc body;
        body.name = "box";
        BoxSpec box;
        box.max = {0.4, 0.1, 0.1};
        box.cells = {8, 2, 2};
        body.mesh.box = box;
        s.bodies.push_back(body);
        s.analysis.dynamics.steps = 1;
        s.backend.kind = BackendKind::OpenCL;
        s.backend.device = devices[d].selector;
        s.solver.precision = p;
        scenes.emplace_back(devices[d].device + (p == Precision::Float ? ", float" : ", double"), s);
      }
  }
  int rc = kExitOk;
  for (const auto& [name, scene] : scenes) {
    double seconds = 0.0;
    const Status st = warmUp(scene, options, &seconds);
    if (st) {
      std::cout << "corofem: warmup: " << name << ": compiled and cached in " << seconds << " s\n";
    } else {
      std::cerr << "corofem: warmup: " << name << ": " << toString(st.code()) << ": " << st.message() << '\n';
      if (!scenePath.empty()) rc = exitCodeFor(st);
    }
  }
  return rc;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
    usage(args.empty() ? std::cerr : std::cout);
    return args.empty() ? kExitBadInput : kExitOk;
  }
  if (args[0] == "--version") {
    std::cout << "corofem 0.1.0\n";
    return kExitOk;
  }
  const std::string cmd = args[0];
  args.erase(args.begin());
  try {
    if (cmd == "run") return cmdRun(args);
    if (cmd == "info") return cmdInfo(args);
    if (cmd == "convert") return cmdConvert(args);
    if (cmd == "warmup") return cmdWarmup(args);
  } catch (const std::exception& e) {
    std::cerr << "corofem: internal error: " << e.what() << '\n';
    return kExitOther;
  }
  std::cerr << "corofem: unknown command '" << cmd << "' (commands: run, info, convert, warmup)\n";
  usage(std::cerr);
  return kExitBadInput;
}
