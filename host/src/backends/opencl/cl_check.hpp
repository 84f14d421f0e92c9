// Status checking of OpenCL calls: every call goes through checkCl, and a failure becomes
// Error(DeviceError) naming the call, the OpenCL error and the device.
#pragma once

#ifndef CL_TARGET_OPENCL_VERSION
#define CL_TARGET_OPENCL_VERSION 120
#endif
#include <CL/cl.h>

#include <string>

namespace corofem::detail::cl {

/// Symbolic name of an OpenCL status code ("CL_OUT_OF_RESOURCES"), or "CL error <n>".
std::string errorString(cl_int status);

/// Throws Error(DeviceError): "<call> failed with <error> on device '<device>'<hint>".
[[noreturn]] void throwClError(const char* call, cl_int status, const std::string& device);

/// Checks the status of an OpenCL call.
inline void checkCl(cl_int status, const char* call, const std::string& device) {
  if (status != CL_SUCCESS) throwClError(call, status, device);
}

}  // namespace corofem::detail::cl
