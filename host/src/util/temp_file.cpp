// Temporaries and their renames (temp_file.hpp).
#include "util/temp_file.hpp"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <random>

namespace corofem::detail {

namespace {

std::uint64_t processToken() {
  static const std::uint64_t token = [] {
    // The clock and an address where std::random_device has no source (it may throw).
    std::uint64_t t = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count()) ^
                      reinterpret_cast<std::uintptr_t>(&t);
    try {
      std::random_device device;
      t ^= (std::uint64_t(device()) << 32) ^ device();
    } catch (...) {
    }
    return t;
  }();
  return token;
}

}  // namespace

std::string temporaryNameFor(const std::string& file) {
  static std::atomic<std::uint64_t> calls{0};
  return file + ".tmp" + std::to_string(processToken()) + "-" + std::to_string(++calls);
}

std::error_code replaceFile(const std::string& tmp, const std::string& file) {
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
  }
  return ec;
}

}  // namespace corofem::detail
