// The C API's version query and its errors: the status names and the calling thread's last error
// (corofem.h, "Errors").
#include "capi/capi_support.hpp"

#include <corofem/version.h>

#include <cstring>

namespace corofem::capi {

static_assert(COROFEM_OK == static_cast<int>(ErrorCode::Ok) &&
                  COROFEM_BAD_INPUT == static_cast<int>(ErrorCode::BadInput) &&
                  COROFEM_SOLVE_FAILED == static_cast<int>(ErrorCode::SolveFailed) &&
                  COROFEM_DEVICE_ERROR == static_cast<int>(ErrorCode::DeviceError) &&
                  COROFEM_NOT_COMPILED_IN == static_cast<int>(ErrorCode::NotCompiledIn) &&
                  COROFEM_IO_ERROR == static_cast<int>(ErrorCode::IoError) &&
                  COROFEM_INTERNAL == static_cast<int>(ErrorCode::Internal),
              "corofem_status mirrors corofem::ErrorCode value for value");

namespace {

struct LastError {
  corofem_status status = COROFEM_OK;
  std::string message;
  /// Where the message could not be copied (out of memory), a static text instead.
  const char* fallback = nullptr;
};

LastError& lastError() noexcept {
  thread_local LastError error;
  return error;
}

}  // namespace

corofem_status record(const char* function, ErrorCode code, const char* message) noexcept {
  LastError& e = lastError();
  e.status = static_cast<corofem_status>(code);
  e.fallback = nullptr;
  try {
    e.message.clear();
    if (code != ErrorCode::Ok) {
      const std::size_t length = std::strlen(function);
      if (!message) message = "";
      if (std::strncmp(message, function, length) != 0 || message[length] != ':')
        e.message.append(function).append(": ");
      e.message.append(message);
    }
  } catch (...) {
    e.message.clear();
    e.fallback = "out of memory while keeping the error message";
  }
  return e.status;
}

}  // namespace corofem::capi

extern "C" {

const char* corofem_version(void) { return COROFEM_VERSION_STRING; }

const char* corofem_status_name(corofem_status status) {
  switch (status) {
    case COROFEM_OK:
    case COROFEM_BAD_INPUT:
    case COROFEM_SOLVE_FAILED:
    case COROFEM_DEVICE_ERROR:
    case COROFEM_NOT_COMPILED_IN:
    case COROFEM_IO_ERROR:
    case COROFEM_INTERNAL: return corofem::toString(static_cast<corofem::ErrorCode>(status));
  }
  return "unknown";
}

corofem_status corofem_last_status(void) { return corofem::capi::lastError().status; }

const char* corofem_last_error_message(void) {
  const corofem::capi::LastError& e = corofem::capi::lastError();
  return e.fallback ? e.fallback : e.message.c_str();
}

}  // extern "C"
