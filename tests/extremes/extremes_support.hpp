// Helpers of the numerical-extremes suite: the backends every test runs on (reference double;
// OpenCL double and float on every device found), scenes on small generated boxes, and a "direct"
// body (Problem + device + driver without a Simulation) for the cases the Scene API cannot
// express (a body released from an inverted or squashed shape).
#pragma once

#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include "model/problem.hpp"
#include "common/body_drivers.hpp"
#include "device/registry.hpp"
#include "util/error.hpp"

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#endif

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <array>
#include <cctype>
#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace corofem::test {

/// One backend / device / precision the suite runs on.
struct BackendCase {
  std::string name;  ///< test-name suffix
  BackendKind kind = BackendKind::Reference;
  Precision precision = Precision::Double;
  std::string device;  ///< the device's selector (OpenCL: its index in cl::listDevices(); Vulkan: the candidate's)
  std::string absent;  ///< non-empty: why this case cannot run here (the test skips with it)
  /// Vulkan: the dynamics' vectors in the device's memory (VulkanTuning::deviceStore = 1; the
  /// default keeps them on the host).
  bool deviceStore = false;

  bool isFloat() const { return isDevice() && precision == Precision::Float; }
  /// A device backend (OpenCL, Vulkan): its rotation methods are its own (the reference's is SVD polar).
  bool isDevice() const { return kind != BackendKind::Reference; }
  std::string describe() const {
    return kind == BackendKind::Reference
               ? "reference (double)"
               : std::string(toString(kind)) + " device " + device + (isFloat() ? " (float)" : " (double)") +
                     (deviceStore ? ", device store" : "");
  }
  /// The options a Simulation of this case is made with.
  SimulationOptions options() const {
    SimulationOptions o;
    if (deviceStore) o.vulkan.deviceStore = 1;
    return o;
  }
};

/// How GoogleTest (and so CTest's test list) prints a case: what it runs on, not its bytes.
inline void PrintTo(const BackendCase& c, std::ostream* os) { *os << c.describe(); }

/// "<backend>_dev<selector>_<the device's name, 20 characters as an identifier>": a case name's stem.
inline std::string caseBase(const std::string& backend, const std::string& selector, const std::string& device) {
  std::string clean;
  for (char c : device.substr(0, 20)) clean += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return backend + "_dev" + selector + "_" + clean;
}

/// Reference, then OpenCL and Vulkan, double and float, on every device. A case that cannot run
/// (library built without OpenCL, no device, no fp64) stays in the list with the reason, so that the
/// skip shows.
inline std::vector<BackendCase> backendCases() {
  std::vector<BackendCase> out;
  out.push_back({"reference", BackendKind::Reference, Precision::Double, "", ""});
#ifdef COROFEM_WITH_OPENCL
  const auto devices = detail::cl::listDevices();
  for (std::size_t i = 0; i < devices.size(); ++i) {
    const std::string base = caseBase("opencl", std::to_string(i), devices[i].name);
    out.push_back({base + "_double", BackendKind::OpenCL, Precision::Double, std::to_string(i),
                   devices[i].fp64 ? "" : "device '" + devices[i].name + "' has no fp64 (cl_khr_fp64)"});
    out.push_back({base + "_float", BackendKind::OpenCL, Precision::Float, std::to_string(i), ""});
  }
  if (devices.empty())
    out.push_back({"opencl_no_device", BackendKind::OpenCL, Precision::Double, "",
                   "no OpenCL device found on any platform (install a GPU driver or pocl-opencl-icd)"});
#else
  out.push_back({"opencl_not_built", BackendKind::OpenCL, Precision::Double, "",
                 "the library was built without the OpenCL backend (configure with -DCOROFEM_WITH_OPENCL=ON)"});
#endif
  std::vector<detail::Candidate> vulkan;
  if (const auto entry = detail::findBackend("vulkan")) vulkan = entry->candidates();
  for (const detail::Candidate& d : vulkan) {
    const std::string base = caseBase("vulkan", d.selector, d.device);
    out.push_back({base + "_double", BackendKind::Vulkan, Precision::Double, d.selector, ""});
    out.push_back({base + "_float", BackendKind::Vulkan, Precision::Float, d.selector, ""});
  }
  if (vulkan.empty())
    out.push_back({"vulkan_no_device", BackendKind::Vulkan, Precision::Double, "",
                   "no Vulkan device here (a build without the Vulkan backend, or no driver: install "
                   "mesa-vulkan-drivers for the lavapipe CPU device)"});
  return out;
}

/// backendCases(), and each Vulkan case again with the device store (BackendCase::deviceStore).
inline std::vector<BackendCase> backendCasesWithDeviceStores() {
  std::vector<BackendCase> out = backendCases();
  const std::size_t n = out.size();
  for (std::size_t i = 0; i < n; ++i)
    if (out[i].kind == BackendKind::Vulkan && out[i].absent.empty()) {
      BackendCase c = out[i];
      c.name += "_store";
      c.deviceStore = true;
      out.push_back(c);
    }
  return out;
}

/// Only the cases that actually run a device-independent double computation are needed by some
/// tests; this keeps the reference case plus the OpenCL ones, exactly as backendCases().
inline std::string caseName(const testing::TestParamInfo<BackendCase>& info) { return info.param.name; }

#define COROFEM_SKIP_ABSENT(c)                                         \
  do {                                                                 \
    if (!(c).absent.empty()) GTEST_SKIP() << (c).absent;               \
  } while (0)

/// A box mesh source (m).
inline MeshSourceDesc box(const Vec3& lo, const Vec3& hi, const std::array<int, 3>& cells, int tetsPerCell = 5) {
  MeshSourceDesc m;
  BoxSpec b;
  b.min = lo;
  b.max = hi;
  b.cells = cells;
  b.tetsPerCell = tetsPerCell;
  m.box = b;
  return m;
}

inline NodeSetDesc planeSet(int axis, double value, double tolerance = 1e-9) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::Plane;
  set.planePoint = {0, 0, 0};
  set.planePoint[static_cast<std::size_t>(axis)] = value;
  set.planeNormal = {0, 0, 0};
  set.planeNormal[static_cast<std::size_t>(axis)] = 1;
  set.planeTolerance = tolerance;
  return set;
}

/// A body with the given mesh and material (co-rotational).
inline BodyDesc makeBody(const MeshSourceDesc& mesh, double E, double nu, double density = 1000.0) {
  BodyDesc body;
  body.name = "body";
  body.mesh = mesh;
  body.material.youngsModulus = E;
  body.material.poissonRatio = nu;
  body.material.density = density;
  return body;
}

/// A dynamic scene of one body on the given backend case.
inline Scene dynamicScene(const BackendCase& c, const BodyDesc& body, double h, int steps) {
  Scene scene;
  scene.name = "extremes";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.timeStep = h;
  scene.analysis.dynamics.steps = steps;
  scene.backend.kind = c.kind;
  scene.backend.device = c.device;
  scene.solver.precision = c.precision;
  // Float PCG cannot reach 1e-6 relative on every system; 1e-5 is about 100 float ulps.
  scene.solver.tolerance = c.isFloat() ? 1e-5 : 1e-8;
  scene.solver.maxIterations = 2000;
  return scene;
}

inline Scene staticScene(const BackendCase& c, const BodyDesc& body, int increments) {
  Scene scene = dynamicScene(c, body, 1.0, 1);
  scene.analysis.kind = AnalysisDesc::Kind::Static;
  scene.analysis.statics.increments = increments;
  // Float: the OpenCL backend stores positions in float (relative to the body's centroid since
  // commit 1ee3d8c), so x is quantised to the ulp of the body's size (~1.5e-8 m at 0.2 m) and
  // f_int carries a noise of E ulp / element size per element corner, which does not shrink as
  // Newton converges. Measured on the 0.4 m cantilever under
  // gravity (E = 1e6 Pa): the relative residual stalls at ~1e-3 and the corrections at ~1e-7 m
  // (|dx| / |u| ~ 1e-5). The defaults (1e-6, 1e-8) are unreachable there; these are not.
  if (c.isFloat()) {
    scene.analysis.statics.residualTolerance = 1e-2;
    scene.analysis.statics.displacementTolerance = 1e-4;
  }
  return scene;
}

/// Creates the simulation; on a missing backend/device records a skip reason in *skip.
inline std::unique_ptr<Simulation> createSim(const Scene& scene, std::string* skip) {
  Result<Simulation> sim = Simulation::create(scene);
  if (!sim) {
    if (sim.status().code() == ErrorCode::NotCompiledIn || sim.status().code() == ErrorCode::DeviceError) {
      *skip = sim.message();
      return nullptr;
    }
    ADD_FAILURE() << "Simulation::create failed: " << sim.message();
    return nullptr;
  }
  static std::string lastPrinted;  // one line per backend/device change, not per simulation
  const std::string where = sim->backendName() + " on " + sim->deviceName();
  if (where != lastPrinted) std::cout << "  [" << where << "]\n";
  lastPrinted = where;
  return std::make_unique<Simulation>(std::move(sim.value()));
}

#define COROFEM_CREATE_SIM(var, scene)                      \
  std::string var##Skip;                                    \
  auto var = createSim((scene), &var##Skip);                \
  if (!var) {                                               \
    if (!var##Skip.empty()) GTEST_SKIP() << var##Skip;      \
    return;                                                 \
  }

/// Problem + device + driver of body 0 of a scene, built as Simulation::create does, for tests
/// that need the driver's setInitialState.
struct DirectBody {
  TetMesh mesh;
  std::unique_ptr<detail::Problem> problem;
  std::unique_ptr<BodyDriver> solver;
};

/// Builds it; returns false with *skip set when the backend/device is missing.
inline bool makeDirectBody(const Scene& scene, DirectBody& out, std::string* skip) {
  try {
    Result<TetMesh> mesh = loadBodyMesh(scene.bodies[0], scene.baseDir);
    if (!mesh) throw detail::Error(mesh.status().code(), mesh.message());
    out.mesh = mesh.value();
    out.problem = std::make_unique<detail::Problem>(
        detail::buildProblem(scene.bodies[0], out.mesh, scene.solver, scene.baseDir));
    const auto entry = detail::findBackend(toString(scene.backend.kind));
    if (!entry) detail::fail(ErrorCode::NotCompiledIn, "no backend '", toString(scene.backend.kind), "'");
    const detail::Candidate c = entry->resolve(scene.backend.device);
    out.solver = std::make_unique<BodyDriver>(entry->create({out.problem.get()}, scene.solver, c, {}), scene.analysis,
                                              scene.solver);
    return true;
  } catch (const detail::Error& e) {
    if (e.code() == ErrorCode::NotCompiledIn || e.code() == ErrorCode::DeviceError) {
      *skip = e.what();
      return false;
    }
    ADD_FAILURE() << "building the body failed: " << e.what();
    return false;
  }
}

#define COROFEM_DIRECT_BODY(var, scene)                      \
  DirectBody var;                                            \
  {                                                          \
    std::string skip_;                                       \
    if (!makeDirectBody((scene), var, &skip_)) {             \
      if (!skip_.empty()) GTEST_SKIP() << skip_;             \
      return;                                                \
    }                                                        \
  }

/// Largest |entry| (inf when any is not finite).
inline double maxAbs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) {
    if (!std::isfinite(x)) return INFINITY;
    m = std::max(m, std::abs(x));
  }
  return m;
}

inline bool allFinite(const std::vector<double>& v) {
  for (double x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

/// Displacements x - X of body 0 (3N).
inline std::vector<double> displacements(const Simulation& sim) {
  std::vector<double> x;
  EXPECT_TRUE(sim.readPositions(0, x));
  const std::vector<double>& X = sim.restMesh(0).nodes;
  for (std::size_t i = 0; i < x.size() && i < X.size(); ++i) x[i] -= X[i];
  return x;
}

/// Smallest signed element volume over rest volume for the positions x (3N) of mesh.
inline double minVolumeRatio(const TetMesh& rest, const Eigen::VectorXd& x) {
  TetMesh deformed = rest;
  deformed.nodes.assign(x.data(), x.data() + x.size());
  double worst = INFINITY;
  for (std::size_t e = 0; e < rest.tetCount(); ++e)
    worst = std::min(worst, signedVolume(deformed, e) / signedVolume(rest, e));
  return worst;
}

}  // namespace corofem::test
