// The reference backend: plain Eigen, double precision, assembled sparse matrices. It is the
// oracle the device backends are tested against, so it favours clarity over speed.
//
// Precision: SolverDesc::precision == Float is accepted and ignored; this backend always computes
// in double (it is the yardstick the float paths are measured against).
// Rotation: every RotationMethod is computed here by the SVD-based polar decomposition
// (polarRotation); the cheaper methods are device-backend variants measured against it.
#include "backends/reference/block_jacobi.hpp"
#include "model/hyperelastic.hpp"
#include "solve/backend.hpp"
#include "util/error.hpp"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <algorithm>
#include <cmath>
#include <type_traits>

namespace corofem::detail {

namespace {

using SpMat = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

bool isHyperelastic(Formulation f) {
  return f == Formulation::StVenantKirchhoff || f == Formulation::NeoHookean;
}

class ReferenceBackend final : public Backend {
 public:
  ReferenceBackend(const Problem& problem, const SolverDesc& solver) : p_(problem), solver_(solver) {
    const std::size_t ne = p_.elements.size();
    if (p_.mesh.tetCount() != ne)
      fail(ErrorCode::Internal, "reference backend: problem '", p_.name, "' has ", ne, " element records for ",
           p_.mesh.tetCount(), " tetrahedra");
    if (static_cast<std::size_t>(p_.lumpedMass.size()) != p_.dofCount() || p_.constrained.size() != p_.dofCount())
      fail(ErrorCode::Internal, "reference backend: problem '", p_.name, "' has inconsistent dof arrays");
    hyper_ = isHyperelastic(p_.formulation);
    if (hyper_) model_ = hyperelasticModelOf(p_.formulation);
    restNodes_.resize(ne);
    for (std::size_t e = 0; e < ne; ++e) restNodes_[e] = gather(p_.restPositions, e);
    if (!hyper_) {
      stiffness_.resize(ne);
      for (std::size_t e = 0; e < ne; ++e) stiffness_[e] = linearStiffness(p_.elements[e], p_.lame);
    }
    rotations_.assign(ne, Mat3::Identity());
    gradients_.assign(ne, Mat3::Identity());
    x_ = p_.restPositions;
    tangentsValid_ = false;
    buildPattern();
  }

  std::string name() const override { return "reference"; }
  std::string deviceName() const override { return "host (Eigen, double)"; }

  void setPositions(const Eigen::VectorXd& x) override {
    checkSize(x, "setPositions");
    x_ = x;
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      const Mat3 F = deformationGradient(p_.elements[e], gather(x_, e));
      gradients_[e] = F;
      // Co-rotational: R = rotational part of F (polar decomposition). Linear: R = I.
      rotations_[e] = p_.formulation == Formulation::Corotational ? polarRotation(F) : Mat3::Identity();
    }
    tangentsValid_ = false;
  }

  void internalForces(Eigen::VectorXd& f) override {
    f.setZero(static_cast<Eigen::Index>(p_.dofCount()));
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      Vec12 fe;
      if (hyper_) {
        checkInversion(e);
        fe = hyperelasticForce(model_, p_.elements[e], p_.lame, gradients_[e]);
      } else {
        fe = corotationalForce(stiffness_[e], rotations_[e], gather(x_, e), restNodes_[e]);  // Eq. 9
      }
      scatterAdd(f, e, fe);
    }
  }

  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override {
    checkSize(p, "apply");
    ensureTangents();
    const double massScale = c.mass + c.damping * p_.rayleighMass;
    const double stiffScale = c.stiffness + c.damping * p_.rayleighStiffness;
    // y = (m + c alpha) M p + (k + c beta) K_t p, M lumped (diagonal), K_t by element loops.
    y = massScale * p_.lumpedMass.cwiseProduct(p);
    if (stiffScale == 0.0) return;
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      Vec12 pe;
      for (int k = 0; k < 4; ++k) pe.segment<3>(3 * k) = p.segment<3>(3 * node(e, k));
      scatterAdd(y, e, stiffScale * (tangents_[e] * pe));
    }
  }

  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    checkSize(b, "solve (right-hand side)");
    if (!b.allFinite())
      fail(ErrorCode::SolveFailed, "reference backend: the right-hand side of the linear system has non-finite "
           "entries (the state diverged; try a smaller time step or load increment)");
    if (x.size() != b.size()) x = Eigen::VectorXd::Zero(b.size());
    assemble(c);

    const Eigen::Index nf = static_cast<Eigen::Index>(freeDofs_.size());
    if (nf == 0) {  // everything constrained: nothing to solve
      x.setZero();
      LinearSolveStats none;
      none.converged = true;
      return none;
    }
    Eigen::VectorXd bf(nf), xf(nf);
    for (Eigen::Index i = 0; i < nf; ++i) {
      bf[i] = b[freeDofs_[static_cast<std::size_t>(i)]];
      xf[i] = x[freeDofs_[static_cast<std::size_t>(i)]];
    }
    if (!xf.allFinite()) xf.setZero();  // a non-finite warm start is useless, not fatal

    LinearSolveStats stats;
    if (solver_.linearSolver == LinearSolverKind::Cholesky) {
      // LDL^T, not LL^T: the hyperelastic tangents become indefinite near buckling and still factor.
      if (!analyzed_) {
        ldlt_.analyzePattern(A_);
        analyzed_ = true;
      }
      ldlt_.factorize(A_);
      if (ldlt_.info() == Eigen::Success) {
        xf = ldlt_.solve(bf);
        stats.iterations = 0;
        stats.converged = true;
      } else {
        stats.converged = false;  // singular: x keeps the warm start, the stats say it failed
      }
    } else {
      switch (solver_.preconditioner) {
        case PreconditionerKind::None:
          stats = runCg<Eigen::IdentityPreconditioner>(bf, xf, nullptr);
          break;
        case PreconditionerKind::Diagonal:
          stats = runCg<Eigen::DiagonalPreconditioner<double>>(bf, xf, nullptr);
          break;
        case PreconditionerKind::BlockDiagonal:
          stats = runCg<BlockJacobiPreconditioner>(bf, xf, &blockStarts_);
          break;
      }
    }
    if (!xf.allFinite())
      fail(ErrorCode::SolveFailed, "reference backend: the linear solve produced non-finite values (",
           solver_.linearSolver == LinearSolverKind::Cholesky ? "LDL^T" : "PCG",
           "); the system matrix is probably singular or the state diverged");

    // True residual on the free dofs (not the solver's recurrence estimate).
    const double bNorm = bf.norm();
    stats.relativeResidual = bNorm > 0.0 ? (bf - A_ * xf).norm() / bNorm : (A_ * xf).norm();
    if (solver_.linearSolver == LinearSolverKind::Cholesky)
      stats.converged = stats.converged && stats.relativeResidual <= std::max(solver_.tolerance, 1e-8);

    x.setZero();
    for (Eigen::Index i = 0; i < nf; ++i) x[freeDofs_[static_cast<std::size_t>(i)]] = xf[i];
    return stats;
  }

  double elasticEnergy() override {
    double energy = 0.0;
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      if (hyper_)
        energy += hyperelasticEnergy(model_, p_.elements[e], p_.lame, gradients_[e]);
      else  // 1/2 u^T K u, u = R^T x - X (R = I for the linear formulation)
        energy += corotationalEnergy(stiffness_[e], rotations_[e], gather(x_, e), restNodes_[e]);
    }
    return energy;
  }

 private:
  Eigen::Index node(std::size_t e, int k) const { return static_cast<Eigen::Index>(p_.mesh.tets[4 * e + k]); }

  std::array<Vec3d, 4> gather(const Eigen::VectorXd& v, std::size_t e) const {
    std::array<Vec3d, 4> out;
    for (int k = 0; k < 4; ++k) out[k] = v.segment<3>(3 * node(e, k));
    return out;
  }

  void scatterAdd(Eigen::VectorXd& v, std::size_t e, const Vec12& fe) const {
    for (int k = 0; k < 4; ++k) v.segment<3>(3 * node(e, k)) += fe.segment<3>(3 * k);
  }

  void checkSize(const Eigen::VectorXd& v, const char* what) const {
    if (static_cast<std::size_t>(v.size()) != p_.dofCount())
      fail(ErrorCode::Internal, "reference backend ", what, ": vector of size ", v.size(), " for ", p_.dofCount(),
           " dofs");
  }

  void checkInversion(std::size_t e) const {
    if (model_ == HyperelasticModel::NeoHookean && !(gradients_[e].determinant() > 0.0))
      fail(ErrorCode::SolveFailed, "body '", p_.name, "': element ", e, " (nodes ", node(e, 0), ", ", node(e, 1), ", ",
           node(e, 2), ", ", node(e, 3), ") is inverted (det F = ", gradients_[e].determinant(),
           "); the Neo-Hookean energy is undefined there. Use smaller load increments or time steps");
  }

  /// Element tangents at the current positions: R K R^T (Eq. 11), K (linear) or the consistent
  /// hyperelastic tangent.
  void ensureTangents() {
    if (tangentsValid_) return;
    tangents_.resize(p_.elements.size());
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      if (hyper_) {
        checkInversion(e);
        tangents_[e] = hyperelasticTangent(model_, p_.elements[e], p_.lame, gradients_[e]);
      } else if (p_.formulation == Formulation::Corotational) {
        tangents_[e] = rotateStiffness(stiffness_[e], rotations_[e]);
      } else {
        tangents_[e] = stiffness_[e];
      }
    }
    tangentsValid_ = true;
  }

  /// The sparsity pattern of A on the free dofs is fixed by the mesh and the constraints: built once
  /// here, with the position in A's value array of every (element, row, col) entry, so that each
  /// assembly only refills values.
  void buildPattern() {
    const std::size_t n = p_.dofCount();
    freeIndex_.assign(n, -1);
    freeDofs_.clear();
    blockStarts_.clear();
    for (std::size_t d = 0; d < n; ++d) {
      if (p_.constrained[d]) continue;
      if (blockStarts_.empty() || d / 3 != static_cast<std::size_t>(freeDofs_.back()) / 3)
        blockStarts_.push_back(static_cast<int>(freeDofs_.size()));  // a new node's block begins
      freeIndex_[d] = static_cast<int>(freeDofs_.size());
      freeDofs_.push_back(static_cast<Eigen::Index>(d));
    }
    blockStarts_.push_back(static_cast<int>(freeDofs_.size()));
    const int nf = static_cast<int>(freeDofs_.size());

    std::vector<Eigen::Triplet<double, int>> triplets;
    triplets.reserve(p_.elements.size() * 144 + static_cast<std::size_t>(nf));
    for (int i = 0; i < nf; ++i) triplets.emplace_back(i, i, 0.0);  // mass diagonal
    for (std::size_t e = 0; e < p_.elements.size(); ++e)
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b) {
          const int r = freeIndex_[static_cast<std::size_t>(3 * node(e, a / 3) + a % 3)];
          const int c = freeIndex_[static_cast<std::size_t>(3 * node(e, b / 3) + b % 3)];
          if (r >= 0 && c >= 0) triplets.emplace_back(r, c, 0.0);
        }
    A_.resize(nf, nf);
    A_.setFromTriplets(triplets.begin(), triplets.end());
    A_.makeCompressed();

    const auto slotOf = [&](int r, int c) {
      const int* begin = A_.innerIndexPtr() + A_.outerIndexPtr()[c];
      const int* end = A_.innerIndexPtr() + A_.outerIndexPtr()[c + 1];
      return static_cast<int>(std::lower_bound(begin, end, r) - A_.innerIndexPtr());
    };
    diagSlot_.resize(static_cast<std::size_t>(nf));
    for (int i = 0; i < nf; ++i) diagSlot_[static_cast<std::size_t>(i)] = slotOf(i, i);
    elementSlots_.assign(p_.elements.size() * 144, -1);
    for (std::size_t e = 0; e < p_.elements.size(); ++e)
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b) {
          const int r = freeIndex_[static_cast<std::size_t>(3 * node(e, a / 3) + a % 3)];
          const int c = freeIndex_[static_cast<std::size_t>(3 * node(e, b / 3) + b % 3)];
          if (r >= 0 && c >= 0) elementSlots_[e * 144 + static_cast<std::size_t>(12 * a + b)] = slotOf(r, c);
        }
  }

  /// A = (m + c alpha) M + (k + c beta) K_t restricted to the free dofs (x_c = 0).
  void assemble(const SystemCoeffs& c) {
    ensureTangents();
    const double massScale = c.mass + c.damping * p_.rayleighMass;
    const double stiffScale = c.stiffness + c.damping * p_.rayleighStiffness;
    double* values = A_.valuePtr();
    std::fill(values, values + A_.nonZeros(), 0.0);
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      const int* slots = &elementSlots_[e * 144];
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b)
          if (slots[12 * a + b] >= 0) values[slots[12 * a + b]] += stiffScale * tangents_[e](a, b);
    }
    for (std::size_t i = 0; i < freeDofs_.size(); ++i)
      values[diagSlot_[i]] += massScale * p_.lumpedMass[freeDofs_[i]];
  }

  template <class Precond>
  LinearSolveStats runCg(const Eigen::VectorXd& bf, Eigen::VectorXd& xf, const std::vector<int>* blocks) {
    Eigen::ConjugateGradient<SpMat, Eigen::Lower | Eigen::Upper, Precond> cg;
    if constexpr (std::is_same_v<Precond, BlockJacobiPreconditioner>) cg.preconditioner().setBlocks(*blocks);
    cg.setTolerance(solver_.tolerance);
    cg.setMaxIterations(solver_.maxIterations);
    cg.compute(A_);
    xf = cg.solveWithGuess(bf, xf);
    LinearSolveStats stats;
    stats.iterations = static_cast<int>(cg.iterations());
    stats.converged = cg.info() == Eigen::Success;
    return stats;
  }

  Problem p_;  // a copy: the backend stays valid whatever happens to the caller's problem
  SolverDesc solver_;
  bool hyper_ = false;
  HyperelasticModel model_ = HyperelasticModel::StVenantKirchhoff;
  std::vector<std::array<Vec3d, 4>> restNodes_;
  std::vector<Mat12> stiffness_;  ///< K_e (linear, co-rotational)
  std::vector<Mat3> rotations_;   ///< R_e at the current positions
  std::vector<Mat3> gradients_;   ///< F_e at the current positions
  std::vector<Mat12> tangents_;   ///< element tangents, valid when tangentsValid_
  bool tangentsValid_ = false;
  Eigen::VectorXd x_;

  std::vector<int> freeIndex_;           ///< dof -> free index or -1
  std::vector<Eigen::Index> freeDofs_;   ///< free index -> dof
  std::vector<int> blockStarts_;         ///< per-node blocks of the free dofs (block Jacobi)
  std::vector<int> elementSlots_;        ///< 144 per element: index into A_'s values, -1 if constrained
  std::vector<int> diagSlot_;
  SpMat A_;
  Eigen::SimplicialLDLT<SpMat, Eigen::Lower> ldlt_;
  bool analyzed_ = false;
};

}  // namespace

std::unique_ptr<Backend> createReferenceBackend(const Problem& problem, const SolverDesc& solver) {
  return std::make_unique<ReferenceBackend>(problem, solver);
}

}  // namespace corofem::detail
