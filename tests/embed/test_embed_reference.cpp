// Coupled mesh checked against someone else's answer: Vega FEM's binding weights for its turtle and
// bridge models (turtle.interp, simpleBridge.interp), and SOFA's liver pair (statistics only).
#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>

#include "common/test_data.hpp"
#include "embed/element_locator.hpp"
#include "embed/embed_test_util.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

namespace corofem {
namespace {

using test::dataPath;
using test::interpolate;
using test::point;

struct VegaPair {
  const char* veg;
  const char* obj;
  const char* interp;
};

struct Loaded {
  TetMesh tets;
  SurfaceMesh surface;
  std::vector<test::VegaInterpRow> rows;
  SurfaceBinding binding;
  double diagonal = 0;  // of the tet mesh's bounding box: the length scale of all tolerances below
};

Loaded loadAndBind(const VegaPair& pair) {
  Loaded l;
  auto tets = readTetMesh(dataPath(pair.veg));
  EXPECT_TRUE(tets.isOk()) << tets.message();
  auto surface = readSurfaceMesh(dataPath(pair.obj));
  EXPECT_TRUE(surface.isOk()) << surface.message();
  if (!tets || !surface) return l;
  l.tets = std::move(tets).value();
  l.surface = std::move(surface).value();
  l.rows = test::readVegaInterp(dataPath(pair.interp));
  l.diagonal = test::diagonalOf(l.tets.nodes);
  auto binding = bindSurface(l.tets, l.surface);
  EXPECT_TRUE(binding.isOk()) << binding.message();
  if (binding) l.binding = std::move(binding).value();
  return l;
}

void printStatistics(const char* name, const SurfaceBinding& b) {
  const BindingStatistics& s = b.statistics;
  std::printf("[ stats    ] %s: %zu vertices, %zu inside, %zu outside, largest distance %.6g (%.3g of the bbox "
              "diagonal %.6g; maxDistance %.6g)\n",
              name, b.vertexCount(), s.insideCount, s.outsideCount, s.largestDistance,
              s.largestDistance / s.boundingBoxDiagonal, s.boundingBoxDiagonal, s.maxDistanceUsed);
}

/// The checks shared by the turtle and the bridge. Returns the number of vertices whose Vega weights
/// are all >= 0 (Vega's element contains them).
std::size_t compareWithVega(const Loaded& l, const char* name) {
  const std::size_t n = l.surface.vertexCount();
  EXPECT_EQ(l.rows.size(), n) << "one interp row per OBJ vertex";
  EXPECT_EQ(l.binding.vertexCount(), n);
  if (l.rows.size() != n || l.binding.vertexCount() != n) return 0;
  printStatistics(name, l.binding);

  // 1. Rest positions. Vega's weights (printed with 6 decimals) reproduce the vertices to about 1e-5
  // (SOURCES.md: 6.8e-6 turtle, 1.0e-5 bridge): a check of the reader and of the node numbering.
  // corofem's weights are computed in double from D_m^-1: they must reproduce the vertex to 1e-6 of
  // the tet mesh's bbox diagonal (the brief); they actually do to rounding, so 1e-12 is asserted.
  double vegaWorst = 0, oursWorst = 0;
  for (std::size_t v = 0; v < n; ++v) {
    const Eigen::Vector3d p = point(l.surface.vertices, v);
    vegaWorst = std::max(vegaWorst, (interpolate(l.tets.nodes, l.rows[v].nodes, l.rows[v].weights) - p).norm());
    const auto* nodes = &l.binding.nodes[4 * v];
    const auto* w = &l.binding.weights[4 * v];
    oursWorst = std::max(oursWorst, (interpolate(l.tets.nodes, nodes, w) - p).norm());
  }
  std::printf("[ rest     ] %s: worst rest-position error: Vega weights %.3g, corofem %.3g (bbox diagonal %.4g)\n",
              name, vegaWorst, oursWorst, l.diagonal);
  EXPECT_LT(vegaWorst, 1.5e-5) << "Vega weights should reproduce the OBJ to the printed precision";
  EXPECT_LT(oursWorst, 1e-12 * l.diagonal);

  // 2. Deformed positions. For every vertex that Vega's element contains (all Vega weights >= 0),
  // compute its exact barycentric coordinates in Vega's element; corofem's element must then give
  // the same deformed position. Under an affine map any element that reproduces the rest position
  // gives the same answer, so the nonlinear maps are the real test: there two elements agree only
  // where the vertex lies in both (on their shared face, edge or node).
  std::mt19937 rng(20261121);
  std::size_t contained = 0, compared = 0, sameElement = 0;
  for (int trial = 0; trial < 4; ++trial) {
    const bool nonlinear = trial != 0;
    const test::SmoothDeformation phi = test::SmoothDeformation::random(rng, l.diagonal, nonlinear);
    const std::vector<double> x = phi.apply(l.tets.nodes);
    std::vector<double> ours(3 * n);
    SurfaceOutput out;
    out.positionsDouble = ours.data();
    const Status st = deformSurface(l.binding, x.data(), l.tets.nodeCount(), out);
    if (!st) {
      ADD_FAILURE() << st.message();
      return 0;
    }
    double worst = 0;
    std::size_t worstVertex = 0;
    contained = compared = sameElement = 0;
    for (std::size_t v = 0; v < n; ++v) {
      const test::VegaInterpRow& row = l.rows[v];
      const bool vegaContains = *std::min_element(row.weights.begin(), row.weights.end()) >= 0.0;
      if (!vegaContains && nonlinear) continue;  // outside: elements legitimately differ
      const auto exact = test::exactBarycentric(l.tets.nodes, row.nodes, point(l.surface.vertices, v));
      const Eigen::Vector3d vega = interpolate(x, row.nodes, exact);
      const double err = (point(ours, v) - vega).norm();
      if (err > worst) worst = err, worstVertex = v;
      if (vegaContains) ++contained;
      ++compared;
      std::array<std::uint32_t, 4> a = row.nodes, b;
      std::copy_n(&l.binding.nodes[4 * v], 4, b.begin());
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      sameElement += a == b;
    }
    std::printf("[ deformed ] %s, %s map: %zu vertices compared (%zu of them bound to the same element as Vega's), worst "
                "difference %.3g = %.3g of the diagonal (vertex %zu)\n",
                name, nonlinear ? "nonlinear" : "affine", compared, sameElement, worst, worst / l.diagonal,
                worstVertex);
    // Rounding: |x| ~ diagonal, a few dozen flops, D_m conditioning: 1e-9 of the diagonal is far above
    // it and far below any effect of picking a wrong element (about |w| * amplitude ~ 1e-3 of it).
    EXPECT_LT(worst, 1e-9 * l.diagonal) << name << ": vertex " << worstVertex;
  }
  return contained;
}

TEST(EmbedVega, TurtleMatchesVegaWeights) {
  COROFEM_REQUIRE_DATA("meshes/vega/turtle/turtle.interp");
  const Loaded l = loadAndBind({"meshes/vega/turtle/turtle-volumetric-homogeneous.veg",
                                "meshes/vega/turtle/turtle.obj", "meshes/vega/turtle/turtle.interp"});
  ASSERT_EQ(l.binding.vertexCount(), 1961u);
  const std::size_t contained = compareWithVega(l, "turtle");
  EXPECT_EQ(contained, 1961u) << "SOURCES.md: all turtle weights are >= 0";
  EXPECT_EQ(l.binding.statistics.outsideCount, 0u);
}

TEST(EmbedVega, BridgeMatchesVegaWeightsAndItsOutsideVertices) {
  COROFEM_REQUIRE_DATA("meshes/vega/simpleBridge/simpleBridge.interp");
  const Loaded l = loadAndBind({"meshes/vega/simpleBridge/simpleBridge-ic_128_0.15_.1.veg",
                                "meshes/vega/simpleBridge/simpleBridge.obj",
                                "meshes/vega/simpleBridge/simpleBridge.interp"});
  ASSERT_EQ(l.binding.vertexCount(), 16085u);
  const std::size_t contained = compareWithVega(l, "bridge");
  EXPECT_EQ(contained, 16085u - 48u) << "SOURCES.md: 48 bridge vertices are outside";

  // The 48 vertices Vega extrapolates: corofem must find them outside too, or inside within its
  // tolerance (then Vega's element merely was not the containing one). Their rest positions are
  // checked above with all the others.
  const BindingStatistics& s = l.binding.statistics;
  const std::vector<std::uint32_t>& outside = s.outsideVertices;
  std::size_t vegaOutside = 0, agreeOutside = 0;
  double largestVegaOutsideDistance = 0;
  detail::ElementLocator locator(l.tets, 0.0);
  std::vector<std::uint32_t> stamp(l.tets.tetCount(), 0);
  std::uint32_t stampId = 0;
  for (std::size_t v = 0; v < l.rows.size(); ++v) {
    if (*std::min_element(l.rows[v].weights.begin(), l.rows[v].weights.end()) >= 0.0) continue;
    ++vegaOutside;
    const bool ours = std::binary_search(outside.begin(), outside.end(), static_cast<std::uint32_t>(v));
    const auto p = point(l.surface.vertices, v);
    const double d = locator.findNearest({p[0], p[1], p[2]}, INFINITY, stamp, stampId).distance;
    largestVegaOutsideDistance = std::max(largestVegaOutsideDistance, d);
    if (ours) {
      ++agreeOutside;
    } else {
      // Inside for corofem: the vertex must lie within rounding of the tet mesh.
      EXPECT_LT(d, 1e-9 * l.diagonal) << "vertex " << v << " is outside for Vega, inside for corofem";
    }
  }
  std::printf("[ outside  ] bridge: Vega extrapolates %zu vertices, corofem finds %zu outside (%zu of them in "
              "common); largest distance of Vega's outside vertices %.4g\n",
              vegaOutside, s.outsideCount, agreeOutside, largestVegaOutsideDistance);
  EXPECT_EQ(vegaOutside, 48u);
  EXPECT_EQ(agreeOutside, 48u);
  // Every corofem-outside vertex has a positive distance that matches an independent query.
  ASSERT_EQ(s.outsideDistances.size(), s.outsideCount);
  for (std::size_t i = 0; i < s.outsideCount; ++i) {
    EXPECT_GT(s.outsideDistances[i], 0.0);
    EXPECT_LE(s.outsideDistances[i], s.largestDistance);
  }
}

TEST(EmbedSofa, LiverSmoothSurfaceBindsToLiverMesh) {
  COROFEM_REQUIRE_DATA("meshes/sofa/liver.msh");
  COROFEM_REQUIRE_DATA("meshes/sofa/liver-smooth.obj");
  auto tets = readTetMesh(dataPath("meshes/sofa/liver.msh"));
  ASSERT_TRUE(tets.isOk()) << tets.message();
  auto surface = readSurfaceMesh(dataPath("meshes/sofa/liver-smooth.obj"));
  ASSERT_TRUE(surface.isOk()) << surface.message();
  ASSERT_EQ(tets->tetCount(), 596u);
  ASSERT_EQ(surface->vertexCount(), 2194u);
  auto binding = bindSurface(*tets, *surface);
  ASSERT_TRUE(binding.isOk()) << binding.message();
  printStatistics("liver", *binding);
  const BindingStatistics& s = binding->statistics;
  EXPECT_EQ(s.insideCount + s.outsideCount, 2194u);
  // A smooth surface around a coarse polyhedral mesh: some vertices must stick out (rounded corners),
  // but all within the default 5% of the diagonal (else binding would have failed).
  EXPECT_LE(s.largestDistance, s.maxDistanceUsed);
  // Rest positions reproduced (to rounding; 1e-12 of the diagonal).
  double worst = 0;
  for (std::size_t v = 0; v < 2194; ++v)
    worst = std::max(worst, (interpolate(tets->nodes, &binding->nodes[4 * v], &binding->weights[4 * v]) -
                             point(surface->vertices, v))
                                .norm());
  EXPECT_LT(worst, 1e-12 * s.boundingBoxDiagonal);

  // So many outside vertices (the smooth surface bulges past the coarse mesh's flat faces) deserve an
  // independent check: brute force over all 596 elements, with the same definitions (inside: all
  // barycentric coordinates >= -1e-10, lowest index; outside: smallest point-tet distance).
  detail::ElementLocator locator(*tets, 0.0);
  std::size_t bruteInside = 0;
  for (std::size_t v = 0; v < 2194; ++v) {
    const auto x = point(surface->vertices, v);
    const detail::Point3 p{x[0], x[1], x[2]};
    std::uint32_t containing = detail::ElementLocator::kNone;
    double nearest = INFINITY;
    for (std::size_t e = 0; e < tets->tetCount() && containing == detail::ElementLocator::kNone; ++e) {
      double w[4];
      locator.barycentric(e, p, w);
      if (*std::min_element(w, w + 4) >= -BindingOptions{}.insideTolerance) containing = static_cast<std::uint32_t>(e);
      nearest = std::min(nearest, locator.pointTetDistance(e, p));
    }
    const auto it = std::lower_bound(s.outsideVertices.begin(), s.outsideVertices.end(), static_cast<std::uint32_t>(v));
    const bool oursOutside = it != s.outsideVertices.end() && *it == v;
    if (containing != detail::ElementLocator::kNone) {
      ++bruteInside;
      EXPECT_FALSE(oursOutside) << "vertex " << v;
      EXPECT_EQ(binding->element[v], containing) << "vertex " << v << ": lowest containing element";
    } else {
      ASSERT_TRUE(oursOutside) << "vertex " << v;
      const double ours = s.outsideDistances[static_cast<std::size_t>(it - s.outsideVertices.begin())];
      // Same formula on the same element, or a tie within 1e-12 of the diagonal.
      EXPECT_NEAR(ours, nearest, 1e-12 * s.boundingBoxDiagonal) << "vertex " << v;
      EXPECT_NEAR(locator.pointTetDistance(binding->element[v], p), nearest, 1e-12 * s.boundingBoxDiagonal);
    }
  }
  EXPECT_EQ(bruteInside, s.insideCount);
}

}  // namespace
}  // namespace corofem
