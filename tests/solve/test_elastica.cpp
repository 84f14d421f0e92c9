// Large deflection of a slender cantilever under a dead tip load against the Euler elastica
// (../shared/data/references/cantilever_elastica.csv), co-rotational statics with load increments,
// and the rigorous nonlinear formulations (St. Venant-Kirchhoff, Neo-Hookean) as a cross-check.
//
// Beam: L = 1 along x, square section h = b = 0.05 (L/h = 20), nu = 0 (no plate/Poisson effect),
// clamped at x = 0, dead load P in -z spread over the nodes of the tip face.
//
// "Once the discretisation's own stiffness is accounted for": linear tetrahedra lock in bending,
// so the mesh is stiffer than E I. We calibrate EI_eff = P L^3 / (3 delta) from the same mesh's
// linear small-load tip deflection, then load to alpha_eff = P L^2 / EI_eff = 1 ... 10 and compare
// v/L (tip deflection along the load) and u/L (tip shortening along x) with the table.
#include "beam_helpers.hpp"
#include "common/test_data.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>

namespace corofem {
namespace {

using namespace corofem::test;

constexpr double kRodLength = 1.0, kRodSide = 0.05, kRodE = 1e7;

struct ElasticaRow {
  double v = 0, u = 0;
};

/// alpha -> (v/L, u/L) from the shared table.
std::map<double, ElasticaRow> readElastica() {
  std::map<double, ElasticaRow> table;
  std::ifstream in(dataPath("references/cantilever_elastica.csv"));
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> values;
    while (std::getline(ss, cell, ',')) values.push_back(std::stod(cell));
    if (values.size() >= 3) table[values[0]] = {values[1], values[2]};
  }
  return table;
}

MeshSourceDesc beamMesh() { return boxMesh({0, 0, 0}, {kRodLength, kRodSide, kRodSide}, {40, 2, 2}); }

BodyDesc beam(Formulation formulation, double load) {
  BodyDesc body = cantileverBody(beamMesh(), 0.0, kRodE, 0.0, 1000.0, formulation);
  body.loads.push_back(tipForce(kRodLength, {0, 0, -load}));
  return body;
}

/// EI_eff of the mesh from a linear solve under a small tip load.
double effectiveBendingStiffness() {
  const double load = 1e-3;
  auto sim = Simulation::create(staticScene(beam(Formulation::Linear, load), 1));
  if (!sim) {
    ADD_FAILURE() << sim.message();
    return NAN;
  }
  runToEnd(sim.value());
  const double delta = -meanDisplacement(sim.value(), planeX(kRodLength))[2];
  return load * std::pow(kRodLength, 3) / (3 * delta);
}

struct Curve {
  std::vector<double> alpha, v, u;  // per increment
};

/// Loads to alpha_eff = alphaMax in `increments` equal increments and records the tip after each.
Curve loadCurve(Formulation formulation, double eiEff, double alphaMax, int increments) {
  Curve c;
  Scene scene = staticScene(beam(formulation, alphaMax * eiEff / (kRodLength * kRodLength)), increments);
  scene.analysis.statics.maxNewtonIterations = 60;
  auto sim = Simulation::create(scene);
  if (!sim) {
    ADD_FAILURE() << sim.message();
    return c;
  }
  int totalNewton = 0;
  while (!sim->finished()) {
    StepReport report;
    Status st = sim->step(&report);
    if (!st) {
      ADD_FAILURE() << toString(formulation) << ": " << st.message();
      return c;
    }
    totalNewton += report.newtonIterations;
    const Vec3 tip = meanDisplacement(sim.value(), planeX(kRodLength));
    c.alpha.push_back(alphaMax * report.time);
    c.v.push_back(-tip[2] / kRodLength);
    c.u.push_back(-tip[0] / kRodLength);
  }
  std::cout << "  " << toString(formulation) << ": " << totalNewton << " Newton iterations over " << increments
            << " increments\n";
  return c;
}

TEST(Elastica, CorotationalFollowsTheElasticaWithCalibratedStiffness) {
  COROFEM_REQUIRE_DATA("references/cantilever_elastica.csv");
  const auto table = readElastica();
  const double ei = kRodE * std::pow(kRodSide, 4) / 12.0;
  const double eiEff = effectiveBendingStiffness();
  std::cout << "  EI_eff / EI = " << eiEff / ei << " (locking of the 40x2x2x5 mesh)\n";
  const Curve co = loadCurve(Formulation::Corotational, eiEff, 10.0, 10);
  ASSERT_EQ(co.alpha.size(), 10u);
  double worstV = 0, worstU = 0;
  for (std::size_t i = 0; i < co.alpha.size(); ++i) {
    const double alpha = std::round(co.alpha[i]);
    const ElasticaRow& ref = table.at(alpha);
    const double ev = co.v[i] - ref.v, eu = co.u[i] - ref.u;
    std::cout << "  alpha_eff " << alpha << ": v/L " << co.v[i] << " (elastica " << ref.v << ", diff " << ev
              << "), u/L " << co.u[i] << " (elastica " << ref.u << ", diff " << eu << ")\n";
    worstV = std::max(worstV, std::abs(ev));
    worstU = std::max(worstU, std::abs(eu));
  }
  std::cout << "  worst |v/L - elastica| " << worstV << ", worst |u/L - elastica| " << worstU << "\n";
  // Measured (40x2x2x5 box, Cholesky, residual tolerance 1e-6): worst 0.0040 in v/L and 0.00085 in
  // u/L, both at alpha_eff = 10, growing steadily with alpha (the calibration captures the locking
  // at small strain; at large rotation a little of it changes with the element orientation). The
  // bounds are twice the measurement: without the calibration (alpha from the beam's EI, 1.56x
  // smaller) v/L at the last increment would be off by ~0.07, so the test still discriminates.
  EXPECT_LT(worstV, 0.008);
  EXPECT_LT(worstU, 0.002);
}

TEST(Elastica, RigorousNonlinearFormulationsAgree) {
  COROFEM_REQUIRE_DATA("references/cantilever_elastica.csv");
  const auto table = readElastica();
  const double eiEff = effectiveBendingStiffness();
  const Curve co = loadCurve(Formulation::Corotational, eiEff, 10.0, 10);
  for (Formulation f : {Formulation::StVenantKirchhoff, Formulation::NeoHookean}) {
    const Curve c = loadCurve(f, eiEff, 10.0, 10);
    ASSERT_EQ(c.alpha.size(), co.alpha.size()) << toString(f);
    double worst = 0;
    for (std::size_t i = 0; i < c.alpha.size(); ++i) {
      const ElasticaRow& ref = table.at(std::round(c.alpha[i]));
      std::cout << "  " << toString(f) << " alpha_eff " << c.alpha[i] << ": v/L " << c.v[i] << " (co-rot " << co.v[i]
                << ", elastica " << ref.v << "), u/L " << c.u[i] << " (co-rot " << co.u[i] << ", elastica "
                << ref.u << ")\n";
      worst = std::max({worst, std::abs(c.v[i] - co.v[i]), std::abs(c.u[i] - co.u[i])});
    }
    std::cout << "  " << toString(f) << ": worst difference from co-rotational " << worst << "\n";
    // Measured: St. Venant-Kirchhoff within 0.0024 of the co-rotational curve, Neo-Hookean within
    // 0.0004 (the strains stay small, where the three constitutive laws nearly coincide; the larger
    // StVK gap was not investigated further). Bound 0.005 of L, and each within 0.01 of the table.
    EXPECT_LT(worst, 0.005) << toString(f);
    for (std::size_t i = 0; i < c.alpha.size(); ++i) {
      const ElasticaRow& ref = table.at(std::round(c.alpha[i]));
      EXPECT_LT(std::abs(c.v[i] - ref.v), 0.01) << toString(f) << " alpha " << c.alpha[i];
      EXPECT_LT(std::abs(c.u[i] - ref.u), 0.01) << toString(f) << " alpha " << c.alpha[i];
    }
  }
}

}  // namespace
}  // namespace corofem
