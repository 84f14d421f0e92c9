// The OpenCL engine's launches, segment tables and transfers (segment_engine.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/segment_engine.hpp"
#include "backends/opencl/engine_amg.hpp"
#include "device/device_warped.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

using cl::checkCl;
using namespace layout;

// ---------------------------------------------------------------------------- launching, tables

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, cl_mem m) {
  // m may be NULL (an absent optional buffer): the kernel sees a NULL pointer (OpenCL 1.2, 5.7.2).
  k.setArg(i, &m, sizeof(cl_mem), dev_);
}

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, cl_uint v) { k.setArg(i, &v, sizeof(cl_uint), dev_); }

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, SumReal v) {
  if (sumSize_ == sizeof(double)) {
    k.setArg(i, &v.value, sizeof(double), dev_);
  } else {
    const float f = static_cast<float>(v.value);
    k.setArg(i, &f, sizeof(float), dev_);
  }
}

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, RealArg v) {
  if (double_) {
    k.setArg(i, &v.value, sizeof(double), dev_);
  } else {
    const float f = static_cast<float>(v.value);
    k.setArg(i, &f, sizeof(float), dev_);
  }
}

std::pair<std::size_t, std::size_t> SegmentEngine::spanItems(Span span, std::size_t lo, std::size_t hi) const {
  const BodySegment& a = segs_[lo];
  const BodySegment& b = segs_[hi - 1];
  const std::size_t nodes = b.nodeBegin + b.nodeSpan - a.nodeBegin;
  switch (span) {
    case Span::Elements: return {a.elemBegin / vec_, (b.elemBegin + b.elemSpan - a.elemBegin) / vec_};
    case Span::Nodes: return {a.nodeBegin, nodes};
    case Span::NodeChunks: return {a.nodeBegin / chunk_, nodes / chunk_};
    case Span::Segments: break;
  }
  return {lo * wg_, (hi - lo) * wg_};
}

void SegmentEngine::enqueue(const ClKernel& kernel, Span span) {
  // Only the work-groups of the span of active segments are launched (a global offset; the
  // kernels derive their work-group from the global id); inactive segments inside the span
  // return at once.
  const auto [offset, global] = spanItems(span, activeLo_, activeHi_);
  enqueueRange(kernel, offset, global, wg_);
}

void SegmentEngine::enqueueRange(const ClKernel& kernel, std::size_t offset, std::size_t global, std::size_t local) {
  cl_event event = nullptr;
  const cl_int status = clEnqueueNDRangeKernel(ctx_->queue(), kernel.get(), 1, &offset, &global, &local, 0,
                                               nullptr, profile_ ? &event : nullptr);
  if (event) {
    profileEvents_.emplace_back(kernel.name(), event);
    if (profileEvents_.size() > 4096) harvestProfile(false);
  }
  if (status != CL_SUCCESS)
    fail(ErrorCode::DeviceError, "clEnqueueNDRangeKernel('", kernel.name(), "', ", global,
         " work-items) failed with ", cl::errorString(status), " on OpenCL device '", dev_, "'");
}

void SegmentEngine::setActive(const std::vector<char>& active) {
  bool changed = false;
  activeLo_ = segs_.size();
  activeHi_ = 0;
  for (std::size_t s = 0; s < segs_.size(); ++s) {
    const char flag = active[s] == 0 ? 0 : active[s] == char(kSegRunningPacked) ? char(kSegRunningPacked) : char(kSegRunning);
    if (flag != 0) {
      activeLo_ = std::min(activeLo_, s);
      activeHi_ = s + 1;
    }
    if (flag != active_[s]) {
      changed = true;
      active_[s] = flag;
      segInfo_[kSegInfoCount * s + kSegActive] = static_cast<cl_uint>(flag);
    }
  }
  if (changed || segInfoStale_) uploadRaw(segInfoBuf_, segInfo_);
  segInfoStale_ = false;
}

void SegmentEngine::setCoefficients(std::size_t s, const SystemCoeffs& c) {
  // A = m M + c (alpha M + beta K^R) + k (K^R + S) = (m + c alpha) M + (k + c beta) K^R + k S.
  const BodySegment& sg = segs_[s];
  const double massCoef = c.mass + c.damping * sg.rayleighMass;
  const double stiffCoef = c.stiffness + c.damping * sg.rayleighStiffness;
  SpringFold fold;
  double deviceMass = massCoef;
  if (!springs_[s].empty() && c.stiffness != 0.0) {
    fold.factor = massCoef != 0.0 ? c.stiffness / massCoef : c.stiffness;
    fold.unitMass = massCoef == 0.0;
    if (fold.unitMass) deviceMass = 1.0;
  }
  // With no mass term and no spring term (a damping product of beta alone) mass_ is multiplied by
  // 0: whatever it holds serves, and the solves' fold stays (no upload a Newton iteration).
  const bool unused = massCoef == 0.0 && c.stiffness == 0.0;
  if (!unused && (springFoldStale_[s] || !(fold == springFold_[s]))) foldSprings(s, fold);
  operatorMass_[s] = massCoef;
  double* coef = &segCoef_[kSegCoefCount * s];
  const double next[4] = {stiffCoef * coef[kCoefLambda], stiffCoef * coef[kCoefMu], deviceMass, stiffCoef};
  double* slot[4] = {&coef[kCoefProdLambda], &coef[kCoefProdMu], &coef[kCoefMass], &coef[kCoefStiff]};
  for (int i = 0; i < 4; ++i)
    if (*slot[i] != next[i]) {
      *slot[i] = next[i];
      coefDirty_ = true;
    }
}

void SegmentEngine::foldSprings(std::size_t s, const SpringFold& fold) {
  const BodySegment& sg = segs_[s];
  if (!hasMass_)
    fail(ErrorCode::DeviceError, "OpenCL backend: body '", sg.problem->name, "' has springs on a device with no mass "
         "buffer (static bodies only); its product has no diagonal term to carry them");
  const Eigen::VectorXd& mass = sg.problem->lumpedMass;
  std::vector<unsigned char> bytes(sg.dofs() * realSize_);
  detail::withReals(bytes.data(), double_, 0, [&](auto* out) {
    using T = std::remove_pointer_t<decltype(out)>;
    for (std::size_t d = 0; d < sg.dofs(); ++d) {
      const double m = fold.unitMass ? 0.0 : mass[static_cast<Eigen::Index>(sg.hostDof(d))];
      out[d] = static_cast<T>(fold.factor == 0.0 ? m : m + fold.factor * springs_[s][d]);
    }
  });
  enqueueWrite(mass_, sg.dofBegin() * realSize_, std::move(bytes));
  springFold_[s] = fold;
  springFoldStale_[s] = 0;
  axReady_[s] = 0;  // formed with the mass of before
}

void SegmentEngine::setSprings(const BodySet& bodies, const std::vector<const Problem*>& problems) {
  if (problems.size() != bodies.size())
    fail(ErrorCode::Internal, "OpenCL backend: ", problems.size(), " spring sets for ", bodies.size(), " bodies");
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const std::size_t s = bodies[i];
    const BodySegment& sg = segs_.at(s);
    const Eigen::VectorXd& k = problems[i]->springStiffness;
    if (k.size() != 0 && static_cast<std::size_t>(k.size()) != sg.dofs())
      fail(ErrorCode::Internal, "OpenCL backend: body '", sg.problem->name, "' got ", k.size(),
           " spring stiffnesses for ", sg.dofs(), " dofs");
    std::vector<double> device;
    if (k.size() != 0 && (k.array() != 0.0).any()) {
      device.resize(sg.dofs());
      for (std::size_t d = 0; d < sg.dofs(); ++d) device[d] = k[static_cast<Eigen::Index>(sg.hostDof(d))];
    }
    if (device.empty() && springs_[s].empty()) continue;
    springs_[s] = std::move(device);
    springFoldStale_[s] = 1;  // folded again by the next coefficients
    axReady_[s] = 0;
  }
}

void SegmentEngine::flushCoefficients() {
  if (!coefDirty_) return;
  upload(segCoefBuf_, segCoef_.data(), 0, segCoef_.size());
  coefDirty_ = false;
}

std::vector<char> SegmentEngine::activeOf(const BodySet& bodies) const {
  std::vector<char> active(segs_.size(), 0);
  for (std::size_t s : bodies) active[s] = 1;
  return active;
}

// ---------------------------------------------------------------------------- transfers

void SegmentEngine::enqueueWrite(const ClBuffer& buf, std::size_t offset, std::vector<unsigned char>&& bytes) {
  // Non-blocking: the host goes on enqueuing while the copy travels. The bytes stay alive (here)
  // until the write's event says it is done; a blocking read (download) drains them all.
  while (!writes_.empty()) {
    cl_int status = CL_QUEUED;
    clGetEventInfo(writes_.front().event, CL_EVENT_COMMAND_EXECUTION_STATUS, sizeof(status), &status, nullptr);
    if (status != CL_COMPLETE && writes_.size() < kMaxPendingWrites) break;
    const cl_int wait = status == CL_COMPLETE ? CL_SUCCESS : clWaitForEvents(1, &writes_.front().event);
    clReleaseEvent(writes_.front().event);
    writes_.pop_front();
    checkCl(wait, "clWaitForEvents (write)", dev_);
  }
  PendingWrite w{std::move(bytes), nullptr};
  checkCl(clEnqueueWriteBuffer(ctx_->queue(), buf.get(), CL_FALSE, offset, w.bytes.size(), w.bytes.data(), 0, nullptr,
                               &w.event),
          "clEnqueueWriteBuffer", dev_);
  writes_.push_back(std::move(w));
}

void SegmentEngine::writesDone() {
  for (PendingWrite& w : writes_) clReleaseEvent(w.event);  // complete: a blocking command followed them
  writes_.clear();
}

void SegmentEngine::upload(const ClBuffer& buf, const double* src, std::size_t begin, std::size_t count) {
  if (count == 0) return;
  std::vector<unsigned char> bytes(count * realSize_);
  if (double_) {
    std::memcpy(bytes.data(), src + begin, count * sizeof(double));
  } else {
    float* out = reinterpret_cast<float*>(bytes.data());
    for (std::size_t i = 0; i < count; ++i) out[i] = static_cast<float>(src[begin + i]);
  }
  enqueueWrite(buf, begin * realSize_, std::move(bytes));
}

void SegmentEngine::setConstraints(const BodySet& bodies, const std::vector<const std::vector<std::uint8_t>*>& constrained) {
  if (constrained.size() != bodies.size())
    fail(ErrorCode::Internal, "OpenCL backend: ", constrained.size(), " constraint masks for ", bodies.size(), " bodies");
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    BodySegment& sg = segs_.at(bodies[i]);
    const std::vector<std::uint8_t>& mask = *constrained[i];
    if (mask.size() != sg.dofs())
      fail(ErrorCode::Internal, "OpenCL backend: body '", sg.problem->name, "' got ", mask.size(),
           " constraint flags for ", sg.dofs(), " dofs");
    // The mask in the device's numbering, and the free mask the kernels project with (1 free, 0
    // constrained) over the segment's real dofs (its padding stays constrained).
    std::vector<unsigned char> bytes(sg.dofs() * realSize_);
    detail::withReals(bytes.data(), double_, 0, [&](auto* out) {
      for (std::size_t d = 0; d < sg.dofs(); ++d) {
        sg.constrained[d] = mask[sg.hostDof(d)] ? 1 : 0;
        out[d] = sg.constrained[d] ? 0 : 1;
      }
    });
    enqueueWrite(free_, sg.dofBegin() * realSize_, std::move(bytes));
    // What the device knew of the body's last solve (its x, A x) was on the old projection.
    xKnown_[bodies[i]] = 0;
    axReady_[bodies[i]] = 0;
    warmLast_[bodies[i]] = 0;
    if (amg_) amg_->constraintsChanged(bodies[i]);
    if (warped_) warped_->constraintsChanged(bodies[i]);
  }
}

void SegmentEngine::setMaterial(const BodySet& bodies, const std::vector<const Problem*>& problems) {
  if (problems.size() != bodies.size())
    fail(ErrorCode::Internal, "OpenCL backend: ", problems.size(), " materials for ", bodies.size(), " bodies");
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const std::size_t s = bodies[i];
    BodySegment& sg = segs_.at(s);
    const Problem& p = *problems[i];
    sg.rayleighMass = p.rayleighMass;
    sg.rayleighStiffness = p.rayleighStiffness;
    segCoef_[kSegCoefCount * s + kCoefLambda] = p.lame.lambda;
    segCoef_[kSegCoefCount * s + kCoefMu] = p.lame.mu;
    // What was formed with the old material: the energy, A x of a warm start, the node blocks.
    energyKnown_[s] = 0;
    axReady_[s] = 0;
    blocksStale_[s] = 1;
    if (amg_) amg_->invalidate(s);
    if (warped_) warped_->invalidate(s);
  }
  // The element kernels read lambda and mu from the coefficients buffer: upload them now (the solve
  // coefficients that multiply them are formed again by the next setCoefficients).
  coefDirty_ = true;
  flushCoefficients();
}

void SegmentEngine::download(const ClBuffer& buf, double* dst, std::size_t begin, std::size_t count) {
  if (count == 0) return;
  staging_.resize(count * realSize_);
  checkCl(clEnqueueReadBuffer(ctx_->queue(), buf.get(), CL_TRUE, begin * realSize_, count * realSize_,
                              staging_.data(), 0, nullptr, nullptr),
          "clEnqueueReadBuffer", dev_);
  writesDone();
  if (double_) {
    std::memcpy(dst + begin, staging_.data(), count * sizeof(double));
  } else {
    const float* in = reinterpret_cast<const float*>(staging_.data());
    for (std::size_t i = 0; i < count; ++i) dst[begin + i] = in[i];
  }
}

std::pair<std::size_t, std::size_t> SegmentEngine::dofRange(const BodySet& bodies) const {
  std::size_t lo = 3 * nodeTotal_, hi = 0;
  for (std::size_t s : bodies) {
    lo = std::min(lo, segs_[s].dofBegin());
    hi = std::max(hi, segs_[s].dofBegin() + segs_[s].dofs());
  }
  return {lo, std::max(lo, hi)};
}

void SegmentEngine::checkSizes(const BodySet& bodies, std::size_t vectors, const char* what) const {
  if (vectors != bodies.size())
    fail(ErrorCode::Internal, "OpenCL backend: ", vectors, " vectors (", what, ") for ", bodies.size(), " bodies");
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i] >= segs_.size() || (i > 0 && bodies[i] <= bodies[i - 1]))
      fail(ErrorCode::Internal, "OpenCL backend: the bodies of a call must be distinct, ascending and below ",
           segs_.size());
}

void SegmentEngine::checkSizes(const BodySet& bodies, const ConstVectors& v, const char* what) const {
  checkSizes(bodies, v.size(), what);
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (!v[i] || static_cast<std::size_t>(v[i]->size()) != segs_[bodies[i]].dofs())
      fail(ErrorCode::Internal, "OpenCL backend: body '", segs_[bodies[i]].problem->name, "': ", what, " has ",
           v[i] ? v[i]->size() : 0, " entries, expected 3N = ", segs_[bodies[i]].dofs());
}

void SegmentEngine::finish() {
  checkCl(clFinish(ctx_->queue()), "clFinish", dev_);
  writesDone();
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
