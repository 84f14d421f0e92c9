// The soak of issue 25: an application drags a body by a handle with random, abrupt motions at a
// VR frame rate, lets go and grabs again, for a long simulated time, and every step must succeed
// with finite positions. Two bodies: SOFA's liver (596 tets, held by a box of nodes at one end, the
// handle at the other) and the paper's Fig. 8 beam (40 tets, clamped at x = 0, the handle at the
// tip). Used by tests/control/test_soak.cpp (a short run in CI) and bench/bench_soak.cpp (the full
// hour, and the integrators compared).
#pragma once

#include <corofem/simulation.hpp>

#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace corofem::test {

/// The liver's mesh file, relative to the project root (tests and benchmarks run there).
inline const char* soakLiverMesh() { return "../shared/data/meshes/sofa/liver.msh"; }

/// A soak scene: "liver" or "beam", open-ended, the library's default integrator unless the
/// caller sets one, 1 Newton iteration (the default), on the reference backend unless changed.
inline Scene soakScene(const std::string& which) {
  Scene scene;
  scene.name = "soak_" + which;
  BodyDesc body;
  body.name = which;
  LoadDesc gravity;
  gravity.kind = LoadDesc::Kind::Gravity;
  gravity.vector = {0.0, -9.81, 0.0};
  body.loads.push_back(gravity);
  NodeSetDesc clamp;
  if (which == "liver") {
    body.mesh.file = soakLiverMesh();
    body.material.youngsModulus = 3000;
    body.material.poissonRatio = 0.45;
    body.material.density = 1;
    body.material.rayleighMass = 1.0;
    clamp.boxMin = {1.2, 0, -2};
    clamp.boxMax = {2, 6, 3};
  } else {
    BoxSpec box;
    box.min = {0, 0, 0};
    box.max = {0.8, 0.1, 0.1};
    box.cells = {8, 1, 1};
    box.tetsPerCell = 5;
    body.mesh.box = box;
    body.material.youngsModulus = 5e5;
    body.material.poissonRatio = 0.3;
    body.material.density = 1000;
    body.material.rayleighMass = 2.0;
    clamp.boxMin = {-1e-9, -1, -1};
    clamp.boxMax = {1e-9, 1, 1};
  }
  body.fixed.push_back(clamp);
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.steps = 0;  // open-ended
  scene.backend.kind = BackendKind::Reference;
  return scene;
}

struct SoakResult {
  long long steps = 0;
  long long failed = 0;       ///< steps whose status was not ok
  long long nonFinite = 0;    ///< reads with a non-finite position
  double largestMove = 0.0;   ///< largest distance of a node from its rest position (m)
  double largestSpringMove = 0.0;  ///< the same while a spring handle held the body
  std::string firstFailure;   ///< the first failed step's message
};

/// Drags `sim`'s body 0 for `seconds` of simulated time at `hz`: the handle grabs the nodes within
/// `grab` of `grabPoint`; every 0.2 to 0.8 s its target jumps to a random point within `reach` of
/// where it was grabbed (a hard handle's nodes follow within one frame: an abrupt drag), and every
/// 10 s it lets go for 1 s and grabs again, as a hard handle and as a spring of `spring` N/m in
/// turns (`spring` 0: hard every time).
inline SoakResult soak(Simulation& sim, double seconds, double hz, const double grabPoint[3], double grab,
                       double reach, unsigned seed, double spring = 0.0) {
  SoakResult r;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0), hold(0.2, 0.8);
  HandleDesc desc;
  for (int k = 0; k < 3; ++k) desc.point[k] = grabPoint[k];
  desc.radius = grab;
  const std::vector<double>& rest = sim.restMesh(0).nodes;
  int handle = 0;
  long long grabs = 0;
  double nextJump = 0.0, target[3] = {grabPoint[0], grabPoint[1], grabPoint[2]};
  const long long frames = static_cast<long long>(std::llround(seconds * hz));
  std::vector<double> x;
  for (long long f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f) / hz;
    const double cycle = std::fmod(t, 10.0);
    if (cycle >= 9.0 && handle != 0) {  // let go
      sim.removeHandle(handle);
      handle = 0;
    } else if (cycle < 9.0 && handle == 0) {  // grab again where the point is now
      desc.stiffness = grabs++ % 2 == 1 ? spring : 0.0;
      Result<int> h = sim.addHandle(desc);
      if (h) handle = h.value();
      nextJump = t;
    }
    if (handle != 0 && t >= nextJump) {
      double d[3];
      do {
        for (double& c : d) c = unit(rng);
      } while (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > 1.0);
      for (int k = 0; k < 3; ++k) target[k] = grabPoint[k] + reach * d[k];
      sim.moveHandle(handle, target);
      nextJump = t + hold(rng);
    }
    const Status st = sim.step(1.0 / hz);
    ++r.steps;
    if (!st) {
      if (r.failed++ == 0) r.firstFailure = "t = " + std::to_string(t) + " s: " + st.message();
    }
    if (f % 30 == 0 || f + 1 == frames) {
      sim.readPositions(0, x);
      for (std::size_t i = 0; i + 2 < x.size(); i += 3) {
        if (!std::isfinite(x[i]) || !std::isfinite(x[i + 1]) || !std::isfinite(x[i + 2])) {
          ++r.nonFinite;
          break;
        }
        const double move = std::hypot(x[i] - rest[i], x[i + 1] - rest[i + 1], x[i + 2] - rest[i + 2]);
        r.largestMove = std::max(r.largestMove, move);
        if (handle != 0 && desc.stiffness > 0.0) r.largestSpringMove = std::max(r.largestSpringMove, move);
      }
    }
  }
  return r;
}

/// The grab point, radius, reach and spring handle's stiffness of each soak body (the spring: about
/// ten times the force that bends the body's free end by its reach, so that it drags it as firmly
/// as a hand, with a visible lag).
struct SoakGrip {
  double point[3];
  double grab, reach, spring;
};
inline SoakGrip soakGrip(const std::string& which) {
  if (which == "liver") return SoakGrip{{-4.2, 2.5, 0.5}, 0.6, 1.5, 2000.0};
  return SoakGrip{{0.8, 0.05, 0.05}, 0.02, 0.3, 500.0};
}

}  // namespace corofem::test
