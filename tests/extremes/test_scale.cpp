// Position and size extremes on one problem: the cantilever (0.4 x 0.1 x 0.1 m, 160 tets, E = 1e6
// Pa, nu = 0.3, rho = 1000 kg/m^3) released under gravity, 30 linearised Newmark steps of 1/60 s
// (max sag ~5e-2 m). Moved ~1e4 m from the origin, written in millimetres (mm, t, s, N, MPa), or
// shrunk geometrically to tiny elements, the displacements must be the same (scaled).
#include "extremes_support.hpp"

#include <cstdio>

namespace corofem::test {
namespace {

class Scale : public testing::TestWithParam<BackendCase> {};

/// The cantilever scaled by `s` (geometry), offset by `offset`, with the given material and
/// gravity; `steps` steps of h. Returns the displacements (empty with *skip or a failure recorded).
struct Units {
  double length = 1.0;   ///< geometry scale s (model length units per metre of the base beam)
  double E = 1e6;        ///< Pa, or MPa in the mm system
  double rho = 1000.0;   ///< kg/m^3, or t/mm^3
  double g = 9.81;       ///< m/s^2, or mm/s^2
  double h = 1.0 / 60.0; ///< s
  Vec3 offset{0, 0, 0};
};

std::vector<double> run(const BackendCase& c, const Units& u, int steps, std::string* skip, std::string* failure) {
  const double s = u.length;
  BodyDesc body = makeBody(box({0, 0, 0}, {0.4 * s, 0.1 * s, 0.1 * s}, {8, 2, 2}), u.E, 0.3, u.rho);
  body.mesh.translate = u.offset;
  NodeSetDesc clamp = planeSet(0, u.offset[0], 1e-6 * s);
  body.fixed.push_back(clamp);
  LoadDesc g;
  g.kind = LoadDesc::Kind::Gravity;
  g.vector = {0, -u.g, 0};
  body.loads.push_back(g);
  Scene scene = dynamicScene(c, body, u.h, steps);
  auto sim = createSim(scene, skip);
  if (!sim) return {};
  while (!sim->finished()) {
    const Status st = sim->step();
    if (!st) {
      EXPECT_EQ(st.code(), ErrorCode::SolveFailed) << st.message();
      *failure = st.message();
      break;
    }
  }
  std::vector<double> x, v;
  EXPECT_TRUE(sim->readPositions(0, x));
  EXPECT_TRUE(sim->readVelocities(0, v));
  EXPECT_TRUE(allFinite(x) && allFinite(v)) << "non-finite output";
  return displacements(*sim);
}

/// max |a - k b| over max |a|.
double relativeDifference(const std::vector<double>& a, const std::vector<double>& b, double k) {
  double worst = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) worst = std::max(worst, std::abs(a[i] - k * b[i]));
  return worst / maxAbs(a);
}

constexpr int kSteps = 30;

TEST_P(Scale, FarFromTheOrigin) {
  // The same beam translated by (6e3, 6e3, 6e3) m (1.04e4 m from the origin).
  // Double: ulp(6e3) = 9e-13 m, far below anything here: displacements equal to 1e-6 of the sag
  // (PCG at 1e-8 over 30 steps; measured ~1e-9).
  // Float: ulp(6e3) = 4.9e-4 m, so absolute positions in float would quantise every element edge
  // (0.05 m) to ~1 % and the rest shape itself would carry ~1 % strain noise. Measured before the
  // OpenCL backend's commit 1ee3d8c (absolute positions uploaded): the run failed at step 1
  // (runaway), and at offsets (d, d, d) the error was 2e-5 (1 m), 1.4e-4 (10 m), 1e-3 (100 m),
  // failure (1e3 m). The backend now uploads positions relative to the body's centroid (kernels
  // use only differences), which removes the dependence on the offset: float must now agree like
  // the unit change below (1e-3; measured 4e-6).
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  std::string skip, failNear, failFar;
  const std::vector<double> near = run(c, Units{}, kSteps, &skip, &failNear);
  if (!skip.empty()) GTEST_SKIP() << skip;
  ASSERT_TRUE(failNear.empty()) << failNear;
  Units far;
  far.offset = {6e3, 6e3, 6e3};
  const std::vector<double> farU = run(c, far, kSteps, &skip, &failFar);
  ASSERT_EQ(near.size(), farU.size());
  const double diff = failFar.empty() ? relativeDifference(near, farU, 1.0) : INFINITY;
  std::printf("  %s: max |u| at origin %.4e m; at 1.04e4 m: %s, max |du| / max |u| = %.3e\n", c.describe().c_str(),
              maxAbs(near), failFar.empty() ? "ran" : ("FAILED: " + failFar.substr(0, 160)).c_str(), diff);
  EXPECT_TRUE(failFar.empty()) << failFar;
  EXPECT_LT(diff, c.isFloat() ? 1e-3 : 1e-6);
}

TEST_P(Scale, MillimetresAndMetresAgree) {
  // mm, t, s, N, MPa is a consistent unit system: lengths x1e3, E x1e-6, rho x1e-12, g x1e3; the
  // displacements in mm must be 1e3 x those in m. Every tolerance in the drivers is relative or
  // scales with the body (force floor (lambda + 2 mu) diag^2, energy floor x diag), so only
  // rounding differs. Bound: 1e-6 relative in double (PCG at 1e-8 over 30 steps), 1e-3 in float
  // (PCG at 1e-5 and float forces; measured ~1e-5).
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  std::string skip, failM, failMm;
  const std::vector<double> metres = run(c, Units{}, kSteps, &skip, &failM);
  if (!skip.empty()) GTEST_SKIP() << skip;
  Units mm;
  mm.length = 1e3;
  mm.E = 1e6 * 1e-6;
  mm.rho = 1000.0 * 1e-12;
  mm.g = 9.81e3;
  const std::vector<double> millimetres = run(c, mm, kSteps, &skip, &failMm);
  ASSERT_TRUE(failM.empty() && failMm.empty()) << failM << failMm;
  const double diff = relativeDifference(millimetres, metres, 1e3);
  std::printf("  %s: max |u| %.4e m vs %.4e mm, relative difference %.3e\n", c.describe().c_str(), maxAbs(metres),
              maxAbs(millimetres), diff);
  EXPECT_LT(diff, c.isFloat() ? 1e-3 : 1e-6);
}

TEST_P(Scale, TinyElementsAgreeWithTheSimilarBody) {
  // Geometric similarity: shrink the beam by s with the same E and rho, gravity g / s and time step
  // h s. Then rho g L / E and h / (L sqrt(rho / E)) are unchanged and u / s must be the same.
  // s = 0.0363 gives elements of ~1e-9 m^3 (the smallest corner tets: (0.05 s)^3 / 6); s = 1e-4
  // gives ~2e-17 m^3 (a 40 micrometre beam). Bounds as for the unit change (1e-6 double, 1e-3
  // float): only rounding differs.
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  std::string skip, fail;
  const std::vector<double> base = run(c, Units{}, kSteps, &skip, &fail);
  if (!skip.empty()) GTEST_SKIP() << skip;
  ASSERT_TRUE(fail.empty()) << fail;
  for (double s : {0.0363, 1e-4}) {
    Units tiny;
    tiny.length = s;
    tiny.g = 9.81 / s;
    tiny.h = s / 60.0;
    const std::vector<double> small = run(c, tiny, kSteps, &skip, &fail);
    ASSERT_TRUE(fail.empty()) << fail;
    const double diff = relativeDifference(small, base, s);
    const double smallestVolume = std::pow(0.05 * s, 3) / 6.0;
    std::printf("  %s: s = %g (smallest element %.1e m^3): max |u| %.4e m, |u/s - u_1| / |u_1| = %.3e\n",
                c.describe().c_str(), s, smallestVolume, maxAbs(small), diff);
    EXPECT_LT(diff, c.isFloat() ? 1e-3 : 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, Scale, testing::ValuesIn(backendCases()), caseName);

}  // namespace
}  // namespace corofem::test
