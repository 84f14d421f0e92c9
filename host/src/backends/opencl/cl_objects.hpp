// OpenCL objects released on destruction: buffers, pinned host stages for transfers, and kernels
// that remember their arguments.
#pragma once

#include "backends/opencl/cl_check.hpp"

#include <cstddef>
#include <string>
#include <vector>

namespace corofem::detail {

/// A device buffer released on destruction.
class ClBuffer {
 public:
  ClBuffer() = default;
  ClBuffer(const ClBuffer&) = delete;
  ClBuffer& operator=(const ClBuffer&) = delete;
  ~ClBuffer();
  /// Allocates `bytes` (at least 16); the allocated size counts in bytes().
  void create(cl_context ctx, std::size_t bytes, const std::string& device);
  cl_mem get() const { return mem_; }
  std::size_t bytes() const { return bytes_; }

 private:
  cl_mem mem_ = nullptr;
  std::size_t bytes_ = 0;
};

/// Host memory for the transfers of one node vector, in device precision: allocated by the driver
/// (CL_MEM_ALLOC_HOST_PTR, page-locked on GPU drivers, so a copy runs at the bus's rate with no
/// intermediate copy by the driver) and mapped for the stage's life. Reused by every transfer, so no
/// transfer allocates (a fresh vector of a 1M-element body's 3N reals page-faults through 2 MB).
/// The host writes into it only after the last non-blocking write that reads from it is done.
class HostStage {
 public:
  HostStage() = default;
  HostStage(const HostStage&) = delete;
  HostStage& operator=(const HostStage&) = delete;
  ~HostStage();
  void create(cl_context ctx, cl_command_queue queue, std::size_t bytes, const std::string& device);
  /// The memory, after waiting for the write in flight from it (if any).
  unsigned char* writable();
  /// The memory as it is (for a blocking read into it, or reading it).
  unsigned char* data() const { return host_; }
  /// Non-blocking write of [offset, offset + bytes) of the stage into `to` at the same offset.
  void write(cl_mem to, std::size_t offset, std::size_t bytes, const std::string& device);
  /// Blocking read of [offset, offset + bytes) of `from` into the stage at the same offset.
  void read(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device);
  /// The same read, not blocking: the caller waits for the event returned (and releases it) before
  /// it reads the stage (nullptr for an empty range).
  cl_event readLater(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device);

 private:
  cl_mem mem_ = nullptr;
  cl_command_queue queue_ = nullptr;
  unsigned char* host_ = nullptr;
  cl_event pending_ = nullptr;  ///< the last non-blocking write from the stage
};

/// A kernel released on destruction.
class ClKernel {
 public:
  ClKernel() = default;
  ClKernel(const ClKernel&) = delete;
  ClKernel& operator=(const ClKernel&) = delete;
  ~ClKernel();
  void create(cl_program program, const char* name, const std::string& device);
  cl_kernel get() const { return k_; }
  const char* name() const { return name_; }
  /// clSetKernelArg(i, bytes) unless argument i already holds these bytes (a launch sequence sets
  /// the same buffers every time: the host's enqueue, not the device, bounds small bodies' PCG on
  /// GPUs). The engine's buffers live as long as its kernels, so a handle's bytes name one buffer.
  void setArg(cl_uint i, const void* value, std::size_t bytes, const std::string& device) const;

 private:
  cl_kernel k_ = nullptr;
  const char* name_ = "";
  mutable std::vector<std::vector<unsigned char>> args_;  ///< the bytes last set, per argument
};

}  // namespace corofem::detail
