// OpenCL device discovery and the context/queue the backend runs on: every platform is searched
// (GPUs and the PoCL CPU device), a selector string picks one, and an embedding application can
// hand over its own cl_context / queue / device instead (the host owns the device).
#pragma once

#include "backends/opencl/cl_check.hpp"

#include <corofem/gpu.hpp>

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace corofem::detail::cl {

/// What the backend needs to know about a device.
struct DeviceInfo {
  cl_platform_id platform = nullptr;
  cl_device_id device = nullptr;
  std::string name;           ///< CL_DEVICE_NAME
  std::string platformName;   ///< CL_PLATFORM_NAME
  std::string driverVersion;  ///< CL_DRIVER_VERSION
  std::string deviceVersion;  ///< CL_DEVICE_VERSION
  bool gpu = false;
  bool cpu = false;           ///< CL_DEVICE_TYPE_CPU (the host's own cores, e.g. PoCL)
  bool fp64 = false;          ///< cl_khr_fp64 (double precision kernels)
  cl_ulong globalMemoryBytes = 0;
  cl_uint computeUnits = 0;
  std::size_t maxWorkGroupSize = 0;

  /// "NVIDIA GeForce ... (GPU, NVIDIA CUDA, fp64)"
  std::string describe() const;
};

/// Every device of every platform, in discovery order (the selector's index refers to this
/// order). Never throws: no platform means an empty list.
std::vector<DeviceInfo> listDevices();

/// Queries one device.
DeviceInfo queryDevice(cl_device_id device);

/// One line per device: "  0: name (CPU, Portable Computing Language, fp64)".
std::string describeDevices(const std::vector<DeviceInfo>& devices);

/// Picks a device: "" = the first GPU, else the first device; a number = index into listDevices();
/// anything else = case-insensitive substring of the device name (first match). Throws
/// Error(DeviceError) listing the available devices when nothing matches.
DeviceInfo selectDevice(const std::string& selector);

/// A context, an in-order queue and the device, retained for the object's lifetime, plus the
/// programs built on this context (in-memory cache, see program_cache.hpp).
class Context {
 public:
  /// A new context on the selected device.
  static std::shared_ptr<Context> create(const std::string& selector);
  /// The process-wide context of the selected device (created on first use), so that backends on
  /// one device share built programs.
  static std::shared_ptr<Context> shared(const std::string& selector);
  /// Adopts an application's context, queue and device (retained here, released on destruction).
  static std::shared_ptr<Context> adopt(cl_context context, cl_command_queue queue, cl_device_id device);
  /// The same from an application's handles (GpuApi::OpenCL, all three); `what` names the option
  /// in errors. Throws Error(BadInput) for another API or a missing handle.
  static std::shared_ptr<Context> adopt(const ExternalDevice& external, const std::string& what);

  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  cl_context context() const { return context_; }
  cl_command_queue queue() const { return queue_; }
  cl_device_id device() const { return info_.device; }
  const DeviceInfo& info() const { return info_; }
  const std::string& deviceName() const { return info_.name; }

  /// In-memory program cache of this context (program_cache.cpp). Returns nullptr when absent.
  cl_program findProgram(const std::string& key);
  /// Stores a built program (takes ownership of one reference).
  void storeProgram(const std::string& key, cl_program program);

 private:
  friend struct ContextTestAccess;  // tests/common/opencl_test_access.hpp
  Context() = default;
  static std::shared_ptr<Context> createOn(const DeviceInfo& info);
  DeviceInfo info_;
  cl_context context_ = nullptr;
  cl_command_queue queue_ = nullptr;
  std::mutex mutex_;
  std::map<std::string, cl_program> programs_;
};

/// A GpuBuffer of an OpenCL buffer: `count` vertices of `stride` bytes from byte `offset`.
GpuBuffer bufferOf(cl_mem buffer, std::size_t offset = 0, std::size_t stride = 0, std::size_t count = 0);
/// The cl_mem of an OpenCL GpuBuffer; throws Error(BadInput), naming `what`, for an empty handle or
/// another API.
cl_mem memOf(const GpuBuffer& buffer, const std::string& what);

}  // namespace corofem::detail::cl
