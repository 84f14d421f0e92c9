// OpenCL objects released on destruction (cl_objects.hpp).
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/cl_objects.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cstring>

namespace corofem::detail {

using cl::checkCl;

ClBuffer::~ClBuffer() {
  if (mem_) clReleaseMemObject(mem_);
}

void ClBuffer::create(cl_context ctx, std::size_t bytes, const std::string& device) {
  cl_int status = CL_SUCCESS;
  const std::size_t size = std::max<std::size_t>(bytes, 16);
  mem_ = clCreateBuffer(ctx, CL_MEM_READ_WRITE, size, nullptr, &status);
  checkCl(status, "clCreateBuffer", device);
  bytes_ = size;
}

HostStage::~HostStage() {
  if (pending_) clReleaseEvent(pending_);
  if (mem_ && host_) {
    cl_event unmapped = nullptr;
    if (clEnqueueUnmapMemObject(queue_, mem_, host_, 0, nullptr, &unmapped) == CL_SUCCESS && unmapped) {
      clWaitForEvents(1, &unmapped);
      clReleaseEvent(unmapped);
    }
  }
  if (mem_) clReleaseMemObject(mem_);
  if (queue_) clReleaseCommandQueue(queue_);
}

void HostStage::create(cl_context ctx, cl_command_queue queue, std::size_t bytes, const std::string& device) {
  cl_int status = CL_SUCCESS;
  const std::size_t size = std::max<std::size_t>(bytes, 16);
  mem_ = clCreateBuffer(ctx, CL_MEM_READ_WRITE | CL_MEM_ALLOC_HOST_PTR, size, nullptr, &status);
  checkCl(status, "clCreateBuffer (pinned host stage)", device);
  queue_ = queue;
  clRetainCommandQueue(queue_);
  host_ = static_cast<unsigned char*>(
      clEnqueueMapBuffer(queue_, mem_, CL_TRUE, CL_MAP_READ | CL_MAP_WRITE, 0, size, 0, nullptr, nullptr, &status));
  checkCl(status, "clEnqueueMapBuffer (pinned host stage)", device);
  std::memset(host_, 0, size);
}

unsigned char* HostStage::writable() {
  if (pending_) {
    const cl_int status = clWaitForEvents(1, &pending_);
    clReleaseEvent(pending_);
    pending_ = nullptr;
    checkCl(status, "clWaitForEvents (host stage write)", "");
  }
  return host_;
}

void HostStage::write(cl_mem to, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return;
  writable();  // at most one write in flight per stage
  checkCl(clEnqueueWriteBuffer(queue_, to, CL_FALSE, offset, bytes, host_ + offset, 0, nullptr, &pending_),
          "clEnqueueWriteBuffer", device);
}

void HostStage::read(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return;
  writable();
  checkCl(clEnqueueReadBuffer(queue_, from, CL_TRUE, offset, bytes, host_ + offset, 0, nullptr, nullptr),
          "clEnqueueReadBuffer", device);
}

cl_event HostStage::readLater(cl_mem from, std::size_t offset, std::size_t bytes, const std::string& device) {
  if (bytes == 0) return nullptr;
  writable();
  cl_event done = nullptr;
  checkCl(clEnqueueReadBuffer(queue_, from, CL_FALSE, offset, bytes, host_ + offset, 0, nullptr, &done),
          "clEnqueueReadBuffer", device);
  return done;
}

ClKernel::~ClKernel() {
  if (k_) clReleaseKernel(k_);
}

void ClKernel::create(cl_program program, const char* name, const std::string& device) {
  cl_int status = CL_SUCCESS;
  k_ = clCreateKernel(program, name, &status);
  if (status != CL_SUCCESS)
    fail(ErrorCode::DeviceError, "clCreateKernel('", name, "') failed with ", cl::errorString(status),
         " on OpenCL device '", device, "'");
  name_ = name;
}

void ClKernel::setArg(cl_uint i, const void* value, std::size_t bytes, const std::string& device) const {
  if (args_.size() <= i) args_.resize(i + 1);
  std::vector<unsigned char>& last = args_[i];
  if (last.size() == bytes && std::memcmp(last.data(), value, bytes) == 0) return;
  last.clear();  // unknown until set: a failed call below leaves it to be set again
  checkCl(clSetKernelArg(k_, i, bytes, value), "clSetKernelArg", device);
  last.assign(static_cast<const unsigned char*>(value), static_cast<const unsigned char*>(value) + bytes);
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
