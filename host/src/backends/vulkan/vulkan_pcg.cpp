// The Vulkan device's PCG building blocks (vulkan_device_impl.hpp; device/device.hpp has their
// contract): the set-up with b and x through the staging buffer, iterations recorded n at a time
// (one dispatch per phase, or whole iterations in pcg_group.comp), non-blocking reads of the
// scalars, the true residual and the solution read back.
#include "backends/vulkan/vulkan_device_impl.hpp"

namespace corofem::detail::vkdevice {

std::vector<PcgStart> VulkanDevice::pcgBegin(const BodySet& set, const std::vector<SystemCoeffs>& coeffs,
                                             const ConstVectors& b, const ConstVectors& x, double tolerance,
                                             int maxIterations) {
  checkSet(set, b.size(), "right-hand sides");
  checkSet(set, x.size(), "starting vectors");
  checkSet(set, coeffs.size(), "coefficients");
  for (std::size_t i = 0; i < set.size(); ++i)
    if (b[i] || x[i]) checkSize(segment(set[i]), *b[i], "a right-hand side");
  solve_ = set;
  cap_ = std::max(0, maxIterations);
  enqueued_ = 0;
  reads_.clear();
  residualFor_.clear();
  endReads_ = 0;
  started_.assign(set.size(), PcgStart::Running);
  resident_.assign(set.size(), 0);
  waitStaging();
  const std::size_t xOffset = 3 * layout_.nodeTotal;  // reals: b first, then x
  std::vector<SystemCoeffs> all(bodyCount());
  std::vector<char> active(bodyCount(), 0);
  bool zeroStart = true, any = false;
  const double maxReal = isDouble_ ? std::numeric_limits<double>::max() : std::numeric_limits<float>::max();
  std::vector<VkBufferCopy> toB, toX;  // from the staging buffer
  BodySet running;
  std::vector<std::pair<double, double>> amgCoefficients;  // (mass, stiffness) of each running body's A
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    const auto join = [&]() {
      active[set[i]] = any = true;
      all[set[i]] = coeffs[i];
      running.push_back(set[i]);
      amgCoefficients.emplace_back(coeffs[i].mass + coeffs[i].damping * sg.rayleighMass,
                                   coeffs[i].stiffness + coeffs[i].damping * sg.rayleighStiffness);
    };
    if (!b[i]) {  // staged by stageSolve: b checked by the set-up's stop test, x = 0
      resident_[i] = 1;
      join();
      continue;
    }
    const Eigen::VectorXd& bi = *b[i];
    const Eigen::VectorXd& xi = *x[i];
    const std::vector<std::uint8_t>& fixed = constrainedHost_[set[i]];
    double bb = 0;  // of b as the device holds it (in float, entries below its range are 0)
    bool inRange = true;
    for (std::size_t d = 0; d < sg.dofs(); ++d)
      if (!fixed[d]) {
        const double given = bi[static_cast<Eigen::Index>(d)];
        const double v = isDouble_ ? given : static_cast<double>(static_cast<float>(given));
        bb += v * v;
        inRange = inRange && std::abs(given) <= maxReal;
      }
    if (!std::isfinite(bb) || !inRange) {
      started_[i] = PcgStart::NonFiniteRhs;
      continue;
    }
    if (bb == 0.0) {
      started_[i] = PcgStart::ZeroRhs;
      continue;
    }
    const bool haveX = static_cast<std::size_t>(xi.size()) == sg.dofs();
    auto start = [&](std::size_t hostDof) {
      if (!haveX || fixed[hostDof]) return 0.0;
      const double v = xi[static_cast<Eigen::Index>(hostDof)];
      return std::isfinite(v) && std::abs(v) <= maxReal ? v : 0.0;  // a non-finite start is useless, not fatal
    };
    for (std::size_t d = 0; d < sg.dofs() && zeroStart; ++d) zeroStart = start(d) == 0.0;
    putReals(up_.mapped(), isDouble_, sg.dofBegin(), sg.dofs(), kChunk, [&](std::size_t d) {
      const std::size_t h = sg.hostDof(d);
      return fixed[h] ? 0.0 : bi[static_cast<Eigen::Index>(h)];  // what a constrained dof holds is not read
    });
    putReals(up_.mapped(), isDouble_, xOffset + sg.dofBegin(), sg.dofs(), kChunk,
             [&](std::size_t d) { return start(sg.hostDof(d)); });
    toB.push_back({sg.dofBegin() * rs_, sg.dofBegin() * rs_, sg.dofs() * rs_});
    toX.push_back({(xOffset + sg.dofBegin()) * rs_, sg.dofBegin() * rs_, sg.dofs() * rs_});
    join();
  }
  solveCoeffs_ = all;
  if (!any) return started_;
  if (amg_) amg_->prepare(running, amgCoefficients);  // the hierarchies (host work, uploads) before recording
  VkCommandBuffer cb = ctx_->begin();
  if (!toB.empty()) {
    vkCmdCopyBuffer(cb, up_.handle(), buffer(kVecB).handle(), static_cast<std::uint32_t>(toB.size()), toB.data());
    vkCmdCopyBuffer(cb, up_.handle(), buffer(kVecX).handle(), static_cast<std::uint32_t>(toX.size()), toX.data());
  }
  if (amg_) amg_->recordWarps(cb, running);
  std::vector<double> sc(kScalarCount * bodyCount(), 0.0);
  for (std::size_t body = 0; body < bodyCount(); ++body) sc[kScalarCount * body + kScalarTol2] = tolerance * tolerance;
  updateReals(cb, buffer(kScalars), sc);
  recordActive(cb, active);
  recordCoefficients(cb, all);
  Push push = basePush();
  if (!zeroStart) {  // q = A x into s
    push.mode = kElementProduct;
    dispatch(cb, element_, setup_, push, elementGroups());
    push.mode = kGatherProduct;
    dispatch(cb, gather_, setup_, push, nodeGroups());
  }
  if (push.precond != 0) {  // the node blocks of R K R^T at the current rotations
    push.mode = kElementCorners;
    dispatch(cb, element_, apply_, push, elementGroups());
    push.mode = kGatherBlocks;
    dispatch(cb, gather_, apply_, push, nodeGroups());
  }
  push.mode = kPcgInit;
  if (zeroStart) push.flags |= kFlagZeroStart;
  dispatch(cb, pcg_, pcgSet_, push, nodeGroups());
  push.flags &= ~kFlagZeroStart;
  if (amg_) amg_->recordCycle(cb, true);  // u = M^-1 r by the V-cycle, over pcg.comp's node-block one
  recordProduct(cb, push, pcgSet_);
  push.mode = kReduceInit;
  dispatch(cb, reduce_, pcgSet_, push, static_cast<std::uint32_t>(bodyCount()));
  stagingUse_ = kOpenCommands;  // left open: the first read of the scalars submits it
  return started_;
}

void VulkanDevice::pcgIterate(int n, const std::vector<char>&) {
  if (std::none_of(started_.begin(), started_.end(), [](PcgStart s) { return s == PcgStart::Running; })) return;
  const int k = std::min(n, cap_ - enqueued_);
  if (k <= 0) return;
  VkCommandBuffer cb = ctx_->begin();
  Push push = basePush();
  if (groupPcg_) {  // k iterations of every body, in as few dispatches as the work bound allows
    for (int done = 0; done < k;) {
      const int now = std::min(k - done, groupIterationsPerDispatch_);
      done += now;
      enqueued_ += now;
      Push p = push;
      p.mode = static_cast<std::uint32_t>(now);
      p.flags |= kFlagProject | (enqueued_ == cap_ ? kFlagCapLast : 0u);
      dispatch(cb, pcgGroup_, pcgSet_, p, static_cast<std::uint32_t>(bodyCount()));
      ++groupDispatches_;
    }
  } else {  // by phases: four dispatches an iteration, or with fusedPcg_ two (three with the V-cycle)
    for (int it = 0; it < k; ++it) {
      ++enqueued_;
      if (enqueued_ == cap_) {  // the cap's last iteration: the update and r . r alone (no next u)
        push.mode = kPcgUpdate;
        dispatch(cb, pcg_, pcgSet_, push, nodeGroups());
        push.mode = kReduceLast;
        dispatch(cb, reduce_, pcgSet_, push, static_cast<std::uint32_t>(bodyCount()));
        phaseDispatches_ += 2;
        break;
      }
      Push p = push;
      p.flags |= kFlagProject;
      if (fusedPcg_ && !amg_) {  // each element computes the update's u at its corners; the node pass stores it
        dispatch(cb, elementFused_, pcgSet_, p, elementGroups());
        p.mode = kFusedUpdateProduct;
        dispatch(cb, pcgFused_, pcgSet_, p, nodeGroups());
        phaseDispatches_ += 2;
        continue;
      }
      push.mode = kPcgUpdate;
      dispatch(cb, pcg_, pcgSet_, push, nodeGroups());
      if (amg_) amg_->recordCycle(cb, false);  // u = M^-1 r by the V-cycle, over the update's
      p.mode = kElementProduct;
      dispatch(cb, element_, pcgSet_, p, elementGroups());
      if (fusedPcg_) {  // the product's node pass and the scalars in one
        p.mode = kFusedProduct;
        dispatch(cb, pcgFused_, pcgSet_, p, nodeGroups());
        phaseDispatches_ += 3;
        continue;
      }
      p.mode = kGatherProduct;
      dispatch(cb, gather_, pcgSet_, p, nodeGroups());
      push.mode = kReduceStep;
      dispatch(cb, reduce_, pcgSet_, push, static_cast<std::uint32_t>(bodyCount()));
      phaseDispatches_ += 4;
    }
  }
  // Left open: the read of the scalars that follows submits the chunk with it.
}

PcgTicket VulkanDevice::pcgRead() {
  if (reads_.size() >= kReadSlots) stash(reads_[reads_.size() - kReadSlots]);
  const PcgTicket ticket = nextTicket_++;
  const std::size_t slot = ticket % kReadSlots;
  VkCommandBuffer cb = ctx_->begin();
  copy(cb, buffer(kScalars), 0, down_, scalarsOffset_ + slot * scalarsBytes(), scalarsBytes());
  vk::hostReadBarrier(cb);
  Read r;
  r.ticket = ticket;
  r.submission = ctx_->submit();
  r.slot = slot;
  reads_.push_back(std::move(r));
  return ticket;
}

void VulkanDevice::pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars) {
  if (reads_.empty() || reads_.front().ticket != ticket)
    fail(ErrorCode::Internal, "vulkan backend: PCG reads taken out of order");
  stash(reads_.front());
  scalarsOf(reads_.front().values, scalars);
  reads_.pop_front();
}

void VulkanDevice::pcgResidual(const std::vector<char>& bodies) {
  residualFor_ = bodies;
  std::vector<char> active(bodyCount(), 0);
  bool any = false;
  for (std::size_t i = 0; i < solve_.size() && i < bodies.size(); ++i)
    if (bodies[i] && started_[i] == PcgStart::Running) active[solve_[i]] = any = true;
  if (!any) return;
  VkCommandBuffer cb = ctx_->begin();
  recordActive(cb, active);
  recordCoefficients(cb, solveCoeffs_);
  Push push = basePush();
  push.mode = kElementProduct;
  dispatch(cb, element_, setup_, push, elementGroups());
  push.mode = kGatherResidual;
  dispatch(cb, gather_, setup_, push, nodeGroups());
  push.mode = kReduceResidual;
  dispatch(cb, reduce_, setup_, push, static_cast<std::uint32_t>(bodyCount()));
  // Submitted now with pcgEnd's reads (no iteration follows a residual): the PCG driver queues the
  // residual before it waits for the last scalars, so that the device computes it and copies the
  // solution meanwhile, and pcgEnd only waits, with no submission and round trip of its own.
  recordEndReads(cb);
  endReads_ = ctx_->submit();
}

void VulkanDevice::stageSolve(const BodySet& set, const vk::Buffer& from, const std::vector<std::size_t>& at) {
  checkSet(set, at.size(), "right-hand sides");
  VkCommandBuffer cb = ctx_->begin();
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    copy(cb, from, (at[i] + sg.dofBegin()) * rs_, buffer(kVecB), sg.dofBegin() * rs_, sg.dofs() * rs_);
    vkCmdFillBuffer(cb, buffer(kVecX).handle(), sg.dofBegin() * rs_, sg.dofs() * rs_, 0u);
  }
  vk::fullBarrier(cb);  // left open: pcgBegin records after it
}

void VulkanDevice::takeSolution(const BodySet& set, const vk::Buffer& to, const std::vector<std::size_t>& at) {
  checkSet(set, at.size(), "solutions");
  VkCommandBuffer cb = ctx_->begin();
  for (std::size_t i = 0; i < set.size(); ++i) {
    const BodySegment& sg = segment(set[i]);
    copy(cb, buffer(kVecX), sg.dofBegin() * rs_, to, (at[i] + sg.dofBegin()) * rs_, sg.dofs() * rs_);
  }
  vk::fullBarrier(cb);  // left open: the store's next pass reads x after it
}

void VulkanDevice::recordEndReads(VkCommandBuffer cb) {
  for (std::size_t i = 0; i < solve_.size(); ++i)
    if (started_[i] == PcgStart::Running && !resident_[i]) {
      const BodySegment& sg = segment(solve_[i]);
      copy(cb, buffer(kVecX), sg.dofBegin() * rs_, down_, sg.dofBegin() * rs_, sg.dofs() * rs_);
    }
  copy(cb, buffer(kScalars), 0, down_, scalarsOffset_ + kReadSlots * scalarsBytes(), scalarsBytes());
  vk::hostReadBarrier(cb);
}

void VulkanDevice::pcgEnd(const std::vector<int>&, const Vectors& x, std::vector<PcgScalars>& residual) {
  checkSet(solve_, x.size(), "solutions");
  residual.assign(solve_.size(), PcgScalars{});
  reads_.clear();
  const bool any = std::any_of(started_.begin(), started_.end(), [](PcgStart s) { return s == PcgStart::Running; });
  if (any) {
    if (!endReads_) {
      recordEndReads(ctx_->begin());
      endReads_ = ctx_->submit();
    }
    ctx_->wait(endReads_);
    const std::size_t finalSlot = scalarsOffset_ + kReadSlots * scalarsBytes();
    std::vector<double> values;
    readScalars(down_.mapped() + finalSlot, values);
    std::vector<PcgScalars> all;
    scalarsOf(values, all);
    for (std::size_t i = 0; i < solve_.size(); ++i) {
      if (started_[i] != PcgStart::Running) continue;
      if (x[i]) getReals(down_.mapped(), isDouble_, segment(solve_[i]), kChunk, *x[i]);
      if (i < residualFor_.size() && residualFor_[i]) residual[i] = all[i];
    }
  }
  residualFor_.clear();
  endReads_ = 0;
}

/// Takes a read's scalars to the host (waiting for it).
void VulkanDevice::stash(Read& r) {
  if (r.stashed) return;
  ctx_->wait(r.submission);
  readScalars(down_.mapped() + scalarsOffset_ + r.slot * scalarsBytes(), r.values);
  r.stashed = true;
}

void VulkanDevice::readScalars(const unsigned char* from, std::vector<double>& values) const {
  values.resize(kScalarCount * bodyCount());
  withReals(from, isDouble_, 0, [&](const auto* in) {
    for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(in[i]);
  });
}

/// The solve's bodies' scalars from the device's (those that did not start: as they entered).
void VulkanDevice::scalarsOf(const std::vector<double>& values, std::vector<PcgScalars>& out) const {
  out.assign(solve_.size(), PcgScalars{});
  for (std::size_t i = 0; i < solve_.size(); ++i) {
    PcgScalars& s = out[i];
    if (started_[i] == PcgStart::ZeroRhs) {
      s.stop = PcgStop::Converged;
      continue;
    }
    if (started_[i] == PcgStart::NonFiniteRhs) {
      s.bb = std::numeric_limits<double>::infinity();
      s.stop = PcgStop::NonFinite;
      continue;
    }
    const double* v = &values[kScalarCount * solve_[i]];
    s.iterations = static_cast<int>(v[kScalarIterations]);
    s.rr = v[kScalarRr];
    s.bb = v[kScalarBb];
    const double stop = v[kScalarStop];
    s.stop = stop == kStopConverged ? PcgStop::Converged
             : stop == kStopBreakdown ? PcgStop::Breakdown
             : stop == kStopNonFinite ? PcgStop::NonFinite
                                      : PcgStop::Running;
  }
}

}  // namespace corofem::detail::vkdevice
