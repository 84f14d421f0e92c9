// One or many bodies in shared OpenCL buffers (segment_engine.hpp): layout, transfers and the
// per-op launch sequences. Build switches (-D), shared by all segments: precision (COROFEM_DOUBLE;
// COROFEM_MIXED: float vectors and products, PCG dot products, partials and scalars in double),
// rotation method (COROFEM_ROT_*), preconditioner (COROFEM_PRECOND_*), work-group size
// (COROFEM_WG), elements per work-item (COROFEM_VEC: 8 on CPUs, 1 on GPUs), nodes per work-item in
// the reducing node kernels (COROFEM_CHUNK: 4 on CPUs; COROFEM_TREE_REDUCE: local-memory trees on
// GPUs). Per body (tables, no switch): Lame parameters, lumped mass, constraints, Rayleigh damping
// (C = alpha M + beta K^R folds into the two coefficients of M and K^R), formulation (the linear one
// never runs compute_rotations). The switches' values come from the tuning (tuning.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/segment_engine.hpp"

#include "mesh/locality_order.hpp"
#include "util/error.hpp"
#include "util/finite.hpp"
#include "util/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <limits>

namespace corofem::detail {

// The device layout constants (kScalarRho, kGeomVolume, kSegActive, ...), shared with the kernels.
namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

namespace {

using cl::checkCl;
using namespace layout;

static_assert(kPackLanes == 8, "pcg_pack.cl's PACK_L and its vector types are 8 lanes");

std::size_t roundUp(std::size_t n, std::size_t m) { return (n + m - 1) / m * m; }

/// The Error a request fails with (set into BatchRequest::error, rethrown by the body's view).
template <class... Parts>
std::exception_ptr errorOf(ErrorCode code, const Parts&... parts) {
  try {
    fail(code, parts...);
  } catch (...) {
    return std::current_exception();
  }
}

/// What the engine reads of `p` (mesh, element rest states, rest positions, lumped mass,
/// constraints, material) in the numbering `order`; loads, prescribed displacements and initial
/// velocities stay with the solver and are not copied.
Problem reorderedProblem(const Problem& p, const LocalityOrder& order) {
  Problem q;
  q.name = p.name;
  q.lame = p.lame;
  q.density = p.density;
  q.rayleighMass = p.rayleighMass;
  q.rayleighStiffness = p.rayleighStiffness;
  q.formulation = p.formulation;
  q.rotation = p.rotation;
  const std::size_t nodes = order.nodes.size(), elements = order.elements.size();
  q.mesh.nodes.resize(3 * nodes);
  q.restPositions.resize(static_cast<Eigen::Index>(3 * nodes));
  const bool mass = static_cast<std::size_t>(p.lumpedMass.size()) == 3 * nodes;
  const bool constrained = p.constrained.size() == 3 * nodes;
  if (mass) q.lumpedMass.resize(static_cast<Eigen::Index>(3 * nodes));
  if (constrained) q.constrained.resize(3 * nodes);
  for (std::size_t i = 0; i < nodes; ++i)
    for (std::size_t k = 0; k < 3; ++k) {
      const std::size_t from = 3 * std::size_t{order.nodes[i]} + k, to = 3 * i + k;
      q.mesh.nodes[to] = p.mesh.nodes[from];
      q.restPositions[static_cast<Eigen::Index>(to)] = p.restPositions[static_cast<Eigen::Index>(from)];
      if (mass) q.lumpedMass[static_cast<Eigen::Index>(to)] = p.lumpedMass[static_cast<Eigen::Index>(from)];
      if (constrained) q.constrained[to] = p.constrained[from];
    }
  q.mesh.tets.resize(4 * elements);
  q.elements.reserve(elements);
  for (std::size_t i = 0; i < elements; ++i) {
    const std::uint32_t e = order.elements[i];
    for (std::size_t k = 0; k < 4; ++k) q.mesh.tets[4 * i + k] = order.nodeOf[p.mesh.tets[4 * std::size_t{e} + k]];
    q.elements.push_back(p.elements[e]);
    if (!p.mesh.regions.empty()) q.mesh.regions.push_back(p.mesh.regions[e]);
  }
  return q;
}

bool hasNonzeroMass(const Problem& p) {
  if (static_cast<std::size_t>(p.lumpedMass.size()) != p.dofCount()) return false;
  for (Eigen::Index d = 0; d < p.lumpedMass.size(); ++d)
    if (p.lumpedMass[d] != 0.0) return true;
  return false;
}

}  // namespace

// ---------------------------------------------------------------------------- RAII wrappers

ClBuffer::~ClBuffer() {
  if (mem_) clReleaseMemObject(mem_);
}

void ClBuffer::create(cl_context ctx, std::size_t bytes, const std::string& device) {
  cl_int status = CL_SUCCESS;
  const std::size_t size = std::max<std::size_t>(bytes, 16);
  mem_ = clCreateBuffer(ctx, CL_MEM_READ_WRITE, size, nullptr, &status);
  checkCl(status, "clCreateBuffer", device);
  bytes_ = size;
}

HostStage::~HostStage() {
  if (pending_) clReleaseEvent(pending_);
  if (mem_ && host_) {
    cl_event unmapped = nullptr;
    if (clEnqueueUnmapMemObject(queue_, mem_, host_, 0, nullptr, &unmapped) == CL_SUCCESS && unmapped) {
      clWaitForEvents(1, &unmapped);
      clReleaseEvent(unmapped);
    }
  }
  if (mem_) clReleaseMemObject(mem_);
  if (queue_) clReleaseCommandQueue(queue_);
}

void HostStage::create(cl_context ctx, cl_command_queue queue, std::size_t bytes, const std::string& device) {
  cl_int status = CL_SUCCESS;
  const std::size_t size = std::max<std::size_t>(bytes, 16);
  mem_ = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_ALLOC_HOST_PTR, size, nullptr, &status);
  checkCl(status, "clCreateBuffer (pinned host stage)", device);
  queue_ = queue;
  clRetainCommandQueue(queue_);
  host_ = static_cast<unsigned char*>(
      clEnqueueMapBuffer(queue_, mem_, CL_TRUE, CL_MAP_READ | CL_MAP_WRITE, 0, size, 0, nullptr, nullptr, &status));
  checkCl(status, "clEnqueueMapBuffer (pinned host stage)", device);
  std::memset(host_, 0, size);
}

unsigned char* HostStage::writable() {
  if (pending_) {
    const cl_int status = clWaitForEvents(1, &pending_);
    clReleaseEvent(pending_);
    pending_ = nullptr;
    checkCl(status, "clWaitForEvents (host stage write)", "");
  }
  return host_;
}

void HostStage::write(cl_mem to, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return;
  writable();  // at most one write in flight per stage
  checkCl(clEnqueueWriteBuffer(queue_, to, CL_FALSE, offset, bytes, host_ + offset, 0, nullptr, &pending_),
          "clEnqueueWriteBuffer", device);
}

void HostStage::read(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return;
  writable();
  checkCl(clEnqueueReadBuffer(queue_, from, CL_TRUE, offset, bytes, host_ + offset, 0, nullptr, nullptr),
          "clEnqueueReadBuffer", device);
}

cl_event HostStage::readLater(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return nullptr;
  writable();
  cl_event done = nullptr;
  checkCl(clEnqueueReadBuffer(queue_, from, CL_FALSE, offset, bytes, host_ + offset, 0, nullptr, &done),
          "clEnqueueReadBuffer", device);
  return done;
}

ClKernel::~ClKernel() {
  if (k_) clReleaseKernel(k_);
}

void ClKernel::create(cl_program program, const char* name, const std::string& device) {
  cl_int status = CL_SUCCESS;
  k_ = clCreateKernel(program, name, &status);
  if (status != CL_SUCCESS)
    fail(ErrorCode::DeviceError, "clCreateKernel('", name, "') failed with ", cl::errorString(status),
         " on OpenCL device '", device, "'");
  name_ = name;
}

// ---------------------------------------------------------------------------- set-up

namespace {
std::atomic<unsigned long long> groupPcgLaunches{0};
std::atomic<unsigned long long> teamPcgLaunches{0};
std::atomic<unsigned long long> packPcgLaunches{0};
std::atomic<unsigned long long> packPcgLanes{0};
}  // namespace

unsigned long long groupPcgLaunchCount() { return groupPcgLaunches.load(); }
unsigned long long teamPcgLaunchCount() { return teamPcgLaunches.load(); }
unsigned long long packPcgLaunchCount() { return packPcgLaunches.load(); }
unsigned long long packPcgLaneCount() { return packPcgLanes.load(); }

SegmentEngine::SegmentEngine(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                             std::shared_ptr<cl::Context> ctx, const OpenCLTuning& tuning)
    : ctx_(std::move(ctx)), solver_(solver), precond_(solver.preconditioner) {
  dev_ = ctx_->deviceName();
  cl_command_queue_properties queueProps = 0;
  clGetCommandQueueInfo(ctx_->queue(), CL_QUEUE_PROPERTIES, sizeof(queueProps), &queueProps, nullptr);
  profile_ = (queueProps & CL_QUEUE_PROFILING_ENABLE) != 0;
  if (problems.empty()) fail(ErrorCode::BadInput, "the OpenCL backend needs at least one body");
  for (const Problem* problem : problems) {
    if (problem->formulation != Formulation::Corotational && problem->formulation != Formulation::Linear)
      fail(ErrorCode::BadInput, "body '", problem->name, "': the OpenCL backend implements the co-rotational "
           "and linear formulations only, not '", toString(problem->formulation),
           "'; use the reference backend (\"backend\": \"reference\") for this formulation");
  }
  if (solver.linearSolver != LinearSolverKind::Pcg)
    fail(ErrorCode::BadInput, "body '", problems.front()->name, "': the OpenCL backend solves with PCG only; "
         "\"cholesky\" is available on the reference backend (\"backend\": \"reference\")");
  double_ = solver.precision == Precision::Double;
  mixed_ = solver.precision == Precision::Mixed;
  const bool fp64 = ctx_->info().fp64;
  if (double_ && !fp64)
    fail(ErrorCode::DeviceError, "OpenCL device '", dev_, "' has no double precision (cl_khr_fp64); "
         "set the solver precision to \"float\" or choose another device");
  if (mixed_ && !fp64)
    fail(ErrorCode::DeviceError, "OpenCL device '", dev_, "' has no double precision (cl_khr_fp64), which "
         "the solver precision \"mixed\" needs for its dot products; set the precision to \"float\" "
         "or choose another device");
  realSize_ = double_ ? sizeof(double) : sizeof(float);
  // Mixed: the vectors are float (realSize_), the partial sums and PCG scalars double (sumSize_).
  sumSize_ = double_ || mixed_ ? sizeof(double) : sizeof(float);
  cl_ulong cache = 0;
  clGetDeviceInfo(ctx_->device(), CL_DEVICE_GLOBAL_MEM_CACHE_SIZE, sizeof(cache), &cache, nullptr);
  tuning_ = resolveTuning(tuning, ctx_->info(), static_cast<std::size_t>(cache));
  wg_ = tuning_.workGroupSize;
  vec_ = tuning_.elementsPerItem;
  chunk_ = tuning_.nodesPerItem;
  treeReduce_ = tuning_.workGroupSums != 0;
  energyWithForces_ = !treeReduce_;  // GPUs: element_energy's work-group trees (no per-item reads)
  hostChunk_ = tuning_.hostChunk;
  tileBytes_ = static_cast<std::size_t>(tuning_.tileBytes);
  groupPcg_ = tuning_.groupPcg != 0;
  teamPcg_ = tuning_.teamPcg != 0;
  packs_ = tuning_.packPcg != 0;
  packAlways_ = tuning_.packPcg > 0;

  // -- the device's numbering per body: a Morton order where the mesh's own scatters the kernels'
  // loads (mesh/locality_order.hpp). The buffers below are made from a copy of the problem in that
  // order, released at the end of the constructor; host vectors are permuted at every transfer.
  int reorder = tuning_.localityOrder;
  if (const char* env = std::getenv("COROFEM_OPENCL_REORDER"); env && *env && reorder < 0)
    reorder = std::string(env) != "0" ? 1 : 0;
  std::vector<std::unique_ptr<Problem>> ordered(problems.size());
  std::vector<LocalityOrder> orders(problems.size());
  if (reorder != 0)
    for (std::size_t s = 0; s < problems.size(); ++s) {
      const Problem& p = *problems[s];
      if (p.elements.size() != p.mesh.tetCount() || p.dofCount() != 3 * p.mesh.nodeCount()) continue;  // reported below
      const std::size_t widest = kElemOutComponents;
      if (p.mesh.tetCount() * widest >= (std::size_t(1) << 32) / 2 || 9 * p.mesh.nodeCount() >= (std::size_t(1) << 32) / 2)
        continue;  // over the 32-bit indexing on its own: refused below, not sorted first
      // Each body its own order, as alone (a batched body's bits are its own run's): copies of one
      // mesh that are only moved get the same order and share packs (pcg_pack.cl); copies whose
      // order differs (rotated, in the Morton order) are not packed together.
      std::optional<LocalityOrder> order = reorder == 1 && p.mesh.tetCount() > 0 ? mortonOrder(p.mesh) : localityOrder(p.mesh);
      if (!order) continue;
      orders[s] = std::move(*order);
      ordered[s] = std::make_unique<Problem>(reorderedProblem(p, orders[s]));
    }

  // -- segments: every body padded to whole work-groups of every kernel (corofem_layout.h)
  const std::size_t elemAlign = std::max<std::size_t>(wg_ * vec_, kStrideAlign);
  const std::size_t nodeAlign = wg_ * chunk_;
  for (std::size_t index = 0; index < problems.size(); ++index) {
    const Problem* problem = ordered[index] ? ordered[index].get() : problems[index];
    Segment sg;
    sg.problem = problem;
    if (ordered[index]) {
      sg.hostNode = std::move(orders[index].nodes);
      sg.deviceNode = std::move(orders[index].nodeOf);
      sg.hostElem = std::move(orders[index].elements);
    }
    sg.nodes = problem->mesh.nodeCount();
    sg.elems = problem->mesh.tetCount();
    if (problem->elements.size() != sg.elems || problem->dofCount() != 3 * sg.nodes)
      fail(ErrorCode::Internal, "OpenCL backend: problem '", problem->name, "' has ", problem->elements.size(),
           " element rest states for ", sg.elems, " tets and ", problem->dofCount(), " dofs for ", sg.nodes,
           " nodes");
    if (sg.elems == 0) fail(ErrorCode::BadInput, "body '", problem->name, "' has no elements");
    sg.elemBegin = stride_;
    sg.elemSpan = roundUp(sg.elems, elemAlign);
    stride_ += sg.elemSpan;
    sg.nodeBegin = nodeTotal_;
    sg.nodeSpan = roundUp(std::max<std::size_t>(sg.nodes, 1), nodeAlign);
    nodeTotal_ += sg.nodeSpan;
    // Partial triples: one per node-kernel work-item, or one per work-group with trees.
    sg.partialBegin = treeReduce_ ? sg.nodeBegin / nodeAlign : sg.nodeBegin / chunk_;
    sg.partialCount = treeReduce_ ? sg.nodeSpan / nodeAlign : sg.nodeSpan / chunk_;
    partialTotal_ += sg.partialCount;
    sg.corotational = problem->formulation == Formulation::Corotational;
    sg.rayleighMass = problem->rayleighMass;
    sg.rayleighStiffness = problem->rayleighStiffness;
    sg.constrained.assign(3 * sg.nodes, 0);
    if (problem->constrained.size() == 3 * sg.nodes) sg.constrained = problem->constrained;
    hasMass_ = hasMass_ || hasNonzeroMass(*problem);
    segs_.push_back(std::move(sg));
  }
  const std::size_t widest = kElemOutComponents;
  if (stride_ * widest >= (std::size_t(1) << 32) / 2 || 9 * nodeTotal_ >= (std::size_t(1) << 32) / 2)
    fail(ErrorCode::BadInput, "body '", problems.front()->name, "'", problems.size() > 1 ? " and the others" : "",
         ": ", stride_, " (padded) elements exceed the OpenCL backend's 32-bit element indexing; split the "
         "body or batch fewer bodies per device");

  findPackMeshes();
  build(solver);
  allocate();
  setAllActive();
  refreshBlocks(false);
  finish();
  // Past the uploads only the name is read: the reordered copies go.
  for (std::size_t s = 0; s < segs_.size(); ++s) segs_[s].problem = problems[s];
}

SegmentEngine::~SegmentEngine() {
  clFinish(ctx_->queue());  // pending writes read, and reads (energyItems_) write, this engine's host bytes
  writesDone();
}

std::vector<KernelProfile> SegmentEngine::kernelProfile() {
  if (!profile_) return {};
  checkCl(clFinish(ctx_->queue()), "clFinish", dev_);
  harvestProfile(true);
  std::vector<KernelProfile> out;
  for (const auto& [kernel, entry] : profileTimes_) out.push_back({kernel, entry.launches, entry.busy, entry.idleBefore});
  return out;
}

void SegmentEngine::harvestProfile(bool all) {
  // In order (an in-order queue): the idle time before a kernel is measured from the end of the
  // kernel before it, so transfers and host round trips in between count as idle.
  while (!profileEvents_.empty()) {
    auto& [name, event] = profileEvents_.front();
    if (!all) {
      cl_int status = CL_QUEUED;
      clGetEventInfo(event, CL_EVENT_COMMAND_EXECUTION_STATUS, sizeof(status), &status, nullptr);
      if (status != CL_COMPLETE) break;
    } else {
      clWaitForEvents(1, &event);
    }
    cl_ulong t0 = 0, t1 = 0;
    clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_START, sizeof(t0), &t0, nullptr);
    clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_END, sizeof(t1), &t1, nullptr);
    ProfileEntry& entry = profileTimes_[name];
    entry.launches += 1;
    entry.busy += static_cast<double>(t1 - t0) * 1e-9;
    if (profileLastEnd_ != 0 && t0 > profileLastEnd_) entry.idleBefore += static_cast<double>(t0 - profileLastEnd_) * 1e-9;
    profileLastEnd_ = t1;
    clReleaseEvent(event);
    profileEvents_.pop_front();
  }
}

void SegmentEngine::build(const SolverDesc& solver) {
  // -- program: only the features these problems use
  options_ = "-cl-std=CL1.2 -DCOROFEM_WG=" + std::to_string(wg_) + " -DCOROFEM_VEC=" + std::to_string(vec_) +
             " -DCOROFEM_CHUNK=" + std::to_string(chunk_) + (treeReduce_ ? " -DCOROFEM_TREE_REDUCE" : "");
  if (double_) options_ += " -DCOROFEM_DOUBLE";
  if (mixed_) options_ += " -DCOROFEM_MIXED";
  // Denormals flushed to zero (CPU devices by default: PoCL then runs the kernels with the FTZ and
  // DAZ bits of MXCSR set). Nothing physical lives below float's 1.2e-38.
  if (tuning_.flushDenormals) options_ += " -cl-denorms-are-zero";
  switch (solver.rotation) {
    case RotationMethod::Polar: options_ += " -DCOROFEM_ROT_POLAR"; break;
    case RotationMethod::Svd: options_ += " -DCOROFEM_ROT_SVD"; break;
    case RotationMethod::Quaternion: options_ += " -DCOROFEM_ROT_QUAT"; break;
    case RotationMethod::Qr: options_ += " -DCOROFEM_ROT_QR"; break;
  }
  if (solver.rotation == RotationMethod::Quaternion)
    options_ += " -DCOROFEM_QUAT_ITERS=" + std::to_string(tuning_.quaternionIterations);
  if (precond_ == PreconditionerKind::BlockDiagonal) options_ += " -DCOROFEM_PRECOND_BLOCK";
  else if (precond_ == PreconditionerKind::Diagonal) options_ += " -DCOROFEM_PRECOND_DIAG";
  static const std::string source = cl::corofemProgramSource();
  build_ = cl::buildProgram(*ctx_, "corofem", source, options_);
  kRotations_.create(build_.program, "compute_rotations", dev_);
  kForces_.create(build_.program, "element_forces", dev_);
  kEnergy_.create(build_.program, "element_energy", dev_);
  kProduct_.create(build_.program, "element_product", dev_);
  kGatherSum_.create(build_.program, "gather_sum", dev_);
  kGatherProduct_.create(build_.program, "gather_product", dev_);
  kBlocks_.create(build_.program, "node_stiffness_blocks", dev_);
  kCornerGradients_.create(build_.program, "corner_gradients", dev_);
  kPcgInit_.create(build_.program, "pcg_init", dev_);
  kPcgUpdate_.create(build_.program, "pcg_update", dev_);
  kReduceFinish_.create(build_.program, "reduce_finish", dev_);
  if (groupPcg_) kPcgIterateGroup_.create(build_.program, "pcg_iterate_group", dev_);
  if (teamPcg_) kPcgIterateTeam_.create(build_.program, "pcg_iterate_team", dev_);
  if (packs_) {
    kPcgIteratePack_.create(build_.program, "pcg_iterate_pack", dev_);
    kPackIn_.create(build_.program, "pack_in", dev_);
    kPackOut_.create(build_.program, "pack_out", dev_);
  }
}

void SegmentEngine::allocate() {
  const std::size_t S = stride_, K = segs_.size();
  cl_context c = ctx_->context();

  // -- segment tables
  segInfo_.assign(kSegInfoCount * K, 0);
  segCoef_.assign(kSegCoefCount * K, 0.0);
  std::vector<cl_uint> elemSeg(S / (wg_ * vec_)), nodeSeg(nodeTotal_ / wg_);
  for (std::size_t s = 0; s < K; ++s) {
    const Segment& sg = segs_[s];
    cl_uint* info = &segInfo_[kSegInfoCount * s];
    info[kSegActive] = 1;
    info[kSegElemEnd] = static_cast<cl_uint>(sg.elemBegin + sg.elems);
    info[kSegNodeEnd] = static_cast<cl_uint>(sg.nodeBegin + sg.nodes);
    info[kSegPartialBegin] = static_cast<cl_uint>(sg.partialBegin);
    info[kSegPartialCount] = static_cast<cl_uint>(sg.partialCount);
    info[kSegElemBegin] = static_cast<cl_uint>(sg.elemBegin);
    info[kSegElemSpan] = static_cast<cl_uint>(sg.elemSpan);
    info[kSegNodeBegin] = static_cast<cl_uint>(sg.nodeBegin);
    segCoef_[kSegCoefCount * s + kCoefLambda] = sg.problem->lame.lambda;
    segCoef_[kSegCoefCount * s + kCoefMu] = sg.problem->lame.mu;
    for (std::size_t g = sg.elemBegin / (wg_ * vec_); g < (sg.elemBegin + sg.elemSpan) / (wg_ * vec_); ++g)
      elemSeg[g] = static_cast<cl_uint>(s);
    for (std::size_t g = sg.nodeBegin / wg_; g < (sg.nodeBegin + sg.nodeSpan) / wg_; ++g)
      nodeSeg[g] = static_cast<cl_uint>(s);
  }
  active_.assign(K, 1);
  activeLo_ = 0;
  activeHi_ = K;
  segInfoBuf_.create(c, segInfo_.size() * sizeof(cl_uint), dev_);
  uploadRaw(segInfoBuf_, segInfo_);
  createReal(segCoefBuf_, segCoef_.size());
  coefDirty_ = true;
  flushCoefficients();
  elemSeg_.create(c, elemSeg.size() * sizeof(cl_uint), dev_);
  uploadRaw(elemSeg_, elemSeg);
  nodeSeg_.create(c, nodeSeg.size() * sizeof(cl_uint), dev_);
  uploadRaw(nodeSeg_, nodeSeg);

  // -- element data, structure of arrays (kernels/shared/corofem_layout.h); padding elements:
  // zero gradients and volume, corners at the segment's first node
  {
    std::vector<cl_uint> nodes(kElemNodeComponents * S, 0);
    for (const Segment& sg : segs_)
      for (std::size_t e = 0; e < sg.elemSpan; ++e)
        for (std::size_t k = 0; k < 4; ++k)
          nodes[k * S + sg.elemBegin + e] =
              static_cast<cl_uint>(sg.nodeBegin + (e < sg.elems ? sg.problem->mesh.tets[4 * e + k] : 0));
    elemNodes_.create(c, nodes.size() * sizeof(cl_uint), dev_);
    uploadRaw(elemNodes_, nodes);
  }
  bool anyCorotational = false;
  for (const Segment& sg : segs_) anyCorotational = anyCorotational || sg.corotational;
  // The Quaternion method's state only where something rotates (linear bodies never do).
  const bool quaternion = solver_.rotation == RotationMethod::Quaternion && anyCorotational;
  rAlways_ = quaternion;
  {
    std::vector<double> geom(kGeomComponents * S, 0.0), quat(quaternion ? kQuatComponents * S : 0, 0.0);
    for (const Segment& sg : segs_)
      for (std::size_t e = 0; e < sg.elems; ++e) {
        const ElementRest& rest = sg.problem->elements[e];
        const std::size_t g = sg.elemBegin + e;
        for (int i = 1; i < 4; ++i)
          for (int k = 0; k < 3; ++k) geom[(3 * (i - 1) + k) * S + g] = rest.grad(i, k);
        geom[kGeomVolume * S + g] = rest.volume;
        if (quaternion) quat[3 * S + g] = 1.0;
      }
    createReal(geom_, geom.size());
    upload(geom_, geom.data(), 0, geom.size());
    // R itself only where every pass writes it (rAlways_: the Quaternion method cannot run a pass
    // again for readRotations); otherwise the first readRotations makes it (ensureRotations).
    if (rAlways_) ensureRotations();
    // At rest (and always for the linear formulation) R = I, so a_i = grad N_i. Without a
    // co-rotational body nothing ever changes them: the kernels read the gradients of geom_, whose
    // first 9 components have the layout of a_i (rotatedGradients()), and no copy is made.
    if (anyCorotational) {
      createReal(rotGrad_, kRotGradComponents * S);
      upload(rotGrad_, geom.data(), 0, kRotGradComponents * S);
    }
    // The warm-start quaternions exist only for the Quaternion method (the kernel gets NULL otherwise).
    if (quaternion) {
      createReal(quat_, quat.size());
      upload(quat_, quat.data(), 0, quat.size());
    }
  }
  createReal(elemOut_, kElemOutComponents * S);

  // -- node gather lists (CSR over all nodes, fixed order: by segment, element, then corner)
  {
    std::size_t entryCount = 0;
    for (const Segment& sg : segs_) entryCount += 4 * sg.elems;
    std::vector<cl_uint> start(nodeTotal_ + 1, 0), entries(entryCount);
    for (const Segment& sg : segs_)
      for (std::size_t e = 0; e < sg.elems; ++e)
        for (int k = 0; k < 4; ++k) ++start[sg.nodeBegin + sg.problem->mesh.tets[4 * e + k] + 1];
    for (std::size_t n = 0; n < nodeTotal_; ++n) start[n + 1] += start[n];
    std::vector<cl_uint> fill(start.begin(), start.end() - 1);
    for (const Segment& sg : segs_)
      for (std::size_t e = 0; e < sg.elems; ++e) {
        const std::size_t g = sg.elemBegin + e;
        for (int k = 0; k < 4; ++k)
          entries[fill[sg.nodeBegin + sg.problem->mesh.tets[4 * e + k]]++] =
              static_cast<cl_uint>(((g / vec_) * 12 + 3 * k) * vec_ + g % vec_);
      }
    nodeStart_.create(c, start.size() * sizeof(cl_uint), dev_);
    uploadRaw(nodeStart_, start);
    nodeEntries_.create(c, entries.size() * sizeof(cl_uint), dev_);
    uploadRaw(nodeEntries_, entries);
  }

  // -- node data (padding nodes: zero mass, constrained)
  const std::size_t dofTotal = 3 * nodeTotal_;
  for (HostStage* stage : {&posStage_, &bStage_, &xStage_, &readStage_})
    stage->create(c, ctx_->queue(), dofTotal * realSize_, dev_);
  xKnown_.assign(K, 0);
  warmLast_.assign(K, 0);
  energy_.assign(K, 0.0);
  energyKnown_.assign(K, 0);
  axReady_.assign(K, 0);
  axCoef_.assign(kSegCoefCount * K, 0.0);
  rStale_.assign(K, 0);  // R = I (ensureRotations uploads it) until a rotation pass runs
  blocksStale_.assign(K, 0);  // the constructor forms the rest state's blocks
  std::vector<double> mass(hasMass_ ? dofTotal : 0, 0.0), freeMask(dofTotal, 0.0);
  for (const Segment& sg : segs_) {
    const Eigen::VectorXd& rest = sg.problem->restPositions;
    putReals(posStage_.writable(), sg.dofBegin(), sg.dofs(), [&](std::size_t d) { return rest[static_cast<Eigen::Index>(d)]; });
    for (std::size_t d = 0; d < sg.dofs(); ++d) freeMask[sg.dofBegin() + d] = sg.constrained[d] ? 0.0 : 1.0;
    if (hasMass_ && static_cast<std::size_t>(sg.problem->lumpedMass.size()) == sg.dofs())
      for (std::size_t d = 0; d < sg.dofs(); ++d)
        mass[sg.dofBegin() + d] = sg.problem->lumpedMass[static_cast<Eigen::Index>(d)];
  }
  createReal(pos_, dofTotal);
  posStage_.write(pos_.get(), 0, dofTotal * realSize_, dev_);
  // Static problems (no body with a nonzero lumped mass) get no mass buffer: the kernels see NULL.
  if (hasMass_) {
    createReal(mass_, dofTotal);
    upload(mass_, mass.data(), 0, dofTotal);
  }
  createReal(free_, dofTotal);
  upload(free_, freeMask.data(), 0, dofTotal);
  if (precond_ != PreconditionerKind::None) {
    // The block preconditioner reads 6 reals per node, the diagonal one 3 (precond.cl).
    createReal(blocks_, (precond_ == PreconditionerKind::BlockDiagonal ? kNodeBlockComponents : 3) * nodeTotal_);
    createReal(minv_, (precond_ == PreconditionerKind::BlockDiagonal ? 9 : 3) * nodeTotal_);
  }
  for (ClBuffer* v : {&x_, &b_, &r_, &z_, &p_, &q_, &s_}) createReal(*v, dofTotal);
  // Partials: the PCG node kernels write sum_real triples; element_energy writes one real per
  // element work-group into the first buffer (at most sumSize_ bytes each), element_forces one per
  // element work-item (energyWithForces_).
  partials_.create(c, std::max(kPartialComponents * std::max(S / (wg_ * vec_), partialTotal_) * sumSize_,
                               energyWithForces_ ? S / vec_ * realSize_ : std::size_t(0)),
                   dev_);
  partialsW_.create(c, kPartialComponents * partialTotal_ * sumSize_, dev_);
  scalars_.create(c, kScalarCount * K * sumSize_, dev_);
  if (groupPcg_) groupOrder_.create(c, (K + 1) * sizeof(cl_uint), dev_);
  if (teamPcg_) {
    const std::vector<cl_uint> state = teamStateAtRest();
    teamState_.create(c, state.size() * sizeof(cl_uint), dev_);
    uploadRaw(teamState_, state);
  }
  lastIterations_.assign(K, 0);
  if (packs_) {
    // The pack meshes' corners (the pack's own node numbers). pcg_iterate_pack adds the element
    // products to the node sums element by element: the order of the gather lists above (by
    // element, then corner), so its sums are the gather's.
    std::vector<cl_uint> corners;
    for (PackMesh& m : packMeshes_) {
      const Problem& p = *segs_[m.bodies.front()].problem;
      m.corners = corners.size();
      for (std::size_t e = 0; e < 4 * p.mesh.tetCount(); ++e) corners.push_back(static_cast<cl_uint>(p.mesh.tets[e]));
    }
    std::size_t elemRows = 0, partialRows = 0;
    for (const PackSlotPlace& slot : packSlots_) {
      const PackMesh& m = packMeshes_[slot.mesh];
      elemRows = std::max(elemRows, slot.elemBase + roundUp(segs_[m.bodies.front()].elems, kPackLanes));
      partialRows = std::max(partialRows, slot.partialBase + segs_[m.bodies.front()].partialCount);
    }
    const std::size_t L = kPackLanes, inverse = precond_ == PreconditionerKind::BlockDiagonal ? 9 : 3;
    packInfo_.create(c, (kPackInfoCount * packSlots_.size() + 1) * sizeof(cl_uint), dev_);  // + the claim word
    packCorners_.create(c, corners.size() * sizeof(cl_uint), dev_);
    uploadRaw(packCorners_, corners);
    createReal(packElem_, elemRows * kPackElemRows * L);
    // The node sums: 3 rows per node for the products, 6 for the blocks of the block preconditioner
    // (pcg_pack.cl's PACK_SUMS).
    createReal(packSums_, (precond_ == PreconditionerKind::BlockDiagonal ? 6 : 3) * packNodeRows_ * L);
    createReal(packVec_, kPackVectors * 3 * packNodeRows_ * L);
    createReal(packFree_, 3 * packNodeRows_ * L);
    if (hasMass_) createReal(packMass_, 3 * packNodeRows_ * L);
    if (precond_ != PreconditionerKind::None) createReal(packMinv_, inverse * packNodeRows_ * L);
    packPartials_.create(c, kPartialComponents * partialRows * L * sumSize_, dev_);
  }
}

void SegmentEngine::findPackMeshes() {
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
      if (m.size() >= tuning_.packPcgMinLanes && padded) packMeshes_.push_back(PackMesh{std::move(m), 0, 0, 0});
  }
  std::sort(packMeshes_.begin(), packMeshes_.end(),
            [](const PackMesh& a, const PackMesh& b) { return a.bodies.front() < b.bodies.front(); });
  std::size_t elemRows = 0, partialRows = 0;
  for (std::size_t i = 0; i < packMeshes_.size(); ++i) {
    PackMesh& m = packMeshes_[i];
    const Segment& first = segs_[m.bodies.front()];
    m.firstSlot = packSlots_.size();
    m.slots = (m.bodies.size() + kPackLanes - 1) / kPackLanes;
    for (std::size_t k = 0; k < m.slots; ++k) {  // rows padded to 8 elements and nodes (pack_in's blocks)
      packSlots_.push_back({i, elemRows, packNodeRows_, partialRows});
      elemRows += roundUp(first.elems, kPackLanes);
      packNodeRows_ += roundUp(first.nodes, kPackLanes);
      partialRows += first.partialCount;
    }
  }
  if (packSlots_.empty()) packs_ = false;
}

std::vector<DeviceBuffer> SegmentEngine::buffers() const {
  const std::pair<const char*, const ClBuffer*> all[] = {
      {"element_segments", &elemSeg_},      {"node_segments", &nodeSeg_},
      {"segment_info", &segInfoBuf_},       {"segment_coefficients", &segCoefBuf_},
      {"element_nodes", &elemNodes_},       {"element_geometry", &geom_},
      {"rotations", &rot_},                 {"rotated_gradients", &rotGrad_},
      {"quaternions", &quat_},
      {"element_output", &elemOut_},        {"gather_starts", &nodeStart_},
      {"gather_entries", &nodeEntries_},    {"positions", &pos_},
      {"lumped_mass", &mass_},              {"free_mask", &free_},
      {"node_blocks", &blocks_},            {"preconditioner_inverse", &minv_},
      {"pcg_x", &x_},                       {"pcg_b", &b_},
      {"pcg_r", &r_},                       {"pcg_u", &z_},
      {"pcg_p", &p_},                       {"pcg_w", &q_},
      {"pcg_s", &s_},                       {"partial_sums", &partials_},
      {"partial_sums_w", &partialsW_},      {"pcg_scalars", &scalars_},
      {"pcg_team_counters", &teamState_},
      {"pcg_group_order", &groupOrder_},
      {"pack_table", &packInfo_},           {"pack_corners", &packCorners_},
      {"pack_element_rows", &packElem_},    {"pack_node_sums", &packSums_},
      {"pack_pcg_vectors", &packVec_},      {"pack_free_mask", &packFree_},
      {"pack_lumped_mass", &packMass_},     {"pack_preconditioner_inverse", &packMinv_},
      {"pack_partial_sums", &packPartials_}};
  std::vector<DeviceBuffer> out;
  for (const auto& [name, buffer] : all)
    if (buffer->get()) out.push_back({name, buffer->bytes()});
  return out;
}

std::size_t SegmentEngine::allocatedBytes() const {
  std::size_t sum = 0;
  for (const DeviceBuffer& b : buffers()) sum += b.bytes;
  return sum;
}

// ---------------------------------------------------------------------------- launching, tables

void ClKernel::setArg(cl_uint i, const void* value, std::size_t bytes, const std::string& device) const {
  if (args_.size() <= i) args_.resize(i + 1);
  std::vector<unsigned char>& last = args_[i];
  if (last.size() == bytes && std::memcmp(last.data(), value, bytes) == 0) return;
  last.clear();  // unknown until set: a failed call below leaves it to be set again
  checkCl(clSetKernelArg(k_, i, bytes, value), "clSetKernelArg", device);
  last.assign(static_cast<const unsigned char*>(value), static_cast<const unsigned char*>(value) + bytes);
}

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, cl_mem m) {
  // m may be NULL (an absent optional buffer): the kernel sees a NULL pointer (OpenCL 1.2, 5.7.2).
  k.setArg(i, &m, sizeof(cl_mem), dev_);
}

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, cl_uint v) { k.setArg(i, &v, sizeof(cl_uint), dev_); }

void SegmentEngine::setArg(const ClKernel& k, cl_uint i, SumReal v) {
  if (sumSize_ == sizeof(double)) {
    k.setArg(i, &v.value, sizeof(double), dev_);
  } else {
    const float f = static_cast<float>(v.value);
    k.setArg(i, &f, sizeof(float), dev_);
  }
}

std::pair<std::size_t, std::size_t> SegmentEngine::spanItems(Span span, std::size_t lo, std::size_t hi) const {
  const Segment& a = segs_[lo];
  const Segment& b = segs_[hi - 1];
  const std::size_t nodes = b.nodeBegin + b.nodeSpan - a.nodeBegin;
  switch (span) {
    case Span::Elements: return {a.elemBegin / vec_, (b.elemBegin + b.elemSpan - a.elemBegin) / vec_};
    case Span::Nodes: return {a.nodeBegin, nodes};
    case Span::NodeChunks: return {a.nodeBegin / chunk_, nodes / chunk_};
    case Span::Segments: break;
    case Span::Teams: return {lo * wg_ * teamSize_, (hi - lo) * wg_ * teamSize_};
  }
  return {lo * wg_, (hi - lo) * wg_};
}

void SegmentEngine::enqueue(const ClKernel& kernel, Span span) {
  // Only the work-groups of the span of active segments are launched (a global offset; the
  // kernels derive their work-group from the global id); inactive segments inside the span
  // return at once.
  const auto [offset, global] = spanItems(span, activeLo_, activeHi_);
  enqueueRange(kernel, offset, global, wg_);
}

void SegmentEngine::enqueueRange(const ClKernel& kernel, std::size_t offset, std::size_t global, std::size_t local) {
  cl_event event = nullptr;
  const cl_int status = clEnqueueNDRangeKernel(ctx_->queue(), kernel.get(), 1, &offset, &global, &local, 0,
                                               nullptr, profile_ ? &event : nullptr);
  if (event) {
    profileEvents_.emplace_back(kernel.name(), event);
    if (profileEvents_.size() > 4096) harvestProfile(false);
  }
  if (status != CL_SUCCESS)
    fail(ErrorCode::DeviceError, "clEnqueueNDRangeKernel('", kernel.name(), "', ", global,
         " work-items) failed with ", cl::errorString(status), " on OpenCL device '", dev_, "'");
}

void SegmentEngine::setActive(const std::vector<char>& active) {
  bool changed = false;
  activeLo_ = segs_.size();
  activeHi_ = 0;
  for (std::size_t s = 0; s < segs_.size(); ++s) {
    const char flag = active[s] == 0 ? 0 : active[s] == char(kSegRunningPacked) ? char(kSegRunningPacked) : char(kSegRunning);
    if (flag != 0) {
      activeLo_ = std::min(activeLo_, s);
      activeHi_ = s + 1;
    }
    if (flag != active_[s]) {
      changed = true;
      active_[s] = flag;
      segInfo_[kSegInfoCount * s + kSegActive] = static_cast<cl_uint>(flag);
    }
  }
  if (changed || segInfoStale_) uploadRaw(segInfoBuf_, segInfo_);
  segInfoStale_ = false;
}

void SegmentEngine::setCoefficients(std::size_t s, const SystemCoeffs& c) {
  // A = m M + c (alpha M + beta K^R) + k K^R = (m + c alpha) M + (k + c beta) K^R.
  const Segment& sg = segs_[s];
  const double massCoef = c.mass + c.damping * sg.rayleighMass;
  const double stiffCoef = c.stiffness + c.damping * sg.rayleighStiffness;
  double* coef = &segCoef_[kSegCoefCount * s];
  const double next[4] = {stiffCoef * coef[kCoefLambda], stiffCoef * coef[kCoefMu], massCoef, stiffCoef};
  double* slot[4] = {&coef[kCoefProdLambda], &coef[kCoefProdMu], &coef[kCoefMass], &coef[kCoefStiff]};
  for (int i = 0; i < 4; ++i)
    if (*slot[i] != next[i]) {
      *slot[i] = next[i];
      coefDirty_ = true;
    }
}

void SegmentEngine::flushCoefficients() {
  if (!coefDirty_) return;
  upload(segCoefBuf_, segCoef_.data(), 0, segCoef_.size());
  coefDirty_ = false;
}

// ---------------------------------------------------------------------------- transfers

void SegmentEngine::enqueueWrite(const ClBuffer& buf, std::size_t offset, std::vector<unsigned char>&& bytes) {
  // Non-blocking: the host goes on enqueuing while the copy travels. The bytes stay alive (here)
  // until the write's event says it is done; a blocking read (download) drains them all.
  while (!writes_.empty()) {
    cl_int status = CL_QUEUED;
    clGetEventInfo(writes_.front().event, CL_EVENT_COMMAND_EXECUTION_STATUS, sizeof(status), &status, nullptr);
    if (status != CL_COMPLETE && writes_.size() < kMaxPendingWrites) break;
    const cl_int wait = status == CL_COMPLETE ? CL_SUCCESS : clWaitForEvents(1, &writes_.front().event);
    clReleaseEvent(writes_.front().event);
    writes_.pop_front();
    checkCl(wait, "clWaitForEvents (write)", dev_);
  }
  PendingWrite w{std::move(bytes), nullptr};
  checkCl(clEnqueueWriteBuffer(ctx_->queue(), buf.get(), CL_FALSE, offset, w.bytes.size(), w.bytes.data(), 0, nullptr,
                               &w.event),
          "clEnqueueWriteBuffer", dev_);
  writes_.push_back(std::move(w));
}

void SegmentEngine::writesDone() {
  for (PendingWrite& w : writes_) clReleaseEvent(w.event);  // complete: a blocking command followed them
  writes_.clear();
}

void SegmentEngine::upload(const ClBuffer& buf, const double* src, std::size_t begin, std::size_t count) {
  if (count == 0) return;
  std::vector<unsigned char> bytes(count * realSize_);
  if (double_) {
    std::memcpy(bytes.data(), src + begin, count * sizeof(double));
  } else {
    float* out = reinterpret_cast<float*>(bytes.data());
    for (std::size_t i = 0; i < count; ++i) out[i] = static_cast<float>(src[begin + i]);
  }
  enqueueWrite(buf, begin * realSize_, std::move(bytes));
}

void SegmentEngine::download(const ClBuffer& buf, double* dst, std::size_t begin, std::size_t count) {
  if (count == 0) return;
  staging_.resize(count * realSize_);
  checkCl(clEnqueueReadBuffer(ctx_->queue(), buf.get(), CL_TRUE, begin * realSize_, count * realSize_,
                              staging_.data(), 0, nullptr, nullptr),
          "clEnqueueReadBuffer", dev_);
  writesDone();
  if (double_) {
    std::memcpy(dst + begin, staging_.data(), count * sizeof(double));
  } else {
    const float* in = reinterpret_cast<const float*>(staging_.data());
    for (std::size_t i = 0; i < count; ++i) dst[begin + i] = in[i];
  }
}

void SegmentEngine::downloadSums(const ClBuffer& buf, double* dst, std::size_t count) {
  if (!mixed_) {
    download(buf, dst, 0, count);
    return;
  }
  checkCl(clEnqueueReadBuffer(ctx_->queue(), buf.get(), CL_TRUE, 0, count * sizeof(double), dst, 0, nullptr,
                              nullptr),
          "clEnqueueReadBuffer", dev_);
  writesDone();
}

void SegmentEngine::getReals(const unsigned char* base, const Segment& sg, Eigen::VectorXd& out) const {
  out.resize(static_cast<Eigen::Index>(sg.dofs()));
  parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t, std::size_t lo, std::size_t hi) {
    withReals(base, sg.dofBegin(), [&](const auto* in) {
      if (sg.hostNode.empty())
        for (std::size_t d = lo; d < hi; ++d) out[static_cast<Eigen::Index>(d)] = static_cast<double>(in[d]);
      else
        for (std::size_t d = lo; d < hi; ++d) out[static_cast<Eigen::Index>(sg.hostDof(d))] = static_cast<double>(in[d]);
    });
  });
}

template <class T>
void SegmentEngine::uploadRaw(const ClBuffer& buf, const std::vector<T>& v) {
  const auto* data = reinterpret_cast<const unsigned char*>(v.data());
  enqueueWrite(buf, 0, std::vector<unsigned char>(data, data + v.size() * sizeof(T)));
}

std::pair<std::size_t, std::size_t> SegmentEngine::dofRange(const std::vector<BatchRequest*>& requests) const {
  std::size_t lo = 3 * nodeTotal_, hi = 0;
  for (const BatchRequest* r : requests) {
    const Segment& sg = segs_[r->body];
    lo = std::min(lo, sg.dofBegin());
    hi = std::max(hi, sg.dofBegin() + sg.dofs());
  }
  return {lo, std::max(lo, hi)};
}

void SegmentEngine::finish() {
  checkCl(clFinish(ctx_->queue()), "clFinish", dev_);
  writesDone();
}

// ---------------------------------------------------------------------------- operations

std::vector<BatchRequest*> SegmentEngine::checked(const std::vector<BatchRequest*>& requests,
                                                  const char* what) const {
  std::vector<BatchRequest*> ok;
  for (BatchRequest* r : requests) {
    if (r->body >= segs_.size()) {
      r->error = errorOf(ErrorCode::Internal, "OpenCL batch: request for body ", r->body, " of ", segs_.size());
      continue;
    }
    const std::size_t dofs = segs_[r->body].dofs();
    const bool needsIn = r->op == BatchOp::SetPositions || r->op == BatchOp::Apply || r->op == BatchOp::Solve;
    const bool needsOut = r->op != BatchOp::SetPositions && r->op != BatchOp::ElasticEnergy;
    if (needsIn && (!r->in || static_cast<std::size_t>(r->in->size()) != dofs)) {
      r->error = errorOf(ErrorCode::Internal, "OpenCL backend: body '", segs_[r->body].problem->name, "': ", what,
                         " has ", r->in ? r->in->size() : 0, " entries, expected 3N = ", dofs);
      continue;
    }
    if (needsOut && !r->out) {
      r->error = errorOf(ErrorCode::Internal, "OpenCL backend: body '", segs_[r->body].problem->name, "': ", what,
                         " has no output vector");
      continue;
    }
    ok.push_back(r);
  }
  return ok;
}

void SegmentEngine::run(BatchOp op, const std::vector<BatchRequest*>& requests) {
  static const char* const what[] = {"the positions", "the forces", "the vector p of apply",
                                     "the right-hand side b", "the energy"};
  std::vector<BatchRequest*> ok = checked(requests, what[static_cast<int>(op)]);
  std::sort(ok.begin(), ok.end(), [](const BatchRequest* a, const BatchRequest* b) { return a->body < b->body; });
  // Tiles of consecutive bodies whose working set fits the device cache (CPUs): a whole PCG solve
  // of a tile then runs on cached data, and an element pass's output is still cached for its
  // gather. One tile on GPUs (tileBytes_ = 0).
  std::vector<BatchRequest*> tile;
  std::size_t bytes = 0;
  auto runTile = [&]() {
    switch (op) {
      case BatchOp::SetPositions: setPositions(tile); break;
      case BatchOp::InternalForces: internalForces(tile); break;
      case BatchOp::Apply: apply(tile); break;
      case BatchOp::Solve: solve(tile); break;
      case BatchOp::ElasticEnergy: elasticEnergy(tile); break;
    }
    tile.clear();
    bytes = 0;
  };
  // A solve round whose iterations run one work-group per body (groupRound) needs no tiles: each
  // group's body stays in its core's cache, and one launch for all balances the cores best.
  const std::size_t tileBytes = op == BatchOp::Solve && groupRound(ok) ? 0 : tileBytes_;
  for (BatchRequest* r : ok) {
    const std::size_t w = workingSet(segs_[r->body]);
    if (!tile.empty() && tileBytes > 0 && bytes + w > tileBytes) runTile();
    tile.push_back(r);
    bytes += w;
  }
  if (!tile.empty()) runTile();
}

std::size_t SegmentEngine::groupTeam(const std::vector<BatchRequest*>& requests) const {
  if (!groupPcg_ || requests.empty()) return 0;
  // The claims' 32-bit epochs advance by 4 per iteration of a launch: caps beyond kTeamMaxIterations
  // (never needed: PCG converges in at most the system's size) take the other paths.
  const bool teams = teamPcg_ && solver_.maxIterations <= kTeamMaxIterations;
  if (teams && tuning_.teamPcgSize > 0) return tuning_.teamPcgSize;
  std::size_t largest = 0, total = 0;
  for (const BatchRequest* r : requests) {
    largest = std::max(largest, segs_[r->body].elems);
    total += segs_[r->body].elems;
  }
  const std::size_t cores = std::max<std::size_t>(1, ctx_->info().computeUnits);
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

std::vector<cl_uint> SegmentEngine::packRound(const std::vector<BatchRequest*>& requests, std::vector<char>& packed) const {
  std::vector<char> in(segs_.size(), 0);
  for (const BatchRequest* r : requests) in[r->body] = 1;
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
    const std::size_t cores = std::max<std::size_t>(1, ctx_->info().computeUnits);
    const std::size_t slotsNeeded = bodies.size() / kPackLanes + (bodies.size() % kPackLanes >= tuning_.packPcgMinLanes ? 1 : 0);
    if (!packAlways_ && static_cast<double>((bodies.size() + cores - 1) / cores) <=
                            kPackCost * static_cast<double>((slotsNeeded + cores - 1) / cores))
      continue;
    // Bodies that took as many iterations last time share a pack: a pack iterates until its
    // last lane stops.
    std::stable_sort(bodies.begin(), bodies.end(),
                     [&](std::size_t a, std::size_t b) { return lastIterations_[a] > lastIterations_[b]; });
    for (std::size_t k = 0; k < m.slots && k * kPackLanes < bodies.size(); ++k) {
      const std::size_t n = std::min<std::size_t>(kPackLanes, bodies.size() - k * kPackLanes);
      if (n < tuning_.packPcgMinLanes) break;
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
    const Segment& sg = segs_[m.bodies.front()];
    cl_uint row[kPackInfoCount] = {};
    row[kPackElems] = static_cast<cl_uint>(sg.elems);
    row[kPackNodes] = static_cast<cl_uint>(sg.nodes);
    row[kPackPartialCount] = static_cast<cl_uint>(sg.partialCount);
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

std::vector<cl_uint> SegmentEngine::teamStateAtRest() const {
  // Per segment kTeamStride words (counts at zero, kTeamFlags: where its claim words start), then
  // each segment's claim words, one per chunk of its larger phase (pcg_group.cl), at epoch 0.
  std::vector<cl_uint> state(kTeamStride * segs_.size(), 0u);
  for (std::size_t s = 0; s < segs_.size(); ++s) {
    const Segment& sg = segs_[s];
    const std::size_t chunks = std::max<std::size_t>(
        {1, (sg.partialCount + wg_ - 1) / wg_, (sg.elemSpan / vec_ + wg_ - 1) / wg_});
    state[kTeamStride * s + kTeamFlags] = static_cast<cl_uint>(state.size());
    state.resize(state.size() + chunks, 0u);
  }
  return state;
}

std::size_t SegmentEngine::workingSet(const Segment& sg) const {
  // Per element: 4 corners, 8 gather entries' worth of CSR, geometry, a_i and the output 12-vector;
  // per node: CSR start, 9 node vectors (x b r u p w s, free, mass) of 3, blocks and inverse.
  return sg.elemSpan * (8 * sizeof(cl_uint) + (kGeomComponents + kRotGradComponents + kElemOutComponents) * realSize_) +
         sg.nodeSpan * (sizeof(cl_uint) + (9 * 3 + kNodeBlockComponents + 9) * realSize_);
}

void SegmentEngine::refreshBlocks(bool cornersWritten) {
  if (precond_ == PreconditionerKind::None) return;
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
  launchRotations(corotational, precond_ != PreconditionerKind::None, rAlways_);
}

void SegmentEngine::setPositions(const std::vector<BatchRequest*>& requests) {
  if (requests.empty()) return;
  // Every kernel uses positions only through differences (F = sum (x_i - x_0) grad N_i^T, forces
  // and energy from F), so the device gets them relative to each body's centroid, subtracted in
  // double: a float body 1e4 m from the origin keeps the resolution of one near it.
  std::vector<char> rotate(segs_.size(), 0);
  unsigned char* stage = posStage_.writable();
  for (const BatchRequest* r : requests) {
    Segment& sg = segs_[r->body];
    const Eigen::VectorXd& x = *r->in;
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
    rotate[r->body] = sg.corotational;
    energyKnown_[r->body] = 0;  // the energy of the new positions is not known yet
  }
  // One write of the packed range; the segments in between get their own unchanged positions.
  const auto [lo, hi] = dofRange(requests);
  posStage_.write(pos_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  // The blocks rotate with R (linear bodies: constant, never stale); formed by the solve that needs
  // them (refreshStaleBlocks), not here: the corner gradients would be overwritten by the forces.
  launchRotations(rotate, false, rAlways_);
  if (precond_ != PreconditionerKind::None)
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

void SegmentEngine::internalForces(const std::vector<BatchRequest*>& requests) {
  if (requests.empty()) return;
  std::vector<char> active(segs_.size(), 0);
  for (const BatchRequest* r : requests) active[r->body] = 1;
  setActive(active);
  static const ClBuffer none;
  launch(kForces_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_,
         rotatedGradients(), pos_, elemOut_, energyWithForces_ ? partials_ : none);
  launch(kGatherSum_, Span::Nodes, nodeSeg_, segInfoBuf_, nodeStart_, nodeEntries_, elemOut_, q_);
  for (const BatchRequest* r : requests) axReady_[r->body] = 0;  // their q_ now holds forces
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
  for (const BatchRequest* r : requests)
    if (warmLast_[r->body] && xKnown_[r->body]) speculate[r->body] = any = true;
  const auto [lo, hi] = dofRange(requests);
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
  for (BatchRequest* r : requests) {
    getReals(readStage_.data(), segs_[r->body], *r->out);
    if (energyWithForces_) {
      energy_[r->body] = energyOf(r->body, energyItems_.data(), itemLo);
      energyKnown_[r->body] = 1;
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
  const Segment& sg = segs_[s];
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

void SegmentEngine::apply(const std::vector<BatchRequest*>& requests) {
  if (requests.empty()) return;
  std::vector<char> active(segs_.size(), 0);
  unsigned char* stage = bStage_.writable();
  for (const BatchRequest* r : requests) {
    const Segment& sg = segs_[r->body];
    const Eigen::VectorXd& v = *r->in;
    putReals(stage, sg.dofBegin(), sg.dofs(), [&](std::size_t d) { return v[static_cast<Eigen::Index>(sg.hostDof(d))]; });
    setCoefficients(r->body, r->coeffs);
    active[r->body] = 1;
  }
  // One write and one read of the packed range (the segments in between: scratch, not computed).
  const auto [lo, hi] = dofRange(requests);
  bStage_.write(p_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  setActive(active);
  for (const BatchRequest* r : requests) axReady_[r->body] = 0;  // their q_ takes the product
  product(p_, q_, false, partialsW_);
  readStage_.read(q_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  writesDone();
  for (BatchRequest* r : requests) getReals(readStage_.data(), segs_[r->body], *r->out);
}

void SegmentEngine::pcgSetup(bool zeroStart, bool haveAx, const std::vector<char>* productFor, bool onlyFor) {
  // r = b - A x (projected), u = M^-1 r, p = s = 0, w = A u; gamma = r.u, rr = r.r, bb = b.b,
  // alpha = gamma / u.w, beta = 0 (kernels/opencl/pcg.cl)
  flushCoefficients();
  const bool anyFor =
      productFor && std::any_of(productFor->begin(), productFor->end(), [](char c) { return c != 0; });
  if (onlyFor) {  // the packs' bodies take the whole set-up in pcg_iterate_pack
    if (!anyFor) return;
    setActive(*productFor);
  }
  if (!zeroStart && !haveAx) product(x_, q_, true, partialsW_);  // a zero start needs no A x
  // M^-1 of the coefficients is formed here too (pcg_init), stored for the iterations.
  launch(kPcgInit_, Span::NodeChunks, nodeSeg_, segInfoBuf_, segCoefBuf_, blocks_, mass_, cl_uint(zeroStart ? 1 : 0),
         b_, q_, free_, minv_, r_, z_, p_, s_, partials_);
  if (productFor) {  // the packs' bodies take w = A u and the first scalars in pcg_iterate_pack
    if (!anyFor) return;
    setActive(*productFor);
  }
  productAndFinish(kReduceInit);
}

void SegmentEngine::productAndFinish(cl_uint mode) {
  const SumReal tol2{solver_.tolerance * solver_.tolerance};
  product(z_, q_, true, partialsW_);
  launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, mode, tol2);
}

void SegmentEngine::pcgIteration(bool last) {
  // p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s, u = M^-1 r; w = A u; alpha, beta.
  // The iteration cap's last iteration has no successor: no w = A u, only gamma and r . r.
  launch(kPcgUpdate_, Span::NodeChunks, nodeSeg_, segInfoBuf_, scalars_, q_, minv_, p_, s_, x_, r_, z_, partials_);
  if (last)
    launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, cl_uint(kReduceLast),
           SumReal{solver_.tolerance * solver_.tolerance});
  else
    productAndFinish(kReduceStep);
}

void SegmentEngine::enqueuePcgIterations(const SystemCoeffs& c, int iterations) {
  for (std::size_t s = 0; s < segs_.size(); ++s) setCoefficients(s, c);
  refreshStaleBlocks(std::vector<char>(segs_.size(), 1));  // as solve() does: the blocks of these rotations
  setAllActive();
  std::fill(xKnown_.begin(), xKnown_.end(), 0);  // the iterations change x
  std::fill(axReady_.begin(), axReady_.end(), 0);
  pcgSetup(false, false);
  for (int i = 0; i < iterations; ++i) pcgIteration(i + 1 == iterations);
  segInfoStale_ = true;  // the device may have stopped a segment: the next setActive uploads the table
}

void SegmentEngine::solve(const std::vector<BatchRequest*>& requests) {
  // Per request: b checked and uploaded, x warm-started; zero right-hand sides answered at once.
  struct Running {
    BatchRequest* request;
    double bb = 0.0;
    bool finite = true;
    bool iterating = true;
  };
  std::vector<Running> runs;
  unsigned char* bStage = bStage_.writable();
  for (BatchRequest* r : requests) {
    const Segment& sg = segs_[r->body];
    const Eigen::VectorXd& b = *r->in;
    Eigen::VectorXd& x = *r->out;
    if (static_cast<std::size_t>(x.size()) != sg.dofs()) x = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(sg.dofs()));
    r->stats = LinearSolveStats{};
    // b packed into its stage in device precision (constrained rows zero, even if not finite) in
    // the pass that sums b . b over the free dofs (per chunk, the chunks in order).
    std::vector<double> bbParts(chunkCount(sg.dofs(), hostChunk_), 0.0);
    parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      withReals(bStage, sg.dofBegin(), [&](auto* out) {
        using T = std::remove_pointer_t<decltype(out)>;
        double sum = 0.0;
        for (std::size_t d = lo; d < hi; ++d) {
          const T v = static_cast<T>(sg.constrained[d] ? 0.0 : b[static_cast<Eigen::Index>(sg.hostDof(d))]);
          sum += static_cast<double>(v) * static_cast<double>(v);  // of what the device gets: b below
          out[d] = v;                                                // float's range is 0 there too
        }
        bbParts[c] = sum;
      });
    });
    double bb = 0.0;
    for (double part : bbParts) bb += part;
    if (!std::isfinite(bb)) {
      r->error = errorOf(ErrorCode::SolveFailed, "body '", sg.problem->name, "': OpenCL PCG: the right-hand side "
                         "is not finite (NaN or Inf in b, or beyond the range of ", double_ ? "double" : "float", "); the state "
                         "diverged before the linear solve");
      continue;
    }
    if (bb == 0.0) {
      x.setZero();
      r->stats.converged = true;
      continue;
    }
    setCoefficients(r->body, r->coeffs);
    runs.push_back({r, bb});
  }
  if (runs.empty()) return;
  std::vector<BatchRequest*> running;
  for (const Running& run : runs) running.push_back(run.request);
  const auto [lo, hi] = dofRange(running);
  std::vector<char> active(segs_.size(), 0);
  for (const Running& run : runs) active[run.request->body] = 1;
  // How the iterations run (groupTeam); in a round of one work-group per body, the bodies of packs
  // (packRound) are flagged for pcg_iterate_pack, which pcg_iterate_group leaves alone.
  const std::size_t team = groupTeam(running);
  std::vector<char> packed(segs_.size(), 0);
  const std::vector<cl_uint> packTable = team == 1 && packs_ ? packRound(running, packed) : std::vector<cl_uint>{};
  bool unpacked = false;
  for (const Running& run : runs) {
    if (packed[run.request->body]) active[run.request->body] = char(kSegRunningPacked);
    else unpacked = true;
  }
  setActive(active);
  bStage_.write(b_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
  // x in one pass: packed (constrained and non-finite entries zero) into its stage, compared bit
  // for bit with what the device holds, and tested for zero. Only the running segments decide
  // (those in between are scratch, not computed): x is uploaded unless the device holds it already,
  // and a start of x = 0 on every running body (Newton's corrections start there) skips the
  // product of r = b - A x.
  bool xThere = true, zeroStart = true;
  unsigned char* xStage = xStage_.writable();
  for (const Running& run : runs) {
    const Segment& sg = segs_[run.request->body];
    const Eigen::VectorXd& x = *run.request->out;
    // The stage changes now and the upload below may fail: unknown until it is done.
    const bool known = xKnown_[run.request->body] != 0;
    xKnown_[run.request->body] = 0;
    std::vector<char> sameParts(chunkCount(sg.dofs(), hostChunk_), 1), zeroParts(sameParts.size(), 1);
    parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      withReals(xStage, sg.dofBegin(), [&](auto* out) {
        using T = std::remove_pointer_t<decltype(out)>;
        bool same = known, zero = true;
        for (std::size_t d = lo; d < hi; ++d) {
          const double v = x[static_cast<Eigen::Index>(sg.hostDof(d))];
          const double packed = sg.constrained[d] || !std::isfinite(v) ? 0.0 : v;
          const T t = static_cast<T>(packed);
          same = same && std::memcmp(&t, &out[d], sizeof(T)) == 0;
          zero = zero && packed == 0.0;
          out[d] = t;
        }
        sameParts[c] = same;
        zeroParts[c] = zero;
      });
    });
    bool bodyZero = true;
    for (std::size_t c = 0; c < sameParts.size(); ++c) {
      xThere = xThere && known && sameParts[c];
      bodyZero = bodyZero && zeroParts[c];
    }
    zeroStart = zeroStart && bodyZero;
    warmLast_[run.request->body] = !bodyZero;  // its own start, not the round's
  }
  if (!xThere) {
    xStage_.write(x_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
    for (std::size_t s = 0; s < segs_.size(); ++s)  // the write covers the bodies in between too
      if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) axReady_[s] = 0;
  }
  // A x formed behind the forces (internalForces) serves if x and every coefficient are unchanged.
  bool haveAx = !zeroStart && xThere;
  for (const Running& run : runs) {
    const std::size_t s = run.request->body;
    haveAx = haveAx && axReady_[s] &&
             std::equal(&segCoef_[kSegCoefCount * s], &segCoef_[kSegCoefCount * (s + 1)], &axCoef_[kSegCoefCount * s]);
  }
  for (const Running& run : runs) axReady_[run.request->body] = 0;  // their q_ is the iterations' from here
  // From here the iterations change x on the device: unknown until the read below.
  // The packs' bodies run their whole solve in pcg_iterate_pack (packWhole): the set-up's w = A u
  // and first scalars, the iterations, the cap's last iteration and the true residual. A product
  // there costs what an iteration does in a pack, about a quarter of the launched product's per
  // body (the launched product and gather of 100 bodies of 2,000 elements took 1.8 ms on 2 cores,
  // twice a solve). Not where the cap leaves the pack no iteration (it is not launched then).
  // From a zero start (Newton's corrections) the packs form the whole set-up themselves (packFresh):
  // their bodies' node blocks, M^-1 and pcg_init too, from a_i, b and the mass, with nothing
  // launched for them (corner_gradients, node_stiffness_blocks and pcg_init took 2.8 ms a step for
  // 100 bodies of 2,000 elements on 2 cores), and pack_in copies neither the PCG vectors nor M^-1.
  const bool packWhole = !packTable.empty() && solver_.maxIterations > 1, packFresh = packWhole && zeroStart;
  std::vector<char> unpackedOnly = active;
  for (std::size_t s = 0; s < segs_.size(); ++s)
    if (packed[s]) unpackedOnly[s] = 0;
  // The node blocks of the bodies rotated since they were formed, for pcg_init's M^-1 (the packs'
  // own with packFresh: theirs stay stale for a later solve outside a pack).
  refreshStaleBlocks(packFresh ? unpackedOnly : active);
  setActive(active);
  if (packWhole) {
    // The packed bodies' segments stay inactive from here (pcgSetup made the unpacked ones the
    // active ones): pcg_iterate_pack marks its lanes running itself. Uploading the table again would
    // revive an unpacked body that reduce_finish stopped at the set-up.
    pcgSetup(zeroStart, haveAx, &unpackedOnly, packFresh);
  } else {
    pcgSetup(zeroStart, haveAx);
  }

  // The device tests convergence after every iteration (reduce_finish) and makes a stopped segment
  // inactive on its own, so the host enqueues checkEvery iterations ahead of what it has read: each
  // chunk of iterations is followed by a non-blocking read of all segments' scalars, and the host
  // waits for a read only while the next chunk is already queued. It learns of a stop at most one
  // chunk late, and that late chunk costs the stopped segment nothing (its work-groups return at
  // once): the answer and the iteration count are those of checking every iteration, whatever
  // checkEvery is. The host narrows the launched span to the segments it still sees running and
  // never writes the segment table while iterating (that could revive a segment the device stopped).
  segInfoStale_ = true;
  const int checkEvery = std::max(1, solver_.checkEvery);
  const int maxIterations = std::max(0, solver_.maxIterations);
  struct Read {
    std::vector<unsigned char> bytes;
    cl_event event = nullptr;
  };
  std::deque<Read> reads;
  auto issueRead = [&]() {
    Read r;
    r.bytes.resize(kScalarCount * segs_.size() * sumSize_);
    checkCl(clEnqueueReadBuffer(ctx_->queue(), scalars_.get(), CL_FALSE, 0, r.bytes.size(), r.bytes.data(), 0,
                                nullptr, &r.event),
            "clEnqueueReadBuffer", dev_);
    reads.push_back(std::move(r));
  };
  std::vector<double> scalars(kScalarCount * segs_.size());
  auto collectLast = [&]() {  // waits for the oldest read: its scalars into `scalars`
    Read r = std::move(reads.front());
    reads.pop_front();
    const cl_int status = clWaitForEvents(1, &r.event);
    clReleaseEvent(r.event);
    checkCl(status, "clWaitForEvents (PCG scalars)", dev_);
    for (std::size_t i = 0; i < scalars.size(); ++i)
      scalars[i] = sumSize_ == sizeof(double) ? reinterpret_cast<const double*>(r.bytes.data())[i]
                                              : reinterpret_cast<const float*>(r.bytes.data())[i];
  };
  auto collect = [&]() {  // waits for the oldest read and takes the stops it shows
    collectLast();
    for (Running& run : runs) {
      if (!run.iterating) continue;
      const double* sc = &scalars[kScalarCount * run.request->body];
      LinearSolveStats& stats = run.request->stats;
      stats.iterations = static_cast<int>(sc[kScalarIterations]);
      stats.relativeResidual = std::sqrt(std::max(0.0, sc[kScalarRr]) / sc[kScalarBb]);
      const auto stop = static_cast<unsigned>(sc[kScalarStop]);
      if (stop == kStopRunning) continue;
      run.iterating = false;
      stats.converged = stop == kStopConverged;
      run.finite = stop != kStopNonFinite && std::isfinite(stats.relativeResidual);
    }
  };
  auto narrowSpan = [&]() {  // the host's view only: the device's table stays as the device left it
    activeLo_ = segs_.size();
    activeHi_ = 0;
    for (const Running& run : runs)
      if (run.iterating) {
        activeLo_ = std::min(activeLo_, run.request->body);
        activeHi_ = std::max(activeHi_, run.request->body + 1);
      }
  };
  int enqueued = 0;
  auto enqueueChunk = [&]() {
    if (team > 0) {  // every iteration but the cap's last in one launch, a work-group (team) per body; then the last
      const cl_uint iterations = cl_uint(maxIterations - enqueued - 1);
      const SumReal tol2{solver_.tolerance * solver_.tolerance};
      if (iterations > 0) {
        const bool teamed = team > 1;
        // A team's phases take the epochs teamEpoch_ + 1 .. + 4 iterations; before they could
        // wrap, the claim words go back to 0 (about every 10^9 phases).
        if (teamed && std::uint64_t{teamEpoch_} + 4 * std::uint64_t{iterations} + 1 > std::numeric_limits<cl_uint>::max()) {
          uploadRaw(teamState_, teamStateAtRest());
          teamEpoch_ = 0;
        }
        teamSize_ = team;
        if (unpacked && !teamed) {
          // The unpacked bodies the costliest first (elements times last iterations), then the
          // claim word; a work-group per compute unit takes them in turn (pcg_iterate_group).
          std::vector<cl_uint> order;
          for (const Running& run : runs)
            if (!packed[run.request->body]) order.push_back(static_cast<cl_uint>(run.request->body));
          const auto cost = [&](cl_uint s) {
            return segs_[s].elems * static_cast<std::size_t>(std::max(1, lastIterations_[s]));
          };
          std::stable_sort(order.begin(), order.end(), [&](cl_uint a, cl_uint b) { return cost(a) > cost(b); });
          const std::size_t count = order.size();
          order.push_back(0);
          uploadRaw(groupOrder_, order);
          launchGroups(kPcgIterateGroup_, std::min(count, tuning_.claimWorkGroups), wg_, cl_uint(stride_), cl_uint(team),
                       teamEpoch_, teamState_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_, rotatedGradients(),
                       nodeStart_, nodeEntries_, elemOut_, mass_, free_, minv_, p_, s_, x_, r_, z_, q_, partials_,
                       partialsW_, scalars_, iterations, tol2, groupOrder_, cl_uint(count));
        }
        if (unpacked && teamed)
          launch(kPcgIterateTeam_, Span::Teams, cl_uint(stride_), cl_uint(team), teamEpoch_, teamState_, segInfoBuf_,
                 segCoefBuf_, elemNodes_, geom_, rotatedGradients(), nodeStart_, nodeEntries_, elemOut_, mass_, free_,
                 minv_, p_, s_, x_, r_, z_, q_, partials_, partialsW_, scalars_, iterations, tol2, groupOrder_,
                 cl_uint(0));
        if (unpacked) {
          if (teamed) {
            teamEpoch_ += 4 * iterations;
            ++teamPcgLaunches;
          } else {
            ++groupPcgLaunches;
          }
        }
        if (!packTable.empty()) {  // the packs' bodies: their vectors in, the iterations, the vectors out
          const std::size_t slots = (packTable.size() - 1) / kPackInfoCount;  // and the claim word
          uploadRaw(packInfo_, packTable);
          const cl_uint rows = cl_uint(3 * packNodeRows_);  // dof rows of each of packVec_'s vectors
          launchGroups(kPackIn_, slots, wg_, packInfo_, segInfoBuf_, cl_uint(stride_), rotatedGradients(), geom_, x_,
                       r_, z_, p_, s_, q_, b_, minv_, mass_, free_, packElem_, packVec_, packMinv_, packMass_,
                       packFree_, rows, cl_uint(packFresh ? 1 : 0));
          // A work-group per compute unit, each taking slots from the claim word (costliest first).
          launchGroups(kPcgIteratePack_, std::min(slots, tuning_.claimWorkGroups), 1, packInfo_, cl_uint(slots), segInfoBuf_, segCoefBuf_, packCorners_, packElem_,
                       packSums_, packVec_, packFree_, packMass_, packMinv_, packPartials_, partials_,
                       scalars_, rows, iterations, cl_uint(packFresh ? 1 : 0), tol2);
          launchGroups(kPackOut_, slots, wg_, packInfo_, segInfoBuf_, x_, r_, z_, p_, s_, q_, packVec_, rows);
          ++packPcgLaunches;
          packPcgLanes += static_cast<unsigned long long>(std::count(packed.begin(), packed.end(), char(1)));
        }
      }
      pcgIteration(true);
      enqueued = maxIterations;
      issueRead();
      return;
    }
    const int n = std::min(checkEvery, maxIterations - enqueued);
    for (int i = 0; i < n; ++i) pcgIteration(enqueued + i + 1 == maxIterations);
    enqueued += n;
    issueRead();
  };
  // The reported residual is the true one, |free (b - A x)| / |free b| (as the interface defines
  // it), not the recurrence's estimate, which drifts from it in float: one more product, for the
  // bodies that iterated. Once the last allowed iteration is queued nothing can follow it, so the
  // pass is queued at once for every body that may have iterated (those that stop in the last chunk
  // included; a result the host then finds it does not need is ignored), without the device
  // waiting for the host to read the last scalars.
  std::vector<char> residualFor(segs_.size(), 0);
  bool residualQueued = false;
  auto queueResidual = [&]() {
    bool any = false;
    std::vector<char> on(segs_.size(), 0);
    for (const Running& run : runs)
      if (run.iterating || (run.finite && run.request->stats.iterations > 0)) on[run.request->body] = any = true;
    residualQueued = true;
    if (!any) return;
    residualFor = on;
    if (packWhole) {  // pcg_iterate_pack formed the packed bodies' residuals (and made them inactive)
      any = false;
      for (std::size_t s = 0; s < segs_.size(); ++s) {
        if (packed[s]) on[s] = 0;
        any = any || on[s];
      }
      if (!any) return;
    }
    setActive(on);  // after every queued iteration: no segment the device stopped can be revived
    // r = free b - A x and its sums from the gather itself (what pcg_init would form: the same bits)
    product(x_, r_, true, partials_, &b_);
    launch(kReduceFinish_, Span::Segments, segInfoBuf_, partials_, partialsW_, scalars_, cl_uint(kReduceResidual),
           SumReal{0.0});
  };
  auto releaseReads = [](std::deque<Read>& list, bool wait) {
    for (Read& r : list) {
      if (wait) clWaitForEvents(1, &r.event);  // the device may still write into r.bytes
      clReleaseEvent(r.event);
    }
    list.clear();
  };
  // The set-up's scalars (a warm start may already have converged), unless the packs' bodies have
  // theirs only after pcg_iterate_pack: the read after the iterations has everyone's.
  if (!packWhole) issueRead();
  try {
    if (enqueued < maxIterations) enqueueChunk();  // runs while that read travels
    for (;;) {
      if (enqueued >= maxIterations && !residualQueued && enqueued > 0) queueResidual();
      collect();
      bool any = false;
      for (const Running& run : runs) any = any || run.iterating;
      if (!any || reads.empty()) break;  // all stopped, or the read after the last allowed iteration was taken
      if (enqueued < maxIterations) {
        narrowSpan();
        enqueueChunk();
      }
    }
  } catch (...) {
    releaseReads(reads, true);
    throw;
  }
  // A chunk enqueued after everything had stopped (no-ops): its read is dropped without waiting; its
  // bytes stay alive until the blocking read of x below has drained the queue.
  std::deque<Read> dropped = std::move(reads);
  reads.clear();
  for (Running& run : runs) {
    if (run.iterating) run.request->stats.iterations = maxIterations;  // capped
    lastIterations_[run.request->body] = run.request->stats.iterations;
  }

  // The true residual (queued above when the iteration cap was reached, else now). The convergence
  // decision above stays the recurrence's (the standard PCG stop test).
  if (!residualQueued) queueResidual();
  bool anyTrue = false;
  for (const Running& run : runs) {
    active[run.request->body] = residualFor[run.request->body] && run.finite && run.request->stats.iterations > 0;
    anyTrue = anyTrue || active[run.request->body];
  }
  if (anyTrue) issueRead();  // completes with the blocking read of x below: one synchronisation for both
  for (std::size_t s = 0; s < segs_.size(); ++s)  // the read overwrites [lo, hi) of the stage
    if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) xKnown_[s] = 0;
  try {
    xStage_.read(x_.get(), lo * realSize_, (hi - lo) * realSize_, dev_);
    writesDone();
  } catch (...) {
    releaseReads(dropped, true);
    releaseReads(reads, true);
    throw;
  }
  releaseReads(dropped, false);  // complete: the blocking read of x followed them
  for (std::size_t s = 0; s < segs_.size(); ++s)  // the stage holds the device's x over [lo, hi)
    if (segs_[s].dofBegin() >= lo && segs_[s].dofBegin() < hi) xKnown_[s] = 1;
  if (anyTrue) {
    collectLast();
    for (Running& run : runs)
      if (active[run.request->body]) {
        const double* sc = &scalars[kScalarCount * run.request->body];
        LinearSolveStats& stats = run.request->stats;
        stats.relativeResidual = std::sqrt(std::max(0.0, sc[kScalarRr]) / sc[kScalarBb]);
        run.finite = std::isfinite(stats.relativeResidual);
      }
  }
  for (Running& run : runs) {
    BatchRequest* r = run.request;
    const Segment& sg = segs_[r->body];
    if (!run.finite) {
      r->error = errorOf(ErrorCode::SolveFailed, "body '", sg.problem->name, "': OpenCL PCG produced a non-finite "
                         "residual after ", r->stats.iterations, " iterations on device '", dev_, "' (the system "
                         "matrix or the right-hand side holds NaN/Inf, or ",
                         double_ ? "double" : mixed_ ? "mixed" : "float", " precision overflowed); check the "
                         "material, time step and loads");
      continue;
    }
    std::vector<char> finiteParts(chunkCount(sg.dofs(), hostChunk_), 1);
    parallelChunks(sg.dofs(), hostChunk_, [&](std::size_t c, std::size_t lo, std::size_t hi) {
      withReals(xStage_.data(), sg.dofBegin() + lo, [&](const auto* out) {
        finiteParts[c] = allFiniteEntries(Eigen::Map<const Eigen::Matrix<std::remove_cv_t<std::remove_pointer_t<decltype(out)>>,
                                                                         Eigen::Dynamic, 1>>(out, static_cast<Eigen::Index>(hi - lo)));
      });
    });
    const bool finite = std::all_of(finiteParts.begin(), finiteParts.end(), [](char f) { return f != 0; });
    if (!finite) {  // the caller's x stays as it was
      r->error = errorOf(ErrorCode::SolveFailed, "body '", sg.problem->name,
                         "': OpenCL PCG produced a non-finite solution on device '", dev_, "'");
      continue;
    }
    getReals(xStage_.data(), sg, *r->out);
  }
}

void SegmentEngine::elasticEnergy(const std::vector<BatchRequest*>& all) {
  // Known from the forces at these positions (CPUs): no pass, no read.
  std::vector<BatchRequest*> requests;
  for (BatchRequest* r : all)
    if (energyWithForces_ && energyKnown_[r->body]) r->energy = energy_[r->body];
    else requests.push_back(r);
  if (requests.empty()) return;
  std::vector<char> active(segs_.size(), 0);
  for (const BatchRequest* r : requests) active[r->body] = 1;
  setActive(active);
  if (energyWithForces_) {  // the forces' pass (into scratch) and its energies: the same bits as with the forces
    launch(kForces_, Span::Elements, cl_uint(stride_), elemSeg_, segInfoBuf_, segCoefBuf_, elemNodes_, geom_,
           rotatedGradients(), pos_, elemOut_, partials_);
    const std::size_t lo = readEnergyItems(nullptr);
    writesDone();
    for (BatchRequest* r : requests) {
      r->energy = energyOf(r->body, energyItems_.data(), lo);
      energy_[r->body] = r->energy;
      energyKnown_[r->body] = 1;
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
  for (BatchRequest* r : requests) {
    const Segment& sg = segs_[r->body];
    double sum = 0.0;
    for (std::size_t g = sg.elemBegin / perGroup; g < (sg.elemBegin + sg.elemSpan) / perGroup; ++g) sum += partial[g];
    r->energy = sum;
  }
}

std::vector<double> SegmentEngine::readRotations(std::size_t s) {
  const Segment& sg = segs_[s];
  ensureRotations();  // R = I for a body never rotated
  if (rStale_[s]) {
    // The last rotation pass wrote no R: run it again for this body with R (from the same positions,
    // so the same a_i, bit for bit; not the corners: the blocks were formed from the first pass).
    std::vector<char> only(segs_.size(), 0);
    only[s] = 1;
    launchRotations(only, false, true);
  }
  std::vector<double> soa(kRotComponents * stride_);
  download(rot_, soa.data(), 0, soa.size());
  std::vector<double> out(9 * sg.elems);
  for (std::size_t e = 0; e < sg.elems; ++e) {
    const std::size_t to = sg.hostElem.empty() ? e : sg.hostElem[e];  // in the problem's element order
    for (std::size_t k = 0; k < 9; ++k) out[9 * to + k] = soa[k * stride_ + sg.elemBegin + e];
  }
  return out;
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
