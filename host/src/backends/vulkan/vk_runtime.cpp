// Vulkan objects of the backend (vk_runtime.hpp).
#include "backends/vulkan/vk_runtime.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <mutex>

namespace corofem::detail::vk {

namespace {

const char* resultName(VkResult r) {
  switch (r) {
    case VK_NOT_READY: return "VK_NOT_READY";
    case VK_TIMEOUT: return "VK_TIMEOUT";
    case VK_ERROR_OUT_OF_HOST_MEMORY: return "VK_ERROR_OUT_OF_HOST_MEMORY";
    case VK_ERROR_OUT_OF_DEVICE_MEMORY: return "VK_ERROR_OUT_OF_DEVICE_MEMORY";
    case VK_ERROR_INITIALIZATION_FAILED: return "VK_ERROR_INITIALIZATION_FAILED";
    case VK_ERROR_DEVICE_LOST: return "VK_ERROR_DEVICE_LOST";
    case VK_ERROR_MEMORY_MAP_FAILED: return "VK_ERROR_MEMORY_MAP_FAILED";
    case VK_ERROR_LAYER_NOT_PRESENT: return "VK_ERROR_LAYER_NOT_PRESENT";
    case VK_ERROR_EXTENSION_NOT_PRESENT: return "VK_ERROR_EXTENSION_NOT_PRESENT";
    case VK_ERROR_FEATURE_NOT_PRESENT: return "VK_ERROR_FEATURE_NOT_PRESENT";
    case VK_ERROR_INCOMPATIBLE_DRIVER: return "VK_ERROR_INCOMPATIBLE_DRIVER";
    case VK_ERROR_TOO_MANY_OBJECTS: return "VK_ERROR_TOO_MANY_OBJECTS";
    default: return "VkResult";
  }
}

}  // namespace

void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) fail(ErrorCode::DeviceError, "Vulkan: ", what, " failed (", resultName(r), " ", static_cast<int>(r), ")");
}

// ------------------------------------------------------------------------------------ Instance

PhysicalDevice describe(VkPhysicalDevice h, bool* usable) {
  VkPhysicalDeviceProperties props;
  vkGetPhysicalDeviceProperties(h, &props);
  VkPhysicalDeviceFeatures features;
  vkGetPhysicalDeviceFeatures(h, &features);
  std::uint32_t families = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(h, &families, nullptr);
  std::vector<VkQueueFamilyProperties> fam(families);
  vkGetPhysicalDeviceQueueFamilyProperties(h, &families, fam.data());
  PhysicalDevice d;
  d.handle = h;
  d.name = props.deviceName;
  d.driver = std::to_string(props.vendorID) + ":" + std::to_string(props.driverVersion);
  d.gpu = props.deviceType == VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU ||
          props.deviceType == VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU ||
          props.deviceType == VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU;
  d.float64 = features.shaderFloat64 == VK_TRUE;
  d.limits = props.limits;
  d.apiVersion = props.apiVersion;
  bool found = false;
  for (std::uint32_t f = 0; f < families && !found; ++f)
    if (fam[f].queueFlags & VK_QUEUE_COMPUTE_BIT) {
      d.queueFamily = f;
      found = true;
    }
  if (usable)
    *usable = found && props.limits.maxPerStageDescriptorStorageBuffers >= 31 && props.apiVersion >= VK_API_VERSION_1_1;
  return d;
}

std::shared_ptr<Instance> Instance::shared() {
  // Made once and kept for the process's life, never destroyed. When the last instance goes, the
  // loader may unload the driver. On an H100 (NVIDIA's libGLX_nvidia, driver 580), in test
  // binaries that had read the device list (an instance made and dropped), every later
  // vkCreateInstance answered VK_ERROR_INCOMPATIBLE_DRIVER; with the instance kept every test
  // passed. A failed creation is not kept: a later call tries again.
  static std::mutex mutex;
  static auto* kept = new std::shared_ptr<Instance>();  // reachable to the end, on purpose
  std::lock_guard<std::mutex> lock(mutex);
  if (!*kept) kept->reset(new Instance());
  return *kept;
}

Instance::Instance() {
  auto app = made<VkApplicationInfo>(VK_STRUCTURE_TYPE_APPLICATION_INFO);
  app.pApplicationName = "corofem";
  app.pEngineName = "corofem";
  app.apiVersion = VK_API_VERSION_1_1;
  auto info = made<VkInstanceCreateInfo>(VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO);
  info.pApplicationInfo = &app;
  const VkResult r = vkCreateInstance(&info, nullptr, &instance_);
  if (r != VK_SUCCESS)
    fail(ErrorCode::DeviceError, "Vulkan: no instance could be made (", resultName(r), "): no Vulkan driver is "
         "installed (Debian: mesa-vulkan-drivers for the lavapipe CPU device, or the GPU vendor's driver)");
  std::uint32_t count = 0;
  vkEnumeratePhysicalDevices(instance_, &count, nullptr);
  std::vector<VkPhysicalDevice> all(count);
  if (count) vkEnumeratePhysicalDevices(instance_, &count, all.data());
  for (VkPhysicalDevice h : all) {
    bool usable = false;
    PhysicalDevice d = describe(h, &usable);
    if (usable) devices_.push_back(d);
  }
}

Instance::~Instance() {
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

// ------------------------------------------------------------------------------------ Buffer

Buffer::Buffer(Context& ctx, std::size_t bytes, bool host, VkBufferUsageFlags usage) : device_(ctx.device()) {
  bytes_ = std::max<std::size_t>(bytes, 16);
  auto info = made<VkBufferCreateInfo>(VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO);
  info.size = bytes_;
  info.usage = usage | VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
               VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  check(vkCreateBuffer(device_, &info, nullptr, &buffer_), "vkCreateBuffer");
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(device_, buffer_, &req);
  auto alloc = made<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex = ctx.memoryType(req.memoryTypeBits, host);
  // On a failure the buffer and its memory go before the throw (no destructor runs).
  auto checked = [&](VkResult r, const char* what) {
    if (r == VK_SUCCESS) return;
    release();
    check(r, what);
  };
  checked(vkAllocateMemory(device_, &alloc, nullptr, &memory_),
          host ? "vkAllocateMemory (host-visible)" : "vkAllocateMemory (device-local)");
  checked(vkBindBufferMemory(device_, buffer_, memory_, 0), "vkBindBufferMemory");
  if (host) {
    void* p = nullptr;
    checked(vkMapMemory(device_, memory_, 0, VK_WHOLE_SIZE, 0, &p), "vkMapMemory");
    mapped_ = static_cast<unsigned char*>(p);
    std::memset(mapped_, 0, bytes_);
  }
}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    release();
    device_ = o.device_;
    buffer_ = o.buffer_;
    memory_ = o.memory_;
    bytes_ = o.bytes_;
    mapped_ = o.mapped_;
    o.buffer_ = VK_NULL_HANDLE;
    o.memory_ = VK_NULL_HANDLE;
    o.mapped_ = nullptr;
    o.bytes_ = 0;
  }
  return *this;
}

void Buffer::release() {
  if (buffer_) vkDestroyBuffer(device_, buffer_, nullptr);
  if (memory_) vkFreeMemory(device_, memory_, nullptr);  // unmaps
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
}

Buffer::~Buffer() { release(); }

// ------------------------------------------------------------------------------------ Context

Context::Context(std::shared_ptr<Instance> instance, std::size_t index, bool float64, std::uint32_t bindings,
                 std::uint32_t pushBytes)
    : instance_(std::move(instance)), bindings_(bindings) {
  if (index >= instance_->devices().size())
    fail(ErrorCode::DeviceError, "Vulkan: device ", index, " does not exist (", instance_->devices().size(),
         " usable here)");
  physical_ = instance_->devices()[index];
  vkGetPhysicalDeviceMemoryProperties(physical_.handle, &memory_);
  const float priority = 1.0f;
  auto queue = made<VkDeviceQueueCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO);
  queue.queueFamilyIndex = physical_.queueFamily;
  queue.queueCount = 1;
  queue.pQueuePriorities = &priority;
  VkPhysicalDeviceFeatures features{};
  features.shaderFloat64 = float64 ? VK_TRUE : VK_FALSE;
  auto info = made<VkDeviceCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO);
  info.queueCreateInfoCount = 1;
  info.pQueueCreateInfos = &queue;
  info.pEnabledFeatures = &features;
  check(vkCreateDevice(physical_.handle, &info, nullptr, &device_), "vkCreateDevice");
  try {
    makeObjects(pushBytes);
  } catch (...) {
    destroy();  // no destructor runs for a constructor that throws
    throw;
  }
}

Context::Context(const ExternalDevice& external, bool float64, std::uint32_t bindings, std::uint32_t pushBytes)
    : ownsDevice_(false), bindings_(bindings) {
  auto missing = [](const char* what, const char* fix) {
    fail(ErrorCode::BadInput, "SimulationOptions::device (Vulkan): ", what, " is null; ", fix);
  };
  if (!external.instance) missing("instance", "give the VkInstance the device was made on");
  if (!external.physicalDevice) missing("physicalDevice", "give the VkPhysicalDevice of the device");
  if (!external.device) missing("device", "give the application's VkDevice");
  if (!external.queue) missing("queue", "give a VkQueue of the device whose family supports compute");
  physical_ = describe(static_cast<VkPhysicalDevice>(external.physicalDevice));
  std::uint32_t families = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical_.handle, &families, nullptr);
  std::vector<VkQueueFamilyProperties> fam(families);
  vkGetPhysicalDeviceQueueFamilyProperties(physical_.handle, &families, fam.data());
  if (external.queueFamily >= families || !(fam[external.queueFamily].queueFlags & VK_QUEUE_COMPUTE_BIT))
    fail(ErrorCode::BadInput, "SimulationOptions::device (Vulkan): queue family ", external.queueFamily, " of '",
         physical_.name, "' ", external.queueFamily >= families ? "does not exist" : "has no compute",
         "; lend a queue of a family with VK_QUEUE_COMPUTE_BIT (", families, " families)");
  if (physical_.apiVersion < VK_API_VERSION_1_1)
    fail(ErrorCode::BadInput, "SimulationOptions::device (Vulkan): '", physical_.name, "' offers Vulkan ",
         VK_API_VERSION_MAJOR(physical_.apiVersion), ".", VK_API_VERSION_MINOR(physical_.apiVersion),
         "; corofem's shaders need Vulkan 1.1 (SPIR-V 1.3): lend a device that offers 1.1 or later, made on an "
         "instance created with apiVersion 1.1 or later");
  if (physical_.limits.maxPerStageDescriptorStorageBuffers < 31)
    fail(ErrorCode::DeviceError, "Vulkan: '", physical_.name, "' binds ",
         physical_.limits.maxPerStageDescriptorStorageBuffers, " storage buffers per stage; corofem's shaders need 31");
  if (float64 && !external.shaderFloat64)
    fail(ErrorCode::BadInput, "SimulationOptions::device (Vulkan): double precision needs the shaderFloat64 feature; ",
         physical_.float64 ? "create the device with it enabled and set ExternalDevice::shaderFloat64"
                           : std::string("'") + physical_.name + "' has none: set solver.precision to \"float\"");
  physical_.queueFamily = external.queueFamily;
  vkGetPhysicalDeviceMemoryProperties(physical_.handle, &memory_);
  device_ = static_cast<VkDevice>(external.device);
  queue_ = static_cast<VkQueue>(external.queue);
  try {
    makeObjects(pushBytes);
  } catch (...) {
    destroy();
    throw;
  }
}

void Context::makeObjects(std::uint32_t pushBytes) {
  const std::uint32_t bindings = bindings_;
  if (!queue_) vkGetDeviceQueue(device_, physical_.queueFamily, 0, &queue_);

  std::vector<VkDescriptorSetLayoutBinding> b(bindings);
  for (std::uint32_t i = 0; i < bindings; ++i) {
    b[i].binding = i;
    b[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    b[i].descriptorCount = 1;
    b[i].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
  }
  auto setInfo = made<VkDescriptorSetLayoutCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO);
  setInfo.bindingCount = bindings;
  setInfo.pBindings = b.data();
  check(vkCreateDescriptorSetLayout(device_, &setInfo, nullptr, &setLayout_), "vkCreateDescriptorSetLayout");
  VkPushConstantRange push{VK_SHADER_STAGE_COMPUTE_BIT, 0, pushBytes};
  auto layoutInfo = made<VkPipelineLayoutCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO);
  layoutInfo.setLayoutCount = 1;
  layoutInfo.pSetLayouts = &setLayout_;
  layoutInfo.pushConstantRangeCount = 1;
  layoutInfo.pPushConstantRanges = &push;
  check(vkCreatePipelineLayout(device_, &layoutInfo, nullptr, &pipelineLayout_), "vkCreatePipelineLayout");
  constexpr std::uint32_t kSets = 64;  // a device's three (six with amg), and its surfaces' (one per set of surfaces)
  VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, bindings * kSets};
  auto poolInfo = made<VkDescriptorPoolCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO);
  poolInfo.flags = VK_DESCRIPTOR_POOL_CREATE_FREE_DESCRIPTOR_SET_BIT;
  poolInfo.maxSets = kSets;
  poolInfo.poolSizeCount = 1;
  poolInfo.pPoolSizes = &size;
  check(vkCreateDescriptorPool(device_, &poolInfo, nullptr, &pool_), "vkCreateDescriptorPool");

  auto cmdInfo = made<VkCommandPoolCreateInfo>(VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO);
  cmdInfo.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  cmdInfo.queueFamilyIndex = physical_.queueFamily;
  check(vkCreateCommandPool(device_, &cmdInfo, nullptr, &commandPool_), "vkCreateCommandPool");
  ring_.resize(16);
  for (Slot& s : ring_) {
    auto a = made<VkCommandBufferAllocateInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO);
    a.commandPool = commandPool_;
    a.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    a.commandBufferCount = 1;
    check(vkAllocateCommandBuffers(device_, &a, &s.cb), "vkAllocateCommandBuffers");
    auto f = made<VkFenceCreateInfo>(VK_STRUCTURE_TYPE_FENCE_CREATE_INFO);
    check(vkCreateFence(device_, &f, nullptr, &s.fence), "vkCreateFence");
  }
}

Context::~Context() { destroy(); }

void Context::destroy() {
  if (!device_) return;
  // Waits for its own submissions only (an application's device may be busy with its own work).
  for (Slot& s : ring_)
    if (s.busy && s.fence) vkWaitForFences(device_, 1, &s.fence, VK_TRUE, std::numeric_limits<std::uint64_t>::max());
  for (Slot& s : ring_)
    if (s.fence) vkDestroyFence(device_, s.fence, nullptr);
  if (commandPool_) vkDestroyCommandPool(device_, commandPool_, nullptr);
  for (VkPipeline p : pipelines_) vkDestroyPipeline(device_, p, nullptr);
  if (pool_) vkDestroyDescriptorPool(device_, pool_, nullptr);
  if (pipelineLayout_) vkDestroyPipelineLayout(device_, pipelineLayout_, nullptr);
  if (setLayout_) vkDestroyDescriptorSetLayout(device_, setLayout_, nullptr);
  if (ownsDevice_) vkDestroyDevice(device_, nullptr);
  device_ = VK_NULL_HANDLE;
}

std::uint32_t Context::memoryType(std::uint32_t typeBits, bool host) const {
  // Host buffers: host-visible and coherent, cached where offered (reads back faster); device
  // buffers: device-local where offered.
  const VkMemoryPropertyFlags need = host ? (VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT) : 0;
  const VkMemoryPropertyFlags want = host ? VK_MEMORY_PROPERTY_HOST_CACHED_BIT : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
  std::uint32_t fallback = std::numeric_limits<std::uint32_t>::max();
  for (std::uint32_t i = 0; i < memory_.memoryTypeCount; ++i) {
    if (!(typeBits & (1u << i))) continue;
    const VkMemoryPropertyFlags f = memory_.memoryTypes[i].propertyFlags;
    if ((f & need) != need) continue;
    if ((f & want) == want) return i;
    if (fallback == std::numeric_limits<std::uint32_t>::max()) fallback = i;
  }
  if (fallback == std::numeric_limits<std::uint32_t>::max())
    fail(ErrorCode::DeviceError, "Vulkan: '", physical_.name, "' has no ", host ? "host-visible" : "usable",
         " memory type for a buffer");
  return fallback;
}

VkPipeline Context::pipeline(const std::uint32_t* words, std::size_t bytes, const char* name) {
  auto m = made<VkShaderModuleCreateInfo>(VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO);
  m.codeSize = bytes;
  m.pCode = words;
  VkShaderModule module = VK_NULL_HANDLE;
  check(vkCreateShaderModule(device_, &m, nullptr, &module), name);
  auto info = made<VkComputePipelineCreateInfo>(VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO);
  info.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  info.stage.module = module;
  info.stage.pName = "main";
  info.layout = pipelineLayout_;
  VkPipeline p = VK_NULL_HANDLE;
  const VkResult r = vkCreateComputePipelines(device_, VK_NULL_HANDLE, 1, &info, nullptr, &p);
  vkDestroyShaderModule(device_, module, nullptr);
  check(r, name);
  pipelines_.push_back(p);
  return p;
}

VkDescriptorSet Context::descriptorSet(const std::vector<const Buffer*>& buffers) {
  if (buffers.size() != bindings_) fail(ErrorCode::Internal, "Vulkan: ", buffers.size(), " buffers for ", bindings_, " bindings");
  auto a = made<VkDescriptorSetAllocateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO);
  a.descriptorPool = pool_;
  a.descriptorSetCount = 1;
  a.pSetLayouts = &setLayout_;
  VkDescriptorSet set = VK_NULL_HANDLE;
  check(vkAllocateDescriptorSets(device_, &a, &set), "vkAllocateDescriptorSets");
  std::vector<VkDescriptorBufferInfo> infos(bindings_);
  std::vector<VkWriteDescriptorSet> writes(bindings_);
  for (std::uint32_t i = 0; i < bindings_; ++i) {
    infos[i] = {buffers[i]->handle(), 0, VK_WHOLE_SIZE};
    writes[i] = made<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
    writes[i].dstSet = set;
    writes[i].dstBinding = i;
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
  }
  vkUpdateDescriptorSets(device_, bindings_, writes.data(), 0, nullptr);
  return set;
}

void Context::freeDescriptorSet(VkDescriptorSet set) {
  if (set) vkFreeDescriptorSets(device_, pool_, 1, &set);
}

void Context::waitSlot(Slot& s) {
  if (!s.busy) return;
  check(vkWaitForFences(device_, 1, &s.fence, VK_TRUE, std::numeric_limits<std::uint64_t>::max()), "vkWaitForFences");
  s.busy = false;
}

VkCommandBuffer Context::begin() {
  if (recording_) {  // left open by an earlier caller: after its commands
    fullBarrier(recording_->cb);
    return recording_->cb;
  }
  Slot& s = ring_[next_];
  next_ = (next_ + 1) % ring_.size();
  if (s.busy && vkGetFenceStatus(device_, s.fence) == VK_NOT_READY) ++blockingWaits_;  // the ring is full
  waitSlot(s);
  check(vkResetFences(device_, 1, &s.fence), "vkResetFences");
  check(vkResetCommandBuffer(s.cb, 0), "vkResetCommandBuffer");
  auto b = made<VkCommandBufferBeginInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO);
  b.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(vkBeginCommandBuffer(s.cb, &b), "vkBeginCommandBuffer");
  fullBarrier(s.cb);  // after every command of the earlier submissions
  recording_ = &s;
  return s.cb;
}

void Context::discard() {
  if (!recording_) return;
  check(vkEndCommandBuffer(recording_->cb), "vkEndCommandBuffer");
  recording_ = nullptr;  // its slot is reset when the ring comes back to it
}

std::uint64_t Context::submit() {
  if (!recording_) fail(ErrorCode::Internal, "Vulkan: submit without a command buffer");
  Slot& s = *recording_;
  recording_ = nullptr;
  check(vkEndCommandBuffer(s.cb), "vkEndCommandBuffer");
  auto info = made<VkSubmitInfo>(VK_STRUCTURE_TYPE_SUBMIT_INFO);
  info.commandBufferCount = 1;
  info.pCommandBuffers = &s.cb;
  check(vkQueueSubmit(queue_, 1, &info, s.fence), "vkQueueSubmit");
  s.busy = true;
  s.id = ++submitted_;
  return s.id;
}

void Context::wait(std::uint64_t id) {
  // Every busy slot up to id; the host stalled once if any of them was still running.
  bool stalled = false;
  for (Slot& s : ring_)
    if (s.busy && s.id <= id) {
      stalled = stalled || vkGetFenceStatus(device_, s.fence) == VK_NOT_READY;
      waitSlot(s);
    }
  if (stalled) ++blockingWaits_;
}

void Context::waitAll() { wait(submitted_); }

void fullBarrier(VkCommandBuffer cb) {
  auto m = made<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
  m.srcAccessMask = VK_ACCESS_MEMORY_WRITE_BIT;
  m.dstAccessMask = VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &m, 0,
                       nullptr, 0, nullptr);
}

void hostReadBarrier(VkCommandBuffer cb) {
  auto m = made<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
  m.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_SHADER_WRITE_BIT;
  m.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                       VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &m, 0, nullptr, 0, nullptr);
}

void renderBarrier(VkCommandBuffer cb) {
  auto m = made<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
  m.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  m.dstAccessMask = VK_ACCESS_MEMORY_READ_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1, &m, 0,
                       nullptr, 0, nullptr);
}

void updateBuffer(VkCommandBuffer cb, const Buffer& to, std::size_t offset, const void* data, std::size_t bytes) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  for (std::size_t at = 0; at < bytes; at += 65536)
    vkCmdUpdateBuffer(cb, to.handle(), offset + at, std::min<std::size_t>(65536, bytes - at), p + at);
}

void zeroBuffer(Context& ctx, const Buffer& b) {
  VkCommandBuffer cb = ctx.begin();
  vkCmdFillBuffer(cb, b.handle(), 0, VK_WHOLE_SIZE, 0u);
  ctx.wait(ctx.submit());
}

void uploadOnce(Context& ctx, const Buffer& to, const void* data, std::size_t bytes) {
  if (bytes == 0) return;
  Buffer staging(ctx, bytes, true);
  std::memcpy(staging.mapped(), data, bytes);
  VkCommandBuffer cb = ctx.begin();
  VkBufferCopy region{0, 0, bytes};
  vkCmdCopyBuffer(cb, staging.handle(), to.handle(), 1, &region);
  ctx.wait(ctx.submit());
}

}  // namespace corofem::detail::vk
