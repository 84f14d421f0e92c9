// How a device backend lays out many bodies in shared arrays, written once for every backend:
// each body a *segment* whose elements and nodes are padded to the device's alignment (whole
// work-groups), in a numbering of the device's own where the mesh's scatters the kernels' loads (a
// Morton order, mesh/locality_order.hpp), with the host-device permutation; and the conversion of
// host vectors (double, the problem's numbering) to and from the device's precision and numbering,
// in chunks on the host's threads.
#pragma once

#include "model/problem.hpp"
#include "util/parallel.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <vector>

namespace corofem::detail {

/// One body's place in a device's shared arrays.
struct BodySegment {
  const Problem* problem = nullptr;         ///< the caller's problem (it outlives the device)
  std::size_t nodes = 0, elems = 0;         ///< real counts
  std::size_t nodeBegin = 0, nodeSpan = 0;  ///< padded range in the shared node arrays
  std::size_t elemBegin = 0, elemSpan = 0;  ///< padded range in the shared element arrays
  bool corotational = true;
  double rayleighMass = 0, rayleighStiffness = 0;
  std::vector<std::uint8_t> constrained;    ///< 3 * nodes, in the device's node order
  double centroid[3] = {0, 0, 0};           ///< subtracted from the last positions set
  /// The device's numbering when it is not the problem's: device node i is the problem's node
  /// hostNode[i], device element i its element hostElem[i]; deviceNode inverts hostNode. Empty:
  /// the problem's own numbering.
  std::vector<std::uint32_t> hostNode, deviceNode, hostElem;

  std::size_t dofBegin() const { return 3 * nodeBegin; }
  std::size_t dofs() const { return 3 * nodes; }
  /// The problem's dof of the segment's device dof d (0 <= d < dofs()).
  std::size_t hostDof(std::size_t d) const { return hostNode.empty() ? d : 3 * std::size_t{hostNode[d / 3]} + d % 3; }
};

/// The bodies of one device laid out end to end.
class BodyLayout {
 public:
  /// `order`: 1 a Morton order for every body, 0 the meshes' own, -1 a Morton order where it is
  /// more local than the mesh's (localityOrder). Elements are padded to `elementAlign`, nodes to
  /// `nodeAlign`. Bodies with `elements * maxComponents` or `9 * nodes` at or above 2^31 keep their
  /// numbering (the caller refuses them). Throws Error(BadInput) for a body without elements,
  /// Error(Internal) for an inconsistent problem.
  BodyLayout(const std::vector<const Problem*>& problems, int order, std::size_t elementAlign, std::size_t nodeAlign,
             std::size_t maxComponents);

  std::vector<BodySegment> segments;
  std::size_t elementTotal = 0;  ///< all segments' padded elements
  std::size_t nodeTotal = 0;     ///< all segments' padded nodes

  /// Body s's problem in the device's numbering (the mesh, element rest states, rest positions,
  /// lumped mass, constraints and material; not the loads): what the device uploads. Valid until
  /// releaseReordered().
  const Problem& deviceProblem(std::size_t s) const { return reordered_[s] ? *reordered_[s] : *segments[s].problem; }
  /// Drops the reordered copies (past the uploads only the permutations are needed).
  void releaseReordered() { reordered_.clear(); reordered_.resize(segments.size()); }

 private:
  std::vector<std::unique_ptr<Problem>> reordered_;
};

/// The reals of a device buffer's host copy `base` as T* (float or double) at real `begin`:
/// fn(T*) (const bytes give const reals).
template <class Byte, class Fn>
void withReals(Byte* base, bool isDouble, std::size_t begin, Fn&& fn) {
  constexpr bool ro = std::is_const_v<Byte>;
  if (isDouble)
    fn(reinterpret_cast<std::conditional_t<ro, const double, double>*>(base) + begin);
  else
    fn(reinterpret_cast<std::conditional_t<ro, const float, float>*>(base) + begin);
}

/// Reals [begin, begin + count) of `base` = value(0 .. count - 1), converted to the device
/// precision, in chunks of `chunk` on the host's threads.
template <class Fn>
void putReals(unsigned char* base, bool isDouble, std::size_t begin, std::size_t count, std::size_t chunk, Fn&& value) {
  parallelChunks(count, chunk, [&](std::size_t, std::size_t lo, std::size_t hi) {
    withReals(base, isDouble, begin, [&](auto* out) {
      for (std::size_t d = lo; d < hi; ++d) out[d] = static_cast<std::remove_pointer_t<decltype(out)>>(value(d));
    });
  });
}

/// A small table of reals as the bytes of a device buffer in its precision (on the calling thread).
inline std::vector<unsigned char> realBytes(const std::vector<double>& values, bool isDouble) {
  std::vector<unsigned char> bytes(values.size() * (isDouble ? sizeof(double) : sizeof(float)));
  putReals(bytes.data(), isDouble, 0, values.size(), values.size() + 1, [&](std::size_t i) { return values[i]; });
  return bytes;
}

/// Segment sg's free dofs in the problem's numbering, ascending (the segment keeps its mask in the
/// device's); with `deviceDofs`, each one's device dof (from the segment's first) at the same index.
std::vector<Eigen::Index> segmentFreeDofs(const BodySegment& sg, std::vector<std::size_t>* deviceDofs = nullptr);

/// out = segment sg's reals of `base` in double, in the problem's dof order (resized only if its
/// size differs), in chunks of `chunk` on the host's threads.
void getReals(const unsigned char* base, bool isDouble, const BodySegment& sg, std::size_t chunk, Eigen::VectorXd& out);

}  // namespace corofem::detail
