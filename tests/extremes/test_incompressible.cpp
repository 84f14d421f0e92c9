// Nearly incompressible material: nu = 0.45, 0.49, 0.499, 0.4999 (lambda / mu = 2 nu / (1 - 2 nu)
// = 9, 49, 499, 4999). The static co-rotational cantilever (0.4 x 0.1 x 0.1 m, 160 tets, E = 1e6
// Pa, gravity) is solved with PCG under each preconditioner; the condition number of K grows
// like lambda / mu, so PCG needs more iterations, and linear tets lock (the deflection shrinks as
// nu -> 1/2; this is the element's known behaviour, not a solver failure). Required: every solve
// either converges or returns a clear SolveFailed status, and nothing is ever non-finite.
#include "extremes_support.hpp"

#include <cstdio>

namespace corofem::test {
namespace {

class Incompressible : public testing::TestWithParam<BackendCase> {};

BodyDesc cantileverOfPoissonRatio(double nu) {
  BodyDesc body = makeBody(box({0, 0, 0}, {0.4, 0.1, 0.1}, {8, 2, 2}), 1e6, nu);
  body.fixed.push_back(planeSet(0, 0.0));
  LoadDesc g;
  g.kind = LoadDesc::Kind::Gravity;
  g.vector = {0, -9.81, 0};
  body.loads.push_back(g);
  return body;
}

TEST_P(Incompressible, StaticSolveConvergesOrSaysSoForEveryPreconditioner) {
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  // Tip deflection at nu = 0.3 (same mesh, same backend): the nearly incompressible answers must
  // lie below it (linear tets lock: the volumetric constraint stiffens bending) and above 0.3 of
  // it (measured: 0.65 of it at nu = 0.4999 on this mesh; a much smaller value would mean a
  // solver that stopped early rather than locking).
  double tipAt03 = 0;
  {
    Scene scene = staticScene(c, cantileverOfPoissonRatio(0.3), 1);
    scene.solver.maxIterations = 20000;
    COROFEM_CREATE_SIM(sim, scene);
    const Status st = sim->step();
    ASSERT_TRUE(st) << st.message();
    std::vector<double> u = displacements(*sim);
    tipAt03 = maxAbs(u);
  }
  std::printf("  %s: max |u| at nu = 0.3: %.4e m\n", c.describe().c_str(), tipAt03);
  std::printf("  %-8s %-15s %-8s %7s %7s %11s %11s\n", "nu", "preconditioner", "status", "newton", "pcg", "residual",
              "max|u|/0.3");
  int solved = 0;
  for (double nu : {0.45, 0.49, 0.499, 0.4999}) {
    for (PreconditionerKind p :
         {PreconditionerKind::None, PreconditionerKind::Diagonal, PreconditionerKind::BlockDiagonal}) {
      // Float does not solve nu >= 0.499 here (it fails, clearly, after 30 Newton iterations in
      // every cut increment): on Vulkan, whose CI device is lavapipe, 13 s or more a solve (the
      // test took 38 to 45 s with the solves at 0.499 and 0.4999, 16 s with the first alone). There
      // one solve (nu = 0.499, diagonal) shows that path. OpenCL float (4 s for the whole table on
      // PoCL) runs them all.
      if (c.kind == BackendKind::Vulkan && c.isFloat() && nu >= 0.499 && (nu > 0.499 || p != PreconditionerKind::Diagonal))
        continue;
      Scene scene = staticScene(c, cantileverOfPoissonRatio(nu), 1);
      scene.solver.preconditioner = p;
      // Generous PCG cap: sqrt(cond) grows like sqrt(lambda / mu) ~ 70 at nu = 0.4999, times the
      // mesh's own ~50; 20000 leaves room, and a solve that still does not converge must say so.
      scene.solver.maxIterations = 20000;
      COROFEM_CREATE_SIM(sim, scene);
      StepReport report;
      const Status st = sim->step(&report);
      std::vector<double> x, v;
      ASSERT_TRUE(sim->readPositions(0, x));
      ASSERT_TRUE(sim->readVelocities(0, v));
      EXPECT_TRUE(allFinite(x) && allFinite(v)) << "non-finite output at nu = " << nu;
      const double tip = maxAbs(displacements(*sim));
      std::printf("  %-8g %-15s %-8s %7d %7d %11.3e %11.3f\n", nu, toString(p), st ? "ok" : "FAILED",
                  report.newtonIterations, report.linearIterations, report.residual, tip / tipAt03);
      if (!st) {
        EXPECT_EQ(st.code(), ErrorCode::SolveFailed) << st.message();
        EXPECT_FALSE(st.message().empty());
        EXPECT_EQ(x, sim->restMesh(0).nodes) << "a failed increment keeps the last good (rest) state";
        const bool floor = st.message().find("rounding floor") != std::string::npos;
        std::printf("      status: %s ...%s\n", st.message().substr(0, 160).c_str(),
                    floor ? " [diagnosed: residual at the rounding floor]" : "");
        continue;
      }
      ++solved;
      // Locking bounds (see above): stiffer than nu = 0.3, but not absurdly.
      EXPECT_LT(tip, 1.0 * tipAt03);
      EXPECT_GT(tip, 0.3 * tipAt03);
    }
  }
  // The double backends solve all twelve; float must solve at least the moderate ones (nu <= 0.49
  // with a preconditioner): below that it may legitimately report SolveFailed.
  EXPECT_GE(solved, c.isFloat() ? 4 : 12);
}

TEST_P(Incompressible, DynamicsStayFiniteAndBounded) {
  // Newmark (linearised, the paper's step) at nu = 0.4999 released under gravity: 30 steps at
  // 60 Hz. The volumetric modes are ~70x stiffer than the shear ones and far beyond 1/h; average
  // acceleration is unconditionally stable, so the motion must stay bounded by the static sag
  // scale (the runaway guard would report otherwise).
  const BackendCase& c = GetParam();
  COROFEM_SKIP_ABSENT(c);
  // Static sag at nu = 0.4999 on the reference backend (double): the scale of the motion.
  double sag = 0;
  {
    Scene scene = staticScene(backendCases()[0], cantileverOfPoissonRatio(0.4999), 1);
    scene.solver.maxIterations = 20000;
    COROFEM_CREATE_SIM(sim, scene);
    ASSERT_TRUE(sim->step());
    sag = maxAbs(displacements(*sim));
  }
  Scene scene = dynamicScene(c, cantileverOfPoissonRatio(0.4999), 1.0 / 60.0, 30);
  scene.solver.maxIterations = 20000;
  COROFEM_CREATE_SIM(sim, scene);
  double worst = 0;
  int linear = 0;
  while (!sim->finished()) {
    StepReport r;
    const Status st = sim->step(&r);
    ASSERT_TRUE(st) << st.message();
    linear += r.linearIterations;
    worst = std::max(worst, maxAbs(displacements(*sim)));
  }
  std::vector<double> v;
  ASSERT_TRUE(sim->readVelocities(0, v));
  EXPECT_TRUE(allFinite(v));
  std::printf("  %s: nu = 0.4999 Newmark 30 steps, %d PCG iterations, max |u| %.4e m\n", c.describe().c_str(), linear,
              worst);
  // Bound: twice the static sag is the undamped overshoot of a suddenly applied load (energy
  // 2x the static strain energy); the runaway guard allows 1.25x the energy given, i.e. sqrt(1.25)
  // more amplitude: 2.3 x sag. Measured: ~2.06 x sag (the linearised step adds a little).
  std::printf("  static sag at nu = 0.4999: %.4e m, dynamic max / sag = %.3f\n", sag, worst / sag);
  EXPECT_LT(worst, 2.3 * sag);
}

INSTANTIATE_TEST_SUITE_P(Backends, Incompressible, testing::ValuesIn(backendCases()), caseName);

}  // namespace
}  // namespace corofem::test
