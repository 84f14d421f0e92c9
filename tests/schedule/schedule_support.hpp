// Helpers of the scheduler tests: small box scenes, a scope with a fresh calibration cache, fake
// backends (common/device_fakes.hpp), runs to the end.
#pragma once

#include "common/device_fakes.hpp"
#include "schedule/scheduler.hpp"

#include "common/test_data.hpp"

#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

namespace corofem::test {

/// A 1 x 0.1 x 0.1 m cantilever (box mesh, 5 tets per cell) clamped at x = 0 under gravity and a
/// tip force. cells = {20, 2, 2} gives 400 elements.
inline BodyDesc boxBeam(std::array<int, 3> cells = {20, 2, 2}) {
  BodyDesc body;
  body.name = "beam";
  BoxSpec box;
  box.max = {1.0, 0.1, 0.1};
  box.cells = cells;
  body.mesh.box = box;
  body.material.youngsModulus = 1e6;
  body.material.poissonRatio = 0.3;
  body.material.density = 1000;
  NodeSetDesc clamp;
  clamp.kind = NodeSetDesc::Kind::Plane;
  clamp.planePoint = {0, 0, 0};
  clamp.planeNormal = {1, 0, 0};
  clamp.planeTolerance = 1e-6;
  body.fixed.push_back(clamp);
  LoadDesc g;
  g.kind = LoadDesc::Kind::Gravity;
  g.vector = {0, -9.81, 0};
  body.loads.push_back(g);
  LoadDesc tip;
  tip.kind = LoadDesc::Kind::Force;
  tip.vector = {0, 0, -2.0};
  tip.nodes = clamp;
  tip.nodes.planePoint = {1, 0, 0};
  body.loads.push_back(tip);
  return body;
}

inline Scene dynamicScene(const BodyDesc& body, int steps = 8) {
  Scene s;
  s.name = "dyn";
  s.bodies.push_back(body);
  s.analysis.kind = AnalysisDesc::Kind::Dynamic;
  s.analysis.dynamics.timeStep = 0.01;
  s.analysis.dynamics.steps = steps;
  s.analysis.dynamics.newtonIterations = 2;
  s.solver.tolerance = 1e-10;
  return s;
}

inline Scene staticScene(const BodyDesc& body, int increments = 3) {
  Scene s;
  s.name = "stat";
  s.bodies.push_back(body);
  s.analysis.kind = AnalysisDesc::Kind::Static;
  s.analysis.statics.increments = increments;
  s.solver.tolerance = 1e-10;
  return s;
}

/// Points the calibration cache at a fresh folder for the scope of a test (and unsets
/// COROFEM_DEVICE); registers the fake backends given, if any, for the same scope.
class HookScope {
 public:
  explicit HookScope(std::vector<detail::BackendEntry> backends = {}) {
    cacheDir_ = tempDir().string();
    setenv("COROFEM_CACHE_DIR", cacheDir_.c_str(), 1);
    unsetenv("COROFEM_DEVICE");
    // With fakes, they and the reference backend are the only ones (a real Vulkan or OpenCL backend
    // not replaced would add its candidates to the fakes').
    if (!backends.empty())
      for (const detail::BackendEntry& e : detail::registeredBackends()) {
        const bool replaced = std::any_of(backends.begin(), backends.end(),
                                          [&](const detail::BackendEntry& f) { return f.name == e.name; });
        if (!replaced && e.name != "reference") hidden_.push_back(std::make_unique<ScopedBackend>(e.name));
      }
    for (detail::BackendEntry& e : backends) registered_.push_back(std::make_unique<ScopedBackend>(std::move(e)));
  }
  ~HookScope() {
    registered_.clear();
    hidden_.clear();
    unsetenv("COROFEM_CACHE_DIR");
    unsetenv("COROFEM_DEVICE");
  }
  const std::string& cacheDir() const { return cacheDir_; }

 private:
  std::string cacheDir_;
  std::vector<std::unique_ptr<ScopedBackend>> registered_, hidden_;
};

/// Runs a simulation to its end; returns the final positions of body 0 (empty on failure).
inline std::vector<double> runToEnd(Simulation& sim) {
  while (!sim.finished()) {
    Status st = sim.step();
    EXPECT_TRUE(st) << st.message();
    if (!st) return {};
  }
  std::vector<double> x;
  EXPECT_TRUE(sim.readPositions(0, x));
  return x;
}

inline detail::Candidate referenceCandidate() { return detail::referenceCandidate(); }

}  // namespace corofem::test
