// A small headless Vulkan renderer that embeds corofem on its own VkDevice (issue 26's sample): SOFA's
// liver (596 tets) with its 2,194-vertex smooth surface, dragged by a handle along a scripted path,
// simulated by corofem's Vulkan backend on the renderer's device and queue, and drawn each frame
// straight from corofem's surface buffer (Simulation::surfaceBuffer: a VkBuffer with vertex-buffer
// usage) -- no copy, no host round trip of the surface, no semaphore: corofem's update ends with a
// barrier to every later command on the queue. Offscreen colour and depth images, no window.
//
//   renderer [--out DIR] [--frames N] [--png-every K] [--width W] [--height H]
//
// Runs from the project root (the liver comes from ../shared/data). Writes DIR/frame_NNNN.png every K
// frames (and the last), DIR/frames.csv (per frame: the step's and the draw's milliseconds, the
// PCG iterations, the pixel check's counts) and prints a summary. Each frame is checked: the
// surface read back (readSurface) is projected and rasterised on the host, and every pixel whose
// 3x3 neighbourhood the host covers alike (inside or outside the surface's silhouette) must be
// drawn alike by the GPU. A drawing of stale or wrong positions differs by more than a pixel where
// the surface moves. Exit 0; 1 for a failed check or a Vulkan or corofem error; 2 for bad
// arguments; 77 when the liver or a Vulkan device with a graphics queue is absent.
#include <corofem/corofem.hpp>

#include <vulkan/vulkan.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

// glslc's SPIR-V of surface.vert and surface.frag (samples/renderer/CMakeLists: -mfmt=c).
const std::uint32_t kVertexShader[] =
#include "surface_vert.inc"
    ;
const std::uint32_t kFragmentShader[] =
#include "surface_frag.inc"
    ;

/// A zeroed Vulkan structure with its sType set.
template <class T>
T info(VkStructureType type) {
  T v{};
  v.sType = type;
  return v;
}

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw std::runtime_error(std::string(what) + " failed (VkResult " + std::to_string(r) + ")");
}

/// Writes RGBA8 pixels (rows top to bottom) as a PNG: zlib's compress2 over rows each led by filter
/// byte 0, chunks with zlib's crc32. Throws when the file cannot be written whole.
void writePng(const std::string& path, const std::vector<std::uint8_t>& rgba, std::uint32_t w, std::uint32_t h) {
  std::vector<std::uint8_t> raw;
  raw.reserve(static_cast<std::size_t>(h) * (4 * w + 1));
  for (std::uint32_t y = 0; y < h; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), rgba.begin() + 4 * static_cast<std::size_t>(y) * w, rgba.begin() + 4 * static_cast<std::size_t>(y + 1) * w);
  }
  uLongf packedSize = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> packed(packedSize);
  if (compress2(packed.data(), &packedSize, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK)
    throw std::runtime_error("zlib could not compress " + path);
  packed.resize(packedSize);
  std::ofstream f(path, std::ios::binary);
  auto u32 = [&](std::uint32_t v) {
    const char b[4] = {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8), static_cast<char>(v)};
    f.write(b, 4);
  };
  auto chunk = [&](const char* type, const std::vector<std::uint8_t>& data) {
    u32(static_cast<std::uint32_t>(data.size()));
    f.write(type, 4);
    f.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
    uLong crc = crc32(0, reinterpret_cast<const Bytef*>(type), 4);
    crc = crc32(crc, data.data(), static_cast<uInt>(data.size()));
    u32(static_cast<std::uint32_t>(crc));
  };
  f.write("\x89PNG\r\n\x1a\n", 8);
  std::vector<std::uint8_t> header(13, 0);
  for (int i = 0; i < 4; ++i) {
    header[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(w >> (24 - 8 * i));
    header[static_cast<std::size_t>(4 + i)] = static_cast<std::uint8_t>(h >> (24 - 8 * i));
  }
  header[8] = 8;  // bits per channel
  header[9] = 6;  // RGBA
  chunk("IHDR", header);
  chunk("IDAT", packed);
  chunk("IEND", {});
  f.close();
  if (!f) throw std::runtime_error("could not write " + path);
}

using Mat4 = std::array<double, 16>;  // row-major

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 c{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 4; ++k) c[4 * i + j] += a[4 * i + k] * b[4 * k + j];
  return c;
}

/// World to Vulkan clip space: a camera at `eye` looking at `at` (y up), a perspective of vertical
/// field of view `fov` (radians) with depth 0 at `near` and 1 at `far`, and y down as Vulkan's
/// framebuffer has it.
Mat4 cameraMatrix(const std::array<double, 3>& eye, const std::array<double, 3>& at, double fov, double aspect,
                  double near, double far) {
  std::array<double, 3> f{at[0] - eye[0], at[1] - eye[1], at[2] - eye[2]};
  const double fl = std::hypot(f[0], f[1], f[2]);
  for (double& v : f) v /= fl;
  std::array<double, 3> s{f[1] * 0 - f[2] * 1, f[2] * 0 - f[0] * 0, f[0] * 1 - f[1] * 0};  // f x up, up = y
  const double sl = std::hypot(s[0], s[1], s[2]);
  for (double& v : s) v /= sl;
  const std::array<double, 3> u{s[1] * f[2] - s[2] * f[1], s[2] * f[0] - s[0] * f[2], s[0] * f[1] - s[1] * f[0]};
  auto dot = [](const std::array<double, 3>& a, const std::array<double, 3>& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  const Mat4 view{s[0], s[1], s[2], -dot(s, eye), u[0], u[1], u[2], -dot(u, eye),
                  -f[0], -f[1], -f[2], dot(f, eye), 0, 0, 0, 1};
  const double t = 1.0 / std::tan(fov / 2);
  const Mat4 proj{t / aspect, 0, 0, 0, 0, -t, 0, 0, 0, 0, far / (near - far), near * far / (near - far), 0, 0, -1, 0};
  return multiply(proj, view);
}

/// The host's coverage of the triangles projected by `m` (pixel centres inside a triangle, either
/// orientation), width x height, rows top to bottom as the framebuffer's.
std::vector<std::uint8_t> hostCoverage(const std::vector<double>& x, const std::vector<std::uint32_t>& triangles, const Mat4& m,
                                       int width, int height) {
  const std::size_t n = x.size() / 3;
  std::vector<double> px(n), py(n);
  for (std::size_t v = 0; v < n; ++v) {
    double clip[4];
    for (int i = 0; i < 4; ++i)
      clip[i] = m[4 * i] * x[3 * v] + m[4 * i + 1] * x[3 * v + 1] + m[4 * i + 2] * x[3 * v + 2] + m[4 * i + 3];
    px[v] = (clip[0] / clip[3] + 1.0) * 0.5 * width;
    py[v] = (clip[1] / clip[3] + 1.0) * 0.5 * height;
  }
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(width) * height, 0);
  for (std::size_t t = 0; t + 2 < triangles.size(); t += 3) {
    const std::uint32_t a = triangles[t], b = triangles[t + 1], c = triangles[t + 2];
    const double area = (px[b] - px[a]) * (py[c] - py[a]) - (py[b] - py[a]) * (px[c] - px[a]);
    if (area == 0) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({px[a], px[b], px[c]}))));
    const int x1 = std::min(width - 1, static_cast<int>(std::ceil(std::max({px[a], px[b], px[c]}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({py[a], py[b], py[c]}))));
    const int y1 = std::min(height - 1, static_cast<int>(std::ceil(std::max({py[a], py[b], py[c]}))));
    auto edge = [&](std::uint32_t p, std::uint32_t q, double sx, double sy) {
      return ((px[q] - px[p]) * (sy - py[p]) - (py[q] - py[p]) * (sx - px[p])) * (area > 0 ? 1 : -1);
    };
    for (int y = y0; y <= y1; ++y)
      for (int xx = x0; xx <= x1; ++xx) {
        const double sx = xx + 0.5, sy = y + 0.5;
        if (edge(a, b, sx, sy) >= 0 && edge(b, c, sx, sy) >= 0 && edge(c, a, sx, sy) >= 0)
          mask[static_cast<std::size_t>(y) * width + xx] = 1;
      }
  }
  return mask;
}

/// An application's Vulkan objects: instance, device and queue (lent to corofem), and what it draws with.
struct Renderer {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  std::uint32_t family = 0;
  std::string deviceName;
  VkPhysicalDeviceMemoryProperties memory{};
  std::uint32_t width = 0, height = 0;
  VkFormat depthFormat = VK_FORMAT_UNDEFINED;
  VkImage colour = VK_NULL_HANDLE, depth = VK_NULL_HANDLE;
  VkDeviceMemory colourMemory = VK_NULL_HANDLE, depthMemory = VK_NULL_HANDLE, readMemory = VK_NULL_HANDLE,
                 indexMemory = VK_NULL_HANDLE;
  VkImageView colourView = VK_NULL_HANDLE, depthView = VK_NULL_HANDLE;
  VkBuffer readBuffer = VK_NULL_HANDLE, indexBuffer = VK_NULL_HANDLE;
  void* readMapped = nullptr;
  VkRenderPass renderPass = VK_NULL_HANDLE;
  VkFramebuffer framebuffer = VK_NULL_HANDLE;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkPipeline pipeline = VK_NULL_HANDLE;
  VkCommandPool pool = VK_NULL_HANDLE;
  VkCommandBuffer cb = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  std::uint32_t indexCount = 0;

  /// False where no device has a queue family with graphics and compute.
  bool open() {
    auto app = info<VkApplicationInfo>(VK_STRUCTURE_TYPE_APPLICATION_INFO);
    app.pApplicationName = "corofem renderer sample";
    app.apiVersion = VK_API_VERSION_1_1;
    auto ii = info<VkInstanceCreateInfo>(VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO);
    ii.pApplicationInfo = &app;
    if (vkCreateInstance(&ii, nullptr, &instance) != VK_SUCCESS) return false;
    std::uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance, &count, nullptr);
    std::vector<VkPhysicalDevice> all(count);
    if (count) vkEnumeratePhysicalDevices(instance, &count, all.data());
    // A GPU where there is one, else the first device (lavapipe, Mesa's CPU driver).
    int best = -1;
    for (VkPhysicalDevice pd : all) {
      VkPhysicalDeviceProperties props;
      vkGetPhysicalDeviceProperties(pd, &props);
      std::uint32_t n = 0;
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, nullptr);
      std::vector<VkQueueFamilyProperties> fam(n);
      vkGetPhysicalDeviceQueueFamilyProperties(pd, &n, fam.data());
      for (std::uint32_t f = 0; f < n; ++f) {
        if (!(fam[f].queueFlags & VK_QUEUE_GRAPHICS_BIT) || !(fam[f].queueFlags & VK_QUEUE_COMPUTE_BIT)) continue;
        const int score = props.deviceType == VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU ? 3
                          : props.deviceType == VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU ? 2 : 1;
        if (score > best) {
          best = score;
          physical = pd;
          family = f;
          deviceName = props.deviceName;
        }
        break;
      }
    }
    if (!physical) return false;
    vkGetPhysicalDeviceMemoryProperties(physical, &memory);
    const float priority = 1.0f;
    auto qi = info<VkDeviceQueueCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO);
    qi.queueFamilyIndex = family;
    qi.queueCount = 1;
    qi.pQueuePriorities = &priority;
    VkPhysicalDeviceFeatures features{};  // corofem runs in float here: no shaderFloat64 needed
    auto di = info<VkDeviceCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO);
    di.queueCreateInfoCount = 1;
    di.pQueueCreateInfos = &qi;
    di.pEnabledFeatures = &features;
    check(vkCreateDevice(physical, &di, nullptr, &device), "vkCreateDevice");
    vkGetDeviceQueue(device, family, 0, &queue);
    return true;
  }

  corofem::ExternalDevice lent() const {
    corofem::ExternalDevice e;
    e.api = corofem::GpuApi::Vulkan;
    e.instance = instance;
    e.physicalDevice = physical;
    e.device = device;
    e.queue = queue;
    e.queueFamily = family;
    return e;
  }

  std::uint32_t memoryType(std::uint32_t bits, VkMemoryPropertyFlags need) const {
    for (std::uint32_t i = 0; i < memory.memoryTypeCount; ++i)
      if ((bits & (1u << i)) && (memory.memoryTypes[i].propertyFlags & need) == need) return i;
    throw std::runtime_error("no suitable memory type");
  }

  VkDeviceMemory bind(VkImage image) {
    VkMemoryRequirements req;
    vkGetImageMemoryRequirements(device, image, &req);
    auto ai = info<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = memoryType(req.memoryTypeBits, 0);
    VkDeviceMemory m = VK_NULL_HANDLE;
    check(vkAllocateMemory(device, &ai, nullptr, &m), "vkAllocateMemory (image)");
    check(vkBindImageMemory(device, image, m, 0), "vkBindImageMemory");
    return m;
  }

  VkBuffer hostBuffer(std::size_t bytes, VkBufferUsageFlags usage, VkDeviceMemory& m, void** mapped) {
    auto bi = info<VkBufferCreateInfo>(VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO);
    bi.size = bytes;
    bi.usage = usage;
    VkBuffer b = VK_NULL_HANDLE;
    check(vkCreateBuffer(device, &bi, nullptr, &b), "vkCreateBuffer");
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(device, b, &req);
    auto ai = info<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = memoryType(req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    check(vkAllocateMemory(device, &ai, nullptr, &m), "vkAllocateMemory (buffer)");
    check(vkBindBufferMemory(device, b, m, 0), "vkBindBufferMemory");
    check(vkMapMemory(device, m, 0, VK_WHOLE_SIZE, 0, mapped), "vkMapMemory");
    return b;
  }

  VkImageView view(VkImage image, VkFormat format, VkImageAspectFlags aspect) {
    auto vi = info<VkImageViewCreateInfo>(VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO);
    vi.image = image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_2D;
    vi.format = format;
    vi.subresourceRange = {aspect, 0, 1, 0, 1};
    VkImageView v = VK_NULL_HANDLE;
    check(vkCreateImageView(device, &vi, nullptr, &v), "vkCreateImageView");
    return v;
  }

  VkImage image(VkFormat format, VkImageUsageFlags usage) {
    auto ci = info<VkImageCreateInfo>(VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO);
    ci.imageType = VK_IMAGE_TYPE_2D;
    ci.format = format;
    ci.extent = {width, height, 1};
    ci.mipLevels = 1;
    ci.arrayLayers = 1;
    ci.samples = VK_SAMPLE_COUNT_1_BIT;
    ci.tiling = VK_IMAGE_TILING_OPTIMAL;
    ci.usage = usage;
    ci.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    VkImage i = VK_NULL_HANDLE;
    check(vkCreateImage(device, &ci, nullptr, &i), "vkCreateImage");
    return i;
  }

  VkShaderModule module(const std::uint32_t* words, std::size_t bytes) {
    auto mi = info<VkShaderModuleCreateInfo>(VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO);
    mi.codeSize = bytes;
    mi.pCode = words;
    VkShaderModule m = VK_NULL_HANDLE;
    check(vkCreateShaderModule(device, &mi, nullptr, &m), "vkCreateShaderModule");
    return m;
  }

  /// Images, render pass, pipeline for `stride`-byte vertices, the index buffer, the read-back buffer.
  void build(std::uint32_t w, std::uint32_t h, const std::vector<std::uint32_t>& triangles, std::uint32_t stride) {
    width = w;
    height = h;
    for (VkFormat f : {VK_FORMAT_D32_SFLOAT, VK_FORMAT_D16_UNORM}) {
      VkFormatProperties p;
      vkGetPhysicalDeviceFormatProperties(physical, f, &p);
      if (p.optimalTilingFeatures & VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT) {
        depthFormat = f;
        break;
      }
    }
    colour = image(VK_FORMAT_R8G8B8A8_UNORM, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
    colourMemory = bind(colour);
    colourView = view(colour, VK_FORMAT_R8G8B8A8_UNORM, VK_IMAGE_ASPECT_COLOR_BIT);
    depth = image(depthFormat, VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT);
    depthMemory = bind(depth);
    depthView = view(depth, depthFormat, VK_IMAGE_ASPECT_DEPTH_BIT);

    VkAttachmentDescription att[2]{};
    att[0].format = VK_FORMAT_R8G8B8A8_UNORM;
    att[0].samples = VK_SAMPLE_COUNT_1_BIT;
    att[0].loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    att[0].storeOp = VK_ATTACHMENT_STORE_OP_STORE;
    att[0].stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    att[0].stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    att[0].initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    att[0].finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
    att[1] = att[0];
    att[1].format = depthFormat;
    att[1].storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    att[1].finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
    VkAttachmentReference colourRef{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
    VkAttachmentReference depthRef{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
    VkSubpassDescription sub{};
    sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
    sub.colorAttachmentCount = 1;
    sub.pColorAttachments = &colourRef;
    sub.pDepthStencilAttachment = &depthRef;
    // The previous frame's copy of the colour image (a transfer read) before this frame's clear;
    // this frame's writes before the copy that follows the pass.
    VkSubpassDependency deps[2]{};
    deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
    deps[0].dstSubpass = 0;
    deps[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
    deps[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT | VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT;
    deps[0].srcAccessMask = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
    deps[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT |
                            VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT;
    deps[1].srcSubpass = 0;
    deps[1].dstSubpass = VK_SUBPASS_EXTERNAL;
    deps[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
    deps[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
    deps[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
    deps[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
    auto rp = info<VkRenderPassCreateInfo>(VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO);
    rp.attachmentCount = 2;
    rp.pAttachments = att;
    rp.subpassCount = 1;
    rp.pSubpasses = &sub;
    rp.dependencyCount = 2;
    rp.pDependencies = deps;
    check(vkCreateRenderPass(device, &rp, nullptr, &renderPass), "vkCreateRenderPass");
    VkImageView views[2] = {colourView, depthView};
    auto fb = info<VkFramebufferCreateInfo>(VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO);
    fb.renderPass = renderPass;
    fb.attachmentCount = 2;
    fb.pAttachments = views;
    fb.width = width;
    fb.height = height;
    fb.layers = 1;
    check(vkCreateFramebuffer(device, &fb, nullptr, &framebuffer), "vkCreateFramebuffer");

    VkPushConstantRange push{VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, 80};
    auto li = info<VkPipelineLayoutCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO);
    li.pushConstantRangeCount = 1;
    li.pPushConstantRanges = &push;
    check(vkCreatePipelineLayout(device, &li, nullptr, &layout), "vkCreatePipelineLayout");
    VkShaderModule vs = module(kVertexShader, sizeof(kVertexShader)), fs = module(kFragmentShader, sizeof(kFragmentShader));
    VkPipelineShaderStageCreateInfo stages[2]{};
    for (int i = 0; i < 2; ++i) {
      stages[i].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
      stages[i].stage = i == 0 ? VK_SHADER_STAGE_VERTEX_BIT : VK_SHADER_STAGE_FRAGMENT_BIT;
      stages[i].module = i == 0 ? vs : fs;
      stages[i].pName = "main";
    }
    // corofem's interleaved surface: position at byte 0, normal at byte 12 of each vertex.
    VkVertexInputBindingDescription binding{0, stride, VK_VERTEX_INPUT_RATE_VERTEX};
    VkVertexInputAttributeDescription attributes[2] = {{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                                       {1, 0, VK_FORMAT_R32G32B32_SFLOAT, 12}};
    auto vi = info<VkPipelineVertexInputStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO);
    vi.vertexBindingDescriptionCount = 1;
    vi.pVertexBindingDescriptions = &binding;
    vi.vertexAttributeDescriptionCount = 2;
    vi.pVertexAttributeDescriptions = attributes;
    auto ia = info<VkPipelineInputAssemblyStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO);
    ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
    VkViewport viewport{0, 0, static_cast<float>(width), static_cast<float>(height), 0, 1};
    VkRect2D scissor{{0, 0}, {width, height}};
    auto vp = info<VkPipelineViewportStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO);
    vp.viewportCount = 1;
    vp.pViewports = &viewport;
    vp.scissorCount = 1;
    vp.pScissors = &scissor;
    auto rs = info<VkPipelineRasterizationStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO);
    rs.polygonMode = VK_POLYGON_MODE_FILL;
    rs.cullMode = VK_CULL_MODE_NONE;
    rs.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
    rs.lineWidth = 1;
    auto ms = info<VkPipelineMultisampleStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO);
    ms.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
    auto ds = info<VkPipelineDepthStencilStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO);
    ds.depthTestEnable = VK_TRUE;
    ds.depthWriteEnable = VK_TRUE;
    ds.depthCompareOp = VK_COMPARE_OP_LESS;
    VkPipelineColorBlendAttachmentState blend{};
    blend.colorWriteMask = VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT | VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
    auto cbs = info<VkPipelineColorBlendStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO);
    cbs.attachmentCount = 1;
    cbs.pAttachments = &blend;
    auto gp = info<VkGraphicsPipelineCreateInfo>(VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO);
    gp.stageCount = 2;
    gp.pStages = stages;
    gp.pVertexInputState = &vi;
    gp.pInputAssemblyState = &ia;
    gp.pViewportState = &vp;
    gp.pRasterizationState = &rs;
    gp.pMultisampleState = &ms;
    gp.pDepthStencilState = &ds;
    gp.pColorBlendState = &cbs;
    gp.layout = layout;
    gp.renderPass = renderPass;
    const VkResult r = vkCreateGraphicsPipelines(device, VK_NULL_HANDLE, 1, &gp, nullptr, &pipeline);
    vkDestroyShaderModule(device, vs, nullptr);
    vkDestroyShaderModule(device, fs, nullptr);
    check(r, "vkCreateGraphicsPipelines");

    void* mapped = nullptr;
    indexBuffer = hostBuffer(triangles.size() * 4, VK_BUFFER_USAGE_INDEX_BUFFER_BIT, indexMemory, &mapped);
    std::memcpy(mapped, triangles.data(), triangles.size() * 4);
    indexCount = static_cast<std::uint32_t>(triangles.size());
    readBuffer = hostBuffer(static_cast<std::size_t>(width) * height * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT, readMemory, &readMapped);

    auto pi = info<VkCommandPoolCreateInfo>(VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO);
    pi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pi.queueFamilyIndex = family;
    check(vkCreateCommandPool(device, &pi, nullptr, &pool), "vkCreateCommandPool");
    auto ca = info<VkCommandBufferAllocateInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO);
    ca.commandPool = pool;
    ca.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ca.commandBufferCount = 1;
    check(vkAllocateCommandBuffers(device, &ca, &cb), "vkAllocateCommandBuffers");
    auto fi = info<VkFenceCreateInfo>(VK_STRUCTURE_TYPE_FENCE_CREATE_INFO);
    check(vkCreateFence(device, &fi, nullptr, &fence), "vkCreateFence");
  }

  /// Draws `vertices` (corofem's buffer, bound at its offset) with `mvp` and copies the colour image
  /// to the host: one submission on the queue corofem updated the surface on, waited for.
  void draw(const corofem::GpuBuffer& vertices, const Mat4& mvp, std::vector<std::uint8_t>& rgba) {
    check(vkResetFences(device, 1, &fence), "vkResetFences");
    check(vkResetCommandBuffer(cb, 0), "vkResetCommandBuffer");
    auto bi = info<VkCommandBufferBeginInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO);
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(vkBeginCommandBuffer(cb, &bi), "vkBeginCommandBuffer");
    VkClearValue clear[2];
    clear[0].color = {{0.96f, 0.96f, 0.94f, 1.0f}};
    clear[1].depthStencil = {1.0f, 0};
    auto rb = info<VkRenderPassBeginInfo>(VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO);
    rb.renderPass = renderPass;
    rb.framebuffer = framebuffer;
    rb.renderArea = {{0, 0}, {width, height}};
    rb.clearValueCount = 2;
    rb.pClearValues = clear;
    vkCmdBeginRenderPass(cb, &rb, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline);
    float push[20];
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) push[4 * j + i] = static_cast<float>(mvp[4 * i + j]);  // column-major
    const double l[3] = {0.3, 0.8, 0.5}, ll = std::hypot(l[0], l[1], l[2]);
    for (int k = 0; k < 3; ++k) push[16 + k] = static_cast<float>(l[k] / ll);
    push[19] = 0;
    vkCmdPushConstants(cb, layout, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), push);
    const VkBuffer vb = reinterpret_cast<VkBuffer>(vertices.handle);
    const VkDeviceSize offset = vertices.offset;
    vkCmdBindVertexBuffers(cb, 0, 1, &vb, &offset);
    vkCmdBindIndexBuffer(cb, indexBuffer, 0, VK_INDEX_TYPE_UINT32);
    vkCmdDrawIndexed(cb, indexCount, 1, 0, 0, 0);
    vkCmdEndRenderPass(cb);
    VkBufferImageCopy copy{};
    copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    copy.imageExtent = {width, height, 1};
    vkCmdCopyImageToBuffer(cb, colour, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, readBuffer, 1, &copy);
    auto m = info<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
    m.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    m.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &m, 0, nullptr, 0, nullptr);
    check(vkEndCommandBuffer(cb), "vkEndCommandBuffer");
    auto si = info<VkSubmitInfo>(VK_STRUCTURE_TYPE_SUBMIT_INFO);
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cb;
    check(vkQueueSubmit(queue, 1, &si, fence), "vkQueueSubmit");
    check(vkWaitForFences(device, 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    rgba.resize(static_cast<std::size_t>(width) * height * 4);
    std::memcpy(rgba.data(), readMapped, rgba.size());
  }

  ~Renderer() {
    if (device) {
      vkDeviceWaitIdle(device);
      if (fence) vkDestroyFence(device, fence, nullptr);
      if (pool) vkDestroyCommandPool(device, pool, nullptr);
      if (pipeline) vkDestroyPipeline(device, pipeline, nullptr);
      if (layout) vkDestroyPipelineLayout(device, layout, nullptr);
      if (framebuffer) vkDestroyFramebuffer(device, framebuffer, nullptr);
      if (renderPass) vkDestroyRenderPass(device, renderPass, nullptr);
      for (VkImageView v : {colourView, depthView})
        if (v) vkDestroyImageView(device, v, nullptr);
      for (VkImage i : {colour, depth})
        if (i) vkDestroyImage(device, i, nullptr);
      for (VkBuffer b : {readBuffer, indexBuffer})
        if (b) vkDestroyBuffer(device, b, nullptr);
      for (VkDeviceMemory m : {colourMemory, depthMemory, readMemory, indexMemory})
        if (m) vkFreeMemory(device, m, nullptr);
      vkDestroyDevice(device, nullptr);
    }
    if (instance) vkDestroyInstance(instance, nullptr);
  }
};

int usage() {
  std::cerr << "usage: renderer [--out DIR] [--frames N >= 1] [--png-every K >= 1] [--width 16..8192] [--height 16..8192]\n";
  return 2;
}

int run(int argc, char** argv) {
  std::string out = "out/renderer";
  long frames = 120, pngEvery = 20;
  std::uint32_t width = 640, height = 480;
  // A whole number in [lo, hi], or false.
  auto number = [](const std::string& text, long lo, long hi, long& out) {
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(text.c_str(), &end, 10);
    if (text.empty() || *end != '\0' || errno != 0 || v < lo || v > hi) return false;
    out = v;
    return true;
  };
  long w = width, h = height;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    const std::string v = argv[++i];
    bool ok = true;
    if (a == "--out") out = v;
    else if (a == "--frames") ok = number(v, 1, 1000000, frames);
    else if (a == "--png-every") ok = number(v, 1, 1000000, pngEvery);
    else if (a == "--width") ok = number(v, 16, 8192, w);
    else if (a == "--height") ok = number(v, 16, 8192, h);
    else ok = false;
    if (!ok) return usage();
  }
  width = static_cast<std::uint32_t>(w);
  height = static_cast<std::uint32_t>(h);
  if (!std::ifstream("../shared/data/meshes/sofa/liver.msh")) {
    std::cerr << "renderer: ../shared/data/meshes/sofa/liver.msh is absent (run from the project root, with the "
                 "shared data folder beside it); skipping\n";
    return 77;
  }
  Renderer r;
  if (!r.open()) {
    std::cerr << "renderer: no Vulkan device with a graphics and compute queue (Debian: mesa-vulkan-drivers); skipping\n";
    return 77;
  }
  // The liver as samples/interactive has it, on corofem's Vulkan backend in float, open-ended at 60 Hz.
  const std::string text = R"({
    "name": "renderer_liver",
    "bodies": [{
      "name": "liver",
      "mesh": {"file": "../shared/data/meshes/sofa/liver.msh"},
      "surface": "../shared/data/meshes/sofa/liver-smooth.obj",
      "material": {"youngs_modulus": 3000, "poisson_ratio": 0.45, "density": 1, "rayleigh_mass": 1.0},
      "fixed": [{"box": {"min": [1.2, 0, -2], "max": [2, 6, 3]}}],
      "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]
    }],
    "analysis": {"type": "dynamic", "time_step": 0.016667, "steps": 0},
    "solver": {"precision": "float", "tolerance": 1e-5, "preconditioner": "block_diagonal"},
    "backend": "vulkan"
  })";
  corofem::Result<corofem::Scene> scene = corofem::parseScene(text, ".");
  if (!scene) throw std::runtime_error("scene: " + scene.message());
  corofem::SimulationOptions options;
  options.device = r.lent();  // corofem's buffers, pipelines and submissions on the renderer's device and queue
  corofem::Result<corofem::Simulation> created = corofem::Simulation::create(scene.value(), options);
  if (!created) throw std::runtime_error("create: " + created.message());
  corofem::Simulation& sim = created.value();
  const corofem::SurfaceMesh& rest = *sim.restSurface(0);
  r.build(width, height, rest.triangles, 24);

  // The camera: the rest surface's bounding box seen from the front, a little above.
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::size_t v = 0; v < rest.vertexCount(); ++v)
    for (int k = 0; k < 3; ++k) {
      lo[static_cast<std::size_t>(k)] = std::min(lo[static_cast<std::size_t>(k)], rest.vertices[3 * v + static_cast<std::size_t>(k)]);
      hi[static_cast<std::size_t>(k)] = std::max(hi[static_cast<std::size_t>(k)], rest.vertices[3 * v + static_cast<std::size_t>(k)]);
    }
  const std::array<double, 3> centre{(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2 + 0.6, (lo[2] + hi[2]) / 2};
  const double radius = 0.5 * std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  const Mat4 mvp = cameraMatrix({centre[0] + 0.35 * radius, centre[1] + 0.6 * radius, centre[2] + 2.1 * radius}, centre,
                                0.75, static_cast<double>(width) / height, 0.1 * radius, 10 * radius);

  // The scripted drag: the left lobe held by a handle and moved along a loop.
  const double grab[3] = {-4.2, 2.6, 0.5};
  corofem::HandleDesc hd;
  for (int k = 0; k < 3; ++k) hd.point[k] = grab[k];
  hd.radius = 0.6;
  corofem::Result<int> handle = sim.addHandle(hd);
  if (!handle) throw std::runtime_error("addHandle: " + handle.message());

  std::filesystem::create_directories(out);
  std::ofstream csv(out + "/frames.csv");
  csv << "frame,step_ms,draw_ms,pcg_iterations,pixels_covered,pixels_checked,pixels_differing\n";
  const double dt = 1.0 / 60.0;
  std::vector<std::uint8_t> rgba;
  std::vector<double> stepMs, drawMs;
  long badPixels = 0, checkedPixels = 0;
  for (long f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f + 1) * dt, a = 2.0 * M_PI * t / 2.0;
    const double target[3] = {grab[0] + 0.8 * std::sin(a), grab[1] + 1.2 * (1.0 - std::cos(a)), grab[2] + 0.6 * std::sin(2 * a)};
    if (!sim.moveHandle(handle.value(), target)) throw std::runtime_error("moveHandle failed");
    corofem::StepReport report;
    auto t0 = Clock::now();
    const corofem::Status st = sim.step(dt, &report);
    if (!st) throw std::runtime_error("step " + std::to_string(f) + ": " + st.message());
    stepMs.push_back(msSince(t0));
    t0 = Clock::now();
    // The surface's update is submitted to the renderer's queue by this call; the draw follows it there.
    const corofem::GpuBuffer vertices = sim.surfaceBuffer(0);
    if (vertices.api != corofem::GpuApi::Vulkan || vertices.stride != 24)
      throw std::runtime_error("the surface is not in a Vulkan buffer of 24-byte vertices (backend " + sim.backendName() + ")");
    r.draw(vertices, mvp, rgba);
    drawMs.push_back(msSince(t0));

    // The check: the host's rasterisation of the surface corofem reports against the GPU's drawing.
    std::vector<double> positions;
    if (!sim.readSurface(0, positions)) throw std::runtime_error("readSurface failed");
    const std::vector<std::uint8_t> mask = hostCoverage(positions, rest.triangles, mvp, static_cast<int>(width), static_cast<int>(height));
    // The clear colour as the UNORM image holds it.
    const std::uint8_t bg[3] = {static_cast<std::uint8_t>(std::lround(0.96 * 255)),
                                static_cast<std::uint8_t>(std::lround(0.96 * 255)),
                                static_cast<std::uint8_t>(std::lround(0.94 * 255))};
    long covered = 0, checked = 0, differing = 0;
    const int W = static_cast<int>(width), H = static_cast<int>(height);
    for (int y = 1; y + 1 < H; ++y)
      for (int x = 1; x + 1 < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * width + static_cast<std::size_t>(x);
        const std::uint8_t c = mask[i];
        bool uniform = true;
        for (int dy = -1; dy <= 1 && uniform; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            if (mask[static_cast<std::size_t>(y + dy) * width + static_cast<std::size_t>(x + dx)] != c) uniform = false;
        const bool drawn = std::memcmp(&rgba[4 * i], bg, 3) != 0;
        covered += drawn;
        if (!uniform) continue;
        ++checked;
        differing += drawn != (c != 0);
      }
    badPixels += differing;
    checkedPixels += checked;
    csv << f << ',' << stepMs.back() << ',' << drawMs.back() << ',' << report.linearIterations << ',' << covered << ','
        << checked << ',' << differing << '\n';
    if (covered == 0) throw std::runtime_error("frame " + std::to_string(f) + " drew nothing");
    if ((f + 1) % pngEvery == 0 || f + 1 == frames) {
      char name[32];
      std::snprintf(name, sizeof(name), "/frame_%04ld.png", f + 1);
      writePng(out + name, rgba, width, height);
    }
  }
  csv.close();
  if (!csv) throw std::runtime_error("could not write " + out + "/frames.csv");
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  std::cout << "renderer: " << frames << " frames of the liver (" << rest.vertexCount() << " surface vertices) on '"
            << r.deviceName << "' (" << sim.backendName() << " backend on the renderer's VkDevice), " << width << "x"
            << height << "; median step " << median(stepMs) << " ms, median surface update + draw + read-back "
            << median(drawMs) << " ms; pixel check: " << badPixels << " of " << checkedPixels
            << " pixels away from the silhouette's edge differ from the host's projection; frames in " << out << '\n';
  if (badPixels != 0) {
    std::cerr << "renderer: the drawn surface is not where the simulation says it is (" << badPixels << " pixels)\n";
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "renderer: " << e.what() << '\n';
    return 1;
  }
}
