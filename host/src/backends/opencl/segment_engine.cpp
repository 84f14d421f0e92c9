// The OpenCL engine's set-up (segment_engine.hpp): tuning, program, buffers and tables. Build
// switches (-D), shared by all segments: precision (COROFEM_DOUBLE; COROFEM_MIXED: float vectors
// and products, PCG dot products, partials and scalars in double), rotation method (COROFEM_ROT_*),
// preconditioner (COROFEM_PRECOND_*), work-group size (COROFEM_WG), elements per work-item
// (COROFEM_VEC), nodes per work-item in the reducing node kernels (COROFEM_CHUNK;
// COROFEM_TREE_REDUCE: local-memory trees), their values from the tuning (tuning.hpp). Per body
// (tables, no switch): Lame parameters, lumped mass, constraints, Rayleigh damping (C = alpha M +
// beta K^R folds into the two coefficients of M and K^R), formulation (the linear one never runs
// compute_rotations).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/segment_engine.hpp"
#include "backends/opencl/engine_amg.hpp"
#include "device/device_warped.hpp"

#include "backends/opencl/cpu_pcg.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <cstring>

namespace corofem::detail {

namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

namespace {

using cl::checkCl;
using namespace layout;

bool hasNonzeroMass(const Problem& p) {
  if (static_cast<std::size_t>(p.lumpedMass.size()) != p.dofCount()) return false;
  for (Eigen::Index d = 0; d < p.lumpedMass.size(); ++d)
    if (p.lumpedMass[d] != 0.0) return true;
  return false;
}

}  // namespace

SegmentEngine::SegmentEngine(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                             std::shared_ptr<cl::Context> ctx, const OpenCLTuning& tuning)
    : ctx_(std::move(ctx)), solver_(resolvedSolver(solver, problems)), precond_(solver_.preconditioner) {
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

  // -- segments: every body padded to whole work-groups of every kernel (corofem_layout.h), each in
  // the device's numbering (a Morton order where the mesh's own scatters the kernels' loads). The
  // buffers below are made from the problems in that numbering; host vectors are permuted at every
  // transfer.
  const std::size_t elemAlign = std::max<std::size_t>(wg_ * vec_, kStrideAlign);
  const std::size_t nodeAlign = wg_ * chunk_;
  BodyLayout layout(problems, tuning_.localityOrder, elemAlign, nodeAlign, kElemOutComponents);
  segs_ = layout.segments;
  springs_.resize(segs_.size());
  springFold_.assign(segs_.size(), SpringFold{});  // mass_ holds M
  springFoldStale_.assign(segs_.size(), 0);
  operatorMass_.assign(segs_.size(), 0.0);
  stride_ = layout.elementTotal;
  nodeTotal_ = layout.nodeTotal;
  for (std::size_t s = 0; s < segs_.size(); ++s) {
    segs_[s].problem = &layout.deviceProblem(s);  // until the uploads are done
    partialTotal_ += partialCount(s);
    hasMass_ = hasMass_ || hasNonzeroMass(*segs_[s].problem);
  }
  if (stride_ * kElemOutComponents >= (std::size_t(1) << 32) / 2 || 9 * nodeTotal_ >= (std::size_t(1) << 32) / 2)
    fail(ErrorCode::BadInput, "body '", problems.front()->name, "'", problems.size() > 1 ? " and the others" : "",
         ": ", stride_, " (padded) elements exceed the OpenCL backend's 32-bit element indexing; split the "
         "body or batch fewer bodies per device");

  cpu_ = std::make_unique<CpuPcg>(*this);
  if (precond_ == PreconditionerKind::Amg) amg_ = std::make_unique<EngineAmg>(*this);
  if (precond_ == PreconditionerKind::WarpedCholesky) warped_ = std::make_unique<DeviceWarped>(segs_);
  try {
    build(solver_);
    allocate();
    setAllActive();
    refreshBlocks(false);
    finish();
  } catch (...) {
    // No destructor runs for a constructor that throws: the uploads already enqueued read host
    // bytes this object owns, so they end here before those bytes go.
    dropReads(true);
    clFinish(ctx_->queue());
    writesDone();
    throw;
  }
  // Past the uploads the device's numbering lives in the permutations: the caller's problems again.
  for (std::size_t s = 0; s < segs_.size(); ++s) segs_[s].problem = problems[s];
  // A device made for bodies that have springs already (a failover) folds them at its first solve.
  setSprings(allBodies(segs_.size()), problems);
}

SegmentEngine::~SegmentEngine() {
  dropReads(true);
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
  // amg: pcg_init forms the inverses of the current node blocks its smoothing uses (engine_amg.hpp).
  if (precond_ == PreconditionerKind::BlockDiagonal || precond_ == PreconditionerKind::Amg)
    options_ += " -DCOROFEM_PRECOND_BLOCK";
  else if (precond_ == PreconditionerKind::Diagonal)
    options_ += " -DCOROFEM_PRECOND_DIAG";
  if (amg_) options_ += " -DCOROFEM_AMG";
  if (amg_ && ctx_->info().fp64) options_ += " -DCOROFEM_AMG_COARSEST_DOUBLE";
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
  cpu_->createKernels();
  if (amg_) amg_->createKernels();
}

void SegmentEngine::allocate() {
  const std::size_t S = stride_, K = segs_.size();
  cl_context c = ctx_->context();

  // -- segment tables
  segInfo_.assign(kSegInfoCount * K, 0);
  segCoef_.assign(kSegCoefCount * K, 0.0);
  std::vector<cl_uint> elemSeg(S / (wg_ * vec_)), nodeSeg(nodeTotal_ / wg_);
  for (std::size_t s = 0; s < K; ++s) {
    const BodySegment& sg = segs_[s];
    cl_uint* info = &segInfo_[kSegInfoCount * s];
    info[kSegActive] = 1;
    info[kSegElemEnd] = static_cast<cl_uint>(sg.elemBegin + sg.elems);
    info[kSegNodeEnd] = static_cast<cl_uint>(sg.nodeBegin + sg.nodes);
    info[kSegPartialBegin] = static_cast<cl_uint>(partialBegin(s));
    info[kSegPartialCount] = static_cast<cl_uint>(partialCount(s));
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
    for (const BodySegment& sg : segs_)
      for (std::size_t e = 0; e < sg.elemSpan; ++e)
        for (std::size_t k = 0; k < 4; ++k)
          nodes[k * S + sg.elemBegin + e] =
              static_cast<cl_uint>(sg.nodeBegin + (e < sg.elems ? sg.problem->mesh.tets[4 * e + k] : 0));
    elemNodes_.create(c, nodes.size() * sizeof(cl_uint), dev_);
    uploadRaw(elemNodes_, nodes);
  }
  bool anyCorotational = false;
  for (const BodySegment& sg : segs_) anyCorotational = anyCorotational || sg.corotational;
  // The Quaternion method's state only where something rotates (linear bodies never do).
  const bool quaternion = solver_.rotation == RotationMethod::Quaternion && anyCorotational;
  // "warped_cholesky" reads R before every solve (its warp): written by the pass that computes it
  // rather than by a second pass for readRotations.
  rAlways_ = quaternion || (precond_ == PreconditionerKind::WarpedCholesky && anyCorotational);
  {
    std::vector<double> geom(kGeomComponents * S, 0.0), quat(quaternion ? kQuatComponents * S : 0, 0.0);
    for (const BodySegment& sg : segs_)
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
    // again for readRotations, "warped_cholesky" reads it at every solve); otherwise the first
    // readRotations makes it (ensureRotations).
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
    for (const BodySegment& sg : segs_) entryCount += 4 * sg.elems;
    std::vector<cl_uint> start(nodeTotal_ + 1, 0), entries(entryCount);
    for (const BodySegment& sg : segs_)
      for (std::size_t e = 0; e < sg.elems; ++e)
        for (int k = 0; k < 4; ++k) ++start[sg.nodeBegin + sg.problem->mesh.tets[4 * e + k] + 1];
    for (std::size_t n = 0; n < nodeTotal_; ++n) start[n + 1] += start[n];
    std::vector<cl_uint> fill(start.begin(), start.end() - 1);
    for (const BodySegment& sg : segs_)
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
  for (const BodySegment& sg : segs_) {
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
  if (formsBlocks()) {
    // The block preconditioner reads 6 reals per node, the diagonal one 3 (precond.cl).
    const bool nodeBlocks = precond_ == PreconditionerKind::BlockDiagonal || precond_ == PreconditionerKind::Amg;
    createReal(blocks_, (nodeBlocks ? kNodeBlockComponents : 3) * nodeTotal_);
    createReal(minv_, (nodeBlocks ? 9 : 3) * nodeTotal_);
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
  lastIterations_.assign(K, 0);
  hostStopped_.assign(K, 0);
  cpu_->allocate();
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
      {"partial_sums_w", &partialsW_},      {"pcg_scalars", &scalars_}};
  std::vector<std::pair<const char*, const ClBuffer*>> list(std::begin(all), std::end(all));
  cpu_->appendBuffers(list);
  std::vector<DeviceBuffer> out;
  for (const auto& [name, buffer] : list)
    if (buffer->get()) out.push_back({name, buffer->bytes()});
  if (amg_)
    for (DeviceBuffer& b : amg_->buffers()) out.push_back(std::move(b));
  return out;
}

std::size_t SegmentEngine::allocatedBytes() const {
  std::size_t sum = 0;
  for (const DeviceBuffer& b : buffers()) sum += b.bytes;
  return sum;
}

std::size_t SegmentEngine::workingSet(std::size_t s) const {
  const BodySegment& sg = segs_[s];
  // Per element: 4 corners, 8 gather entries' worth of CSR, geometry, a_i and the output 12-vector;
  // per node: CSR start, 9 node vectors (x b r u p w s, free, mass) of 3, blocks and inverse.
  return sg.elemSpan * (8 * sizeof(cl_uint) + (kGeomComponents + kRotGradComponents + kElemOutComponents) * realSize_) +
         sg.nodeSpan * (sizeof(cl_uint) + (9 * 3 + kNodeBlockComponents + 9) * realSize_);
}


std::size_t SegmentEngine::partialBegin(std::size_t s) const {
  return treeReduce_ ? segs_[s].nodeBegin / (wg_ * chunk_) : segs_[s].nodeBegin / chunk_;
}

std::size_t SegmentEngine::partialCount(std::size_t s) const {
  return treeReduce_ ? segs_[s].nodeSpan / (wg_ * chunk_) : segs_[s].nodeSpan / chunk_;
}

std::vector<BodySet> SegmentEngine::tiles(const BodySet& bodies, std::size_t tileBytes) const {
  // Tiles of consecutive bodies whose working set fits the device cache (CPUs): a whole PCG solve
  // of a tile then runs on cached data, and an element pass's output is still cached for its
  // gather. One tile on GPUs (tileBytes_ = 0).
  std::vector<BodySet> out;
  std::size_t bytes = 0;
  for (std::size_t s : bodies) {
    const std::size_t w = workingSet(s);
    if (out.empty() || (tileBytes > 0 && bytes + w > tileBytes && !out.back().empty())) {
      out.emplace_back();
      bytes = 0;
    }
    out.back().push_back(s);
    bytes += w;
  }
  return out;
}

CpuPcgCounts SegmentEngine::pcgCounts() const { return cpu_ ? cpu_->counts() : CpuPcgCounts{}; }

DevicePositions SegmentEngine::devicePositions(std::size_t s) const {
  const BodySegment& sg = segs_.at(s);
  const std::size_t nodeBytes = 3 * (double_ ? sizeof(double) : sizeof(float));
  return {{GpuApi::OpenCL, ctx_->context(), ctx_->queue(), ctx_->device()},
          cl::bufferOf(pos_.get(), 0, nodeBytes, nodeTotal_),
          sg.nodeBegin,
          double_,
          sg.centroid,
          sg.deviceNode.empty() ? nullptr : sg.deviceNode.data()};
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
