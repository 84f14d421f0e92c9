// The "vulkan" entry of the backend registry (device/registry.hpp): the devices the Vulkan
// instance lists, the selector's rule (selectDeviceIndex), what the backend refuses, and its build
// id (the embedded shaders' hash) for the calibration cache.
#include "backends/vulkan/shaders.hpp"
#include "backends/vulkan/vk_runtime.hpp"
#include "backends/vulkan/vulkan_device.hpp"
#include "device/registry.hpp"
#include "util/error.hpp"

#include <sstream>

namespace corofem::detail {

std::string vulkanRefusal(const Problem& p, const SolverDesc& s) {
  if (std::string why = hostOnlyFeature(p, s); !why.empty()) return why;
  if (s.preconditioner == PreconditionerKind::WarpedCholesky)
    return "the preconditioner \"warped_cholesky\" runs on the reference and opencl backends, not on vulkan; set "
           "\"backend\": \"reference\" or \"opencl\", or the preconditioner \"amg\"";
  if (s.precision == Precision::Mixed)
    return "the vulkan backend runs in float or double, not mixed precision; set solver.precision to \"float\" or "
           "\"double\"";
  return "";
}

namespace {

std::size_t deviceIndex(const std::string& selector) {
  const auto instance = vk::Instance::shared();
  const auto& devices = instance->devices();
  auto list = [&] {
    std::ostringstream os;
    for (std::size_t i = 0; i < devices.size(); ++i) os << (i ? ", " : "") << i << " (" << devices[i].name << ")";
    return devices.empty() ? std::string("none") : os.str();
  };
  if (devices.empty())
    fail(ErrorCode::DeviceError, "Vulkan: no device can run corofem's shaders here (Vulkan 1.1, a compute queue and 31 "
         "storage buffers per stage are needed); install mesa-vulkan-drivers for the lavapipe CPU device");
  std::vector<std::string> names;
  std::vector<bool> gpu;
  for (const vk::PhysicalDevice& d : devices) {
    names.push_back(d.name);
    gpu.push_back(d.gpu);
  }
  if (const std::size_t i = selectDeviceIndex(names, gpu, selector); i < devices.size()) return i;
  fail(ErrorCode::DeviceError, "Vulkan device selector '", selector, "' matches no device; give an index or a part "
       "of a name of: ", list());
}

Candidate candidateOf(std::size_t index) {
  const auto instance = vk::Instance::shared();
  const vk::PhysicalDevice& d = instance->devices()[index];
  Candidate c;
  c.backend = "vulkan";
  c.device = d.name;
  c.selector = std::to_string(index);
  c.driver = d.driver;
  c.gpu = d.gpu;
  return c;
}

}  // namespace

void registerVulkanBackend() {
  BackendEntry e;
  e.name = "vulkan";
  e.batches = true;
  e.passes = [](const PlanPasses& step) {
    std::vector<std::string> k;
    if (step.corotational) k.push_back(std::string("rotations.comp (") + toString(step.rotation) + ")");
    k.push_back("element.comp + gather.comp (forces and element energies)");
    k.push_back(std::string("element.comp + gather.comp (product of ") +
                (step.dynamic ? (step.damping ? "M, C, K_t" : "M, K_t") : "K_t") + ")");
    k.push_back(std::string("pcg.comp") + step.formsInverse() +
                " + reduce.comp (single-reduction PCG, scalars and stop flags on the device)" +
                "; on a GPU (VulkanTuning::fusedPcg) an iteration in " + (step.amg() ? "three" : "two") +
                " dispatches: " + (step.amg() ? "pcg.comp's update, the V-cycle, element.comp" : "element_fused.comp") +
                " and pcg_fused.comp with the scalars" +
                (step.amg() ? "" : "; bodies up to VulkanTuning::groupPcgNodes nodes (by default 2,048 on a CPU "
                            "device, none on a GPU) run whole iterations in one pcg_group.comp dispatch, a "
                            "work-group per body"));
    if (step.amg())
      k.push_back("amg.comp V-cycle per iteration: Chebyshev smoothing with 4 products (element.comp + "
                  "gather.comp), level-0 passes and sliced-ELLPACK products on the coarse levels (the "
                  "iterations dispatched phase by phase, not in pcg_group.comp)");
    return k;
  };
  e.buffers = [](const PlanPasses& step, const PlanSizes& z) {
    // vulkan_build.cpp's buffers, this body's share (padding aside).
    const double E = z.elements, N = z.nodes, D = 3 * N, r = z.realBytes;
    std::vector<PlanBuffer> b = {
        {"element_corners", 16 * E},
        {"element_geometry", 10 * E * r},
        {"rotated_gradients", 9 * E * r},
        {"element_output", 12 * E * r},
        {"element_energies", E * r},
        {"gather_lists", 4 * (N + 1) + 16 * E},
        {"positions", D * r},
        {"lumped_mass, free_mask, spring_stiffness", 3 * D * r},
        {"node_blocks, preconditioner_inverse", 15 * N * r},
        {"pcg_vectors (b x r u p s w)", 7 * D * r},
        {"product input and output", 2 * D * r},
        {"staging (host-visible: up, down)", 3 * D * r + E * r}};
    if (step.corotational && step.rotation == RotationMethod::Quaternion) b.push_back({"quaternions", 4 * E * r});
    if (step.amg()) {
      b.push_back({"amg levels (estimate: prolongations, coarse operators)", z.amgEntriesPerDof * D * (r + 4)});
      b.push_back({"amg level-0 vectors", 3 * D * r});
    }
    return b;
  };
  e.candidates = [] {
    std::vector<Candidate> out;
    try {
      const auto instance = vk::Instance::shared();
      for (std::size_t i = 0; i < instance->devices().size(); ++i) out.push_back(candidateOf(i));
    } catch (const Error&) {
      // no Vulkan driver here: no candidate (the scheduler goes on with the others)
    }
    return out;
  };
  e.resolve = [](const std::string& selector) {
    if (selector == kExternalSelector) {  // the handles come with create (DeviceOptions::external)
      Candidate c;
      c.backend = "vulkan";
      c.device = "the application's Vulkan device";
      c.selector = kExternalSelector;
      c.driver = "external";
      return c;
    }
    return candidateOf(deviceIndex(selector));
  };
  e.refuses = vulkanRefusal;
  e.create = [](const std::vector<const Problem*>& problems, const SolverDesc& solver, const Candidate& c,
                const DeviceOptions& options) -> std::unique_ptr<Device> {
    if (c.selector == kExternalSelector) {
      if (options.external.api != GpuApi::Vulkan)
        fail(ErrorCode::BadInput, "device 'vulkan:external' needs SimulationOptions::device with the application's "
             "Vulkan handles (api GpuApi::Vulkan)");
      return createVulkanDevice(problems, solver, options.external, options.vulkan);
    }
    return createVulkanDevice(problems, solver, deviceIndex(c.selector), options.vulkan);
  };
  e.buildId = [] {
    std::ostringstream hex;
    hex << "shaders " << std::hex << vk::shaderHash();
    return hex.str();
  };
  registerBackend(std::move(e));
}

}  // namespace corofem::detail
