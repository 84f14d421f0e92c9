// Names of the scene enumerations, the inverse of the parser's tables (scene_parser.cpp).
#include <corofem/scene.hpp>

namespace corofem {

// Switches rather than the parser's tables (std::string, built at start-up), so that benchmark
// registration during static initialisation may call them; tests/scene/test_enum_names.cpp checks
// that every name parses back to its enumerator.
const char* toString(Formulation f) {
  switch (f) {
    case Formulation::Linear: return "linear";
    case Formulation::Corotational: return "corotational";
    case Formulation::StVenantKirchhoff: return "stvk";
    case Formulation::NeoHookean: return "neo_hookean";
  }
  return "?";
}
const char* toString(RotationMethod m) {
  switch (m) {
    case RotationMethod::Polar: return "polar";
    case RotationMethod::Svd: return "svd";
    case RotationMethod::Quaternion: return "quaternion";
    case RotationMethod::Qr: return "qr";
  }
  return "?";
}
const char* toString(BackendKind b) {
  switch (b) {
    case BackendKind::Auto: return "auto";
    case BackendKind::Reference: return "reference";
    case BackendKind::OpenCL: return "opencl";
    case BackendKind::Vulkan: return "vulkan";
  }
  return "?";
}
const char* toString(Precision p) {
  switch (p) {
    case Precision::Double: return "double";
    case Precision::Float: return "float";
    case Precision::Mixed: return "mixed";
  }
  return "?";
}
const char* toString(SurfaceLayout l) {
  switch (l) {
    case SurfaceLayout::Interleaved: return "interleaved";
    case SurfaceLayout::Separate: return "separate";
  }
  return "?";
}
const char* toString(PreconditionerKind p) {
  switch (p) {
    case PreconditionerKind::None: return "none";
    case PreconditionerKind::Diagonal: return "diagonal";
    case PreconditionerKind::BlockDiagonal: return "block_diagonal";
    case PreconditionerKind::Amg: return "amg";
    case PreconditionerKind::WarpedCholesky: return "warped_cholesky";
    case PreconditionerKind::Auto: return "auto";
  }
  return "?";
}

}  // namespace corofem
