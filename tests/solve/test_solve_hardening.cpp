// Regression tests of issue 27 through the public Simulation API: a static St. Venant-Kirchhoff
// answer with inverted elements reported as success (item 10).
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

}  // namespace
}  // namespace corofem
