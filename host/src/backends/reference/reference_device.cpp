// The reference device: plain Eigen, double precision, assembled sparse matrices, one body after
// another. It is the oracle the device backends are tested against -- their element operations
// and, since it runs the same single-reduction PCG (kernels/opencl/pcg.cl) on the same projected
// system, their iterations -- so it favours clarity over speed. Its per-element passes run on the
// host's threads (kElementChunk); every sum over elements is made in element order, so its answers
// do not depend on the threads.
//
// Precision: SolverDesc::precision is accepted and ignored; this device always computes in double.
// Rotation: every RotationMethod is computed here by the polar decomposition (polarRotation,
// model/element.hpp); the cheaper methods are device variants measured against it.
// The PCG runs on the free dofs of the assembled A (the constrained rows and columns dropped),
// which is the device backends' projected system; its products run on the host's threads
// (kColumnChunk), each entry of A v a sum in the same order whatever the threads.
#include "backends/reference/reference_device.hpp"

#include "backends/reference/block_jacobi.hpp"
#include "precond/amg.hpp"
#include "precond/warped_cholesky.hpp"
#include "device/registry.hpp"
#include "model/hyperelastic.hpp"
#include "util/error.hpp"
#include "util/parallel.hpp"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <algorithm>
#include <cmath>
#include <deque>
#include <exception>
#include <memory>
#include <utility>
#include <vector>

namespace corofem::detail {

namespace {

using SpMat = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

/// The per-element passes (rotations, tangents, element forces and products) run in chunks of this
/// many elements on the host's threads (util/parallel.hpp). Each element's result is its own, and
/// every sum over elements is made afterwards in element order, so the answers have the bits of
/// one thread's pass.
constexpr std::size_t kElementChunk = 1024;

/// The products A v of a body of more free dofs than this run on the host's threads in chunks of
/// kColumnChunk columns (about 45 to 80 entries each in a 3D mesh); a smaller body's run on the
/// calling thread, where waking the pool would cost more than it saves (docs/performance.md).
constexpr std::size_t kSerialColumns = 4096;
constexpr std::size_t kColumnChunk = 1024;

/// One body: its element state at the current positions, its assembled system on the free dofs,
/// and the PCG state of the solve in progress.
class ReferenceBody {
 public:
  ReferenceBody(const Problem& problem, const SolverDesc& solver) : p_(problem), solver_(solver) {
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
    buildPattern();
  }

  const Problem& problem() const { return p_; }

  /// A new material: the element stiffnesses K_e (linear, co-rotational) formed again.
  void setMaterial(const Problem& p) {
    p_.lame = p.lame;
    p_.rayleighMass = p.rayleighMass;
    p_.rayleighStiffness = p.rayleighStiffness;
    if (!hyper_)
      for (std::size_t e = 0; e < stiffness_.size(); ++e) stiffness_[e] = linearStiffness(p_.elements[e], p_.lame);
    tangentsValid_ = false;
    energiesValid_ = false;
    running_ = false;
    amg_.clear();
    cholesky_.clear();
  }

  long long amgBuilds() const { return amg_.builds(); }
  long long choleskyBuilds() const { return cholesky_.builds(); }

  /// New springs (Problem::springStiffness): the next assembly adds them.
  void setSprings(const Problem& p) {
    if (p.springStiffness.size() != 0 && static_cast<std::size_t>(p.springStiffness.size()) != p_.dofCount())
      fail(ErrorCode::Internal, "reference backend: body '", p_.name, "' got ", p.springStiffness.size(),
           " spring stiffnesses for ", p_.dofCount(), " dofs");
    p_.springStiffness = p.springStiffness;
    running_ = false;
  }

  /// New constrained dofs: the free-dof pattern of A is built again (and the direct solve's
  /// analysis redone on its next use).
  void setConstraints(const std::vector<std::uint8_t>& constrained) {
    if (constrained.size() != p_.dofCount())
      fail(ErrorCode::Internal, "reference backend: body '", p_.name, "' got ", constrained.size(),
           " constraint flags for ", p_.dofCount(), " dofs");
    p_.constrained = constrained;
    buildPattern();
    analyzed_ = false;
    running_ = false;  // amg's hierarchy and the warped factor follow at the next solve (ensure: the spare, or a new one)
  }

  void setPositions(const Eigen::VectorXd& x) {
    checkSize(x, "setPositions");
    x_ = x;
    energiesValid_ = false;
    parallelChunks(p_.elements.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) {
        const Mat3 F = deformationGradient(p_.elements[e], gather(x_, e));
        gradients_[e] = F;
        // Co-rotational: R = rotational part of F (polar decomposition). Linear: R = I.
        rotations_[e] = p_.formulation == Formulation::Corotational ? polarRotation(F) : Mat3::Identity();
      }
    });
    tangentsValid_ = false;
  }

  void internalForces(Eigen::VectorXd& f) {
    f.setZero(static_cast<Eigen::Index>(p_.dofCount()));
    checkInversions();
    elementVectors_.resize(p_.elements.size());
    elementEnergies_.resize(p_.elements.size());
    parallelChunks(p_.elements.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e)
        elementVectors_[e] = hyper_ ? hyperelasticForce(model_, p_.elements[e], p_.lame, gradients_[e])
                                    : corotationalForce(stiffness_[e], rotations_[e], gather(x_, e), restNodes_[e],
                                                        &elementEnergies_[e]);  // Eq. 9
    });
    energiesValid_ = !hyper_;  // the energies of these positions, which elasticEnergy() sums
    for (std::size_t e = 0; e < p_.elements.size(); ++e) scatterAdd(f, e, elementVectors_[e]);
  }

  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
    checkSize(p, "apply");
    ensureTangents();
    const auto [massScale, stiffScale] = scales(c);
    // y = (m + c alpha) M p + (k + c beta) K_t p, M lumped (diagonal), K_t by element loops.
    y = massScale * p_.lumpedMass.cwiseProduct(p);
    if (c.stiffness != 0.0 && p_.springStiffness.size() == p.size()) y += c.stiffness * p_.springStiffness.cwiseProduct(p);
    if (stiffScale == 0.0) return;
    elementVectors_.resize(p_.elements.size());
    parallelChunks(p_.elements.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) {
        Vec12 pe;
        for (int k = 0; k < 4; ++k) pe.segment<3>(3 * k) = p.segment<3>(3 * node(e, k));
        elementVectors_[e] = stiffScale * tangents_[e].lazyProduct(pe);
      }
    });
    for (std::size_t e = 0; e < p_.elements.size(); ++e) scatterAdd(y, e, elementVectors_[e]);
  }

  double elasticEnergy() {
    if (!energiesValid_) {
      elementEnergies_.resize(p_.elements.size());
      parallelChunks(p_.elements.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
        for (std::size_t e = begin; e < end; ++e)
          elementEnergies_[e] = hyper_ ? hyperelasticEnergy(model_, p_.elements[e], p_.lame, gradients_[e])
                                       // 1/2 u^T K u, u = R^T x - X (R = I for the linear formulation)
                                       : corotationalEnergy(stiffness_[e], rotations_[e], gather(x_, e), restNodes_[e]);
      });
      energiesValid_ = true;
    }
    double energy = 0.0;
    for (const double e : elementEnergies_) energy += e;
    return energy;
  }

  // -- PCG (kernels/opencl/pcg.cl's single-reduction form, in double, on the free dofs)

  PcgStart pcgBegin(const SystemCoeffs& c, const Eigen::VectorXd& b, const Eigen::VectorXd& x, double tolerance,
                    int maxIterations) {
    checkSize(b, "the right-hand side of a solve");
    tol2_ = tolerance * tolerance;
    cap_ = maxIterations;
    running_ = false;
    const Eigen::Index nf = static_cast<Eigen::Index>(freeDofs_.size());
    bf_.resize(nf);
    xf_.resize(nf);
    for (Eigen::Index i = 0; i < nf; ++i) {
      const Eigen::Index d = freeDofs_[static_cast<std::size_t>(i)];
      bf_[i] = b[d];
      xf_[i] = x.size() == b.size() && std::isfinite(x[d]) ? x[d] : 0.0;  // a non-finite start is useless, not fatal
    }
    sc_ = PcgScalars{};
    sc_.bb = bf_.squaredNorm();
    if (!std::isfinite(sc_.bb)) return PcgStart::NonFiniteRhs;
    if (sc_.bb == 0.0) {
      xf_.setZero();
      sc_.stop = PcgStop::Converged;
      return PcgStart::ZeroRhs;
    }
    assemble(c);
    formPreconditioner(c);
    product(xf_, w_);
    r_ = bf_ - w_;
    u_ = precondition(r_);
    d_ = ad_ = Eigen::VectorXd::Zero(nf);
    product(u_, w_);
    gamma_ = r_.dot(u_);
    sc_.rr = r_.squaredNorm();
    const double delta = u_.dot(w_);
    beta_ = 0.0;
    const bool breakdown = !(delta > 0.0);
    alpha_ = breakdown ? 0.0 : gamma_ / delta;
    stopTest(breakdown);
    running_ = true;
    return PcgStart::Running;
  }

  /// One iteration if the body is still running; `last`: the cap's last (no next product).
  void pcgIteration(bool last) {
    if (!running_ || sc_.stop != PcgStop::Running) return;
    d_ = u_ + beta_ * d_;     // p = u + beta p
    ad_ = w_ + beta_ * ad_;   // s = A p = w + beta s
    xf_ += alpha_ * d_;
    r_ -= alpha_ * ad_;
    u_ = precondition(r_);
    const double gammaNew = r_.dot(u_);
    sc_.rr = r_.squaredNorm();
    bool breakdown = false;
    if (!last) {
      product(u_, w_);
      const double delta = u_.dot(w_);
      beta_ = gamma_ != 0.0 ? gammaNew / gamma_ : 0.0;
      const double pq = alpha_ != 0.0 ? delta - beta_ * gammaNew / alpha_ : 0.0;
      breakdown = !(pq > 0.0);
      alpha_ = breakdown ? 0.0 : gammaNew / pq;
    }
    gamma_ = gammaNew;
    sc_.iterations += 1;
    stopTest(breakdown);
  }

  const PcgScalars& scalars() const { return sc_; }
  bool running() const { return running_; }
  int cap() const { return cap_; }

  PcgScalars trueResidual() const {
    PcgScalars t = sc_;
    Eigen::VectorXd ax;
    product(xf_, ax);
    t.rr = (bf_ - ax).squaredNorm();
    return t;
  }

  void pcgEnd(Eigen::VectorXd& x) const {
    x.setZero(static_cast<Eigen::Index>(p_.dofCount()));
    for (std::size_t i = 0; i < freeDofs_.size(); ++i) x[freeDofs_[i]] = xf_[static_cast<Eigen::Index>(i)];
  }

  LinearSolveStats solveDirect(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    checkSize(b, "the right-hand side of a solve");
    const Eigen::Index nf = static_cast<Eigen::Index>(freeDofs_.size());
    Eigen::VectorXd bf(nf);
    for (Eigen::Index i = 0; i < nf; ++i) bf[i] = b[freeDofs_[static_cast<std::size_t>(i)]];
    if (!bf.allFinite())
      fail(ErrorCode::SolveFailed, "body '", p_.name, "': the right-hand side of the linear system has non-finite "
           "entries (the state diverged; try a smaller time step or load increment)");
    if (x.size() != b.size()) x = Eigen::VectorXd::Zero(b.size());
    LinearSolveStats stats;
    if (nf == 0) {  // everything constrained: nothing to solve
      x.setZero();
      stats.converged = true;
      return stats;
    }
    assemble(c);
    // LDL^T, not LL^T: the hyperelastic tangents become indefinite near buckling and still factor.
    if (!analyzed_) {
      ldlt_.analyzePattern(A_);
      analyzed_ = true;
    }
    ldlt_.factorize(A_);
    Eigen::VectorXd xf = Eigen::VectorXd::Zero(nf);
    if (ldlt_.info() == Eigen::Success) {
      xf = ldlt_.solve(bf);
      stats.converged = true;
    }
    if (!xf.allFinite())
      fail(ErrorCode::SolveFailed, "body '", p_.name, "': the direct solve (LDL^T) produced non-finite values; the "
           "system matrix is probably singular or the state diverged");
    // True residual on the free dofs.
    const double bNorm = bf.norm();
    stats.relativeResidual = bNorm > 0.0 ? (bf - A_ * xf).norm() / bNorm : (A_ * xf).norm();
    stats.converged = stats.converged && stats.relativeResidual <= std::max(solver_.tolerance, 1e-8);
    x.setZero();
    for (Eigen::Index i = 0; i < nf; ++i) x[freeDofs_[static_cast<std::size_t>(i)]] = xf[i];
    return stats;
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

  /// checkInversion of every element of a hyperelastic body, in element order (before a parallel
  /// pass, whose chunks must not throw).
  void checkInversions() const {
    if (hyper_)
      for (std::size_t e = 0; e < p_.elements.size(); ++e) checkInversion(e);
  }

  void checkInversion(std::size_t e) const {
    if (model_ == HyperelasticModel::NeoHookean && !(gradients_[e].determinant() > 0.0))
      fail(ErrorCode::SolveFailed, "body '", p_.name, "': element ", e, " (nodes ", node(e, 0), ", ", node(e, 1), ", ",
           node(e, 2), ", ", node(e, 3), ") is inverted (det F = ", gradients_[e].determinant(),
           "); the Neo-Hookean energy is undefined there. Use smaller load increments or time steps");
  }

  /// The coefficients of M and K_t in A with Rayleigh damping: (m + c alpha, k + c beta).
  std::pair<double, double> scales(const SystemCoeffs& c) const {
    return {c.mass + c.damping * p_.rayleighMass, c.stiffness + c.damping * p_.rayleighStiffness};
  }

  /// Element tangents at the current positions: R K R^T (Eq. 11), K (linear) or the consistent
  /// hyperelastic tangent.
  void ensureTangents() {
    if (tangentsValid_) return;
    tangents_.resize(p_.elements.size());
    checkInversions();
    parallelChunks(p_.elements.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) {
        if (hyper_)
          tangents_[e] = hyperelasticTangent(model_, p_.elements[e], p_.lame, gradients_[e]);
        else if (p_.formulation == Formulation::Corotational)
          tangents_[e] = rotateStiffness(stiffness_[e], rotations_[e]);
        else
          tangents_[e] = stiffness_[e];
      }
    });
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

    // The pattern from the nodes' neighbours (the nodes they share an element with, themselves
    // included): column j of a free dof of node a holds the free dofs of a's neighbours, ascending
    // (dofs are numbered node by node), and a free dof of a node in no element its diagonal alone.
    // Made straight into A_'s arrays: the element pairs' 144 entries each are never listed.
    const std::size_t N = n / 3;
    std::vector<std::vector<int>> neighbours(N);
    for (std::size_t e = 0; e < p_.elements.size(); ++e)
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          neighbours[static_cast<std::size_t>(node(e, a))].push_back(static_cast<int>(node(e, b)));
    std::vector<int> start(static_cast<std::size_t>(nf) + 1, 0);
    for (auto& list : neighbours) {
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
    }
    const auto freeOfNode = [&](std::size_t m) {
      int k = 0;
      for (std::size_t c = 0; c < 3; ++c) k += freeIndex_[3 * m + c] >= 0 ? 1 : 0;
      return k;
    };
    for (int j = 0; j < nf; ++j) {
      const auto a = static_cast<std::size_t>(freeDofs_[static_cast<std::size_t>(j)]) / 3;
      int rows = neighbours[a].empty() ? 1 : 0;
      for (const int m : neighbours[a]) rows += freeOfNode(static_cast<std::size_t>(m));
      start[static_cast<std::size_t>(j) + 1] = start[static_cast<std::size_t>(j)] + rows;
    }
    A_.resize(nf, nf);
    A_.makeCompressed();
    A_.resizeNonZeros(start.back());
    std::copy(start.begin(), start.end(), A_.outerIndexPtr());
    std::fill(A_.valuePtr(), A_.valuePtr() + start.back(), 0.0);
    for (int j = 0; j < nf; ++j) {
      const auto a = static_cast<std::size_t>(freeDofs_[static_cast<std::size_t>(j)]) / 3;
      int* rows = A_.innerIndexPtr() + start[static_cast<std::size_t>(j)];
      if (neighbours[a].empty()) *rows = j;
      for (const int m : neighbours[a])
        for (std::size_t c = 0; c < 3; ++c)
          if (const int r = freeIndex_[3 * static_cast<std::size_t>(m) + c]; r >= 0) *rows++ = r;
    }

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

  /// A = (m + c alpha) M + (k + c beta) K_t + k S restricted to the free dofs (x_c = 0).
  void assemble(const SystemCoeffs& c) {
    ensureTangents();
    const auto [massScale, stiffScale] = scales(c);
    double* values = A_.valuePtr();
    std::fill(values, values + A_.nonZeros(), 0.0);
    for (std::size_t e = 0; e < p_.elements.size(); ++e) {
      const int* slots = &elementSlots_[e * 144];
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b)
          if (slots[12 * a + b] >= 0) values[slots[12 * a + b]] += stiffScale * tangents_[e](a, b);
    }
    for (std::size_t i = 0; i < freeDofs_.size(); ++i) values[diagSlot_[i]] += massScale * p_.lumpedMass[freeDofs_[i]];
    if (c.stiffness != 0.0 && p_.springStiffness.size() != 0)
      for (std::size_t i = 0; i < freeDofs_.size(); ++i)
        values[diagSlot_[i]] += c.stiffness * p_.springStiffness[freeDofs_[i]];
  }

  /// y = A v on the free dofs, each entry the sum over A's column in stored order: A^T v, which is
  /// A v to rounding (A is symmetric but for the rounding of the co-rotational tangents' diagonal
  /// blocks R K_ii R^T and of the linear K_e), on the host's threads in chunks of columns: the same
  /// bits on any number of threads, since each entry is one column's sum.
  void product(const Eigen::VectorXd& v, Eigen::VectorXd& y) const {
    const Eigen::Index n = A_.cols();
    y.resize(n);
    const int* start = A_.outerIndexPtr();
    const int* row = A_.innerIndexPtr();
    const double* value = A_.valuePtr();
    const std::size_t chunk = static_cast<std::size_t>(n) <= kSerialColumns ? kSerialColumns : kColumnChunk;
    parallelChunks(static_cast<std::size_t>(n), chunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t j = begin; j < end; ++j) {
        double sum = 0.0;
        for (int q = start[j]; q < start[j + 1]; ++q) sum += value[q] * v[row[q]];
        y[static_cast<Eigen::Index>(j)] = sum;
      }
    });
  }

  /// M^-1 of the assembled A: none, its diagonal (1 where a diagonal entry is 0), its 3x3 node
  /// blocks over each node's free dofs (BlockJacobiPreconditioner), the warped multigrid
  /// (precond/amg.hpp) or the warped factor (precond/warped_cholesky.hpp) of the rest operator
  /// with A's coefficients.
  void formPreconditioner(const SystemCoeffs& c) {
    switch (solver_.preconditioner) {
      case PreconditionerKind::None: break;
      case PreconditionerKind::Diagonal:
        formDiagonalInverse();
        break;
      case PreconditionerKind::Amg:
        amgBlocksInverse_ = nodeBlocks(A_, freeDofs_).second;  // level 0's smoother
        formAmg(c);
        break;
      case PreconditionerKind::WarpedCholesky:
        formCholesky(c);
        break;
      case PreconditionerKind::BlockDiagonal:
        blocks_.setBlocks(blockStarts_);
        blocks_.factorize(A_);
        break;
      case PreconditionerKind::Auto:
        fail(ErrorCode::Internal, "reference backend: the preconditioner \"auto\" reached a body unresolved");
    }
  }

  Eigen::VectorXd precondition(const Eigen::VectorXd& r) const {
    switch (solver_.preconditioner) {
      case PreconditionerKind::None: return r;
      case PreconditionerKind::Diagonal: return diagInverse_.cwiseProduct(r);
      case PreconditionerKind::BlockDiagonal: return blocks_.solve(r);
      case PreconditionerKind::Amg: {
        Eigen::VectorXd z;
        const AmgFineOperator fine{[this](const Eigen::VectorXd& v, Eigen::VectorXd& y) { product(v, y); },
                                   [this](const Eigen::VectorXd& v, Eigen::VectorXd& y) { y = amgBlocksInverse_ * v; }};
        amg_.amg().apply(fine, r, z);
        return z;
      }
      case PreconditionerKind::WarpedCholesky: {
        Eigen::VectorXd z;
        cholesky_.cholesky().apply(r, z);
        return z;
      }
      case PreconditionerKind::Auto: break;  // resolved before (formPreconditioner refuses it)
    }
    return r;
  }

  void formDiagonalInverse() {
    diagInverse_.resize(A_.rows());
    for (std::size_t i = 0; i < diagSlot_.size(); ++i) {
      const double d = A_.valuePtr()[diagSlot_[i]];
      diagInverse_[static_cast<Eigen::Index>(i)] = d != 0.0 ? 1.0 / d : 1.0;
    }
  }

  /// The multigrid hierarchy over the rest operator with A's coefficients (BodyAmg: made again
  /// where they moved far), then the warp of the current positions.
  void formAmg(const SystemCoeffs& c) {
    const auto [massScale, stiffScale] = scales(c);
    amg_.ensure(p_, freeDofs_, massScale, stiffScale);
    if (p_.formulation != Formulation::Linear) amg_.amg().setPositions(x_);  // linear: K_t = K_0, no warp
  }

  /// The factor of the rest operator with A's coefficients (BodyCholesky: made again where they
  /// moved far), then the warp: each node's rotation from its elements' (the co-rotational R_e; a
  /// hyperelastic formulation's polar rotations of F_e; none for the linear formulation, K_t = K_0).
  void formCholesky(const SystemCoeffs& c) {
    const auto [massScale, stiffScale] = scales(c);
    cholesky_.ensure(p_, freeDofs_, massScale, stiffScale);
    if (p_.formulation == Formulation::Linear) {
      cholesky_.cholesky().setNodeRotations({});
      return;
    }
    if (p_.formulation == Formulation::Corotational) {
      cholesky_.cholesky().setNodeRotations(nodeRotations(p_.mesh, rotations_));
      return;
    }
    std::vector<Mat3> elementRotations(gradients_.size());
    parallelChunks(gradients_.size(), kElementChunk, [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t e = begin; e < end; ++e) elementRotations[e] = polarRotation(gradients_[e]);
    });
    cholesky_.cholesky().setNodeRotations(nodeRotations(p_.mesh, elementRotations));
  }

  /// The kernels' stop test after the set-up and every iteration (pcg.cl, update_scalars).
  void stopTest(bool breakdown) {
    sc_.stop = !std::isfinite(sc_.rr) ? PcgStop::NonFinite
               : sc_.rr <= tol2_ * sc_.bb ? PcgStop::Converged
               : breakdown               ? PcgStop::Breakdown
                                         : PcgStop::Running;
  }

  Problem p_;  // a copy: the body stays valid whatever happens to the caller's problem
  SolverDesc solver_;
  bool hyper_ = false;
  HyperelasticModel model_ = HyperelasticModel::StVenantKirchhoff;
  std::vector<std::array<Vec3d, 4>> restNodes_;
  std::vector<Mat12> stiffness_;  ///< K_e (linear, co-rotational)
  std::vector<Mat3> rotations_;   ///< R_e at the current positions
  std::vector<Mat3> gradients_;   ///< F_e at the current positions
  std::vector<Mat12> tangents_;   ///< element tangents, valid when tangentsValid_
  std::vector<Vec12> elementVectors_;  ///< scratch: each element's force or product, summed in element order
  std::vector<double> elementEnergies_;  ///< each element's energy, summed in element order
  bool energiesValid_ = false;  ///< elementEnergies_ hold the current positions' (internalForces made them)
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

  // The solve in progress (free dofs): b, x, r, u = M^-1 r, the direction p (d_) and s = A p (ad_),
  // w = A u; its scalars and preconditioner.
  Eigen::VectorXd bf_, xf_, r_, u_, d_, ad_, w_, diagInverse_;
  BlockJacobiPreconditioner blocks_;
  BodyAmg amg_;
  BodyCholesky cholesky_;
  AmgMatrix amgBlocksInverse_;  ///< the inverses of A's node blocks (amg's smoother)
  PcgScalars sc_;
  double gamma_ = 0.0, alpha_ = 0.0, beta_ = 0.0, tol2_ = 0.0;
  int cap_ = 0;
  bool running_ = false;
};

class ReferenceDevice final : public Device {
 public:
  ReferenceDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver) {
    const SolverDesc resolved = resolvedSolver(solver, problems);
    for (const Problem* p : problems) bodies_.push_back(std::make_unique<ReferenceBody>(*p, resolved));
  }

  std::string name() const override { return "reference"; }
  std::string deviceName() const override { return "host (Eigen, double)"; }
  std::size_t bodyCount() const override { return bodies_.size(); }
  const Problem& problem(std::size_t body) const override { return at(body).problem(); }

  void setPositions(const BodySet& set, const ConstVectors& x) override {
    check(set, x.size());
    forBodies(set, [&](std::size_t i) { at(set[i]).setPositions(*x[i]); });
  }
  void internalForces(const BodySet& set, const Vectors& f) override {
    check(set, f.size());
    forBodies(set, [&](std::size_t i) { at(set[i]).internalForces(*f[i]); });
  }
  void apply(const BodySet& set, const std::vector<SystemCoeffs>& c, const ConstVectors& p, const Vectors& y) override {
    check(set, p.size());
    check(set, y.size());
    check(set, c.size());
    forBodies(set, [&](std::size_t i) { at(set[i]).apply(c[i], *p[i], *y[i]); });
  }
  void elasticEnergy(const BodySet& set, std::vector<double>& energy) override {
    energy.resize(set.size());
    forBodies(set, [&](std::size_t i) { energy[i] = at(set[i]).elasticEnergy(); });
  }
  void setMaterial(const BodySet& set, const std::vector<const Problem*>& problems) override {
    check(set, problems.size());
    for (std::size_t i = 0; i < set.size(); ++i) at(set[i]).setMaterial(*problems[i]);
  }
  bool removeBody(std::size_t body) override {
    at(body);
    bodies_.erase(bodies_.begin() + static_cast<std::ptrdiff_t>(body));
    solve_.clear();  // between steps: no solve is in progress
    reads_.clear();
    residualFor_.clear();
    return true;
  }
  std::vector<DeviceCounter> counters() const override {
    long long amg = 0, cholesky = 0;
    for (const auto& b : bodies_) {
      amg += b->amgBuilds();
      cholesky += b->choleskyBuilds();
    }
    return {{"amg_hierarchies_made", amg}, {"warped_cholesky_factors_made", cholesky}};
  }
  void setSprings(const BodySet& set, const std::vector<const Problem*>& problems) override {
    check(set, problems.size());
    for (std::size_t i = 0; i < set.size(); ++i) at(set[i]).setSprings(*problems[i]);
  }
  void setConstraints(const BodySet& set, const std::vector<const std::vector<std::uint8_t>*>& constrained) override {
    check(set, constrained.size());
    for (std::size_t i = 0; i < set.size(); ++i) at(set[i]).setConstraints(*constrained[i]);
  }

  std::vector<PcgStart> pcgBegin(const BodySet& set, const std::vector<SystemCoeffs>& c, const ConstVectors& b,
                                 const ConstVectors& x, double tolerance, int maxIterations) override {
    check(set, b.size());
    check(set, x.size());
    check(set, c.size());
    solve_ = set;
    enqueued_ = 0;
    cap_ = maxIterations;
    reads_.clear();
    std::vector<PcgStart> out(set.size());
    forBodies(set, [&](std::size_t i) { out[i] = at(set[i]).pcgBegin(c[i], *b[i], *x[i], tolerance, maxIterations); });
    return out;
  }

  void pcgIterate(int n, const std::vector<char>&) override {
    const int first = enqueued_;
    const int count = std::max(0, std::min(n, cap_ - enqueued_));
    enqueued_ += count;
    // Each body its own iterations in turn (iteration k the cap's last where first + k + 1 = cap).
    forBodies(solve_, [&](std::size_t i) {
      for (int k = 0; k < count; ++k) at(solve_[i]).pcgIteration(first + k + 1 == cap_);
    });
  }

  PcgTicket pcgRead() override {
    std::vector<PcgScalars> now;
    for (std::size_t body : solve_) now.push_back(at(body).scalars());
    reads_.push_back(std::move(now));
    return firstTicket_ + reads_.size() - 1;
  }

  void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) override {
    if (reads_.empty() || ticket != firstTicket_)
      fail(ErrorCode::Internal, "reference backend: PCG reads taken out of order");
    scalars = std::move(reads_.front());
    reads_.pop_front();
    ++firstTicket_;
  }

  void pcgResidual(const std::vector<char>& bodies) override { residualFor_ = bodies; }

  void pcgEnd(const std::vector<int>&, const Vectors& x, std::vector<PcgScalars>& residual) override {
    residual.assign(solve_.size(), PcgScalars{});
    forBodies(solve_, [&](std::size_t i) {
      ReferenceBody& b = at(solve_[i]);
      if (i < residualFor_.size() && residualFor_[i]) residual[i] = b.trueResidual();
      if (b.running()) b.pcgEnd(*x[i]);
    });
    firstTicket_ += reads_.size();
    reads_.clear();
    residualFor_.clear();
  }

  bool hasDirectSolve() const override { return true; }
  LinearSolveStats solveDirect(std::size_t body, const SystemCoeffs& c, const Eigen::VectorXd& b,
                               Eigen::VectorXd& x) override {
    return at(body).solveDirect(c, b, x);
  }

 private:
  ReferenceBody& at(std::size_t body) const {
    if (body >= bodies_.size())
      fail(ErrorCode::Internal, "reference backend: body ", body, " of ", bodies_.size());
    return *bodies_[body];
  }
  static void check(const BodySet& set, std::size_t n) {
    if (set.size() != n) fail(ErrorCode::Internal, "reference backend: ", n, " vectors for ", set.size(), " bodies");
  }

  /// fn(i) for every body set[i]: across the host's threads, a body on each, where the set's work
  /// spreads (two bodies or more, the largest at most half of their elements); else one body after
  /// another, each body's own passes on the threads. The bodies are independent, so either way each
  /// gets the bits it gets alone. A body's error stops nothing else; the first body's (in set order)
  /// is thrown once all are done.
  template <class Fn>
  void forBodies(const BodySet& set, Fn&& fn) {
    std::size_t largest = 0, total = 0;
    for (std::size_t body : set) {
      const std::size_t e = at(body).problem().elements.size();
      largest = std::max(largest, e);
      total += e;
    }
    std::vector<std::exception_ptr> errors(set.size());
    const auto run = [&](std::size_t, std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        try {
          fn(i);
        } catch (...) {
          errors[i] = std::current_exception();
        }
      }
    };
    if (set.size() < 2 || 2 * largest > total)
      run(0, 0, set.size());
    else
      parallelChunks(set.size(), 1, run);
    for (const std::exception_ptr& e : errors)
      if (e) std::rethrow_exception(e);
  }

  std::vector<std::unique_ptr<ReferenceBody>> bodies_;
  BodySet solve_;  ///< the bodies of the solve in progress
  int enqueued_ = 0, cap_ = 0;
  std::deque<std::vector<PcgScalars>> reads_;  ///< snapshots not yet taken, the oldest first
  PcgTicket firstTicket_ = 0;                  ///< the ticket of reads_.front()
  std::vector<char> residualFor_;
};

}  // namespace

std::unique_ptr<Device> createReferenceDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver) {
  return std::make_unique<ReferenceDevice>(problems, solver);
}

void registerReferenceBackend() {
  BackendEntry e;
  e.name = "reference";
  e.candidates = [] { return std::vector<Candidate>{referenceCandidate()}; };
  e.resolve = [](const std::string&) { return referenceCandidate(); };
  e.create = [](const std::vector<const Problem*>& problems, const SolverDesc& solver, const Candidate&,
                const DeviceOptions&) { return createReferenceDevice(problems, solver); };
  // The calibration cache's key: bumped when the device's speed changes (Newton's polar rotations,
  // the PCG's products on threads, batches: 2026-11-28).
  e.buildId = [] { return std::string("reference-2"); };
  e.batches = true;  // a batch's bodies share each call, run across the host's threads (forBodies)
  // A hyperelastic body's inverted element fails the whole call (checkInversion): it runs alone.
  e.batchable = [](const Problem& p) { return !isHyperelastic(p.formulation); };
  registerBackend(std::move(e));
}

}  // namespace corofem::detail
