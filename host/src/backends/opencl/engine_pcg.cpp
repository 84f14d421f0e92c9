// The OpenCL engine's PCG building blocks (segment_engine.hpp; the loop is solve/pcg.cpp's):
// the set-up, the launched iterations (kernels/opencl/pcg.cl), the non-blocking reads of the
// scalars, the true residual and the read of x. The CPU devices' one-launch iterations are
// cpu_pcg.cpp's.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/cpu_pcg.hpp"
#include "backends/opencl/engine_amg.hpp"
#include "backends/opencl/segment_engine.hpp"
#include "device/device_warped.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

using cl::checkCl;
using namespace layout;

void SegmentEngine::pcgSetup(bool zeroStart, bool haveAx, const std::vector<char>* productFor, bool onlyFor) {
  // r = b - A x (projected), u = M^-1 r, p = s = 0, w = A u; gamma = r.u, rr = r.r, bb = b.b,
  // alpha = gamma / u.w, beta = 0 (kernels/opencl/pcg.cl)
  flushCoefficients();
  const bool anyFor =
      productFor && std::any_of(productFor->begin(), productFor->end(), [](char c) { return c != 0; });
  if (onlyFor) {  // the packs' bodies take the whole set-up in pcg_iterate_pack
    if (!anyFor) return;
    setActive(*productFor);
  }
  if (!zeroStart && !haveAx) product(x_, q_, true, partialsW_);  // a zero start needs no A x
  // M^-1 of the coefficients is formed here too (pcg_init), stored for the iterations.
  launch(kPcgInit_, Span::NodeChunks, nodeSeg_, segInfoBuf_, segCoefBuf_, blocks_, mass_, cl_uint(zeroStart ? 1 : 0),
         b_, q_, free_, minv_, r_, z_, p_, s_, partials_);
  if (amg_) amg_->cycle(true);  // u = M^-1 r by the V-cycle, over pcg_init's node-block one
  if (warped_) hostPrecondition();  // u = M^-1 r by the factor, over pcg_init's u = r
  if (productFor) {  // the packs' bodies take w = A u and the first scalars in pcg_iterate_pack
    if (!anyFor) return;
    setActive(*productFor);
  }
  productAndFinish(kReduceInit);
}

void SegmentEngine::productAndFinish(cl_uint mode) {
  product(z_, q_, true, partialsW_);
  launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, mode,
         SumReal{round_.tolerance * round_.tolerance});
}

void SegmentEngine::pcgIteration(bool last) {
  // p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s, u = M^-1 r; w = A u; alpha, beta.
  // The iteration cap's last iteration has no successor: no w = A u, only gamma and r . r.
  launch(kPcgUpdate_, Span::NodeChunks, nodeSeg_, segInfoBuf_, scalars_, q_, minv_, p_, s_, x_, r_, z_, partials_);
  // u = M^-1 r by the V-cycle, over pcg_update's node-block one. The cap's last iteration needs r . r
  // alone (the stop test), not u: no cycle.
  if (amg_ && !last) amg_->cycle(false);
  if (warped_ && !last) hostPrecondition();
  if (last)
    launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, cl_uint(kReduceLast),
           SumReal{round_.tolerance * round_.tolerance});
  else
    productAndFinish(kReduceStep);
}

void SegmentEngine::enqueuePcgIterations(const SystemCoeffs& c, int iterations) {
  for (std::size_t s = 0; s < segs_.size(); ++s) setCoefficients(s, c);
  refreshStaleBlocks(std::vector<char>(segs_.size(), 1));  // as pcgBegin does: the blocks of these rotations
  if (warped_) prepareWarped(allBodies(segs_.size()));  // before the segments are made active: it may launch
  setAllActive();
  std::fill(xKnown_.begin(), xKnown_.end(), 0);  // the iterations change x
  std::fill(axReady_.begin(), axReady_.end(), 0);
  std::fill(hostStopped_.begin(), hostStopped_.end(), 0);
  round_.tolerance = solver_.tolerance;
  if (amg_) amg_->prepare(allBodies(segs_.size()));
  pcgSetup(false, false);
  for (int i = 0; i < iterations; ++i) pcgIteration(i + 1 == iterations);
  segInfoStale_ = true;  // the device may have stopped a segment: the next setActive uploads the table
}

std::vector<BodySet> SegmentEngine::pcgTiles(const BodySet& bodies) const {
  // A round whose iterations run one work-group per body (pcg_iterate_group) needs no tiles: each
  // group's body stays in its core's cache, and one launch for all balances the cores best.
  return tiles(bodies, cpu_->groupTeam(bodies) > 0 ? 0 : tileBytes_);
}

std::vector<PcgStart> SegmentEngine::pcgBegin(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs,
                                              const ConstVectors& bs, const ConstVectors& xs, double tolerance,
                                              int maxIterations) {
  checkSizes(bodies, bs, "the right-hand side b");
  checkSizes(bodies, xs.size(), "the starting vectors");
  checkSizes(bodies, coeffs.size(), "the coefficients");
  dropReads(true);  // a solve that ended in an error leaves its reads
  round_ = Round{};
  std::fill(hostStopped_.begin(), hostStopped_.end(), 0);
  round_.bodies = bodies;
  round_.running.assign(bodies.size(), 0);
  round_.cap = std::max(0, maxIterations);
  round_.tolerance = tolerance;
  std::vector<PcgStart> out(bodies.size(), PcgStart::Running);
  // Per body: b packed into its stage in device precision (constrained rows zero, even if not
  // finite) in the pass that sums b . b over the free dofs (per chunk, the chunks in order).
  unsigned char* bStage = bStage_.writable();
  BodySet running;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const BodySegment& sg = segs_[bodies[i]];
    const Eigen::VectorXd& b = *bs[i];
    std::vector<double> bbParts(chunkCount(sg.dofs(), hostChunk_), 0.0);
    parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      withReals(bStage, sg.dofBegin(), [&](auto* dst) {
        using T = std::remove_pointer_t<decltype(dst)>;
        double sum = 0.0;
        for (std::size_t d = lo; d < hi; ++d) {
          const T v = static_cast<T>(sg.constrained[d] ? 0.0 : b[static_cast<Eigen::Index>(sg.hostDof(d))]);
          sum += static_cast<double>(v) * static_cast<double>(v);  // of what the device gets: b below
          dst[d] = v;                                                // float's range is 0 there too
        }
        bbParts[c] = sum;
      });
    });
    double bb = 0.0;
    for (double part : bbParts) bb += part;
    if (!std::isfinite(bb)) {
      out[i] = PcgStart::NonFiniteRhs;
      continue;
    }
    if (bb == 0.0) {
      out[i] = PcgStart::ZeroRhs;
      continue;
    }
    setCoefficients(bodies[i], coeffs[i]);
    round_.running[i] = 1;
    running.push_back(bodies[i]);
  }
  if (running.empty()) return out;
  const auto [lo, hi] = dofRange(running);
  round_.lo = lo;
  round_.hi = hi;
  std::vector<char> active = activeOf(running);
  // How the iterations run (cpu_pcg.hpp); in a round of one work-group per body, the bodies of packs
  // are flagged for pcg_iterate_pack, which pcg_iterate_group leaves alone.
  timedTicket_ = ~PcgTicket{0};
  round_.team = cpu_->chooseTeam(cpu_->groupTeam(running), running);
  round_.packed.assign(segs_.size(), 0);
  if (round_.team == 1) round_.packTable = cpu_->packRound(running, round_.packed);
  for (std::size_t s : running) {
    if (round_.packed[s]) active[s] = char(kSegRunningPacked);
    else round_.unpacked = true;
  }
  setActive(active);
  bStage_.write(b_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  // x in one pass: packed (constrained and non-finite entries zero) into its stage, compared bit
  // for bit with what the device holds, and tested for zero. Only the running segments decide
  // (those in between are scratch, not computed): x is uploaded unless the device holds it already,
  // and a start of x = 0 on every running body (Newton's corrections start there) skips the
  // product of r = b - A x.
  bool xThere = true, zeroStart = true;
  unsigned char* xStage = xStage_.writable();
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    if (!round_.running[i]) continue;
    const std::size_t s = bodies[i];
    const BodySegment& sg = segs_[s];
    const Eigen::VectorXd& x = *xs[i];
    const bool sized = static_cast<std::size_t>(x.size()) == sg.dofs();
    // The stage changes now and the upload below may fail: unknown until it is done.
    const bool known = xKnown_[s] != 0;
    xKnown_[s] = 0;
    std::vector<char> sameParts(chunkCount(sg.dofs(), hostChunk_), 1), zeroParts(sameParts.size(), 1);
    parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      withReals(xStage, sg.dofBegin(), [&](auto* dst) {
        using T = std::remove_pointer_t<decltype(dst)>;
        bool same = known, zero = true;
        for (std::size_t d = lo; d < hi; ++d) {
          const double v = sized ? x[static_cast<Eigen::Index>(sg.hostDof(d))] : 0.0;
          const double packed = sg.constrained[d] || !std::isfinite(v) ? 0.0 : v;
          const T t = static_cast<T>(packed);
          same = same && std::memcmp(&t, &dst[d], sizeof(T)) == 0;
          zero = zero && packed == 0.0;
          dst[d] = t;
        }
        sameParts[c] = same;
        zeroParts[c] = zero;
      });
    });
    bool bodyZero = true;
    for (std::size_t c = 0; c < sameParts.size(); ++c) {
      xThere = xThere && known && sameParts[c];
      bodyZero = bodyZero && zeroParts[c];
    }
    zeroStart = zeroStart && bodyZero;
    warmLast_[s] = !bodyZero;  // its own start, not the round's
  }
  if (!xThere) {
    xStage_.write(x_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
    for (std::size_t s = 0; s < segs_.size(); ++s)  // the write covers the bodies in between too
      if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) axReady_[s] = 0;
  }
  // A x formed behind the forces (internalForces) serves if x and every coefficient are unchanged.
  bool haveAx = !zeroStart && xThere;
  for (std::size_t s : running)
    haveAx = haveAx && axReady_[s] &&
             std::equal(&segCoef_[kSegCoefCount * s], &segCoef_[kSegCoefCount * (s + 1)], &axCoef_[kSegCoefCount * s]);
  for (std::size_t s : running) axReady_[s] = 0;  // their q_ is the iterations' from here
  // The packs' bodies run their whole solve in pcg_iterate_pack (packWhole): the set-up's w = A u
  // and first scalars, the iterations, the cap's last iteration and the true residual. Not where the
  // cap leaves the pack no iteration (it is not launched then). From a zero start (Newton's
  // corrections) the packs form the whole set-up themselves (packFresh): their bodies' node blocks,
  // M^-1 and pcg_init too, from a_i, b and the mass, with nothing launched for them, and pack_in
  // copies neither the PCG vectors nor M^-1.
  round_.packWhole = !round_.packTable.empty() && round_.cap > 1;
  round_.packFresh = round_.packWhole && zeroStart;
  std::vector<char> unpackedOnly = active;
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (round_.packed[s]) unpackedOnly[s] = 0;
  // The node blocks of the bodies rotated since they were formed, for pcg_init's M^-1 (the packs'
  // own with packFresh: theirs stay stale for a later solve outside a pack).
  refreshStaleBlocks(round_.packFresh ? unpackedOnly : active);
  if (amg_) amg_->prepare(running);
  if (warped_) prepareWarped(running);
  setActive(active);
  if (round_.packWhole) {
    // The packed bodies' segments stay inactive from here (pcgSetup made the unpacked ones the
    // active ones): pcg_iterate_pack marks its lanes running itself. Uploading the table again would
    // revive an unpacked body that reduce_finish stopped at the set-up.
    pcgSetup(zeroStart, haveAx, &unpackedOnly, round_.packFresh);
  } else {
    pcgSetup(zeroStart, haveAx);
  }
  // From here the device may stop segments on its own: the host never writes the segment table
  // while iterating (that could revive a segment the device stopped).
  segInfoStale_ = true;
  return out;
}

void SegmentEngine::narrowSpan(const std::vector<char>& running) {
  // The host's view only: the device's table stays as the device left it.
  activeLo_ = segs_.size();
  activeHi_ = 0;
  for (std::size_t i = 0; i < round_.bodies.size(); ++i) {
    const bool on = round_.running[i] && running[i];
    hostStopped_[round_.bodies[i]] = on ? 0 : 1;
    if (on) {
      activeLo_ = std::min(activeLo_, round_.bodies[i]);
      activeHi_ = std::max(activeHi_, round_.bodies[i] + 1);
    }
  }
}

void SegmentEngine::pcgIterate(int n, const std::vector<char>& running) {
  n = std::min(n, round_.cap - round_.enqueued);
  if (n <= 0) return;
  if (round_.enqueued > 0) narrowSpan(running);
  if (round_.team > 0) {
    // Every iteration but the cap's last in one launch (a work-group, or a team, per body, and the
    // packs), then the last launched.
    const cl_uint iterations = cl_uint(round_.cap - round_.enqueued - 1);
    if (iterations > 0) {  // timed to the read that follows (pcgTake)
      cpu_->roundStarted();
      timedTicket_ = firstTicket_ + reads_.size();
      cpu_->launchIterations(iterations);
    }
    pcgIteration(true);
    round_.enqueued = round_.cap;
    return;
  }
  for (int i = 0; i < n; ++i) pcgIteration(round_.enqueued + i + 1 == round_.cap);
  round_.enqueued += n;
}

PcgTicket SegmentEngine::pcgRead() {
  Read r;
  r.bytes.resize(kScalarCount * segs_.size() * sumSize_);
  checkCl(clEnqueueReadBuffer(ctx_->queue(), scalars_.get(), CL_FALSE, 0, r.bytes.size(), r.bytes.data(), 0, nullptr,
                              &r.event),
          "clEnqueueReadBuffer (PCG scalars)", dev_);
  reads_.push_back(std::move(r));
  return firstTicket_ + reads_.size() - 1;
}

void SegmentEngine::pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) {
  if (reads_.empty() || ticket != firstTicket_) fail(ErrorCode::Internal, "OpenCL backend: PCG reads taken out of order");
  Read r = std::move(reads_.front());
  reads_.pop_front();
  ++firstTicket_;
  const cl_int status = clWaitForEvents(1, &r.event);
  clReleaseEvent(r.event);
  checkCl(status, "clWaitForEvents (PCG scalars)", dev_);
  scalars.resize(round_.bodies.size());
  for (std::size_t i = 0; i < round_.bodies.size(); ++i) {
    const std::size_t at = kScalarCount * round_.bodies[i];
    auto value = [&](unsigned k) {
      return sumSize_ == sizeof(double) ? reinterpret_cast<const double*>(r.bytes.data())[at + k]
                                        : static_cast<double>(reinterpret_cast<const float*>(r.bytes.data())[at + k]);
    };
    scalars[i].iterations = static_cast<int>(value(kScalarIterations));
    scalars[i].rr = value(kScalarRr);
    scalars[i].bb = value(kScalarBb);
    scalars[i].stop = static_cast<PcgStop>(static_cast<unsigned>(value(kScalarStop)));
  }
  if (ticket == timedTicket_) {  // the one-launch round's read: its time per iteration
    int iterations = 0;
    for (std::size_t i = 0; i < round_.bodies.size(); ++i)
      if (round_.running[i]) iterations = std::max(iterations, scalars[i].iterations);
    cpu_->roundDone(iterations);
  }
}

void SegmentEngine::dropReads(bool wait) {
  for (Read& r : reads_) {
    if (wait) clWaitForEvents(1, &r.event);  // the device may still write into r.bytes
    clReleaseEvent(r.event);
  }
  firstTicket_ += reads_.size();
  reads_.clear();
}

void SegmentEngine::pcgResidual(const std::vector<char>& bodies) {
  round_.residualFor.assign(segs_.size(), 0);
  std::vector<char> on(segs_.size(), 0);
  bool any = false;
  for (std::size_t i = 0; i < round_.bodies.size(); ++i)
    if (bodies[i] && round_.running[i]) {
      round_.residualFor[round_.bodies[i]] = 1;
      // pcg_iterate_pack formed the packed bodies' residuals (and made them inactive).
      if (!(round_.packWhole && round_.packed[round_.bodies[i]])) on[round_.bodies[i]] = any = true;
    }
  if (!any) return;
  setActive(on);  // after every queued iteration: no segment the device stopped can be revived
  // r = free b - A x and its sums from the gather itself (what pcg_init would form: the same bits)
  product(x_, r_, true, partials_, &b_);
  launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, cl_uint(kReduceResidual),
         SumReal{0.0});
}

void SegmentEngine::pcgEnd(const std::vector<int>& iterations, const Vectors& xs, std::vector<PcgScalars>& residual) {
  checkSizes(round_.bodies, xs.size(), "the solutions");
  residual.assign(round_.bodies.size(), PcgScalars{});
  for (std::size_t i = 0; i < round_.bodies.size(); ++i)
    if (round_.running[i]) lastIterations_[round_.bodies[i]] = iterations[i];
  if (std::none_of(round_.running.begin(), round_.running.end(), [](char c) { return c != 0; })) return;
  // Reads enqueued after everything had stopped (no-ops) are dropped without waiting; their bytes
  // stay alive until the blocking read of x below has drained the queue.
  std::deque<Read> dropped = std::move(reads_);
  reads_.clear();
  firstTicket_ += dropped.size();
  const bool anyTrue = std::any_of(round_.residualFor.begin(), round_.residualFor.end(), [](char c) { return c != 0; });
  PcgTicket trueRead = 0;
  if (anyTrue) trueRead = pcgRead();  // completes with the blocking read of x: one synchronisation for both
  const std::size_t lo = round_.lo, hi = round_.hi;
  for (std::size_t s = 0; s < segs_.size(); ++s)  // the read overwrites [lo, hi) of the stage
    if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) xKnown_[s] = 0;
  try {
    xStage_.read(x_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
    writesDone();
  } catch (...) {
    for (Read& r : dropped) {
      clWaitForEvents(1, &r.event);
      clReleaseEvent(r.event);
    }
    dropReads(true);
    throw;
  }
  for (Read& r : dropped) clReleaseEvent(r.event);  // complete: the blocking read of x followed them
  for (std::size_t s = 0; s < segs_.size(); ++s)  // the stage holds the device's x over [lo, hi)
    if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) xKnown_[s] = 1;
  if (anyTrue) {
    std::vector<PcgScalars> all;
    pcgTake(trueRead, all);
    for (std::size_t i = 0; i < round_.bodies.size(); ++i)
      if (round_.residualFor[round_.bodies[i]]) residual[i] = all[i];
  }
  for (std::size_t i = 0; i < round_.bodies.size(); ++i)
    if (round_.running[i]) getReals(xStage_.data(), segs_[round_.bodies[i]], *xs[i]);
}

long long SegmentEngine::amgBuilds() const { return amg_ ? amg_->builds() : 0; }
long long SegmentEngine::warpedBuilds() const { return warped_ ? warped_->builds() : 0; }

void SegmentEngine::prepareWarped(const BodySet& running) {
  std::vector<std::pair<double, double>> coefficients;
  for (std::size_t s : running)
    coefficients.emplace_back(operatorMass_[s], segCoef_[kSegCoefCount * s + kCoefStiff]);
  warped_->prepare(running, coefficients, [this](const BodySet& due) { return readRotations(due); });
}

void SegmentEngine::hostPrecondition() {
  if (activeLo_ >= activeHi_) return;
  // The span's r, partials and segment table, in queue order after the kernel that formed r (the
  // table: which segments the device has stopped since the host last read their scalars).
  const std::size_t dofLo = segs_[activeLo_].dofBegin();
  const std::size_t dofHi = segs_[activeHi_ - 1].dofBegin() + 3 * segs_[activeHi_ - 1].nodeSpan;
  const std::size_t partLo = kPartialComponents * partialBegin(activeLo_);
  const std::size_t partHi = kPartialComponents * (partialBegin(activeHi_ - 1) + partialCount(activeHi_ - 1));
  std::vector<unsigned char>& r = warpedR_;
  std::vector<cl_uint>& table = warpedTable_;
  r.resize((dofHi - dofLo) * realSize_);
  table.resize(kSegInfoCount * (activeHi_ - activeLo_));
  std::vector<unsigned char> parts((partHi - partLo) * sumSize_);  // each moved into its write
  std::vector<unsigned char> z(r.size());
  cl_event reads[2] = {nullptr, nullptr};
  checkCl(clEnqueueReadBuffer(ctx_->queue(), r_.get(), CL_FALSE, dofLo * realSize_, r.size(), r.data(), 0, nullptr,
                              &reads[0]),
          "clEnqueueReadBuffer", dev_);
  cl_int read = clEnqueueReadBuffer(ctx_->queue(), segInfoBuf_.get(), CL_FALSE,
                                    kSegInfoCount * activeLo_ * sizeof(cl_uint), table.size() * sizeof(cl_uint),
                                    table.data(), 0, nullptr, &reads[1]);
  if (read == CL_SUCCESS)
    read = clEnqueueReadBuffer(ctx_->queue(), partials_.get(), CL_TRUE, partLo * sumSize_, parts.size(), parts.data(),
                               0, nullptr, nullptr);
  if (read != CL_SUCCESS) clWaitForEvents(reads[1] ? 2 : 1, reads);  // nothing may write r or table after this
  for (cl_event e : reads)
    if (e) clReleaseEvent(e);  // done: the blocking read behind them on the in-order queue is
  checkCl(read, "clEnqueueReadBuffer", dev_);
  writesDone();
  // z over the span: each running segment's from the factor, and r . z in its first partial (the
  // others' sums kept: r . r, and b . b of pcg_init); elsewhere (padding, and segments stopped or
  // out of the solve, which read no z) r as pcg_init and pcg_update left it.
  std::memcpy(z.data(), r.data(), r.size());
  for (std::size_t s = activeLo_; s < activeHi_; ++s) {
    if (!active_[s] || hostStopped_[s] || table[kSegInfoCount * (s - activeLo_) + kSegActive] == 0) continue;
    const std::size_t at = (segs_[s].dofBegin() - dofLo) * realSize_;
    const double rz = warped_->apply(s, r.data() + at, z.data() + at, double_);
    const std::size_t first = kPartialComponents * partialBegin(s) - partLo;
    for (std::size_t g = 0; g < partialCount(s); ++g) {
      const double v = g == 0 ? rz : 0.0;
      if (sumSize_ == sizeof(double))
        reinterpret_cast<double*>(parts.data())[first + kPartialComponents * g] = v;
      else
        reinterpret_cast<float*>(parts.data())[first + kPartialComponents * g] = static_cast<float>(v);
    }
  }
  enqueueWrite(z_, dofLo * realSize_, std::move(z));
  enqueueWrite(partials_, partLo * sumSize_, std::move(parts));
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
