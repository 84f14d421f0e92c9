// Device discovery, selection and context ownership (cl_context.hpp).
#include "backends/opencl/cl_context.hpp"

#include "device/registry.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <sstream>

namespace corofem::detail::cl {

namespace {

std::string deviceString(cl_device_id device, cl_device_info what) {
  std::size_t size = 0;
  if (clGetDeviceInfo(device, what, 0, nullptr, &size) != CL_SUCCESS || size == 0) return {};
  std::string s(size, '\0');
  if (clGetDeviceInfo(device, what, size, s.data(), nullptr) != CL_SUCCESS) return {};
  while (!s.empty() && (s.back() == '\0' || s.back() == ' ')) s.pop_back();
  return s;
}

std::string platformString(cl_platform_id platform, cl_platform_info what) {
  std::size_t size = 0;
  if (clGetPlatformInfo(platform, what, 0, nullptr, &size) != CL_SUCCESS || size == 0) return {};
  std::string s(size, '\0');
  if (clGetPlatformInfo(platform, what, size, s.data(), nullptr) != CL_SUCCESS) return {};
  while (!s.empty() && (s.back() == '\0' || s.back() == ' ')) s.pop_back();
  return s;
}

}  // namespace

std::string DeviceInfo::describe() const {
  std::ostringstream os;
  os << name << " (" << (gpu ? "GPU" : "CPU/other") << ", " << platformName << ", "
     << (fp64 ? "fp64" : "no fp64") << ")";
  return os.str();
}

DeviceInfo queryDevice(cl_device_id device) {
  DeviceInfo info;
  info.device = device;
  clGetDeviceInfo(device, CL_DEVICE_PLATFORM, sizeof(info.platform), &info.platform, nullptr);
  info.name = deviceString(device, CL_DEVICE_NAME);
  info.driverVersion = deviceString(device, CL_DRIVER_VERSION);
  info.deviceVersion = deviceString(device, CL_DEVICE_VERSION);
  if (info.platform) info.platformName = platformString(info.platform, CL_PLATFORM_NAME);
  cl_device_type type = 0;
  clGetDeviceInfo(device, CL_DEVICE_TYPE, sizeof(type), &type, nullptr);
  info.gpu = (type & CL_DEVICE_TYPE_GPU) != 0;
  info.cpu = (type & CL_DEVICE_TYPE_CPU) != 0;
  const std::string extensions = deviceString(device, CL_DEVICE_EXTENSIONS);
  info.fp64 = extensions.find("cl_khr_fp64") != std::string::npos;
  clGetDeviceInfo(device, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof(info.globalMemoryBytes),
                  &info.globalMemoryBytes, nullptr);
  clGetDeviceInfo(device, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof(info.computeUnits), &info.computeUnits,
                  nullptr);
  clGetDeviceInfo(device, CL_DEVICE_MAX_WORK_GROUP_SIZE, sizeof(info.maxWorkGroupSize),
                  &info.maxWorkGroupSize, nullptr);
  return info;
}

std::vector<DeviceInfo> listDevices() {
  std::vector<DeviceInfo> out;
  cl_uint platformCount = 0;
  if (clGetPlatformIDs(0, nullptr, &platformCount) != CL_SUCCESS || platformCount == 0) return out;
  std::vector<cl_platform_id> platforms(platformCount);
  if (clGetPlatformIDs(platformCount, platforms.data(), nullptr) != CL_SUCCESS) return out;
  for (cl_platform_id platform : platforms) {
    cl_uint count = 0;
    if (clGetDeviceIDs(platform, CL_DEVICE_TYPE_ALL, 0, nullptr, &count) != CL_SUCCESS || count == 0)
      continue;
    std::vector<cl_device_id> devices(count);
    if (clGetDeviceIDs(platform, CL_DEVICE_TYPE_ALL, count, devices.data(), nullptr) != CL_SUCCESS)
      continue;
    for (cl_device_id d : devices) out.push_back(queryDevice(d));
  }
  return out;
}

std::string describeDevices(const std::vector<DeviceInfo>& devices) {
  std::ostringstream os;
  if (devices.empty()) os << "  (none: no OpenCL platform or device was found; install a driver or "
                             "pocl-opencl-icd for the CPU)\n";
  for (std::size_t i = 0; i < devices.size(); ++i) os << "  " << i << ": " << devices[i].describe() << "\n";
  return os.str();
}

DeviceInfo selectDevice(const std::string& selector) {
  const std::vector<DeviceInfo> devices = listDevices();
  if (devices.empty())
    fail(ErrorCode::DeviceError, "no OpenCL device found (no platform reports a device); install a "
                                 "GPU driver or pocl-opencl-icd, or use \"backend\": \"reference\"");
  std::vector<std::string> names;
  std::vector<bool> gpu;
  for (const DeviceInfo& d : devices) {
    names.push_back(d.name);
    gpu.push_back(d.gpu);
  }
  if (const std::size_t i = selectDeviceIndex(names, gpu, selector); i < devices.size()) return devices[i];
  fail(ErrorCode::DeviceError, "OpenCL device selector '", selector,
       "' matches no device; give an index or a part of a name from this list:\n",
       describeDevices(devices));
}

std::shared_ptr<Context> Context::createOn(const DeviceInfo& info) {
  std::shared_ptr<Context> ctx(new Context());
  ctx->info_ = info;
  cl_int status = CL_SUCCESS;
  cl_context_properties props[] = {CL_CONTEXT_PLATFORM,
                                   reinterpret_cast<cl_context_properties>(info.platform), 0};
  ctx->context_ = clCreateContext(props, 1, &info.device, nullptr, nullptr, &status);
  checkCl(status, "clCreateContext", info.name);
  ctx->queue_ = clCreateCommandQueue(ctx->context_, info.device, 0, &status);
  checkCl(status, "clCreateCommandQueue", info.name);
  return ctx;
}

std::shared_ptr<Context> Context::create(const std::string& selector) {
  return createOn(selectDevice(selector));
}

std::shared_ptr<Context> Context::shared(const std::string& selector) {
  static std::mutex mutex;
  static std::map<cl_device_id, std::weak_ptr<Context>> contexts;
  const DeviceInfo info = selectDevice(selector);
  std::lock_guard<std::mutex> lock(mutex);
  if (auto existing = contexts[info.device].lock()) return existing;
  auto made = createOn(info);
  contexts[info.device] = made;
  return made;
}

std::shared_ptr<Context> Context::adopt(const ExternalDevice& external, const std::string& what) {
  if (external.api != GpuApi::OpenCL)
    fail(ErrorCode::BadInput, what, ": the handles are not OpenCL's (ExternalDevice::api); this device takes an "
         "OpenCL context, queue and device");
  if (!external.context || !external.queue || !external.device)
    fail(ErrorCode::BadInput, what, ": give the OpenCL context, queue and device together");
  return adopt(static_cast<cl_context>(external.context), static_cast<cl_command_queue>(external.queue),
               static_cast<cl_device_id>(external.device));
}

GpuBuffer bufferOf(cl_mem buffer, std::size_t offset, std::size_t stride, std::size_t count) {
  GpuBuffer b;
  if (!buffer) return b;
  b.api = GpuApi::OpenCL;
  b.handle = static_cast<std::uint64_t>(reinterpret_cast<std::uintptr_t>(buffer));
  b.offset = offset;
  b.stride = stride;
  b.bytes = stride * count;
  return b;
}

cl_mem memOf(const GpuBuffer& buffer, const std::string& what) {
  if (buffer.api != GpuApi::OpenCL || !buffer.handle)
    fail(ErrorCode::BadInput, what, ": ", buffer.handle ? "the buffer is not an OpenCL one (GpuBuffer::api)" : "the buffer is empty",
         "; give a cl_mem as GpuBuffer{GpuApi::OpenCL, handle}");
  return reinterpret_cast<cl_mem>(static_cast<std::uintptr_t>(buffer.handle));
}

std::shared_ptr<Context> Context::adopt(cl_context context, cl_command_queue queue, cl_device_id device) {
  if (!context || !queue || !device)
    fail(ErrorCode::BadInput, "adopting an OpenCL context: the context, queue and device must all be "
                              "non-null");
  std::shared_ptr<Context> ctx(new Context());
  ctx->info_ = queryDevice(device);
  // The backend orders its commands (non-blocking writes, kernels, reads of the PCG scalars) by the
  // queue alone: an out-of-order queue, or one of another context or device, would run them wrong.
  cl_context queueContext = nullptr;
  cl_device_id queueDevice = nullptr;
  cl_command_queue_properties properties = 0;
  checkCl(clGetCommandQueueInfo(queue, CL_QUEUE_CONTEXT, sizeof(queueContext), &queueContext, nullptr),
          "clGetCommandQueueInfo(CL_QUEUE_CONTEXT)", ctx->info_.name);
  checkCl(clGetCommandQueueInfo(queue, CL_QUEUE_DEVICE, sizeof(queueDevice), &queueDevice, nullptr),
          "clGetCommandQueueInfo(CL_QUEUE_DEVICE)", ctx->info_.name);
  checkCl(clGetCommandQueueInfo(queue, CL_QUEUE_PROPERTIES, sizeof(properties), &properties, nullptr),
          "clGetCommandQueueInfo(CL_QUEUE_PROPERTIES)", ctx->info_.name);
  if (queueContext != context || queueDevice != device)
    fail(ErrorCode::BadInput, "adopting an OpenCL context on '", ctx->info_.name, "': the command queue belongs "
         "to another ", queueContext != context ? "context" : "device", "; pass the queue created for this "
         "context and device");
  if (properties & CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE)
    fail(ErrorCode::BadInput, "adopting an OpenCL context on '", ctx->info_.name, "': the command queue is "
         "out of order, and the backend relies on the queue's order; create an in-order queue for it "
         "(without CL_QUEUE_OUT_OF_ORDER_EXEC_MODE_ENABLE)");
  checkCl(clRetainContext(context), "clRetainContext", ctx->info_.name);
  ctx->context_ = context;
  checkCl(clRetainCommandQueue(queue), "clRetainCommandQueue", ctx->info_.name);
  ctx->queue_ = queue;
  return ctx;
}

Context::~Context() {
  for (auto& entry : programs_) clReleaseProgram(entry.second);
  if (queue_) {
    clFinish(queue_);
    clReleaseCommandQueue(queue_);
  }
  if (context_) clReleaseContext(context_);
}

cl_program Context::findProgram(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = programs_.find(key);
  return it == programs_.end() ? nullptr : it->second;
}

void Context::storeProgram(const std::string& key, cl_program program) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = programs_.find(key);
  if (it != programs_.end()) {
    clReleaseProgram(it->second);
    it->second = program;
  } else {
    programs_[key] = program;
  }
}

}  // namespace corofem::detail::cl
