// Resolution of the relative paths in a scene file.
#include "scene/scene_paths.hpp"

#include <filesystem>

namespace corofem::scene {

std::string resolveScenePath(const std::string& baseDir, const std::string& path) {
  const std::filesystem::path p(path);
  if (baseDir.empty() || p.is_absolute()) return path;
  return (std::filesystem::path(baseDir) / p).lexically_normal().string();
}

}  // namespace corofem::scene
