// Internal error type. Inside the library, code throws corofem::detail::Error; every public entry
// point catches it (and std::exception) and returns a Status, so no exception crosses the API.
#pragma once

#include <corofem/status.hpp>

#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

namespace corofem::detail {

/// Longest message an Error carries (bytes). Messages quote tokens, names and paths from the input;
/// the places that do shorten what they quote (shorten()), and fail() elides the middle of anything
/// longer still, so that no input, however large, makes a message of unbounded size.
constexpr std::size_t kMaxMessageBytes = 4096;

/// Length of the longest prefix of s of at most max bytes that does not end inside a UTF-8 sequence.
inline std::size_t utf8Prefix(std::string_view s, std::size_t max) {
  if (s.size() <= max) return s.size();
  std::size_t n = max;
  while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80) --n;  // s[n] continues a character
  return n;
}

/// s itself when it has at most max bytes, else its start, "..." and how much was left out:
/// "aaaaaaaa... (40000 bytes)". For quoting input (tokens, names, values) in messages.
inline std::string shorten(std::string_view s, std::size_t max = 40) {
  if (s.size() <= max) return std::string(s);
  return std::string(s.substr(0, utf8Prefix(s, max))) + "... (" + std::to_string(s.size()) + " bytes)";
}

/// s itself when it has at most head + tail bytes, else its first `head` and last `tail` bytes
/// with how much was left out between them: for text whose end matters as much as its start.
inline std::string elideMiddle(std::string_view s, std::size_t head, std::size_t tail) {
  if (s.size() <= head + tail) return std::string(s);
  const std::size_t front = utf8Prefix(s, head);
  std::size_t back = s.size() - tail;
  while (back < s.size() && (static_cast<unsigned char>(s[back]) & 0xC0) == 0x80) ++back;
  return std::string(s.substr(0, front)) + " [... " + std::to_string(back - front) + " bytes left out ...] " +
         std::string(s.substr(back));
}

/// A message of at most about kMaxMessageBytes: a longer one keeps its start and its end (where
/// the fix is usually named) with the middle elided.
inline std::string boundMessage(std::string message) {
  if (message.size() <= kMaxMessageBytes) return message;
  return elideMiddle(message, kMaxMessageBytes * 3 / 4, kMaxMessageBytes / 4);
}

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(boundMessage(message)), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

/// Builds a message from stream-able parts: fail(ErrorCode::BadInput, "file ", path, ":", line, ...).
template <class... Parts>
[[noreturn]] void fail(ErrorCode code, const Parts&... parts) {
  std::ostringstream os;
  (os << ... << parts);
  throw Error(code, os.str());
}

/// Runs fn() and converts any exception into a Status (for public entry points).
template <class Fn>
Status guard(Fn&& fn) {
  try {
    fn();
    return Status::ok();
  } catch (const Error& e) {
    return Status(e.code(), e.what());
  } catch (const std::bad_alloc&) {
    return Status(ErrorCode::Internal, "out of memory");
  } catch (const std::exception& e) {
    return Status(ErrorCode::Internal, boundMessage(std::string("unexpected error: ") + e.what()));
  }
}

/// Runs fn() returning T and converts any exception into a Result<T>.
template <class T, class Fn>
Result<T> guardResult(Fn&& fn) {
  try {
    return Result<T>(fn());
  } catch (const Error& e) {
    return Result<T>(e.code(), e.what());
  } catch (const std::bad_alloc&) {
    return Result<T>(ErrorCode::Internal, "out of memory");
  } catch (const std::exception& e) {
    return Result<T>(ErrorCode::Internal, boundMessage(std::string("unexpected error: ") + e.what()));
  }
}

}  // namespace corofem::detail
