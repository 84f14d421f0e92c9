// The OpenCL backend's side of corofem/tuning.hpp: the per-device-class table.
#pragma once

#include "backends/opencl/cl_context.hpp"

#include <corofem/tuning.hpp>

#include <cstddef>

namespace corofem::detail {

using corofem::OpenCLTuning;

/// The largest iteration cap pcg_iterate_team takes (its claims' 32-bit epochs advance by 4 per
/// iteration of a launch); larger caps take the other strategies.
constexpr int kTeamMaxIterations = 1 << 24;
/// OpenCLTuning::teamPcg as resolveTuning leaves it where each round's team or single work-group is
/// chosen by their measured times (team_choice.hpp): the default on CPU devices.
constexpr int kTeamPcgByMeasurement = 2;
/// What a pack's iteration costs a core, in iterations of one body of the same mesh alone
/// (pcg_iterate_group); a round packs a mesh's bodies only where ceil(bodies / cores) exceeds
/// kPackCost * ceil(packs / cores).
constexpr double kPackCost = 2.5;

/// `requested` with every automatic value replaced by the value of `device`'s class (and the
/// strategies a setting rules out switched off: pcg_iterate_group needs per-work-item sums, packs
/// and teams need pcg_iterate_group, teams a CPU device). `cacheBytes`: the device's last-level
/// cache (CL_DEVICE_GLOBAL_MEM_CACHE_SIZE). Throws Error(BadInput) naming the field for a value out
/// of its range.
OpenCLTuning resolveTuning(const OpenCLTuning& requested, const cl::DeviceInfo& device, std::size_t cacheBytes);

/// The working set of the bodies a batch runs together on a CPU device whose last-level cache holds
/// `cacheBytes`: 8 MiB, or a quarter of the cache where that is more, never more than the cache.
/// 0 (one tile) when the device reports no cache.
std::size_t defaultTileBytes(std::size_t cacheBytes);

}  // namespace corofem::detail
