// The "amg" preconditioner on the OpenCL engine: each body's hierarchy made on the host
// (precond/amg.hpp, the same as the reference backend's), its levels laid end to end over the
// bodies in device buffers, and the V-cycle of kernels/opencl/amg.cl run between pcg_init or
// pcg_update (which form r and the current diagonal inverse) and the product w = A u.
//
// Per PCG iteration: 5 products of the current operator (the PCG's own and 4 in the smoothing of
// level 0), and per coarser level 6 sparse products and 5 vector kernels; the host reads nothing.
// The host's work per solve: the hierarchy of a body where it has none for the solve's ratio of
// mass to stiffness (BodyAmg), and the warp (one rotation per level-0 aggregate) where its
// positions changed.
#pragma once

#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/cl_objects.hpp"
#include "device/device_amg.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

class SegmentEngine;

class EngineAmg {
 public:
  explicit EngineAmg(SegmentEngine& engine);
  void createKernels();
  /// Keeps the bodies' positions for their next warp.
  void positionsSet(const BodySet& bodies, const ConstVectors& x);
  /// The body's material changed: its hierarchy is made again at its next solve.
  void invalidate(std::size_t segment);
  /// The segment's constraints changed: its free dofs are read again at the next prepare, where
  /// BodyAmg::ensure takes back a hierarchy made for exactly them (the spare) or makes one.
  void constraintsChanged(std::size_t segment);
  /// Hierarchies made so far, every body's.
  long long builds() const;
  /// Before a solve of the running segments (their coefficients set): their hierarchies, the
  /// device's levels where one changed, the warp where positions changed.
  void prepare(const BodySet& running);
  /// z_ = M^-1 r_ on the active segments with the partial sums pcg_update leaves (r . z, r . r),
  /// and |free b|^2 from b_ with `setup` (pcg_init's). The coarse levels run over every body's rows
  /// (a stopped body's are scratch no active segment reads).
  void cycle(bool setup);
  std::vector<DeviceBuffer> buffers() const;

 private:
  /// A level matrix on the device: sliced ELLPACK in slices of kSlice rows (amg_spmv), dense
  /// rowBlock x colBlock blocks (BlockRows, amg_blocks_*: the blocked layout, block()), or
  /// CSR (the coarsest inverse, amg_coarsest): `start` the slices', the block rows' or the rows'
  /// first entries.
  struct Csr {
    std::unique_ptr<ClBuffer> start, cols, values;
    std::size_t rows = 0;
    std::size_t rowBlock = 0, colBlock = 0;  ///< 0: not in blocks
  };
  /// The blocked layout's vertex rows (DeviceAmgLayout::block) with per-work-item sums (the
  /// tuning's workGroupSums 0: CPU devices by default); 0 with work-group sums (GPUs), whose
  /// coarse products take a row per work-item in sliced ELLPACK.
  std::size_t block() const;
  static constexpr std::size_t kSlice = 16;  ///< kAmgSlice of kernels/opencl/amg.cl
  /// Block rows per work-group of amg_blocks_*.
  static constexpr std::size_t kBlockGroup = 16;
  /// Device level k >= 1: every body's hierarchy level k end to end.
  struct Level {
    std::size_t rows = 0;
    Csr A, P, Pt, inverse;  ///< P: rows here, columns on level k + 1; inverse: the coarsest bodies'
    std::size_t inverseEntries = 0;
    bool smooths = false;   ///< some body has a coarser level below this one
    std::unique_ptr<ClBuffer> dinv, b, x, res, d, t;
  };
  void upload();
  void uploadWarp(const BodySet& running);
  void coarse(std::size_t k);
  void spmv(const Csr& m, const ClBuffer& x, const ClBuffer* b, cl_uint mode, const ClBuffer& y);
  std::unique_ptr<ClBuffer> buffer(std::size_t bytes);
  std::unique_ptr<ClBuffer> reals(const std::vector<double>& values);
  /// The format of Csr for a transfer or an operator: rowBlock x colBlock blocks where both are
  /// set (the blocked layout), else sliced ELLPACK.
  void setRows(Csr& out, const AmgMatrix& m, std::size_t rowBlock, std::size_t colBlock);
  /// CSR (the coarsest inverse), its values in double with `doubleValues` whatever the engine's
  /// precision (where the device has fp64).
  void setCsr(Csr& out, const AmgMatrix& m, bool doubleValues);
  void putRows(Csr& out, const std::vector<cl_uint>& start, const std::vector<cl_uint>& cols,
               std::vector<double> values, bool doubleValues);

  SegmentEngine& e_;
  DeviceAmg host_;                        ///< the hierarchies and their layout
  // Level 0 (device dofs), levels 1.. and the warp.
  Csr P0_, Pt0_;
  std::vector<Level> levels_;             ///< levels_[k - 1] is device level k
  std::unique_ptr<ClBuffer> scale_, res0_, d0_, e0_, nodeAggregate_, rotations_;
  ClKernel kFineBegin_, kFinePass_, kUnwarp_, kWarpAdd_, kSpmv_, kCoarseBegin_, kCoarseStep_, kCoarsest_,
      kBlocks3x6_, kBlocks6x3_, kBlocks6x6_;
};

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
