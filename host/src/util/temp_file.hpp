// Files written whole through a temporary beside them and a rename, so that a reader never sees
// half a file: the kernel cache and the scheduler's calibrations take both a unique temporary and
// the rename; the text writer of the outputs (mesh/text_writer.cpp) takes the rename.
#pragma once

#include <string>
#include <system_error>

namespace corofem::detail {

/// `file` + ".tmp" + a number unique to this process and call (a random number drawn once per
/// process, then a count): two processes writing the same file never share a temporary.
std::string temporaryNameFor(const std::string& file);

/// Puts `tmp` in the place of `file` (std::filesystem::rename, which replaces an existing file on
/// every system; std::rename does not on Windows). On failure `tmp` is removed and the error
/// returned; an empty error_code on success.
std::error_code replaceFile(const std::string& tmp, const std::string& file);

}  // namespace corofem::detail
