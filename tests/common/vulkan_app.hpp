// An application's own Vulkan device, as a renderer makes it, for the tests that lend it to corofem
// (corofem::ExternalDevice) and then read corofem's surface buffers the way a renderer would: on the
// same queue, in a later submission, with no other synchronisation (Simulation::surfaceBuffer).
#pragma once

#include <corofem/gpu.hpp>

#include <vulkan/vulkan.h>

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace corofem::test {

/// A zeroed Vulkan structure with its sType set.
template <class T>
T info(VkStructureType type) {
  T v{};
  v.sType = type;
  return v;
}

class VulkanApp {
 public:
  /// The first physical device with a queue family doing graphics and compute (lavapipe in CI).
  /// `float64`: enables shaderFloat64 where the device has it. ok() is false where there is none.
  /// Where Khronos' validation layer is installed (Debian: vulkan-validationlayers), the instance
  /// runs under it, and every error or warning it reports about the application's or corofem's
  /// use of the API on this device lands in messages(). Synchronisation validation is asked for
  /// too, but Debian 12's layer (1.3.239) reported neither a barrier removed between two of
  /// corofem's dispatches in one command buffer nor the surface update's final barrier removed
  /// (tried by hand, 2026-11-27): barriers are checked by review and on a GPU, not here.
  explicit VulkanApp(bool float64) {
    auto app = info<VkApplicationInfo>(VK_STRUCTURE_TYPE_APPLICATION_INFO);
    app.pApplicationName = "corofem test application";
    app.apiVersion = VK_API_VERSION_1_1;
    auto ii = info<VkInstanceCreateInfo>(VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO);
    ii.pApplicationInfo = &app;
    const char* layer = "VK_LAYER_KHRONOS_validation";
    const char* extensions[2] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME};
    const VkValidationFeatureEnableEXT sync = VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;
    auto features = info<VkValidationFeaturesEXT>(VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT);
    features.enabledValidationFeatureCount = 1;
    features.pEnabledValidationFeatures = &sync;
    if (hasValidationLayer()) {
      ii.enabledLayerCount = 1;
      ii.ppEnabledLayerNames = &layer;
      ii.enabledExtensionCount = 2;
      ii.ppEnabledExtensionNames = extensions;
      ii.pNext = &features;
      validated = true;
    }
    VkResult made = vkCreateInstance(&ii, nullptr, &instance);
    if (made != VK_SUCCESS && validated) {  // the layer is listed but cannot be loaded: go on without it
      validated = false;
      ii.enabledLayerCount = ii.enabledExtensionCount = 0;
      ii.pNext = nullptr;
      made = vkCreateInstance(&ii, nullptr, &instance);
    }
    if (made != VK_SUCCESS) {
      why = "no Vulkan instance (no driver)";
      return;
    }
    if (validated) {
      auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT"));
      auto mi = info<VkDebugUtilsMessengerCreateInfoEXT>(VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT);
      mi.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
      mi.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
      mi.pfnUserCallback = &VulkanApp::onMessage;
      mi.pUserData = &messages_;
      if (!create || create(instance, &mi, nullptr, &messenger) != VK_SUCCESS) validated = false;
    }
    std::uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance, &count, nullptr);
    std::vector<VkPhysicalDevice> all(count);
    if (count) vkEnumeratePhysicalDevices(instance, &count, all.data());
    for (VkPhysicalDevice pd : all) {
      std::uint32_t n = 0;
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, nullptr);
      std::vector<VkQueueFamilyProperties> fam(n);
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, fam.data());
      for (std::uint32_t f = 0; f < n && !physical; ++f)
        if ((fam[f].queueFlags & VK_QUEUE_GRAPHICS_BIT) && (fam[f].queueFlags & VK_QUEUE_COMPUTE_BIT)) {
          physical = pd;
          family = f;
        }
      if (physical) break;
    }
    if (!physical) {
      why = "no Vulkan device with a graphics and compute queue";
      return;
    }
    VkPhysicalDeviceFeatures has{};
    vkGetPhysicalDeviceFeatures(physical, &has);
    VkPhysicalDeviceFeatures enabled{};
    hasFloat64 = float64 && has.shaderFloat64 == VK_TRUE;
    enabled.shaderFloat64 = hasFloat64 ? VK_TRUE : VK_FALSE;
    const float priority = 1.0f;
    auto qi = info<VkDeviceQueueCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO);
    qi.queueFamilyIndex = family;
    qi.queueCount = 1;
    qi.pQueuePriorities = &priority;
    auto di = info<VkDeviceCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO);
    di.queueCreateInfoCount = 1;
    di.pQueueCreateInfos = &qi;
    di.pEnabledFeatures = &enabled;
    if (vkCreateDevice(physical, &di, nullptr, &device) != VK_SUCCESS) {
      why = "vkCreateDevice failed";
      return;
    }
    vkGetDeviceQueue(device, family, 0, &queue);
    auto pi = info<VkCommandPoolCreateInfo>(VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO);
    pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pi.queueFamilyIndex = family;
    if (vkCreateCommandPool(device, &pi, nullptr, &pool) != VK_SUCCESS) why = "vkCreateCommandPool failed";
  }
  ~VulkanApp() {
    if (device) {
      vkDeviceWaitIdle(device);
      if (pool) vkDestroyCommandPool(device, pool, nullptr);
      vkDestroyDevice(device, nullptr);
    }
    if (messenger) {
      auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
      if (destroy) destroy(instance, messenger, nullptr);
    }
    if (instance) vkDestroyInstance(instance, nullptr);
  }

  /// The validation layer's messages so far (empty without the layer: validated is then false).
  const std::vector<std::string>& messages() const { return messages_; }
  VulkanApp(const VulkanApp&) = delete;
  VulkanApp& operator=(const VulkanApp&) = delete;

  bool ok() const { return device != VK_NULL_HANDLE && pool != VK_NULL_HANDLE; }

  /// The handles as corofem takes them.
  ExternalDevice external() const {
    ExternalDevice e;
    e.api = GpuApi::Vulkan;
    e.instance = instance;
    e.physicalDevice = physical;
    e.device = device;
    e.queue = queue;
    e.queueFamily = family;
    e.shaderFloat64 = hasFloat64;
    return e;
  }

  static void need(VkResult r, const char* what) {
    if (r != VK_SUCCESS) throw std::runtime_error(std::string(what) + " failed (" + std::to_string(r) + ")");
  }

  /// `b`'s region as floats, copied on this queue after everything submitted to it (a renderer's
  /// read: corofem's update ends with a barrier to every later command on the queue), waited for
  /// with a fence of the application's own.
  std::vector<float> read(const GpuBuffer& b) {
    if (b.api != GpuApi::Vulkan || !b) throw std::runtime_error("not a Vulkan buffer");
    VkBuffer host = VK_NULL_HANDLE;
    VkDeviceMemory memory = VK_NULL_HANDLE;
    auto bi = info<VkBufferCreateInfo>(VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO);
    bi.size = b.bytes;
    bi.usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    need(vkCreateBuffer(device, &bi, nullptr, &host), "vkCreateBuffer");
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(device, host, &req);
    VkPhysicalDeviceMemoryProperties props;
    vkGetPhysicalDeviceMemoryProperties(physical, &props);
    auto ai = info<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    ai.allocationSize = req.size;
    const VkMemoryPropertyFlags wanted = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    for (std::uint32_t i = 0; i < props.memoryTypeCount; ++i)
      if ((req.memoryTypeBits & (1u << i)) && (props.memoryTypes[i].propertyFlags & wanted) == wanted) {
        ai.memoryTypeIndex = i;
        break;
      }
    need(vkAllocateMemory(device, &ai, nullptr, &memory), "vkAllocateMemory");
    need(vkBindBufferMemory(device, host, memory, 0), "vkBindBufferMemory");
    VkCommandBuffer cb = VK_NULL_HANDLE;
    auto ca = info<VkCommandBufferAllocateInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO);
    ca.commandPool = pool;
    ca.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ca.commandBufferCount = 1;
    need(vkAllocateCommandBuffers(device, &ca, &cb), "vkAllocateCommandBuffers");
    auto begin = info<VkCommandBufferBeginInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO);
    vkBeginCommandBuffer(cb, &begin);
    VkBufferCopy region{b.offset, 0, b.bytes};
    vkCmdCopyBuffer(cb, reinterpret_cast<VkBuffer>(b.handle), host, 1, &region);
    auto m = info<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
    m.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    m.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &m, 0, nullptr, 0, nullptr);
    vkEndCommandBuffer(cb);
    VkFence fence = VK_NULL_HANDLE;
    auto fi = info<VkFenceCreateInfo>(VK_STRUCTURE_TYPE_FENCE_CREATE_INFO);
    need(vkCreateFence(device, &fi, nullptr, &fence), "vkCreateFence");
    auto si = info<VkSubmitInfo>(VK_STRUCTURE_TYPE_SUBMIT_INFO);
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cb;
    need(vkQueueSubmit(queue, 1, &si, fence), "vkQueueSubmit");
    need(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    std::vector<float> out(b.bytes / sizeof(float));
    void* p = nullptr;
    need(vkMapMemory(device, memory, 0, b.bytes, 0, &p), "vkMapMemory");
    std::memcpy(out.data(), p, b.bytes);
    vkUnmapMemory(device, memory);
    vkDestroyFence(device, fence, nullptr);
    vkFreeCommandBuffers(device, pool, 1, &cb);
    vkDestroyBuffer(device, host, nullptr);
    vkFreeMemory(device, memory, nullptr);
    return out;
  }

  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  VkCommandPool pool = VK_NULL_HANDLE;
  std::uint32_t family = 0;
  bool hasFloat64 = false;
  bool validated = false;  ///< the validation layer watches this device
  std::string why;  ///< why ok() is false

 private:
  static bool hasValidationLayer() {
    std::uint32_t n = 0;
    vkEnumerateInstanceLayerProperties(&n, nullptr);
    std::vector<VkLayerProperties> layers(n);
    if (n) vkEnumerateInstanceLayerProperties(&n, layers.data());
    for (const VkLayerProperties& l : layers)
      if (std::string(l.layerName) == "VK_LAYER_KHRONOS_validation") return true;
    return false;
  }
  static VKAPI_ATTR VkBool32 VKAPI_CALL onMessage(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                 VkDebugUtilsMessageTypeFlagsEXT,
                                                 const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
    static_cast<std::vector<std::string>*>(user)->push_back(data && data->pMessage ? data->pMessage : "(no text)");
    return VK_FALSE;
  }
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  std::vector<std::string> messages_;
};

}  // namespace corofem::test
