// The cache folder (cache_dir.hpp).
#include "util/cache_dir.hpp"

#include <cstdlib>
#include <filesystem>

namespace corofem::detail {

std::string cacheDirectory() {
  namespace fs = std::filesystem;
  if (const char* dir = std::getenv("COROFEM_CACHE_DIR"); dir && *dir) return std::string(dir) == "off" ? "" : dir;
#ifdef _WIN32
  if (const char* local = std::getenv("LOCALAPPDATA"); local && *local) return (fs::path(local) / "corofem").string();
#endif
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return (fs::path(xdg) / "corofem").string();
  if (const char* home = std::getenv("HOME"); home && *home) return (fs::path(home) / ".cache" / "corofem").string();
  return {};
}

}  // namespace corofem::detail
