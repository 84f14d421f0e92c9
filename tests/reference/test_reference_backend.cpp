// The reference backend: products against a dense assembly, PCG against LDL^T, constraints, warm
// starts, rigid motions of a whole mesh and the patch test.
#include "small_meshes.hpp"

#include "model/hyperelastic.hpp"
#include "common/body_backend.hpp"
#include "common/random_vector.hpp"
#include "solve/device_slot.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <limits>

using namespace corofem;
using namespace corofem::detail;
using corofem::test::boxMesh;
using corofem::test::elementNodes;
using corofem::test::makeProblem;

namespace corofem {
/// How GoogleTest (and so CTest's test list) prints a formulation: its name.
inline void PrintTo(Formulation f, std::ostream* os) { *os << toString(f); }

}  // namespace corofem

namespace {

/// Dense tangent of the whole mesh, assembled here from the element functions (independent of the
/// backend's sparse pattern and slot bookkeeping).
Eigen::MatrixXd denseTangent(const Problem& p, const Eigen::VectorXd& x) {
  const auto n = static_cast<Eigen::Index>(p.dofCount());
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(n, n);
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    const Mat3 F = deformationGradient(p.elements[e], elementNodes(p, x, e));
    Mat12 Ke;
    switch (p.formulation) {
      case Formulation::Linear: Ke = linearStiffness(p.elements[e], p.lame); break;
      case Formulation::Corotational:
        Ke = rotateStiffness(linearStiffness(p.elements[e], p.lame), polarRotation(F));
        break;
      default: Ke = hyperelasticTangent(hyperelasticModelOf(p.formulation), p.elements[e], p.lame, F);
    }
    for (int a = 0; a < 12; ++a)
      for (int b = 0; b < 12; ++b)
        K(3 * p.mesh.tets[4 * e + a / 3] + a % 3, 3 * p.mesh.tets[4 * e + b / 3] + b % 3) += Ke(a, b);
  }
  return K;
}

Eigen::VectorXd randomDeformation(const Problem& p, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  Eigen::VectorXd x = p.restPositions;
  for (Eigen::Index i = 0; i < x.size(); ++i) x[i] += u(rng);
  return x;
}

void fixPlane(Problem& p, int axis, double value) {
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
    if (std::abs(p.mesh.nodes[3 * n + axis] - value) < 1e-12)
      for (int c = 0; c < 3; ++c) p.constrained[3 * n + c] = 1;
}

SolverDesc solverDesc(LinearSolverKind kind, PreconditionerKind pre = PreconditionerKind::Diagonal,
                      double tol = 1e-12) {
  SolverDesc s;
  s.linearSolver = kind;
  s.preconditioner = pre;
  s.tolerance = tol;
  s.maxIterations = 5000;
  return s;
}

}  // namespace

class ReferenceBackendByFormulation : public ::testing::TestWithParam<Formulation> {};

TEST_P(ReferenceBackendByFormulation, ApplyEqualsDenseAssembly) {
  Problem p = makeProblem(boxMesh(2, 2, 3, 1.0, 1.0, 1.5, 0.2, 4), 1e5, 0.3, 1000.0, GetParam());
  p.rayleighMass = 0.3;
  p.rayleighStiffness = 0.01;
  auto backend = test::createReferenceBackend(p, SolverDesc{});
  const Eigen::VectorXd x = randomDeformation(p, 0.05, 1);
  backend->setPositions(x);
  const Eigen::MatrixXd K = denseTangent(p, x);
  const SystemCoeffs c{2.0, 0.5, 1.5};
  const Eigen::MatrixXd A = (c.mass + c.damping * p.rayleighMass) * Eigen::MatrixXd(p.lumpedMass.asDiagonal()) +
                            (c.stiffness + c.damping * p.rayleighStiffness) * K;
  const Eigen::VectorXd v = Eigen::VectorXd::Random(static_cast<Eigen::Index>(p.dofCount()));
  Eigen::VectorXd y;
  backend->apply(c, v, y);
  // Same sums in a different order: rounding, 1e-12 relative.
  EXPECT_LT((y - A * v).norm(), 1e-12 * (A * v).norm());
  // The symmetric tangent of every formulation.
  EXPECT_LT((K - K.transpose()).norm(), 1e-12 * K.norm());

  // Internal forces equal the element functions summed.
  Eigen::VectorXd f;
  backend->internalForces(f);
  Eigen::VectorXd expected = Eigen::VectorXd::Zero(f.size());
  for (std::size_t e = 0; e < p.elements.size(); ++e) {
    const auto xe = elementNodes(p, x, e), Xe = elementNodes(p, p.restPositions, e);
    const Mat3 F = deformationGradient(p.elements[e], xe);
    Vec12 fe;
    if (GetParam() == Formulation::Linear || GetParam() == Formulation::Corotational) {
      const Mat3 R = GetParam() == Formulation::Linear ? Mat3::Identity() : polarRotation(F);
      fe = corotationalForce(linearStiffness(p.elements[e], p.lame), R, xe, Xe);
    } else {
      fe = hyperelasticForce(hyperelasticModelOf(GetParam()), p.elements[e], p.lame, F);
    }
    for (int k = 0; k < 4; ++k) expected.segment<3>(3 * p.mesh.tets[4 * e + k]) += fe.segment<3>(3 * k);
  }
  EXPECT_LT((f - expected).norm(), 1e-12 * expected.norm());
  EXPECT_GT(backend->elasticEnergy(), 0.0);
}

TEST_P(ReferenceBackendByFormulation, PcgAndCholeskyAgreeAndRespectConstraints) {
  Problem p = makeProblem(boxMesh(2, 2, 4, 0.5, 0.5, 1.0, 0.2, 5), 1e5, 0.3, 1000.0, GetParam());
  fixPlane(p, 2, 0.0);
  const Eigen::VectorXd x = randomDeformation(p, 0.01, 2);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(static_cast<Eigen::Index>(p.dofCount()));
  const SystemCoeffs c{1.0, 0.0, 1.0};  // a dynamics-like system, SPD for every formulation here

  auto chol = test::createReferenceBackend(p, solverDesc(LinearSolverKind::Cholesky));
  chol->setPositions(x);
  Eigen::VectorXd xc = Eigen::VectorXd::Zero(b.size());
  const LinearSolveStats sc = chol->solve(c, b, xc);
  EXPECT_TRUE(sc.converged);
  EXPECT_EQ(sc.iterations, 0);
  EXPECT_LT(sc.relativeResidual, 1e-12);  // direct solve: rounding times a modest condition number

  for (PreconditionerKind pre : {PreconditionerKind::None, PreconditionerKind::Diagonal,
                                 PreconditionerKind::BlockDiagonal, PreconditionerKind::Amg,
                                 PreconditionerKind::WarpedCholesky}) {
    auto pcg = test::createReferenceBackend(p, solverDesc(LinearSolverKind::Pcg, pre, 1e-10));
    pcg->setPositions(x);
    Eigen::VectorXd xp = Eigen::VectorXd::Constant(b.size(), 3.0);  // constrained entries must come back 0
    const LinearSolveStats sp = pcg->solve(c, b, xp);
    EXPECT_TRUE(sp.converged) << static_cast<int>(pre);
    EXPECT_GT(sp.iterations, 0);
    // The true residual; Eigen's CG stops on its recurrence residual, which drifts slightly from it.
    EXPECT_LT(sp.relativeResidual, 1e-9);
    // Error <= condition number * residual: 1e-10 * (cond ~ 1e3 here) with margin.
    EXPECT_LT((xp - xc).norm(), 1e-6 * xc.norm()) << static_cast<int>(pre);
    for (std::size_t d = 0; d < p.dofCount(); ++d)
      if (p.constrained[d]) {
        EXPECT_EQ(xp[static_cast<Eigen::Index>(d)], 0.0);
        EXPECT_EQ(xc[static_cast<Eigen::Index>(d)], 0.0);
      }

    // Warm start from the exact (Cholesky) solution: converged at once (0 or 1 iterations).
    Eigen::VectorXd warm = xc;
    const LinearSolveStats sw = pcg->solve(c, b, warm);
    EXPECT_TRUE(sw.converged);
    EXPECT_LE(sw.iterations, 1);
  }

  // The free-dof residual of the Cholesky solution, checked with apply() (constrained rows ignored).
  Eigen::VectorXd Ax;
  chol->apply(c, xc, Ax);
  Eigen::VectorXd r = b - Ax;
  for (std::size_t d = 0; d < p.dofCount(); ++d)
    if (p.constrained[d]) r[static_cast<Eigen::Index>(d)] = 0.0;
  EXPECT_LT(r.norm(), 1e-10 * b.norm());
}

INSTANTIATE_TEST_SUITE_P(AllFormulations, ReferenceBackendByFormulation,
                         ::testing::Values(Formulation::Linear, Formulation::Corotational,
                                           Formulation::StVenantKirchhoff, Formulation::NeoHookean),
                         [](const auto& info) {
                           switch (info.param) {
                             case Formulation::Linear: return std::string("Linear");
                             case Formulation::Corotational: return std::string("Corotational");
                             case Formulation::StVenantKirchhoff: return std::string("StVenantKirchhoff");
                             case Formulation::NeoHookean: return std::string("NeoHookean");
                           }
                           return std::string("Unknown");
                         });

TEST(ReferenceBackend, NameZeroRhsAndNonFinite) {
  Problem p = makeProblem(boxMesh(1, 1, 1), 1e5, 0.3, 1000.0, Formulation::Corotational);
  fixPlane(p, 0, 0.0);
  SolverDesc s;
  s.precision = Precision::Float;  // accepted: the reference backend computes in double anyway
  auto backend = test::createReferenceBackend(p, s);
  EXPECT_EQ(backend->name(), "reference");
  EXPECT_EQ(backend->deviceName(), "host (Eigen, double)");
  backend->setPositions(p.restPositions);
  Eigen::VectorXd x = Eigen::VectorXd::Ones(static_cast<Eigen::Index>(p.dofCount()));
  const LinearSolveStats st = backend->solve({0, 0, 1}, Eigen::VectorXd::Zero(x.size()), x);
  EXPECT_TRUE(st.converged);
  EXPECT_EQ(st.relativeResidual, 0.0);
  EXPECT_EQ(x.norm(), 0.0);

  Eigen::VectorXd bad = Eigen::VectorXd::Zero(x.size());
  bad[5] = std::nan("");
  try {
    backend->solve({0, 0, 1}, bad, x);
    ADD_FAILURE() << "no error for a NaN right-hand side";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
  }
}

TEST(ReferenceBackend, RigidMotionOfAMeshHasNoCorotationalForce) {
  const TetMesh mesh = boxMesh(2, 2, 2, 1.0, 0.5, 0.7, 0.2, 9);
  std::mt19937 rng(31);
  std::vector<Mat3> rotations = {test::rotation(Vec3d::UnitX(), M_PI), test::rotation(Vec3d::UnitY(), M_PI),
                                 test::rotation(Vec3d::UnitZ(), M_PI), test::randomRotation(rng)};
  const double E = 1e5;
  for (Formulation form : {Formulation::Corotational, Formulation::Linear, Formulation::StVenantKirchhoff,
                           Formulation::NeoHookean}) {
    const Problem p = makeProblem(mesh, E, 0.3, 1000.0, form);
    auto backend = test::createReferenceBackend(p, SolverDesc{});
    // Force scale: E times a characteristic area (the box is O(1) m; elements ~ (0.3 m)^2).
    const double forceScale = E * 0.1;
    for (const Mat3& Q : rotations) {
      Eigen::VectorXd x(p.restPositions.size());
      for (std::size_t n = 0; n < mesh.nodeCount(); ++n)
        x.segment<3>(3 * n) = Q * p.restPositions.segment<3>(3 * n) + Vec3d(3.0, -7.0, 2.0);
      backend->setPositions(x);
      Eigen::VectorXd f;
      backend->internalForces(f);
      if (form == Formulation::Linear) {
        EXPECT_GT(f.norm(), 0.1 * forceScale);  // 180-degree or random rotations: O(E L^2) forces
      } else {
        // Rotation invariance (co-rotational and both hyperelastic models): rounding only, with
        // positions O(10) m: 1e-11 relative.
        EXPECT_LT(f.norm(), 1e-11 * forceScale) << static_cast<int>(form);
        EXPECT_LT(std::abs(backend->elasticEnergy()), 1e-9 * forceScale);
      }
    }
  }
}

/// Patch test: a linear displacement field u = G X + t prescribed on the boundary of an irregular
/// mesh is reproduced exactly at the interior nodes, with the constant stress in every element.
TEST(ReferenceBackend, PatchTestLinearAndCorotational) {
  const TetMesh mesh = boxMesh(3, 3, 3, 1.0, 1.0, 1.0, 0.3, 21);
  Mat3 G;
  G << 1e-3, 2e-4, -3e-4, 5e-4, -1e-3, 1e-4, 2e-4, 3e-4, 6e-4;
  const Vec3d t(1e-3, -2e-3, 5e-4);
  for (Formulation form : {Formulation::Linear, Formulation::Corotational}) {
    Problem p = makeProblem(mesh, 2e5, 0.3, 1000.0, form);
    // For the co-rotational formulation the field includes a large rotation: F = Q (I + G).
    const Mat3 Q = form == Formulation::Corotational ? test::rotation(Vec3d(1, 2, 3), 0.8) : Mat3::Identity();
    const Mat3 Ftarget = Q * (Mat3::Identity() + G);
    PrescribedDisplacement pd;
    std::size_t interior = 0;
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      const Vec3d X = p.restPositions.segment<3>(3 * n);
      const bool boundary = (X.array().abs() < 1e-12).any() || ((X.array() - 1.0).abs() < 1e-12).any();
      if (!boundary) {
        ++interior;
        continue;
      }
      const Vec3d u = Ftarget * X + t - X;
      for (int c = 0; c < 3; ++c) {
        pd.dofs.push_back(static_cast<std::uint32_t>(3 * n + c));
        pd.values.push_back(u[c]);
        p.constrained[3 * n + c] = 1;
      }
    }
    ASSERT_EQ(interior, 8u);
    p.prescribed.push_back(pd);
    auto backend = test::createReferenceBackend(p, solverDesc(LinearSolverKind::Cholesky));
    Eigen::VectorXd x = p.restPositions;
    p.applyPrescribed(x, 1.0, false);
    // Newton on f_int(x) = 0 over the free dofs (one step for the linear formulation).
    for (int it = 0; it < 30; ++it) {
      backend->setPositions(x);
      Eigen::VectorXd f, dx = Eigen::VectorXd::Zero(x.size());
      backend->internalForces(f);
      backend->solve({0, 0, 1}, -f, dx);
      x += dx;
      if (dx.norm() < 1e-14) break;
    }
    for (std::size_t n = 0; n < mesh.nodeCount(); ++n) {
      const Vec3d X = p.restPositions.segment<3>(3 * n);
      // Exact reproduction up to rounding of O(1) coordinates through a well-conditioned solve.
      EXPECT_LT((x.segment<3>(3 * n) - (Ftarget * X + t)).norm(), 1e-10) << "node " << n;
    }
    // The constant stress of the field: Hooke's law of the co-rotated strain R^T F - I (R = I linear).
    const Mat3 Rt = form == Formulation::Corotational ? polarRotation(Ftarget) : Mat3::Identity();
    const Mat3 sigma = hookeStress(smallStrain(Rt.transpose() * Ftarget), p.lame);
    for (std::size_t e = 0; e < p.elements.size(); ++e) {
      const Mat3 F = deformationGradient(p.elements[e], elementNodes(p, x, e));
      const Mat3 R = form == Formulation::Corotational ? polarRotation(F) : Mat3::Identity();
      const Mat3 s = hookeStress(smallStrain(R.transpose() * F), p.lame);
      // Stress (~ E * 1e-3 = 200 Pa) from gradients of positions exact to 1e-10 over elements of
      // size ~0.1: 1e-6 relative is rounding with margin.
      EXPECT_LT((s - sigma).norm(), 1e-6 * sigma.norm()) << "element " << e;
    }
    // The free-dof residual vanishes.
    backend->setPositions(x);
    Eigen::VectorXd f;
    backend->internalForces(f);
    for (std::size_t d = 0; d < p.dofCount(); ++d)
      if (p.constrained[d]) f[static_cast<Eigen::Index>(d)] = 0.0;
    EXPECT_LT(f.norm(), 1e-8);  // N; element forces are ~ 200 Pa * 0.01 m^2 = 2 N
  }
}

TEST(ReferenceBackend, InvertedNeoHookeanElementIsASolveFailureNamingIt) {
  Problem p = makeProblem(boxMesh(1, 1, 1), 1e5, 0.3, 1000.0, Formulation::NeoHookean);
  auto backend = test::createReferenceBackend(p, SolverDesc{});
  Eigen::VectorXd x = p.restPositions;
  for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n) x[3 * n + 2] *= -1.0;  // mirror: every element inverted
  backend->setPositions(x);
  EXPECT_EQ(backend->elasticEnergy(), std::numeric_limits<double>::infinity());  // usable by a line search
  Eigen::VectorXd f;
  try {
    backend->internalForces(f);
    ADD_FAILURE() << "no error for inverted Neo-Hookean elements";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
    EXPECT_NE(std::string(e.what()).find("element 0 (nodes"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("inverted"), std::string::npos) << e.what();
  }
  // St. Venant-Kirchhoff stays defined for the same state (finite forces, no error).
  p.formulation = Formulation::StVenantKirchhoff;
  auto svk = test::createReferenceBackend(p, SolverDesc{});
  svk->setPositions(x);
  svk->internalForces(f);
  EXPECT_TRUE(f.allFinite());
}

TEST(ReferenceBackend, ACallOverSeveralBodiesFinishesEveryBodyAndThrowsTheFirstBodysError) {
  // Two equal Neo-Hookean bodies: the device runs a call's bodies across the host's threads, and a
  // body whose element is inverted fails the call with its own error once the others are done.
  const TetMesh mesh = boxMesh(2, 1, 1);
  Problem p0 = makeProblem(mesh, 1e5, 0.3, 1000.0, Formulation::NeoHookean);
  Problem p1 = p0;
  p0.name = "first";
  p1.name = "second";
  auto device = detail::createReferenceDevice({&p0, &p1}, SolverDesc{});
  Eigen::VectorXd mirrored = p0.restPositions;
  for (std::size_t n = 0; n < mesh.nodeCount(); ++n) mirrored[3 * n + 2] *= -1.0;
  const Eigen::VectorXd moved = p0.restPositions + 0.01 * Eigen::VectorXd::Ones(p0.restPositions.size());
  auto errorOf = [&](const Eigen::VectorXd& x0, const Eigen::VectorXd& x1) -> std::string {
    device->setPositions({0, 1}, {&x0, &x1});
    Eigen::VectorXd f0, f1;
    try {
      device->internalForces({0, 1}, {&f0, &f1});
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::SolveFailed);
      if (x0 != mirrored) EXPECT_TRUE(f0.size() == p0.restPositions.size() && f0.allFinite()) << "body 0 was not done";
      if (x1 != mirrored) EXPECT_TRUE(f1.size() == p1.restPositions.size() && f1.allFinite()) << "body 1 was not done";
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(errorOf(moved, moved), "");
  EXPECT_NE(errorOf(moved, mirrored).find("body 'second'"), std::string::npos);
  EXPECT_NE(errorOf(mirrored, mirrored).find("body 'first'"), std::string::npos);
  EXPECT_NE(errorOf(mirrored, moved).find("body 'first'"), std::string::npos);
}

TEST(ReferenceBackend, ABodyLeavesItsDeviceInPlaceAndTheOthersKeepTheirState) {
  // A reference device drops a body without being made again (Device::removeBody): the slot keeps
  // the same device, and the other bodies keep their positions (the same energies, bit for bit)
  // and whatever they had built.
  Problem first = makeProblem(boxMesh(3, 1, 1));
  Problem second = makeProblem(boxMesh(2, 2, 1));
  Problem third = makeProblem(boxMesh(1, 2, 2));
  first.name = "first";
  second.name = "second";
  third.name = "third";
  std::unique_ptr<Device> device = createReferenceDevice({&first, &second, &third}, SolverDesc{});
  const Device* made = device.get();
  DeviceSlot slot(std::move(device), SolverDesc{});
  std::vector<Eigen::VectorXd> x;
  for (const Problem* p : {&first, &second, &third})
    x.push_back(p->restPositions + 0.01 * test::randomVector(p->dofCount(), static_cast<unsigned>(x.size()) + 5));
  slot.setPositions({0, 1, 2}, {&x[0], &x[1], &x[2]});
  std::vector<double> before;
  slot.elasticEnergy({0, 1, 2}, before);
  slot.removeBody(1);
  EXPECT_EQ(&slot.device(), made) << "the device was made again";
  ASSERT_EQ(slot.bodyCount(), 2u);
  EXPECT_EQ(slot.problem(1).name, "third");
  std::vector<double> after;
  slot.elasticEnergy({0, 1}, after);
  EXPECT_EQ(after[0], before[0]);
  EXPECT_EQ(after[1], before[2]);
  EXPECT_GT(after[1], 0.0);
}

TEST(ReferenceBackend, TheEnergyTheForcePassKeepsHasTheBitsOfOneComputedAlone) {
  // internalForces keeps each co-rotational element's energy; elasticEnergy at the same positions
  // sums those. It must give what a device that never evaluated forces gives, and drop them when
  // the positions or the material change.
  Problem p = makeProblem(boxMesh(3, 2, 2, 1.0, 0.5, 0.5, 0.2, 7), 1e5, 0.3, 1000.0, Formulation::Corotational);
  const Eigen::VectorXd x = p.restPositions + 0.05 * test::randomVector(p.dofCount(), 3);
  const Eigen::VectorXd x2 = p.restPositions + 0.05 * test::randomVector(p.dofCount(), 4);
  const auto alone = [&](const Problem& problem, const Eigen::VectorXd& at) {
    auto fresh = test::createReferenceBackend(problem, SolverDesc{});
    fresh->setPositions(at);
    return fresh->elasticEnergy();
  };
  auto backend = test::createReferenceBackend(p, SolverDesc{});
  Eigen::VectorXd f;
  backend->setPositions(x);
  backend->internalForces(f);
  const double kept = backend->elasticEnergy();
  EXPECT_GT(kept, 0.0);
  EXPECT_EQ(kept, alone(p, x)) << "the kept energies' sum";
  EXPECT_EQ(backend->elasticEnergy(), kept) << "asked twice";
  backend->setPositions(x2);
  EXPECT_EQ(backend->elasticEnergy(), alone(p, x2)) << "after new positions";
  backend->internalForces(f);
  Problem stiffer = p;
  stiffer.lame.mu *= 2.0;
  stiffer.lame.lambda *= 2.0;
  backend->device().setMaterial({0}, {&stiffer});
  const double afterMaterial = backend->elasticEnergy();
  EXPECT_EQ(afterMaterial, alone(stiffer, x2)) << "after a material change";
  EXPECT_NE(afterMaterial, alone(p, x2));
}
