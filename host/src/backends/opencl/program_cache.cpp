// Program building and caching (program_cache.hpp).
#include "backends/opencl/program_cache.hpp"

#include "util/cache_dir.hpp"
#include "util/error.hpp"
#include "util/hash.hpp"
#include "util/temp_file.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <vector>


namespace corofem {
struct EmbeddedSource {
  const char* name;
  const char* text;
};
extern const EmbeddedSource corofem_opencl_sources[];
extern const std::size_t corofem_opencl_sources_count;
}  // namespace corofem

namespace corofem::detail::cl {

namespace fs = std::filesystem;

std::uint64_t fnv1a64(const std::string& text, std::uint64_t seed) {
  return detail::fnv1a64(text.data(), text.size(), seed);
}

std::string kernelCacheDirectory() {
  const std::string dir = cacheDirectory();
  return dir.empty() ? dir : (fs::path(dir) / "kernels").string();
}

std::string corofemProgramSource() {
  // Headers first, then the kernel files in dependency order; unknown files last (alphabetical,
  // as CMake globbed them).
  static const std::array<const char*, 8> kOrder = {"mat3.cl",   "rotation.cl", "element_force.cl",
                                                    "gather.cl", "precond.cl",  "pcg.cl", "pcg_group.cl",
                                                    "pcg_pack.cl"};
  std::vector<const EmbeddedSource*> headers, kernels, others;
  for (std::size_t i = 0; i < corofem_opencl_sources_count; ++i) {
    const EmbeddedSource& s = corofem_opencl_sources[i];
    const std::string name = s.name;
    if (name.size() > 2 && name.substr(name.size() - 2) == ".h") headers.push_back(&s);
    else others.push_back(&s);
  }
  // The layout header defines `real`: first.
  std::stable_sort(headers.begin(), headers.end(), [](const EmbeddedSource* a, const EmbeddedSource* b) {
    return std::string(a->name) == "corofem_layout.h" && std::string(b->name) != "corofem_layout.h";
  });
  for (const char* want : kOrder)
    for (auto it = others.begin(); it != others.end(); ++it)
      if (std::string((*it)->name) == want) {
        kernels.push_back(*it);
        others.erase(it);
        break;
      }
  std::ostringstream os;
  os << "#define COROFEM_EMBEDDED 1\n";
  for (auto* group : {&headers, &kernels, &others})
    for (const EmbeddedSource* s : *group) os << "#line 1 \"" << s->name << "\"\n" << s->text << "\n";
  return os.str();
}

namespace {

std::string buildLog(cl_program program, cl_device_id device) {
  std::size_t size = 0;
  clGetProgramBuildInfo(program, device, CL_PROGRAM_BUILD_LOG, 0, nullptr, &size);
  std::string log(size, '\0');
  if (size) clGetProgramBuildInfo(program, device, CL_PROGRAM_BUILD_LOG, size, log.data(), nullptr);
  while (!log.empty() && (log.back() == '\0' || log.back() == '\n')) log.pop_back();
  return log;
}

/// Loads and builds a cached binary; nullptr when the file is absent or does not load.
cl_program loadBinary(Context& ctx, const std::string& file, const std::string& options) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return nullptr;
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.empty()) return nullptr;
  const unsigned char* data = bytes.data();
  const std::size_t size = bytes.size();
  cl_int binaryStatus = CL_SUCCESS, status = CL_SUCCESS;
  cl_device_id device = ctx.device();
  cl_program program =
      clCreateProgramWithBinary(ctx.context(), 1, &device, &size, &data, &binaryStatus, &status);
  if (status != CL_SUCCESS || binaryStatus != CL_SUCCESS || !program) {
    if (program) clReleaseProgram(program);
    return nullptr;
  }
  if (clBuildProgram(program, 1, &device, options.c_str(), nullptr, nullptr) != CL_SUCCESS) {
    clReleaseProgram(program);
    return nullptr;
  }
  // A binary that builds but lacks kernels (truncated file) is also rejected.
  cl_uint kernelCount = 0;
  if (clCreateKernelsInProgram(program, 0, nullptr, &kernelCount) != CL_SUCCESS || kernelCount == 0) {
    clReleaseProgram(program);
    return nullptr;
  }
  return program;
}

/// Writes the program's device binary (atomically: temporary file, then rename). Best effort.
void storeBinary(Context& ctx, cl_program program, const std::string& file) {
  std::size_t size = 0;
  if (clGetProgramInfo(program, CL_PROGRAM_BINARY_SIZES, sizeof(size), &size, nullptr) != CL_SUCCESS ||
      size == 0)
    return;
  std::vector<unsigned char> bytes(size);
  unsigned char* ptr = bytes.data();
  if (clGetProgramInfo(program, CL_PROGRAM_BINARIES, sizeof(ptr), &ptr, nullptr) != CL_SUCCESS) return;
  (void)ctx;
  std::error_code ec;
  fs::create_directories(fs::path(file).parent_path(), ec);
  const std::string tmp = temporaryNameFor(file);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return;
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    out.close();  // the flush that meets a full disk
    if (!out) {
      fs::remove(tmp, ec);
      return;
    }
  }
  replaceFile(tmp, file);  // best effort: a binary not kept is compiled again next time
}

}  // namespace

bool cachesBinaries(const DeviceInfo& device) {
  return device.platformName.find("Portable Computing Language") == std::string::npos;
}

ProgramBuild buildProgram(Context& ctx, const std::string& label, const std::string& source,
                          const std::string& options, BinaryCache cache) {
  const DeviceInfo& dev = ctx.info();
  std::uint64_t h = fnv1a64(dev.name);
  h = fnv1a64(dev.driverVersion, h);
  h = fnv1a64(dev.deviceVersion, h);
  h = fnv1a64(options, h);
  h = fnv1a64(source, h);
  std::ostringstream keyStream;
  keyStream << std::hex << std::setw(16) << std::setfill('0') << h;
  const std::string key = keyStream.str();

  ProgramBuild result;
  const std::string dir = (cache == BinaryCache::Always || cachesBinaries(dev)) ? kernelCacheDirectory() : "";
  if (!dir.empty()) result.cacheFile = (fs::path(dir) / (key + ".clbin")).string();

  if (cl_program p = ctx.findProgram(key)) {
    result.program = p;
    result.origin = ProgramOrigin::Memory;
    return result;
  }
  if (!result.cacheFile.empty()) {
    if (cl_program p = loadBinary(ctx, result.cacheFile, options)) {
      ctx.storeProgram(key, p);
      result.program = p;
      result.origin = ProgramOrigin::Disk;
      return result;
    }
  }

  const char* text = source.c_str();
  const std::size_t length = source.size();
  cl_int status = CL_SUCCESS;
  cl_program program = clCreateProgramWithSource(ctx.context(), 1, &text, &length, &status);
  checkCl(status, "clCreateProgramWithSource", dev.name);
  cl_device_id device = ctx.device();
  status = clBuildProgram(program, 1, &device, options.c_str(), nullptr, nullptr);
  if (status != CL_SUCCESS) {
    const std::string log = buildLog(program, device);
    clReleaseProgram(program);
    fail(ErrorCode::DeviceError, "building OpenCL program '", label, "' for device '", dev.name,
         "' with options '", options, "' failed (clBuildProgram: ", errorString(status),
         "); compiler log:\n", log.empty() ? std::string("(empty log)") : log);
  }
  ctx.storeProgram(key, program);
  if (!result.cacheFile.empty()) storeBinary(ctx, program, result.cacheFile);
  result.program = program;
  result.origin = ProgramOrigin::Compiled;
  return result;
}

}  // namespace corofem::detail::cl
