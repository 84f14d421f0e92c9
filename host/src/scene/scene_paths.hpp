// Paths named in a scene file (mesh, .bou, surface) are relative to the scene file's folder; names
// in a scene (the scene's, the bodies', the probes') become file names and CSV column names.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace corofem::scene {

/// `path` when it is absolute or `baseDir` is empty, else baseDir/path (lexically normalised, so
/// messages show "../shared/data/x.msh" rather than "docs/examples/../../../shared/data/x.msh").
std::string resolveScenePath(const std::string& baseDir, const std::string& path);

/// Longest name (scene, body, probe) in bytes: names become file names (<body>_surface_000012.vtu
/// must fit in the 255 bytes a file name may have) and column names.
constexpr std::size_t kMaxNameBytes = 128;

/// What is wrong with a probe's name, or "" when nothing is: empty, longer than kMaxNameBytes, or
/// holding a control character (a newline would split probes.csv's header).
std::string nameProblem(std::string_view name);

/// What is wrong with a name that becomes a file or folder name in the output folder (the scene's
/// and the bodies'), or "" when nothing is: nameProblem's reasons, a '/' or '\' (a name such as
/// "../../x" or "/abs/path" would write outside the output folder), or "." or "..".
std::string fileNameProblem(std::string_view name);

}  // namespace corofem::scene
