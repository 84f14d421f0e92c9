// The OpenCL backend: per-element rotations, matrix-free co-rotational forces and products,
// deterministic per-node gathers and a PCG whose scalars stay on the device (kernels/opencl/).
//
// Per call:
//   setPositions   upload x; compute_rotations (R, a_i = R grad N_i); corner_gradients +
//                  node_stiffness_blocks (preconditioner blocks, rotated with the elements)
//   internalForces element_forces + gather_sum; download f
//   apply          upload p; element_product + gather_product; download y
//   solve          upload b, x; precond_invert; r = b - A x; PCG iterations (5 launches each, no
//                  host read); read the scalars every checkEvery iterations; true residual; download x
// Build switches (-D), chosen per problem: precision (COROFEM_DOUBLE; COROFEM_MIXED: float vectors
// and products, PCG dot products, partials and scalars in double), rotation method
// (COROFEM_ROT_*), preconditioner (COROFEM_PRECOND_*), work-group size (COROFEM_WG), elements per
// work-item (COROFEM_VEC: 8 on CPUs, 1 on GPUs), nodes per work-item in the reducing node kernels
// (COROFEM_CHUNK: 4 on CPUs; COROFEM_TREE_REDUCE: local-memory trees on GPUs). Rayleigh damping needs no switch:
// C = alpha M + beta K^R folds into the two coefficients of M and K^R, so a problem without damping
// runs exactly the same kernels with the same cost.
// Tuning overrides for experiments (not for production): COROFEM_OPENCL_WG, COROFEM_OPENCL_VEC,
// COROFEM_OPENCL_CHUNK, COROFEM_OPENCL_OPTIONS (extra compiler options), COROFEM_OPENCL_PROFILE=1
// (per-kernel device times printed when the backend is destroyed).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/opencl_backend.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <map>
#include <utility>

namespace corofem::detail {

// The device layout constants (kScalarRho, kGeomVolume, ...), shared with the kernels.
namespace layout {
#include "../../../../kernels/shared/corofem_layout.h"
}  // namespace layout

namespace {

using cl::checkCl;
using namespace layout;

/// A device buffer released on destruction.
class Buffer {
 public:
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  ~Buffer() {
    if (mem_) clReleaseMemObject(mem_);
  }
  void create(cl_context ctx, std::size_t bytes, const std::string& device) {
    cl_int status = CL_SUCCESS;
    mem_ = clCreateBuffer(ctx, CL_MEM_READ_WRITE, std::max<std::size_t>(bytes, 16), nullptr, &status);
    checkCl(status, "clCreateBuffer", device);
    bytes_ = bytes;
  }
  cl_mem get() const { return mem_; }
  std::size_t bytes() const { return bytes_; }

 private:
  cl_mem mem_ = nullptr;
  std::size_t bytes_ = 0;
};

/// A kernel released on destruction.
class Kernel {
 public:
  Kernel() = default;
  Kernel(const Kernel&) = delete;
  Kernel& operator=(const Kernel&) = delete;
  ~Kernel() {
    if (k_) clReleaseKernel(k_);
  }
  void create(cl_program program, const char* name, const std::string& device) {
    cl_int status = CL_SUCCESS;
    k_ = clCreateKernel(program, name, &status);
    if (status != CL_SUCCESS)
      fail(ErrorCode::DeviceError, "clCreateKernel('", name, "') failed with ",
           cl::errorString(status), " on OpenCL device '", device, "'");
    name_ = name;
  }
  cl_kernel get() const { return k_; }
  const char* name() const { return name_; }

 private:
  cl_kernel k_ = nullptr;
  const char* name_ = "";
};

/// A floating-point kernel argument, passed as float or double by the backend's precision.
struct RealArg {
  double value;
};

constexpr std::size_t kDefaultWorkGroup = 64;

std::size_t roundUp(std::size_t n, std::size_t m) { return (n + m - 1) / m * m; }

class OpenCLBackend final : public OpenCLBackendInternal {
 public:
  OpenCLBackend(const Problem& problem, const SolverDesc& solver, std::shared_ptr<cl::Context> ctx,
                const OpenCLOptions& options);

  ~OpenCLBackend() override {
    for (const auto& [kernel, entry] : profileTimes_)
      std::fprintf(stderr, "[corofem opencl profile] %-24s %8ld launches %10.1f us each\n", kernel.c_str(),
                   entry.first, 1e6 * entry.second / static_cast<double>(entry.first));
  }
  std::string name() const override { return "opencl"; }
  std::string deviceName() const override { return ctx_->info().describe(); }
  void setPositions(const Eigen::VectorXd& x) override;
  void internalForces(Eigen::VectorXd& f) override;
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override;
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override;
  double elasticEnergy() override;

  std::vector<double> readRotations() override;
  const std::string& buildOptions() const override { return options_; }
  cl::ProgramOrigin programOrigin() const override { return build_.origin; }
  const cl::ProgramBuild& programBuild() const override { return build_; }
  cl::Context& context() override { return *ctx_; }
  cl_mem positionBuffer() const override { return pos_.get(); }
  bool positionsAreDouble() const override { return double_; }
  const double* positionCentroid() const override { return centroid_; }
  void enqueueRotations() override;
  void enqueueForces() override;
  void enqueueElementForces() override;
  void enqueueProduct(const SystemCoeffs& c) override;
  void enqueueElementProduct(const SystemCoeffs& c) override;
  void enqueuePcgIterations(const SystemCoeffs& c, int iterations) override;
  void finish() override { checkCl(clFinish(ctx_->queue()), "clFinish", dev_); }

 private:
  // -- argument setting and launching
  void setArg(cl_kernel k, cl_uint i, cl_mem m) {
    checkCl(clSetKernelArg(k, i, sizeof(cl_mem), &m), "clSetKernelArg", dev_);
  }
  void setArg(cl_kernel k, cl_uint i, const Buffer& b) { setArg(k, i, b.get()); }
  void setArg(cl_kernel k, cl_uint i, cl_uint v) {
    checkCl(clSetKernelArg(k, i, sizeof(cl_uint), &v), "clSetKernelArg", dev_);
  }
  void setArg(cl_kernel k, cl_uint i, RealArg v) {
    if (double_) {
      checkCl(clSetKernelArg(k, i, sizeof(double), &v.value), "clSetKernelArg", dev_);
    } else {
      const float f = static_cast<float>(v.value);
      checkCl(clSetKernelArg(k, i, sizeof(float), &f), "clSetKernelArg", dev_);
    }
  }
  template <class... Args>
  void launch(const Kernel& kernel, std::size_t items, const Args&... args) {
    cl_uint index = 0;
    (setArg(kernel.get(), index++, args), ...);
    const std::size_t global = roundUp(std::max<std::size_t>(items, 1), wg_);
    cl_event event = nullptr;
    const cl_int status = clEnqueueNDRangeKernel(ctx_->queue(), kernel.get(), 1, nullptr, &global, &wg_,
                                                 0, nullptr, profile_ ? &event : nullptr);
    if (event) {
      clWaitForEvents(1, &event);
      cl_ulong t0 = 0, t1 = 0;
      clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_START, sizeof(t0), &t0, nullptr);
      clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_END, sizeof(t1), &t1, nullptr);
      auto& entry = profileTimes_[kernel.name()];
      entry.first += 1;
      entry.second += static_cast<double>(t1 - t0) * 1e-9;
      clReleaseEvent(event);
    }
    if (status != CL_SUCCESS)
      fail(ErrorCode::DeviceError, "clEnqueueNDRangeKernel('", kernel.name(), "', ", global,
           " work-items) failed with ", cl::errorString(status), " on OpenCL device '", dev_, "'");
  }

  // -- transfers (blocking, through the staging area, converting to the device precision)
  void upload(const Buffer& buf, const double* src, std::size_t count);
  void download(const Buffer& buf, double* dst, std::size_t count);
  /// Reads sum_real values (PCG scalars: double in mixed precision, else the vector precision).
  void downloadSums(const Buffer& buf, double* dst, std::size_t count);
  template <class T>
  void uploadRaw(const Buffer& buf, const std::vector<T>& v) {
    checkCl(clEnqueueWriteBuffer(ctx_->queue(), buf.get(), CL_TRUE, 0, v.size() * sizeof(T), v.data(), 0,
                                 nullptr, nullptr),
            "clEnqueueWriteBuffer", dev_);
  }
  void createReal(Buffer& buf, std::size_t count) { buf.create(ctx_->context(), count * realSize_, dev_); }

  void checkVector(const Eigen::VectorXd& v, const char* what) const {
    if (static_cast<std::size_t>(v.size()) != dofs_)
      fail(ErrorCode::Internal, "OpenCL backend: ", what, " has ", v.size(), " entries, expected 3N = ",
           dofs_);
  }
  void coefficients(const SystemCoeffs& c, double& massCoef, double& stiffCoef) const {
    // A = m M + c (alpha M + beta K^R) + k K^R = (m + c alpha) M + (k + c beta) K^R.
    massCoef = c.mass + c.damping * rayleighMass_;
    stiffCoef = c.stiffness + c.damping * rayleighStiffness_;
  }
  /// y = A v (element product + gather), p . y partial sums per group into partials_.
  void product(const Buffer& v, const Buffer& y, double massCoef, double stiffCoef, bool project);
  void refreshBlocks(bool cornersWritten = false);  ///< cornersWritten: by compute_rotations
  void pcgSetup(double massCoef, double stiffCoef);     ///< preconditioner, r, z, p, rho from b_, x_
  void pcgIteration(double massCoef, double stiffCoef); ///< one PCG iteration, no host read

  std::shared_ptr<cl::Context> ctx_;
  std::string dev_;
  bool profile_ = false;  ///< COROFEM_OPENCL_PROFILE: per-kernel device times, printed on destruction
  std::map<std::string, std::pair<long, double>> profileTimes_;
  OpenCLOptions opts_;
  std::string options_;
  cl::ProgramBuild build_;
  bool double_ = false;
  bool mixed_ = false;          ///< float vectors, double dot products and PCG scalars
  std::size_t realSize_ = sizeof(float);
  std::size_t sumSize_ = sizeof(float);  ///< size of sum_real (corofem_layout.h)
  std::size_t wg_ = 64;
  std::size_t vec_ = 1;         ///< elements per work-item in the element kernels
  std::size_t elemItems_ = 0;   ///< work-items of the element kernels
  std::size_t chunk_ = 1;       ///< nodes per work-item in the PCG node kernels (corofem_reduce.h)
  std::size_t nodeItems_ = 0;   ///< work-items of the PCG node kernels
  std::size_t partialCount_ = 0;///< partial sums they write
  bool treeReduce_ = false;     ///< work-group trees in local memory (GPUs) or per-item partials
  Formulation formulation_;
  PreconditionerKind precond_;
  SolverDesc solver_;
  double lambda_ = 0, mu_ = 0, rayleighMass_ = 0, rayleighStiffness_ = 0;
  std::size_t nodes_ = 0, elems_ = 0, dofs_ = 0, stride_ = 0;
  std::size_t elemGroups_ = 0, nodeGroups_ = 0;
  std::vector<std::uint8_t> constrained_;
  std::vector<unsigned char> staging_;
  Eigen::VectorXd relative_;  ///< positions relative to their centroid (setPositions)
  double centroid_[3] = {0, 0, 0};  ///< that centroid

  Kernel kRotations_, kForces_, kEnergy_, kProduct_, kProductStored_, kGatherSum_, kGatherProduct_,
      kBlocks_, kCornerGradients_, kPrecondInvert_, kPcgInit_, kPcgUpdate_, kPcgDirection_, kReduceFinish_;
  Buffer elemNodes_, geom_, rot_, rotGrad_, quat_, stiffness_, elemOut_, nodeStart_, nodeEntries_;
  Buffer pos_, mass_, free_, blocks_, minv_, x_, b_, r_, z_, p_, q_, partials_, scalars_;
};

OpenCLBackend::OpenCLBackend(const Problem& problem, const SolverDesc& solver,
                             std::shared_ptr<cl::Context> ctx, const OpenCLOptions& options)
    : ctx_(std::move(ctx)), opts_(options), formulation_(problem.formulation),
      precond_(solver.preconditioner), solver_(solver) {
  dev_ = ctx_->deviceName();
  cl_command_queue_properties queueProps = 0;
  clGetCommandQueueInfo(ctx_->queue(), CL_QUEUE_PROPERTIES, sizeof(queueProps), &queueProps, nullptr);
  profile_ = (queueProps & CL_QUEUE_PROFILING_ENABLE) != 0;
  if (formulation_ != Formulation::Corotational && formulation_ != Formulation::Linear)
    fail(ErrorCode::BadInput, "body '", problem.name, "': the OpenCL backend implements the co-rotational "
         "and linear formulations only, not '", toString(formulation_),
         "'; use the reference backend (\"backend\": \"reference\") for this formulation");
  if (solver.linearSolver != LinearSolverKind::Pcg)
    fail(ErrorCode::BadInput, "body '", problem.name, "': the OpenCL backend solves with PCG only; "
         "\"cholesky\" is available on the reference backend (\"backend\": \"reference\")");
  double_ = solver.precision == Precision::Double;
  mixed_ = solver.precision == Precision::Mixed;
  const bool fp64 = ctx_->info().fp64 && !options.assumeNoFp64;
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
  wg_ = options.workGroupSize ? options.workGroupSize : kDefaultWorkGroup;
  vec_ = options.vectorWidth ? options.vectorWidth : (ctx_->info().gpu ? 1 : 8);
  if (const char* env = std::getenv("COROFEM_OPENCL_VEC"); env && *env && !options.vectorWidth)
    vec_ = static_cast<std::size_t>(std::strtoul(env, nullptr, 10));  // tuning experiments
  chunk_ = options.nodeChunk ? options.nodeChunk : (ctx_->info().gpu ? 1 : 4);  // 4: enough work-groups to balance 2+ threads on small meshes
  if (const char* env = std::getenv("COROFEM_OPENCL_CHUNK"); env && *env && !options.nodeChunk)
    chunk_ = std::max<std::size_t>(1, std::strtoul(env, nullptr, 10));  // tuning experiments
  if (vec_ != 1 && vec_ != 4 && vec_ != 8 && vec_ != 16)
    fail(ErrorCode::BadInput, "OpenCL element vector width ", vec_, " must be 1, 4, 8 or 16");
  if (const char* env = std::getenv("COROFEM_OPENCL_WG"); env && *env && !options.workGroupSize)
    wg_ = static_cast<std::size_t>(std::strtoul(env, nullptr, 10));  // tuning experiments
  if ((wg_ & (wg_ - 1)) != 0 || wg_ > ctx_->info().maxWorkGroupSize)
    fail(ErrorCode::BadInput, "OpenCL work-group size ", wg_, " must be a power of two <= ",
         ctx_->info().maxWorkGroupSize, " on device '", dev_, "'");

  nodes_ = problem.mesh.nodeCount();
  elems_ = problem.mesh.tetCount();
  dofs_ = 3 * nodes_;
  if (problem.elements.size() != elems_ || problem.dofCount() != dofs_)
    fail(ErrorCode::Internal, "OpenCL backend: problem '", problem.name, "' has ", problem.elements.size(),
         " element rest states for ", elems_, " tets and ", problem.dofCount(), " dofs for ", nodes_,
         " nodes");
  if (elems_ == 0) fail(ErrorCode::BadInput, "body '", problem.name, "' has no elements");
  const std::size_t widest = options.storedStiffness ? kStoredKComponents : kElemOutComponents;
  if ((elems_ + kStrideAlign) * widest >= (std::size_t(1) << 32) / 2)
    fail(ErrorCode::BadInput, "body '", problem.name, "': ", elems_, " elements exceed the OpenCL "
         "backend's 32-bit element indexing; split the body");
  stride_ = roundUp(elems_, kStrideAlign);
  elemItems_ = (elems_ + vec_ - 1) / vec_;
  elemGroups_ = roundUp(elemItems_, wg_) / wg_;
  nodeGroups_ = roundUp(std::max<std::size_t>(nodes_, 1), wg_) / wg_;
  nodeItems_ = (nodes_ + chunk_ - 1) / chunk_;
  treeReduce_ = options.treeReduce >= 0 ? options.treeReduce != 0 : ctx_->info().gpu;
  if (const char* env = std::getenv("COROFEM_OPENCL_TREE"); env && *env && options.treeReduce < 0)
    treeReduce_ = std::string(env) != "0";  // tuning experiments
  partialCount_ = roundUp(std::max<std::size_t>(nodeItems_, 1), wg_);
  if (treeReduce_) partialCount_ /= wg_;
  lambda_ = problem.lame.lambda;
  mu_ = problem.lame.mu;
  rayleighMass_ = problem.rayleighMass;
  rayleighStiffness_ = problem.rayleighStiffness;

  // -- program: only the features this problem uses
  options_ = "-cl-std=CL1.2 -DCOROFEM_WG=" + std::to_string(wg_) + " -DCOROFEM_VEC=" + std::to_string(vec_) +
             " -DCOROFEM_CHUNK=" + std::to_string(chunk_) + (treeReduce_ ? " -DCOROFEM_TREE_REDUCE" : "");
  if (double_) options_ += " -DCOROFEM_DOUBLE";
  if (mixed_) options_ += " -DCOROFEM_MIXED";
  switch (solver.rotation) {
    case RotationMethod::Polar: options_ += " -DCOROFEM_ROT_POLAR"; break;
    case RotationMethod::Svd: options_ += " -DCOROFEM_ROT_SVD"; break;
    case RotationMethod::Quaternion: options_ += " -DCOROFEM_ROT_QUAT"; break;
    case RotationMethod::Qr: options_ += " -DCOROFEM_ROT_QR"; break;
  }
  if (options.quaternionIterations > 0)
    options_ += " -DCOROFEM_QUAT_ITERS=" + std::to_string(options.quaternionIterations);
  if (precond_ == PreconditionerKind::BlockDiagonal) options_ += " -DCOROFEM_PRECOND_BLOCK";
  else if (precond_ == PreconditionerKind::Diagonal) options_ += " -DCOROFEM_PRECOND_DIAG";
  if (const char* extra = std::getenv("COROFEM_OPENCL_OPTIONS"); extra && *extra)
    options_ += std::string(" ") + extra;  // tuning experiments: extra compiler options
  static const std::string source = cl::corofemProgramSource();
  build_ = cl::buildProgram(*ctx_, "corofem", source, options_);
  kRotations_.create(build_.program, "compute_rotations", dev_);
  kForces_.create(build_.program, "element_forces", dev_);
  kEnergy_.create(build_.program, "element_energy", dev_);
  kProduct_.create(build_.program, "element_product", dev_);
  kProductStored_.create(build_.program, "element_product_stored", dev_);
  kGatherSum_.create(build_.program, "gather_sum", dev_);
  kGatherProduct_.create(build_.program, "gather_product", dev_);
  kBlocks_.create(build_.program, "node_stiffness_blocks", dev_);
  kCornerGradients_.create(build_.program, "corner_gradients", dev_);
  kPrecondInvert_.create(build_.program, "precond_invert", dev_);
  kPcgInit_.create(build_.program, "pcg_init", dev_);
  kPcgUpdate_.create(build_.program, "pcg_update", dev_);
  kPcgDirection_.create(build_.program, "pcg_direction", dev_);
  kReduceFinish_.create(build_.program, "reduce_finish", dev_);

  // -- element data, structure of arrays (kernels/shared/corofem_layout.h)
  const std::size_t S = stride_;
  cl_context c = ctx_->context();
  {
    std::vector<cl_uint> nodes(kElemNodeComponents * S, 0);
    for (std::size_t e = 0; e < elems_; ++e)
      for (std::size_t k = 0; k < 4; ++k) nodes[k * S + e] = problem.mesh.tets[4 * e + k];
    elemNodes_.create(c, nodes.size() * sizeof(cl_uint), dev_);
    uploadRaw(elemNodes_, nodes);
  }
  {
    std::vector<double> geom(kGeomComponents * S, 0.0), rot(kRotComponents * S, 0.0),
        quat(kQuatComponents * S, 0.0);
    for (std::size_t e = 0; e < elems_; ++e) {
      const ElementRest& rest = problem.elements[e];
      for (int i = 1; i < 4; ++i)
        for (int k = 0; k < 3; ++k) geom[(3 * (i - 1) + k) * S + e] = rest.grad(i, k);
      geom[kGeomVolume * S + e] = rest.volume;
      rot[0 * S + e] = rot[4 * S + e] = rot[8 * S + e] = 1.0;
      quat[3 * S + e] = 1.0;
    }
    createReal(geom_, geom.size());
    upload(geom_, geom.data(), geom.size());
    createReal(rot_, rot.size());
    upload(rot_, rot.data(), rot.size());
    // At rest (and always for the linear formulation) R = I, so a_i = grad N_i.
    createReal(rotGrad_, kRotGradComponents * S);
    upload(rotGrad_, geom.data(), kRotGradComponents * S);
    // The warm-start quaternions exist only for the Quaternion method (a 1-real stand-in otherwise).
    if (solver.rotation == RotationMethod::Quaternion) {
      createReal(quat_, quat.size());
      upload(quat_, quat.data(), quat.size());
    } else {
      createReal(quat_, 1);
    }
  }
  if (opts_.storedStiffness) {
    std::vector<double> K(kStoredKComponents * S, 0.0);
    for (std::size_t e = 0; e < elems_; ++e) {
      const Mat12 Ke = linearStiffness(problem.elements[e], problem.lame);
      std::size_t idx = 0;
      for (int r = 0; r < 12; ++r)
        for (int col = r; col < 12; ++col, ++idx) K[idx * S + e] = Ke(r, col);
    }
    createReal(stiffness_, K.size());
    upload(stiffness_, K.data(), K.size());
  }
  createReal(elemOut_, kElemOutComponents * S);

  // -- node gather lists (CSR, fixed order: by element, then corner)
  {
    std::vector<cl_uint> start(nodes_ + 1, 0), entries(4 * elems_);
    for (std::size_t e = 0; e < elems_; ++e)
      for (int k = 0; k < 4; ++k) ++start[problem.mesh.tets[4 * e + k] + 1];
    for (std::size_t n = 0; n < nodes_; ++n) start[n + 1] += start[n];
    std::vector<cl_uint> fill(start.begin(), start.end() - 1);
    for (std::size_t e = 0; e < elems_; ++e)
      for (int k = 0; k < 4; ++k)
        entries[fill[problem.mesh.tets[4 * e + k]]++] =
            static_cast<cl_uint>(((e / vec_) * 12 + 3 * k) * vec_ + e % vec_);
    nodeStart_.create(c, start.size() * sizeof(cl_uint), dev_);
    uploadRaw(nodeStart_, start);
    nodeEntries_.create(c, entries.size() * sizeof(cl_uint), dev_);
    uploadRaw(nodeEntries_, entries);
  }

  // -- node data
  createReal(pos_, dofs_);
  upload(pos_, problem.restPositions.data(), dofs_);
  {
    std::vector<double> mass(dofs_, 0.0), freeMask(dofs_, 1.0);
    if (static_cast<std::size_t>(problem.lumpedMass.size()) == dofs_)
      for (std::size_t d = 0; d < dofs_; ++d) mass[d] = problem.lumpedMass[d];
    constrained_.assign(dofs_, 0);
    if (problem.constrained.size() == dofs_) constrained_ = problem.constrained;
    for (std::size_t d = 0; d < dofs_; ++d)
      if (constrained_[d]) freeMask[d] = 0.0;
    createReal(mass_, dofs_);
    upload(mass_, mass.data(), dofs_);
    createReal(free_, dofs_);
    upload(free_, freeMask.data(), dofs_);
  }
  createReal(blocks_, kNodeBlockComponents * nodes_);
  createReal(minv_, (precond_ == PreconditionerKind::BlockDiagonal ? 9 : 3) * nodes_);
  for (Buffer* v : {&x_, &b_, &r_, &z_, &p_, &q_}) createReal(*v, dofs_);
  // Partials: the PCG node kernels write sum_real triples; element_energy writes one real per group
  // into the same buffer (at most sumSize_ bytes each, so the sum_real size covers both).
  partials_.create(c, kPartialComponents * std::max(elemGroups_, partialCount_) * sumSize_, dev_);
  scalars_.create(c, kScalarCount * sumSize_, dev_);
  refreshBlocks();
  finish();
}

void OpenCLBackend::upload(const Buffer& buf, const double* src, std::size_t count) {
  staging_.resize(count * realSize_);
  if (double_) {
    std::memcpy(staging_.data(), src, count * sizeof(double));
  } else {
    float* out = reinterpret_cast<float*>(staging_.data());
    for (std::size_t i = 0; i < count; ++i) out[i] = static_cast<float>(src[i]);
  }
  checkCl(clEnqueueWriteBuffer(ctx_->queue(), buf.get(), CL_TRUE, 0, count * realSize_, staging_.data(), 0,
                               nullptr, nullptr),
          "clEnqueueWriteBuffer", dev_);
}

void OpenCLBackend::download(const Buffer& buf, double* dst, std::size_t count) {
  staging_.resize(count * realSize_);
  checkCl(clEnqueueReadBuffer(ctx_->queue(), buf.get(), CL_TRUE, 0, count * realSize_, staging_.data(), 0,
                              nullptr, nullptr),
          "clEnqueueReadBuffer", dev_);
  if (double_) {
    std::memcpy(dst, staging_.data(), count * sizeof(double));
  } else {
    const float* in = reinterpret_cast<const float*>(staging_.data());
    for (std::size_t i = 0; i < count; ++i) dst[i] = in[i];
  }
}

void OpenCLBackend::downloadSums(const Buffer& buf, double* dst, std::size_t count) {
  if (!mixed_) {
    download(buf, dst, count);
    return;
  }
  checkCl(clEnqueueReadBuffer(ctx_->queue(), buf.get(), CL_TRUE, 0, count * sizeof(double), dst, 0, nullptr,
                              nullptr),
          "clEnqueueReadBuffer", dev_);
}

void OpenCLBackend::refreshBlocks(bool cornersWritten) {
  if (precond_ == PreconditionerKind::None) return;
  if (!cornersWritten)
    launch(kCornerGradients_, elemItems_, cl_uint(elems_), cl_uint(stride_), geom_, rotGrad_, elemOut_);
  launch(kBlocks_, nodes_, cl_uint(nodes_), cl_uint(stride_), nodeStart_, nodeEntries_, elemOut_, geom_,
         RealArg{lambda_}, RealArg{mu_}, blocks_);
}

void OpenCLBackend::enqueueRotations() {
  if (formulation_ != Formulation::Corotational) return;
  launch(kRotations_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, geom_, pos_, rot_, rotGrad_,
         quat_, elemOut_, cl_uint(precond_ != PreconditionerKind::None ? 1 : 0));
}

void OpenCLBackend::setPositions(const Eigen::VectorXd& x) {
  checkVector(x, "the positions");
  // Every kernel uses positions only through differences (F = sum (x_i - x_0) grad N_i^T, forces
  // and energy from F), so the device gets them relative to their centroid, subtracted in double:
  // a float body 1e4 m from the origin keeps the resolution of one near it.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (std::size_t n = 0; n < nodes_; ++n) centroid += x.segment<3>(static_cast<Eigen::Index>(3 * n));
  centroid /= static_cast<double>(std::max<std::size_t>(nodes_, 1));
  relative_.resize(static_cast<Eigen::Index>(dofs_));
  for (std::size_t n = 0; n < nodes_; ++n)
    relative_.segment<3>(static_cast<Eigen::Index>(3 * n)) = x.segment<3>(static_cast<Eigen::Index>(3 * n)) - centroid;
  upload(pos_, relative_.data(), dofs_);
  for (int a = 0; a < 3; ++a) centroid_[a] = centroid[a];
  enqueueRotations();
  if (formulation_ == Formulation::Corotational) refreshBlocks(true);  // the blocks rotate with R
}

void OpenCLBackend::enqueueElementForces() {
  launch(kForces_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, geom_, rotGrad_, pos_,
         RealArg{lambda_}, RealArg{mu_}, elemOut_);
}

void OpenCLBackend::enqueueForces() {
  enqueueElementForces();
  launch(kGatherSum_, nodes_, cl_uint(nodes_), nodeStart_, nodeEntries_, elemOut_, q_);
}

void OpenCLBackend::internalForces(Eigen::VectorXd& f) {
  enqueueForces();
  f.resize(static_cast<Eigen::Index>(dofs_));
  download(q_, f.data(), dofs_);
}

void OpenCLBackend::enqueueElementProduct(const SystemCoeffs& c) {
  double massCoef = 0, stiffCoef = 0;
  coefficients(c, massCoef, stiffCoef);
  if (opts_.storedStiffness)
    launch(kProductStored_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, stiffness_, rot_, p_,
           RealArg{stiffCoef}, elemOut_);
  else
    launch(kProduct_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, geom_, rotGrad_, p_,
           RealArg{stiffCoef * lambda_}, RealArg{stiffCoef * mu_}, elemOut_);
}

void OpenCLBackend::product(const Buffer& v, const Buffer& y, double massCoef, double stiffCoef,
                            bool project) {
  if (opts_.storedStiffness)
    launch(kProductStored_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, stiffness_, rot_, v,
           RealArg{stiffCoef}, elemOut_);
  else
    launch(kProduct_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, geom_, rotGrad_, v,
           RealArg{stiffCoef * lambda_}, RealArg{stiffCoef * mu_}, elemOut_);
  launch(kGatherProduct_, nodeItems_, cl_uint(nodes_), nodeStart_, nodeEntries_, elemOut_,
         mass_, RealArg{massCoef}, free_, cl_uint(project ? 1 : 0), v, y, partials_);
}

void OpenCLBackend::enqueueProduct(const SystemCoeffs& c) {
  double massCoef = 0, stiffCoef = 0;
  coefficients(c, massCoef, stiffCoef);
  product(p_, q_, massCoef, stiffCoef, false);
}

void OpenCLBackend::apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
  checkVector(p, "the vector p of apply");
  upload(p_, p.data(), dofs_);
  enqueueProduct(c);
  y.resize(static_cast<Eigen::Index>(dofs_));
  download(q_, y.data(), dofs_);
}

void OpenCLBackend::pcgSetup(double massCoef, double stiffCoef) {
  if (precond_ != PreconditionerKind::None)
    launch(kPrecondInvert_, nodes_, cl_uint(nodes_), blocks_, mass_, RealArg{massCoef}, RealArg{stiffCoef},
           free_, minv_);
  // r = b - A x (projected), z = M^-1 r, p = z, rho = r.z, rr = r.r, bb = b.b
  product(x_, q_, massCoef, stiffCoef, true);
  launch(kPcgInit_, nodeItems_, cl_uint(nodes_), b_, q_, free_, minv_, r_, z_, p_, partials_);
  launch(kReduceFinish_, 1, cl_uint(partialCount_), partials_, scalars_, cl_uint(kReduceInit));
}

void OpenCLBackend::pcgIteration(double massCoef, double stiffCoef) {
  const cl_uint groups = cl_uint(partialCount_);
  product(p_, q_, massCoef, stiffCoef, true);  // q = A p, partial p.q
  launch(kReduceFinish_, 1, groups, partials_, scalars_, cl_uint(kReduceAlpha));
  launch(kPcgUpdate_, nodeItems_, cl_uint(nodes_), scalars_, p_, q_, minv_, x_, r_, z_, partials_);
  launch(kReduceFinish_, 1, groups, partials_, scalars_, cl_uint(kReduceBeta));
  launch(kPcgDirection_, dofs_, cl_uint(dofs_), scalars_, z_, p_);
}

void OpenCLBackend::enqueuePcgIterations(const SystemCoeffs& c, int iterations) {
  double massCoef = 0, stiffCoef = 0;
  coefficients(c, massCoef, stiffCoef);
  pcgSetup(massCoef, stiffCoef);
  for (int i = 0; i < iterations; ++i) pcgIteration(massCoef, stiffCoef);
}

LinearSolveStats OpenCLBackend::solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  checkVector(b, "the right-hand side b");
  if (static_cast<std::size_t>(x.size()) != dofs_) x = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(dofs_));
  LinearSolveStats stats;
  double bb = 0.0;
  for (std::size_t d = 0; d < dofs_; ++d)
    if (!constrained_[d]) bb += b[d] * b[d];
  if (!std::isfinite(bb))
    fail(ErrorCode::SolveFailed, "OpenCL PCG: the right-hand side is not finite (NaN or Inf in b); the "
         "state diverged before the linear solve");
  if (bb == 0.0) {
    x.setZero();
    stats.converged = true;
    return stats;
  }
  double massCoef = 0, stiffCoef = 0;
  coefficients(c, massCoef, stiffCoef);

  Eigen::VectorXd x0 = x;
  for (std::size_t d = 0; d < dofs_; ++d)
    if (constrained_[d] || !std::isfinite(x0[d])) x0[d] = 0.0;
  upload(b_, b.data(), dofs_);
  upload(x_, x0.data(), dofs_);
  pcgSetup(massCoef, stiffCoef);
  const cl_uint groups = cl_uint(partialCount_);

  const double tol = solver_.tolerance;
  const int checkEvery = std::max(1, solver_.checkEvery);
  std::vector<double> scalars(kScalarCount);
  auto readScalars = [&]() { downloadSums(scalars_, scalars.data(), kScalarCount); };
  auto relative = [&]() { return std::sqrt(std::max(0.0, scalars[kScalarRr]) / scalars[kScalarBb]); };

  readScalars();
  stats.relativeResidual = relative();
  bool finite = std::isfinite(stats.relativeResidual);
  stats.converged = finite && stats.relativeResidual <= tol;
  int it = 0;
  while (finite && !stats.converged && it < solver_.maxIterations) {
    pcgIteration(massCoef, stiffCoef);
    ++it;
    if (it % checkEvery == 0 || it == solver_.maxIterations) {
      readScalars();
      stats.relativeResidual = relative();
      finite = std::isfinite(stats.relativeResidual);
      stats.converged = finite && stats.relativeResidual <= tol;
      if (scalars[kScalarBreakdown] != 0.0) break;  // p.Ap <= 0: no further progress possible
    }
  }
  stats.iterations = it;
  if (finite && it > 0) {
    // The reported residual is the true one, |free (b - A x)| / |free b| (as the interface
    // defines it), not the recurrence's estimate, which drifts from it in float: one more product.
    // The convergence decision above stays the recurrence's (the standard PCG stop test).
    product(x_, q_, massCoef, stiffCoef, true);
    launch(kPcgInit_, nodeItems_, cl_uint(nodes_), b_, q_, free_, minv_, r_, z_, p_, partials_);
    launch(kReduceFinish_, 1, groups, partials_, scalars_, cl_uint(kReduceInit));
    readScalars();
    stats.relativeResidual = relative();
    finite = std::isfinite(stats.relativeResidual);
  }
  if (!finite)
    fail(ErrorCode::SolveFailed, "OpenCL PCG produced a non-finite residual after ", it, " iterations on "
         "device '", dev_, "' (the system matrix or the right-hand side holds NaN/Inf, or ",
         double_ ? "double" : mixed_ ? "mixed" : "float", " precision overflowed); check the material, "
         "time step and loads");
  Eigen::VectorXd out(static_cast<Eigen::Index>(dofs_));
  download(x_, out.data(), dofs_);
  if (!out.allFinite())
    fail(ErrorCode::SolveFailed, "OpenCL PCG produced a non-finite solution on device '", dev_, "'");
  x = std::move(out);
  return stats;
}

double OpenCLBackend::elasticEnergy() {
  launch(kEnergy_, elemItems_, cl_uint(elems_), cl_uint(stride_), elemNodes_, geom_, rotGrad_, pos_,
         RealArg{lambda_}, RealArg{mu_}, elemOut_, partials_);
  std::vector<double> partial(elemGroups_);
  download(partials_, partial.data(), elemGroups_);
  double sum = 0.0;
  for (double v : partial) sum += v;  // fixed order: deterministic
  return sum;
}

std::vector<double> OpenCLBackend::readRotations() {
  std::vector<double> soa(kRotComponents * stride_);
  download(rot_, soa.data(), soa.size());
  std::vector<double> out(9 * elems_);
  for (std::size_t e = 0; e < elems_; ++e)
    for (std::size_t k = 0; k < 9; ++k) out[9 * e + k] = soa[k * stride_ + e];
  return out;
}

}  // namespace

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendOn(const Problem& problem, const SolverDesc& solver,
                                                             std::shared_ptr<cl::Context> context,
                                                             const OpenCLOptions& options) {
  return std::make_unique<OpenCLBackend>(problem, solver, std::move(context), options);
}

std::unique_ptr<OpenCLBackendInternal> createOpenCLBackendAdopting(const Problem& problem,
                                                                   const SolverDesc& solver,
                                                                   cl_context context,
                                                                   cl_command_queue queue,
                                                                   cl_device_id device,
                                                                   const OpenCLOptions& options) {
  return createOpenCLBackendOn(problem, solver, cl::Context::adopt(context, queue, device), options);
}

std::unique_ptr<Backend> createOpenCLBackend(const Problem& problem, const SolverDesc& solver,
                                             const std::string& deviceSelector) {
  return createOpenCLBackendOn(problem, solver, cl::Context::shared(deviceSelector));
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
