// Reading an input file (mesh, surface, .bou node set, scene) whole into memory, safely: only
// regular files (a directory, a FIFO, /dev/zero or a terminal is refused before any read, so
// nothing blocks or reads without end), and at most the InputLimits (corofem/mesh.hpp) of its kind.
#pragma once

#include <corofem/mesh.hpp>

#include <cstdint>
#include <string>
#include <string_view>

namespace corofem::mesh {

/// One field of InputLimits, as messages name it: in C++, in the C API and on the command line.
struct LimitName {
  const char* field;    ///< "maxInputBytes" (InputLimits::maxInputBytes)
  const char* cField;   ///< "max_input_bytes" (corofem_input_limits.max_input_bytes)
  const char* flag;     ///< "--max-input-bytes" (the corofem command)
  const char* example;  ///< a raised value for the flag, "4G"
  std::uint64_t defaultValue;
};

constexpr LimitName kMaxInputBytes{"maxInputBytes", "max_input_bytes", "--max-input-bytes", "4G",
                                   InputLimits{}.maxInputBytes};
constexpr LimitName kMaxSceneBytes{"maxSceneBytes", "max_scene_bytes", "--max-scene-bytes", "64M",
                                   InputLimits{}.maxSceneBytes};
constexpr LimitName kMaxBoxTets{"maxBoxTets", "max_box_tets", "--max-box-tets", "100M", InputLimits{}.maxBoxTets};

/// "InputLimits::maxInputBytes" followed by ", the default" when `value` is the default.
std::string limitInUse(const LimitName& limit, std::uint64_t value);

/// How to raise the limit: "InputLimits::maxInputBytes (C API: corofem_input_limits.max_input_bytes;
/// the corofem command: --max-input-bytes, e.g. --max-input-bytes 4G)".
std::string howToRaise(const LimitName& limit);

/// A size or count: a whole number > 0, optionally with K, M, G or T (powers of 1024; a trailing B
/// is allowed: "4GB"). Throws BadInput naming `what` (e.g. "--max-input-bytes") and `example` when
/// the text is not such a number or does not fit in 64 bits.
std::uint64_t parseSize(std::string_view text, const std::string& what, const char* example);

/// Which limit of InputLimits a file is read under.
enum class InputKind {
  Data,   ///< a mesh, surface or .bou file: maxInputBytes
  Scene,  ///< a scene file: maxSceneBytes
};

/// Reads the regular file at path whole. `name` says what the file is in messages, path included
/// ("mesh file beam.msh", "the scene file \"a.json\""); `openHint` follows the reason when the file
/// cannot be opened. Throws IoError when the file cannot be opened or read, BadInput when it is not
/// a regular file or is larger than the limit of its kind (the message names the limit and how to
/// raise it).
std::string readInputFile(const std::string& path, const std::string& name, const std::string& openHint,
                          const InputLimits& limits, InputKind kind = InputKind::Data);

}  // namespace corofem::mesh
