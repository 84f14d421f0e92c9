// Tuning of the device backends: how they shape their kernels and which launch strategies they
// take on a device. None of it changes the mathematics: every setting gives the same answer to
// rounding, and the OpenCL strategies of one device class (launched, pcg_iterate_group,
// pcg_iterate_pack) the same bits.
//
// Every field's "automatic" value (0, or -1 for the switches) means "the value of the device's
// class" (CPU devices such as PoCL, GPUs); any other value overrides it. The measurements behind
// the defaults are in docs/performance.md.
#pragma once

#include <cstddef>

namespace corofem {

struct OpenCLTuning {
  /// Work-items per work-group of every kernel: a power of two, at most the device's maximum.
  /// 0 = 64.
  std::size_t workGroupSize = 0;
  /// Elements per work-item in the element kernels (rotations, forces, products): 1, 4, 8 or 16.
  /// 0 = 8 on CPU devices (vector code), 1 on GPUs.
  std::size_t elementsPerItem = 0;
  /// Nodes per work-item in the PCG node kernels, >= 1. 0 = 4 on CPU devices, 1 on GPUs.
  std::size_t nodesPerItem = 0;
  /// Partial sums of the dot products: 1 one per work-group (local-memory trees, GPU style), 0 one
  /// per work-item (CPU style, which also lets the forces' pass return the strain energy);
  /// -1 = 1 on GPUs, 0 on CPU devices.
  int workGroupSums = -1;
  /// Entries (doubles) per chunk of the host's passes over node vectors (packing, converting and
  /// checking 3N-entry vectors on the host's threads), >= 1. 0 = 65,536: a body of up to 21,845
  /// nodes is one chunk, run on the calling thread.
  std::size_t hostChunk = 0;
  /// Quaternion rotation method: fixed-point iterations per update, >= 1. 0 = 6.
  int quaternionIterations = 0;
  /// Batches on CPU devices: consecutive bodies whose working set fits in this many bytes run
  /// each launch sequence together (a tile), so that a tile's solve stays in the cache. 0 = all
  /// bodies in one tile; -1 = CPU devices: defaultTileBytes of the last-level cache, GPUs: 0.
  long long tileBytes = -1;
  /// PCG iterations of a solve round in one launch, a work-group per body (pcg_iterate_group), for
  /// rounds of small bodies (at most groupPcgSmallElements each) or of at least groupPcgMinBodies
  /// bodies none larger than groupPcgMaxElements: 1 on, 0 off, -1 = on on CPU devices (needs
  /// per-work-item sums: workGroupSums 0).
  int groupPcg = -1;
  /// The fewest bodies of a round run by pcg_iterate_group for their count, >= 1. 0 = the device's
  /// compute units (a work-group per body uses no more cores than there are bodies).
  std::size_t groupPcgMinBodies = 0;
  /// Rounds whose bodies have at most this many elements each run in one launch whatever their
  /// count (one core without launches beats all cores with them). 0 = 8,192 / compute units.
  std::size_t groupPcgSmallElements = 0;
  /// The largest body (elements) of a round run in one launch for its count; none may also exceed
  /// twice its share (elements of the round / compute units). 0 = 32,768 / compute units.
  std::size_t groupPcgMaxElements = 0;
  /// Rounds of fewer bodies than compute units in one launch with a team of work-groups per body
  /// (pcg_iterate_team): 1 in every such round, 0 never, -1 = on CPU devices where the process may
  /// run on as many CPUs as the device has compute units, a team of two taking the team or one
  /// work-group per body (pcg_iterate_group, one core) round by round, whichever has been the
  /// faster lately by the measured time per iteration (larger teams always the team); both give
  /// the same bits. A team's members wait for each
  /// other: on a quiet machine the fastest way for a lone body of 2,560 to 32,768 elements on 2
  /// cores, while another process keeps a core busy the slower (a parked member holds the others).
  int teamPcg = -1;
  /// The largest body (elements) for pcg_iterate_team. 0 = 16,384 per compute unit.
  std::size_t teamPcgMaxElements = 0;
  /// The fewest elements of the largest body per work-group of a team, >= 1. 0 = 1,280.
  std::size_t teamPcgMinElements = 0;
  /// With teamPcg on: work-groups per body in every solve round, whatever the rule above says
  /// (more than the compute units too: then they run in turns). 0 = by the rule.
  std::size_t teamPcgSize = 0;
  /// In rounds run by pcg_iterate_group, the bodies that share one mesh (the same element corners
  /// and node count) iterate in packs of 8, a body per vector lane (pcg_iterate_pack): 1 in every
  /// such round, 0 never, -1 = on CPU devices where packs shorten the round (a pack's iteration
  /// costs a core about 2.5 bodies' iterations).
  int packPcg = -1;
  /// The fewest bodies of a pack (a pack costs its 8 lanes whatever it holds), 1 to 8. 0 = 3.
  std::size_t packPcgMinLanes = 0;
  /// Work-groups of pcg_iterate_group and pcg_iterate_pack, each taking the next body or pack (the
  /// costliest first) from a claim word until none is left, >= 1. 0 = the device's compute units.
  std::size_t claimWorkGroups = 0;
  /// The device's numbering of a body's elements and nodes: 1 a Morton order always, 0 the mesh's
  /// own, -1 = a Morton order where it is more local than the mesh's (mesh/locality_order.hpp).
  /// Host vectors keep the mesh's numbering either way.
  int localityOrder = -1;
  /// Denormal floats flushed to zero (-cl-denorms-are-zero): 1 on, 0 off, -1 = on CPU devices,
  /// where an x86 core takes a microcode assist per operation on a denormal.
  int flushDenormals = -1;
};


/// The Vulkan backend's strategies (host/src/backends/vulkan/). Like OpenCLTuning, none of it
/// changes the mathematics: both PCG paths run the same phases in the same order.
struct VulkanTuning {
  /// Bodies of at most this many nodes run their PCG iterations in one dispatch, a work-group per
  /// body meeting at barriers (kernels/vulkan/pcg_group.comp); larger ones take a dispatch per
  /// phase (an update, the product's element and node passes, the scalars: four an iteration, or
  /// two with fusedPcg), which spreads a body over the device. 0 = 2,048 on a CPU device (on
  /// lavapipe, a step of a 270-node block: 8.5 ms in one dispatch against 10.0 ms per phase; of a
  /// 2,100-node block: 55 against 35 ms) and never on a GPU (an H200: 2.5 against 1.7 ms for the
  /// 270-node block, 14.2 against 2.6 ms for the 2,100-node one; docs/performance.md); -1 = never.
  long long groupPcgNodes = 0;
  /// Off the one-dispatch path, a PCG iteration in two dispatches instead of four
  /// (kernels/vulkan/pcg_fused.comp): the update folded into the product's passes, each element
  /// computing the new u at its corners, and the scalars into the node pass's last work-group;
  /// with the amg preconditioner, whose V-cycle runs between the update and the product, three.
  /// The same operations either way (the same bits on lavapipe). It saves dispatches and their
  /// barriers, which bound a small body's iteration on a GPU (bench_vulkan's dispatch yardstick;
  /// docs/performance.md), for three more vectors and the preconditioner's entries read at each
  /// element's corners, which a CPU device pays for. -1 = on a GPU only; 0 = never; 1 = always.
  int fusedPcg = -1;
  /// The device's numbering of a body's elements and nodes, as OpenCLTuning::localityOrder.
  int localityOrder = -1;
  /// Where a dynamic step's vectors live (positions, velocities, accelerations, loads, reactions,
  /// the residual and Newton's correction): in the device's memory, in its precision, its per-dof
  /// passes on the device, so that a step moves no vector through the host but for the multigrid's
  /// warp (the host reads a few sums per pass); or on the host, in double, each device call
  /// converting its vectors on the way. 0 = on the host (the default until it is measured on a
  /// GPU); -1 = on a GPU only; 1 = always. On lavapipe, a CPU device, the device's store halves the
  /// host's CPU a step at 100k elements but takes 5-30 % longer (docs/performance.md). In float the
  /// state is float's: positions read back to about 1e-7 of the body's size. A device lost with the
  /// state loses it: the bodies fail over to the next device at rest, at their rest positions.
  int deviceStore = 0;
};

}  // namespace corofem
