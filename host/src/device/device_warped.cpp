// The "warped_cholesky" preconditioner's host side on a device backend (device_warped.hpp).
#include "device/device_warped.hpp"

#include "util/error.hpp"

namespace corofem::detail {

DeviceWarped::DeviceWarped(const std::vector<BodySegment>& segments)
    : segs_(segments),
      bodies_(segments.size()),
      freeDofs_(segments.size()),
      freeDevice_(segments.size()),
      freeKnown_(segments.size(), 0),
      warpStale_(segments.size(), 1) {}

void DeviceWarped::positionsSet(const BodySet& bodies) {
  for (std::size_t s : bodies) warpStale_.at(s) = 1;
}

void DeviceWarped::invalidate(std::size_t s) {
  bodies_.at(s).clear();
  freeKnown_[s] = 0;
  warpStale_[s] = 1;
}

void DeviceWarped::constraintsChanged(std::size_t s) { freeKnown_.at(s) = 0; }

long long DeviceWarped::builds() const {
  long long n = 0;
  for (const BodyCholesky& b : bodies_) n += b.builds();
  return n;
}

void DeviceWarped::prepare(const BodySet& running, const std::vector<std::pair<double, double>>& coefficients,
                           const std::function<std::vector<std::vector<double>>(const BodySet&)>& rotationsOf) {
  if (coefficients.size() != running.size())
    fail(ErrorCode::Internal, "warped_cholesky: ", coefficients.size(), " coefficients for ", running.size(), " bodies");
  BodySet due;  // co-rotational bodies whose warp is due
  for (std::size_t i = 0; i < running.size(); ++i) {
    const std::size_t s = running[i];
    const BodySegment& sg = segs_.at(s);
    if (!freeKnown_[s]) {
      freeDofs_[s] = segmentFreeDofs(sg, &freeDevice_[s]);
      freeKnown_[s] = 1;
    }
    BodyCholesky& body = bodies_[s];
    if (body.ensure(*sg.problem, freeDofs_[s], coefficients[i].first, coefficients[i].second) != Made::Kept)
      warpStale_[s] = 1;  // the factor taken back or made has another body's warp, or none
    if (!warpStale_[s]) continue;
    if (sg.corotational) {
      due.push_back(s);
      continue;
    }
    body.cholesky().setNodeRotations({});  // the linear formulation: K_t = K_0, no warp
    warpStale_[s] = 0;
  }
  if (due.empty()) return;
  const std::vector<std::vector<double>> rotations = rotationsOf(due);
  if (rotations.size() != due.size())
    fail(ErrorCode::Internal, "warped_cholesky: element rotations of ", rotations.size(), " bodies for ", due.size());
  for (std::size_t i = 0; i < due.size(); ++i) {
    const std::size_t s = due[i];
    const std::vector<double>& r = rotations[i];
    const TetMesh& mesh = segs_[s].problem->mesh;
    if (r.size() != 9 * mesh.tetCount())
      fail(ErrorCode::Internal, "warped_cholesky: ", r.size() / 9, " element rotations for ", mesh.tetCount(),
           " elements");
    std::vector<Mat3> elementRotations(mesh.tetCount());
    for (std::size_t e = 0; e < elementRotations.size(); ++e)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) elementRotations[e](a, b) = r[9 * e + 3 * a + b];
    bodies_[s].cholesky().setNodeRotations(nodeRotations(mesh, elementRotations));
    warpStale_[s] = 0;
  }
}

double DeviceWarped::apply(std::size_t s, const unsigned char* r, unsigned char* z, bool isDouble) {
  const BodySegment& sg = segs_.at(s);
  const std::vector<std::size_t>& dev = freeDevice_[s];
  const WarpedCholesky& factor = bodies_[s].cholesky();
  if (!freeKnown_[s] || !factor.built() || factor.builtFreeDofs().size() != dev.size())
    fail(ErrorCode::Internal, "warped_cholesky: body '", sg.problem->name, "' applied before its factor was made");
  const Eigen::Index n = static_cast<Eigen::Index>(dev.size());
  r_.resize(n);
  double rz = 0.0;
  withReals(r, isDouble, 0, [&](const auto* in) {
    for (Eigen::Index i = 0; i < n; ++i) r_[i] = static_cast<double>(in[dev[static_cast<std::size_t>(i)]]);
    factor.apply(r_, z_);
    withReals(z, isDouble, 0, [&](auto* out) {
      using T = std::remove_pointer_t<decltype(out)>;
      for (std::size_t d = 0; d < sg.dofs(); ++d) out[d] = T(0);
      for (Eigen::Index i = 0; i < n; ++i) {
        const std::size_t d = dev[static_cast<std::size_t>(i)];
        out[d] = static_cast<T>(z_[i]);
        rz += static_cast<double>(in[d]) * static_cast<double>(out[d]);
      }
    });
  });
  return rz;
}

}  // namespace corofem::detail
