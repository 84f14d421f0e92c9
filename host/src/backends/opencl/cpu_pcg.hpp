// The CPU devices' PCG iterations in one launch (kernels/opencl/cpu/): the same arithmetic and bits
// as the launched iterations (pcg.cl), without a launch per phase, which on a CPU device costs more
// than a small body's work.
//   pcg_iterate_group  a work-group per compute unit takes the round's bodies from a claim word,
//                      the costliest first, and runs each body's iterations on one core
//   pcg_iterate_team   a team of work-groups per body, for rounds of fewer bodies than cores (by
//                      default chosen round by round against pcg_iterate_group by their measured
//                      times: team_choice.hpp)
//   pcg_iterate_pack   up to kPackLanes bodies that share a mesh in one work-item, a body per vector
//                      lane, between pack_in and pack_out (the packs run their bodies' whole solve)
// Which a solve round takes (groupTeam, packRound) follows the tuning's rule (corofem/tuning.hpp).
#pragma once

#include "backends/opencl/cl_objects.hpp"
#include "backends/opencl/team_choice.hpp"

#include <chrono>
#include <cstddef>
#include <optional>
#include <vector>

namespace corofem::detail {

class SegmentEngine;

/// The one-launch PCG iterations an engine ran (Device::counters: "pcg_group_launches", ...).
struct CpuPcgCounts {
  unsigned long long groupLaunches = 0;  ///< launches of pcg_iterate_group
  unsigned long long teamLaunches = 0;   ///< launches of pcg_iterate_team
  unsigned long long packLaunches = 0;   ///< launches of pcg_iterate_pack
  unsigned long long packLanes = 0;      ///< bodies iterated in those packs (one per lane of a launch)
};

class CpuPcg {
 public:
  /// After the engine's segments are laid out: finds the pack meshes.
  explicit CpuPcg(SegmentEngine& engine);
  /// The kernels the tuning uses, from the engine's program.
  void createKernels();
  /// Its buffers (the team's state, the group's order, the packs' rows).
  void allocate();
  /// Its buffers with their names, for SegmentEngine::buffers.
  void appendBuffers(std::vector<std::pair<const char*, const ClBuffer*>>& out) const;

  /// How a solve round of these segments runs its PCG iterations: 0 launched (4 launches per
  /// iteration); 1 in pcg_iterate_group, a work-group per body on one core, when each body is small
  /// enough that one core without launches beats all cores with them, or when the bodies fill the
  /// cores and none is too large for one core or much larger than a core's share of the round;
  /// T >= 2 in pcg_iterate_team, T work-groups per body, when fewer bodies than cores would leave
  /// cores idle (teams on, none larger than teamPcgMaxElements).
  std::size_t groupTeam(const std::vector<std::size_t>& segments) const;
  /// The way of a round of `segments` that groupTeam gave `team`, where teams are chosen by
  /// measurement (teamPcg -1) and the team has two members: the team, or 1 (a work-group per body)
  /// where that has been the faster lately (team_choice.hpp).
  std::size_t chooseTeam(std::size_t team, const std::vector<std::size_t>& segments);
  /// The round chooseTeam chose starts its one-launch iterations now / has done `iterations` of
  /// them (its read taken): the measurement of that way.
  void roundStarted();
  void roundDone(int iterations);
  /// The packs of a solve round that takes pcg_iterate_group: the rows of the pack table
  /// (kPackInfoCount each, the costliest first, then the claim word at 0; empty without packs),
  /// with packed[s] = 1 for the bodies they take. Bodies of a pack mesh are packed in the order of
  /// their last solve's iterations (bodies that stop together share a pack), kPackLanes at a time;
  /// a remainder of fewer than packPcgMinLanes bodies is not packed.
  std::vector<cl_uint> packRound(const std::vector<std::size_t>& segments, std::vector<char>& packed) const;
  /// Enqueues `iterations` iterations (every one but the cap's last) of the round's running bodies
  /// in one launch each for the unpacked (group or team) and for the packs.
  void launchIterations(cl_uint iterations);
  const CpuPcgCounts& counts() const { return counts_; }

 private:
  CpuPcgCounts counts_;
  /// teamState_ between launches: the counts at zero, the claim words at epoch 0.
  std::vector<cl_uint> teamStateAtRest() const;
  void findPackMeshes();

  SegmentEngine& e_;
  bool group_ = false, team_ = false, packs_ = false, packAlways_ = false;
  bool teamChosen_ = false;    ///< teams by measurement (teamPcg -1), not always (1)
  TeamChoice choice_;
  bool timing_ = false;        ///< the round in flight was chosen by choice_
  TeamChoice::Way timedWay_ = TeamChoice::Way::Team;
  std::size_t timedElements_ = 0;  ///< the timed round's elements (its work per iteration)
  /// When the timed round's one-launch iterations were queued (none: not started).
  std::optional<std::chrono::steady_clock::time_point> roundStart_;
  std::size_t teamSize_ = 1;   ///< the round's work-groups per body (pcg_iterate_team)
  cl_uint teamEpoch_ = 0;      ///< the last epoch pcg_iterate_team's claim words may hold
  friend struct SegmentEngineTestAccess;  // tests/common/opencl_test_access.hpp

  // -- packs (pcg_pack.cl): each mesh shared by at least packPcgMinLanes bodies (a *pack mesh*)
  // gets its corners once and ceil(bodies / kPackLanes) slots of lane-interleaved rows.
  struct PackMesh {
    std::vector<std::size_t> bodies;  ///< its segments
    std::size_t corners = 0;          ///< its first entry in packCorners_
    std::size_t firstSlot = 0;        ///< its slots: [firstSlot, firstSlot + slots)
    std::size_t slots = 0;
  };
  struct PackSlotPlace {
    std::size_t mesh = 0;             ///< the pack mesh whose bodies it takes
    std::size_t elemBase = 0, nodeBase = 0, partialBase = 0;
  };
  std::vector<PackMesh> packMeshes_;
  std::vector<PackSlotPlace> packSlots_;
  std::size_t packNodeRows_ = 0;      ///< node rows of all slots (each vector of packVec_)

  ClKernel kGroup_, kTeam_, kPack_, kPackIn_, kPackOut_;
  ClBuffer teamState_;   ///< pcg_iterate_team's state, kTeamStride per segment, then claim words
  ClBuffer groupOrder_;  ///< pcg_iterate_group's segments, the costliest first, then the claim word
  // The slots' table of the round, the pack meshes' corners, the slots' element rows (a_i, volume),
  // node sums, PCG vectors (x r u p s w b), free masks, masses, M^-1 and partial sums.
  ClBuffer packInfo_, packCorners_, packElem_, packSums_, packVec_, packFree_, packMass_, packMinv_, packPartials_;
};

}  // namespace corofem::detail
