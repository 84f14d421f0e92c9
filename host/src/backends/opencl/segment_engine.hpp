// The OpenCL device state of one or more bodies held in shared buffers, and the launch sequences
// of the Device operations (device/device.hpp). Each body is a segment (device/body_layout.hpp)
// whose elements and nodes are padded to whole work-groups, so that every kernel launch serves all
// bodies at once and each work-group reads its body's material, coefficients, PCG scalars and
// `active` flag from per-segment tables (kernels/shared/corofem_layout.h). A body's answer does not
// depend on the other segments (its sums run over its own partials in the same order), so a body
// among many gets the bits it would get alone.
//
// The work is split by concern over several files:
//   segment_engine.cpp      set-up: tuning, program, buffers and tables
//   engine_transfer.cpp     launches, the segment tables, transfers between host and device
//   engine_element.cpp      rotations, forces, products, energies (on CPUs in tiles of the cache)
//   engine_pcg.cpp          the PCG building blocks: set-up, launched iterations, reads, true residual
//   cpu_pcg.cpp             the CPU devices' one-launch iterations (pcg_iterate_group, _team, _pack)
//
// Per call (only the called bodies' segments are active):
//   setPositions    one write of the packed relative positions; compute_rotations
//   internalForces  element_forces + gather_sum; one read, not blocking, with A x queued behind it
//                   for the bodies whose last solve was warm-started (used by the next solve if
//                   x, the rotations and the coefficients are unchanged)
//   apply           one write of p; element_product + gather_product; one read
//   pcgBegin        writes of b and x; node blocks where stale; M^-1, r = b - A x, w = A M^-1 r
//   pcgIterate      4 launches per iteration (kernels/opencl/pcg.cl), or on CPUs all but the cap's
//                   last in one launch (cpu_pcg.hpp); the device stops each segment at convergence,
//                   breakdown or a non-finite residual
//   pcgRead/Take    a non-blocking read of every segment's scalars
//   pcgResidual     r = free b - A x and its sums; pcgEnd one read of x
//   elasticEnergy   CPUs: the energy the last internalForces read with the forces, while the
//                   positions are unchanged, else element_forces' energy partials; GPUs:
//                   element_energy; one read of the partials, summed per segment in order
#pragma once

#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/cl_objects.hpp"
#include "backends/opencl/program_cache.hpp"
#include "backends/opencl/tuning.hpp"
#include "device/body_layout.hpp"
#include "device/device.hpp"

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace corofem::detail {

/// One kernel's totals on a profiling queue (SegmentEngine::kernelProfile).
struct KernelProfile {
  std::string kernel;
  long launches = 0;
  double deviceSeconds = 0.0;      ///< summed device time of its launches
  double idleSecondsBefore = 0.0;  ///< summed idle time of the device before its launches
};

class CpuPcg;
class DeviceWarped;
class EngineAmg;
struct CpuPcgCounts;

class SegmentEngine {
 public:
  friend struct SegmentEngineTestAccess;  // tests/common/opencl_test_access.hpp
  friend class CpuPcg;
  friend class EngineAmg;
  /// All problems share the program (precision, rotation method, preconditioner of `solver`; the
  /// kernels' shapes and strategies of `tuning`, resolved for the device); each keeps its material,
  /// mass, Rayleigh damping, constraints and formulation (co-rotational or linear). Throws
  /// Error(BadInput) for another formulation, another linear solver or an empty body,
  /// Error(DeviceError) for a device problem. The problems must outlive the engine.
  SegmentEngine(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                std::shared_ptr<cl::Context> ctx, const OpenCLTuning& tuning);
  ~SegmentEngine();
  SegmentEngine(const SegmentEngine&) = delete;
  SegmentEngine& operator=(const SegmentEngine&) = delete;

  std::size_t segmentCount() const { return segs_.size(); }
  const Problem& problem(std::size_t s) const { return *segs_.at(s).problem; }

  // -- the Device operations (device/device.hpp), for segments = bodies
  void setPositions(const BodySet& bodies, const ConstVectors& x);
  void internalForces(const BodySet& bodies, const Vectors& f);
  void apply(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p, const Vectors& y);
  void elasticEnergy(const BodySet& bodies, std::vector<double>& energy);
  void setConstraints(const BodySet& bodies, const std::vector<const std::vector<std::uint8_t>*>& constrained);
  void setMaterial(const BodySet& bodies, const std::vector<const Problem*>& problems);
  void setSprings(const BodySet& bodies, const std::vector<const Problem*>& problems);
  /// The bodies of a solve in tiles solved one after another (CPU devices, where a tile's working
  /// set fits the cache), or all at once.
  std::vector<BodySet> pcgTiles(const BodySet& bodies) const;
  std::vector<PcgStart> pcgBegin(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& b,
                                 const ConstVectors& x, double tolerance, int maxIterations);
  bool pcgOneLaunch() const { return round_.team > 0; }
  bool pcgSetupReadable() const { return !round_.packWhole; }
  void pcgIterate(int n, const std::vector<char>& running);
  PcgTicket pcgRead();
  void pcgTake(PcgTicket ticket, std::vector<PcgScalars>& scalars);
  void pcgResidual(const std::vector<char>& bodies);
  void pcgEnd(const std::vector<int>& iterations, const Vectors& x, std::vector<PcgScalars>& residual);

  cl::Context& context() { return *ctx_; }
  std::string deviceDescription() const { return ctx_->info().describe(); }
  const std::string& buildOptions() const { return options_; }
  const cl::ProgramBuild& programBuild() const { return build_; }
  /// Bytes of all device buffers allocated (each at its clCreateBuffer size): the sum of buffers().
  std::size_t allocatedBytes() const;
  /// Every buffer allocated, named for what it holds, at its clCreateBuffer size.
  std::vector<DeviceBuffer> buffers() const;

  /// Segment `s`'s rotations, 9 per element (row-major R, the problem's element order), as last
  /// computed.
  std::vector<double> readRotations(std::size_t s) { return std::move(readRotations(BodySet{s}).front()); }
  /// The same for each of `segments`, in one read of the elements they span.
  std::vector<std::vector<double>> readRotations(const BodySet& segments);
  /// Segment 0's relative positions start at offset 0 of this buffer (3 reals per node).
  cl_mem positionBuffer() const { return pos_.get(); }
  bool positionsAreDouble() const { return double_; }
  const double* positionCentroid(std::size_t s) const { return segs_[s].centroid; }
  /// Segment s's positions as Device::devicePositions describes them (its nodes from nodeBegin).
  DevicePositions devicePositions(std::size_t s) const;
  /// The one-launch PCG iterations this engine ran (zeros on a GPU, which launches every iteration).
  CpuPcgCounts pcgCounts() const;
  /// The "amg" hierarchies made so far (0 without the multigrid).
  long long amgBuilds() const;
  /// The "warped_cholesky" factors made so far (0 without it).
  long long warpedBuilds() const;

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
  /// What a kernel's work-items cover: elements (VEC per item), nodes, node chunks (CHUNK per
  /// item), or segments (one work-group each, reduce_finish).
  enum class Span { Elements, Nodes, NodeChunks, Segments };

  // -- launching (engine_transfer.cpp)
  void setArg(const ClKernel& k, cl_uint i, cl_mem m);
  void setArg(const ClKernel& k, cl_uint i, const ClBuffer& b) { setArg(k, i, b.get()); }
  void setArg(const ClKernel& k, cl_uint i, cl_uint v);
  /// A kernel argument of type sum_real (corofem_layout.h: float, or double in double/mixed precision).
  struct SumReal {
    double value;
  };
  void setArg(const ClKernel& k, cl_uint i, SumReal v);
  /// A kernel argument of type real (float, or double in double precision).
  struct RealArg {
    double value;
  };
  void setArg(const ClKernel& k, cl_uint i, RealArg v);
  template <class... Args>
  void launch(const ClKernel& kernel, Span span, const Args&... args) {
    if (activeLo_ >= activeHi_) return;  // no active segment
    cl_uint index = 0;
    (setArg(kernel, index++, args), ...);
    enqueue(kernel, span);
  }
  void enqueue(const ClKernel& kernel, Span span);
  /// `global` work-items in work-groups of `local` from global id `offset`, arguments set first.
  template <class... Args>
  void launchRange(const ClKernel& kernel, std::size_t offset, std::size_t global, std::size_t local,
                   const Args&... args) {
    cl_uint index = 0;
    (setArg(kernel, index++, args), ...);
    enqueueRange(kernel, offset, global, local);
  }
  void enqueueRange(const ClKernel& kernel, std::size_t offset, std::size_t global, std::size_t local);
  /// First work-item and count of `span` over the segments [lo, hi).
  std::pair<std::size_t, std::size_t> spanItems(Span span, std::size_t lo, std::size_t hi) const;
  void harvestProfile(bool all);

  // -- segment tables (engine_transfer.cpp)
  /// Marks exactly the segments with active[s] != 0 active (one small write when it changed), with
  /// the flag active[s] (kSegRunning, or kSegRunningPacked for the bodies of pcg_iterate_pack).
  void setActive(const std::vector<char>& active);
  void setAllActive() { setActive(std::vector<char>(segs_.size(), 1)); }
  /// active[s] = 1 for the segments of `bodies`.
  std::vector<char> activeOf(const BodySet& bodies) const;
  /// The coefficients of A = m M + c C + k K^R for segment s, Rayleigh terms folded in.
  void setCoefficients(std::size_t s, const SystemCoeffs& c);
  void flushCoefficients();
  /// Segment s's first partial triple and their count: one per node-kernel work-item (CPUs), or
  /// one per work-group with trees (GPUs).
  std::size_t partialBegin(std::size_t s) const;
  std::size_t partialCount(std::size_t s) const;

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
  template <class T>
  void uploadRaw(const ClBuffer& buf, const std::vector<T>& v) {
    const auto* data = reinterpret_cast<const unsigned char*>(v.data());
    enqueueWrite(buf, 0, std::vector<unsigned char>(data, data + v.size() * sizeof(T)));
  }
  void createReal(ClBuffer& buf, std::size_t count) { buf.create(ctx_->context(), count * realSize_, dev_); }
  // Staging in the device's precision and numbering (device/body_layout.hpp).
  template <class Byte, class Fn>
  void withReals(Byte* base, std::size_t begin, Fn&& fn) const {
    detail::withReals(base, double_, begin, std::forward<Fn>(fn));
  }
  template <class Fn>
  void putReals(unsigned char* base, std::size_t begin, std::size_t count, Fn&& value) const {
    detail::putReals(base, double_, begin, count, hostChunk_, std::forward<Fn>(value));
  }
  void getReals(const unsigned char* base, const BodySegment& sg, Eigen::VectorXd& out) const {
    detail::getReals(base, double_, sg, hostChunk_, out);
  }
  /// The packed dof range [begin, end) covering the given segments.
  std::pair<std::size_t, std::size_t> dofRange(const BodySet& bodies) const;
  /// Throws Error(Internal) unless each vector has 3N entries of its body.
  void checkSizes(const BodySet& bodies, const ConstVectors& v, const char* what) const;
  void checkSizes(const BodySet& bodies, std::size_t vectors, const char* what) const;

  // -- set-up (segment_engine.cpp)
  void build(const SolverDesc& solver);
  void allocate();
  /// Device bytes a PCG iteration of the segment touches (the tile budget's unit).
  std::size_t workingSet(std::size_t s) const;
  /// `bodies` in tiles of consecutive bodies whose working set fits `tileBytes` (0: one tile).
  std::vector<BodySet> tiles(const BodySet& bodies, std::size_t tileBytes) const;

  // -- element operations (engine_element.cpp)
  /// The preconditioner is formed on the device from node blocks (pcg_init's M^-1): every one but
  /// none and "warped_cholesky" (the host's factor).
  bool formsBlocks() const {
    return precond_ != PreconditionerKind::None && precond_ != PreconditionerKind::WarpedCholesky;
  }
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
  void setPositionsTile(const BodySet& bodies, const ConstVectors& x);
  void internalForcesTile(const BodySet& bodies, const Vectors& f);
  void applyTile(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p, const Vectors& y);
  void elasticEnergyTile(const BodySet& bodies, std::vector<double>& energy);
  /// Segment s's energy from the element work-items' partials of the read span [lo, lo + n) (host
  /// copy `items`, device precision), summed in order: the same bits however the partials were made.
  double energyOf(std::size_t s, const unsigned char* items, std::size_t lo) const;
  /// Reads the energy partials of the active segments' element work-items into energyItems_:
  /// blocking when `done` is null, else not, with the event in *done. Returns the span's first item.
  std::size_t readEnergyItems(cl_event* done);

  // -- PCG (engine_pcg.cpp)
  /// w = A u (projected) into q_, then reduce_finish's scalar update in `mode`.
  void productAndFinish(cl_uint mode);
  /// M^-1 from the blocks and the coefficients (nothing without a preconditioner), r = b - A x,
  /// u = M^-1 r, w = A u and the first scalars; `haveAx`: q_ holds A x already (internalForces);
  /// `zeroStart`: x = 0 on every active segment, so r = b without a product. `productFor` (the
  /// packs' set-up): w = A u and the scalars only for these segments (made the active ones), the
  /// others' pcg_init partials left for pcg_iterate_pack; with `onlyFor` everything only for them
  /// (the others take their whole set-up in pcg_iterate_pack).
  void pcgSetup(bool zeroStart, bool haveAx, const std::vector<char>* productFor = nullptr, bool onlyFor = false);
  /// One launched PCG iteration; `last`: the iteration cap's last, whose next product is not needed.
  void pcgIteration(bool last = false);
  /// "warped_cholesky" before a solve of `running`: their factors and warps (device_warped.hpp),
  /// the warp from the rotations the device computed.
  void prepareWarped(const BodySet& running);
  /// "warped_cholesky": z_ = M^-1 r_ of the running segments on the host after pcg_init or
  /// pcg_update (which left z_ = r_), and r . z in place of their partials' first sums (the others
  /// kept: r . r, and b . b of pcg_init); none for a segment the host or the device has stopped.
  /// One blocking read of r_, the partials and the segment table; two writes.
  void hostPrecondition();
  /// Waits for the pending scalar reads (on an error, or a solve that ends before taking them).
  void dropReads(bool wait);
  /// The host's view of the launched span: the segments still running as it knows.
  void narrowSpan(const std::vector<char>& running);

  std::shared_ptr<cl::Context> ctx_;
  std::string dev_;
  bool profile_ = false;  ///< the queue profiles: kernel events are kept (kernelProfile)
  struct ProfileEntry {
    long launches = 0;
    double busy = 0.0, idleBefore = 0.0;
  };
  std::map<std::string, ProfileEntry> profileTimes_;
  std::deque<std::pair<std::string, cl_event>> profileEvents_;
  cl_ulong profileLastEnd_ = 0;
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
  std::size_t hostChunk_ = 0;            ///< entries per chunk of the host's passes (OpenCLTuning::hostChunk)
  std::vector<BodySegment> segs_;
  std::size_t stride_ = 0;               ///< S: all segments' padded elements
  std::size_t nodeTotal_ = 0;            ///< all segments' padded nodes
  std::size_t partialTotal_ = 0;
  bool hasMass_ = false;                 ///< some body has a nonzero lumped mass
  std::unique_ptr<CpuPcg> cpu_;          ///< the CPU devices' one-launch iterations (cpu_pcg.hpp)
  std::unique_ptr<EngineAmg> amg_;       ///< the "amg" preconditioner's levels (engine_amg.hpp), or null
  std::unique_ptr<DeviceWarped> warped_; ///< the "warped_cholesky" factors (device_warped.hpp), or null
  std::vector<unsigned char> warpedR_;   ///< hostPrecondition's read of r
  std::vector<cl_uint> warpedTable_;     ///< and of the segment table
  /// Per segment: a body of the solve the host has seen stop (narrowSpan); hostPrecondition skips it.
  std::vector<char> hostStopped_;
  std::vector<int> lastIterations_;      ///< per segment: iterations of its last solve

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
  /// Per segment: q_ holds free(A x_) formed by internalForces with the coefficients axCoef_ (and
  /// the rotations and x of now); cleared by anything that writes q_.
  std::vector<char> axReady_;
  std::vector<double> axCoef_;
  /// The application's springs (Problem::springStiffness, N/m) per segment in the device's dof
  /// order, empty for none. The kernels have no spring term of their own: A = m M + s K + s S has
  /// S diagonal, so the segment's stretch of mass_ holds D = M + (s / m) S with the coefficient m
  /// (or D = s S with the coefficient 1 where m = 0), m D = m M + s S. setCoefficients folds them
  /// again when s / m changes (the time step, or a damping product's s = 0: D = M).
  struct SpringFold {
    double factor = 0.0;    ///< D = (unitMass ? 0 : M) + factor S
    bool unitMass = false;  ///< the segment's mass coefficient is 1, not m (m = 0)
    bool operator==(const SpringFold& o) const { return factor == o.factor && unitMass == o.unitMass; }
  };
  std::vector<std::vector<double>> springs_;
  std::vector<SpringFold> springFold_;  ///< what mass_ holds per segment
  std::vector<char> springFoldStale_;   ///< the springs changed since: fold again
  /// Per segment, the system's m + c alpha of the last coefficients (segCoef_ holds the device's,
  /// 1 where springs stand in for a zero mass term).
  std::vector<double> operatorMass_;
  void foldSprings(std::size_t s, const SpringFold& fold);
  std::vector<unsigned char> staging_;   ///< device-precision staging of other blocking reads
  std::deque<PendingWrite> writes_;      ///< non-blocking writes in flight, oldest first

  /// The solve in progress (pcgBegin .. pcgEnd).
  struct Round {
    BodySet bodies;                      ///< the solve's bodies (segments), as the driver gave them
    std::vector<char> running;           ///< per body of the set: set up and iterating
    std::size_t team = 0;                ///< 0 launched, 1 pcg_iterate_group, T >= 2 teams of T
    std::vector<char> packed;            ///< per segment: its iterations run in a pack
    std::vector<cl_uint> packTable;      ///< the packs' table (cpu_pcg.hpp); empty without packs
    bool unpacked = false;               ///< some running body is not packed
    bool packWhole = false, packFresh = false;  ///< the packs run the whole solve / and its set-up
    std::size_t lo = 0, hi = 0;          ///< the packed dof range of the running bodies
    int cap = 0, enqueued = 0;
    double tolerance = 0.0;
    std::vector<char> residualFor;       ///< per segment: its true residual was queued
  } round_;
  struct Read {
    std::vector<unsigned char> bytes;
    cl_event event = nullptr;
  };
  std::deque<Read> reads_;               ///< scalar reads not yet taken, the oldest first
  PcgTicket firstTicket_ = 0;            ///< the ticket of reads_.front()
  /// The read after a one-launch round's iterations (CpuPcg::roundDone times the round to it).
  PcgTicket timedTicket_ = ~PcgTicket{0};

  ClKernel kRotations_, kForces_, kEnergy_, kProduct_, kGatherSum_, kGatherProduct_, kBlocks_, kCornerGradients_,
      kPcgInit_, kPcgUpdate_, kReduceFinish_;
  ClBuffer elemSeg_, nodeSeg_, segInfoBuf_, segCoefBuf_;
  ClBuffer elemNodes_, geom_, rot_, rotGrad_, quat_, elemOut_, nodeStart_, nodeEntries_;
  // PCG (pcg.cl): z_ holds u = M^-1 r, q_ holds w = A u (and A v of apply), s_ holds s = A p;
  // partials_ takes pcg_init/pcg_update's and element_energy's sums, partialsW_ gather_product's.
  ClBuffer pos_, mass_, free_, blocks_, minv_, x_, b_, r_, z_, p_, q_, s_, partials_, partialsW_, scalars_;
};

}  // namespace corofem::detail
