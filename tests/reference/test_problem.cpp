// Problem building (node sets -> constraints and loads, masses, initial velocity, errors) and the
// load / prescribed-displacement scaling of statics and dynamics.
#include "small_meshes.hpp"

#include "model/problem.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

using namespace corofem;
using namespace corofem::detail;

namespace {

NodeSetDesc boxSet(Vec3 lo, Vec3 hi) {
  NodeSetDesc s;
  s.kind = NodeSetDesc::Kind::Box;
  s.boxMin = lo;
  s.boxMax = hi;
  return s;
}

BodyDesc beamBody() {
  BodyDesc body;
  body.name = "beam";
  body.material.youngsModulus = 1e6;
  body.material.poissonRatio = 0.3;
  body.material.density = 500.0;
  body.fixed.push_back(boxSet({-1, -1, -1}, {0, 2, 2}));  // the x = 0 face
  return body;
}

std::string buildError(const BodyDesc& body, const TetMesh& mesh) {
  try {
    buildProblem(body, mesh, SolverDesc{}, "");
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::BadInput);
    return e.what();
  }
  ADD_FAILURE() << "buildProblem accepted a bad body";
  return {};
}

}  // namespace

TEST(BuildProblem, MassGravityForceDisplacementAndConstraints) {
  const TetMesh mesh = test::boxMesh(4, 1, 1, 2.0, 0.5, 0.5, 0.0);
  BodyDesc body = beamBody();
  LoadDesc gravity;
  gravity.kind = LoadDesc::Kind::Gravity;
  gravity.vector = {0, -9.81, 0};
  LoadDesc force;
  force.kind = LoadDesc::Kind::Force;
  force.vector = {0, 0, -40.0};
  force.nodes = boxSet({2, -1, -1}, {3, 2, 2});  // the x = 2 face: 4 nodes
  force.rampTime = 0.5;
  LoadDesc drag;
  drag.kind = LoadDesc::Kind::Displacement;
  drag.vector = {0.1, 0.0, -0.2};
  drag.nodes = boxSet({0.9, -1, -1}, {1.1, 2, 2});  // the x = 1 cross-section: 4 nodes
  drag.rampTime = 2.0;
  body.loads = {gravity, force, drag};
  body.formulation = Formulation::NeoHookean;
  SolverDesc solver;
  solver.rotation = RotationMethod::Qr;

  const Problem p = buildProblem(body, mesh, solver, "");
  EXPECT_EQ(p.name, "beam");
  EXPECT_EQ(p.formulation, Formulation::NeoHookean);
  EXPECT_EQ(p.rotation, RotationMethod::Qr);
  EXPECT_EQ(p.elements.size(), mesh.tetCount());
  EXPECT_EQ(p.dofCount(), 3 * mesh.nodeCount());
  const double volume = 2.0 * 0.5 * 0.5, mass = 500.0 * volume;
  // Sums of many O(1) terms: 1e-12 relative.
  EXPECT_NEAR(p.lumpedMass.sum(), 3 * mass, 1e-12 * mass);
  const Lame expected = lameFromYoungPoisson(1e6, 0.3);
  EXPECT_DOUBLE_EQ(p.lame.mu, expected.mu);
  EXPECT_DOUBLE_EQ(p.lame.lambda, expected.lambda);

  ASSERT_EQ(p.forces.size(), 2u);
  // Gravity: consistent nodal forces sum to rho g V, and node by node equal lumped mass times g.
  Vec3d g = Vec3d::Zero();
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) g += p.forces[0].f.segment<3>(3 * n);
  EXPECT_LT((g - Vec3d(0, -9.81 * mass, 0)).norm(), 1e-12 * mass * 9.81);
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    EXPECT_NEAR(p.forces[0].f[3 * n + 1], -9.81 * p.lumpedMass[3 * n + 1], 1e-12 * mass);
  // The force load: -40 N spread over the 4 nodes of the end face.
  int loaded = 0;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
    if (p.forces[1].f[3 * n + 2] != 0.0) {
      ++loaded;
      EXPECT_DOUBLE_EQ(p.forces[1].f[3 * n + 2], -10.0);
      EXPECT_DOUBLE_EQ(mesh.nodes[3 * n], 2.0);
    }
  EXPECT_EQ(loaded, 4);
  EXPECT_EQ(p.forces[1].rampTime, 0.5);

  // Fixed x = 0 face and dragged x = 1 section are constrained; nothing else.
  ASSERT_EQ(p.prescribed.size(), 1u);
  EXPECT_EQ(p.prescribed[0].dofs.size(), 12u);
  EXPECT_EQ(p.prescribed[0].rampTime, 2.0);
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
    const double x = mesh.nodes[3 * n];
    const bool held = x == 0.0 || x == 1.0;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(p.constrained[3 * n + c], held ? 1 : 0) << "node " << n;
  }
  for (std::size_t k = 0; k < p.prescribed[0].dofs.size(); ++k)
    EXPECT_EQ(p.prescribed[0].values[k], drag.vector[p.prescribed[0].dofs[k] % 3]);
}

TEST(BuildProblem, InitialVelocityLinearPlusAngularAboutCentroid) {
  const TetMesh mesh = test::boxMesh(2, 2, 2, 1.0, 2.0, 3.0, 0.2, 3);
  BodyDesc body = beamBody();
  body.fixed.clear();
  body.initialVelocity = {1.0, 0.0, -2.0};
  body.initialAngularVelocity = {0.0, 0.5, 1.0};
  const Problem p = buildProblem(body, mesh, SolverDesc{}, "");
  // Momentum sum m_i v_i = M v0 (the angular part has zero momentum about the mass centroid),
  // and v_i - v0 is perpendicular to omega. Rounding of O(1) sums: 1e-12 relative.
  Vec3d momentum = Vec3d::Zero();
  double mass = 0;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
    momentum += p.lumpedMass[3 * n] * p.initialVelocity.segment<3>(3 * n);
    mass += p.lumpedMass[3 * n];
    const Vec3d w = p.initialVelocity.segment<3>(3 * n) - Vec3d(1.0, 0.0, -2.0);
    EXPECT_NEAR(w.dot(Vec3d(0.0, 0.5, 1.0)), 0.0, 1e-12);
  }
  EXPECT_LT((momentum - mass * Vec3d(1.0, 0.0, -2.0)).norm(), 1e-12 * mass);
  // Node 0 at the origin; the (unperturbed-boundary) box's centroid is (0.5, 1, 1.5).
  const Vec3d expected = Vec3d(1.0, 0.0, -2.0) + Vec3d(0.0, 0.5, 1.0).cross(Vec3d(0, 0, 0) - Vec3d(0.5, 1.0, 1.5));
  EXPECT_LT((p.initialVelocity.segment<3>(0) - expected).norm(), 1e-12);
}

TEST(BuildProblem, ErrorsNameTheBodyAndElement) {
  TetMesh mesh = test::boxMesh(2, 1, 1);
  // Append a degenerate element (a repeated node) to an otherwise good mesh.
  mesh.tets.insert(mesh.tets.end(), {0, 1, 2, 2});
  const std::string zero = buildError(beamBody(), mesh);
  EXPECT_NE(zero.find("body 'beam'"), std::string::npos) << zero;
  EXPECT_NE(zero.find("element 12 (nodes 0, 1, 2, 2) has zero volume"), std::string::npos) << zero;

  mesh = test::boxMesh(2, 1, 1);
  std::swap(mesh.tets[4 * 5 + 2], mesh.tets[4 * 5 + 3]);
  const std::string inverted = buildError(beamBody(), mesh);
  EXPECT_NE(inverted.find("element 5 (nodes"), std::string::npos) << inverted;
  EXPECT_NE(inverted.find("inverted"), std::string::npos) << inverted;

  mesh = test::boxMesh(2, 1, 1);
  BodyDesc body = beamBody();
  body.material.poissonRatio = 0.5;
  const std::string nu = buildError(body, mesh);
  EXPECT_NE(nu.find("body 'beam'"), std::string::npos) << nu;
  EXPECT_NE(nu.find("Poisson"), std::string::npos) << nu;

  body = beamBody();
  body.material.density = 0;
  EXPECT_NE(buildError(body, mesh).find("density"), std::string::npos);

  // A fixed node that is also dragged is ambiguous.
  body = beamBody();
  LoadDesc drag;
  drag.kind = LoadDesc::Kind::Displacement;
  drag.nodes = boxSet({-1, -1, -1}, {0.1, 0.1, 0.1});
  body.loads.push_back(drag);
  const std::string overlap = buildError(body, mesh);
  EXPECT_NE(overlap.find("fixed node set"), std::string::npos) << overlap;

  // An empty node set carries the resolver's message, prefixed with the body and the set.
  body = beamBody();
  body.fixed[0] = boxSet({5, 5, 5}, {6, 6, 6});
  const std::string empty = buildError(body, mesh);
  EXPECT_NE(empty.find("body 'beam': fixed node set 0"), std::string::npos) << empty;
  EXPECT_NE(empty.find("selects no nodes"), std::string::npos) << empty;
}

TEST(ProblemScaling, StaticsLoadFactorAndDynamicsRamp) {
  Problem p = test::makeProblem(test::boxMesh(1, 1, 1));
  const auto n3 = static_cast<Eigen::Index>(p.dofCount());
  ExternalForce ramped{Eigen::VectorXd::Constant(n3, 2.0), 1.0};
  ExternalForce instant{Eigen::VectorXd::Constant(n3, 1.0), 0.0};
  p.forces = {ramped, instant};
  // Statics: every load scaled by the load factor, ramps ignored.
  EXPECT_DOUBLE_EQ(p.externalForce(0.5, false)[0], 1.5);
  EXPECT_DOUBLE_EQ(p.externalForce(1.0, false)[0], 3.0);
  // Dynamics: min(1, t / ramp), and 1 for rampTime == 0.
  EXPECT_DOUBLE_EQ(p.externalForce(0.0, true)[0], 1.0);
  EXPECT_DOUBLE_EQ(p.externalForce(0.25, true)[0], 1.5);
  EXPECT_DOUBLE_EQ(p.externalForce(5.0, true)[0], 3.0);

  PrescribedDisplacement d;
  d.dofs = {3, 4};
  d.values = {0.2, -0.4};
  d.rampTime = 2.0;
  p.prescribed = {d};
  p.constrained[3] = p.constrained[4] = p.constrained[0] = 1;  // dof 0: a fixed dof
  Eigen::VectorXd x = p.restPositions + Eigen::VectorXd::Constant(n3, 0.01);
  p.applyPrescribed(x, 1.0, true);  // t = 1 of a 2 s ramp: half
  EXPECT_DOUBLE_EQ(x[3], p.restPositions[3] + 0.1);
  EXPECT_DOUBLE_EQ(x[4], p.restPositions[4] - 0.2);
  EXPECT_DOUBLE_EQ(x[0], p.restPositions[0]);         // fixed: back at rest
  EXPECT_DOUBLE_EQ(x[1], p.restPositions[1] + 0.01);  // free: untouched
  p.applyPrescribed(x, 0.5, false);  // statics: load factor 0.5
  EXPECT_DOUBLE_EQ(x[3], p.restPositions[3] + 0.1);
  p.applyPrescribed(x, 10.0, true);
  EXPECT_DOUBLE_EQ(x[4], p.restPositions[4] - 0.4);
}
