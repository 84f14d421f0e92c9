// libFuzzer target: the medit reader (mesh::parseMedit) and the shared mesh validation, from memory.
#define COROFEM_FUZZ_PARSER parseMedit
#define COROFEM_FUZZ_PATH "fuzz.mesh"
#include "fuzz_tet_reader.hpp"
