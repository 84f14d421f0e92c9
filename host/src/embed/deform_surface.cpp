// deformSurface: the per-frame update of the coupled mesh (paper Section 5): vertex positions from the
// deformed tetrahedra, then smooth vertex normals, into renderer-ready float buffers.
#include <corofem/embed.hpp>

#include "util/error.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

namespace corofem {
namespace {

constexpr std::size_t kVerticesPerDeformThread = 100000;  // below this a thread costs more than it saves

/// Pass 1, vertices [first, last): x_v = sum_k w_vk x_{n_vk}, into `out` (double) and/or `outFloat`.
void computePositions(const SurfaceBinding& b, const double* x, std::size_t first, std::size_t last, double* out,
                      float* outFloat) {
  const std::uint32_t* nodes = b.nodes.data();
  const double* weights = b.weights.data();
  for (std::size_t v = first; v < last; ++v) {
    const std::uint32_t* n = nodes + 4 * v;
    const double* w = weights + 4 * v;
    const double* x0 = x + 3 * static_cast<std::size_t>(n[0]);
    const double* x1 = x + 3 * static_cast<std::size_t>(n[1]);
    const double* x2 = x + 3 * static_cast<std::size_t>(n[2]);
    const double* x3 = x + 3 * static_cast<std::size_t>(n[3]);
    for (int a = 0; a < 3; ++a) {
      const double p = w[0] * x0[a] + w[1] * x1[a] + w[2] * x2[a] + w[3] * x3[a];
      if (out) out[3 * v + a] = p;
      if (outFloat) outFloat[3 * v + a] = static_cast<float>(p);
    }
  }
}

/// Pass 2, triangles [first, last): face vector f_t = (x_b - x_a) x (x_c - x_a) of t = (a, b, c), whose
/// length is twice the area.
void computeFaceVectors(const SurfaceBinding& b, const double* p, std::size_t first, std::size_t last,
                        double* faces) {
  const std::uint32_t* tri = b.triangles.data();
  for (std::size_t f = first; f < last; ++f) {
    const std::uint32_t* t = tri + 3 * f;
    const double* a = p + 3 * static_cast<std::size_t>(t[0]);
    const double* bb = p + 3 * static_cast<std::size_t>(t[1]);
    const double* c = p + 3 * static_cast<std::size_t>(t[2]);
    const double e1[3] = {bb[0] - a[0], bb[1] - a[1], bb[2] - a[2]};
    const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    faces[3 * f + 0] = e1[1] * e2[2] - e1[2] * e2[1];
    faces[3 * f + 1] = e1[2] * e2[0] - e1[0] * e2[2];
    faces[3 * f + 2] = e1[0] * e2[1] - e1[1] * e2[0];
  }
}

/// Pass 3, vertices [first, last): n_v = normalise(sum of f_t over the incident triangles t): the
/// area-weighted mean of the face normals. Gathered per vertex in ascending triangle order (no
/// scatter, no races, the same bits for every thread count).
void computeNormals(const SurfaceBinding& b, const double* p, const double* faces, std::size_t first,
                    std::size_t last, const SurfaceOutput& out) {
  const std::uint32_t* offsets = b.vertexTriangleOffsets.data();
  const std::uint32_t* incident = b.vertexTriangles.data();
  for (std::size_t v = first; v < last; ++v) {
    double n[3] = {0.0, 0.0, 0.0};
    for (std::uint32_t q = offsets[v]; q < offsets[v + 1]; ++q) {
      const double* f = faces + 3 * static_cast<std::size_t>(incident[q]);
      n[0] += f[0];
      n[1] += f[1];
      n[2] += f[2];
    }
    const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double scale = length > 0.0 ? 1.0 / length : 0.0;
    float nf[3];
    for (int a = 0; a < 3; ++a) nf[a] = static_cast<float>(n[a] * scale);
    if (out.normals) std::copy(nf, nf + 3, out.normals + 3 * v);
    if (out.interleaved) {
      float* dst = out.interleaved + 6 * v;
      for (int a = 0; a < 3; ++a) {
        dst[a] = static_cast<float>(p[3 * v + a]);
        dst[3 + a] = nf[a];
      }
    }
  }
}

/// Runs fn(first, last) over [0, count) on `threads` threads (contiguous ranges), or inline.
template <class Fn>
void parallelRanges(std::size_t count, std::size_t threads, Fn&& fn) {
  if (threads <= 1) {
    fn(std::size_t{0}, count);
    return;
  }
  std::vector<std::thread> workers;
  workers.reserve(threads - 1);
  for (std::size_t t = 1; t < threads; ++t)
    workers.emplace_back([&, t] { fn(count * t / threads, count * (t + 1) / threads); });
  fn(std::size_t{0}, count / threads);
  for (auto& w : workers) w.join();
}

}  // namespace

Status deformSurface(const SurfaceBinding& binding, const double* tetNodePositions, std::size_t tetNodeCount,
                     const SurfaceOutput& output) {
  return detail::guard([&] {
    if (tetNodeCount != binding.tetNodeCount)
      detail::fail(ErrorCode::BadInput, "deformSurface: ", tetNodeCount, " node positions given but the surface "
                   "was bound to a tet mesh of ", binding.tetNodeCount, " nodes; pass that mesh's current positions");
    if (!tetNodePositions)
      detail::fail(ErrorCode::BadInput, "deformSurface: tetNodePositions is null");
    if (!output.interleaved && !output.positions && !output.normals && !output.positionsDouble)
      detail::fail(ErrorCode::BadInput, "deformSurface: SurfaceOutput has no buffer set; set interleaved, or "
                   "positions / normals / positionsDouble");
    const std::size_t vertexCount = binding.vertexCount();
    if (binding.nodes.size() != 4 * vertexCount || binding.weights.size() != 4 * vertexCount ||
        binding.vertexTriangleOffsets.size() != vertexCount + 1)
      detail::fail(ErrorCode::BadInput, "deformSurface: the SurfaceBinding is inconsistent (sizes of nodes, weights "
                   "and vertexTriangleOffsets do not match its ", vertexCount, " vertices); make it with bindSurface");
    if (vertexCount == 0) return;

    std::size_t threads = output.threads > 0
                              ? static_cast<std::size_t>(output.threads)
                              : std::clamp<std::size_t>((vertexCount + kVerticesPerDeformThread - 1) / kVerticesPerDeformThread, 1,
                                                        std::max(1u, std::thread::hardware_concurrency()));
    threads = std::min(threads, vertexCount);

    const bool wantNormals = output.interleaved || output.normals;
    // Normals need the positions of neighbouring vertices and the face vectors of all incident
    // triangles: passes over double scratch buffers, kept per calling thread so that frames do not
    // reallocate.
    thread_local std::vector<double> positionScratch, faceScratch;
    double* positions = output.positionsDouble;
    const std::size_t triangleCount = binding.triangles.size() / 3;
    if (!positions && wantNormals) {
      if (positionScratch.size() < 3 * vertexCount) positionScratch.resize(3 * vertexCount);
      positions = positionScratch.data();
    }
    parallelRanges(vertexCount, threads, [&](std::size_t first, std::size_t last) {
      computePositions(binding, tetNodePositions, first, last, positions, output.positions);
    });
    if (wantNormals) {
      if (faceScratch.size() < 3 * triangleCount) faceScratch.resize(3 * triangleCount);
      double* faces = faceScratch.data();
      parallelRanges(triangleCount, std::min(threads, std::max<std::size_t>(triangleCount, 1)),
                     [&](std::size_t first, std::size_t last) {
                       computeFaceVectors(binding, positions, first, last, faces);
                     });
      parallelRanges(vertexCount, threads, [&](std::size_t first, std::size_t last) {
        computeNormals(binding, positions, faces, first, last, output);
      });
    }
  });
}

}  // namespace corofem
