// The OpenCL device state and per-call work of one or more bodies held in shared buffers: each
// body is a *segment* whose elements and nodes are padded to whole work-groups, so that every
// kernel launch serves all bodies at once and each work-group reads its body's material,
// coefficients, PCG scalars and `active` flag from per-segment tables (kernels/shared/
// corofem_layout.h). The single-body OpenCL backend is the one-segment case; the OpenCL batch
// device (solve/batch.hpp) is the many-segment case. Same kernels, same host logic: a body's
// answer does not depend on the other segments (its sums run over its own partials in the same
// order), so a batched body gets the bits it would get alone.
//
// Per call (requests of one op, at most one per segment; only their segments are active; on CPUs
// the requesting bodies run in tiles whose working set fits the cache, each tile as below):
//   SetPositions    one write of the packed relative positions; compute_rotations (+ blocks)
//   InternalForces  element_forces + gather_sum; one read, not blocking, with A x queued behind it
//                   for the bodies whose last solve was warm-started (used by the next solve if
//                   x, the rotations and the coefficients are unchanged)
//   Apply           one write of p; element_product + gather_product; one read
//   Solve           writes of b and x; M^-1, r = b - A x, w = A M^-1 r (pcg_init); PCG iterations
//                   for all active segments (4 launches each;
//                   kernels/opencl/pcg.cl; on CPUs all but the cap's last in one launch,
//                   pcg_iterate_group, for rounds of small bodies or of many: groupRound; bodies
//                   with the same mesh in packs of kPackLanes, a body per vector lane:
//                   pcg_iterate_pack between pack_in and pack_out), the device
//                   stopping each segment at convergence, breakdown or a non-finite residual;
//                   after every checkEvery iterations a non-blocking read of all segments'
//                   scalars, waited for one chunk later; the true residual per segment; one read of x
//   ElasticEnergy   CPUs: the energy the last InternalForces read with the forces, while the positions
//                   are unchanged, else element_forces' energy partials (one per work-item); GPUs:
//                   element_energy; one read of the partials, summed per segment in order
#pragma once

#include "backends/opencl/opencl_backend.hpp"
#include "backends/opencl/tuning.hpp"
#include "solve/batch.hpp"
#include "util/parallel.hpp"

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace corofem::detail {

/// A device buffer released on destruction.
class ClBuffer {
 public:
  ClBuffer() = default;
  ClBuffer(const ClBuffer&) = delete;
  ClBuffer& operator=(const ClBuffer&) = delete;
  ~ClBuffer();
  /// Allocates `bytes` (at least 16); the allocated size counts in bytes().
  void create(cl_context ctx, std::size_t bytes, const std::string& device);
  cl_mem get() const { return mem_; }
  std::size_t bytes() const { return bytes_; }

 private:
  cl_mem mem_ = nullptr;
  std::size_t bytes_ = 0;
};

/// Host memory for the transfers of one node vector, in device precision: allocated by the driver
/// (CL_MEM_ALLOC_HOST_PTR, page-locked on GPU drivers, so a copy runs at the bus's rate with no
/// intermediate copy by the driver) and mapped for the stage's life. Reused by every transfer, so no
/// transfer allocates (a fresh vector of a 1M-element body's 3N reals page-faults through 2 MB).
/// The host writes into it only after the last non-blocking write that reads from it is done.
class HostStage {
 public:
  HostStage() = default;
  HostStage(const HostStage&) = delete;
  HostStage& operator=(const HostStage&) = delete;
  ~HostStage();
  void create(cl_context ctx, cl_command_queue queue, std::size_t bytes, const std::string& device);
  /// The memory, after waiting for the write in flight from it (if any).
  unsigned char* writable();
  /// The memory as it is (for a blocking read into it, or reading it).
  unsigned char* data() const { return host_; }
  /// Non-blocking write of [offset, offset + bytes) of the stage into `to` at the same offset.
  void write(cl_mem to, std::size_t offset, std::size_t bytes, const std::string& device);
  /// Blocking read of [offset, offset + bytes) of `from` into the stage at the same offset.
  void read(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device);
  /// The same read, not blocking: the caller waits for the event returned (and releases it) before
  /// it reads the stage (nullptr for an empty range).
  cl_event readLater(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device);

 private:
  cl_mem mem_ = nullptr;
  cl_command_queue queue_ = nullptr;
  unsigned char* host_ = nullptr;
  cl_event pending_ = nullptr;  ///< the last non-blocking write from the stage
};

/// A kernel released on destruction.
class ClKernel {
 public:
  ClKernel() = default;
  ClKernel(const ClKernel&) = delete;
  ClKernel& operator=(const ClKernel&) = delete;
  ~ClKernel();
  void create(cl_program program, const char* name, const std::string& device);
  cl_kernel get() const { return k_; }
  const char* name() const { return name_; }
  /// clSetKernelArg(i, bytes) unless argument i already holds these bytes (a launch sequence sets
  /// the same buffers every time: the host's enqueue, not the device, bounds small bodies' PCG on
  /// GPUs). The engine's buffers live as long as its kernels, so a handle's bytes name one buffer.
  void setArg(cl_uint i, const void* value, std::size_t bytes, const std::string& device) const;

 private:
  cl_kernel k_ = nullptr;
  const char* name_ = "";
  mutable std::vector<std::vector<unsigned char>> args_;  ///< the bytes last set, per argument
};

/// One kernel's totals on a profiling queue (SegmentEngine::kernelProfile).
struct KernelProfile {
  std::string kernel;
  long launches = 0;
  double deviceSeconds = 0.0;      ///< summed device time of its launches
  double idleSecondsBefore = 0.0;  ///< summed idle time of the device before its launches
};

/// Launches of pcg_iterate_group (one-launch PCG iterations) by every engine of the process so
/// far: tests check with it that the path they compare was taken.
unsigned long long groupPcgLaunchCount();
/// Launches of pcg_iterate_team (one-launch PCG iterations, several work-groups per body) so far.
unsigned long long teamPcgLaunchCount();
/// Launches of pcg_iterate_pack (one-launch PCG iterations, bodies of one mesh in vector lanes) so far.
unsigned long long packPcgLaunchCount();
/// Bodies iterated in those packs so far (one per lane of a launch).
unsigned long long packPcgLaneCount();

class SegmentEngine {
 public:
  friend struct SegmentEngineTestAccess;  // tests/common/opencl_test_access.hpp
  /// All problems share the program (precision, rotation method, preconditioner of `solver`;
  /// the kernels' shapes and strategies of `tuning`, resolved for the device); each keeps its material, mass, Rayleigh damping, constraints and
  /// formulation (co-rotational or linear). Throws Error(BadInput) for another formulation or
  /// an empty body, Error(DeviceError) for a device problem. The problems must outlive the engine.
  SegmentEngine(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                std::shared_ptr<cl::Context> ctx, const OpenCLTuning& tuning);
  ~SegmentEngine();
  SegmentEngine(const SegmentEngine&) = delete;
  SegmentEngine& operator=(const SegmentEngine&) = delete;

  std::size_t segmentCount() const { return segs_.size(); }

  /// Runs requests that all have `op`, at most one per segment (request.body = segment). A
  /// failure of one request (non-finite right-hand side or solution: SolveFailed; a vector of the
  /// wrong size: Internal) sets its `error` and leaves the others running. A device failure
  /// throws Error(DeviceError).
  void run(BatchOp op, const std::vector<BatchRequest*>& requests);

  cl::Context& context() { return *ctx_; }
  std::string deviceDescription() const { return ctx_->info().describe(); }
  const std::string& buildOptions() const { return options_; }
  const cl::ProgramBuild& programBuild() const { return build_; }
  /// Bytes of all device buffers allocated (each at its clCreateBuffer size): the sum of buffers().
  std::size_t allocatedBytes() const;
  /// Every buffer allocated, named for what it holds, at its clCreateBuffer size.
  std::vector<DeviceBuffer> buffers() const;

  /// Segment `s`'s rotations, 9 per element (row-major R), as last computed.
  std::vector<double> readRotations(std::size_t s);
  /// Segment 0's relative positions start at offset 0 of this buffer (3 reals per node).
  cl_mem positionBuffer() const { return pos_.get(); }
  bool positionsAreDouble() const { return double_; }
  const double* positionCentroid(std::size_t s) const { return segs_[s].centroid; }
  /// Segment s's positions as Backend::devicePositions describes them (its nodes from nodeBegin).
  DevicePositions devicePositions(std::size_t s) const {
    return {ctx_->context(), ctx_->queue(), ctx_->device(), pos_.get(), segs_[s].nodeBegin, double_, segs_[s].centroid,
            segs_[s].deviceNode.empty() ? nullptr : segs_[s].deviceNode.data()};
  }

  // Device-only work on every segment (benchmarks), no transfers.
  void enqueueRotations();
  void enqueueForces();
  void enqueueElementForces();
  void enqueueProduct(const SystemCoeffs& c);
  void enqueueElementProduct(const SystemCoeffs& c);
  void enqueuePcgIterations(const SystemCoeffs& c, int iterations);
  void finish();
  /// Per kernel so far: launches, device seconds and the device's idle seconds before its launches
  /// (the previous command's end to its start: launch overhead and host round trips). Only on a
  /// queue created with CL_QUEUE_PROFILING_ENABLE (benchmarks adopt one); empty otherwise.
  std::vector<KernelProfile> kernelProfile();

 private:
  struct Segment {
    const Problem* problem = nullptr;
    std::size_t nodes = 0, elems = 0;         ///< real counts
    std::size_t nodeBegin = 0, nodeSpan = 0;  ///< padded range in the shared node arrays
    std::size_t elemBegin = 0, elemSpan = 0;  ///< padded range in the shared element arrays
    std::size_t partialBegin = 0, partialCount = 0;
    bool corotational = true;
    double rayleighMass = 0, rayleighStiffness = 0;
    std::vector<std::uint8_t> constrained;    ///< 3 * nodes, in the device's node order
    double centroid[3] = {0, 0, 0};           ///< subtracted from the last positions set
    /// The device's numbering when it is not the problem's (localityOrder): device node i is the
    /// problem's node hostNode[i], device element i its element hostElem[i]; deviceNode inverts
    /// hostNode. Empty: the problem's own numbering.
    std::vector<std::uint32_t> hostNode, deviceNode, hostElem;
    std::size_t dofBegin() const { return 3 * nodeBegin; }
    std::size_t dofs() const { return 3 * nodes; }
    /// The problem's dof of the segment's device dof d (0 <= d < dofs()).
    std::size_t hostDof(std::size_t d) const { return hostNode.empty() ? d : 3 * std::size_t{hostNode[d / 3]} + d % 3; }
  };
  /// What a kernel's work-items cover: elements (VEC per item), nodes, node chunks (CHUNK per
  /// item), or segments (one work-group each, reduce_finish).
  /// Teams: teamSize_ work-groups per segment (pcg_iterate_team; pcg_iterate_group: teams of one).
  enum class Span { Elements, Nodes, NodeChunks, Segments, Teams };

  // -- launching
  void setArg(const ClKernel& k, cl_uint i, cl_mem m);
  void setArg(const ClKernel& k, cl_uint i, const ClBuffer& b) { setArg(k, i, b.get()); }
  void setArg(const ClKernel& k, cl_uint i, cl_uint v);
  /// A kernel argument of type sum_real (corofem_layout.h: float, or double in double/mixed precision).
  struct SumReal {
    double value;
  };
  void setArg(const ClKernel& k, cl_uint i, SumReal v);
  template <class... Args>
  void launch(const ClKernel& kernel, Span span, const Args&... args) {
    if (activeLo_ >= activeHi_) return;  // no active segment
    cl_uint index = 0;
    (setArg(kernel, index++, args), ...);
    enqueue(kernel, span);
  }
  void enqueue(const ClKernel& kernel, Span span);
  /// `groups` work-groups of `local` work-items from global id 0 (the pack kernels: a work-group per
  /// pack slot in use).
  template <class... Args>
  void launchGroups(const ClKernel& kernel, std::size_t groups, std::size_t local, const Args&... args) {
    cl_uint index = 0;
    (setArg(kernel, index++, args), ...);
    enqueueRange(kernel, 0, groups * local, local);
  }
  void enqueueRange(const ClKernel& kernel, std::size_t offset, std::size_t global, std::size_t local);
  /// First work-item and count of `span` over the segments [lo, hi).
  std::pair<std::size_t, std::size_t> spanItems(Span span, std::size_t lo, std::size_t hi) const;

  // -- segment state
  /// Marks exactly the segments with active[s] != 0 active (one small write when it changed), with
  /// the flag active[s] (kSegRunning, or kSegRunningPacked for the bodies of pcg_iterate_pack).
  void setActive(const std::vector<char>& active);
  void setAllActive() { setActive(std::vector<char>(segs_.size(), 1)); }
  /// The coefficients of A = m M + c C + k K^R for segment s, Rayleigh terms folded in.
  void setCoefficients(std::size_t s, const SystemCoeffs& c);
  void flushCoefficients();

  // -- transfers, converting to the device precision; ranges in reals of the packed arrays. Writes
  // are non-blocking (enqueueWrite keeps their bytes until done), reads blocking.
  struct PendingWrite {
    std::vector<unsigned char> bytes;
    cl_event event;
  };
  static constexpr std::size_t kMaxPendingWrites = 16;
  void enqueueWrite(const ClBuffer& buf, std::size_t offset, std::vector<unsigned char>&& bytes);
  /// Releases the pending writes; only after a blocking command that followed them.
  void writesDone();
  void upload(const ClBuffer& buf, const double* src, std::size_t begin, std::size_t count);
  void download(const ClBuffer& buf, double* dst, std::size_t begin, std::size_t count);
  void downloadSums(const ClBuffer& buf, double* dst, std::size_t count);
  template <class T>
  void uploadRaw(const ClBuffer& buf, const std::vector<T>& v);
  /// fn(T* reals) with T the device's real type (float or double), at real `begin` of `base`
  /// (a stage's memory; const bytes give const reals).
  template <class Byte, class Fn>
  void withReals(Byte* base, std::size_t begin, Fn&& fn) const {
    constexpr bool ro = std::is_const_v<Byte>;
    if (realSize_ == sizeof(double))
      fn(reinterpret_cast<std::conditional_t<ro, const double, double>*>(base) + begin);
    else
      fn(reinterpret_cast<std::conditional_t<ro, const float, float>*>(base) + begin);
  }
  std::size_t hostChunk_ = 0;  ///< OpenCLTuning::hostChunk
  /// Reals [begin, begin + count) of `base` = value(0 .. count - 1), converted to the device
  /// precision (in chunks on the host's threads).
  template <class Fn>
  void putReals(unsigned char* base, std::size_t begin, std::size_t count, Fn&& value) const {
    parallelChunks(count, hostChunk_, [&](std::size_t, std::size_t lo, std::size_t hi) {
      withReals(base, begin, [&](auto* out) {
        for (std::size_t d = lo; d < hi; ++d) out[d] = static_cast<std::remove_pointer_t<decltype(out)>>(value(d));
      });
    });
  }
  /// out = the segment's reals of `base` in double, in the problem's dof order (resized only if its
  /// size differs).
  void getReals(const unsigned char* base, const Segment& sg, Eigen::VectorXd& out) const;
  void createReal(ClBuffer& buf, std::size_t count) { buf.create(ctx_->context(), count * realSize_, dev_); }
  /// The packed dof range [begin, end) covering the given segments.
  std::pair<std::size_t, std::size_t> dofRange(const std::vector<BatchRequest*>& requests) const;

  // -- the operations
  void build(const SolverDesc& solver);
  void allocate();
  void refreshBlocks(bool cornersWritten);
  /// The preconditioner's node blocks of the running segments whose rotations changed since their
  /// blocks were formed (blocksStale_), before a solve: the last evaluation of a step (a dynamic
  /// step's end, a Newton loop's convergence check) is followed by no solve, so setPositions leaves
  /// them to the solve that needs them.
  void refreshStaleBlocks(const std::vector<char>& running);
  /// compute_rotations on the segments with rotate[s] (made the active ones); R itself only with
  /// writeR (rStale_ records the segments left without it).
  void launchRotations(const std::vector<char>& rotate, bool writeCorners, bool writeR);
  /// Allocates R (rot_) as I for every element, once: at set-up where every pass writes R
  /// (rAlways_), else at the first pass that writes it or readRotations.
  void ensureRotations();
  /// The a_i the element kernels read: rotGrad_, or without a co-rotational body (nothing rotates)
  /// the gradients in geom_'s first 9 components, the same layout.
  const ClBuffer& rotatedGradients() const { return rotGrad_.get() ? rotGrad_ : geom_; }
  void elementProduct(const ClBuffer& v);  ///< element products of v (coefficients flushed)
  /// y = A v (projected onto the free dofs when `project`); partial sums of v . y into `partials`.
  /// With `residualOf` (b): y = free b - A v instead, and the sums (0, y . y, |free b|^2).
  void product(const ClBuffer& v, const ClBuffer& y, bool project, const ClBuffer& partials,
               const ClBuffer* residualOf = nullptr);
  /// w = A u (projected) into q_, then reduce_finish's scalar update in `mode`.
  void productAndFinish(cl_uint mode);
  /// M^-1 from the blocks and the coefficients (nothing without a preconditioner), r = b - A x,
  /// u = M^-1 r, w = A u and the first scalars; `haveAx`: q_ holds A x already (internalForces);
  /// `zeroStart`:
  /// x = 0 on every active segment, so r = b without a product. `productFor` (the packs' set-up):
  /// w = A u and the scalars only for these segments (made the active ones), the others' pcg_init
  /// partials left for pcg_iterate_pack; with `onlyFor` everything only for them (the others take
  /// their whole set-up in pcg_iterate_pack).
  void pcgSetup(bool zeroStart, bool haveAx, const std::vector<char>* productFor = nullptr, bool onlyFor = false);
  /// One PCG iteration; `last`: the iteration cap's last, whose next product is not needed.
  void pcgIteration(bool last = false);
  void setPositions(const std::vector<BatchRequest*>& requests);
  void internalForces(const std::vector<BatchRequest*>& requests);
  void apply(const std::vector<BatchRequest*>& requests);
  void solve(const std::vector<BatchRequest*>& requests);
  void elasticEnergy(const std::vector<BatchRequest*>& requests);
  /// Device bytes a PCG iteration of the segment touches (the tile budget's unit).
  std::size_t workingSet(const Segment& sg) const;
  /// Requests whose vector has 3N entries (the others get an Internal error).
  std::vector<BatchRequest*> checked(const std::vector<BatchRequest*>& requests, const char* what) const;

  std::shared_ptr<cl::Context> ctx_;
  std::string dev_;
  /// On a queue with CL_QUEUE_PROFILING_ENABLE (benchmarks): per kernel, its launches, device time
  /// and the device's idle time before it (kernelProfile). Events are kept, not waited for, and
  /// harvested once complete.
  struct ProfileEntry {
    long launches = 0;
    double busy = 0.0, idleBefore = 0.0;
  };
  bool profile_ = false;
  std::map<std::string, ProfileEntry> profileTimes_;
  std::deque<std::pair<std::string, cl_event>> profileEvents_;
  cl_ulong profileLastEnd_ = 0;
  void harvestProfile(bool all);
  SolverDesc solver_;
  PreconditionerKind precond_;
  OpenCLTuning tuning_;                  ///< resolved for the device (resolveTuning)
  /// Every rotation pass writes R: the Quaternion method cannot run a pass again for readRotations
  /// (each pass advances its warm start). Otherwise R is written only when read back.
  bool rAlways_ = false;
  std::vector<char> rStale_;             ///< per segment: rotated since R was last written
  std::vector<char> blocksStale_;        ///< per segment: rotated since its node blocks were formed
  std::string options_;
  cl::ProgramBuild build_;
  bool double_ = false;
  bool mixed_ = false;                   ///< float vectors, double dot products and PCG scalars
  std::size_t realSize_ = sizeof(float);
  std::size_t sumSize_ = sizeof(float);  ///< size of sum_real (corofem_layout.h)
  std::size_t wg_ = 64;
  std::size_t vec_ = 1;                  ///< elements per work-item in the element kernels
  std::size_t chunk_ = 1;                ///< nodes per work-item in the PCG node kernels
  bool treeReduce_ = false;              ///< partial sums per work-group (GPUs) or per work-item
  std::size_t tileBytes_ = 0;            ///< working set of the bodies run together (0: all at once)
  bool groupPcg_ = false;                ///< PCG iterations of a round in pcg_iterate_group (one launch)
  bool teamPcg_ = false;                 ///< ... and rounds of fewer bodies than cores in pcg_iterate_team
  std::size_t teamSize_ = 1;             ///< work-groups per segment of Span::Teams (the round's)
  cl_uint teamEpoch_ = 0;                ///< the last epoch pcg_iterate_team's claim words may hold
  /// teamState_ between launches: the counts at zero, the claim words at epoch 0.
  std::vector<cl_uint> teamStateAtRest() const;
  /// How a solve round of these bodies runs its PCG iterations: 0 launched (4 launches per
  /// iteration); 1 in pcg_iterate_group, a work-group per body on one core, when each body is small
  /// enough that one core without launches beats all cores with them, or when the bodies fill the
  /// cores and none is too large for one core (groupPcgMaxElements) or much larger than a core's share
  /// of the round; T >= 2 in pcg_iterate_team, T work-groups per body, when fewer bodies than cores
  /// would leave cores idle (teamPcg_, none larger than teamPcgMaxElements).
  std::size_t groupTeam(const std::vector<BatchRequest*>& requests) const;
  bool groupRound(const std::vector<BatchRequest*>& requests) const { return groupTeam(requests) > 0; }

  // -- packs (pcg_pack.cl): the PCG solves of up to kPackLanes bodies with the same mesh (corners
  // and node count) in one work-item, a body per vector lane, on CPU devices in rounds that take
  // pcg_iterate_group. Each mesh shared by at least packPcgMinLanes bodies (a *pack mesh*) gets its
  // corners once and ceil(bodies / kPackLanes) slots of lane-interleaved rows.
  struct PackMesh {
    std::vector<std::size_t> bodies;      ///< its segments
    std::size_t corners = 0;              ///< its first entry in packCorners_
    std::size_t firstSlot = 0;            ///< its slots: [firstSlot, firstSlot + slots)
    std::size_t slots = 0;
  };
  struct PackSlotPlace {
    std::size_t mesh = 0;                 ///< the pack mesh whose bodies it takes
    std::size_t elemBase = 0, nodeBase = 0, partialBase = 0;
  };
  /// Finds the pack meshes (segs_ made); sets packs_ = false where there are none.
  void findPackMeshes();
  /// The packs of a solve round that takes pcg_iterate_group: the rows of packInfo_ (kPackInfoCount
  /// each, the costliest first, then the claim word at 0; empty without packs), with packed[s] = 1
  /// for the bodies they take. Bodies of a pack mesh
  /// are packed in the order of their last solve's iterations (bodies that stop together share a
  /// pack), kPackLanes at a time; a remainder of fewer than packPcgMinLanes bodies is not packed.
  std::vector<cl_uint> packRound(const std::vector<BatchRequest*>& requests, std::vector<char>& packed) const;
  bool packs_ = false;                   ///< pcg_iterate_pack for the pack meshes' bodies
  bool packAlways_ = false;              ///< ... in every round, not only where kPackCost says so
  std::vector<PackMesh> packMeshes_;
  std::vector<PackSlotPlace> packSlots_;
  std::size_t packNodeRows_ = 0;         ///< node rows of all slots (each vector of packVec_)
  std::vector<int> lastIterations_;      ///< per segment: iterations of its last solve
  std::vector<Segment> segs_;
  std::size_t stride_ = 0;               ///< S: all segments' padded elements
  std::size_t nodeTotal_ = 0;            ///< all segments' padded nodes
  std::size_t partialTotal_ = 0;
  bool hasMass_ = false;                 ///< some body has a nonzero lumped mass

  std::vector<cl_uint> segInfo_;         ///< host copy of the device table (kSegInfoCount per segment)
  std::vector<double> segCoef_;          ///< host copy (kSegCoefCount per segment)
  bool coefDirty_ = true;
  std::vector<char> active_;
  bool segInfoStale_ = false;            ///< the device may have deactivated segments (PCG stops): upload next time
  std::size_t activeLo_ = 0, activeHi_ = 0;  ///< span of the active segments
  // Pinned stages of the per-step transfers, each filled or read in one pass that also converts
  // precision (and checks, packs, compares) while touching the user's vector once.
  HostStage posStage_;                   ///< the device positions (relative), all segments
  HostStage bStage_;                     ///< b of solve, p of apply
  HostStage xStage_;                     ///< x of solve: what the host last wrote to or read from x_
  HostStage readStage_;                  ///< blocking reads (forces, products)
  /// Per segment: the device's x equals xStage_'s (bit for bit), so that a solve warm-started from
  /// the previous solution (an application's usual frame) uploads no x.
  std::vector<char> xKnown_;
  /// Per segment: its last solve started from a nonzero x (so the next one likely does too).
  std::vector<char> warmLast_;
  /// CPU configuration (no work-group trees): element_forces also writes each work-item's strain
  /// energy into partials_, read with the forces; energy_[s] is then segment s's energy at its
  /// current positions until setPositions changes them (energyKnown_[s]).
  bool energyWithForces_ = false;
  std::vector<double> energy_;
  std::vector<char> energyKnown_;
  std::vector<unsigned char> energyItems_;  ///< host copy of the energy partials (the engine outlives its reads)
  /// Segment s's energy from the element work-items' partials of the read span [lo, lo + n) (host
  /// copy `items`, device precision), summed in order: the same bits however the partials were made.
  double energyOf(std::size_t s, const unsigned char* items, std::size_t lo) const;
  /// Reads the energy partials of the active segments' element work-items into energyItems_:
  /// blocking when `done` is null, else not, with the event in *done. Returns the span's first item.
  std::size_t readEnergyItems(cl_event* done);
  /// Per segment: q_ holds free(A x_) formed by internalForces with the coefficients axCoef_ (and
  /// the rotations and x of now); cleared by anything that writes q_.
  std::vector<char> axReady_;
  std::vector<double> axCoef_;
  std::vector<unsigned char> staging_;   ///< device-precision staging of other blocking reads
  std::deque<PendingWrite> writes_;      ///< non-blocking writes in flight, oldest first

  ClKernel kRotations_, kForces_, kEnergy_, kProduct_, kGatherSum_, kGatherProduct_, kBlocks_,
      kCornerGradients_, kPcgInit_, kPcgUpdate_, kReduceFinish_, kPcgIterateGroup_,
      kPcgIterateTeam_, kPcgIteratePack_, kPackIn_, kPackOut_;
  ClBuffer elemSeg_, nodeSeg_, segInfoBuf_, segCoefBuf_;
  ClBuffer elemNodes_, geom_, rot_, rotGrad_, quat_, elemOut_, nodeStart_, nodeEntries_;
  // PCG (pcg.cl): z_ holds u = M^-1 r, q_ holds w = A u (and A v of apply), s_ holds s = A p;
  // partials_ takes pcg_init/pcg_update's and element_energy's sums, partialsW_ gather_product's.
  ClBuffer pos_, mass_, free_, blocks_, minv_, x_, b_, r_, z_, p_, q_, s_, partials_, partialsW_, scalars_;
  ClBuffer teamState_;  ///< teamPcg_: pcg_iterate_team's state, kTeamStride per segment, then claim words
  ClBuffer groupOrder_; ///< groupPcg_: pcg_iterate_group's segments, the costliest first, then the claim word
  // packs_ (corofem_layout.h, "packs of bodies"): the slots' table of the round, the pack meshes'
  // corners, the slots' element rows (a_i, volume), node sums, PCG vectors (x r u p s w b), free
  // masks, masses, M^-1 and partial sums.
  ClBuffer packInfo_, packCorners_, packElem_, packSums_, packVec_, packFree_, packMass_,
      packMinv_, packPartials_;
};

}  // namespace corofem::detail
