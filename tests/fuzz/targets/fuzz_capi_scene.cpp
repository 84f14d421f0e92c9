// libFuzzer target: the C API's scene and mesh entry points (corofem.h): corofem_scene_parse on the
// input's JSON text, then corofem_scene_set_body_mesh with an in-memory mesh made of the input's
// remaining bytes (node and tet counts, coordinates, indices in and out of range), then the
// library's check of that mesh (loadBodyMesh, which Simulation::create runs). Invariants: every
// status is one of the documented codes, a refusal has a bounded message and is never an internal
// error, and an accepted mesh has indices in range, finite coordinates and positive volumes.
// The input: the JSON text, a NUL byte, then the mesh bytes.
#include "fuzz_support.hpp"

#include "capi/capi_support.hpp"

#include <corofem/corofem.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace {

using namespace corofem;

/// The last call's status as the C API reports it, checked.
void checkStatus(corofem_status st, const char* what) {
  fuzz::require(st >= COROFEM_OK && st <= COROFEM_INTERNAL, std::string(what) + ": an undocumented status");
  if (st == COROFEM_OK) {
    fuzz::require(corofem_last_error_message()[0] == '\0', std::string(what) + ": a success left a message");
    return;
  }
  fuzz::checkRefusal(Status(static_cast<ErrorCode>(st), corofem_last_error_message()), what);
}

/// Bytes [at, at + n) of the input, zero past its end.
void take(const std::uint8_t* data, std::size_t size, std::size_t& at, void* out, std::size_t n) {
  std::memset(out, 0, n);
  if (at < size) std::memcpy(out, data + at, std::min(n, size - at));
  at += n;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::uint8_t* nul = static_cast<const std::uint8_t*>(std::memchr(data, 0, size));
  const std::string text(reinterpret_cast<const char*>(data), nul ? static_cast<std::size_t>(nul - data) : size);
  corofem_scene* scene = nullptr;
  const corofem_status parsed = corofem_scene_parse(text.c_str(), "", nullptr, 0, &scene);
  checkStatus(parsed, "corofem_scene_parse");
  if (parsed != COROFEM_OK) {
    fuzz::require(scene == nullptr, "a refused scene left a handle");
    return 0;
  }
  fuzz::require(scene != nullptr, "an accepted scene gave no handle");
  int bodies = 0;
  checkStatus(corofem_scene_body_count(scene, &bodies), "corofem_scene_body_count");
  fuzz::require(bodies >= 1, "a scene without bodies was accepted");

  // An in-memory mesh for body 0 from the bytes after the NUL: up to 40 nodes and 40 tets.
  std::size_t at = nul ? static_cast<std::size_t>(nul - data) + 1 : size;
  std::uint8_t counts[2];
  take(data, size, at, counts, 2);
  const std::size_t nodes = counts[0] % 41, tets = counts[1] % 41;
  std::vector<double> xyz(3 * nodes);
  for (double& x : xyz) take(data, size, at, &x, sizeof x);
  std::vector<std::uint32_t> corners(4 * tets);
  for (std::uint32_t& c : corners) {
    std::uint8_t b = 0;
    take(data, size, at, &b, 1);
    c = b % (nodes + 2);  // now and then one past the last node
  }
  const corofem_status set =
      corofem_scene_set_body_mesh(scene, 0, nodes ? xyz.data() : nullptr, nodes, tets ? corners.data() : nullptr, tets);
  checkStatus(set, "corofem_scene_set_body_mesh");
  if (set == COROFEM_OK) {
    const Result<TetMesh> mesh = loadBodyMesh(scene->scene.bodies.front(), "");
    if (mesh.isOk()) fuzz::checkTetMesh(mesh.value(), "loadBodyMesh of a C API mesh");
    else fuzz::checkRefusal(mesh.status(), "loadBodyMesh of a C API mesh");
  }
  corofem_scene_destroy(scene);
  return 0;
}
