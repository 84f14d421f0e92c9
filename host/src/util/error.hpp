// Internal error type. Inside the library, code throws corofem::detail::Error; every public entry
// point catches it (and std::exception) and returns a Status, so no exception crosses the API.
#pragma once

#include <corofem/status.hpp>

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace corofem::detail {

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
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
    return Status(ErrorCode::Internal, std::string("unexpected error: ") + e.what());
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
    return Result<T>(ErrorCode::Internal, std::string("unexpected error: ") + e.what());
  }
}

}  // namespace corofem::detail
