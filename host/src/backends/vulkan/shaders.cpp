// The embedded SPIR-V (shaders.hpp). The .inc files are glslc's C initializer lists.
#include "backends/vulkan/shaders.hpp"

#include "util/hash.hpp"

#include <initializer_list>

namespace corofem::detail::vk {

namespace {

// clang-format off
const std::uint32_t kRotationsFloat[] =
#include "rotations_float.inc"
;
const std::uint32_t kRotationsDouble[] =
#include "rotations_double.inc"
;
const std::uint32_t kElementFloat[] =
#include "element_float.inc"
;
const std::uint32_t kElementDouble[] =
#include "element_double.inc"
;
const std::uint32_t kGatherFloat[] =
#include "gather_float.inc"
;
const std::uint32_t kGatherDouble[] =
#include "gather_double.inc"
;
const std::uint32_t kPcgFloat[] =
#include "pcg_float.inc"
;
const std::uint32_t kPcgDouble[] =
#include "pcg_double.inc"
;
const std::uint32_t kReduceFloat[] =
#include "reduce_float.inc"
;
const std::uint32_t kReduceDouble[] =
#include "reduce_double.inc"
;
const std::uint32_t kPcgGroupFloat[] =
#include "pcg_group_float.inc"
;
const std::uint32_t kPcgGroupDouble[] =
#include "pcg_group_double.inc"
;
const std::uint32_t kElementFusedFloat[] =
#include "element_fused_float.inc"
;
const std::uint32_t kElementFusedDouble[] =
#include "element_fused_double.inc"
;
const std::uint32_t kPcgFusedFloat[] =
#include "pcg_fused_float.inc"
;
const std::uint32_t kPcgFusedDouble[] =
#include "pcg_fused_double.inc"
;
const std::uint32_t kSurfaceFloat[] =
#include "surface_float.inc"
;
const std::uint32_t kSurfaceDouble[] =
#include "surface_double.inc"
;
const std::uint32_t kAmgFloat[] =
#include "amg_float.inc"
;
const std::uint32_t kAmgDouble[] =
#include "amg_double.inc"
;
const std::uint32_t kStepFloat[] =
#include "step_float.inc"
;
const std::uint32_t kStepDouble[] =
#include "step_double.inc"
;
// clang-format on

template <std::size_t N>
Spirv of(const std::uint32_t (&words)[N]) {
  return {words, sizeof(words)};
}

}  // namespace

Spirv shaderCode(Shader shader, bool isDouble) {
  switch (shader) {
    case Shader::Rotations: return isDouble ? of(kRotationsDouble) : of(kRotationsFloat);
    case Shader::Element: return isDouble ? of(kElementDouble) : of(kElementFloat);
    case Shader::Gather: return isDouble ? of(kGatherDouble) : of(kGatherFloat);
    case Shader::Pcg: return isDouble ? of(kPcgDouble) : of(kPcgFloat);
    case Shader::Reduce: return isDouble ? of(kReduceDouble) : of(kReduceFloat);
    case Shader::PcgGroup: return isDouble ? of(kPcgGroupDouble) : of(kPcgGroupFloat);
    case Shader::ElementFused: return isDouble ? of(kElementFusedDouble) : of(kElementFusedFloat);
    case Shader::PcgFused: return isDouble ? of(kPcgFusedDouble) : of(kPcgFusedFloat);
    case Shader::Surface: return isDouble ? of(kSurfaceDouble) : of(kSurfaceFloat);
    case Shader::Amg: return isDouble ? of(kAmgDouble) : of(kAmgFloat);
    case Shader::Step: return isDouble ? of(kStepDouble) : of(kStepFloat);
  }
  return {};
}

std::uint64_t shaderHash() {
  std::uint64_t h = kFnv1aOffset;
  for (Shader s : {Shader::Rotations, Shader::Element, Shader::Gather, Shader::Pcg, Shader::Reduce, Shader::PcgGroup,
                   Shader::ElementFused, Shader::PcgFused, Shader::Surface, Shader::Amg, Shader::Step})
    for (bool d : {false, true}) {
      const Spirv code = shaderCode(s, d);
      h = fnv1a64(code.words, code.bytes, h);
    }
  return h;
}

}  // namespace corofem::detail::vk
