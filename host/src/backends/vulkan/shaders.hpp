// The SPIR-V of the compute shaders in kernels/vulkan/, compiled at build time by glslc
// (cmake/CompileShaders.cmake) and embedded here, in float and in double.
#pragma once

#include <cstddef>
#include <cstdint>

namespace corofem::detail::vk {

enum class Shader { Rotations, Element, Gather, Pcg, Reduce, PcgGroup, ElementFused, PcgFused, Surface, Amg, Step };

struct Spirv {
  const std::uint32_t* words = nullptr;
  std::size_t bytes = 0;
};

Spirv shaderCode(Shader shader, bool isDouble);

/// FNV-1a over every embedded shader's words (the calibration cache's build id).
std::uint64_t shaderHash();

}  // namespace corofem::detail::vk
