// The knob sweep: three fixed scenes, each run across the solver knobs, timed per step and compared
// with a double-precision reference solve.
//
// Scenes (all SI units):
//   fig8       the paper's Fig. 8 beam: 0.8 x 0.1 x 0.1 m, 8 x 1 x 1 cells x 5 tets, E = 50 kPa,
//              nu = 0.3, rho = 1000, clamped at x = 0, gravity -y; Newmark (beta 1/4, gamma 1/2),
//              h = 0.01 s, one linearised Newton iteration per step (the paper), 100 steps (50 with --quick). The beam
//              swings down through large rotations. Error: every node, final state, against the
//              reference solve of the same mesh.
//   cantilever 1 x 0.1 x 0.1 m, E = 10 MPa, nu = 0.3, clamped at x = 0, tip force P = 250 N (-y)
//              spread over the x = 1 face: alpha = P L^2 / (E I) = 250 / (1e7 * 0.1^4 / 12) = 3.0
//              (cantilever_elastica.md: tip deflection 0.60 L, rotation 63 deg). Static, 6 load
//              increments. Knob rows on 20 x 2 x 2 cells against the same mesh ("same_mesh"); the
//              resolution rows (10r x r x r cells) against the finest mesh, compared on the nodes of
//              the coarsest mesh, which every finer box mesh contains ("finest_mesh").
//   cantilever_dyn  the same beam (30 x 3 x 3 cells; 20 x 2 x 2 with --quick) and tip force, ramped
//              over 0.3 s, in dynamics: Newmark, h = 0.01 s, one linearised Newton iteration per
//              step, mass damping 10 1/s, 100 steps. Error: every node, final state, same mesh.
//   coupled    the coupled-mesh body: a 0.8 x 0.1 x 0.1 m box beam of 8r x r x r cells (E = 3 MPa,
//              nu = 0.3, rho = 1000, mass damping 15 1/s, clamped at x = 0, gravity -y; Newmark,
//              h = 0.01 s, one linearised Newton iteration per step as in the paper, 100 steps)
//              drives the SAME fine surface, a cylinder of radius 0.04 m around the beam axis
//              (48 x 160 quads as triangles, 7728 vertices), bound with bindSurface. Error: the
//              surface vertices' displacement (deformSurface), final state, against the finest
//              tet mesh solved by the reference.
//   coupled_tol  only with --only coupled_tol: the 48x6x6 coupled mesh on the OpenCL backend,
//              PCG tolerance 1e-5 to 1e-8 x float / mixed / double, against its own Cholesky solve.
//
// The reference of each (scene, mesh): reference backend, double, LDL^T (Cholesky), co-rotational,
// statics to a relative residual of 1e-8 (the knob rows keep the default 1e-6; 1e-10 stalls at
// 3e-9 on the 9k-dof mesh). Linear-formulation rows are measured against the same co-rotational
// reference, so their error is the formulation's error.
//
// Time per step: StepReport::wallSeconds, the median over the steps of one run (dynamics), or the
// median over 3 repetitions (1 with --quick) of a whole static solve divided by its increments.
#include "tradeoff.hpp"

#include <corofem/embed.hpp>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace corofem::tradeoff {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One configuration of the knobs.
struct Knobs {
  BackendKind backend = BackendKind::Reference;
  LinearSolverKind linearSolver = LinearSolverKind::Pcg;
  Precision precision = Precision::Double;
  RotationMethod rotation = RotationMethod::Polar;
  PreconditionerKind preconditioner = PreconditionerKind::Diagonal;
  double tolerance = 1e-6;
  int maxIterations = 1000;
  Formulation formulation = Formulation::Corotational;
};

enum class SceneKind { Fig8, Cantilever, CantileverDynamic, Coupled };

struct SceneCase {
  std::string name;  ///< CSV "scene" column
  SceneKind kind;
  int level;         ///< refinement level r
  int steps;         ///< dynamics: time steps
};

// ---- scene construction ----------------------------------------------------------------------

NodeSetDesc plane(double x) {
  NodeSetDesc s;
  s.kind = NodeSetDesc::Kind::Plane;
  s.planePoint = {x, 0, 0};
  s.planeNormal = {1, 0, 0};
  s.planeTolerance = 1e-6;
  return s;
}

std::array<int, 3> cellsOf(SceneKind kind, int level) {
  if (kind == SceneKind::Cantilever || kind == SceneKind::CantileverDynamic) return {10 * level, level, level};
  return {8 * level, level, level};
}

Scene buildScene(const SceneCase& c, const Knobs& k) {
  BodyDesc body;
  body.name = "beam";
  BoxSpec box;
  box.cells = cellsOf(c.kind, c.level);
  box.tetsPerCell = 5;
  body.fixed.push_back(plane(0.0));
  Scene scene;
  scene.name = c.name;
  switch (c.kind) {
    case SceneKind::Fig8: {
      box.max = {0.8, 0.1, 0.1};
      body.material.youngsModulus = 5e4;
      body.material.poissonRatio = 0.3;
      body.material.density = 1000;
      LoadDesc g;
      g.kind = LoadDesc::Kind::Gravity;
      g.vector = {0, -9.81, 0};
      body.loads.push_back(g);
      scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
      scene.analysis.dynamics.timeStep = 0.01;
      scene.analysis.dynamics.steps = c.steps;
      scene.analysis.dynamics.newtonIterations = 1;
      break;
    }
    case SceneKind::Cantilever: {
      box.max = {1.0, 0.1, 0.1};
      body.material.youngsModulus = 1e7;
      body.material.poissonRatio = 0.3;
      body.material.density = 1000;
      LoadDesc f;
      f.kind = LoadDesc::Kind::Force;
      f.vector = {0, -250.0, 0};  // alpha = P L^2 / (E I) = 3
      f.nodes = plane(1.0);
      body.loads.push_back(f);
      scene.analysis.kind = AnalysisDesc::Kind::Static;
      scene.analysis.statics.increments = 6;
      scene.analysis.statics.maxNewtonIterations = 30;
      break;
    }
    case SceneKind::CantileverDynamic: {
      box.max = {1.0, 0.1, 0.1};
      body.material.youngsModulus = 1e7;
      body.material.poissonRatio = 0.3;
      body.material.density = 1000;
      body.material.rayleighMass = 10.0;  // damping ratio ~0.5 on the first mode (omega_1 ~ 10/s)
      LoadDesc f;
      f.kind = LoadDesc::Kind::Force;
      f.vector = {0, -250.0, 0};  // alpha = 3 at full load
      f.nodes = plane(1.0);
      f.rampTime = 0.3;
      body.loads.push_back(f);
      scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
      scene.analysis.dynamics.timeStep = 0.01;
      scene.analysis.dynamics.steps = c.steps;
      scene.analysis.dynamics.newtonIterations = 1;
      break;
    }
    case SceneKind::Coupled: {
      box.max = {0.8, 0.1, 0.1};
      body.material.youngsModulus = 3e6;
      body.material.poissonRatio = 0.3;
      body.material.density = 1000;
      body.material.rayleighMass = 15.0;  // about critical for the first bending mode (omega ~ 9/s)
      LoadDesc g;
      g.kind = LoadDesc::Kind::Gravity;
      g.vector = {0, -9.81, 0};
      body.loads.push_back(g);
      scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
      scene.analysis.dynamics.timeStep = 0.01;
      scene.analysis.dynamics.steps = c.steps;
      scene.analysis.dynamics.newtonIterations = 1;
      break;
    }
  }
  body.mesh.box = box;
  body.formulation = k.formulation;
  scene.bodies.push_back(body);
  scene.solver.linearSolver = k.linearSolver;
  scene.solver.precision = k.precision;
  scene.solver.rotation = k.rotation;
  scene.solver.preconditioner = k.preconditioner;
  scene.solver.tolerance = k.tolerance;
  scene.solver.maxIterations = k.maxIterations;
  scene.backend.kind = k.backend;
  scene.output.vtk = false;
  return scene;
}

/// The coupled scene's render surface: an open cylinder of radius 0.04 m around the beam's axis
/// (y = z = 0.05), x from 0.01 to 0.79, 48 segments around and 160 along, quads split in two.
SurfaceMesh cylinderSurface() {
  constexpr int kAround = 48, kAlong = 160;
  constexpr double kPi = 3.14159265358979323846;
  SurfaceMesh s;
  for (int i = 0; i <= kAlong; ++i) {
    const double x = 0.01 + 0.78 * i / kAlong;
    for (int j = 0; j < kAround; ++j) {
      const double t = 2 * kPi * j / kAround;
      s.vertices.insert(s.vertices.end(), {x, 0.05 + 0.04 * std::cos(t), 0.05 + 0.04 * std::sin(t)});
    }
  }
  for (int i = 0; i < kAlong; ++i)
    for (int j = 0; j < kAround; ++j) {
      const auto a = std::uint32_t(i * kAround + j), b = std::uint32_t(i * kAround + (j + 1) % kAround);
      const auto c = a + kAround, d = b + kAround;
      s.triangles.insert(s.triangles.end(), {a, b, d, a, d, c});
    }
  return s;
}

// ---- running and measuring -------------------------------------------------------------------

/// What one run produced: its final state and its timing.
struct RunResult {
  std::string status = "ok";
  std::vector<double> displacement;  ///< 3 per node, final state
  std::vector<double> rest;          ///< 3 per node
  TetMesh mesh;
  double energy = kNaN;              ///< elastic + kinetic (J), final state
  double msPerStep = kNaN, msMin = kNaN;
  double totalMs = 0;                ///< sum of the step times
  int steps = 0;
  double pcgPerStep = 0, newtonPerStep = 0, convergedFraction = 0;
  std::string device;
};

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string clean(std::string s) {
  for (char& ch : s)
    if (ch == ',' || ch == '\n' || ch == '"') ch = ';';
  if (s.size() > 160) s = s.substr(0, 160) + "...";
  return s;
}

RunResult runOnce(const Scene& scene) {
  RunResult r;
  auto sim = Simulation::create(scene);
  if (!sim) {
    r.status = "create failed: " + clean(sim.message());
    return r;
  }
  r.device = sim->backendName() + ": " + sim->deviceName();
  std::vector<double> stepMs;
  long pcg = 0, newton = 0, converged = 0;
  while (!sim->finished()) {
    StepReport rep;
    const Status st = sim->step(&rep);
    if (!st) {
      r.status = "step " + std::to_string(sim->stepsTaken() + 1) + " failed: " + clean(st.message());
      break;
    }
    stepMs.push_back(1e3 * rep.wallSeconds);
    r.totalMs += 1e3 * rep.wallSeconds;
    pcg += rep.linearIterations;
    newton += rep.newtonIterations;
    converged += rep.converged ? 1 : 0;
  }
  r.steps = int(stepMs.size());
  if (r.steps > 0) {
    r.msPerStep = median(stepMs);
    r.msMin = *std::min_element(stepMs.begin(), stepMs.end());
    r.pcgPerStep = double(pcg) / r.steps;
    r.newtonPerStep = double(newton) / r.steps;
    r.convergedFraction = double(converged) / r.steps;
  }
  if (r.status != "ok") return r;
  r.mesh = sim->restMesh(0);
  r.rest = r.mesh.nodes;
  std::vector<double> x;
  sim->readPositions(0, x);
  r.displacement.resize(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) r.displacement[i] = x[i] - r.rest[i];
  const EnergyReport e = sim->energies(0);
  r.energy = e.elastic + e.kinetic;
  return r;
}

/// Dynamics: one run, median over its steps. Statics: `reps` runs, median of (total / increments);
/// a static run's increments differ in Newton iterations, so the mean over one solve is the unit.
RunResult measure(const Scene& scene, int reps) {
  if (scene.analysis.kind == AnalysisDesc::Kind::Dynamic) return runOnce(scene);
  std::vector<double> perStep;
  RunResult last;
  for (int i = 0; i < std::max(1, reps); ++i) {
    last = runOnce(scene);
    if (last.status != "ok" || last.steps == 0) return last;
    perStep.push_back(last.totalMs / last.steps);
  }
  last.msPerStep = median(perStep);
  last.msMin = *std::min_element(perStep.begin(), perStep.end());
  return last;
}

double relativeL2(const std::vector<double>& a, const std::vector<double>& ref) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    num += (a[i] - ref[i]) * (a[i] - ref[i]);
    den += ref[i] * ref[i];
  }
  return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

/// Displacements (3 per point) of `mesh` at the nodes of `points` that are also nodes of `mesh`
/// (matched by coordinates): the nodes of the coarsest box mesh lie in every finer one.
std::vector<double> atCommonNodes(const TetMesh& mesh, const std::vector<double>& disp,
                                  const TetMesh& points) {
  std::vector<double> out;
  out.reserve(points.nodes.size());
  for (std::size_t p = 0; p < points.nodeCount(); ++p) {
    const double* q = &points.nodes[3 * p];
    std::size_t found = mesh.nodeCount();
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      const double* m = &mesh.nodes[3 * n];
      if (std::abs(m[0] - q[0]) < 1e-9 && std::abs(m[1] - q[1]) < 1e-9 && std::abs(m[2] - q[2]) < 1e-9) {
        found = n;
        break;
      }
    }
    for (int d = 0; d < 3; ++d) out.push_back(found < mesh.nodeCount() ? disp[3 * found + d] : kNaN);
  }
  return out;
}

/// Surface vertex displacements of the cylinder driven by a run's final state.
std::vector<double> surfaceDisplacement(const RunResult& r, const SurfaceMesh& surface) {
  auto binding = bindSurface(r.mesh, surface);
  if (!binding) return {};
  std::vector<double> x(r.rest.size()), out(surface.vertices.size());
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = r.rest[i] + r.displacement[i];
  SurfaceOutput so;
  so.positionsDouble = out.data();
  if (!deformSurface(*binding, x.data(), r.mesh.nodeCount(), so)) return {};
  for (std::size_t i = 0; i < out.size(); ++i) out[i] -= surface.vertices[i];
  return out;
}


// ---- the knob sets ---------------------------------------------------------------------------

Knobs cholesky() {
  Knobs k;
  k.linearSolver = LinearSolverKind::Cholesky;
  return k;
}

/// The full knob set of one scene at one mesh: every knob varied around a baseline, and the
/// precision x preconditioner x tolerance product on the device backend.
std::vector<Knobs> fullKnobs(bool quick, bool withOpenCL) {
  std::vector<Knobs> out;
  out.push_back(cholesky());
  Knobs lin = cholesky();
  lin.formulation = Formulation::Linear;
  out.push_back(lin);
  const std::vector<PreconditionerKind> preconds = {PreconditionerKind::None, PreconditionerKind::Diagonal,
                                                    PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg};
  const std::vector<PreconditionerKind> quickPreconds = {PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg};
  // "warped_cholesky" runs on the reference backend alone.
  std::vector<PreconditionerKind> refPreconds = quick ? quickPreconds : preconds;
  refPreconds.push_back(PreconditionerKind::WarpedCholesky);
  const std::vector<double> refTols = quick ? std::vector<double>{1e-2, 1e-4, 1e-8}
                                            : std::vector<double>{1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8};
  for (auto pc : refPreconds)
    for (double tol : refTols) {
      Knobs k;
      k.preconditioner = pc;
      k.tolerance = tol;
      out.push_back(k);
    }
  for (auto pc : {PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg, PreconditionerKind::WarpedCholesky})
    for (int cap : (quick ? std::vector<int>{5, 20} : std::vector<int>{5, 10, 20, 50, 100})) {
      Knobs k;
      k.tolerance = 1e-10;  // the cap, not the tolerance, ends these solves
      k.maxIterations = cap;
      k.preconditioner = pc;
      out.push_back(k);
    }
  if (!withOpenCL) return out;
  const std::vector<double> clTols = quick ? std::vector<double>{1e-2, 1e-5} : std::vector<double>{1e-2, 1e-4, 1e-6};
  // Mixed: float vectors and products, PCG dot products and scalars in double.
  for (auto prec : {Precision::Float, Precision::Mixed, Precision::Double})
    for (auto pc : (quick ? quickPreconds : preconds))
      for (double tol : clTols) {
        Knobs k;
        k.backend = BackendKind::OpenCL;
        k.precision = prec;
        k.preconditioner = pc;
        k.tolerance = tol;
        out.push_back(k);
      }
  for (auto rot : {RotationMethod::Svd, RotationMethod::Quaternion, RotationMethod::Qr})
    for (auto prec : {Precision::Float, Precision::Mixed, Precision::Double}) {
      if (quick && prec != Precision::Float) continue;
      Knobs k;
      k.backend = BackendKind::OpenCL;
      k.precision = prec;
      k.rotation = rot;
      k.preconditioner = PreconditionerKind::BlockDiagonal;
      k.tolerance = 1e-4;
      out.push_back(k);
    }
  for (auto pc : {PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg})
    for (int cap : (quick ? std::vector<int>{10} : std::vector<int>{5, 10, 30, 100})) {
      Knobs k;
      k.backend = BackendKind::OpenCL;
      k.precision = Precision::Float;
      k.preconditioner = pc;
      k.tolerance = 1e-10;
      k.maxIterations = cap;
      out.push_back(k);
    }
  for (auto prec : {Precision::Float, Precision::Mixed, Precision::Double}) {
    Knobs k;
    k.backend = BackendKind::OpenCL;
    k.precision = prec;
    k.preconditioner = PreconditionerKind::BlockDiagonal;
    k.tolerance = 1e-4;
    k.formulation = Formulation::Linear;
    out.push_back(k);
  }
  return out;
}

/// The small knob set run at every mesh resolution.
std::vector<Knobs> resolutionKnobs(bool withOpenCL) {
  std::vector<Knobs> out;
  out.push_back(cholesky());
  Knobs lin = cholesky();
  lin.formulation = Formulation::Linear;
  out.push_back(lin);
  Knobs pcg;
  pcg.preconditioner = PreconditionerKind::BlockDiagonal;
  pcg.tolerance = 1e-4;
  out.push_back(pcg);
  Knobs loose = pcg;
  loose.tolerance = 1e-2;
  out.push_back(loose);
  if (withOpenCL) {
    Knobs f = pcg;
    f.backend = BackendKind::OpenCL;
    f.precision = Precision::Float;
    out.push_back(f);
    Knobs fl = f;
    fl.tolerance = 1e-2;
    out.push_back(fl);
    Knobs d = f;
    d.precision = Precision::Double;
    d.tolerance = 1e-6;
    out.push_back(d);
    // Mixed (float products, double dot products and PCG scalars) at the float and the double
    // tolerance, and float at the double one: the three precisions side by side.
    Knobs m = f;
    m.precision = Precision::Mixed;
    out.push_back(m);
    Knobs m6 = m;
    m6.tolerance = 1e-6;
    out.push_back(m6);
    Knobs f6 = f;
    f6.tolerance = 1e-6;
    out.push_back(f6);
  }
  return out;
}

// ---- the sweep -------------------------------------------------------------------------------

struct Reference {
  RunResult run;
  std::vector<double> compare;  ///< what errors are measured on (nodes, common nodes or surface)
};

struct CsvWriter {
  std::ofstream file;
  void header() {
    file << "scene,reference,backend,device,precision,rotation,preconditioner,linear_solver,tolerance,"
            "max_iterations,resolution,mesh,formulation,ms_per_step,ms_per_step_min,steps,disp_error,"
            "energy_error,iterations,newton_iterations,converged_fraction,status\n";
    file.flush();
  }
};

std::size_t tetCount(SceneKind kind, int level) {
  const auto c = cellsOf(kind, level);
  return std::size_t(5) * c[0] * c[1] * c[2];
}

std::string meshLabel(SceneKind kind, int level) {
  const auto c = cellsOf(kind, level);
  return std::to_string(c[0]) + "x" + std::to_string(c[1]) + "x" + std::to_string(c[2]) + "x5";
}

}  // namespace

int runSweep(const Options& options) {
  const bool quick = options.quick;
  const int reps = quick ? 1 : 3;
  const int steps = quick ? 50 : 100;
  const auto start = std::chrono::steady_clock::now();

  // Is the device backend there? (Probe once with the smallest scene.)
  bool withOpenCL = !options.skipOpenCL;
  if (withOpenCL) {
    Knobs k;
    k.backend = BackendKind::OpenCL;
    auto sim = Simulation::create(buildScene({"fig8", SceneKind::Fig8, 1, 1}, k));
    if (!sim) {
      std::fprintf(stderr, "corofem_tradeoff: no OpenCL backend (%s); reference backend only\n",
                   sim.message().c_str());
      withOpenCL = false;
    } else {
      std::fprintf(stderr, "corofem_tradeoff: OpenCL device: %s\n", sim->deviceName().c_str());
    }
  }

  CsvWriter csv;
  csv.file.open(options.out);
  if (!csv.file) {
    std::fprintf(stderr, "corofem_tradeoff: cannot write %s\n", options.out.c_str());
    return 1;
  }
  csv.header();
  const SurfaceMesh surface = cylinderSurface();

  auto emit = [&](const SceneCase& c, const char* refKind, const Knobs& k, const RunResult& r,
                  const Reference& ref, const std::vector<double>& compare) {
    double disp = kNaN, energy = kNaN;
    if (r.status == "ok" && compare.size() == ref.compare.size() && !compare.empty()) {
      disp = relativeL2(compare, ref.compare);
      energy = std::abs(r.energy - ref.run.energy) / std::max(std::abs(ref.run.energy), 1e-300);
    }
    char line[1024];
    std::snprintf(line, sizeof line,
                  "%s,%s,%s,%s,%s,%s,%s,%s,%g,%d,%zu,%s,%s,%.6g,%.6g,%d,%.6g,%.6g,%.4g,%.4g,%.3g,%s\n",
                  c.name.c_str(), refKind, toString(k.backend), clean(r.device).c_str(),
                  k.backend == BackendKind::Reference ? "double" : toString(k.precision),
                  k.backend == BackendKind::Reference ? "polar" : toString(k.rotation),
                  k.linearSolver == LinearSolverKind::Cholesky ? "-" : toString(k.preconditioner),
                  k.linearSolver == LinearSolverKind::Cholesky ? "cholesky" : "pcg",
                  k.linearSolver == LinearSolverKind::Cholesky ? 0.0 : k.tolerance,
                  k.linearSolver == LinearSolverKind::Cholesky ? 0 : k.maxIterations,
                  tetCount(c.kind, c.level), meshLabel(c.kind, c.level).c_str(),
                  toString(k.formulation), r.msPerStep, r.msMin, r.steps, disp, energy, r.pcgPerStep,
                  r.newtonPerStep, r.convergedFraction, r.status.c_str());
    csv.file << line;
    csv.file.flush();
    std::fprintf(stderr, "  %-10s %-9s %-6s %-10s %-14s tol=%-6g cap=%-4d %-12s %-12s %8.3f ms  err=%.3g  %s\n",
                 c.name.c_str(), toString(k.backend), k.backend == BackendKind::Reference ? "double" : toString(k.precision),
                 toString(k.rotation), k.linearSolver == LinearSolverKind::Cholesky ? "cholesky" : toString(k.preconditioner),
                 k.tolerance, k.maxIterations, meshLabel(c.kind, c.level).c_str(), toString(k.formulation),
                 r.msPerStep, disp, r.status.c_str());
  };

  auto want = [&](const std::string& scene) { return options.only.empty() || options.only == scene; };

  // fig8: the full knob set against the same mesh.
  if (want("fig8")) {
    const SceneCase c{"fig8", SceneKind::Fig8, 1, steps};
    Reference ref;
    ref.run = runOnce(buildScene(c, cholesky()));
    ref.compare = ref.run.displacement;
    std::fprintf(stderr, "fig8 reference: %s\n", ref.run.status.c_str());
    for (const Knobs& k : fullKnobs(quick, withOpenCL)) {
      RunResult r = measure(buildScene(c, k), reps);
      emit(c, "same_mesh", k, r, ref, r.displacement);
    }
  }

  // cantilever_dyn: the same beam and load in dynamics (the VR case), full knob set, same mesh.
  if (want("cantilever_dyn")) {
    const SceneCase c{"cantilever_dyn", SceneKind::CantileverDynamic, quick ? 2 : 3, steps};
    Reference ref;
    ref.run = runOnce(buildScene(c, cholesky()));
    ref.compare = ref.run.displacement;
    std::fprintf(stderr, "cantilever_dyn reference: %s\n", ref.run.status.c_str());
    for (const Knobs& k : fullKnobs(quick, withOpenCL)) {
      RunResult r = measure(buildScene(c, k), reps);
      emit(c, "same_mesh", k, r, ref, r.displacement);
    }
  }

  // cantilever: full knob set at level 2 (same mesh), then the resolution rows (finest mesh).
  if (want("cantilever")) {
    const SceneCase c{"cantilever", SceneKind::Cantilever, 2, 0};
    Knobs tight = cholesky();
    Scene refScene = buildScene(c, tight);
    refScene.analysis.statics.residualTolerance = 1e-8;
    refScene.analysis.statics.displacementTolerance = 1e-12;
    Reference ref;
    ref.run = runOnce(refScene);
    ref.compare = ref.run.displacement;
    std::fprintf(stderr, "cantilever reference: %s\n", ref.run.status.c_str());
    for (const Knobs& k : fullKnobs(quick, withOpenCL)) {
      RunResult r = measure(buildScene(c, k), reps);
      emit(c, "same_mesh", k, r, ref, r.displacement);
    }

    const int finest = quick ? 4 : 6;
    const std::vector<int> levels = quick ? std::vector<int>{1, 2, 4} : std::vector<int>{1, 2, 3, 6};
    const SceneCase cf{"cantilever_res", SceneKind::Cantilever, finest, 0};
    Scene fineScene = buildScene(cf, tight);
    fineScene.analysis.statics.residualTolerance = 1e-8;
    fineScene.analysis.statics.displacementTolerance = 1e-12;
    Reference fine;
    fine.run = runOnce(fineScene);
    const TetMesh coarsest = *generateBox(*buildScene({"", SceneKind::Cantilever, 1, 0}, tight).bodies[0].mesh.box);
    fine.compare = atCommonNodes(fine.run.mesh, fine.run.displacement, coarsest);
    std::fprintf(stderr, "cantilever finest reference (%s): %s\n", meshLabel(SceneKind::Cantilever, finest).c_str(),
                 fine.run.status.c_str());
    for (int level : levels)
      for (const Knobs& k : resolutionKnobs(withOpenCL)) {
        const SceneCase cl{"cantilever_res", SceneKind::Cantilever, level, 0};
        RunResult r = measure(buildScene(cl, k), reps);
        emit(cl, "finest_mesh", k, r, fine,
             r.status == "ok" ? atCommonNodes(r.mesh, r.displacement, coarsest) : std::vector<double>{});
      }
  }

  // coupled: the resolution rows, errors on the fine surface against the finest tet mesh.
  if (want("coupled")) {
    const int finest = quick ? 3 : 6;
    const std::vector<int> levels = quick ? std::vector<int>{1, 2, 3} : std::vector<int>{1, 2, 3, 4, 6};
    const SceneCase cf{"coupled", SceneKind::Coupled, finest, steps};
    Reference fine;
    fine.run = runOnce(buildScene(cf, cholesky()));
    fine.compare = surfaceDisplacement(fine.run, surface);
    std::fprintf(stderr, "coupled finest reference (%s, %zu surface vertices): %s\n",
                 meshLabel(SceneKind::Coupled, finest).c_str(), surface.vertexCount(), fine.run.status.c_str());
    for (int level : levels)
      for (const Knobs& k : resolutionKnobs(withOpenCL)) {
        const SceneCase cl{"coupled", SceneKind::Coupled, level, steps};
        RunResult r = measure(buildScene(cl, k), reps);
        emit(cl, "finest_mesh_surface", k, r, fine,
             r.status == "ok" ? surfaceDisplacement(r, surface) : std::vector<double>{});
      }
  }

  // coupled_tol (only when asked for by name: --only coupled_tol): the finest coupled mesh on the
  // OpenCL backend at PCG tolerances 1e-5 to 1e-8 in float, mixed and double, against its own
  // Cholesky solve: where each precision's error floor lies (docs/tradeoff.md, Mixed precision).
  if (options.only == "coupled_tol" && withOpenCL) {
    const int level = quick ? 3 : 6;
    const SceneCase c{"coupled_tol", SceneKind::Coupled, level, steps};
    Reference ref;
    ref.run = runOnce(buildScene(c, cholesky()));
    ref.compare = surfaceDisplacement(ref.run, surface);
    std::fprintf(stderr, "coupled_tol reference (%s): %s\n", meshLabel(SceneKind::Coupled, level).c_str(),
                 ref.run.status.c_str());
    for (double tol : {1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 1e-8})
      for (Precision prec : {Precision::Float, Precision::Mixed, Precision::Double}) {
        Knobs k;
        k.backend = BackendKind::OpenCL;
        k.precision = prec;
        k.preconditioner = PreconditionerKind::BlockDiagonal;
        k.tolerance = tol;
        RunResult r = measure(buildScene(c, k), reps);
        emit(c, "same_mesh_surface", k, r, ref, r.status == "ok" ? surfaceDisplacement(r, surface) : std::vector<double>{});
      }
  }

  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::fprintf(stderr, "corofem_tradeoff: sweep done in %.1f s, wrote %s\n", seconds, options.out.c_str());
  return 0;
}

}  // namespace corofem::tradeoff
