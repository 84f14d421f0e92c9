// Conformance, whole steps and determinism: small scenes (the scheduler tests' box beam,
// schedule/schedule_support.hpp) run by a Simulation on the case's device
// (SimulationOptions::devices = {"<backend>:<selector>"}) and on the reference backend, dynamic
// (Newmark, two bodies in one batch) and static (Newton); and the same run twice on the device,
// bit for bit, through a Simulation and through the device interface.
#include "conformance/conformance_support.hpp"
#include "model/problem.hpp"
#include "schedule/schedule_support.hpp"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <cstdio>

namespace corofem::test {
namespace {

class ConformanceSteps : public ConformanceBase {
 protected:
  /// Two bodies: the co-rotational box beam (240 elements) with Rayleigh damping and a smaller
  /// linear one (100 elements) beside it, both clamped at x = 0 under gravity and a tip force.
  Scene dynamicTwoBodies() const {
    BodyDesc beam = boxBeam({12, 2, 2});
    beam.material.rayleighMass = 0.5;
    beam.material.rayleighStiffness = 0.002;
    BodyDesc bar = boxBeam({5, 2, 2});
    bar.name = "linear-bar";
    bar.formulation = Formulation::Linear;
    bar.material.youngsModulus = 1.5e6;
    bar.material.poissonRatio = 0.3;
    bar.material.density = 800.0;
    bar.mesh.box->min = {0.0, 0.0, 0.5};
    bar.mesh.box->max = {0.6, 0.1, 0.6};
    bar.fixed[0].planePoint = {0, 0, 0};
    bar.loads[1].nodes.planePoint = {0.6, 0, 0};
    Scene s = dynamicScene(beam, 10);
    s.bodies.push_back(bar);
    return withSolver(s);
  }
  /// A compact block (0.2 m cube, 4 x 4 x 4 cells, 320 elements) clamped at z = 0 under gravity and
  /// 1.1 kN spread over its top, pressing and shearing it (strains of a few %). Compact and heavily
  /// loaded, so that float resolves its equilibrium: the rounding of the positions (u_f |x - c| ~
  /// 6e-9 m) moves a node's force by ~E h u_f |x - c| ~ 3e-4 N against ~40 N of load per top node,
  /// ~1e-5 relative. (A slender soft beam's float forces stall at a relative residual of ~1e-2:
  /// the library then fails the increment and says so, a limit of float statics, not of a backend.)
  Scene staticBlock() const {
    BodyDesc block = boxBeam();
    block.name = "block";
    block.mesh.box->max = {0.2, 0.2, 0.2};
    block.mesh.box->cells = {4, 4, 4};
    block.fixed[0].planeNormal = {0, 0, 1};
    block.loads[1].vector = {300.0, -200.0, -1000.0};
    block.loads[1].nodes.planeNormal = {0, 0, 1};
    block.loads[1].nodes.planePoint = {0, 0, 0.2};
    Scene s = staticScene(block, 2);
    // Newton's own tolerances: double to 1e-8 of the forces; float to its operator's accuracy
    // (kOpFloat: a tighter test would chase the rounding of the float forces).
    s.analysis.statics.residualTolerance = isDouble() ? 1e-8 : kOpFloat;
    s.analysis.statics.displacementTolerance = isDouble() ? 1e-8 : kOpFloat;
    return withSolver(s);
  }
  Scene withSolver(Scene s) const {
    s.solver.precision = GetParam().precision;
    s.solver.preconditioner = PreconditionerKind::BlockDiagonal;
    s.solver.tolerance = solver().tolerance;
    s.solver.maxIterations = 5000;
    s.output.vtk = false;
    return s;
  }

  /// The scene on `device` ("reference" or the case's request), checked to run there (the
  /// reference backend is every order's last fallback: a device that failed would hand its bodies
  /// to it and the comparison would pass for nothing).
  std::unique_ptr<Simulation> simulate(const Scene& scene, const std::string& device) const {
    SimulationOptions o;
    o.devices = {device};
    o.opencl = morton();
    Result<Simulation> sim = Simulation::create(scene, o);
    if (!sim) {
      ADD_FAILURE() << device << ": " << sim.message();
      return nullptr;
    }
    auto out = std::make_unique<Simulation>(std::move(sim.value()));
    const nlohmann::json report = nlohmann::json::parse(out->schedulerReport());
    const std::string prefix = device == "reference" ? "reference" : device + " (";
    for (const auto& body : report["bodies"])
      EXPECT_EQ(body["current"].get<std::string>().rfind(prefix, 0), 0u) << report.dump();
    return out;
  }

  /// Positions and velocities of every body after every step.
  struct Run {
    std::vector<std::vector<std::vector<double>>> x, v;  ///< [step][body]
    std::vector<StepReport> reports;
  };
  static Run runAll(Simulation& sim) {
    Run r;
    while (!sim.finished()) {
      StepReport rep;
      const Status st = sim.step(&rep);
      EXPECT_TRUE(st) << st.message();
      if (!st) break;
      r.reports.push_back(rep);
      r.x.emplace_back(static_cast<std::size_t>(sim.bodyCount()));
      r.v.emplace_back(static_cast<std::size_t>(sim.bodyCount()));
      for (int b = 0; b < sim.bodyCount(); ++b) {
        EXPECT_TRUE(sim.readPositions(b, r.x.back()[static_cast<std::size_t>(b)]));
        EXPECT_TRUE(sim.readVelocities(b, r.v.back()[static_cast<std::size_t>(b)]));
      }
    }
    return r;
  }
  static Eigen::VectorXd vec(const std::vector<double>& v) {
    return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
  }
};

TEST_P(ConformanceSteps, DynamicStepsMatchTheReference) {
  // The bound, per body, first-order in the differences of each Newton solve of the velocity
  // update A dv = -r / ka, A = M + h gamma C + h^2 beta K_t (dynamics.cpp; ka = 1 / (h gamma),
  // kx = h beta / gamma): the device's dv differs from the reference's by at most
  //   kappa(A) (2 tau + eps_A) |dv|                        (residuals to tau each side, and the
  //                                                          device's product off by eps_A)
  // + h gamma eps_op sqrt(n) max|f_int| / lambda_min(A)     (its forces, in r, off by eps_op of
  //                                                          their largest entry, on n free dofs)
  // with |dv| <= |v_{n+1} - v_n| per step (each of the `newton` solves corrects the same step).
  // A velocity error at step n moves the positions by kx dv at once and by (T - t_{n+1}) dv by the
  // end (T = 0.1 s: far below the bodies' periods, so nothing oscillates back). The bound is
  // ~8 kappa(A) (2 tau + eps_A) of the motion: meaningful where kappa(A) tau is small (float: tau =
  // 1e-5, so these bodies keep kappa(A) below ~300: a soft beam and a soft bar). Spectra from the
  // reference at rest (a factor 2 on each for their estimates); v and f_int (at x) from the
  // reference's run.
  const Scene scene = dynamicTwoBodies();
  const auto ref = simulate(scene, "reference");
  const auto dev = simulate(scene, GetParam().request());
  ASSERT_TRUE(ref && dev);
  const Run want = runAll(*ref), got = runAll(*dev);
  ASSERT_EQ(got.x.size(), want.x.size());
  ASSERT_EQ(want.x.size(), 10u);
  const auto& d = scene.analysis.dynamics;
  const double h = d.timeStep, kx = h * d.newmarkBeta / d.newmarkGamma, T = h * static_cast<double>(want.x.size());
  const double tau = scene.solver.tolerance, eps = opTolerance();
  for (int body = 0; body < ref->bodyCount(); ++body) {
    const std::size_t bi = static_cast<std::size_t>(body);
    const detail::Problem p = detail::buildProblem(scene.bodies[bi], ref->restMesh(body), scene.solver, scene.baseDir);
    auto reference = makeReference({&p}, solver());
    const Spectrum a = spectrum(*reference, 0, {1.0, h * d.newmarkGamma, h * h * d.newmarkBeta});
    const double rootN = std::sqrt(static_cast<double>(freeCount(p)));
    double bound = 0.0;
    Eigen::VectorXd vPrev = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(p.dofCount())), f;
    for (std::size_t n = 0; n < want.x.size(); ++n) {
      const Eigen::VectorXd v = vec(want.v[n][bi]), x = vec(want.x[n][bi]);
      reference->setPositions({0}, {&x});
      reference->internalForces({0}, {&f});
      const double forces = freeOnly(p, f).cwiseAbs().maxCoeff();
      const double dv = d.newtonIterations * (2.0 * a.kappa() * (2.0 * tau + productTolerance()) * (v - vPrev).norm() +
                                              h * d.newmarkGamma * eps * rootN * forces / (0.5 * a.lambdaMin));
      bound += (kx + T - h * static_cast<double>(n + 1)) * dv;
      vPrev = v;
    }
    const Eigen::VectorXd xr = vec(want.x.back()[bi]), xd = vec(got.x.back()[bi]);
    const double moved = (xr - p.restPositions).norm();
    std::printf("[info] %s: |x - x_ref| = %.2e m after %zu steps (bound %.2e, displacement %.2e; kappa(A) %.1e)\n",
                p.name.c_str(), (xd - xr).norm(), want.x.size(), bound, moved, a.kappa());
    EXPECT_GT(moved, 0.0);
    EXPECT_LE((xd - xr).norm(), bound) << p.name;
    EXPECT_LT(bound, 0.1 * moved) << p.name << ": a bound this loose would test nothing";
  }
  for (std::size_t n = 0; n < got.reports.size(); ++n) EXPECT_TRUE(got.reports[n].converged) << "step " << n + 1;
}

TEST_P(ConformanceSteps, StaticIncrementsMatchTheReference) {
  // Both runs end each increment at a relative residual |f_ext - f_int| <= tol_N max(|f_ext|,
  // |f_int|) of their own forces; the device's forces are off by eps_op of their largest entry
  // (<= eps_op sqrt(n) max|f_int| in the 2-norm, n free dofs). Two states whose true residuals are r_1,
  // r_2 differ by at most |K_t^-1| (|r_1| + |r_2|) = (|r_1| + |r_2|) / lambda_min(K_t), K_t at
  // the reference's final state (a factor 2 for the spectrum's estimates).
  const Scene scene = staticBlock();
  const auto ref = simulate(scene, "reference");
  const auto dev = simulate(scene, GetParam().request());
  ASSERT_TRUE(ref && dev);
  const Run want = runAll(*ref), got = runAll(*dev);
  ASSERT_EQ(got.x.size(), want.x.size());
  const detail::Problem p = detail::buildProblem(scene.bodies[0], ref->restMesh(0), scene.solver, scene.baseDir);
  auto reference = makeReference({&p}, solver());
  const Eigen::VectorXd xr = vec(want.x.back()[0]), xd = vec(got.x.back()[0]);
  reference->setPositions({0}, {&xr});
  const Spectrum k = spectrum(*reference, 0, {0.0, 0.0, 1.0});
  const double fext = freeOnly(p, p.externalForce(1.0, false)).norm();
  const double tolN = scene.analysis.statics.residualTolerance;
  const double u = (xr - p.restPositions).norm();
  Eigen::VectorXd f;
  reference->internalForces({0}, {&f});
  const double scale = std::max(fext, freeOnly(p, f).norm()), forces = freeOnly(p, f).cwiseAbs().maxCoeff();
  const double bound =
      2.0 * (2.0 * tolN * scale + opTolerance() * std::sqrt(static_cast<double>(freeCount(p))) * forces) / k.lambdaMin;
  std::printf("[info] static block: |x - x_ref| = %.2e m (bound %.2e, displacement %.2e; kappa(K_t) %.1e)\n",
              (xd - xr).norm(), bound, u, k.kappa());
  EXPECT_LE((xd - xr).norm(), bound);
  EXPECT_LT(bound, 0.1 * u) << "a bound this loose would test nothing";
  for (const StepReport& r : got.reports) EXPECT_TRUE(r.converged) << "increment " << r.step;
}

TEST_P(ConformanceSteps, TheSameRunTwiceGivesTheSameBits) {
  // A Simulation twice on the device: every body's positions and velocities after every step, and
  // the steps' reports, bit for bit.
  const Scene scene = dynamicTwoBodies();
  const auto first = simulate(scene, GetParam().request());
  const auto second = simulate(scene, GetParam().request());
  ASSERT_TRUE(first && second);
  const Run a = runAll(*first), b = runAll(*second);
  ASSERT_EQ(a.x.size(), b.x.size());
  for (std::size_t n = 0; n < a.x.size(); ++n) {
    for (std::size_t body = 0; body < a.x[n].size(); ++body) {
      EXPECT_EQ(a.x[n][body], b.x[n][body]) << "step " << n + 1 << ", body " << body;
      EXPECT_EQ(a.v[n][body], b.v[n][body]) << "step " << n + 1 << ", body " << body;
    }
    EXPECT_EQ(a.reports[n].linearIterations, b.reports[n].linearIterations) << "step " << n + 1;
    EXPECT_EQ(a.reports[n].linearResidual, b.reports[n].linearResidual) << "step " << n + 1;
    EXPECT_EQ(a.reports[n].residual, b.reports[n].residual) << "step " << n + 1;
  }
}

TEST_P(ConformanceSteps, TheSameCallsTwiceGiveTheSameBits) {
  // The suite's bodies on two devices of the case, and the first again: positions, forces,
  // energies, products and a solve of every body at once, bit for bit.
  struct Answers {
    std::vector<Eigen::VectorXd> f, y, x;
    std::vector<double> energy;
    std::vector<int> iterations;
  };
  const detail::BodySet all = detail::allBodies(count());
  auto run = [&](detail::Device& dev) {
    Answers a;
    std::vector<Eigen::VectorXd> pos(count()), p(count()), b(count()), zero(count());
    detail::ConstVectors xs, ps;
    detail::Vectors fs, ys;
    std::vector<detail::SystemCoeffs> c;
    a.f.resize(count());
    a.y.resize(count());
    for (std::size_t i = 0; i < count(); ++i) {
      pos[i] = randomPositions(problem(i), 1000 + static_cast<unsigned>(i));
      p[i] = randomVector(problem(i).dofCount(), 1100 + static_cast<unsigned>(i));
      b[i] = randomVector(problem(i).dofCount(), 1200 + static_cast<unsigned>(i));
      zero[i] = Eigen::VectorXd::Zero(b[i].size());
      xs.push_back(&pos[i]);
      ps.push_back(&p[i]);
      fs.push_back(&a.f[i]);
      ys.push_back(&a.y[i]);
      c.push_back(bodies()[i].solve);
    }
    dev.setPositions(all, xs);
    dev.internalForces(all, fs);
    dev.elasticEnergy(all, a.energy);
    dev.apply(all, c, ps, ys);
    const SetSolve s = solveSet(dev, all, b, zero, solver(), c);
    a.x = s.x;
    for (const detail::PcgSolve& one : s.solves) a.iterations.push_back(one.stats.iterations);
    return a;
  };
  std::unique_ptr<detail::Device> other = makeDevice(problemsOf(bodies()), solver());
  const Answers first = run(device()), second = run(*other), again = run(device());
  for (const Answers* k : {&second, &again}) {
    const char* what = k == &second ? "another device" : "the same device again";
    for (std::size_t i = 0; i < count(); ++i) {
      EXPECT_TRUE(sameBits(k->f[i], first.f[i])) << what << ", " << problem(i).name << ": forces";
      EXPECT_TRUE(sameBits(k->y[i], first.y[i])) << what << ", " << problem(i).name << ": product";
      EXPECT_TRUE(sameBits(k->x[i], first.x[i])) << what << ", " << problem(i).name << ": solution";
      EXPECT_EQ(k->energy[i], first.energy[i]) << what << ", " << problem(i).name;
      EXPECT_EQ(k->iterations[i], first.iterations[i]) << what << ", " << problem(i).name;
    }
  }
}

COROFEM_CONFORMANCE_SUITE(ConformanceSteps);

}  // namespace
}  // namespace corofem::test
