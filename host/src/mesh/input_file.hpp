// Reading an input file (mesh, surface, .bou node set, scene) whole into memory, safely: only
// regular files (a directory, a FIFO, /dev/zero or a terminal is refused before any read, so
// nothing blocks or reads without end), and at most maxInputBytes() of them.
#pragma once

#include <cstdint>
#include <string>

namespace corofem::mesh {

/// Environment variable that overrides the size limit: bytes, or a number with K, M, G or T
/// (binary multiples), e.g. COROFEM_MAX_INPUT_BYTES=4G.
constexpr const char* kMaxInputBytesVariable = "COROFEM_MAX_INPUT_BYTES";

/// The default limit: 1 GiB, far above any mesh corofem can simulate on one machine.
constexpr std::uint64_t kDefaultMaxInputBytes = std::uint64_t(1) << 30;

/// The default limit of a scene file: 16 MiB (scenes have a few KiB; the parsed JSON takes many
/// times the text's size, so a 1 GiB scene would exhaust the memory).
constexpr std::uint64_t kDefaultMaxSceneBytes = std::uint64_t(16) << 20;

/// A limit from the environment variable `variable`: a whole number > 0, optionally with K, M, G or
/// T (powers of 1024); `fallback` when the variable is unset or empty. Throws BadInput naming the
/// variable, the default and `example` when its value is not such a number.
std::uint64_t limitFromEnvironment(const char* variable, std::uint64_t fallback, const char* example);

/// The largest input file corofem reads: $COROFEM_MAX_INPUT_BYTES, or `fallback` when unset.
/// Throws BadInput naming the variable when its value is not a size.
std::uint64_t maxInputBytes(std::uint64_t fallback = kDefaultMaxInputBytes);

/// Reads the regular file at path whole. `name` says what the file is in messages, path included
/// ("mesh file beam.msh", "the scene file \"a.json\""); `openHint` follows the reason when the file
/// cannot be opened. Throws IoError when the file cannot be opened or read, BadInput when it is not
/// a regular file or is larger than maxInputBytes(defaultLimit).
std::string readInputFile(const std::string& path, const std::string& name, const std::string& openHint = "",
                          std::uint64_t defaultLimit = kDefaultMaxInputBytes);

}  // namespace corofem::mesh
