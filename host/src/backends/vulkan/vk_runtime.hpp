// The Vulkan objects the backend needs, each owned once: the instance (shared by every device of
// the process), a logical device with one compute queue, buffers, the compute pipelines of the
// embedded shaders over one descriptor-set layout, and a ring of command buffers with their fences.
// Every failed Vulkan call throws Error(DeviceError) naming the call and the VkResult.
#pragma once

#include <corofem/gpu.hpp>

#include <vulkan/vulkan.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail::vk {

/// A zeroed Vulkan structure of type `type` (sType set).
template <class T>
T made(VkStructureType type) {
  T v{};
  v.sType = type;
  return v;
}

/// Throws Error(DeviceError) "Vulkan: <what> failed (<result>)" unless r is VK_SUCCESS.
void check(VkResult r, const char* what);

/// A physical device that can run the backend (a compute queue, storage buffers).
struct PhysicalDevice {
  VkPhysicalDevice handle = VK_NULL_HANDLE;
  std::string name;
  std::string driver;  ///< "<vendor id>:<driver version>" (part of the calibration cache's key)
  bool gpu = false;    ///< integrated, discrete or virtual GPU (not a CPU device such as lavapipe)
  bool float64 = false;
  std::uint32_t queueFamily = 0;
  std::uint32_t apiVersion = 0;  ///< the Vulkan version the device offers
  VkPhysicalDeviceLimits limits{};
};

/// What corofem needs to know of a physical device; `*usable` false where it has no compute queue,
/// too few storage buffers per stage or Vulkan older than 1.1 (the shaders' SPIR-V 1.3).
PhysicalDevice describe(VkPhysicalDevice handle, bool* usable = nullptr);

/// The process's Vulkan instance and its usable devices, made at the first call that succeeds and
/// kept until the process ends (vk_runtime.cpp says why). Throws Error(DeviceError) where there is
/// no Vulkan driver.
class Instance {
 public:
  static std::shared_ptr<Instance> shared();
  ~Instance();
  Instance(const Instance&) = delete;
  Instance& operator=(const Instance&) = delete;
  VkInstance handle() const { return instance_; }
  const std::vector<PhysicalDevice>& devices() const { return devices_; }

 private:
  Instance();
  VkInstance instance_ = VK_NULL_HANDLE;
  std::vector<PhysicalDevice> devices_;
};

class Context;

/// A VkBuffer with its own memory; host-visible buffers stay mapped.
class Buffer {
 public:
  Buffer() = default;
  /// `usage`: beyond storage and transfers (VK_BUFFER_USAGE_VERTEX_BUFFER_BIT for what a renderer
  /// draws from).
  Buffer(Context& ctx, std::size_t bytes, bool host, VkBufferUsageFlags usage = 0);
  ~Buffer();
  Buffer(Buffer&& o) noexcept { *this = std::move(o); }
  Buffer& operator=(Buffer&& o) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  VkBuffer handle() const { return buffer_; }
  std::size_t bytes() const { return bytes_; }
  unsigned char* mapped() const { return mapped_; }

 private:
  void release();
  VkDevice device_ = VK_NULL_HANDLE;
  VkBuffer buffer_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  std::size_t bytes_ = 0;
  unsigned char* mapped_ = nullptr;
};

/// A logical device on one physical device with one compute queue, the pipelines of the shaders,
/// and the ring of command buffers. Either its own device (made and destroyed here) or an
/// application's (ExternalDevice: used, never destroyed).
class Context {
 public:
  /// Its own device on instance device `index`. `float64`: the device enables shaderFloat64 (the
  /// double shaders need it). `bindings`: the storage buffers of the one descriptor-set layout.
  Context(std::shared_ptr<Instance> instance, std::size_t index, bool float64, std::uint32_t bindings,
          std::uint32_t pushBytes);
  /// The application's device and queue (GpuApi::Vulkan). Throws Error(BadInput) naming what is
  /// missing or wrong in `external` (a null handle, a queue family without compute, float64 asked
  /// of a device without shaderFloat64 enabled).
  Context(const ExternalDevice& external, bool float64, std::uint32_t bindings, std::uint32_t pushBytes);
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  const PhysicalDevice& physical() const { return physical_; }
  VkDevice device() const { return device_; }
  std::uint32_t memoryType(std::uint32_t typeBits, bool host) const;

  /// A compute pipeline from SPIR-V words over the shared layout.
  VkPipeline pipeline(const std::uint32_t* words, std::size_t bytes, const char* name);
  /// A descriptor set of the shared layout with buffers[i] at binding i (freed with the context, or
  /// by freeDescriptorSet).
  VkDescriptorSet descriptorSet(const std::vector<const Buffer*>& buffers);
  void freeDescriptorSet(VkDescriptorSet set);
  VkPipelineLayout pipelineLayout() const { return pipelineLayout_; }
  /// The storage buffers of the shared layout (a descriptor set binds one at each).
  std::uint32_t bindings() const { return bindings_; }

  /// The open command buffer: the one an earlier begin() gave and nobody submitted yet (its commands
  /// first, then a full barrier), or a new one of the ring (waits for the ring's oldest when all
  /// are in flight). A caller that records work no one waits for yet may leave it open: the next
  /// submit, whoever calls it, takes it along.
  VkCommandBuffer begin();
  /// Whether a command buffer is open.
  bool recording() const { return recording_ != nullptr; }
  /// Submits the open command buffer; returns its submission number.
  std::uint64_t submit();
  /// Submits the open command buffer if there is one; returns the newest submission number (every
  /// command recorded so far is in it or before it).
  std::uint64_t flush() { return recording_ ? submit() : submitted_; }
  /// Drops the open command buffer's commands unsubmitted (their owner is going away: what they
  /// would compute has no reader).
  void discard();
  /// Waits for submission `id` (and so for every one before it).
  void wait(std::uint64_t id);
  void waitAll();
  std::uint64_t lastSubmission() const { return submitted_; }
  /// Waits on the host that found work still running (each a host round trip that stalled).
  std::uint64_t blockingWaits() const { return blockingWaits_; }

 private:
  struct Slot {
    VkCommandBuffer cb = VK_NULL_HANDLE;
    VkFence fence = VK_NULL_HANDLE;
    std::uint64_t id = 0;
    bool busy = false;
  };
  void waitSlot(Slot& s);
  void makeObjects(std::uint32_t pushBytes);  ///< everything but the VkDevice
  void destroy();

  std::shared_ptr<Instance> instance_;  ///< null on an application's device
  bool ownsDevice_ = true;
  PhysicalDevice physical_;
  VkPhysicalDeviceMemoryProperties memory_{};
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  VkDescriptorSetLayout setLayout_ = VK_NULL_HANDLE;
  VkPipelineLayout pipelineLayout_ = VK_NULL_HANDLE;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
  std::uint32_t bindings_ = 0;
  std::vector<VkPipeline> pipelines_;
  VkCommandPool commandPool_ = VK_NULL_HANDLE;
  std::vector<Slot> ring_;
  std::size_t next_ = 0;
  Slot* recording_ = nullptr;
  std::uint64_t submitted_ = 0;
  std::uint64_t blockingWaits_ = 0;
};

/// Every earlier command's memory writes made visible to every later command.
void fullBarrier(VkCommandBuffer cb);
/// Transfer writes made visible to the host (after a copy into a host buffer).
void hostReadBarrier(VkCommandBuffer cb);
/// Compute shaders' writes made visible to every later command on the queue, in every stage and
/// for every kind of read (a renderer's draw on the same queue, in a later submission too).
void renderBarrier(VkCommandBuffer cb);
/// Copies `bytes` from the host into `to` at offset 0 through a temporary staging buffer, and waits.
void uploadOnce(Context& ctx, const Buffer& to, const void* data, std::size_t bytes);
/// Records `bytes` of `data` into `to` at byte `offset` through the command buffer itself
/// (vkCmdUpdateBuffer, in pieces of its 64 KiB limit; no barrier after).
void updateBuffer(VkCommandBuffer cb, const Buffer& to, std::size_t offset, const void* data, std::size_t bytes);
/// Fills `b` with zero bytes, and waits.
void zeroBuffer(Context& ctx, const Buffer& b);

}  // namespace corofem::detail::vk
