// Whole-file reading of inputs with the regular-file check and the size limit (input_file.hpp).
#include "mesh/input_file.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <limits>
#include <string_view>

#ifdef _WIN32
#include <filesystem>
#include <fstream>
#else
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#endif

namespace corofem::mesh {

namespace {

/// What a path that is not a regular file is, for the error.
enum class Kind { Directory, Fifo, CharacterDevice, BlockDevice, Socket, Other };

[[noreturn]] void failNotRegular(const std::string& name, Kind kind) {
  const char* words = kind == Kind::Directory         ? "a directory"
                      : kind == Kind::Fifo            ? "a FIFO (a named pipe)"
                      : kind == Kind::CharacterDevice ? "a character device"
                      : kind == Kind::BlockDevice     ? "a block device"
                      : kind == Kind::Socket          ? "a socket"
                                                      : "not a regular file";
  detail::fail(ErrorCode::BadInput, "cannot read ", name, ": it is ", words,
               ", not a regular file; give the path of a file (corofem reads inputs from regular files only, "
               "so save piped or generated data to a file first)");
}

#ifndef _WIN32
/// An input file open for reading (POSIX). The kind checked is the opened file's own (fstat), so
/// nothing can swap the path between the check and the read. Closed when the read ends, by return
/// or by throw.
class InputSource {
 public:
  InputSource(const std::string& path, const std::string& name, const std::string& openHint) : name_(name) {
    // O_NONBLOCK: opening a FIFO without a writer would otherwise wait forever. Regular files ignore it.
    fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd_ < 0) detail::fail(ErrorCode::IoError, "cannot open ", name, ": ", std::strerror(errno), openHint);
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      const int e = errno;
      ::close(fd_);
      detail::fail(ErrorCode::IoError, "cannot read ", name, ": ", std::strerror(e));
    }
    if (!S_ISREG(st.st_mode)) {
      ::close(fd_);
      failNotRegular(name, S_ISDIR(st.st_mode)    ? Kind::Directory
                           : S_ISFIFO(st.st_mode) ? Kind::Fifo
                           : S_ISCHR(st.st_mode)  ? Kind::CharacterDevice
                           : S_ISBLK(st.st_mode)  ? Kind::BlockDevice
                           : S_ISSOCK(st.st_mode) ? Kind::Socket
                                                  : Kind::Other);
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
  }
  InputSource(const InputSource&) = delete;
  InputSource& operator=(const InputSource&) = delete;
  ~InputSource() { ::close(fd_); }

  std::uint64_t size() const { return size_; }

  /// Reads up to n bytes into `to`; 0 at the end of the file. Throws IoError naming the file.
  std::size_t read(char* to, std::size_t n) {
    for (;;) {
      const ssize_t got = ::read(fd_, to, n);
      if (got >= 0) return static_cast<std::size_t>(got);
      if (errno != EINTR) detail::fail(ErrorCode::IoError, "cannot read ", name_, ": ", std::strerror(errno));
    }
  }

 private:
  std::string name_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};
#else
/// An input file open for reading (Windows): its kind from std::filesystem, then a binary
/// std::ifstream (the kind is the path's, checked before the open: not race-free as on POSIX). The path converts to fs::path as everywhere else in the library (the active code
/// page). Compiled in CI by MinGW-w64 (tests/portability/), not run there.
class InputSource {
 public:
  InputSource(const std::string& path, const std::string& name, const std::string& openHint) : name_(name) {
    namespace fs = std::filesystem;
    const fs::path p(path);
    std::error_code ec;
    const fs::file_status status = fs::status(p, ec);
    if (status.type() == fs::file_type::not_found)
      detail::fail(ErrorCode::IoError, "cannot open ", name, ": No such file or directory", openHint);
    if (ec) detail::fail(ErrorCode::IoError, "cannot open ", name, ": ", ec.message(), openHint);
    switch (status.type()) {
      case fs::file_type::regular: break;
      case fs::file_type::directory: failNotRegular(name, Kind::Directory);
      case fs::file_type::fifo: failNotRegular(name, Kind::Fifo);
      case fs::file_type::character: failNotRegular(name, Kind::CharacterDevice);
      case fs::file_type::block: failNotRegular(name, Kind::BlockDevice);
      case fs::file_type::socket: failNotRegular(name, Kind::Socket);
      default: failNotRegular(name, Kind::Other);
    }
    errno = 0;  // the standard streams need not set it: a reason only where the C library gave one
    in_.open(p, std::ios::binary);
    if (!in_) detail::fail(ErrorCode::IoError, "cannot open ", name, ": ", reason(), openHint);
    size_ = fs::file_size(p, ec);
    if (ec) detail::fail(ErrorCode::IoError, "cannot read ", name, ": ", ec.message());
  }

  std::uint64_t size() const { return size_; }

  /// Reads up to n bytes into `to`; 0 at the end of the file. Throws IoError naming the file.
  std::size_t read(char* to, std::size_t n) {
    errno = 0;
    in_.read(to, static_cast<std::streamsize>(n));
    if (in_.bad()) detail::fail(ErrorCode::IoError, "cannot read ", name_, ": ", reason());
    return static_cast<std::size_t>(in_.gcount());
  }

 private:
  static std::string reason() { return errno ? std::strerror(errno) : "the system gave no reason"; }

  std::string name_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
};
#endif

[[noreturn]] void failTooLarge(const std::string& name, const std::string& what, std::uint64_t limit,
                               const LimitName& limitName) {
  detail::fail(ErrorCode::BadInput, "cannot read ", name, ": ", what, " the limit of ", limit, " bytes (",
               limitInUse(limitName, limit), "); if the file is right, raise the limit: ", howToRaise(limitName));
}

}  // namespace

std::string limitInUse(const LimitName& limit, std::uint64_t value) {
  return std::string("InputLimits::") + limit.field + (value == limit.defaultValue ? ", the default" : "");
}

std::string howToRaise(const LimitName& limit) {
  return std::string("InputLimits::") + limit.field + " (C API: corofem_input_limits." + limit.cField +
         "; the corofem command: " + limit.flag + ", e.g. " + limit.flag + " " + limit.example + ")";
}

std::uint64_t parseSize(std::string_view text, const std::string& what, const char* example) {
  std::uint64_t value = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  std::string_view suffix(ptr, static_cast<std::size_t>(text.data() + text.size() - ptr));
  if (!suffix.empty() && (suffix.back() == 'B' || suffix.back() == 'b')) suffix.remove_suffix(1);  // "4GB"
  int shift = -1;
  if (suffix.empty()) {
    shift = 0;
  } else if (suffix.size() == 1) {
    switch (suffix[0]) {
      case 'k': case 'K': shift = 10; break;
      case 'm': case 'M': shift = 20; break;
      case 'g': case 'G': shift = 30; break;
      case 't': case 'T': shift = 40; break;
      default: break;
    }
  }
  if (ec != std::errc() || ptr == text.data() || shift < 0 || value == 0 ||
      value > (std::numeric_limits<std::uint64_t>::max() >> shift))
    detail::fail(ErrorCode::BadInput, what, " \"", detail::shorten(text),
                 "\" is not a limit; give a whole number > 0, optionally with K, M, G or T (powers of 1024), e.g. ",
                 what, " ", example);
  return value << shift;
}

std::string readInputFile(const std::string& path, const std::string& name, const std::string& openHint,
                          const InputLimits& limits, InputKind kind) {
  const LimitName& limitName = kind == InputKind::Scene ? kMaxSceneBytes : kMaxInputBytes;
  const std::uint64_t limit = kind == InputKind::Scene ? limits.maxSceneBytes : limits.maxInputBytes;
  InputSource in(path, name, openHint);
  const std::uint64_t size = in.size();
  if (size > limit) failTooLarge(name, "it has " + std::to_string(size) + " bytes, more than", limit, limitName);

  std::string text(static_cast<std::size_t>(size), '\0');
  std::size_t got = 0;
  for (;;) {
    if (got == text.size()) {
      // At the size the file had when opened: read on in case it grew, but never past the limit.
      if (got > limit) failTooLarge(name, "it grew, while being read, past", limit, limitName);
      // Room for 64 KiB more, or for one byte past the limit (to see that the file passed it).
      const std::uint64_t room = limit - got;
      text.resize(got + static_cast<std::size_t>(room >= (std::uint64_t(1) << 16) ? std::uint64_t(1) << 16 : room + 1));
    }
    const std::size_t n = in.read(text.data() + got, text.size() - got);
    if (n == 0) break;
    got += n;
  }
  text.resize(got);
  return text;
}

}  // namespace corofem::mesh
