// A fill-reducing order for the warped Cholesky's factor (precond/warped_cholesky.hpp) whose
// elimination tree splits into independent subtrees: geometric nested dissection of the body's
// nodes.
//
// The free dofs are grouped by node (a node's dofs stay together, so the factor's supernodes are at
// least a node wide). A set of nodes is split at the median of its rest positions along the longest
// side of its bounding box; the nodes of one half next to the other (the smaller of the two such
// borders) form a separator, ordered after both halves, and each half is split again, until a part
// holds at most kLeafNodes nodes, which approximate minimum degree orders. The two halves of a split
// then never meet in the factor (L's rows below a half are in that half or in the separators above
// it), so their triangular solves run side by side (precond/supernodal_ldlt.hpp); and the
// separators of a mesh are thin (a slender beam's are its cross-sections), so the fill stays near
// that of minimum degree on the whole.
//
// Deterministic: every choice follows from the positions and the pattern alone (ties by index).
#pragma once

#include "precond/rest_system.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace corofem::detail {

/// Parts of at most this many nodes are ordered by minimum degree, not split.
constexpr std::size_t kLeafNodes = 64;

/// The order of the free dofs `freeDofs` (strictly ascending dof indices 3 n + c of nodes at rest
/// positions `rest`, 3N entries) for a factor of `A` (their operator, its pattern symmetric):
/// position[i] is the place of free dof i in the elimination order (a permutation of 0..n-1).
/// Throws Error(Internal) for inconsistent sizes or a free dof's rest position not finite.
std::vector<int> nestedDissection(const AmgMatrix& A, const std::vector<Eigen::Index>& freeDofs,
                                  const Eigen::VectorXd& rest);

}  // namespace corofem::detail
