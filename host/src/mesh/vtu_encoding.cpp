// Binary .vtu arrays: VTK's headers, zlib blocks (when built with zlib) and base64.
#include "mesh/vtu_encoding.hpp"

#include "util/error.hpp"

#ifdef COROFEM_WITH_ZLIB
#include <zlib.h>
#endif

namespace corofem {

bool vtuZlibAvailable() {
#ifdef COROFEM_WITH_ZLIB
  return true;
#else
  return false;
#endif
}

namespace mesh {
namespace {

[[noreturn]] void failNoZlib(const std::string& path) {
  detail::fail(ErrorCode::BadInput, "cannot write ", path,
               ": zlib compression (output.vtu_compression \"zlib\", VtuOptions::compression) needs a corofem "
               "built with zlib, and this one was built without it; install zlib1g-dev and rebuild, or use "
               "\"none\"");
}

#ifdef COROFEM_WITH_ZLIB
/// One block compressed with zlib's default level.
std::string compressBlock(std::string_view block, const std::string& path) {
  uLongf size = compressBound(static_cast<uLong>(block.size()));
  std::string out(size, '\0');
  const int rc = compress2(reinterpret_cast<Bytef*>(out.data()), &size,
                           reinterpret_cast<const Bytef*>(block.data()), static_cast<uLong>(block.size()),
                           Z_DEFAULT_COMPRESSION);
  if (rc != Z_OK)
    detail::fail(ErrorCode::IoError, "cannot write ", path, ": zlib failed to compress a block (error ", rc,
                 rc == Z_MEM_ERROR ? ", out of memory" : "", ")");
  out.resize(size);
  return out;
}
#endif

}  // namespace

void checkVtuOptions(const VtuOptions& options, const std::string& path) {
  if (options.compression == VtuCompression::None) return;
  if (options.format == VtuFormat::Ascii)
    detail::fail(ErrorCode::BadInput, "cannot write ", path,
                 ": zlib compression (output.vtu_compression, VtuOptions::compression) applies to binary arrays "
                 "only, and the format is \"ascii\"; set output.vtu_format to \"base64\" or \"raw\", or the "
                 "compression to \"none\"");
  if (!vtuZlibAvailable()) failNoZlib(path);
}

VtuPayload encodeVtuArray(std::string_view bytes, VtuCompression compression, const std::string& path) {
  VtuPayload p;
  if (compression == VtuCompression::None) {
    appendLittleEndian(p.header, std::uint64_t(bytes.size()));
    p.data.assign(bytes.data(), bytes.size());
    return p;
  }
#ifdef COROFEM_WITH_ZLIB
  const std::size_t blocks = (bytes.size() + kVtuBlockSize - 1) / kVtuBlockSize;
  appendLittleEndian(p.header, std::uint64_t(blocks));
  appendLittleEndian(p.header, std::uint64_t(kVtuBlockSize));
  appendLittleEndian(p.header, std::uint64_t(bytes.size() % kVtuBlockSize));  // 0: the last block is full
  for (std::size_t b = 0; b < blocks; ++b) {
    const std::string block = compressBlock(bytes.substr(b * kVtuBlockSize, kVtuBlockSize), path);
    appendLittleEndian(p.header, std::uint64_t(block.size()));
    p.data += block;
  }
  return p;
#else
  failNoZlib(path);
#endif
}

std::string base64(std::string_view bytes) {
  static constexpr char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const std::uint32_t v = std::uint32_t(std::uint8_t(bytes[i])) << 16 | std::uint32_t(std::uint8_t(bytes[i + 1])) << 8 |
                            std::uint32_t(std::uint8_t(bytes[i + 2]));
    for (int k = 3; k >= 0; --k) out.push_back(kDigits[(v >> (6 * k)) & 63u]);
  }
  const std::size_t rest = bytes.size() - i;
  if (rest > 0) {
    std::uint32_t v = std::uint32_t(std::uint8_t(bytes[i])) << 16;
    if (rest == 2) v |= std::uint32_t(std::uint8_t(bytes[i + 1])) << 8;
    out.push_back(kDigits[(v >> 18) & 63u]);
    out.push_back(kDigits[(v >> 12) & 63u]);
    out.push_back(rest == 2 ? kDigits[(v >> 6) & 63u] : '=');
    out.push_back('=');
  }
  return out;
}

}  // namespace mesh
}  // namespace corofem
