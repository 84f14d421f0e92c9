// The host side of the "amg" preconditioner (precond/amg.hpp) on a device backend, written once for
// every backend (OpenCL, Vulkan): each body's hierarchy made for its solve's coefficients
// (BodyAmg), every body's levels laid end to end in the device's numbering, the warp's rotations
// of the bodies whose positions changed, and the sparse formats the devices read. A backend turns
// the layout into buffers and runs the V-cycle of its kernels.
//
// The layout (device level k >= 1 holds every body's level k, body after body; a body's rows only
// reach its own columns):
//   - level 0 is the device's dof numbering (3 per node, padding and constrained dofs included);
//   - P0 (level-0 rows, level-1 columns) and its transpose Pt0;
//   - per coarser level: the rest operator A and its scaled inverse diagonal (of the bodies that
//     have a level below it), P and Pt to the next level, and the dense inverse of the operator of
//     each body whose coarsest level it is;
//   - per segment the scale 1 / lambda_max of level 0's Chebyshev bound, and per device node the
//     aggregate (among all bodies') whose rotation turns it, or -1 (no warp: linear bodies, nodes
//     with every dof held).
#pragma once

#include "device/body_layout.hpp"
#include "device/device.hpp"
#include "precond/amg.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

namespace corofem::detail {

/// Device level k >= 1 of every body.
struct DeviceAmgLevel {
  std::size_t rows = 0;
  AmgMatrix A;                ///< the rest operators of the bodies with a coarser level below this one
  AmgMatrix P, Pt;            ///< P: rows here, columns on level k + 1; Pt = P^T
  AmgMatrix inverse;          ///< the dense inverses of the bodies whose coarsest level this is
  std::size_t inverseEntries = 0;
  bool smooths = false;       ///< some body has a coarser level below this one
  std::vector<double> dinv;   ///< per row: 1 / (A_ii lambda_max) (0 on the coarsest bodies' rows)
};

struct DeviceAmgLayout {
  /// 0: a body's level-k rows (k >= 1) end to end as its hierarchy numbers them; else each vertex
  /// of a level (AmgLevel::vertexStart) takes `block` rows, its own first and zero rows after
  /// them (no entries, dinv 0), so that every coarse matrix is made of dense block x block blocks
  /// (P0 and Pt0: 3 x block and block x 3, level 0 having 3 rows per node).
  std::size_t block = 0;
  AmgMatrix P0, Pt0;                        ///< level 0 <-> level 1
  std::vector<DeviceAmgLevel> levels;       ///< levels[k - 1] is device level k
  std::vector<double> scale;                ///< per segment: 1 / level 0's lambda_max (1 without a hierarchy)
  std::vector<std::int32_t> nodeAggregate;  ///< per device node: its aggregate, or -1
  std::size_t aggregates = 0;               ///< every body's level-0 aggregates
};

/// A matrix in slices of `slice` rows (sliced ELLPACK): slice s holds its rows' entries column by
/// column from start[s], as many columns as its longest row, the shorter rows padded with value 0
/// at column 0 (a device skips padding: its column may belong to another body, whose x may not be
/// finite). start has one entry per slice and one past the last.
struct SlicedEll {
  std::size_t rows = 0;
  std::vector<std::uint32_t> start, cols;
  std::vector<double> values;
};
SlicedEll slicedEll(const AmgMatrix& m, std::size_t slice);

/// A matrix of a blocked layout (DeviceAmgLayout::block) in dense blocks of rowBlock x colBlock:
/// block row i (rows [rowBlock i, rowBlock (i + 1))) holds the blocks start[i] .. start[i + 1], in
/// ascending block column cols[j], each with its entries column by column (entry (r, c) of block j
/// at values[rowBlock colBlock j + rowBlock c + r]; zero where the matrix has none), then `pad`
/// zeros (a device reading whole vectors past a block's last column stays in the buffer). Throws
/// Error(Internal) where the matrix's sizes are not whole blocks.
struct BlockRows {
  std::size_t blockRows = 0, rowBlock = 0, colBlock = 0;
  std::vector<std::uint32_t> start, cols;
  std::vector<double> values;
};
BlockRows blockRows(const AmgMatrix& m, std::size_t rowBlock, std::size_t colBlock, std::size_t pad);

/// The hierarchies of a device's bodies (segments), and their layout.
class DeviceAmg {
 public:
  /// `segments`: the device's (alive as long as this; their constraints are read at each prepare
  /// after constraintsChanged).
  explicit DeviceAmg(const std::vector<BodySegment>& segments);

  /// Keeps the bodies' positions (the problem's numbering) for their next warp.
  void positionsSet(const BodySet& bodies, const ConstVectors& x);
  /// The body's material changed: its hierarchy is made again at its next solve.
  void invalidate(std::size_t segment);
  /// The body's constraints changed: its free dofs are read again at its next solve, where
  /// BodyAmg::ensure takes back a hierarchy made for exactly them (the spare) or makes one.
  void constraintsChanged(std::size_t segment);
  /// Hierarchies made so far, every body's.
  long long builds() const;

  /// Before a solve of `running` (segments), coefficients[i] = (mass, stiffness) of the operator
  /// m M + s K of running[i]: makes or takes back their hierarchies. Returns whether the layout
  /// changed since the last layout() (the device uploads layout() again).
  bool prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients);
  /// Every body's levels end to end over `nodeTotal` device nodes; with `block` > 0 each coarse
  /// vertex in `block` rows (DeviceAmgLayout::block; at least the largest vertex, 6 always
  /// suffices). Throws Error(Internal) for a vertex larger than `block`.
  DeviceAmgLayout layout(std::size_t nodeTotal, std::size_t block = 0);
  /// Segment s's hierarchy.
  const BodyAmg& body(std::size_t s) const { return bodies_.at(s); }
  /// The device holds layout()'s levels now (called once its upload succeeded; until then prepare
  /// keeps saying the layout changed). Every co-rotational body's warp is due again (warps()): the
  /// device's aggregates start at the identity.
  void layoutUploaded();
  /// For each body of `running` whose positions changed since its last warp (co-rotational, with
  /// positions set): its aggregates' rotations by shape matching, as fn(first aggregate, 9 reals
  /// per aggregate, row-major).
  void warps(const BodySet& running, const std::function<void(std::size_t, const std::vector<double>&)>& fn);

 private:
  const std::vector<BodySegment>& segs_;
  std::vector<BodyAmg> bodies_;                       ///< per segment
  std::vector<std::vector<Eigen::Index>> freeDofs_;   ///< per segment, in the problem's numbering
  std::vector<char> freeKnown_;                       ///< per segment: freeDofs_ is its constraints'
  std::vector<Eigen::VectorXd> positions_;            ///< per segment: the last positions set
  std::vector<char> warpStale_;
  std::vector<std::size_t> aggregateBegin_;           ///< per segment: its first aggregate
  bool dirty_ = true;                                 ///< the layout lags the hierarchies
};

}  // namespace corofem::detail
