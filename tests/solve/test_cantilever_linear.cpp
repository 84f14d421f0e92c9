// Linear cantilever: tip deflection under a tip load and under self-weight against the beam closed
// forms (../shared/data/references/linear_beam_closed_forms.md), converging with refinement.
//
// Beam: 10 x 0.5 x 1 (x along the length, y the width b = 0.5, z the height h = 1), clamped at
// x = 0 (every node of that face), loaded in -z, so it bends across the height:
//   I = b h^3 / 12 = 0.5 / 12 = 0.041667, A = 0.5.
// Tip load P:       delta = P L^3 / (3 E I) + P L / (kappa G A)
// Self-weight q:    delta = q L^4 / (8 E I) + q L^2 / (2 kappa G A),  q = rho g A
// (Timoshenko shear terms, kappa = 5/6, G = E / (2 (1 + nu)); they add 0.8 % and 0.5 % here.)
// Linear tetrahedra lock in bending, so the computed deflections approach these from below.
#include "beam_helpers.hpp"
#include "common/test_data.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <string>
#include <vector>

namespace corofem {
namespace {

using namespace corofem::test;

constexpr double kBarLength = 10.0, kBarWidth = 0.5, kBarHeight = 1.0;
constexpr double kBarE = 1e9, kBarNu = 0.3, kBarRho = 1000.0, kBarG = 9.81, kBarP = 1e4;
constexpr double kBarI = kBarWidth * kBarHeight * kBarHeight * kBarHeight / 12.0, kBarArea = kBarWidth * kBarHeight;
constexpr double kBarKappa = 5.0 / 6.0;
constexpr double kBarShear = kBarE / (2.0 * (1.0 + kBarNu));

double tipLoadClosedForm() {
  return kBarP * std::pow(kBarLength, 3) / (3 * kBarE * kBarI) + kBarP * kBarLength / (kBarKappa * kBarShear * kBarArea);
}
double selfWeightClosedForm() {
  const double q = kBarRho * kBarG * kBarArea;
  return q * std::pow(kBarLength, 4) / (8 * kBarE * kBarI) + q * kBarLength * kBarLength / (2 * kBarKappa * kBarShear * kBarArea);
}

/// Tip deflection (mean -u_z of the tip face) of the linear formulation, one static increment.
double tipDeflection(const MeshSourceDesc& mesh, bool selfWeight) {
  BodyDesc body = cantileverBody(mesh, 0.0, kBarE, kBarNu, kBarRho, Formulation::Linear);
  if (selfWeight)
    body.loads.push_back(gravity({0, 0, -kBarG}));
  else
    body.loads.push_back(tipForce(kBarLength, {0, 0, -kBarP}));
  Scene scene = staticScene(body, 1);
  auto sim = Simulation::create(scene);
  if (!sim) {
    ADD_FAILURE() << sim.message();
    return NAN;
  }
  if (!runToEnd(sim.value())) return NAN;
  return -meanDisplacement(sim.value(), planeX(kBarLength))[2];
}

struct Series {
  std::vector<std::string> labels;
  std::vector<double> errors;  // (closed form - computed) / closed form
};

Series run(const std::vector<std::pair<std::string, MeshSourceDesc>>& meshes, bool selfWeight) {
  Series s;
  const double exact = selfWeight ? selfWeightClosedForm() : tipLoadClosedForm();
  for (const auto& [label, mesh] : meshes) {
    const double delta = tipDeflection(mesh, selfWeight);
    const double error = (exact - delta) / exact;
    std::cout << "  " << (selfWeight ? "self-weight" : "tip load   ") << "  " << label << ": delta = " << delta
              << " m, closed form " << exact << " m, error " << 100 * error << " %\n";
    s.labels.push_back(label);
    s.errors.push_back(error);
  }
  return s;
}

/// The error shrinks with every refinement and stays positive (locking: too stiff, never too soft
/// by more than rounding).
void expectMonotone(const Series& s) {
  for (std::size_t i = 0; i < s.errors.size(); ++i) {
    EXPECT_GT(s.errors[i], -0.02) << s.labels[i] << ": softer than the beam by more than the 2 % that the clamp "
                                  << "and the Timoshenko approximation can explain";
    if (i > 0) EXPECT_LT(s.errors[i], s.errors[i - 1]) << s.labels[i] << " is not better than " << s.labels[i - 1];
  }
}

std::vector<std::pair<std::string, MeshSourceDesc>> barMeshes() {
  std::vector<std::pair<std::string, MeshSourceDesc>> meshes;
  for (const char* name : {"bar-186", "bar-651", "bar-2523", "bar-14114"})
    meshes.push_back({name, fileMesh(dataPath(std::string("meshes/ipc/") + name + ".msh"))});
  return meshes;
}

std::vector<std::pair<std::string, MeshSourceDesc>> boxMeshes() {
  std::vector<std::pair<std::string, MeshSourceDesc>> meshes;
  for (int n : {1, 2, 4}) {
    const std::array<int, 3> cells{20 * n, n, 2 * n};
    meshes.push_back({"box " + std::to_string(cells[0]) + "x" + std::to_string(cells[1]) + "x" +
                          std::to_string(cells[2]) + "x5",
                      boxMesh({0, 0, 0}, {kBarLength, kBarWidth, kBarHeight}, cells)});
  }
  return meshes;
}

TEST(LinearCantilever, TipLoadConvergesOnBarMeshes) {
  COROFEM_REQUIRE_DATA("meshes/ipc/bar-14114.msh");
  const Series s = run(barMeshes(), false);
  expectMonotone(s);
  // Measured (reference backend, Cholesky): 65 %, 40 %, 15 %, 5.6 % (tip load) and 66 %, 39 %, 15 %,
  // 5.9 % (self-weight). The unstructured bar meshes have 1-3 elements through the height, so the
  // locking error is large; the bounds leave ~1/3 headroom over the measurement: bar-2523 within
  // 20 %, bar-14114 within 8 %.
  EXPECT_LT(s.errors[2], 0.20) << "bar-2523";
  EXPECT_LT(s.errors[3], 0.08) << "bar-14114";
}

TEST(LinearCantilever, SelfWeightConvergesOnBarMeshes) {
  COROFEM_REQUIRE_DATA("meshes/ipc/bar-14114.msh");
  const Series s = run(barMeshes(), true);
  expectMonotone(s);
  // Measured (reference backend, Cholesky): 65 %, 40 %, 15 %, 5.6 % (tip load) and 66 %, 39 %, 15 %,
  // 5.9 % (self-weight). The unstructured bar meshes have 1-3 elements through the height, so the
  // locking error is large; the bounds leave ~1/3 headroom over the measurement: bar-2523 within
  // 20 %, bar-14114 within 8 %.
  EXPECT_LT(s.errors[2], 0.20) << "bar-2523";
  EXPECT_LT(s.errors[3], 0.08) << "bar-14114";
}

TEST(LinearCantilever, TipLoadConvergesOnGeneratedBoxes) {
  const Series s = run(boxMeshes(), false);
  expectMonotone(s);
  // Measured: 32 %, 11 %, 3.5 % (tip load) and 33 %, 12 %, 3.7 % (self-weight): the error falls
  // about 3x per halving of the cell size. The finest box (8 cells through the height) within 5 %.
  EXPECT_LT(s.errors.back(), 0.05) << "finest box";
}

TEST(LinearCantilever, SelfWeightConvergesOnGeneratedBoxes) {
  const Series s = run(boxMeshes(), true);
  expectMonotone(s);
  // Measured: 32 %, 11 %, 3.5 % (tip load) and 33 %, 12 %, 3.7 % (self-weight): the error falls
  // about 3x per halving of the cell size. The finest box (8 cells through the height) within 5 %.
  EXPECT_LT(s.errors.back(), 0.05) << "finest box";
}

}  // namespace
}  // namespace corofem
