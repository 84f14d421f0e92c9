// The reference device (reference_device.cpp): Eigen, double precision, assembled sparse matrices,
// every formulation, PCG and sparse LDL^T. The oracle of the device backends.
#pragma once

#include "device/device.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

/// A reference device holding copies of `problems` (each body its own).
std::unique_ptr<Device> createReferenceDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver);

}  // namespace corofem::detail
