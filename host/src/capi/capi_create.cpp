// The C API's creation and destruction of simulations with their options, and the warm-up
// (corofem.h, "creation").
#include "capi/capi_support.hpp"

namespace corofem::capi {
namespace {

SimulationOptions optionsOf(const corofem_options& o, const char* function) {
  SimulationOptions options;
  options.devices = stringList(o.devices, o.device_count, function, "options->devices");
  const corofem_external_device& d = o.device;
  switch (d.api) {
    case COROFEM_GPU_NONE: break;
    case COROFEM_GPU_OPENCL: options.device.api = GpuApi::OpenCL; break;
    case COROFEM_GPU_VULKAN: options.device.api = GpuApi::Vulkan; break;
    default:
      detail::fail(ErrorCode::BadInput, function, ": options->device.api is ", static_cast<int>(d.api),
                   "; use COROFEM_GPU_NONE (no device lent), COROFEM_GPU_OPENCL or COROFEM_GPU_VULKAN");
  }
  options.device.context = d.context;
  options.device.queue = d.queue;
  options.device.device = d.device;
  options.device.instance = d.instance;
  options.device.physicalDevice = d.physical_device;
  options.device.queueFamily = d.queue_family;
  options.device.shaderFloat64 = d.shader_float64 != 0;
  options.inputLimits = limitsOf(&o.limits);
  return options;
}

}  // namespace
}  // namespace corofem::capi

using namespace corofem;
using namespace corofem::capi;

extern "C" {

corofem_status corofem_simulation_create(const corofem_scene* scene, const corofem_options* options,
                                         corofem_simulation** simulation) {
  static constexpr const char* kFn = "corofem_simulation_create";
  return call(kFn, [&] {
    require(scene, kFn, "scene", "pass a scene from corofem_scene_load or corofem_scene_parse");
    require(simulation, kFn, "simulation", "pass the address of a corofem_simulation* to receive the simulation");
    const SimulationOptions o = options ? optionsOf(*options, kFn) : SimulationOptions{};
    Result<Simulation> made = Simulation::create(scene->scene, o);
    if (!made) return made.status();
    *simulation = new corofem_simulation{std::move(made).value()};
    return Status::ok();
  });
}

corofem_status corofem_warm_up(const corofem_scene* scene, const corofem_options* options, double* seconds) {
  static constexpr const char* kFn = "corofem_warm_up";
  return call(kFn, [&] {
    require(scene, kFn, "scene", "pass a scene from corofem_scene_load or corofem_scene_parse");
    const SimulationOptions o = options ? optionsOf(*options, kFn) : SimulationOptions{};
    double taken = 0.0;
    const Status st = warmUp(scene->scene, o, &taken);
    if (seconds) *seconds = taken;
    return st;
  });
}

void corofem_simulation_destroy(corofem_simulation* simulation) {
  // ~Simulation does not throw (the C++ API's destructors are noexcept).
  delete simulation;
}

}  // extern "C"
