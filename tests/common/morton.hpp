// --corofem_morton (tests/common/test_main.cpp): every OpenCL device the tests make lays its bodies
// out in a Morton order of its own (OpenCLTuning::localityOrder = 1), so that every host-device
// transfer's permutation, the batches' and the device surfaces' are tested too.
#pragma once

#include <corofem/tuning.hpp>

namespace corofem::test {

/// Whether the run forces the Morton order on every OpenCL device.
inline bool& mortonEverywhere() {
  static bool on = false;
  return on;
}

/// `t` with the Morton order forced where the run asks for it and `t` leaves the order automatic.
inline OpenCLTuning morton(OpenCLTuning t = {}) {
  if (mortonEverywhere() && t.localityOrder < 0) t.localityOrder = 1;
  return t;
}

}  // namespace corofem::test

/// The first line of a test that sets every device's order itself (OpenCLTuning::localityOrder 0
/// or 1, or each value in turn): under --corofem_morton it would run again exactly as in the
/// suite's own run, so the repeat skips it. (GoogleTest's form: an `else` written after it cannot
/// bind to its `if`.)
#define COROFEM_SKIP_IN_MORTON_REPEAT()         \
  switch (0)                                    \
  case 0:                                       \
  default:                                      \
    if (!::corofem::test::mortonEverywhere()) { \
    } else                                      \
      GTEST_SKIP() << "sets its devices' orders itself: the suite's own run is this run"
