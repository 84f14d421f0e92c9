// libFuzzer target: the veg reader (mesh::parseVeg) and the shared mesh validation, from memory.
#define COROFEM_FUZZ_PARSER parseVeg
#define COROFEM_FUZZ_PATH "fuzz.veg"
#include "fuzz_tet_reader.hpp"
