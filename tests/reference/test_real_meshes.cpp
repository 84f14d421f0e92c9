// The reference backend on the shared real meshes (irregular, unstructured): patch test, rigid
// motions, and LDL^T on an indefinite hyperelastic tangent.
#include "small_meshes.hpp"
#include "common/test_data.hpp"

#include "model/hyperelastic.hpp"
#include "common/body_backend.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <map>

using namespace corofem;
using namespace corofem::detail;

namespace {

TetMesh readMesh(const std::string& rel) {
  Result<TetMesh> mesh = readTetMesh(test::dataPath(rel));
  EXPECT_TRUE(mesh.isOk()) << mesh.message();
  return mesh.isOk() ? std::move(mesh).value() : TetMesh{};
}

/// Nodes on the surface: those of tet faces that belong to exactly one tet.
std::vector<std::uint8_t> boundaryNodes(const TetMesh& mesh) {
  std::map<std::array<std::uint32_t, 3>, int> faces;
  const int local[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  for (std::size_t e = 0; e < mesh.tetCount(); ++e)
    for (const auto& f : local) {
      std::array<std::uint32_t, 3> key = {mesh.tets[4 * e + f[0]], mesh.tets[4 * e + f[1]], mesh.tets[4 * e + f[2]]};
      std::sort(key.begin(), key.end());
      ++faces[key];
    }
  std::vector<std::uint8_t> onBoundary(mesh.nodeCount(), 0);
  for (const auto& [key, count] : faces)
    if (count == 1)
      for (std::uint32_t n : key) onBoundary[n] = 1;
  return onBoundary;
}

}  // namespace

TEST(RealMeshes, PatchTestOnTheLiver) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver.msh");
  const TetMesh mesh = readMesh("meshes/sofa/liver.msh");
  ASSERT_EQ(mesh.tetCount(), 596u);
  Problem p = test::makeProblem(mesh, 3e3, 0.45, 1000.0, Formulation::Linear);
  const auto onBoundary = boundaryNodes(mesh);
  Mat3 G;
  G << 2e-3, -1e-3, 5e-4, 3e-4, 1e-3, -2e-3, 1e-3, 4e-4, -5e-4;
  const Vec3d t(0.01, 0.02, -0.03);
  PrescribedDisplacement pd;
  std::size_t interior = 0;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
    if (!onBoundary[n]) {
      ++interior;
      continue;
    }
    const Vec3d u = G * p.restPositions.segment<3>(3 * n) + t;
    for (int c = 0; c < 3; ++c) {
      pd.dofs.push_back(static_cast<std::uint32_t>(3 * n + c));
      pd.values.push_back(u[c]);
      p.constrained[3 * n + c] = 1;
    }
  }
  ASSERT_GT(interior, 10u);
  p.prescribed.push_back(pd);
  for (LinearSolverKind kind : {LinearSolverKind::Cholesky, LinearSolverKind::Pcg}) {
    SolverDesc s;
    s.linearSolver = kind;
    s.tolerance = 1e-13;
    s.maxIterations = 10000;
    auto backend = test::createReferenceBackend(p, s);
    Eigen::VectorXd x = p.restPositions;
    p.applyPrescribed(x, 1.0, false);
    backend->setPositions(x);
    Eigen::VectorXd f, dx = Eigen::VectorXd::Zero(x.size());
    backend->internalForces(f);
    const LinearSolveStats st = backend->solve({0, 0, 1}, -f, dx);
    EXPECT_TRUE(st.converged);
    x += dx;
    // Coordinates O(5), displacements O(1e-2): the field is reproduced to rounding amplified by the
    // conditioning of this irregular mesh (1e-9 absolute, i.e. 1e-7 of the displacement).
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      const Vec3d X = p.restPositions.segment<3>(3 * n);
      EXPECT_LT((x.segment<3>(3 * n) - (X + G * X + t)).norm(), 1e-9) << "node " << n;
    }
  }
}

TEST(RealMeshes, RigidRotationOfTheBarHasNoCorotationalForce) {
  COROFEM_REQUIRE_DATA("meshes/ipc/bar-651.msh");
  const TetMesh mesh = readMesh("meshes/ipc/bar-651.msh");
  const double E = 1e7;
  for (Formulation form : {Formulation::Corotational, Formulation::Linear}) {
    const Problem p = test::makeProblem(mesh, E, 0.3, 1000.0, form);
    auto backend = test::createReferenceBackend(p, SolverDesc{});
    for (const Vec3d& axis : {Vec3d::UnitX(), Vec3d::UnitY(), Vec3d::UnitZ()}) {
      const Mat3 Q = test::rotation(axis, M_PI);
      Eigen::VectorXd x(p.restPositions.size());
      for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
        x.segment<3>(3 * n) = Q * p.restPositions.segment<3>(3 * n) + Vec3d(1.0, 2.0, 3.0);
      backend->setPositions(x);
      Eigen::VectorXd f;
      backend->internalForces(f);
      // Elements of the bar are ~0.3 m across: force scale E * 0.1 m^2; coordinates O(10) m so
      // rounding gives ~1e-14 relative per element, summed over a few hundred: 1e-11.
      const double scale = E * 0.1;
      if (form == Formulation::Corotational)
        EXPECT_LT(f.lpNorm<Eigen::Infinity>(), 1e-11 * scale);
      else
        EXPECT_GT(f.lpNorm<Eigen::Infinity>(), 0.1 * scale);
    }
  }
}

TEST(RealMeshes, LdltFactorsAnIndefiniteSvkTangent) {
  // St. Venant-Kirchhoff under strong uniaxial compression (F = diag(0.4, 1, 1)) loses stiffness in
  // the compressed direction: the tangent becomes indefinite. LDL^T must still solve the system
  // (PCG is not expected to).
  Problem p = test::makeProblem(test::boxMesh(2, 2, 2, 1.0, 1.0, 1.0, 0.15, 8), 1e5, 0.3, 1000.0,
                                Formulation::StVenantKirchhoff);
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (p.mesh.nodes[3 * n] == 0.0) p.constrained[3 * n] = p.constrained[3 * n + 1] = p.constrained[3 * n + 2] = 1;
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) x[3 * n] *= 0.4;
  SolverDesc s;
  s.linearSolver = LinearSolverKind::Cholesky;
  auto backend = test::createReferenceBackend(p, s);
  backend->setPositions(x);

  // The free-dof tangent (dense, from apply on unit vectors) is indeed indefinite.
  std::vector<Eigen::Index> freeDofs;
  for (std::size_t d = 0; d < p.dofCount(); ++d)
    if (!p.constrained[d]) freeDofs.push_back(static_cast<Eigen::Index>(d));
  const auto nf = static_cast<Eigen::Index>(freeDofs.size());
  Eigen::MatrixXd K(nf, nf);
  for (Eigen::Index j = 0; j < nf; ++j) {
    Eigen::VectorXd e = Eigen::VectorXd::Zero(x.size()), y;
    e[freeDofs[static_cast<std::size_t>(j)]] = 1.0;
    backend->apply({0, 0, 1}, e, y);
    for (Eigen::Index i = 0; i < nf; ++i) K(i, j) = y[freeDofs[static_cast<std::size_t>(i)]];
  }
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(K).eigenvalues();
  ASSERT_LT(ev.minCoeff(), -1e-3 * ev.maxCoeff()) << "the test state is not indefinite";

  const Eigen::VectorXd b = Eigen::VectorXd::Random(x.size());
  Eigen::VectorXd sol = Eigen::VectorXd::Zero(x.size());
  const LinearSolveStats st = backend->solve({0, 0, 1}, b, sol);
  EXPECT_TRUE(st.converged);
  EXPECT_LT(st.relativeResidual, 1e-8);  // direct solve; the matrix is indefinite but not near-singular
  Eigen::VectorXd bf(nf), xf(nf);
  for (Eigen::Index i = 0; i < nf; ++i) {
    bf[i] = b[freeDofs[static_cast<std::size_t>(i)]];
    xf[i] = sol[freeDofs[static_cast<std::size_t>(i)]];
  }
  EXPECT_LT((K * xf - bf).norm(), 1e-8 * bf.norm());
}
