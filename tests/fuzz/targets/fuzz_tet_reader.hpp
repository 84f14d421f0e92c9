// The body of the in-memory tet-mesh targets (Gmsh, Medit, VTK legacy, Vega): parse the input as
// the format's text, then the shared validation, exactly as readTetMesh does after reading the
// file; check what is accepted (checkTetMesh) and how a refusal reads (checkRefusal). Each
// target's .cpp defines COROFEM_FUZZ_PARSER and COROFEM_FUZZ_PATH and includes this.
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
  const Result<TetMesh> mesh = detail::guardResult<TetMesh>([&] {
    return mesh::finalizeTetMesh(mesh::COROFEM_FUZZ_PARSER(text, COROFEM_FUZZ_PATH, report), COROFEM_FUZZ_PATH,
                                 MeshValidation{}, &report);
  });
  if (mesh.isOk()) {
    fuzz::checkTetMesh(mesh.value(), COROFEM_FUZZ_PATH);
    fuzz::require(!report.format.empty(), "an accepted mesh without a format name");
  } else {
    fuzz::checkRefusal(mesh.status(), COROFEM_FUZZ_PATH);
  }
  return 0;
}
