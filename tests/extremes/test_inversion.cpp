// Inverted and flattened elements: a free cube (0.1 m, 135 tets, E = 1e5 Pa, nu = 0.3) starts
// from a degenerate shape (squashed flat: every node at z = 0, every element of zero volume) or
// turned inside out (the nodes above the mid-plane mirrored through it: the upper half's elements
// inverted) or scrambled (every node at a random point of the box), is released at rest and integrated with backward Euler plus mass damping until it
// settles. The Scene API has no initial positions, so the body is built directly (Problem +
// backend + DynamicSolver) and started with BodySolver::setInitialState.
//
// Which rotation methods claim inversion: the reference backend always takes the SVD polar factor
// with the smallest singular direction flipped when det F < 0 (a proper rotation; the elastic
// force then pushes the element back through zero volume). On OpenCL, Svd does the same; Polar
// falls back to that SVD path for inverted or degenerate elements; Quaternion returns a proper
// rotation for any F (not necessarily the flipped-SVD one); Qr is Gram-Schmidt of F's columns.
// Svd and the reference must recover; the others must recover or fail with a clear status (the
// test prints which).
#include "extremes_support.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>

#include <random>

namespace corofem::test {
namespace {

struct InversionCase {
  BackendCase backend;
  RotationMethod rotation = RotationMethod::Svd;
  bool mustRecover = true;
};

void PrintTo(const InversionCase& c, std::ostream* os) { *os << c.backend.describe() << ", " << toString(c.rotation); }

std::vector<InversionCase> inversionCases() {
  std::vector<InversionCase> out;
  for (const BackendCase& c : backendCases()) {
    if (!c.isDevice()) {
      out.push_back({c, RotationMethod::Svd, true});  // the reference ignores the choice: SVD polar
      continue;
    }
    for (RotationMethod r : {RotationMethod::Svd, RotationMethod::Polar, RotationMethod::Quaternion, RotationMethod::Qr})
      out.push_back({c, r, r == RotationMethod::Svd || r == RotationMethod::Polar});
  }
  return out;
}

std::string inversionName(const testing::TestParamInfo<InversionCase>& info) {
  return info.param.backend.name + "_" + toString(info.param.rotation);
}

enum class Start { Flat, Mirrored, Scrambled };

/// Rigid (Procrustes) fit of x to the rest positions X: the largest distance of a node from the
/// best rotated and translated copy of the rest shape (m). Zero iff x is a rigid motion of X.
double shapeError(const Eigen::VectorXd& X, const Eigen::VectorXd& x) {
  const Eigen::Index n = X.size() / 3;
  const Eigen::Map<const Eigen::Matrix3Xd> P(X.data(), 3, n), Q(x.data(), 3, n);
  const Eigen::Vector3d cp = P.rowwise().mean(), cq = Q.rowwise().mean();
  const Eigen::Matrix3Xd p = P.colwise() - cp, q = Q.colwise() - cq;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(q * p.transpose(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  if (Eigen::Matrix3d(svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) d(2, 2) = -1;  // proper rotation
  const Eigen::Matrix3d R = svd.matrixU() * d * svd.matrixV().transpose();
  return ((R * p) - q).colwise().norm().maxCoeff();
}

class Inversion : public testing::TestWithParam<InversionCase> {
 protected:
  void run(Start start) {
    const InversionCase& ic = GetParam();
    COROFEM_SKIP_ABSENT(ic.backend);
    constexpr double L = 0.1;
    BodyDesc body = makeBody(box({0, 0, 0}, {L, L, L}, {3, 3, 3}), 1e5, 0.3);
    // Mass damping 20 1/s: the slowest modes (~50 Hz) decay over ~0.1 s; backward Euler damps the rest.
    body.material.rayleighMass = 20.0;
    constexpr double h = 0.004;
    constexpr int steps = 300;  // 1.2 s: ~12 decay times of the mass damping
    Scene scene = dynamicScene(ic.backend, body, h, steps);
    scene.analysis.dynamics.integrator = Integrator::BackwardEuler;
    scene.solver.rotation = ic.rotation;
    COROFEM_DIRECT_BODY(d, scene);

    const Eigen::VectorXd& X = d.problem->restPositions;
    Eigen::VectorXd x0 = X;
    for (Eigen::Index i = 2; i < x0.size(); i += 3) {
      if (start == Start::Flat) x0[i] = 0.0;
      else if (start == Start::Mirrored && X[i] > 0.5 * L) x0[i] = L - X[i];  // mirror through z = L / 2
    }
    if (start == Start::Scrambled) {
      // Every node at a random point of the rest box (fixed seed): roughly half the elements
      // inverted, many nearly degenerate (the classic test of Irving et al. 2004).
      std::mt19937 rng(12345);
      std::uniform_real_distribution<double> u(0.0, L);
      for (Eigen::Index i = 0; i < x0.size(); ++i) x0[i] = u(rng);
    }
    d.solver->setInitialState(x0, Eigen::VectorXd::Zero(x0.size()));
    const double startVolume = minVolumeRatio(d.mesh, x0);
    const double u0 = d.solver->elasticEnergy();

    std::string failure;
    int taken = 0;
    for (int s = 1; s <= steps; ++s) {
      try {
        d.solver->step(s, steps);
        taken = s;
      } catch (const detail::Error& e) {
        EXPECT_EQ(e.code(), ErrorCode::SolveFailed) << e.what();
        failure = e.what();
        break;
      }
    }
    const Eigen::VectorXd& x = d.solver->positions();
    ASSERT_TRUE(x.allFinite() && d.solver->velocities().allFinite()) << "non-finite state after " << taken << " steps";
    const double u1 = d.solver->elasticEnergy();
    const double volume = minVolumeRatio(d.mesh, x);
    const double shape = shapeError(X, x);
    std::cout << "  " << ic.backend.describe() << ", rotation " << toString(ic.rotation) << ", start "
              << (start == Start::Flat ? "flat" : start == Start::Mirrored ? "mirrored" : "scrambled") << " (min volume ratio " << startVolume
              << ", U0 " << u0 << " J): " << taken << "/" << steps << " steps, U " << u1
              << " J, min volume ratio " << volume << ", shape error " << shape / L << " L"
              << (failure.empty() ? "" : ", FAILED: " + failure.substr(0, 200)) << "\n";

    const bool recovered = failure.empty() && volume > 0.9 && shape < 1e-2 * L;
    if (ic.mustRecover) {
      // Recovery: every element back to within 10 % of its rest volume and the shape within 1 % of L
      // of a rigid copy of the rest shape (backward Euler + damping leave a slowly decaying residual
      // motion; 1.2 s is ~12 decay times, far below these bounds when the body recovered).
      EXPECT_TRUE(failure.empty()) << failure;
      EXPECT_GT(volume, 0.9);
      EXPECT_LT(shape, 1e-2 * L);
      EXPECT_LT(u1, 1e-3 * u0);
    } else {
      // Recover, or say so: a body that stays inverted or distorted without a failed status is the
      // one outcome not allowed.
      EXPECT_TRUE(recovered || !failure.empty())
          << "rotation " << toString(ic.rotation) << " neither recovered nor reported a failure";
      std::cout << "  -> " << (recovered ? "recovers" : "reports SolveFailed") << "\n";
    }
  }
};

TEST_P(Inversion, SquashedFlatRecovers) { run(Start::Flat); }
TEST_P(Inversion, TurnedInsideOutRecovers) { run(Start::Mirrored); }
TEST_P(Inversion, ScrambledNodesRecover) { run(Start::Scrambled); }

INSTANTIATE_TEST_SUITE_P(Backends, Inversion, testing::ValuesIn(inversionCases()), inversionName);

}  // namespace
}  // namespace corofem::test
