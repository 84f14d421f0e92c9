// Fault injection for the failover tests: a Backend decorator that throws Error(DeviceError) the
// way a failing OpenCL device does, at a chosen point.
#pragma once

#include "solve/backend.hpp"

#include <memory>
#include <string>

namespace corofem::detail {

enum class FaultKind {
  None,
  Build,       ///< at creation: the program does not build
  Allocation,  ///< at the atCall-th call of any method (0 = at creation): a buffer allocation fails
  Launch,      ///< at the atCall-th solve(): a kernel launch fails before anything is computed
  ReadBack,    ///< at the atCall-th internalForces(): the work ran, its output is garbage, then
               ///< the read-back fails (the output vector is left overwritten with NaN)
};

struct FaultSpec {
  FaultKind kind = FaultKind::None;
  int atCall = 1;  ///< 1-based count of the calls the kind counts
};

/// Wraps `inner`. Throws Error(DeviceError) here for Build, and for Allocation with atCall 0.
std::unique_ptr<Backend> injectFaults(std::unique_ptr<Backend> inner, const FaultSpec& spec);

const char* toString(FaultKind k);

}  // namespace corofem::detail
