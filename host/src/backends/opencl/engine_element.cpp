// The OpenCL engine's element operations (segment_engine.hpp): rotations, node blocks, forces,
// products and energies, on CPU devices in tiles of bodies whose working set fits the cache.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/segment_engine.hpp"
#include "backends/opencl/engine_amg.hpp"
#include "device/device_warped.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cstring>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

using cl::checkCl;
using namespace layout;

// ---------------------------------------------------------------------------- the Device's calls

namespace {

/// v[at, at + n) of a per-body vector list.
template <class V>
V slice(const V& v, std::size_t at, std::size_t n) {
  return V(v.begin() + static_cast<std::ptrdiff_t>(at), v.begin() + static_cast<std::ptrdiff_t>(at + n));
}

}  // namespace

void SegmentEngine::setPositions(const BodySet& bodies, const ConstVectors& x) {
  checkSizes(bodies, x, "the positions");
  if (amg_) amg_->positionsSet(bodies, x);
  if (warped_) warped_->positionsSet(bodies);
  std::size_t at = 0;
  for (const BodySet& tile : tiles(bodies, tileBytes_)) {
    setPositionsTile(tile, slice(x, at, tile.size()));
    at += tile.size();
  }
}

void SegmentEngine::internalForces(const BodySet& bodies, const Vectors& f) {
  checkSizes(bodies, f.size(), "the forces");
  std::size_t at = 0;
  for (const BodySet& tile : tiles(bodies, tileBytes_)) {
    internalForcesTile(tile, slice(f, at, tile.size()));
    at += tile.size();
  }
}

void SegmentEngine::apply(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
                          const Vectors& y) {
  checkSizes(bodies, p, "the vector p of apply");
  checkSizes(bodies, y.size(), "the products");
  checkSizes(bodies, coeffs.size(), "the coefficients");
  std::size_t at = 0;
  for (const BodySet& tile : tiles(bodies, tileBytes_)) {
    applyTile(tile, slice(coeffs, at, tile.size()), slice(p, at, tile.size()), slice(y, at, tile.size()));
    at += tile.size();
  }
}

void SegmentEngine::elasticEnergy(const BodySet& bodies, std::vector<double>& energy) {
  checkSizes(bodies, bodies.size(), "the energies");
  energy.assign(bodies.size(), 0.0);
  std::size_t at = 0;
  for (const BodySet& tile : tiles(bodies, tileBytes_)) {
    std::vector<double> e(tile.size());
    elasticEnergyTile(tile, e);
    std::copy(e.begin(), e.end(), energy.begin() + static_cast<std::ptrdiff_t>(at));
    at += tile.size();
  }
}

// ---------------------------------------------------------------------------- the launch sequences

void SegmentEngine::refreshBlocks(bool cornersWritten) {
  if (!formsBlocks()) return;
  const cl_uint S = static_cast<cl_uint>(stride_);
  if (!cornersWritten)
    launch(kCornerGradients_, Span::Elements, S, elemSeg_, segInfoBuf_, geom_, rotatedGradients(), elemOut_);
  launch(kBlocks_, Span::Nodes, nodeSeg_, segInfoBuf_, segCoefBuf_, nodeStart_, nodeEntries_, elemOut_, blocks_);
}

void SegmentEngine::refreshStaleBlocks(const std::vector<char>& running) {
  std::vector<char> stale(segs_.size(), 0);
  bool any = false;
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (running[s] && blocksStale_[s]) stale[s] = any = true;
  if (!any) return;
  // One pass for all of them: in tiles of the device cache (as SegmentEngine::run tiles a round)
  // the two passes took as long (100 bodies of 2,000 elements on 2 cores). corner_gradients reads
  // the a_i the rotations wrote: the same corners (store_corner_gradients of the same values), so
  // the same blocks as compute_rotations' corners gave.
  setActive(stale);
  refreshBlocks(false);
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (stale[s]) blocksStale_[s] = 0;
}

void SegmentEngine::ensureRotations() {
  if (rot_.get()) return;
  const std::size_t S = stride_;
  std::vector<double> rot(kRotComponents * S, 0.0);
  for (std::size_t e = 0; e < S; ++e) rot[0 * S + e] = rot[4 * S + e] = rot[8 * S + e] = 1.0;
  createReal(rot_, rot.size());
  upload(rot_, rot.data(), 0, rot.size());
}

void SegmentEngine::launchRotations(const std::vector<char>& rotate, bool writeCorners, bool writeR) {
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (rotate[s]) axReady_[s] = 0;  // A changes with the rotations (the positions may already be up)
  if (writeR) ensureRotations();
  setActive(rotate);
  // rot_ may be NULL here (not written: writeR is 0).
  launch(kRotations_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, elemNodes_, geom_, pos_, rot_,
         rotGrad_, quat_, elemOut_, cl_uint(writeCorners ? 1 : 0), cl_uint(writeR ? 1 : 0));
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (rotate[s]) rStale_[s] = !writeR;
}

void SegmentEngine::enqueueRotations() {
  std::vector<char> corotational(segs_.size());
  for (std::size_t s = 0; s < segs_.size(); ++s) corotational[s] = segs_[s].corotational;
  launchRotations(corotational, formsBlocks(), rAlways_);
}

void SegmentEngine::setPositionsTile(const BodySet& bodies, const ConstVectors& xs) {
  if (bodies.empty()) return;
  // Every kernel uses positions only through differences (F = sum (x_i - x_0) grad N_i^T, forces
  // and energy from F), so the device gets them relative to each body's centroid, subtracted in
  // double: a float body 1e4 m from the origin keeps the resolution of one near it.
  std::vector<char> rotate(segs_.size(), 0);
  unsigned char* stage = posStage_.writable();
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    BodySegment& sg = segs_[bodies[i]];
    const Eigen::VectorXd& x = *xs[i];
    // Summed per chunk of nodes, the chunks in order: the same bits with any number of threads.
    const std::size_t nodeChunk = std::max<std::size_t>(1, hostChunk_ / 2);
    std::vector<Eigen::Vector3d> parts(chunkCount(sg.nodes, nodeChunk), Eigen::Vector3d::Zero());
    parallelChunks(sg.nodes, nodeChunk, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (std::size_t n = lo; n < hi; ++n) sum += x.segment<3>(static_cast<Eigen::Index>(3 * n));
      parts[c] = sum;
    });
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& part : parts) centroid += part;
    centroid /= static_cast<double>(std::max<std::size_t>(sg.nodes, 1));
    putReals(stage, sg.dofBegin(), sg.dofs(),
             [&](std::size_t d) { return x[static_cast<Eigen::Index>(sg.hostDof(d))] - centroid[static_cast<Eigen::Index>(d % 3)]; });
    for (int a = 0; a < 3; ++a) sg.centroid[a] = centroid[a];
    rotate[bodies[i]] = sg.corotational;
    energyKnown_[bodies[i]] = 0;  // the energy of the new positions is not known yet
  }
  // One write of the packed range; the segments in between get their own unchanged positions.
  const auto [lo, hi] = dofRange(bodies);
  posStage_.write(pos_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  // The blocks rotate with R (linear bodies: constant, never stale); formed by the solve that needs
  // them (refreshStaleBlocks), not here: the corner gradients would be overwritten by the forces.
  launchRotations(rotate, false, rAlways_);
  if (formsBlocks())
    for (std::size_t s = 0; s < segs_.size(); ++s)
      if (rotate[s]) blocksStale_[s] = 1;
}

void SegmentEngine::enqueueElementForces() {
  setAllActive();
  static const ClBuffer none;  // the energies as internalForces has them stored (CPUs), for the benchmark
  launch(kForces_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_,
         rotatedGradients(), pos_, elemOut_, energyWithForces_ ? partials_ : none);
}

void SegmentEngine::enqueueForces() {
  std::fill(axReady_.begin(), axReady_.end(), 0);
  enqueueElementForces();
  launch(kGatherSum_, Span::Nodes, nodeSeg_, segInfoBuf_, nodeStart_, nodeEntries_, elemOut_, q_);
}

void SegmentEngine::internalForcesTile(const BodySet& bodies, const Vectors& out) {
  if (bodies.empty()) return;
  setActive(activeOf(bodies));
  static const ClBuffer none;
  launch(kForces_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_,
         rotatedGradients(), pos_, elemOut_, energyWithForces_ ? partials_ : none);
  launch(kGatherSum_, Span::Nodes, nodeSeg_, segInfoBuf_, nodeStart_, nodeEntries_, elemOut_, q_);
  for (std::size_t s : bodies) axReady_[s] = 0;  // their q_ now holds forces
  // The energies of these positions (CPUs): the element work-items' partials of the active span,
  // read before the forces (the same wait), for an elasticEnergy at the same positions.
  cl_event energies = nullptr;
  const std::size_t itemLo = energyWithForces_ ? readEnergyItems(&energies) : 0;
  // A solve usually follows, and one warm-started from the solution the device still holds (an
  // application's frame, warm-started from the previous velocities) begins with A x. Queued behind
  // the read of the forces, that product runs while the host takes them and forms b; the solve uses
  // it when x, the rotations and the coefficients are still those it was formed with (axReady_),
  // else forms its own. For the bodies whose last solve was warm-started: a body that is only
  // evaluated (no solve follows) pays one product for nothing.
  std::vector<char> speculate(segs_.size(), 0);
  bool any = false;
  for (std::size_t s : bodies)
    if (warmLast_[s] && xKnown_[s]) speculate[s] = any = true;
  const auto [lo, hi] = dofRange(bodies);
  cl_event forces = readStage_.readLater(q_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  auto waitForForces = [&]() {  // also on an error below: the reads write into host memory until done
    cl_int status = forces ? clWaitForEvents(1, &forces) : CL_SUCCESS;
    if (forces) clReleaseEvent(forces);
    forces = nullptr;
    const cl_int energyStatus = energies ? clWaitForEvents(1, &energies) : CL_SUCCESS;
    if (energies) clReleaseEvent(energies);
    energies = nullptr;
    return status != CL_SUCCESS ? status : energyStatus;
  };
  if (any) {
    try {
      setActive(speculate);
      product(x_, q_, true, partialsW_);
    } catch (...) {
      waitForForces();
      throw;
    }
  }
  checkCl(waitForForces(), "clWaitForEvents (forces)", dev_);
  // Not writesDone(): writes queued after the read (the segment table, the coefficients of the
  // product above) may still be waiting; the next blocking read releases them.
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (speculate[s]) {
      axReady_[s] = 1;
      std::copy_n(&segCoef_[kSegCoefCount * s], kSegCoefCount, &axCoef_[kSegCoefCount * s]);
    }
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    getReals(readStage_.data(), segs_[bodies[i]], *out[i]);
    if (energyWithForces_) {
      energy_[bodies[i]] = energyOf(bodies[i], energyItems_.data(), itemLo);
      energyKnown_[bodies[i]] = 1;
    }
  }
}

std::size_t SegmentEngine::readEnergyItems(cl_event* done) {
  // Into a member: an error in the caller can unwind before a non-blocking read is waited for, and
  // the engine's destructor drains the queue; a buffer of the call's would be freed under the write.
  const auto [lo, count] = spanItems(Span::Elements, activeLo_, activeHi_);
  if (energyItems_.size() < stride_ / vec_ * realSize_) energyItems_.resize(stride_ / vec_ * realSize_);
  checkCl(clEnqueueReadBuffer(ctx_->queue(), partials_.get(), done ? CL_FALSE : CL_TRUE, lo * realSize_,
                              count * realSize_, energyItems_.data(), 0, nullptr, done),
          "clEnqueueReadBuffer (energies)", dev_);
  return lo;
}

double SegmentEngine::energyOf(std::size_t s, const unsigned char* items, std::size_t lo) const {
  const BodySegment& sg = segs_[s];
  double sum = 0.0;
  for (std::size_t i = sg.elemBegin / vec_; i < (sg.elemBegin + sg.elemSpan) / vec_; ++i)
    sum += double_ ? reinterpret_cast<const double*>(items)[i - lo] : reinterpret_cast<const float*>(items)[i - lo];
  return sum;
}

void SegmentEngine::elementProduct(const ClBuffer& v) {
  flushCoefficients();
  const cl_uint S = static_cast<cl_uint>(stride_);
  launch(kProduct_, Span::Elements, S, elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_, rotatedGradients(), v,
         elemOut_);
}

void SegmentEngine::product(const ClBuffer& v, const ClBuffer& y, bool project, const ClBuffer& partials,
                            const ClBuffer* residualOf) {
  static const ClBuffer none;  // a NULL argument: y = A v
  if (residualOf && !project) fail(ErrorCode::Internal, "OpenCL backend: the residual is always projected");  // gather.cl
  elementProduct(v);
  launch(kGatherProduct_, Span::NodeChunks, nodeSeg_, segInfoBuf_, segCoefBuf_, nodeStart_, nodeEntries_, elemOut_,
         mass_, free_, cl_uint(project ? 1 : 0), v, y, partials, residualOf ? *residualOf : none);
}

void SegmentEngine::enqueueElementProduct(const SystemCoeffs& c) {
  for (std::size_t s = 0; s < segs_.size(); ++s) setCoefficients(s, c);
  setAllActive();
  elementProduct(p_);
}

void SegmentEngine::enqueueProduct(const SystemCoeffs& c) {
  for (std::size_t s = 0; s < segs_.size(); ++s) setCoefficients(s, c);
  setAllActive();
  std::fill(axReady_.begin(), axReady_.end(), 0);
  product(p_, q_, false, partialsW_);
}

void SegmentEngine::applyTile(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& ps,
                              const Vectors& ys) {
  if (bodies.empty()) return;
  unsigned char* stage = bStage_.writable();
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const BodySegment& sg = segs_[bodies[i]];
    const Eigen::VectorXd& v = *ps[i];
    putReals(stage, sg.dofBegin(), sg.dofs(), [&](std::size_t d) { return v[static_cast<Eigen::Index>(sg.hostDof(d))]; });
    setCoefficients(bodies[i], coeffs[i]);
  }
  // One write and one read of the packed range (the segments in between: scratch, not computed).
  const auto [lo, hi] = dofRange(bodies);
  bStage_.write(p_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  setActive(activeOf(bodies));
  for (std::size_t s : bodies) axReady_[s] = 0;  // their q_ takes the product
  product(p_, q_, false, partialsW_);
  readStage_.read(q_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  writesDone();
  for (std::size_t i = 0; i < bodies.size(); ++i) getReals(readStage_.data(), segs_[bodies[i]], *ys[i]);
}

void SegmentEngine::elasticEnergyTile(const BodySet& all, std::vector<double>& energy) {
  // Known from the forces at these positions (CPUs): no pass, no read.
  BodySet bodies;
  std::vector<std::size_t> where;  // index into `all` of each of `bodies`
  for (std::size_t i = 0; i < all.size(); ++i)
    if (energyWithForces_ && energyKnown_[all[i]]) {
      energy[i] = energy_[all[i]];
    } else {
      bodies.push_back(all[i]);
      where.push_back(i);
    }
  if (bodies.empty()) return;
  setActive(activeOf(bodies));
  if (energyWithForces_) {  // the forces' pass (into scratch) and its energies: the same bits as with the forces
    launch(kForces_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_,
           rotatedGradients(), pos_, elemOut_, partials_);
    const std::size_t lo = readEnergyItems(nullptr);
    writesDone();
    for (std::size_t k = 0; k < bodies.size(); ++k) {
      energy[where[k]] = energy_[bodies[k]] = energyOf(bodies[k], energyItems_.data(), lo);
      energyKnown_[bodies[k]] = 1;
    }
    return;
  }
  launch(kEnergy_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_, rotatedGradients(),
         pos_, elemOut_, partials_);
  // One read of the per-work-group partials of the active span, summed per segment in a fixed
  // order (deterministic).
  const std::size_t perGroup = wg_ * vec_;
  const std::size_t lo = segs_[activeLo_].elemBegin / perGroup;
  const std::size_t hi = (segs_[activeHi_ - 1].elemBegin + segs_[activeHi_ - 1].elemSpan) / perGroup;
  std::vector<double> partial(hi);
  download(partials_, partial.data(), lo, hi - lo);
  for (std::size_t k = 0; k < bodies.size(); ++k) {
    const BodySegment& sg = segs_[bodies[k]];
    double sum = 0.0;
    for (std::size_t g = sg.elemBegin / perGroup; g < (sg.elemBegin + sg.elemSpan) / perGroup; ++g) sum += partial[g];
    energy[where[k]] = sum;
  }
}

std::vector<std::vector<double>> SegmentEngine::readRotations(const BodySet& segments) {
  ensureRotations();  // R = I for a body never rotated
  // The segments whose last rotation pass wrote no R: that pass again with R (from the same
  // positions, so the same a_i, bit for bit; not the corners: the blocks were formed from the first).
  std::vector<char> rerun(segs_.size(), 0);
  bool any = false;
  std::size_t lo = stride_, hi = 0;  // the elements the segments span
  for (std::size_t s : segments) {
    if (rStale_.at(s)) rerun[s] = any = true;
    lo = std::min(lo, segs_[s].elemBegin);
    hi = std::max(hi, segs_[s].elemBegin + segs_[s].elems);
  }
  if (any) launchRotations(rerun, false, true);
  std::vector<double> soa(kRotComponents * stride_);
  if (lo < hi)
    for (std::size_t k = 0; k < kRotComponents; ++k) download(rot_, soa.data(), k * stride_ + lo, hi - lo);
  std::vector<std::vector<double>> out;
  for (std::size_t s : segments) {
    const BodySegment& sg = segs_[s];
    std::vector<double>& r = out.emplace_back(9 * sg.elems);
    for (std::size_t e = 0; e < sg.elems; ++e) {
      const std::size_t to = sg.hostElem.empty() ? e : sg.hostElem[e];  // in the problem's element order
      for (std::size_t k = 0; k < 9; ++k) r[9 * to + k] = soa[k * stride_ + sg.elemBegin + e];
    }
  }
  return out;
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
