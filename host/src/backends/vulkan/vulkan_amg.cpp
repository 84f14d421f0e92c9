// The "amg" preconditioner on the Vulkan device (vulkan_amg.hpp).
#include "backends/vulkan/vulkan_amg.hpp"

#include "backends/vulkan/shaders.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <limits>

namespace corofem::detail {

namespace {

// amg.comp's passes and flags.
constexpr std::uint32_t kFineBegin = 0, kFineStep = 1, kUnwarp = 2, kWarpAdd = 3, kSpmv = 4, kCoarseBegin = 5,
                        kCoarseStep = 6, kCoarseAdd = 7, kCoarsest = 8;
constexpr std::uint32_t kZero = 1, kLast = 2, kSetup = 4, kResidual = 8;
constexpr std::size_t kSlice = 16;  ///< amg.comp's slice of 16 rows
// amg.comp's Chebyshev constants are those of degree 2 over [1/30, 1] (engine_amg.cpp's Chebyshev).
static_assert(WarpedAmg::kChebyshevDegree == 2, "amg.comp runs one Chebyshev step after its begin");
constexpr std::uint32_t kWg = 64;

// The shared layout's bindings the multigrid's descriptor set replaces (amg.comp).
constexpr std::size_t kBindIdx = 1, kBindVal = 2, kBindVec = 4, kBindInv = 5, kBindRes0 = 6, kBindD0 = 7, kBindAd0 = 8;

std::uint32_t groupsOf(std::size_t items) { return static_cast<std::uint32_t>((items + kWg - 1) / kWg); }

/// The packed host copies, appended to.
struct Packed {
  std::vector<std::uint32_t> idx;
  std::vector<double> val, inv;
};

std::uint32_t offset(std::size_t n) {
  if (n > std::numeric_limits<std::uint32_t>::max())
    fail(ErrorCode::DeviceError, "Vulkan: the multigrid's levels need more than 2^32 entries in one buffer; use fewer "
         "elements per device, the preconditioner \"diagonal\", or the opencl backend");
  return static_cast<std::uint32_t>(n);
}

}  // namespace

VulkanAmg::VulkanAmg(VulkanAmgHost host) : host_(std::move(host)), amg_(*host_.segments) {
  rs_ = host_.isDouble ? sizeof(double) : sizeof(float);
  vk::Context& ctx = *host_.ctx;
  const vk::Spirv code = vk::shaderCode(vk::Shader::Amg, host_.isDouble);
  pipeline_ = ctx.pipeline(code.words, code.bytes, "amg.comp");
  const std::size_t fine = std::max<std::size_t>(3 * host_.nodeTotal, 1) * rs_;
  res0_ = vk::Buffer(ctx, fine, false);
  d0_ = vk::Buffer(ctx, fine, false);
  ad0_ = vk::Buffer(ctx, fine, false);
  // Finite from the start: a padding node's entries are never written by the passes but are read
  // by the products' gathers of the segment's own nodes only; zero them once all the same.
  for (const vk::Buffer* b : {&res0_, &d0_, &ad0_}) vk::zeroBuffer(ctx, *b);
  productD_ = host_.productSet(d0_, ad0_);
  productU_ = host_.productSet(*host_.u, ad0_);
}

VulkanAmg::~VulkanAmg() {
  try {
    host_.ctx->waitAll();
    for (VkDescriptorSet s : {set_, productD_, productU_})
      if (s != VK_NULL_HANDLE) host_.ctx->freeDescriptorSet(s);
  } catch (...) {
  }
}

void VulkanAmg::prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients) {
  if (amg_.prepare(running, coefficients)) upload();
}

void VulkanAmg::upload() {
  const DeviceAmgLayout layout = amg_.layout(host_.nodeTotal);
  Packed p;
  std::size_t vecEntries = 3 * host_.nodeTotal;  // e0 first
  auto ell = [&](const AmgMatrix& m) {
    const SlicedEll e = slicedEll(m, kSlice);
    Matrix out;
    out.rows = e.rows;
    out.start = offset(p.idx.size());
    p.idx.insert(p.idx.end(), e.start.begin(), e.start.end());
    out.cols = offset(p.idx.size());
    p.idx.insert(p.idx.end(), e.cols.begin(), e.cols.end());
    out.values = offset(p.val.size());
    p.val.insert(p.val.end(), e.values.begin(), e.values.end());
    return out;
  };
  auto csr = [&](const AmgMatrix& m) {
    Matrix out;
    out.rows = static_cast<std::size_t>(m.rows());
    out.start = offset(p.idx.size());
    p.idx.insert(p.idx.end(), m.outerIndexPtr(), m.outerIndexPtr() + m.rows() + 1);
    out.cols = offset(p.idx.size());
    p.idx.insert(p.idx.end(), m.innerIndexPtr(), m.innerIndexPtr() + m.nonZeros());
    out.values = offset(p.inv.size());
    p.inv.insert(p.inv.end(), m.valuePtr(), m.valuePtr() + m.nonZeros());
    return out;
  };
  P0_ = ell(layout.P0);
  Pt0_ = ell(layout.Pt0);
  levels_.assign(layout.levels.size(), Level{});
  for (std::size_t k = 0; k < layout.levels.size(); ++k) {
    const DeviceAmgLevel& from = layout.levels[k];
    Level& L = levels_[k];
    L.rows = from.rows;
    L.A = ell(from.A);
    L.P = ell(from.P);
    L.Pt = ell(from.Pt);
    L.inverse = csr(from.inverse);
    L.inverseEntries = from.inverseEntries;
    L.smooths = from.smooths;
    L.dinv = offset(p.val.size());
    p.val.insert(p.val.end(), from.dinv.begin(), from.dinv.end());
    for (std::uint32_t* v : {&L.b, &L.x, &L.res, &L.d, &L.t}) {
      *v = offset(vecEntries);
      vecEntries += from.rows;
    }
  }
  scale_ = offset(p.val.size());
  p.val.insert(p.val.end(), layout.scale.begin(), layout.scale.end());
  // Every aggregate at I until its body's positions give its rotation (a solve before any
  // setPositions, or a body handed over by a failover without positions, runs unwarped).
  rotations_ = offset(p.val.size());
  for (std::size_t a = 0; a < layout.aggregates; ++a)
    for (int i = 0; i < 9; ++i) p.val.push_back(i % 4 == 0 ? 1.0 : 0.0);
  nodeAggregate_ = offset(p.idx.size());
  for (std::int32_t a : layout.nodeAggregate) p.idx.push_back(static_cast<std::uint32_t>(a));

  vk::Context& ctx = *host_.ctx;
  // The device's limits: every buffer bound whole, the largest dispatch (P0's rows, 3 per node).
  const VkPhysicalDeviceLimits& lim = ctx.physical().limits;
  const std::size_t largest = std::max({p.idx.size() * sizeof(std::uint32_t), p.val.size() * rs_, p.inv.size() * rs_,
                                        vecEntries * rs_});
  if (largest > lim.maxStorageBufferRange)
    fail(ErrorCode::DeviceError, "Vulkan: the multigrid's levels of these bodies need a ", largest, "-byte buffer; '",
         ctx.physical().name, "' binds at most ", lim.maxStorageBufferRange, " bytes (maxStorageBufferRange): use "
         "fewer elements per device, the preconditioner \"diagonal\", or the opencl backend");
  if (groupsOf(3 * host_.nodeTotal) > lim.maxComputeWorkGroupCount[0])
    fail(ErrorCode::DeviceError, "Vulkan: the multigrid's finest products need ", groupsOf(3 * host_.nodeTotal),
         " work-groups; '", ctx.physical().name, "' allows ", lim.maxComputeWorkGroupCount[0], " per dispatch");
  ctx.wait(ctx.flush());  // the buffers replaced may still be read by recorded work
  const std::vector<unsigned char> val = realBytes(p.val, host_.isDouble), inv = realBytes(p.inv, host_.isDouble);
  idx_ = vk::Buffer(ctx, std::max<std::size_t>(p.idx.size(), 1) * sizeof(std::uint32_t), false);
  val_ = vk::Buffer(ctx, std::max<std::size_t>(val.size(), rs_), false);
  inv_ = vk::Buffer(ctx, std::max<std::size_t>(inv.size(), rs_), false);
  vec_ = vk::Buffer(ctx, std::max<std::size_t>(vecEntries, 1) * rs_, false);
  vk::uploadOnce(ctx, idx_, p.idx.data(), p.idx.size() * sizeof(std::uint32_t));
  vk::uploadOnce(ctx, val_, val.data(), val.size());
  vk::uploadOnce(ctx, inv_, inv.data(), inv.size());
  vk::zeroBuffer(ctx, vec_);
  if (set_ != VK_NULL_HANDLE) ctx.freeDescriptorSet(set_);
  std::vector<const vk::Buffer*> b;
  for (const vk::Buffer& s : *host_.shared) b.push_back(&s);
  b[kBindIdx] = &idx_;
  b[kBindVal] = &val_;
  b[kBindVec] = &vec_;
  b[kBindInv] = &inv_;
  b[kBindRes0] = &res0_;
  b[kBindD0] = &d0_;
  b[kBindAd0] = &ad0_;
  set_ = ctx.descriptorSet(b);
  amg_.layoutUploaded();
}

void VulkanAmg::recordWarps(VkCommandBuffer cb, const BodySet& running) {
  amg_.warps(running, [&](std::size_t first, const std::vector<double>& values) {
    const std::vector<unsigned char> bytes = realBytes(values, host_.isDouble);
    vk::updateBuffer(cb, val_, (rotations_ + 9 * first) * rs_, bytes.data(), bytes.size());
  });
  vk::fullBarrier(cb);
}

void VulkanAmg::fine(VkCommandBuffer cb, std::uint32_t mode, std::uint32_t flags) const {
  VulkanPush push;
  push.mode = mode;
  push.flags = flags;
  const bool warp = mode == kUnwarp || mode == kWarpAdd;
  push.o[0] = warp ? nodeAggregate_ : scale_;
  push.o[1] = rotations_;
  host_.dispatch(cb, pipeline_, set_, push, static_cast<std::uint32_t>(host_.nodeTotal / kWg));
}

void VulkanAmg::rows(VkCommandBuffer cb, std::uint32_t mode, std::size_t rows, std::uint32_t flags,
                     std::initializer_list<std::uint32_t> offsets) const {
  if (rows == 0) return;
  VulkanPush push;
  push.mode = mode;
  push.flags = flags;
  push.rows = static_cast<std::uint32_t>(rows);
  std::size_t i = 0;
  for (std::uint32_t o : offsets) push.o[i++] = o;
  host_.dispatch(cb, pipeline_, set_, push, groupsOf(rows));
}

void VulkanAmg::spmv(VkCommandBuffer cb, const Matrix& m, std::uint32_t x, std::uint32_t b, bool residual,
                     std::uint32_t y) const {
  rows(cb, kSpmv, m.rows, residual ? kResidual : 0u, {m.start, m.cols, m.values, x, b, y});
}

void VulkanAmg::coarse(VkCommandBuffer cb, std::size_t k) const {
  // The V-cycle on device level k (>= 1) for L.b into L.x (EngineAmg::coarse).
  const Level& L = levels_[k - 1];
  const bool deeper = k < levels_.size();
  if (!L.smooths) {  // every body's coarsest level: its exact solve alone
    rows(cb, kCoarsest, L.rows, 0, {L.inverse.start, L.inverse.cols, L.inverse.values, L.b, L.x});
    return;
  }
  // Pre-smoothing from 0.
  rows(cb, kCoarseBegin, L.rows, kZero, {L.dinv, L.b, L.b, L.res, L.d, L.x});
  spmv(cb, L.A, L.d, 0, false, L.t);
  rows(cb, kCoarseStep, L.rows, 0, {L.dinv, L.t, L.res, L.d, L.x});
  if (deeper) {
    const Level& N = levels_[k];
    spmv(cb, L.A, L.x, L.b, true, L.t);  // t = b - A x
    spmv(cb, L.Pt, L.t, 0, false, N.b);
    coarse(cb, k + 1);
    spmv(cb, L.P, N.x, 0, false, L.t);
    rows(cb, kCoarseAdd, L.rows, 0, {L.t, L.x});
  }
  // Post-smoothing.
  spmv(cb, L.A, L.x, 0, false, L.t);
  rows(cb, kCoarseBegin, L.rows, 0, {L.dinv, L.b, L.t, L.res, L.d, L.x});
  spmv(cb, L.A, L.d, 0, false, L.t);
  rows(cb, kCoarseStep, L.rows, 0, {L.dinv, L.t, L.res, L.d, L.x});
  // The bodies whose coarsest level this is: x = A^-1 b (only their rows).
  if (L.inverseEntries > 0) rows(cb, kCoarsest, L.rows, 0, {L.inverse.start, L.inverse.cols, L.inverse.values, L.b, L.x});
}

void VulkanAmg::recordCycle(VkCommandBuffer cb, bool setup) {
  // Level 0: u = M^-1 r with the current operator (EngineAmg::cycle).
  fine(cb, kFineBegin, kZero);
  host_.product(cb, productD_);
  fine(cb, kFineStep, 0);
  if (!levels_.empty()) {
    host_.product(cb, productU_);
    fine(cb, kUnwarp, 0);
    spmv(cb, Pt0_, 0, 0, false, levels_[0].b);  // e0 is amgVec's first part
    coarse(cb, 1);
    spmv(cb, P0_, levels_[0].x, 0, false, 0);
    fine(cb, kWarpAdd, 0);
  }
  host_.product(cb, productU_);
  fine(cb, kFineBegin, 0);
  host_.product(cb, productD_);
  fine(cb, kFineStep, kLast | (setup ? kSetup : 0u));
}

std::vector<DeviceBuffer> VulkanAmg::buffers() const {
  std::vector<DeviceBuffer> out;
  for (const vk::Buffer* b : {&res0_, &d0_, &ad0_}) out.push_back({"amg level-0 vectors", b->bytes()});
  out.push_back({"amg levels (indices)", idx_.bytes()});
  out.push_back({"amg levels (values, warp)", val_.bytes()});
  out.push_back({"amg coarse vectors", vec_.bytes()});
  out.push_back({"amg coarsest inverses", inv_.bytes()});
  return out;
}

}  // namespace corofem::detail
