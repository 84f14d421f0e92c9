// What the drivers measure a body's residuals and states against: which dofs are free, its size,
// and the force below which a residual counts as zero.
#pragma once

#include "model/problem.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>

namespace corofem::detail {

struct BodyScale {
  Eigen::ArrayXd freeMask;  ///< 1 on free dofs, 0 on constrained ones
  double diagonal = 1.0;    ///< rest bounding-box diagonal (m), the body's length scale
  /// Force below which a residual counts as zero: the force that strains the whole body by 1e-8,
  /// (lambda + 2 mu) * diagonal^2 * 1e-8 (N). It keeps an unloaded body, whose internal forces are
  /// pure rounding, from failing a purely relative test.
  double forceFloor = 0.0;
};

inline BodyScale bodyScale(const Problem& p) {
  BodyScale s;
  const Eigen::Index n = p.restPositions.size();
  s.freeMask = Eigen::ArrayXd::Ones(n);
  for (Eigen::Index d = 0; d < n; ++d)
    if (static_cast<std::size_t>(d) < p.constrained.size() && p.constrained[static_cast<std::size_t>(d)])
      s.freeMask[d] = 0.0;
  if (n >= 3) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = Eigen::Vector3d::Constant(-INFINITY);
    for (Eigen::Index k = 0; k + 2 < n; k += 3) {
      const Eigen::Vector3d q = p.restPositions.segment<3>(k);
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
    s.diagonal = (hi - lo).norm();
  }
  if (!(s.diagonal > 0.0) || !std::isfinite(s.diagonal)) s.diagonal = 1.0;
  const double modulus = p.lame.lambda + 2.0 * p.lame.mu;  // P-wave modulus, > 0
  s.forceFloor = 1e-8 * (modulus > 0.0 ? modulus : 1.0) * s.diagonal * s.diagonal;
  return s;
}

}  // namespace corofem::detail
