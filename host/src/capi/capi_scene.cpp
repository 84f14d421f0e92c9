// The C API's scenes (corofem.h, "scenes"): load, parse, an in-memory mesh for a body. Creating
// simulations from them is capi_create.cpp's (this file links without the solver: the fuzz target
// tests/fuzz/targets/fuzz_capi_scene.cpp).
#include "capi/capi_support.hpp"

#include <memory>

namespace corofem::capi {
namespace {

/// Hands a parsed scene to the caller as a new handle.
Status giveScene(Result<Scene> parsed, corofem_scene** out) {
  if (!parsed) return parsed.status();
  *out = new corofem_scene{std::move(parsed).value()};
  return Status::ok();
}

corofem_status load(const char* kFn, const char* path, const char* const* overrides, size_t override_count,
                    const corofem_input_limits* limits, corofem_scene** scene) {
  return call(kFn, [&] {
    require(path, kFn, "path", "pass the path of a JSON scene file");
    require(scene, kFn, "scene", "pass the address of a corofem_scene* to receive the scene");
    const std::vector<std::string> sets = stringList(overrides, override_count, kFn, "overrides");
    return giveScene(loadScene(path, sets, limitsOf(limits)), scene);
  });
}

corofem_status parse(const char* kFn, const char* json, const char* base_dir, const char* const* overrides,
                     size_t override_count, const corofem_input_limits* limits, corofem_scene** scene) {
  return call(kFn, [&] {
    require(json, kFn, "json", "pass the scene's JSON text");
    require(scene, kFn, "scene", "pass the address of a corofem_scene* to receive the scene");
    const std::vector<std::string> sets = stringList(overrides, override_count, kFn, "overrides");
    return giveScene(parseScene(json, base_dir ? base_dir : "", sets, limitsOf(limits)), scene);
  });
}

}  // namespace
}  // namespace corofem::capi

using namespace corofem;
using namespace corofem::capi;

extern "C" {

corofem_status corofem_scene_load(const char* path, const char* const* overrides, size_t override_count,
                                  corofem_scene** scene) {
  return load("corofem_scene_load", path, overrides, override_count, nullptr, scene);
}

corofem_status corofem_scene_load_with_limits(const char* path, const char* const* overrides, size_t override_count,
                                              const corofem_input_limits* limits, corofem_scene** scene) {
  return load("corofem_scene_load_with_limits", path, overrides, override_count, limits, scene);
}

corofem_status corofem_scene_parse(const char* json, const char* base_dir, const char* const* overrides,
                                   size_t override_count, corofem_scene** scene) {
  return parse("corofem_scene_parse", json, base_dir, overrides, override_count, nullptr, scene);
}

corofem_status corofem_scene_parse_with_limits(const char* json, const char* base_dir, const char* const* overrides,
                                               size_t override_count, const corofem_input_limits* limits,
                                               corofem_scene** scene) {
  return parse("corofem_scene_parse_with_limits", json, base_dir, overrides, override_count, limits, scene);
}

void corofem_scene_destroy(corofem_scene* scene) { delete scene; }

corofem_status corofem_scene_body_count(const corofem_scene* scene, int* count) {
  static constexpr const char* kFn = "corofem_scene_body_count";
  return call(kFn, [&] {
    require(scene, kFn, "scene", "pass a scene from corofem_scene_load or corofem_scene_parse");
    require(count, kFn, "count", "pass the address of an int");
    *count = static_cast<int>(scene->scene.bodies.size());
    return Status::ok();
  });
}

corofem_status corofem_scene_set_step_count(corofem_scene* scene, int steps) {
  static constexpr const char* kFn = "corofem_scene_set_step_count";
  return call(kFn, [&] {
    require(scene, kFn, "scene", "pass a scene from corofem_scene_load or corofem_scene_parse");
    AnalysisDesc& analysis = scene->scene.analysis;
    if (analysis.kind == AnalysisDesc::Kind::Static) {
      if (steps < 1)
        detail::fail(ErrorCode::BadInput, kFn, ": a static analysis takes >= 1 load increments, got ", steps);
      analysis.statics.increments = steps;
    } else {
      if (steps < 0)
        detail::fail(ErrorCode::BadInput, kFn, ": a dynamic analysis takes >= 0 steps (0: open-ended), got ", steps);
      analysis.dynamics.steps = steps;
    }
    return Status::ok();
  });
}

corofem_status corofem_scene_set_body_mesh(corofem_scene* scene, int body, const double* nodes, size_t node_count,
                                           const uint32_t* tets, size_t tet_count) {
  static constexpr const char* kFn = "corofem_scene_set_body_mesh";
  return call(kFn, [&] {
    require(scene, kFn, "scene", "pass a scene from corofem_scene_load or corofem_scene_parse");
    std::vector<BodyDesc>& bodies = scene->scene.bodies;
    if (body < 0 || static_cast<std::size_t>(body) >= bodies.size())
      detail::fail(ErrorCode::BadInput, kFn, ": body index ", body, " is out of range: the scene has ", bodies.size(),
                   " body(ies), numbered from 0");
    if (node_count < 4 || tet_count < 1)
      detail::fail(ErrorCode::BadInput, kFn, ": a mesh needs at least 4 nodes and 1 tetrahedron; got ", node_count,
                   " and ", tet_count);
    require(nodes, kFn, "nodes", "pass 3 * node_count coordinates (m)");
    require(tets, kFn, "tets", "pass 4 * tet_count node indices (0-based)");
    auto mesh = std::make_shared<TetMesh>();
    mesh->nodes.assign(nodes, nodes + 3 * node_count);
    mesh->tets.assign(tets, tets + 4 * tet_count);
    MeshSourceDesc& source = bodies[static_cast<std::size_t>(body)].mesh;
    source.file.clear();
    source.box.reset();
    source.mesh = std::move(mesh);
    return Status::ok();
  });
}

corofem_options corofem_default_options(void) {
  corofem_options o;
  o.devices = nullptr;
  o.device_count = 0;
  o.device.api = COROFEM_GPU_NONE;
  o.device.context = o.device.queue = o.device.device = nullptr;
  o.device.instance = o.device.physical_device = nullptr;
  o.device.queue_family = 0;
  o.device.shader_float64 = 0;
  o.limits = corofem_default_input_limits();
  return o;
}

corofem_input_limits corofem_default_input_limits(void) {
  const InputLimits defaults;
  corofem_input_limits l;
  l.max_input_bytes = defaults.maxInputBytes;
  l.max_scene_bytes = defaults.maxSceneBytes;
  l.max_box_tets = defaults.maxBoxTets;
  return l;
}

}  // extern "C"
