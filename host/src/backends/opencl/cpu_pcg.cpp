// The CPU devices' one-launch PCG iterations (cpu_pcg.hpp): which a round takes, their buffers and
// their launches.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/cpu_pcg.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <limits>
#include <map>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

using namespace layout;

static_assert(kPackLanes == 8, "pcg_pack.cl's PACK_L and its vector types are 8 lanes");

namespace {

std::size_t roundUp(std::size_t n, std::size_t m) { return (n + m - 1) / m * m; }

}  // namespace

CpuPcg::CpuPcg(SegmentEngine& engine) : e_(engine) {
  // The "amg" cycle runs between the launched iterations' kernels (engine_amg.hpp), the
  // "warped_cholesky" factor on the host between them (device_warped.hpp): no one-launch PCG.
  const bool launched = e_.precond_ == PreconditionerKind::Amg || e_.precond_ == PreconditionerKind::WarpedCholesky;
  group_ = !launched && e_.tuning_.groupPcg != 0;
  team_ = !launched && e_.tuning_.teamPcg != 0;
  teamChosen_ = team_ && e_.tuning_.teamPcg == kTeamPcgByMeasurement;
  packs_ = !launched && e_.tuning_.packPcg != 0;
  packAlways_ = e_.tuning_.packPcg > 0;
  findPackMeshes();
}

void CpuPcg::createKernels() {
  const cl_program program = e_.build_.program;
  if (group_) kGroup_.create(program, "pcg_iterate_group", e_.dev_);
  if (team_) kTeam_.create(program, "pcg_iterate_team", e_.dev_);
  if (packs_) {
    kPack_.create(program, "pcg_iterate_pack", e_.dev_);
    kPackIn_.create(program, "pack_in", e_.dev_);
    kPackOut_.create(program, "pack_out", e_.dev_);
  }
}

void CpuPcg::allocate() {
  cl_context c = e_.ctx_->context();
  if (group_) groupOrder_.create(c, (e_.segs_.size() + 1) * sizeof(cl_uint), e_.dev_);
  if (team_) {
    const std::vector<cl_uint> state = teamStateAtRest();
    teamState_.create(c, state.size() * sizeof(cl_uint), e_.dev_);
    e_.uploadRaw(teamState_, state);
  }
  if (packs_) {
    // The pack meshes' corners (the pack's own node numbers). pcg_iterate_pack adds the element
    // products to the node sums element by element: the order of the gather lists above (by
    // element, then corner), so its sums are the gather's.
    std::vector<cl_uint> corners;
    for (PackMesh& m : packMeshes_) {
      const Problem& p = *e_.segs_[m.bodies.front()].problem;
      m.corners = corners.size();
      for (std::size_t e = 0; e < 4 * p.mesh.tetCount(); ++e) corners.push_back(static_cast<cl_uint>(p.mesh.tets[e]));
    }
    std::size_t elemRows = 0, partialRows = 0;
    for (const PackSlotPlace& slot : packSlots_) {
      const PackMesh& m = packMeshes_[slot.mesh];
      elemRows = std::max(elemRows, slot.elemBase + roundUp(e_.segs_[m.bodies.front()].elems, kPackLanes));
      partialRows = std::max(partialRows, slot.partialBase + e_.partialCount(m.bodies.front()));
    }
    const std::size_t L = kPackLanes, inverse = e_.precond_ == PreconditionerKind::BlockDiagonal ? 9 : 3;
    packInfo_.create(c, (kPackInfoCount * packSlots_.size() + 1) * sizeof(cl_uint), e_.dev_);  // + the claim word
    packCorners_.create(c, corners.size() * sizeof(cl_uint), e_.dev_);
    e_.uploadRaw(packCorners_, corners);
    e_.createReal(packElem_, elemRows * kPackElemRows * L);
    // The node sums: 3 rows per node for the products, 6 for the blocks of the block preconditioner
    // (pcg_pack.cl's PACK_SUMS).
    e_.createReal(packSums_, (e_.precond_ == PreconditionerKind::BlockDiagonal ? 6 : 3) * packNodeRows_ * L);
    e_.createReal(packVec_, kPackVectors * 3 * packNodeRows_ * L);
    e_.createReal(packFree_, 3 * packNodeRows_ * L);
    if (e_.hasMass_) e_.createReal(packMass_, 3 * packNodeRows_ * L);
    if (e_.precond_ != PreconditionerKind::None) e_.createReal(packMinv_, inverse * packNodeRows_ * L);
    packPartials_.create(c, kPartialComponents * partialRows * L * e_.sumSize_, e_.dev_);
  }
}

void CpuPcg::appendBuffers(std::vector<std::pair<const char*, const ClBuffer*>>& out) const {
  const std::pair<const char*, const ClBuffer*> mine[] = {
      {"pcg_team_counters", &teamState_},   {"pcg_group_order", &groupOrder_},
      {"pack_table", &packInfo_},           {"pack_corners", &packCorners_},
      {"pack_element_rows", &packElem_},    {"pack_node_sums", &packSums_},
      {"pack_pcg_vectors", &packVec_},      {"pack_free_mask", &packFree_},
      {"pack_lumped_mass", &packMass_},     {"pack_preconditioner_inverse", &packMinv_},
      {"pack_partial_sums", &packPartials_}};
  out.insert(out.end(), std::begin(mine), std::end(mine));
}

void CpuPcg::findPackMeshes() {
  const std::vector<BodySegment>& segs_ = e_.segs_;
  packMeshes_.clear();
  packSlots_.clear();
  packNodeRows_ = 0;
  if (!packs_) return;
  // Bodies with the same corners and node count in the device's numbering (copies of a mesh that
  // are only moved; each body has the numbering it would have alone), each mesh's bodies in
  // segment order.
  std::map<std::pair<std::size_t, std::size_t>, std::vector<std::size_t>> bySize;
  for (std::size_t s = 0; s < segs_.size(); ++s) bySize[{segs_[s].nodes, segs_[s].elems}].push_back(s);
  for (const auto& [size, bodies] : bySize) {
    std::vector<std::vector<std::size_t>> meshes;
    for (std::size_t s : bodies) {
      auto same = std::find_if(meshes.begin(), meshes.end(), [&](const std::vector<std::size_t>& m) {
        return segs_[m.front()].problem->mesh.tets == segs_[s].problem->mesh.tets;
      });
      if (same == meshes.end()) meshes.push_back({s});
      else same->push_back(s);
    }
    // pack_in and pack_out move blocks of 8 elements and 8 nodes: the segments' padding covers them
    // (always but with tiny work-groups).
    const bool padded = segs_[bodies.front()].elemSpan >= roundUp(size.second, kPackLanes) &&
                        segs_[bodies.front()].nodeSpan >= roundUp(size.first, kPackLanes);
    for (std::vector<std::size_t>& m : meshes)
      if (m.size() >= e_.tuning_.packPcgMinLanes && padded) packMeshes_.push_back(PackMesh{std::move(m), 0, 0, 0});
  }
  std::sort(packMeshes_.begin(), packMeshes_.end(),
            [](const PackMesh& a, const PackMesh& b) { return a.bodies.front() < b.bodies.front(); });
  std::size_t elemRows = 0, partialRows = 0;
  for (std::size_t i = 0; i < packMeshes_.size(); ++i) {
    PackMesh& m = packMeshes_[i];
    const BodySegment& first = segs_[m.bodies.front()];
    m.firstSlot = packSlots_.size();
    m.slots = (m.bodies.size() + kPackLanes - 1) / kPackLanes;
    for (std::size_t k = 0; k < m.slots; ++k) {  // rows padded to 8 elements and nodes (pack_in's blocks)
      packSlots_.push_back({i, elemRows, packNodeRows_, partialRows});
      elemRows += roundUp(first.elems, kPackLanes);
      packNodeRows_ += roundUp(first.nodes, kPackLanes);
      partialRows += e_.partialCount(m.bodies.front());
    }
  }
  if (packSlots_.empty()) packs_ = false;
}

std::size_t CpuPcg::groupTeam(const std::vector<std::size_t>& requests) const {
  if (!group_ || requests.empty()) return 0;
  const OpenCLTuning& tuning_ = e_.tuning_;
  // The claims' 32-bit epochs advance by 4 per iteration of a launch: caps beyond kTeamMaxIterations
  // (never needed: PCG converges in at most the system's size) take the other paths.
  const bool teams = team_ && e_.solver_.maxIterations <= kTeamMaxIterations;
  if (teams && tuning_.teamPcgSize > 0) return tuning_.teamPcgSize;
  std::size_t largest = 0, total = 0;
  for (std::size_t s : requests) {
    largest = std::max(largest, e_.segs_[s].elems);
    total += e_.segs_[s].elems;
  }
  const std::size_t cores = std::max<std::size_t>(1, e_.ctx_->info().computeUnits);
  // Fewer bodies than cores: a team of up to cores / bodies work-groups per body, each with at
  // least tuning_.teamPcgMinElements elements of the largest (below that, one core without the team's
  // hand-offs is as fast), none larger than tuning_.teamPcgMaxElements (above that, the launched iterations,
  // which keep their pace when other processes take cores).
  if (teams && requests.size() < cores && largest <= tuning_.teamPcgMaxElements) {
    const std::size_t team = std::min(cores / requests.size(), largest / tuning_.teamPcgMinElements);
    if (team >= 2) return team;
  }
  if (largest <= tuning_.groupPcgSmallElements) return 1;  // one core without launches wins for each
  // Enough bodies for the cores, none too large for one core's cache, and none much larger than a
  // core's share (the one-launch round lasts as long as its largest body on one core). A review
  // measured on 2 cores: 10k + 10k elements 4.8 ms one-launch against 7.0 launched, 35k + 35k 20.6
  // against 18.7, 94k + 384 72 against 25.
  return requests.size() >= tuning_.groupPcgMinBodies && largest <= tuning_.groupPcgMaxElements && largest * cores <= 2 * total ? 1 : 0;
}

std::size_t CpuPcg::chooseTeam(std::size_t team, const std::vector<std::size_t>& segments) {
  timing_ = false;
  roundStart_.reset();
  // Only teams of two: one work-group then runs a round on half the cores the team has, so that a
  // probe of the other way costs at most about twice a round (a larger team's round on one core
  // would cost as many times as it has members). A team size the tuning fixes is not chosen.
  if (team != 2 || !teamChosen_ || e_.tuning_.teamPcgSize > 0) return team;
  timing_ = true;
  timedWay_ = choice_.next();
  timedElements_ = 0;
  for (std::size_t s : segments) timedElements_ += e_.segs_[s].elems;
  return timedWay_ == TeamChoice::Way::Team ? team : 1;
}

void CpuPcg::roundStarted() {
  if (timing_) roundStart_ = std::chrono::steady_clock::now();
}

void CpuPcg::roundDone(int iterations) {
  if (!timing_ || !roundStart_) return;
  timing_ = false;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - *roundStart_).count();
  roundStart_.reset();
  // Per iteration and element: rounds of other bodies (Newton drops the converged ones) compare.
  if (iterations > 0 && timedElements_ > 0)
    choice_.measured(timedWay_, seconds / iterations / static_cast<double>(timedElements_));
}

std::vector<cl_uint> CpuPcg::packRound(const std::vector<std::size_t>& requests, std::vector<char>& packed) const {
  if (!packs_) return {};
  const std::vector<BodySegment>& segs_ = e_.segs_;
  const std::vector<int>& lastIterations_ = e_.lastIterations_;
  std::vector<char> in(segs_.size(), 0);
  for (std::size_t s : requests) in[s] = 1;
  struct Pack {
    std::size_t slot, cost;
    std::vector<std::size_t> lanes;
  };
  std::vector<Pack> packs;
  for (const PackMesh& m : packMeshes_) {
    std::vector<std::size_t> bodies;
    for (std::size_t s : m.bodies)
      if (in[s]) bodies.push_back(s);
    // A pack takes a core for about what kPackCost bodies take alone (pcg_iterate_group): packed
    // only where that shortens the round, unless packs were asked for (packAlways_).
    const std::size_t cores = std::max<std::size_t>(1, e_.ctx_->info().computeUnits);
    const std::size_t slotsNeeded = bodies.size() / kPackLanes + (bodies.size() % kPackLanes >= e_.tuning_.packPcgMinLanes ? 1 : 0);
    if (!packAlways_ && static_cast<double>((bodies.size() + cores - 1) / cores) <=
                            kPackCost * static_cast<double>((slotsNeeded + cores - 1) / cores))
      continue;
    // Bodies that took as many iterations last time share a pack: a pack iterates until its
    // last lane stops.
    std::stable_sort(bodies.begin(), bodies.end(),
                     [&](std::size_t a, std::size_t b) { return lastIterations_[a] > lastIterations_[b]; });
    for (std::size_t k = 0; k < m.slots && k * kPackLanes < bodies.size(); ++k) {
      const std::size_t n = std::min<std::size_t>(kPackLanes, bodies.size() - k * kPackLanes);
      if (n < e_.tuning_.packPcgMinLanes) break;
      const std::size_t first = bodies[k * kPackLanes];
      packs.push_back({m.firstSlot + k, segs_[first].elems * static_cast<std::size_t>(std::max(1, lastIterations_[first])),
                       std::vector<std::size_t>(bodies.begin() + k * kPackLanes, bodies.begin() + k * kPackLanes + n)});
    }
  }
  // The costliest first: the device's threads take the work-groups in order.
  std::stable_sort(packs.begin(), packs.end(), [](const Pack& a, const Pack& b) { return a.cost > b.cost; });
  std::vector<cl_uint> table;
  for (const Pack& pack : packs) {
    const PackSlotPlace& place = packSlots_[pack.slot];
    const PackMesh& m = packMeshes_[place.mesh];
    const BodySegment& sg = segs_[m.bodies.front()];
    cl_uint row[kPackInfoCount] = {};
    row[kPackElems] = static_cast<cl_uint>(sg.elems);
    row[kPackNodes] = static_cast<cl_uint>(sg.nodes);
    row[kPackPartialCount] = static_cast<cl_uint>(e_.partialCount(m.bodies.front()));
    row[kPackCorners] = static_cast<cl_uint>(m.corners);
    row[kPackElemBase] = static_cast<cl_uint>(place.elemBase);
    row[kPackNodeBase] = static_cast<cl_uint>(place.nodeBase);
    row[kPackPartialBase] = static_cast<cl_uint>(place.partialBase);
    for (std::size_t l = 0; l < pack.lanes.size(); ++l) {
      row[kPackLane0 + l] = static_cast<cl_uint>(pack.lanes[l] + 1);
      packed[pack.lanes[l]] = 1;
    }
    table.insert(table.end(), row, row + kPackInfoCount);
  }
  if (!table.empty()) table.push_back(0);  // the claim word, at 0 (pcg_iterate_pack)
  return table;
}

std::vector<cl_uint> CpuPcg::teamStateAtRest() const {
  const std::vector<BodySegment>& segs_ = e_.segs_;
  const std::size_t wg_ = e_.wg_, vec_ = e_.vec_;
  // Per segment kTeamStride words (counts at zero, kTeamFlags: where its claim words start), then
  // each segment's claim words, one per chunk of its larger phase (pcg_group.cl), at epoch 0.
  std::vector<cl_uint> state(kTeamStride * segs_.size(), 0u);
  for (std::size_t s = 0; s < segs_.size(); ++s) {
    const BodySegment& sg = segs_[s];
    const std::size_t chunks = std::max<std::size_t>(
        {1, (e_.partialCount(s) + wg_ - 1) / wg_, (sg.elemSpan / vec_ + wg_ - 1) / wg_});
    state[kTeamStride * s + kTeamFlags] = static_cast<cl_uint>(state.size());
    state.resize(state.size() + chunks, 0u);
  }
  return state;
}

void CpuPcg::launchIterations(cl_uint iterations) {
  SegmentEngine& e = e_;
  const SegmentEngine::Round& round = e.round_;
  const std::size_t team = round.team;
  const bool teamed = team > 1;
  const SegmentEngine::SumReal tol2{round.tolerance * round.tolerance};
  // A team's phases take the epochs teamEpoch_ + 1 .. + 4 iterations; before they could wrap, the
  // claim words go back to 0 (about every 10^9 phases).
  if (teamed && std::uint64_t{teamEpoch_} + 4 * std::uint64_t{iterations} + 1 > std::numeric_limits<cl_uint>::max()) {
    e.uploadRaw(teamState_, teamStateAtRest());
    teamEpoch_ = 0;
  }
  teamSize_ = team;
  if (round.unpacked && !teamed) {
    // The unpacked bodies the costliest first (elements times last iterations), then the claim
    // word; a work-group per compute unit takes them in turn (pcg_iterate_group).
    std::vector<cl_uint> order;
    for (std::size_t i = 0; i < round.bodies.size(); ++i)
      if (round.running[i] && !round.packed[round.bodies[i]]) order.push_back(static_cast<cl_uint>(round.bodies[i]));
    const auto cost = [&](cl_uint s) {
      return e.segs_[s].elems * static_cast<std::size_t>(std::max(1, e.lastIterations_[s]));
    };
    std::stable_sort(order.begin(), order.end(), [&](cl_uint a, cl_uint b) { return cost(a) > cost(b); });
    const std::size_t count = order.size();
    order.push_back(0);
    e.uploadRaw(groupOrder_, order);
    e.launchRange(kGroup_, 0, std::min(count, e.tuning_.claimWorkGroups) * e.wg_, e.wg_, cl_uint(e.stride_),
                  cl_uint(team), teamEpoch_, teamState_, e.segInfoBuf_, e.segCoefBuf_, e.elemNodes_, e.geom_,
                  e.rotatedGradients(), e.nodeStart_, e.nodeEntries_, e.elemOut_, e.mass_, e.free_, e.minv_, e.p_,
                  e.s_, e.x_, e.r_, e.z_, e.q_, e.partials_, e.partialsW_, e.scalars_, iterations, tol2, groupOrder_,
                  cl_uint(count));
    ++counts_.groupLaunches;
  }
  if (round.unpacked && teamed && e.activeLo_ < e.activeHi_) {
    // teamSize_ work-groups per segment of the active span.
    const std::size_t groups = team * e.wg_;
    e.launchRange(kTeam_, e.activeLo_ * groups, (e.activeHi_ - e.activeLo_) * groups, e.wg_, cl_uint(e.stride_),
                  cl_uint(team), teamEpoch_, teamState_, e.segInfoBuf_, e.segCoefBuf_, e.elemNodes_, e.geom_,
                  e.rotatedGradients(), e.nodeStart_, e.nodeEntries_, e.elemOut_, e.mass_, e.free_, e.minv_, e.p_,
                  e.s_, e.x_, e.r_, e.z_, e.q_, e.partials_, e.partialsW_, e.scalars_, iterations, tol2, groupOrder_,
                  cl_uint(0));
    teamEpoch_ += 4 * iterations;
    ++counts_.teamLaunches;
  }
  if (!round.packTable.empty()) {  // the packs' bodies: their vectors in, the iterations, the vectors out
    const std::size_t slots = (round.packTable.size() - 1) / kPackInfoCount;  // and the claim word
    e.uploadRaw(packInfo_, round.packTable);
    const cl_uint rows = cl_uint(3 * packNodeRows_);  // dof rows of each of packVec_'s vectors
    const cl_uint fresh = round.packFresh ? 1 : 0;
    e.launchRange(kPackIn_, 0, slots * e.wg_, e.wg_, packInfo_, e.segInfoBuf_, cl_uint(e.stride_),
                  e.rotatedGradients(), e.geom_, e.x_, e.r_, e.z_, e.p_, e.s_, e.q_, e.b_, e.minv_, e.mass_, e.free_,
                  packElem_, packVec_, packMinv_, packMass_, packFree_, rows, fresh);
    // A work-group per compute unit, each taking slots from the claim word (costliest first).
    e.launchRange(kPack_, 0, std::min(slots, e.tuning_.claimWorkGroups), 1, packInfo_, cl_uint(slots), e.segInfoBuf_,
                  e.segCoefBuf_, packCorners_, packElem_, packSums_, packVec_, packFree_, packMass_, packMinv_,
                  packPartials_, e.partials_, e.scalars_, rows, iterations, fresh, tol2);
    e.launchRange(kPackOut_, 0, slots * e.wg_, e.wg_, packInfo_, e.segInfoBuf_, e.x_, e.r_, e.z_, e.p_, e.s_, e.q_,
                  packVec_, rows);
    ++counts_.packLaunches;
    counts_.packLanes += static_cast<unsigned long long>(std::count(round.packed.begin(), round.packed.end(), char(1)));
  }
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
