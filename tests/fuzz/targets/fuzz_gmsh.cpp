// libFuzzer target: the gmsh reader (mesh::parseGmsh) and the shared mesh validation, from memory.
#define COROFEM_FUZZ_PARSER parseGmsh
#define COROFEM_FUZZ_PATH "fuzz.msh"
#include "fuzz_tet_reader.hpp"
