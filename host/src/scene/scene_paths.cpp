// Resolution of the relative paths in a scene file, and the rules for names.
#include "scene/scene_paths.hpp"

#include <cstdio>
#include <filesystem>

namespace corofem::scene {

std::string resolveScenePath(const std::string& baseDir, const std::string& path) {
  const std::filesystem::path p(path);
  if (baseDir.empty() || p.is_absolute()) return path;
  return (std::filesystem::path(baseDir) / p).lexically_normal().string();
}

std::string nameProblem(std::string_view name) {
  if (name.empty()) return "must not be empty";
  if (name.size() > kMaxNameBytes)
    return "is " + std::to_string(name.size()) + " bytes long; a name may have at most " +
           std::to_string(kMaxNameBytes) + " bytes";
  for (char c : name) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte < 0x20 || byte == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", byte);
      return std::string("contains a control character (byte ") + hex +
             "); use letters, digits, spaces and punctuation";
    }
  }
  return "";
}

std::string fileNameProblem(std::string_view name) {
  std::string problem = nameProblem(name);
  if (!problem.empty()) return problem;
  if (name.find_first_of("/\\") != std::string_view::npos)
    return std::string("contains '") + name[name.find_first_of("/\\")] +
           "'; the name becomes a file name in the output folder, so it may not contain '/' or '\\' "
           "(use --out to choose the folder)";
  if (name == "." || name == "..")
    return "is \"" + std::string(name) + "\", which names a folder; the name becomes a file name in the output folder";
  return "";
}

}  // namespace corofem::scene
