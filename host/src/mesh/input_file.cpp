// Whole-file reading of inputs with the regular-file check and the size limit (input_file.hpp).
#include "mesh/input_file.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <limits>
#include <string_view>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace corofem::mesh {

namespace {

/// Closes the descriptor when the read ends, by return or by throw.
class Descriptor {
 public:
  explicit Descriptor(int fd) : fd_(fd) {}
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  ~Descriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  int get() const { return fd_; }

 private:
  int fd_;
};

const char* kindOf(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO (a named pipe)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

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
  // O_NONBLOCK: opening a FIFO without a writer would otherwise wait forever. Regular files ignore it.
  const Descriptor fd(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY));
  if (fd.get() < 0) detail::fail(ErrorCode::IoError, "cannot open ", name, ": ", std::strerror(errno), openHint);
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0)
    detail::fail(ErrorCode::IoError, "cannot read ", name, ": ", std::strerror(errno));
  if (!S_ISREG(st.st_mode))
    detail::fail(ErrorCode::BadInput, "cannot read ", name, ": it is ", kindOf(st.st_mode),
                 ", not a regular file; give the path of a file (corofem reads inputs from regular files only, "
                 "so save piped or generated data to a file first)");
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size > limit) failTooLarge(name, "it has " + std::to_string(size) + " bytes, more than", limit, limitName);

  std::string text(static_cast<std::size_t>(size), '\0');
  std::size_t got = 0;
  for (;;) {
    if (got == text.size()) {
      // At the size fstat gave: read on in case the file grew, but never past the limit.
      if (got > limit) failTooLarge(name, "it grew, while being read, past", limit, limitName);
      // Room for 64 KiB more, or for one byte past the limit (to see that the file passed it).
      const std::uint64_t room = limit - got;
      text.resize(got + static_cast<std::size_t>(room >= (std::uint64_t(1) << 16) ? std::uint64_t(1) << 16 : room + 1));
    }
    const ssize_t n = ::read(fd.get(), text.data() + got, text.size() - got);
    if (n < 0) {
      if (errno == EINTR) continue;
      detail::fail(ErrorCode::IoError, "cannot read ", name, ": ", std::strerror(errno));
    }
    if (n == 0) break;
    got += static_cast<std::size_t>(n);
  }
  text.resize(got);
  return text;
}

}  // namespace corofem::mesh
