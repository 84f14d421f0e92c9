// The smallest application of the installed package: a box cantilever under gravity, ten steps,
// its tip's sag printed. Exit 0 only when every call succeeded and the tip went down.
#include <corofem/corofem.hpp>

#include <cstdio>
#include <vector>

int main() {
  corofem::Scene scene;
  corofem::BodyDesc body;
  corofem::BoxSpec box;
  box.max = {1.0, 0.1, 0.1};
  box.cells = {10, 1, 1};
  body.mesh.box = box;
  body.material.youngsModulus = 1e6;
  corofem::NodeSetDesc clamp;
  clamp.kind = corofem::NodeSetDesc::Kind::Plane;
  clamp.planeNormal = {1, 0, 0};
  body.fixed.push_back(clamp);
  corofem::LoadDesc gravity;  // -9.81 m/s^2 in y by default
  body.loads.push_back(gravity);
  scene.bodies.push_back(body);
  scene.analysis.kind = corofem::AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.steps = 10;
  scene.backend.kind = corofem::BackendKind::Reference;

  corofem::Result<corofem::Simulation> sim = corofem::Simulation::create(scene);
  if (!sim) {
    std::fprintf(stderr, "create: %s\n", sim.message().c_str());
    return 1;
  }
  while (!sim->finished())
    if (corofem::Status s = sim->step(); !s) {
      std::fprintf(stderr, "step: %s\n", s.message().c_str());
      return 1;
    }
  std::vector<double> x;
  if (corofem::Status s = sim->readPositions(0, x); !s) {
    std::fprintf(stderr, "read: %s\n", s.message().c_str());
    return 1;
  }
  const std::vector<double>& rest = sim->restMesh(0).nodes;
  double sag = 0;
  for (std::size_t i = 1; i < x.size(); i += 3) sag = std::min(sag, x[i] - rest[i]);
  std::printf("corofem %s: tip sag after 10 steps %.3g m\n", "consumer", sag);
  return sag < 0 ? 0 : 1;
}
