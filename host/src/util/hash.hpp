// FNV-1a, 64 bits: the keys of caches and kept data (built programs, shaders, a body's stiffness).
// Not for security; stable across runs and machines of either byte order for byte data.
#pragma once

#include <cstddef>
#include <cstdint>

namespace corofem::detail {

constexpr std::uint64_t kFnv1aOffset = 1469598103934665603ull;

/// `h` (the offset basis by default, or an earlier hash to chain) with `bytes` bytes of `data` mixed in.
inline std::uint64_t fnv1a64(const void* data, std::size_t bytes, std::uint64_t h = kFnv1aOffset) {
  const auto* c = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) h = (h ^ c[i]) * 1099511628211ull;
  return h;
}

}  // namespace corofem::detail
