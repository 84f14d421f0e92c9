// Rigid rotation: a free cube (0.1 m, 135 tets, E = 1e6 Pa, nu = 0.3, rho = 1000 kg/m^3) spun at
// 10 rad/s about a tilted axis for 1000 steps, and rigidly rotated copies of the rest shape near
// 180 degrees. The co-rotational formulation must not see strain in a rigid rotation.
#include "extremes_support.hpp"

#include <Eigen/Geometry>

#include <cstdio>
#include <cstdlib>

namespace corofem::test {
namespace {

class Spin : public testing::TestWithParam<BackendCase> {};

struct SpinRun {
  int failedAt = 0;  ///< 0 = all steps ran
  std::string failure;
  double ke0 = 0, keMin = 0, keMax = 0, keEnd = 0;
  double maxRatio = 0, maxRatioEarly = 0;  ///< max U / KE overall and over the first 100 steps
};

constexpr double kL = 0.1, kE = 1e6, kRho = 1000.0, kOmega = 10.0;
/// Physical strain of the spin: centrifugal stress ~ rho omega^2 L^2, so U / KE ~ rho omega^2 L^2
/// / E = 1e-3 here (the body really stretches a little).
constexpr double kCentrifugal = kRho * kOmega * kOmega * kL * kL / kE;

/// Spins the cube about a tilted axis for `steps` steps of h; stops at the first failed step,
/// which must be a clean SolveFailed with finite buffers.
SpinRun spin(const BackendCase& c, double h, int steps, Integrator integrator, std::string* skip) {
  SpinRun r;
  BodyDesc body = makeBody(box({0, 0, 0}, {kL, kL, kL}, {3, 3, 3}), kE, 0.3, kRho);
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 3).normalized();
  body.initialAngularVelocity = {kOmega * axis.x(), kOmega * axis.y(), kOmega * axis.z()};
  Scene scene = dynamicScene(c, body, h, steps);
  scene.analysis.dynamics.integrator = integrator;
  auto sim = createSim(scene, skip);
  if (!sim) return r;
  r.ke0 = r.keMin = r.keMax = sim->energies(0).kinetic;
  for (int s = 1; s <= steps; ++s) {
    const Status st = sim->step();
    if (!st) {
      EXPECT_EQ(st.code(), ErrorCode::SolveFailed) << st.message();
      r.failedAt = s;
      r.failure = st.message();
      break;
    }
    const EnergyReport e = sim->energies(0);
    EXPECT_TRUE(std::isfinite(e.elastic) && std::isfinite(e.kinetic));
    const double ratio = e.elastic / e.kinetic;
    r.maxRatio = std::max(r.maxRatio, ratio);
    if (s <= 100) r.maxRatioEarly = std::max(r.maxRatioEarly, ratio);
    r.keMin = std::min(r.keMin, e.kinetic);
    r.keMax = std::max(r.keMax, e.kinetic);
    r.keEnd = e.kinetic;
  }
  std::vector<double> x, v;
  EXPECT_TRUE(sim->readPositions(0, x));
  EXPECT_TRUE(sim->readVelocities(0, v));
  EXPECT_TRUE(allFinite(x) && allFinite(v)) << "non-finite output";
  std::printf("  %s, h = 1/%.0f s, %s: %s, KE in [%.4f, %.4f] KE0 (end %.4f), max U/KE %.3e (first 100 steps "
              "%.3e; centrifugal scale %.1e)%s%s\n",
              c.describe().c_str(), 1.0 / h, integrator == Integrator::Newmark ? "Newmark" : "backward Euler",
              r.failedAt ? ("FAILED at step " + std::to_string(r.failedAt)).c_str() : "all steps",
              r.keMin / r.ke0, r.keMax / r.ke0, r.keEnd / r.ke0, r.maxRatio, r.maxRatioEarly, kCentrifugal,
              r.failure.empty() ? "" : "\n      status: ", r.failure.substr(0, 160).c_str());
  return r;
}

TEST_P(Spin, FreeSpinHasNoSpuriousStrainEnergyGrowth) {
  // The cube (0.1 m, 135 tets, E = 1e6 Pa, rho = 1000) spun at 10 rad/s about a tilted axis for
  // 1000 steps of 1/240 s (0.042 rad per step, ~6.6 turns: every angle, 180 degrees included),
  // with the paper's linearised average-acceleration step. Bounds: U / KE below the centrifugal
  // scale rho omega^2 L^2 / E (measured ~0.3 of it), no growth (the max over 1000 steps at most
  // 1.5x that of the first 100: a steady spin oscillates about its stretched state), and KE within
  // 1 % of its start (angular momentum and energy of a free spin are conserved).
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  std::string skip;
  const SpinRun r = spin(c, 1.0 / 240.0, 1000, Integrator::Newmark, &skip);
  if (!skip.empty()) GTEST_SKIP() << skip;
  ASSERT_EQ(r.failedAt, 0) << r.failure;
  EXPECT_LT(r.maxRatio, kCentrifugal);
  EXPECT_LT(r.maxRatio, 1.5 * r.maxRatioEarly);
  EXPECT_GT(r.keMin, 0.99 * r.ke0);
  EXPECT_LT(r.keMax, 1.01 * r.ke0);
}

TEST_P(Spin, At60HzNewmarkRunsAwayCleanlyAndBackwardEulerDampsTheSpin) {
  // Measured limitation, stated here so that a change shows: at 60 Hz (0.167 rad per step) the
  // average-acceleration Newmark step is not energy-conserving for a rotating co-rotational body
  // (the trapezoidal rule conserves energy only for linear systems; its chord interpolation of a
  // rotation stretches the body a little every step): the linearised step runs away at step ~376
  // and converged Newton (newton_iterations 3) even at ~116, on every backend. The runaway guard
  // must catch it cleanly (SolveFailed, finite buffers) - never NaN. Backward Euler stays bounded
  // (U / KE below the centrifugal scale) but dissipates the rigid spin itself (measured: KE down to
  // ~2 % of its start after 1000 steps): bounded, not accurate.
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  std::string skip;
  const SpinRun newmark = spin(c, 1.0 / 60.0, 1000, Integrator::Newmark, &skip);
  if (!skip.empty()) GTEST_SKIP() << skip;
  if (newmark.failedAt == 0) {
    EXPECT_LT(newmark.maxRatio, kCentrifugal) << "ran through, but with spurious strain energy";
  } else {
    EXPECT_NE(newmark.failure.find("ran away"), std::string::npos) << newmark.failure;
  }
  const SpinRun euler = spin(c, 1.0 / 60.0, 1000, Integrator::BackwardEuler, &skip);
  EXPECT_EQ(euler.failedAt, 0) << euler.failure;
  EXPECT_LT(euler.maxRatio, kCentrifugal);
  EXPECT_LE(euler.keMax, 1.0 * euler.ke0 * (1 + 1e-9));  // dissipative: never gains energy
}

struct RotationCase {
  BackendCase backend;
  RotationMethod rotation = RotationMethod::Polar;
};

void PrintTo(const RotationCase& c, std::ostream* os) { *os << c.backend.describe() << ", " << toString(c.rotation); }

std::vector<RotationCase> rotationCases() {
  std::vector<RotationCase> out;
  for (const BackendCase& c : backendCases()) {
    if (!c.isDevice()) {
      out.push_back({c, RotationMethod::Svd});
      continue;
    }
    for (RotationMethod r : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion, RotationMethod::Qr})
      out.push_back({c, r});
  }
  return out;
}

class RigidRotation : public testing::TestWithParam<RotationCase> {};

TEST_P(RigidRotation, RotatedRestShapeHasNoStrainNear180Degrees) {
  // The rest shape rotated rigidly by theta about a tilted axis: no strain energy, no force. Near
  // 180 degrees the polar iteration's scaling and the quaternion's sign choice are most delicate.
  const RotationCase& rc = GetParam();
  COROFEM_SKIP_ABSENT(rc.backend);
  constexpr double L = 0.1, E = 1e6;
  BodyDesc body = makeBody(box({0, 0, 0}, {L, L, L}, {3, 3, 3}), E, 0.3);
  Scene scene = dynamicScene(rc.backend, body, 1.0 / 60.0, 1);
  scene.solver.rotation = rc.rotation;
  COROFEM_DIRECT_BODY(d, scene);
  const Eigen::VectorXd& X = d.problem->restPositions;
  const Eigen::Vector3d axis = Eigen::Vector3d(1, -2, 0.5).normalized();
  const double volume = L * L * L;
  // Energy scale of a strain eps: E eps^2 V / 2. Double: eps ~ 1e-12 is rounding; float: the
  // positions themselves carry ~6e-8 relative rounding (ulp of 0.1 m over 0.033 m elements), so
  // eps ~ 1e-6 -> 5e-13 E V. Bounds: 1e-20 E V (double), 1e-11 E V (float).
  const double bound = (rc.backend.isFloat() ? 1e-11 : 1e-20) * E * volume;
  // Quaternion (Mueller et al. 2016) runs a fixed number of iterations warm-started from the
  // previous call's rotation: from the identity a large rotation needs several calls (measured:
  // a cold 90-degree jump leaves U ~ 3e-9 J, |f| ~ 4e-3 N after one call in double). In a
  // simulation the rotation changes a little per step, so the warm start is what it is designed
  // for; the test allows it 4 evaluations at the same positions, the other methods one.
  const int passes = rc.rotation == RotationMethod::Quaternion ? 4 : 1;
  for (double degrees : {90.0, 179.0, 179.99, 180.0, 180.01, 270.0}) {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(degrees * M_PI / 180.0, axis).toRotationMatrix();
    Eigen::VectorXd x = X;
    for (Eigen::Index i = 0; i < X.size(); i += 3) x.segment<3>(i) = R * X.segment<3>(i);
    Eigen::VectorXd f;
    double U = 0, firstU = 0;
    for (int pass = 0; pass < passes; ++pass) {
      detail::DeviceSlot& slot = d.solver->slot();
      slot.setPositions({0}, {&x});
      slot.internalForces({0}, {&f});
      std::vector<double> energy;
      slot.elasticEnergy({0}, energy);
      U = energy.at(0);
      if (pass == 0) firstU = U;
    }
    // Force scale: E L^2 eps with the same eps as the energy bound.
    const double fmax = f.cwiseAbs().maxCoeff();
    const double fbound = (rc.backend.isFloat() ? 1e-5 : 1e-9) * E * L * L / 3.0;
    std::printf("  %s, %s, %7.2f deg: U %.3e J (first evaluation %.3e; bound %.1e), max |f| %.3e N (bound %.1e)\n",
                rc.backend.describe().c_str(), toString(rc.rotation), degrees, U, firstU, bound, fmax, fbound);
    EXPECT_TRUE(std::isfinite(U) && f.allFinite());
    EXPECT_LT(std::abs(U), bound) << degrees << " degrees";
    EXPECT_LT(fmax, fbound) << degrees << " degrees";
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, Spin, testing::ValuesIn(backendCases()), caseName);
INSTANTIATE_TEST_SUITE_P(Backends, RigidRotation, testing::ValuesIn(rotationCases()),
                         [](const testing::TestParamInfo<RotationCase>& info) {
                           return info.param.backend.name + "_" + toString(info.param.rotation);
                         });

}  // namespace
}  // namespace corofem::test
