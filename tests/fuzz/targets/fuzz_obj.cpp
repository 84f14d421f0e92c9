// libFuzzer target: the Wavefront OBJ surface reader (mesh::parseObj), from memory.
#include "fuzz_support.hpp"

#include "mesh/readers.hpp"
#include "util/error.hpp"

#include <cstddef>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace corofem;
  const std::string text = fuzz::expandRuns({reinterpret_cast<const char*>(data), size});
  MeshReadReport report;
  const Result<SurfaceMesh> surface =
      detail::guardResult<SurfaceMesh>([&] { return mesh::parseObj(text, "fuzz.obj", report); });
  if (surface.isOk()) fuzz::checkSurface(surface.value(), "fuzz.obj");
  else fuzz::checkRefusal(surface.status(), "fuzz.obj");
  return 0;
}
