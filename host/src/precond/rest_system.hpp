// What the preconditioners made from a body's REST system share (precond/amg.hpp's multigrid,
// precond/warped_cholesky.hpp's factor): the rest operator A_0 = m M + s K_0 on the free dofs
// (K_0 the sum of the linear element stiffnesses, the tangent of every formulation at rest; M
// lumped), K_0 kept across set-ups, and a pair of preconditioners, the one in use and a spare, made
// for a ratio m / s each.
//
// A preconditioner made from A_0 at one ratio m / s serves a solve whose ratio is within a factor
// of 2 of it: the integrators keep the mass coefficient at 1, so the time step alone moves the
// ratio (backward Euler: m / s = 1 / h^2), and one made for a nearby step is still a good one. The
// one it replaces is kept as a spare and taken back where the ratio returns near its own: a step
// retried in substeps (h / 2, h / 4: the ratio 4x, 16x) and the next full step then cost one
// set-up each, not one per change. The same for constraints: a preconditioner serves the free dofs
// it was made for, so a hard grab costs one set-up and its release none (the spare).
#pragma once

#include "model/problem.hpp"

#include <Eigen/SparseCore>

#include <cmath>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

namespace corofem::detail {

using AmgMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

/// K_0 of a body on all its dofs (3N x 3N): the sum of the linear element stiffnesses (the tangent
/// of every formulation at rest), with every diagonal entry present (zero where no element adds to
/// it), so that restOperator always finds the entry its mass goes to.
AmgMatrix restStiffness(const Problem& p);
/// m M + s K_0 on the free dofs `freeDofs` (strictly ascending dof indices) from K_0 on all dofs
/// (restStiffness of the same body): M lumped. O(nonzeros), no assembly. Throws Error(Internal) for
/// free dofs out of order or a stiffness of another size.
AmgMatrix restOperator(const AmgMatrix& stiffness, const Problem& p, const std::vector<Eigen::Index>& freeDofs,
                       double massScale, double stiffScale);

/// Whether `freeDofs` are strictly ascending dof indices within 0..dofs - 1 (the rows and columns
/// of a rest operator come out in order only for those).
bool freeDofsInOrder(const std::vector<Eigen::Index>& freeDofs, Eigen::Index dofs);
/// Throws Error(Internal) naming `who` unless `A` is n x n for the n free dofs `freeDofs` and they
/// are in order (freeDofsInOrder) for a body at rest positions `rest` (3N entries).
void checkRestSystem(const char* who, const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs,
                     const Eigen::VectorXd& rest);

/// The graph of A's vertices, vertex v holding rows [vertexStart[v], vertexStart[v + 1]) (ascending,
/// from 0 to A's rows): u is a neighbour of v where a row of v has a non-zero entry in a column of
/// u != v, each neighbour once, in the order v's rows meet them. CSR: v's neighbours are
/// adj[start[v] .. start[v + 1]). (The multigrid's aggregation of a level, the nested dissection of
/// the free dofs' nodes.)
struct VertexGraph {
  std::vector<int> start, adj;
};
VertexGraph vertexGraph(const AmgMatrix& A, const std::vector<int>& vertexStart);

/// K_0 of a body kept across set-ups: constraints and coefficients change a preconditioner, not
/// K_0, so a grab's set-up restricts it instead of assembling again (the assembly was about half of
/// a multigrid set-up on the 12,960-tet beam). Made again where the body's mesh, rest state,
/// material or lumped mass differ from those it was made from (a hash of them). Its memory, about
/// that of A_0, stays with the body.
class KeptStiffness {
 public:
  /// K_0 of `p`; `remade` is set where it was made (again) by this call.
  const AmgMatrix& of(const Problem& p, bool& remade);

 private:
  AmgMatrix stiffness_;
  std::uint64_t key_ = 0;
};

/// What RestPair::find did, and what a body's ensure() reports: the preconditioner in use kept, the
/// spare taken back, or one made.
enum class Made { Kept, Switched, Built };

/// m / s of a rest operator m M + s K_0 (infinite for s = 0: statics has m = 0 and s = 1, so it
/// is 0 there; infinite only for a mass matrix alone).
inline double restRatio(double massScale, double stiffScale) {
  return stiffScale != 0.0 ? massScale / stiffScale : INFINITY;
}

/// Whether a preconditioner made at the ratio `made` serves a solve at `ratio`: within a factor of
/// 2, or equal where either is 0 or infinite (never where either is NaN).
inline bool ratioServes(double ratio, double made) {
  return std::isfinite(ratio) && std::isfinite(made) ? (ratio == 0.0 ? made == 0.0 : made > 0.5 * ratio && made < 2.0 * ratio)
                                                     : ratio == made;
}

/// The preconditioner in use and the spare (see the top of this file). T has built(),
/// builtFreeDofs() and clear().
template <class T>
class RestPair {
 public:
  RestPair() : now_(std::make_unique<T>()), spare_(std::make_unique<T>()) {}
  /// Kept where the one in use serves (ratio, freeDofs); Switched where the spare does (it is now
  /// in use); Built where neither does: then now() is the one to make (the one in use before is
  /// the spare), and made() records its ratio once it is. Until then now() serves no ratio, so
  /// one whose making threw half way is never taken.
  Made find(double ratio, const std::vector<Eigen::Index>& freeDofs) {
    auto fits = [&](const T& t, double made) { return t.built() && t.builtFreeDofs() == freeDofs && ratioServes(ratio, made); };
    if (fits(*now_, ratio_)) return Made::Kept;
    std::swap(now_, spare_);
    std::swap(ratio_, spareRatio_);
    if (fits(*now_, ratio_)) return Made::Switched;
    ratio_ = NAN;
    return Made::Built;
  }
  void made(double ratio) { ratio_ = ratio; }
  T& now() { return *now_; }
  const T& now() const { return *now_; }
  const T& spare() const { return *spare_; }
  double nowRatio() const { return ratio_; }
  double spareRatio() const { return spareRatio_; }
  void clear() {
    now_->clear();
    spare_->clear();
  }

 private:
  std::unique_ptr<T> now_, spare_;
  double ratio_ = 0.0, spareRatio_ = 0.0;  ///< m / s each was made from (restRatio)
};

}  // namespace corofem::detail
