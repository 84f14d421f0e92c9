// Kernel conformance of the OpenCL backend against the double-precision element mathematics
// (model/element.hpp): rotations (every method), internal forces with the SVD rotation, the strain
// energy and the vector widths, on random element soups of awkward sizes (1, 7, 97, 1001 elements:
// not multiples of the work-group size), in double and float, on every OpenCL device present. The
// products (mass, damping, Rayleigh) and the linear formulation against the reference are
// tests/conformance/ (every backend's).
//
// Tolerances, float: positions are rounded to float (relative 6e-8, absolute up to 2.4e-7 m at
// |x| <= 4 m) and element edges are >= ~0.25 m, so F carries a relative error up to ~1e-6; the
// polar factor amplifies a perturbation of F by at most 1 / (s_i + s_j) <= ~1 here (singular
// values >= 0.6), and the kernels add a few hundred roundings. Hence 2e-5 on the entries of R.
// Forces and products are relative to the largest entry: the strain q = R^T x - X is ~0.15 of an
// edge, so the float cancellation costs a factor ~10 on top of the F error: 1e-4. Double: the
// same chain with eps = 2.2e-16 gives ~1e-14..1e-13; 1e-10 leaves room for ill-shaped
// samples and still catches any wrong term (those are O(1)).
#include "backends/opencl/opencl_backend.hpp"
#include "opencl/opencl_test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <random>

namespace corofem {
namespace {

using detail::Mat3;
using detail::Vec3d;
using test::DeviceCase;

constexpr std::size_t kSizes[] = {1, 7, 97, 1001};

enum class Shape { WellShaped, Inverted, NearlyFlat, PureRotation, LargeStretch };

/// Deformed positions of a soup: each element rotated by a random R, stretched by a random
/// symmetric strain of size `strain`, translated; Inverted mirrors it first; NearlyFlat squashes
/// it to 1e-7 of its height along a random axis; LargeStretch stretches it by 1/30 to 30 along
/// random principal axes.
Eigen::VectorXd deform(const TetMesh& mesh, Shape shape, std::mt19937& rng, double strain = 0.15) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd x(static_cast<Eigen::Index>(mesh.nodes.size()));
  for (std::size_t e = 0; e < mesh.tetCount(); ++e) {
    Vec3d c = Vec3d::Zero();
    for (int k = 0; k < 4; ++k) c += Vec3d(&mesh.nodes[3 * mesh.tets[4 * e + k]]) / 4.0;
    Mat3 S = Mat3::Identity();
    if (shape != Shape::PureRotation) {
      Mat3 A;
      for (int i = 0; i < 9; ++i) A(i / 3, i % 3) = u(rng);
      S += strain * 0.5 * (A + A.transpose());
    }
    if (shape == Shape::Inverted) S = S * Eigen::Vector3d(1, 1, -1).asDiagonal();
    if (shape == Shape::NearlyFlat) {
      const Mat3 Q = test::randomRotation(rng);
      S = Q * Eigen::Vector3d(1, 1, 1e-7).asDiagonal() * Q.transpose();
    }
    if (shape == Shape::LargeStretch) {  // principal stretches from 1/30 to 30, log-uniform
      const Mat3 Q = test::randomRotation(rng);
      const Vec3d s(std::pow(30.0, u(rng)), std::pow(30.0, u(rng)), std::pow(30.0, u(rng)));
      S = Q * s.asDiagonal() * Q.transpose();
    }
    const Mat3 R = test::randomRotation(rng);
    const Vec3d t(u(rng), u(rng), u(rng));
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t n = mesh.tets[4 * e + k];
      x.segment<3>(3 * n) = c + t + R * S * (Vec3d(&mesh.nodes[3 * n]) - c);
    }
  }
  return x;
}

std::array<Vec3d, 4> corners(const Eigen::VectorXd& x, const TetMesh& mesh, std::size_t e) {
  std::array<Vec3d, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = x.segment<3>(3 * mesh.tets[4 * e + k]);
  return out;
}

class OpenCLKernels : public ::testing::TestWithParam<DeviceCase> {
 protected:
  bool isDouble() const { return GetParam().precision == Precision::Double; }
  double rotTol() const { return isDouble() ? 1e-10 : 2e-5; }
  double relTol() const { return isDouble() ? 1e-10 : 1e-4; }

  std::unique_ptr<detail::OpenCLBackendInternal> backend(const detail::Problem& p, RotationMethod m,
                                                        const detail::OpenCLTuning& o = {}) {
    // The same solver settings as test_backend.cpp (block preconditioner), so that both files
    // share the programs built once per process (PoCL compiles take seconds each).
    SolverDesc s;
    s.precision = GetParam().precision;
    s.rotation = m;
    s.preconditioner = PreconditionerKind::BlockDiagonal;
    return test::openclOn(p, s, detail::cl::Context::shared(std::to_string(GetParam().device)), o);
  }

  /// Max over elements of max |R_device - R_reference| entries, and checks every R is proper.
  static double rotationError(const std::vector<double>& got, const detail::Problem& p,
                              const Eigen::VectorXd& x, double properTol, const char* what) {
    double err = 0;
    for (std::size_t e = 0; e < p.elements.size(); ++e) {
      Mat3 R;
      for (int k = 0; k < 9; ++k) R(k / 3, k % 3) = got[9 * e + k];
      EXPECT_TRUE(R.allFinite()) << what << ": element " << e;
      EXPECT_NEAR(R.determinant(), 1.0, properTol) << what << ": element " << e << " R =\n" << R;
      EXPECT_LE((R * R.transpose() - Mat3::Identity()).cwiseAbs().maxCoeff(), properTol)
          << what << ": element " << e;
      const Mat3 ref = detail::polarRotation(detail::deformationGradient(p.elements[e], corners(x, p.mesh, e)));
      err = std::max(err, (R - ref).cwiseAbs().maxCoeff());
    }
    return err;
  }
};

TEST_P(OpenCLKernels, RotationsMatchPolarDecompositionOnWellShapedElements) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(7);
  for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion}) {
    for (std::size_t n : kSizes) {
      const detail::Problem p = test::makeProblem(test::randomSoup(n, rng));
      auto b = backend(p, m);
      const Eigen::VectorXd x = deform(p.mesh, Shape::WellShaped, rng);
      // Quaternion: warm-started iteration from the identity; repeated updates at the same
      // positions play the role of successive time steps (6 iterations each).
      const int updates = m == RotationMethod::Quaternion ? 8 : 1;
      for (int i = 0; i < updates; ++i) b->setPositions(x);
      const double err = rotationError(b->readRotations(), p, x, rotTol(), toString(m));
      EXPECT_LE(err, rotTol()) << toString(m) << ", " << n << " elements";
      if (n == 1001) std::printf("[info] %s, %zu elements: max |R - R_reference| entry %.3g\n", toString(m), n, err);
    }
  }
}

// The polar method's two iterations: vectors of elements whose F^T F is within 1/2 of I take the
// Newton-Schulz iteration (the small strains of most frames, 0.01 and 0.05 here), the others the
// scaled Newton one (0.4: most vectors hold a lane beyond the bound; 0.15 mixes both). Every strain
// gives the reference's polar factor and a proper rotation to the precision's tolerance.
TEST_P(OpenCLKernels, PolarMatchesReferenceOnBothSidesOfTheNewtonSchulzBound) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(31);
  for (double strain : {0.01, 0.05, 0.15, 0.4}) {
    for (std::size_t n : kSizes) {
      const detail::Problem p = test::makeProblem(test::randomSoup(n, rng));
      auto b = backend(p, RotationMethod::Polar);
      const Eigen::VectorXd x = deform(p.mesh, Shape::WellShaped, rng, strain);
      b->setPositions(x);
      const double err = rotationError(b->readRotations(), p, x, rotTol(), "Polar");
      EXPECT_LE(err, rotTol()) << "strain " << strain << ", " << n << " elements";
      if (n == 1001)
        std::printf("[info] strain %.2f, %zu elements: max |R - R_reference| entry %.3g\n", strain, n, err);
    }
  }
}

// Stretches of 1/30 to 30: the scaled Newton iteration of the polar method must take its scaled
// steps here (near convergence it drops the scaling) and still converge, or hand the element to
// the SVD path; either way the reference's polar factor, to a tolerance that depends on how the
// method's conditioning grows with that of F (up to 900).
TEST_P(OpenCLKernels, RotationsMatchPolarDecompositionUnderLargeStretches) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(29);
  for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd}) {
    for (std::size_t n : kSizes) {
      const detail::Problem p = test::makeProblem(test::randomSoup(n, rng));
      auto b = backend(p, m);
      const Eigen::VectorXd x = deform(p.mesh, Shape::LargeStretch, rng);
      b->setPositions(x);
      // Polar iterates on F itself; the SVD path diagonalises F^T F, which squares the condition
      // number (up to 900^2 here), and float gives ~1e-3 there (2.1e-3 measured on PoCL).
      const double tol = m == RotationMethod::Polar ? (isDouble() ? 1e-10 : 1e-4) : (isDouble() ? 1e-9 : 1e-2);
      const double err = rotationError(b->readRotations(), p, x, isDouble() ? 1e-10 : 2e-5, toString(m));
      EXPECT_LE(err, tol) << toString(m) << ", " << n << " elements";
      if (n == 1001) std::printf("[info] large stretches, %s, %zu elements: max |R - R_reference| entry %.3g\n", toString(m), n, err);
    }
  }
}

TEST_P(OpenCLKernels, QrEqualsPolarForPureRotationsAndStaysProperUnderStrain) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(11);
  for (std::size_t n : kSizes) {
    const detail::Problem p = test::makeProblem(test::randomSoup(n, rng));
    auto b = backend(p, RotationMethod::Qr);
    Eigen::VectorXd x = deform(p.mesh, Shape::PureRotation, rng);
    b->setPositions(x);
    EXPECT_LE(rotationError(b->readRotations(), p, x, rotTol(), "Qr"), rotTol()) << n << " elements";
    // Under a 15% strain the edge frame differs from the polar factor by O(strain): it must stay a
    // proper rotation and within the size of the strain.
    x = deform(p.mesh, Shape::WellShaped, rng);
    b->setPositions(x);
    const double err = rotationError(b->readRotations(), p, x, rotTol(), "Qr");
    EXPECT_LE(err, 0.5) << n << " elements";
  }
}

TEST_P(OpenCLKernels, InvertedElements) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(13);
  const detail::Problem p = test::makeProblem(test::randomSoup(97, rng));
  const Eigen::VectorXd x = deform(p.mesh, Shape::Inverted, rng);
  // Svd reproduces the reference's convention (smallest singular direction flipped); Polar hands
  // inverted elements to the same SVD path. Quaternion and Qr: a proper rotation, nothing more.
  for (RotationMethod m : {RotationMethod::Svd, RotationMethod::Polar}) {
    auto b = backend(p, m);
    b->setPositions(x);
    EXPECT_LE(rotationError(b->readRotations(), p, x, rotTol(), toString(m)), rotTol()) << toString(m);
  }
  for (RotationMethod m : {RotationMethod::Quaternion, RotationMethod::Qr}) {
    auto b = backend(p, m);
    b->setPositions(x);
    const double err = rotationError(b->readRotations(), p, x, rotTol(), toString(m));
    RecordProperty(std::string("inverted_max_entry_error_") + toString(m), std::to_string(err));
    std::printf("[info] inverted elements, %s: max |R - R_reference| entry %.3g\n", toString(m), err);
  }
}

TEST_P(OpenCLKernels, NearlyFlatElementsGiveFiniteProperRotations) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(17);
  const detail::Problem p = test::makeProblem(test::randomSoup(97, rng));
  const Eigen::VectorXd x = deform(p.mesh, Shape::NearlyFlat, rng);
  for (RotationMethod m : {RotationMethod::Polar, RotationMethod::Svd, RotationMethod::Quaternion,
                           RotationMethod::Qr}) {
    auto b = backend(p, m);
    b->setPositions(x);
    const std::vector<double> R = b->readRotations();
    // Only finiteness and properness are checked (inside rotationError); the in-plane rotation of
    // a flattened element is still determined, but its sign conventions differ between methods.
    rotationError(R, p, x, rotTol(), toString(m));
  }
}

TEST_P(OpenCLKernels, InternalForcesMatchEquation9) {
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(19);
  for (std::size_t n : kSizes) {
    const detail::Problem p = test::makeProblem(test::randomSoup(n, rng), 2e5, 0.35);
    auto b = backend(p, RotationMethod::Svd);
    const Eigen::VectorXd x = deform(p.mesh, Shape::WellShaped, rng);
    b->setPositions(x);
    Eigen::VectorXd f;
    b->internalForces(f);
    Eigen::VectorXd ref(f.size());
    double energy = 0;
    for (std::size_t e = 0; e < n; ++e) {
      const auto xe = corners(x, p.mesh, e);
      const auto Xe = corners(p.restPositions, p.mesh, e);
      const Mat3 R = detail::polarRotation(detail::deformationGradient(p.elements[e], xe));
      const detail::Mat12 K = detail::linearStiffness(p.elements[e], p.lame);
      const detail::Vec12 fe = detail::corotationalForce(K, R, xe, Xe);
      for (int k = 0; k < 4; ++k) ref.segment<3>(3 * p.mesh.tets[4 * e + k]) = fe.segment<3>(3 * k);
      energy += detail::corotationalEnergy(K, R, xe, Xe);
    }
    const double scale = ref.cwiseAbs().maxCoeff();
    ASSERT_GT(scale, 0.0);
    EXPECT_LE((f - ref).cwiseAbs().maxCoeff(), relTol() * scale) << n << " elements";
    if (n == 1001) std::printf("[info] forces: max error / max |f| = %.3g\n", (f - ref).cwiseAbs().maxCoeff() / scale);
    EXPECT_NEAR(b->elasticEnergy(), energy, relTol() * energy) << n << " elements";
  }
}

TEST_P(OpenCLKernels, EveryVectorWidthGivesTheSameOperators) {
  // The element kernels process COROFEM_VEC elements per work-item (1 on GPUs, 8 on CPUs by
  // default); every width must give the same forces and products (97: not a multiple of any).
  COROFEM_REQUIRE_OPENCL_DEVICE(GetParam());
  std::mt19937 rng(31);
  const detail::Problem p = test::makeProblem(test::randomSoup(97, rng));
  const Eigen::VectorXd x = deform(p.mesh, Shape::WellShaped, rng);
  Eigen::VectorXd v(x.size());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (Eigen::Index i = 0; i < v.size(); ++i) v[i] = u(rng);
  Eigen::VectorXd f1, y1;
  for (std::size_t width : {1, 8, 16}) {
    detail::OpenCLTuning o;
    o.elementsPerItem = width;
    // Width 1 as on GPUs (local-memory tree reductions), the program test_backend.cpp also builds.
    o.nodesPerItem = width == 1 ? 1 : 0;
    o.workGroupSums = width == 1 ? 1 : -1;
    auto b = backend(p, RotationMethod::Polar, o);  // Polar: scalar at width 1, vectorised above
    b->setPositions(x);
    Eigen::VectorXd f, y;
    b->internalForces(f);
    b->apply({2.0, 0.0, 1.0}, v, y);
    if (width == 1) {
      f1 = f;
      y1 = y;
      continue;
    }
    // Same arithmetic per lane: equal up to contraction differences of the compiler.
    EXPECT_LE((f - f1).cwiseAbs().maxCoeff(), relTol() * f1.cwiseAbs().maxCoeff()) << "width " << width;
    EXPECT_LE((y - y1).cwiseAbs().maxCoeff(), relTol() * y1.cwiseAbs().maxCoeff()) << "width " << width;
  }
}

INSTANTIATE_TEST_SUITE_P(Devices, OpenCLKernels, ::testing::ValuesIn(test::deviceCases()), test::caseName);

}  // namespace
}  // namespace corofem
