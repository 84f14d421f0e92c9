// libFuzzer target: the vtk reader (mesh::parseVtkLegacy) and the shared mesh validation, from memory.
#define COROFEM_FUZZ_PARSER parseVtkLegacy
#define COROFEM_FUZZ_PATH "fuzz.vtk"
#include "fuzz_tet_reader.hpp"
