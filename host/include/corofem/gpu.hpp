// Handles of an application's GPU objects as corofem takes and gives them: a buffer a renderer draws
// from (GpuBuffer) and the device objects an application lends (ExternalDevice). Plain values of
// no API's types, so that this header and everything that includes it compile without OpenCL or
// Vulkan headers; the application casts them to its API's types.
#pragma once

#include <cstddef>
#include <cstdint>

namespace corofem {

/// The API a handle belongs to.
enum class GpuApi {
  None,    ///< no handle (a host device, or nothing to give)
  OpenCL,  ///< cl_mem, cl_context, cl_command_queue, cl_device_id
  Vulkan,  ///< VkBuffer, VkDevice, ... (the Vulkan backend)
};

/// A region of a device buffer holding vertices, as a renderer binds it.
///
///   corofem::GpuBuffer b = sim.surfaceBuffer(0);
///   if (b.api == corofem::GpuApi::OpenCL) {
///     cl_mem mem = reinterpret_cast<cl_mem>(static_cast<std::uintptr_t>(b.handle));
///     // vertex v at byte b.offset + v * b.stride
///   }
struct GpuBuffer {
  GpuApi api = GpuApi::None;
  /// The API's handle as an integer: OpenCL, the cl_mem (a pointer); Vulkan, the VkBuffer (a
  /// 64-bit non-dispatchable handle). 0: none.
  std::uint64_t handle = 0;
  std::size_t offset = 0;  ///< bytes from the buffer's start to the first vertex
  std::size_t stride = 0;  ///< bytes from one vertex to the next
  std::size_t bytes = 0;   ///< bytes of the region: vertex count * stride
  explicit operator bool() const { return handle != 0; }
};

/// Device objects that an application owns and lends to corofem, which uses them for as long as it
/// lives and never destroys them; the application keeps them alive meanwhile.
///
/// OpenCL (api = GpuApi::OpenCL): `context`, an in-order `queue` on it and that queue's `device`
/// (a cl_context, cl_command_queue and cl_device_id, all three, retained while used). corofem's
/// buffers and kernels then live in the application's context, so that its output buffers can be
/// shared with the application's own work on the queue.
///
/// Vulkan (api = GpuApi::Vulkan): `instance`, `physicalDevice`, `device` (a VkInstance,
/// VkPhysicalDevice and VkDevice) and a `queue` (VkQueue) of family `queueFamily` that supports
/// compute; `context` is not used. corofem's buffers, pipelines and command buffers then live on the
/// application's device, so a renderer draws the surfaces (Simulation::surfaceBuffer) from
/// corofem's VkBuffers directly. corofem submits to the queue only from inside its own calls; Vulkan
/// asks that no other thread submit to the same queue meanwhile (the application's lock, if it
/// shares the queue between threads). The device needs Vulkan 1.1 (the instance created with
/// apiVersion 1.1 or later) and no extension; `shaderFloat64` says whether it was created with that
/// feature enabled, which double precision needs (Vulkan cannot be asked). corofem's buffers are
/// exclusive to the lent queue's family. The application waits for its own submissions that read
/// corofem's buffers before destroying the Simulation or removing a body of a batch (corofem waits
/// only for its own work).
struct ExternalDevice {
  GpuApi api = GpuApi::None;  ///< None: none lent
  void* context = nullptr;    ///< OpenCL: cl_context
  void* queue = nullptr;      ///< OpenCL: cl_command_queue; Vulkan: VkQueue
  void* device = nullptr;     ///< OpenCL: cl_device_id; Vulkan: VkDevice
  void* instance = nullptr;        ///< Vulkan: VkInstance
  void* physicalDevice = nullptr;  ///< Vulkan: VkPhysicalDevice
  std::uint32_t queueFamily = 0;   ///< Vulkan: the family of `queue`
  bool shaderFloat64 = false;      ///< Vulkan: `device` has the shaderFloat64 feature enabled
  explicit operator bool() const { return api != GpuApi::None; }
};

}  // namespace corofem
