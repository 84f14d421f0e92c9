// The accuracy of the formulation itself, as the paper's Fig. 5: static load-displacement curves of
// a real part for the linear, co-rotational and rigorous nonlinear (St. Venant-Kirchhoff,
// Neo-Hookean) formulations, all on the reference backend with the LDL^T (Cholesky) solver.
//
// Part: sfepy/elbow2.mesh, a solid rod of radius 0.03 m bent into a U (bend radius 0.1 m, 1823 nodes,
// 8161 tets), both ends on the plane y = 0, centred at x = 0 and x = 0.2. The x = 0 end face is
// clamped; a total force P (1, 0, 1)/sqrt(2) is spread over the nodes of the x = 0.2 end face: it
// opens the U in its plane and bends it out of plane. Material: E = 10 MPa, nu = 0.3 (rubber-like;
// with E I = E pi r^4 / 4 = 6.4 N m^2 and a lever of ~0.2 m, P = 300 N is far into large rotations).
// The "load point" is the mean displacement of the loaded face's nodes.
//
// Each formulation is a static analysis with K equal load increments (Newton to a relative residual
// of 1e-8 per increment); after every increment the load point's displacement is written.
#include "tradeoff.hpp"

#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

namespace corofem::tradeoff {
namespace {

NodeSetDesc endFace(double xCentre) {
  NodeSetDesc s;
  s.kind = NodeSetDesc::Kind::Box;
  s.boxMin = {xCentre - 0.05, -1e-6, -0.05};
  s.boxMax = {xCentre + 0.05, 1e-6, 0.05};
  return s;
}

Scene elbowScene(const std::string& meshPath, Formulation f, double forceMax, int increments) {
  BodyDesc body;
  body.name = "elbow";
  body.mesh.file = meshPath;
  body.material.youngsModulus = 1e7;
  body.material.poissonRatio = 0.3;
  body.material.density = 1000;
  body.formulation = f;
  body.fixed.push_back(endFace(0.0));
  LoadDesc load;
  load.kind = LoadDesc::Kind::Force;
  const double c = forceMax / std::sqrt(2.0);
  load.vector = {c, 0.0, c};
  load.nodes = endFace(0.2);
  body.loads.push_back(load);
  Scene scene;
  scene.name = "fig5_elbow";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Static;
  scene.analysis.statics.increments = increments;
  scene.analysis.statics.maxNewtonIterations = 50;
  scene.analysis.statics.residualTolerance = 1e-8;
  scene.analysis.statics.displacementTolerance = 1e-10;
  scene.solver.linearSolver = LinearSolverKind::Cholesky;
  scene.backend.kind = BackendKind::Reference;
  scene.output.vtk = false;
  return scene;
}

const char* label(Formulation f) {
  switch (f) {
    case Formulation::Linear: return "linear";
    case Formulation::Corotational: return "corotational";
    case Formulation::StVenantKirchhoff: return "stvk";
    case Formulation::NeoHookean: return "neohookean";
  }
  return "?";
}

}  // namespace

int runFig5(const Options& options) {
  const std::string meshPath = options.dataDir + "/meshes/sfepy/elbow2.mesh";
  const double forceMax = options.forceMax > 0 ? options.forceMax : 300.0;
  const int increments = options.increments > 0 ? options.increments : (options.quick ? 10 : 30);
  std::ofstream csv(options.out);
  if (!csv) {
    std::fprintf(stderr, "corofem_tradeoff: cannot write %s\n", options.out.c_str());
    return 1;
  }
  csv << "formulation,increment,load_factor,force_N,ux,uy,uz,u_norm,newton_iterations,wall_s,status\n";
  int failures = 0;
  for (Formulation f : {Formulation::Linear, Formulation::Corotational, Formulation::StVenantKirchhoff,
                        Formulation::NeoHookean}) {
    auto sim = Simulation::create(elbowScene(meshPath, f, forceMax, increments));
    if (!sim) {
      std::fprintf(stderr, "fig5 %s: %s\n", label(f), sim.message().c_str());
      return 1;
    }
    auto loaded = resolveNodeSet(sim->scene().bodies[0].loads[0].nodes, sim->restMesh(0));
    if (!loaded) {
      std::fprintf(stderr, "fig5: %s\n", loaded.message().c_str());
      return 1;
    }
    const std::vector<double>& rest = sim->restMesh(0).nodes;
    double total = 0;
    int newtonTotal = 0;
    std::vector<double> x;
    csv << label(f) << ",0,0,0,0,0,0,0,0,0,ok\n";
    while (!sim->finished()) {
      StepReport rep;
      const Status st = sim->step(&rep);
      if (!st) {
        std::fprintf(stderr, "fig5 %s: increment %d failed: %s\n", label(f), sim->stepsTaken() + 1,
                     st.message().c_str());
        ++failures;
        break;
      }
      total += rep.wallSeconds;
      newtonTotal += rep.newtonIterations;
      sim->readPositions(0, x);
      double u[3] = {0, 0, 0};
      for (std::uint32_t n : *loaded)
        for (int d = 0; d < 3; ++d) u[d] += (x[3 * n + d] - rest[3 * n + d]) / double(loaded->size());
      char line[512];
      std::snprintf(line, sizeof line, "%s,%d,%.6g,%.6g,%.9g,%.9g,%.9g,%.9g,%d,%.4g,ok\n", label(f), rep.step,
                    sim->time(), sim->time() * forceMax, u[0], u[1], u[2],
                    std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]), rep.newtonIterations, rep.wallSeconds);
      csv << line;
      csv.flush();
    }
    std::fprintf(stderr, "fig5 %-12s %d increments, %d Newton iterations, %.2f s (%zu loaded nodes)\n", label(f),
                 sim->stepsTaken(), newtonTotal, total, loaded->size());
  }
  return failures ? 3 : 0;
}

}  // namespace corofem::tradeoff
