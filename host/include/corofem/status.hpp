// Status and Result<T>: how every public corofem call reports failure. No exception crosses the
// public API; a failure carries a code and a message that names the place and the fix.
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <utility>

namespace corofem {

/// What kind of failure. The `corofem` command maps these to exit codes (BadInput -> 2,
/// SolveFailed -> 3, the others -> 1).
enum class ErrorCode {
  Ok = 0,
  BadInput,        ///< malformed file, invalid value, unknown key: the user can fix the input
  SolveFailed,     ///< Newton or the linear solver did not converge, or the state became non-finite
  DeviceError,     ///< an OpenCL (or other backend) call failed
  NotCompiledIn,   ///< the requested backend or feature was not built into this library
  IoError,         ///< a file could not be opened, read or written
  Internal,        ///< a bug in corofem: please report it
};

/// Name of an error code, e.g. "bad input".
inline const char* toString(ErrorCode code) {
  switch (code) {
    case ErrorCode::Ok: return "ok";
    case ErrorCode::BadInput: return "bad input";
    case ErrorCode::SolveFailed: return "solve failed";
    case ErrorCode::DeviceError: return "device error";
    case ErrorCode::NotCompiledIn: return "not compiled in";
    case ErrorCode::IoError: return "i/o error";
    case ErrorCode::Internal: return "internal error";
  }
  return "unknown";
}

/// Success, or an error code with a message.
class Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status ok() { return {}; }

  bool isOk() const { return code_ == ErrorCode::Ok; }
  explicit operator bool() const { return isOk(); }
  ErrorCode code() const { return code_; }
  const std::string& message() const { return message_; }

 private:
  ErrorCode code_ = ErrorCode::Ok;
  std::string message_;
};

/// A value or an error (C++17 stand-in for std::expected).
template <class T>
class Result {
 public:
  Result(T value) : value_(std::move(value)) {}                 // NOLINT: implicit by design
  Result(Status status) : status_(std::move(status)) { assert(!status_.isOk()); }  // NOLINT
  Result(ErrorCode code, std::string message) : status_(code, std::move(message)) {}

  bool isOk() const { return value_.has_value(); }
  explicit operator bool() const { return isOk(); }
  const Status& status() const { return status_; }
  const std::string& message() const { return status_.message(); }

  T& value() & { assert(value_); return *value_; }
  const T& value() const& { assert(value_); return *value_; }
  T&& value() && { assert(value_); return std::move(*value_); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

 private:
  std::optional<T> value_;
  Status status_;
};

}  // namespace corofem
