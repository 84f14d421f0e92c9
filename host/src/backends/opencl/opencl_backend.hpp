// The OpenCL backend (co-rotational and linear formulations): internal interface for tests and
// benchmarks, beyond the Backend interface of solve/backend.hpp.
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#include "solve/backend.hpp"

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// Options of the OpenCL backend that the scene does not expose (tuning, benchmarking).
struct OpenCLOptions {
  bool storedStiffness = false;  ///< product with a stored 12x12 K_e per element instead of the gradients
  std::size_t workGroupSize = 0; ///< power of two, 0 = the default (64)
  std::size_t vectorWidth = 0;   ///< elements per work-item in the element kernels (1, 4, 8, 16), 0 = 8 on CPUs, 1 on GPUs
  std::size_t nodeChunk = 0;     ///< nodes per work-item in the PCG node kernels, 0 = default (1 on GPUs, CPUs: see the backend)
  int treeReduce = -1;           ///< 1: partial sums by local-memory trees (GPU style), 0: one per work-item, -1: by device type
  /// 1: the PCG's second-stage sums run in the last work-group of gather_product_finish (one launch
  /// fewer per iteration), 0 or -1 (default): in reduce_finish. Opt-in: OpenCL
  /// 1.2 gives its cross-work-group publication no device-scope fence (kernels/opencl/README.md).
  int fusedReduce = -1;
  /// Entries per chunk of the host's passes over node vectors (util/parallel.hpp), 0 = the
  /// default (65,536); tests set small ones to run the chunked passes on small meshes.
  std::size_t hostChunk = 0;
  int quaternionIterations = 0;  ///< Quaternion rotation method: iterations per update, 0 = default (6)
  bool assumeNoFp64 = false;     ///< tests: treat the device as lacking cl_khr_fp64 (the error path of double/mixed)
  long long tileBytes = -1;      ///< batches: bodies run together up to this working set; -1 = by device (CPUs: defaultTileBytes of the cache, GPUs: all), 0 = all
  /// PCG iterations of a solve round in one launch, a work-group per body (pcg_iterate_group, CPU
  /// devices): the same bits as the launched iterations. 1: for a round of bodies of at most
  /// `groupPcgSmallElements` elements each, or of at least `groupPcgMinBodies` bodies (see
  /// groupPcgMaxElements);
  /// 0: never; -1 (default): 1 on CPU devices, 0 on GPUs (whose partial sums are work-group trees).
  int groupPcg = -1;
  /// The fewest bodies in a solve round for the one-launch iterations; 0 = the default (the
  /// device's compute units: one work-group per body cannot use more cores than bodies).
  std::size_t groupPcgMinBodies = 0;
  /// Rounds of fewer bodies still run in one launch when no body has more elements than this; 0 =
  /// the default, 8,192 / compute units (4,096 on 2 cores, where one core without launches took a
  /// 1k-element box's step with 20 iterations in 0.41 ms against 0.72 ms launched on both, and a
  /// 10k one's in 2.1-2.2 ms against 2.0; more cores favour the launched iterations).
  std::size_t groupPcgSmallElements = 0;
  /// A round of at least `groupPcgMinBodies` bodies runs in one launch only when none has more
  /// elements than this, nor more than twice its share (total / compute units); 0 = the default,
  /// 32,768 / compute units (16,384 on 2 cores, where 10k + 10k elements ran 1.5x faster in one
  /// launch and 35k + 35k 1.1x slower).
  std::size_t groupPcgMaxElements = 0;
  /// A solve round of fewer bodies than the device's compute units runs its iterations in one
  /// launch with a team of up to (compute units / bodies) work-groups per body (pcg_iterate_team:
  /// each member claims its share of every phase's chunks first and the unclaimed rest after, the
  /// same bits as the launched iterations), when groupPcg is on and each member has at least
  /// `teamPcgMinElements` of the largest body's elements. 1: on; 0: never; -1 (default): on with
  /// groupPcg on a CPU device of several compute units (never on GPUs).
  int teamPcg = -1;
  /// The largest body for pcg_iterate_team; 0 = the default, 16,384 elements per compute unit (on
  /// 2 cores the team beat the launched iterations at 10k and 100k elements on an idle machine, but
  /// lost at 100k with another busy process on the cores).
  std::size_t teamPcgMaxElements = 0;
  /// The fewest elements of the largest body per work-group of a team; 0 = the default, 1,280 (on
  /// 2 cores a team of 2 lost to one work-group at 1k elements, tied at 2.3k and won from 2.9k).
  std::size_t teamPcgMinElements = 0;
  /// Tests: with teamPcg on, every solve round's iterations in teams of this many work-groups per
  /// body, whatever the rule says (more than the device's cores, too: the groups then run in turns
  /// and the first does the work); 0 = by the rule.
  std::size_t teamPcgSize = 0;
  /// In a solve round that runs pcg_iterate_group, the iterations of bodies that share one mesh
  /// (the same element corners and node count; material, rest shape, mass, constraints and solve
  /// each their own) in packs of 8, a body per vector lane of one work-item (pcg_iterate_pack: the
  /// same bits as pcg_iterate_group, every load a whole vector instead of a gather). 1: in every
  /// such round; 0: never; -1 (default): on CPU devices, in the rounds where packs shorten the
  /// round (a pack costs a core about 2.5 bodies' iterations: SegmentEngine::kPackCost).
  /// COROFEM_OPENCL_PACK_PCG=0/1 sets it when -1.
  int packPcg = -1;
  /// The fewest bodies of a pack (a pack costs its 8 lanes whatever it holds); 0 = the default, 3.
  /// COROFEM_OPENCL_PACK_PCG_MIN sets it when 0.
  std::size_t packPcgMinLanes = 0;
  /// Tests: the work-groups that take a round's packs (pcg_iterate_pack: each takes the next slot,
  /// the costliest first, until none is left); 0 = the device's compute units.
  std::size_t packPcgTakers = 0;
  /// Tests: the work-groups of pcg_iterate_group (each takes the next body, the costliest first,
  /// until none is left); 0 = the device's compute units.
  std::size_t groupPcgTakers = 0;
  /// Tests: the epoch pcg_iterate_team's claims start from (the wrap of the 32-bit epochs, which
  /// otherwise comes after about 10^9 phases); 0 = the default.
  unsigned teamEpochStart = 0;
  /// The device's numbering of elements and nodes: -1 (default) a Morton order where it is more
  /// local than the mesh's own (mesh/locality_order.hpp; the box generator's numbering stays), 0 the
  /// mesh's own, 1 the Morton order always (tests). Host vectors keep the mesh's numbering either way.
  /// COROFEM_OPENCL_REORDER=0/1 sets it when this is -1.
  int localityOrder = -1;
  /// -cl-denorms-are-zero: -1 (default) on CPU devices (a denormal float costs an x86 core a
  /// microcode assist per operation), 0 never, 1 always. COROFEM_OPENCL_FTZ=0/1 sets it when -1.
  int flushDenormals = -1;
};

/// Backend plus what the conformance tests and the benchmark need to see.
class OpenCLBackendInternal : public Backend {
 public:
  /// The element rotations, 9 per element (row-major R), as last computed by setPositions.
  virtual std::vector<double> readRotations() = 0;
  /// The -D options the program was built with.
  virtual const std::string& buildOptions() const = 0;
  /// Where the program came from (memory, disk cache, compiler).
  virtual cl::ProgramOrigin programOrigin() const = 0;
  virtual const cl::ProgramBuild& programBuild() const = 0;
  virtual cl::Context& context() = 0;
  /// Bytes of device memory the backend allocated (the sum of its buffers' sizes). Only buffers
  /// something reads exist: no mass buffer for a static problem (no nonzero lumped mass), the
  /// stored K_e only with OpenCLOptions::storedStiffness, quaternions only for that rotation
  /// method, preconditioner data only with a preconditioner.
  virtual std::size_t allocatedBytes() const = 0;

  // The node positions on the device (e.g. for DeviceSurface::updateFromDevice, no host round trip):
  // 3 reals per node (double when positionsAreDouble(), else float, also in mixed precision), those
  // last given to setPositions, minus positionCentroid() (the mean of those positions, subtracted in
  // double so that float keeps its resolution far from the origin): x_n = pos[m] + centroid, with m
  // = n, or m = DevicePositions::deviceNode[n] where the device numbers the nodes in its locality
  // order (OpenCLOptions::localityOrder).
  /// The buffer of 3 * nodeCount relative positions; owned by the backend, valid for its lifetime.
  virtual cl_mem positionBuffer() const = 0;
  virtual bool positionsAreDouble() const = 0;
  /// The centroid subtracted by the last setPositions (0 before the first).
  virtual const double* positionCentroid() const = 0;

  // Device-only work for the benchmark (no transfers); finish() waits for it.
  virtual void enqueueRotations() = 0;         ///< rotations from the positions on the device
  virtual void enqueueForces() = 0;            ///< element forces + gather
  virtual void enqueueElementForces() = 0;     ///< element forces only (no gather)
  virtual void enqueueProduct(const SystemCoeffs& c) = 0;  ///< q = A p (element product + gather)
  virtual void enqueueElementProduct(const SystemCoeffs& c) = 0;  ///< element product only
  /// PCG set-up from the b and x last given to solve(), then `iterations` iterations, no reads.
  virtual void enqueuePcgIterations(const SystemCoeffs& c, int iterations) = 0;
  virtual void finish() = 0;
};

/// The backend on a given context (shared, private or adopted). Throws Error(BadInput) for a
/// formulation other than co-rotational or linear, Error(DeviceError) for a device problem.
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem,
                                                             const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLOptions& options = {});

class BatchDevice;

/// The OpenCL batch device (solve/batch.hpp: createOpenCLBatchDevice) on a given context and with
/// the tuning options of the single backend (tests, benchmarks).
std::unique_ptr<BatchDevice> createOpenCLBatchDeviceOn(const std::vector<const Problem*>& problems,
                                                       const SolverDesc& solver,
                                                       std::shared_ptr<cl::Context> context,
                                                       const OpenCLOptions& options = {});

/// The backend on an application's own context, queue and device (retained, never released
/// beyond the backend's own references).
std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem,
                                                                   const SolverDesc& solver,
                                                                   cl_context context,
                                                                   cl_command_queue queue,
                                                                   cl_device_id device,
                                                                   const OpenCLOptions& options = {});

}  // namespace corofem::detail
