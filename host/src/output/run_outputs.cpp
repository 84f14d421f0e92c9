#include "output/run_outputs.hpp"

#include "mesh/text_writer.hpp"
#include "scene/scene_paths.hpp"
#include "util/error.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numeric>

namespace corofem::detail {

namespace fs = std::filesystem;

namespace {

int findBody(const Simulation& sim, const std::string& name) {
  if (name.empty()) return 0;
  for (int b = 0; b < sim.bodyCount(); ++b)
    if (sim.scene().bodies[static_cast<std::size_t>(b)].name == name) return b;
  std::string names;
  for (const auto& body : sim.scene().bodies) names += (names.empty() ? "\"" : ", \"") + body.name + "\"";
  fail(ErrorCode::BadInput, "output.probes: body \"", name, "\" does not exist; the scene's bodies are ", names);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Replaces every NaN or infinity in j by null (what JSON has for them), counting them and keeping
/// the key path of the first.
void nullNonFinite(nlohmann::json& j, const std::string& path, std::size_t& count, std::string& first) {
  if (j.is_number_float() && !std::isfinite(j.get<double>())) {
    const double x = j.get<double>();
    if (count++ == 0) first = "summary.json " + path + " = " + (std::isnan(x) ? "nan" : x > 0 ? "inf" : "-inf");
    j = nullptr;
  } else if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it)
      nullNonFinite(it.value(), path.empty() ? it.key() : path + "." + it.key(), count, first);
  } else if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i) nullNonFinite(j[i], path + "[" + std::to_string(i) + "]", count, first);
  }
}

std::string vtkName(const std::string& body, int step) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%06d.vtu", step);
  return body + buf;
}

}  // namespace

RunOutputs::RunOutputs(const Simulation& sim, const std::string& dir, const InputLimits& limits) : dir_(dir) {
  const Scene& scene = sim.scene();
  // Body names become file names in the folder (<body>.pvd, vtk/<body>_000012.vtu): one such as
  // "../../x" or "/abs/path" would write outside it. loadScene refuses them; so does this, for a
  // Scene made in code.
  for (std::size_t b = 0; b < scene.bodies.size(); ++b) {
    const std::string problem = scene::fileNameProblem(scene.bodies[b].name);
    if (!problem.empty())
      fail(ErrorCode::BadInput, "bodies[", b, "].name: the name \"", shorten(scene.bodies[b].name), "\" ", problem);
  }
  if (scene.output.vtk && scene.output.vtuCompression == VtuCompression::Zlib) {
    // A scene made in code skips the parser's checks: refuse here, before anything is written.
    if (scene.output.vtuFormat == VtuFormat::Ascii)
      fail(ErrorCode::BadInput, "output.vtu_compression: \"zlib\" compresses binary arrays only, and vtu_format is "
           "\"ascii\"; set vtu_format to \"base64\" or \"raw\", or use \"none\"");
    if (!vtuZlibAvailable())
      fail(ErrorCode::BadInput, "output.vtu_compression: \"zlib\" needs a corofem built with zlib, and this one was "
           "built without it; install zlib1g-dev and rebuild, or use \"none\"");
  }
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) fail(ErrorCode::IoError, "cannot create the output folder ", dir_, ": ", ec.message());

  for (std::size_t i = 0; i < scene.output.probes.size(); ++i) {
    const ProbeDesc& desc = scene.output.probes[i];
    Probe probe;
    probe.name = desc.name.empty() ? "probe" + std::to_string(i) : desc.name;
    const std::string problem = scene::nameProblem(probe.name);
    if (!problem.empty())
      fail(ErrorCode::BadInput, "output.probes[", i, "].name: the name \"", shorten(probe.name), "\" ", problem);
    probe.body = findBody(sim, desc.body);
    auto nodes = resolveNodeSet(desc.nodes, sim.restMesh(probe.body), scene.baseDir, limits);
    if (!nodes) fail(nodes.status().code(), "output.probes[", i, "] (\"", probe.name, "\"): ", nodes.message());
    probe.nodes = std::move(nodes.value());
    probes_.push_back(std::move(probe));
  }

  std::vector<std::string> columns{"step",     "time",      "newton_iterations", "linear_iterations",
                                   "residual", "linear_residual", "converged", "elastic_energy",
                                   "kinetic_energy"};
  for (const Probe& p : probes_)
    for (const char* c : {"_ux", "_uy", "_uz"}) columns.push_back(p.name + c);
  csv_.open((fs::path(dir_) / "probes.csv").string(), columns);

  if (scene.output.vtk) {
    fs::create_directories(fs::path(dir_) / "vtk", ec);
    if (ec) fail(ErrorCode::IoError, "cannot create ", (fs::path(dir_) / "vtk").string(), ": ", ec.message());
    for (const BodyDesc& body : scene.bodies)
      series_.push_back(std::make_unique<PvdSeries>((fs::path(dir_) / (body.name + ".pvd")).string()));
  }
  for (int b = 0; b < sim.bodyCount(); ++b) {
    const bool hasSurface = sim.restSurface(b) != nullptr;
    surfaceSeries_.push_back(hasSurface && scene.output.vtk
        ? std::make_unique<PvdSeries>((fs::path(dir_) / (scene.bodies[static_cast<std::size_t>(b)].name + "_surface.pvd")).string())
        : nullptr);
    if (hasSurface && scene.output.surfaceObj) {
      fs::create_directories(fs::path(dir_) / "surface", ec);
      if (ec) fail(ErrorCode::IoError, "cannot create ", (fs::path(dir_) / "surface").string(), ": ", ec.message());
    }
  }
}

RunOutputs::~RunOutputs() = default;

void RunOutputs::record(const Simulation& sim, const StepReport& report) {
  if (report.step > 0) {
    stepWallSeconds_.push_back(report.wallSeconds);
    reports_.push_back(report);
  }
  double elastic = 0, kinetic = 0;
  for (int b = 0; b < sim.bodyCount(); ++b) {
    const EnergyReport e = sim.energies(b);
    elastic += e.elastic;
    kinetic += e.kinetic;
  }
  const std::string where = "probes.csv step " + std::to_string(report.step);
  csv_.beginRow();
  csv_.add(report.step);
  csv_.add(report.time, where);
  csv_.add(report.newtonIterations);
  csv_.add(report.linearIterations);
  csv_.add(report.residual, where);
  csv_.add(report.linearResidual, where);
  csv_.add(report.converged ? 1 : 0);
  csv_.add(elastic, where);
  csv_.add(kinetic, where);

  lastProbe_.clear();
  std::vector<double> x;
  for (const Probe& p : probes_) {
    Status st = sim.readPositions(p.body, x);
    if (!st) fail(st.code(), st.message());
    const std::vector<double>& x0 = sim.restMesh(p.body).nodes;
    double u[3] = {0, 0, 0};
    for (std::uint32_t n : p.nodes)
      for (int c = 0; c < 3; ++c) u[c] += x[3 * n + c] - x0[3 * n + c];
    for (double& c : u) c /= static_cast<double>(p.nodes.size());
    for (double c : u) csv_.add(c, where);
    lastProbe_.insert(lastProbe_.end(), u, u + 3);
  }
  csv_.endRow();

  const Scene& scene = sim.scene();
  const int every = scene.output.vtkEvery;
  const bool due = report.step == 0 || sim.finished() || (every > 0 && report.step % every == 0);
  if (due && (scene.output.vtk || scene.output.surfaceObj)) writeVtk(sim, report.step, report.time);
}

void RunOutputs::writeVtk(const Simulation& sim, int step, double time) {
  if (step == lastVtkStep_) return;
  lastVtkStep_ = step;
  std::vector<double> x, v;
  const VtuOptions vtu{sim.scene().output.vtuFormat, sim.scene().output.vtuCompression};
  for (int b = 0; b < sim.bodyCount(); ++b) {
    const BodyDesc& body = sim.scene().bodies[static_cast<std::size_t>(b)];
    if (const SurfaceMesh* rest = sim.restSurface(b)) {
      // The coupled render surface, recomputed from the deformed tetrahedra (paper Sec. 5), with its
      // smooth unit normals (OBJ vn, VTU "Normals").
      SurfaceMesh surface = *rest;
      Status st = sim.readSurface(b, surface.vertices, &surface.normals);
      if (!st) fail(st.code(), st.message());
      char suffix[32];
      std::snprintf(suffix, sizeof suffix, "_surface_%06d", step);
      if (sim.scene().output.surfaceObj) {
        st = writeSurfaceMesh((fs::path(dir_) / "surface" / (body.name + suffix + ".obj")).string(), surface);
        if (!st) fail(st.code(), st.message());
      }
      if (auto& series = surfaceSeries_[static_cast<std::size_t>(b)]) {
        const std::string name = body.name + suffix + ".vtu";
        st = writeSurfaceMesh((fs::path(dir_) / "vtk" / name).string(), surface, vtu);
        if (!st) fail(st.code(), st.message());
        series->add(time, "vtk/" + name);
        st = series->write();
        if (!st) fail(st.code(), st.message());
      }
    }
    if (!sim.scene().output.vtk) continue;
    TetMesh mesh = sim.restMesh(b);
    Status st = sim.readPositions(b, x);
    if (!st) fail(st.code(), st.message());
    MeshField disp{"displacement", 3, false, {}};
    disp.values.resize(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) disp.values[i] = x[i] - mesh.nodes[i];
    std::vector<MeshField> fields{disp};
    if (sim.scene().analysis.kind == AnalysisDesc::Kind::Dynamic && sim.readVelocities(b, v))
      fields.push_back(MeshField{"velocity", 3, false, v});
    mesh.nodes = x;
    const std::string name = vtkName(body.name, step);
    st = writeTetMesh((fs::path(dir_) / "vtk" / name).string(), mesh, fields, vtu);
    if (!st) fail(st.code(), st.message());
    series_[static_cast<std::size_t>(b)]->add(time, "vtk/" + name);
    st = series_[static_cast<std::size_t>(b)]->write();
    if (!st) fail(st.code(), st.message());
  }
}

void RunOutputs::finish(const Simulation& sim, const Status& status, double totalWallSeconds) {
  using nlohmann::json;
  const Scene& scene = sim.scene();
  json j;
  j["scene"] = scene.name;
  const Convergence conv = convergence();
  j["status"] = !status.isOk() ? "failed" : conv.unconverged > 0 ? "ok_unconverged" : "ok";
  if (!status.isOk()) {
    j["error"] = status.message();
    j["error_kind"] = toString(status.code());
  }
  j["backend"] = sim.backendName();
  j["device"] = sim.deviceName();
  {
    // Where the bodies ran and why (schedule/scheduler.hpp), and the device failures survived.
    json sched = json::parse(sim.schedulerReport());
    j["fallbacks"] = sched["fallbacks"];
    sched.erase("fallbacks");
    j["scheduler"] = sched;
  }
  j["analysis"] = scene.analysis.kind == AnalysisDesc::Kind::Static ? "static" : "dynamic";
  j["steps_requested"] = sim.stepCount();
  j["steps_taken"] = sim.stepsTaken();
  j["time"] = sim.time();
  j["total_wall_time_s"] = totalWallSeconds;

  std::vector<double> linIters, newtonIters;
  long long linTotal = 0, newtonTotal = 0;
  for (const StepReport& r : reports_) {
    linIters.push_back(r.linearIterations);
    newtonIters.push_back(r.newtonIterations);
    linTotal += r.linearIterations;
    newtonTotal += r.newtonIterations;
  }
  json wall;
  wall["median"] = median(stepWallSeconds_);
  wall["min"] = stepWallSeconds_.empty() ? 0.0 : *std::min_element(stepWallSeconds_.begin(), stepWallSeconds_.end());
  wall["max"] = stepWallSeconds_.empty() ? 0.0 : *std::max_element(stepWallSeconds_.begin(), stepWallSeconds_.end());
  wall["mean"] = stepWallSeconds_.empty() ? 0.0
      : std::accumulate(stepWallSeconds_.begin(), stepWallSeconds_.end(), 0.0) / static_cast<double>(stepWallSeconds_.size());
  j["wall_time_per_step_s"] = wall;
  j["linear_iterations"] = {{"total", linTotal}, {"median_per_step", median(linIters)}};
  j["newton_iterations"] = {{"total", newtonTotal}, {"median_per_step", median(newtonIters)}};
  // Steps that completed with linear solves short of solver.tolerance (their answer is inexact).
  j["convergence"] = {{"steps_unconverged", conv.unconverged},
                      {"steps_recorded", reports_.size()},
                      {"first_unconverged_step", conv.first > 0 ? json(conv.first) : json(nullptr)},
                      {"worst_unconverged_linear_residual", conv.worstUnconverged},
                      {"worst_linear_residual", conv.worst},
                      {"solver_tolerance", scene.solver.tolerance},
                      {"solver_max_iterations", scene.solver.maxIterations}};

  json bodies = json::array();
  for (int b = 0; b < sim.bodyCount(); ++b) {
    const TetMesh& mesh = sim.restMesh(b);
    const MeshReadReport& rep = sim.meshReport(b);
    const EnergyReport e = sim.energies(b);
    bodies.push_back({{"name", scene.bodies[static_cast<std::size_t>(b)].name},
                      {"formulation", toString(scene.bodies[static_cast<std::size_t>(b)].formulation)},
                      {"nodes", mesh.nodeCount()},
                      {"tets", mesh.tetCount()},
                      {"mesh_format", rep.format},
                      {"reoriented_elements", rep.reorientedElements},
                      {"skipped_elements", rep.skippedElements},
                      {"elastic_energy", e.elastic},
                      {"kinetic_energy", e.kinetic}});
    if (const BindingStatistics* stats = sim.surfaceBinding(b)) {
      const SurfaceMesh* surface = sim.restSurface(b);
      bodies.back()["surface"] = {{"file", scene.bodies[static_cast<std::size_t>(b)].surface},
                                  {"vertices", surface->vertexCount()},
                                  {"triangles", surface->triangleCount()},
                                  {"inside", stats->insideCount},
                                  {"outside", stats->outsideCount},
                                  {"largest_distance", stats->largestDistance},
                                  {"max_distance_allowed", stats->maxDistanceUsed},
                                  {"layout", toString(scene.bodies[static_cast<std::size_t>(b)].surfaceLayout)}};
    }
  }
  j["bodies"] = bodies;
  json probes = json::object();
  for (std::size_t i = 0; i < probes_.size(); ++i) {
    if (lastProbe_.size() >= 3 * (i + 1))
      probes[probes_[i].name] = {lastProbe_[3 * i], lastProbe_[3 * i + 1], lastProbe_[3 * i + 2]};
  }
  j["final_probe_displacement"] = probes;
  if (!series_.empty()) {
    json vtk = json::array();
    for (const auto& s : series_) vtk.push_back(fs::path(s->path()).filename().string());
    for (const auto& s : surfaceSeries_)
      if (s) vtk.push_back(fs::path(s->path()).filename().string());
    j["vtk_series"] = vtk;
  }

  summaryNonFinite_ = 0;
  firstSummaryNonFinite_.clear();
  nullNonFinite(j, "", summaryNonFinite_, firstSummaryNonFinite_);
  const std::size_t total = csv_.nonFiniteCount() + summaryNonFinite_;
  if (total > 0)
    j["non_finite_values"] = {{"count", total},
                              {"first", csv_.nonFiniteCount() ? csv_.firstNonFinite() : firstSummaryNonFinite_},
                              {"written_as", "an empty cell in probes.csv, null in summary.json"}};
  // Through a temporary file and a rename, every write checked: a full disk is an error, and a
  // summary that exists is whole. Invalid UTF-8 in a message is replaced, not an exception.
  mesh::TextWriter out;
  out << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << '\n';
  out.save((fs::path(dir_) / "summary.json").string());
}

RunOutputs::Convergence RunOutputs::convergence() const {
  Convergence c;
  for (const StepReport& r : reports_) {
    c.worst = std::max(c.worst, r.linearResidual);
    if (r.converged) continue;
    if (c.unconverged++ == 0) c.first = r.step;
    c.worstUnconverged = std::max(c.worstUnconverged, r.linearResidual);
  }
  return c;
}

std::string RunOutputs::convergenceNote(const Simulation& sim) const {
  const Convergence c = convergence();
  if (c.unconverged == 0) return "";
  const SolverDesc& solver = sim.scene().solver;
  char worst[32], tolerance[32];
  std::snprintf(worst, sizeof worst, "%.2g", c.worstUnconverged);
  std::snprintf(tolerance, sizeof tolerance, "%g", solver.tolerance);
  const bool pcg = solver.linearSolver == LinearSolverKind::Pcg;
  return std::to_string(c.unconverged) + " of " + std::to_string(reports_.size()) +
         " steps finished with linear solves short of solver.tolerance = " + tolerance + " (the first: step " +
         std::to_string(c.first) + "; the worst relative residual " + worst +
         (pcg ? ", solver.max_iterations = " + std::to_string(solver.maxIterations) : std::string()) +
         "): their answer is inexact, and summary.json says \"ok_unconverged\"; " +
         (pcg ? "raise solver.max_iterations for converged solves" : "check the constraints and the material");
}

std::string RunOutputs::nonFiniteNote() const {
  const std::size_t total = csv_.nonFiniteCount() + summaryNonFinite_;
  if (total == 0) return "";
  return std::to_string(total) + (total == 1 ? " value was" : " values were") + " not finite (the first: " +
         (csv_.nonFiniteCount() ? csv_.firstNonFinite() : firstSummaryNonFinite_) +
         "); probes.csv leaves such a cell empty and summary.json writes null";
}

}  // namespace corofem::detail
