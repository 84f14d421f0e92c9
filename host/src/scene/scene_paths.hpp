// Paths named in a scene file (mesh, .bou, surface) are relative to the scene file's folder.
#pragma once

#include <string>

namespace corofem::scene {

/// `path` when it is absolute or `baseDir` is empty, else baseDir/path (lexically normalised, so
/// messages show "../shared/data/x.msh" rather than "docs/examples/../../../shared/data/x.msh").
std::string resolveScenePath(const std::string& baseDir, const std::string& path);

}  // namespace corofem::scene
