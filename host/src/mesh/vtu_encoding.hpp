// The binary data arrays of VTK XML files (.vtu): little-endian bytes, base64, and the headers and
// zlib blocks of VTK's layout with header_type UInt64 (VTK's file-formats document, "VTK XML Formats"):
//   uncompressed: [UInt64 byte count][data]
//   zlib:         [UInt64 nblocks][UInt64 block size][UInt64 last block size][UInt64 compressed size] x nblocks,
//                 then the compressed blocks; the last block size is 0 when the last block is full.
#pragma once

#include <corofem/mesh.hpp>

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace corofem::mesh {

/// Uncompressed bytes per zlib block (VTK's default).
constexpr std::size_t kVtuBlockSize = 32768;

/// Appends v to out as little-endian bytes (integers and IEEE floats), whatever the host's order.
template <class T>
void appendLittleEndian(std::string& out, T v) {
  static_assert(std::is_arithmetic_v<T> && (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8));
  using Bits = std::conditional_t<sizeof(T) == 8, std::uint64_t,
               std::conditional_t<sizeof(T) == 4, std::uint32_t,
               std::conditional_t<sizeof(T) == 2, std::uint16_t, std::uint8_t>>>;
  Bits bits;
  std::memcpy(&bits, &v, sizeof bits);
  for (std::size_t i = 0; i < sizeof bits; ++i) out.push_back(static_cast<char>((bits >> (8 * i)) & 0xffu));
}

/// The values converted to Out, as little-endian bytes.
template <class Out, class In>
std::string littleEndianBytes(const std::vector<In>& values) {
  std::string out;
  out.reserve(values.size() * sizeof(Out));
  for (const In& v : values) appendLittleEndian(out, static_cast<Out>(v));
  return out;
}

/// One array as the file stores it: the header, then the (compressed) data.
struct VtuPayload {
  std::string header;
  std::string data;
};

/// The header and data of `bytes` with VTK's layout (top of this file). Zlib in a build without
/// zlib throws BadInput naming `path`, the scene key and the fix.
VtuPayload encodeVtuArray(std::string_view bytes, VtuCompression compression, const std::string& path);

/// Throws BadInput, naming `path`, for options this build cannot write: zlib without zlib, or
/// zlib with the ascii format.
void checkVtuOptions(const VtuOptions& options, const std::string& path);

/// Standard base64 (RFC 4648, with '=' padding).
std::string base64(std::string_view bytes);

}  // namespace corofem::mesh
