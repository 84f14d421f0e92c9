// The host side of the "warped_cholesky" preconditioner (precond/warped_cholesky.hpp) on a device
// backend, written once for every backend: each body's factor of its rest operator made for its
// solve's coefficients (BodyCholesky, the reference backend's), its warp from the element rotations
// the device computed, and z = W A_0^-1 W^T r applied on the host to r as the device holds it (its
// precision, its numbering, padding and constrained dofs included).
//
// The factor's two triangular solves run on the host's threads between the device's update of r
// and its product w = A u: a backend reads r, calls apply and writes z back with the sum r . z in
// the place of the device's own. On a CPU device (PoCL) r and z cross no bus; on a GPU each
// iteration costs a round trip, the price of a factor no GPU kernel applies yet.
#pragma once

#include "device/body_layout.hpp"
#include "device/device.hpp"
#include "precond/warped_cholesky.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <functional>
#include <utility>
#include <vector>

namespace corofem::detail {

class DeviceWarped {
 public:
  /// `segments`: the device's (alive as long as this; their constraints are read at each prepare
  /// after constraintsChanged).
  explicit DeviceWarped(const std::vector<BodySegment>& segments);

  /// The bodies' positions changed: their warps are due at their next solve.
  void positionsSet(const BodySet& bodies);
  /// The body's material changed: its factor is made again at its next solve.
  void invalidate(std::size_t segment);
  /// The body's constraints changed: its free dofs are read again at its next solve, where
  /// BodyCholesky::ensure takes back the factor made for exactly them (the spare) or makes one.
  void constraintsChanged(std::size_t segment);
  /// Factors made so far, every body's.
  long long builds() const;

  /// Before a solve of `running` (segments), coefficients[i] = (mass, stiffness) of the operator
  /// m M + s K of running[i]: makes or takes back their factors, and warps each co-rotational body
  /// whose positions changed since its last warp by its element rotations: rotationsOf(due), called
  /// once where some are due, gives per segment of `due` 9 reals per element of the problem's
  /// numbering, row-major. Throws as WarpedCholesky::build (Error(SolveFailed) naming the body for
  /// a singular rest operator).
  void prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients,
               const std::function<std::vector<std::vector<double>>(const BodySet& due)>& rotationsOf);

  /// z = W A_0^-1 W^T r on segment s's free dofs, 0 on its constrained ones: r and z point at the
  /// segment's first dof in the device's reals (float, or double with `isDouble`), its 3 N dofs in
  /// the device's numbering. Returns r . z over the free dofs of the reals as stored, summed in
  /// the problem's dof order (the same bits on any threads). Only after prepare of the segment.
  double apply(std::size_t s, const unsigned char* r, unsigned char* z, bool isDouble);

 private:
  const std::vector<BodySegment>& segs_;
  std::vector<BodyCholesky> bodies_;                  ///< per segment
  std::vector<std::vector<Eigen::Index>> freeDofs_;   ///< per segment, in the problem's numbering
  /// Per segment, per free dof: its device dof (from the segment's first).
  std::vector<std::vector<std::size_t>> freeDevice_;
  std::vector<char> freeKnown_;                       ///< per segment: freeDofs_ is its constraints'
  std::vector<char> warpStale_;                       ///< per segment: positions changed since its warp
  Eigen::VectorXd r_, z_;                             ///< work vectors of apply
};

}  // namespace corofem::detail
