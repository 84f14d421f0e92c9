// Regression tests of issue 27, items 10 and 11, through the public Simulation API: a static
// St. Venant-Kirchhoff answer with inverted elements reported as success, and two messages that
// said what had not happened (float precision blamed on the double backend; "blew up" for a capped
// linear solve that made no progress). Item 12 (unconverged runs reported as "ok") is a matter of
// `corofem run`'s summary: tests/cli/test_cli_hardening.cpp.
#include "beam_helpers.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace corofem {
namespace {

using namespace corofem::test;

bool has(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

NodeSetDesc planeZ(double z) {
  NodeSetDesc set;
  set.kind = NodeSetDesc::Kind::Plane;
  set.planePoint = {0, 0, z};
  set.planeNormal = {0, 0, 1};
  set.planeTolerance = 1e-6;
  return set;
}

/// A 0.2 x 0.2 x 0.1 m St. Venant-Kirchhoff block (2 x 2 x 2 cells, 40 tets), its bottom face held,
/// its top face pushed down by twice the height: through the bottom, to the block's mirror image.
/// St. Venant-Kirchhoff's energy vanishes at every reflection (E = (F^T F - I) / 2 = 0 for
/// F = diag(1, 1, -1)), so Newton finds an equilibrium with elements turned inside out.
Scene mirroredBlock() {
  BodyDesc body;
  body.name = "block";
  body.mesh = boxMesh({0, 0, 0}, {0.2, 0.2, 0.1}, {2, 2, 2});
  body.material.youngsModulus = 1e5;
  body.material.poissonRatio = 0.3;
  body.formulation = Formulation::StVenantKirchhoff;
  body.fixed.push_back(planeZ(0.0));
  LoadDesc push;
  push.kind = LoadDesc::Kind::Displacement;
  push.vector = {0, 0, -0.2};
  push.nodes = planeZ(0.1);
  body.loads.push_back(push);
  return staticScene(body, 1);
}

TEST(Issue27Item10, StVenantKirchhoffStaticsThatInvertElementsFailAndSaySo) {
  auto sim = Simulation::create(mirroredBlock());
  ASSERT_TRUE(sim) << sim.message();
  std::vector<double> before;
  ASSERT_TRUE(sim->readPositions(0, before));
  const Status st = sim->step();
  // Before the fix the increment "converged" with half the block inside out, and the step said ok.
  ASSERT_FALSE(st) << "a static St. Venant-Kirchhoff answer with inverted elements was reported as success";
  EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
  const std::string& m = st.message();
  EXPECT_TRUE(has(m, "body 'block': static increment 1/1")) << m;
  EXPECT_TRUE(has(m, " of 40 elements inverted (det F <= 0; the lowest, -")) << m;  // count and worst J
  EXPECT_TRUE(has(m, "St. Venant-Kirchhoff")) << m;
  EXPECT_TRUE(has(m, "\"neo_hookean\"")) << m;  // the fix
  EXPECT_LT(m.size(), 1024u) << m;
  std::vector<double> after;
  ASSERT_TRUE(sim->readPositions(0, after));
  EXPECT_EQ(after, before) << "a failed increment keeps the last good (rest) state";
}

TEST(Issue27Item10, NeoHookeanAndCorotationalBlocksAreNotAffected) {
  // The same push with Neo-Hookean fails as before (its forces refuse inversion); co-rotational
  // elements may invert (their force pushes them back) and the step succeeds as before.
  Scene nh = mirroredBlock();
  nh.bodies[0].formulation = Formulation::NeoHookean;
  auto a = Simulation::create(nh);
  ASSERT_TRUE(a) << a.message();
  const Status st = a->step();
  ASSERT_FALSE(st);
  EXPECT_TRUE(has(st.message(), "Neo-Hookean energy is undefined")) << st.message();

  Scene corot = mirroredBlock();
  corot.bodies[0].formulation = Formulation::Corotational;
  auto b = Simulation::create(corot);
  ASSERT_TRUE(b) << b.message();
  const Status ok = b->step();
  EXPECT_TRUE(ok) << ok.message();
}

TEST(Issue27Item11, AStalledResidualOnTheDoubleBackendDoesNotBlameFloat) {
  // docs/examples/static_cantilever.json, coarser: a 1 m co-rotational cantilever (E = 1e7 Pa),
  // 10 N at the tip, statics on the reference backend (double). Its force evaluation's rounding
  // floor is ~5e-9 relative; asked for 1e-10, Newton stalls there.
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.1, 0.1}, {5, 1, 1}), 0.0, 1e7, 0.3, 1000,
                                 Formulation::Corotational);
  body.loads.push_back(tipForce(1.0, {0, -10, 0}));
  Scene scene = staticScene(body, 4, LinearSolverKind::Pcg);
  scene.solver.preconditioner = PreconditionerKind::BlockDiagonal;
  scene.analysis.statics.residualTolerance = 1e-10;
  scene.analysis.statics.displacementTolerance = 1e-10;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const Status st = sim->step();
  ASSERT_FALSE(st) << "the residual floor of double was expected above 1e-10 here";
  const std::string& m = st.message();
  EXPECT_TRUE(has(m, "rounding floor")) << m;
  // Before the fix: 'typical of solver.precision "float" ...; use "double"', on the double backend.
  EXPECT_FALSE(has(m, "float")) << m;
  EXPECT_TRUE(has(m, "in double precision on '")) << m;
  EXPECT_TRUE(has(m, "analysis.residual_tolerance = 1.0e-10 cannot be reached")) << m;
  EXPECT_TRUE(has(m, "use a residual_tolerance above the stalled residual (e.g. 1e-08)")) << m;
}

TEST(Issue27Item11, AStalledNewtonFarAboveAnyRoundingFloorIsNotCalledOne) {
  // A soft 1 m co-rotational cantilever (E = 1e5 Pa) under a 50 N tip load in one increment: far
  // beyond where the co-rotational tangent (no geometric stiffness) lets Newton converge, it stalls
  // at a relative residual of ~3e-2 with corrections of ~1e-3 of the displacement. No rounding
  // gives a residual of 3e-2 in double; before the fix the message said it was the floor and
  // advised "double", the precision in use.
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.1, 0.1}, {10, 1, 1}), 0.0, 1e5, 0.3, 1000,
                                 Formulation::Corotational);
  body.loads.push_back(tipForce(1.0, {0, -50, 0}));
  Scene scene = staticScene(body, 1);
  scene.analysis.statics.residualTolerance = 1e-6;
  scene.analysis.statics.displacementTolerance = 1e-8;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const Status st = sim->step();
  ASSERT_FALSE(st);
  const std::string& m = st.message();
  EXPECT_TRUE(has(m, "did not converge in 30 Newton iterations (relative residual ")) << m;
  EXPECT_FALSE(has(m, "rounding floor")) << m;
  EXPECT_FALSE(has(m, "float")) << m;
  EXPECT_TRUE(has(m, "try more increments (analysis.increments)")) << m;
}

TEST(Issue27Item11, ACappedSolveThatMadeNoProgressIsNotCalledABlowUp) {
  // The 1 x 0.1 x 0.1 m beam of issue 29 (there 72 x 6 x 6 cells; 12 x 2 x 2 here), clamped, under
  // gravity, backward Euler at 1/60 s, PCG capped at 5 iterations: step 1's solve stops far from
  // its tolerance, the Newton residual's norm grows while its relative value stays near 1, and the
  // step fails. Nothing blew up: the message says what happened and leads with the cap.
  BodyDesc body = cantileverBody(boxMesh({0, 0, 0}, {1, 0.1, 0.1}, {12, 2, 2}), 0.0, 1e6, 0.3, 1000,
                                 Formulation::Corotational);
  body.loads.push_back(gravity({0, -9.81, 0}));
  Scene scene;
  scene.name = "capped";
  scene.bodies.push_back(body);
  scene.analysis.kind = AnalysisDesc::Kind::Dynamic;
  scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
  scene.analysis.dynamics.timeStep = 1.0 / 60.0;
  scene.analysis.dynamics.steps = 2;
  scene.solver.maxIterations = 5;
  scene.backend.kind = BackendKind::Reference;
  auto sim = Simulation::create(scene);
  ASSERT_TRUE(sim) << sim.message();
  const Status st = sim->step();
  ASSERT_FALSE(st);
  EXPECT_EQ(st.code(), ErrorCode::SolveFailed);
  const std::string& m = st.message();
  EXPECT_FALSE(has(m, "blew up")) << m;
  EXPECT_TRUE(has(m, "time step 1/2")) << m;
  EXPECT_TRUE(has(m, "its linear solves stopped at solver.max_iterations = 5 with a relative residual up to ")) << m;
  EXPECT_TRUE(has(m, "the Newton residual grew from ")) << m;
  EXPECT_TRUE(has(m, "(relative 1.0e+00 to ")) << m;  // what it was: no progress, not an explosion
  EXPECT_TRUE(has(m, "; raise solver.max_iterations")) << m;  // the first fix named is the cap
  EXPECT_LT(m.size(), 1024u) << m;
}

}  // namespace
}  // namespace corofem
