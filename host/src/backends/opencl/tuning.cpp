// The OpenCL backend's tuning table per device class (tuning.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/tuning.hpp"

#include "util/error.hpp"
#include "util/parallel.hpp"

#include <algorithm>
#include <string>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

namespace {

constexpr std::size_t kDefaultWorkGroup = 64;
constexpr std::size_t kDefaultHostChunk = std::size_t{1} << 16;
constexpr int kDefaultQuaternionIterations = 6;
constexpr std::size_t kTeamPcgMinElements = 1280;
constexpr std::size_t kTeamPcgMaxElementsPerCore = 16384;
constexpr std::size_t kPackMinLanes = 3;

}  // namespace

std::size_t defaultTileBytes(std::size_t cacheBytes) {
  constexpr std::size_t kTileTarget = std::size_t{8} << 20;
  return std::min(cacheBytes, std::max(cacheBytes / 4, kTileTarget));
}

OpenCLTuning resolveTuning(const OpenCLTuning& requested, const cl::DeviceInfo& device, std::size_t cacheBytes) {
  OpenCLTuning t = requested;
  const bool gpu = device.gpu;
  const bool cpu = device.cpu && !device.gpu;
  const std::size_t cores = std::max<cl_uint>(1, device.computeUnits);
  auto bad = [&](const char* field, auto value, const char* range) {
    fail(ErrorCode::BadInput, "OpenCL tuning: ", field, " = ", value, " is out of range (", range, ") on device '",
         device.name, "'");
  };

  if (!t.workGroupSize) t.workGroupSize = kDefaultWorkGroup;
  if ((t.workGroupSize & (t.workGroupSize - 1)) != 0 || t.workGroupSize > device.maxWorkGroupSize)
    bad("workGroupSize", t.workGroupSize, "a power of two up to the device's maximum work-group size");
  if (!t.elementsPerItem) t.elementsPerItem = gpu ? 1 : 8;
  if (t.elementsPerItem != 1 && t.elementsPerItem != 4 && t.elementsPerItem != 8 && t.elementsPerItem != 16)
    bad("elementsPerItem", t.elementsPerItem, "1, 4, 8 or 16");
  if (!t.nodesPerItem) t.nodesPerItem = gpu ? 1 : 4;
  if (t.workGroupSums < 0) t.workGroupSums = gpu ? 1 : 0;
  if (!t.hostChunk) t.hostChunk = kDefaultHostChunk;
  if (t.quaternionIterations < 0) bad("quaternionIterations", t.quaternionIterations, ">= 1, or 0 for 6");
  if (!t.quaternionIterations) t.quaternionIterations = kDefaultQuaternionIterations;
  if (t.tileBytes < 0) t.tileBytes = gpu ? 0 : static_cast<long long>(defaultTileBytes(cacheBytes));

  // The one-launch strategies need per-work-item partial sums (pcg_group.cl, pcg_pack.cl).
  if (t.groupPcg < 0) t.groupPcg = gpu ? 0 : 1;
  if (t.workGroupSums) t.groupPcg = 0;
  if (!t.groupPcgMinBodies) t.groupPcgMinBodies = cores;
  if (!t.groupPcgSmallElements) t.groupPcgSmallElements = 8192 / cores;
  if (!t.groupPcgMaxElements) t.groupPcgMaxElements = 32768 / cores;
  if (!t.claimWorkGroups) t.claimWorkGroups = cores;

  // Teams hand work over through coherent caches: CPU devices only. By default each round's team or
  // one work-group per body, whichever has been the faster lately (team_choice.hpp), and only where
  // the process may run on as many CPUs as the device has compute units: pinned to fewer, a team's
  // members take turns on one CPU and each waits a time slice for the others.
  const bool byDefault = t.teamPcg < 0 && usableCpus() >= cores;
  t.teamPcg = !t.groupPcg || !cpu ? 0 : t.teamPcg > 0 ? 1 : byDefault ? kTeamPcgByMeasurement : 0;
  if (!t.teamPcgMinElements) t.teamPcgMinElements = kTeamPcgMinElements;
  if (!t.teamPcgMaxElements) t.teamPcgMaxElements = kTeamPcgMaxElementsPerCore * cores;

  // Packs: one work-item per pack, so CPU devices only (a GPU would run a pack on one lane).
  if (t.packPcg < 0 && !cpu) t.packPcg = 0;
  if (!t.groupPcg) t.packPcg = 0;
  if (!t.packPcgMinLanes) t.packPcgMinLanes = kPackMinLanes;
  if (t.packPcgMinLanes > layout::kPackLanes)
    bad("packPcgMinLanes", t.packPcgMinLanes, ("1 to " + std::to_string(layout::kPackLanes)).c_str());

  if (t.flushDenormals < 0) t.flushDenormals = cpu ? 1 : 0;
  return t;
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
