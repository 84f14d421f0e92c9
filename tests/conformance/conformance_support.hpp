// The conformance suite: every candidate device of every registered backend other than the
// reference one (device/registry.hpp: today OpenCL's devices, later Vulkan's or an embedder's),
// in double and in float, against the reference device (backends/reference: Eigen, double, the
// same single-reduction PCG on the same projected system) holding the same problems. Devices are
// made only through the registry entries' `create`, with the OpenCL tuning of the run
// (test::morton(): the Morton order under --corofem_morton), so a new backend is tested by
// registering it; nothing here names a backend other than "reference".
//
// Tolerances (derived here, used by every test of the suite; the measured values are printed by
// the tests that use them):
//
// Element operations (forces, energy), relative to the largest entry of the reference's answer
// (the energy relative to itself). Both sides evaluate the same element formulas; they
// differ by (a) the summation order of the per-node gathers (at most ~24 elements per node here:
// gamma_24 = 24 u relative to the sum of the magnitudes) and (b) the rotations: the reference takes
// the polar factor from an SVD, a device from an iteration that stops at its own test (kernels:
// the last Newton step below sqrt(3 eps), so the factor is good to a few eps), and the forces
// K (R^T x - X) lose |x - c| / |u| of that to the cancellation of the rigid part (c: the body's
// centroid; u: the strain-producing displacement). The deformations below (randomPositions) keep
// strains of a few % on elements of size h in bodies of size L <= ~30 h, so |x - c| / |u| <= ~30-600.
//   double: u = 1.1e-16, 600 x ~10 roundings x u ~ 1e-12; kOpDouble = 1e-10 leaves a factor 100.
//   float: the device rounds x - c to float (u = 6e-8): 30 x 6e-8 = 2e-6 on the strains of the most
//     stressed elements (those set the largest entry), ~10 float operations per entry (rotation,
//     12 x 12 product, rotation back, gather) ~ 2e-5; kOpFloat = 1e-4 leaves a factor 5. The
//     OpenCL tests use the same two numbers (tests/opencl/test_kernels.cpp).
// Products y = A p alone have no rigid part to cancel (p is no position): the rotation of p, the
// 12 x 12 product, the rotation back and the gather make ~50 roundings per entry (gamma_50 = 50 u
// relative to the sum of the magnitudes), and the rotations themselves carry the positions'
// rounding over an element, u |x - c| / h <= ~10 u here: ~70 u, relative to the largest entry.
//   double: 70 x 1.1e-16 ~ 1e-14; kProductDouble = 1e-13. float: 70 x 6e-8 = 4e-6; kProductFloat = 1e-5.
//
// PCG. Both sides run the same iteration to the same relative tolerance tau of the recurrence
// residual (double: tau = 1e-10; float: 1e-5, above what float resolves on these systems, a few
// eps_float times their effective condition). The checks, with A the reference's matrix (double)
// on the free dofs, lambda_max / lambda_min its extreme eigenvalues (estimated by power and
// inverse iteration on the reference device, `spectrum`), kappa = lambda_max / lambda_min:
//  - true residual |b - A x| / |b| of the device's x, computed by the reference in double: the
//      device stops when its recurrence residual is <= tau; the true one differs from it by the
//      attainable accuracy of CG in finite precision (Greenbaum 1997: the gap grows like
//      u sum_j (|A| |x_j| + |r_j|) over the k iterations, |r_0| <= |b| + |A| |x_0|), with 64
//      roundings in one product A p (the operator's own error, as above) and b itself rounded:
//        <= tau + (64 + k) u (1 + lambda_max (|x_ref| + 2 |x_0|) / |b|),  u the device's unit
//      roundoff (double: a few 1e-11 here, so ~tau; float: up to ~1e-3 for kappa ~1e4).
//  - the device's reported residual (its own b - A x after the solve) against that true residual:
//      |reported - true| <= 64 u (1 + lambda_max |x| / |b|) (one product and one subtraction in
//      the device's precision).
//  - the solution against the reference's PCG solution: |x - x_ref| / |x_ref| <=
//      2 kappa (res_dev + res_ref), res the true residuals: x - x_ref = A^-1 (r_ref - r_dev), and
//      |A^-1| |b| / |x_ref| <= kappa; the factor 2 covers the spectrum estimate (power iteration
//      approaches lambda_max from below, inverse iteration lambda_min from above).
//  - iteration counts: exact arithmetic gives both sides the same count; rounding moves the
//      crossing of tau. Double: the two recurrences differ by ~eps kappa per iteration, far below
//      the per-iteration reduction, so a crossing moves by at most one iteration, except where the
//      (non-monotone) residual stalls near tau: |k - k_ref| <= 1 + k_ref / 50. Float: finite
//      precision CG loses orthogonality, which delays convergence by a fraction of the iterations
//      that grows with the condition number (Greenbaum & Strakos 1992): |k - k_ref| <= 2 + k_ref / 4;
//      and where the reference stopped by CG's finite termination (k_ref >= the free dofs: a
//      system of a few dofs), which float loses, float may take up to the count of the rate bound
//      that finite-precision CG still obeys (Greenbaum 1989): |r_k| / |b| <= 2 sqrt(kappa)
//      ((sqrt(kappa) - 1) / (sqrt(kappa) + 1))^k, i.e. k <= sqrt(kappa) / 2 ln(2 sqrt(kappa) / tau),
//      kappa(A) standing in for the preconditioned system's (which the interface does not expose;
//      the diagonal and node-block scalings here lower it: their counts are below those without).
#pragma once

#include "common/morton.hpp"
#include "common/test_problems.hpp"
#include "device/registry.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <memory>
#include <ostream>
#include <random>
#include <string>
#include <vector>

namespace corofem::test {

/// One device the suite runs: a candidate of a registered backend, in one precision.
struct ConformanceCase {
  std::string backend;   ///< the registry's name
  std::string selector;  ///< the candidate's selector (Candidate::selector)
  std::string device;    ///< the candidate's device name
  Precision precision = Precision::Double;
  std::string name;  ///< test-name suffix
  /// What SimulationOptions::devices calls it.
  std::string request() const { return backend + ":" + selector; }
  std::string describe() const {
    return backend + ":" + selector + " (" + device + ", " + (precision == Precision::Double ? "double" : "float") +
           ")";
  }
};

inline void PrintTo(const ConformanceCase& c, std::ostream* os) { *os << c.describe(); }

inline std::string identifier(const std::string& text, std::size_t length) {
  std::string out;
  for (char c : text) out += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return out.substr(0, length);
}

/// The backends under test, each with why it lists no candidate (empty when it lists some).
struct RegisteredBackend {
  std::string name;
  std::vector<detail::Candidate> candidates;
  std::string error;  ///< candidates() threw this
};

inline std::vector<RegisteredBackend> backendsUnderTest() {
  std::vector<RegisteredBackend> out;
  for (const detail::BackendEntry& e : detail::registeredBackends()) {
    if (e.name == "reference") continue;
    RegisteredBackend b;
    b.name = e.name;
    try {
      b.candidates = e.candidates();
    } catch (const std::exception& ex) {
      b.error = ex.what();
    }
    out.push_back(std::move(b));
  }
  return out;
}

/// Every candidate of every registered backend but the reference one, in double and in float.
inline std::vector<ConformanceCase> conformanceCases() {
  std::vector<ConformanceCase> out;
  for (const RegisteredBackend& b : backendsUnderTest())
    for (const detail::Candidate& c : b.candidates)
      for (Precision p : {Precision::Double, Precision::Float}) {
        ConformanceCase k{b.name, c.selector, c.device, p, ""};
        k.name = identifier(b.name, 16) + "_" + identifier(c.selector, 8) + "_" + identifier(c.device, 24) +
                 (p == Precision::Double ? "_double" : "_float");
        // Unique, as GoogleTest requires (two devices may share a name, or a selector its prefix).
        const std::string base = k.name;
        auto taken = [&] {
          return std::any_of(out.begin(), out.end(), [&](const ConformanceCase& o) { return o.name == k.name; });
        };
        for (int n = 2; taken(); ++n) k.name = base + "_" + std::to_string(n);
        out.push_back(k);
      }
  return out;
}

inline std::string caseName(const testing::TestParamInfo<ConformanceCase>& info) { return info.param.name; }

// ------------------------------------------------------------------------------------ tolerances

constexpr double kUnitDouble = 1.1102230246251565e-16;  ///< unit roundoff of double
constexpr double kUnitFloat = 5.9604644775390625e-08;   ///< unit roundoff of float
constexpr double kOpDouble = 1e-10;                     ///< element operations (see above)
constexpr double kOpFloat = 1e-4;
constexpr double kProductDouble = 1e-13;                ///< products alone (see above)
constexpr double kProductFloat = 1e-5;

// ---------------------------------------------------------------------------------- the bodies

/// A body of the suite: its problem and the system its solves use (dynamic where it is held only
/// by its mass or by too few constraints, static where it is clamped).
struct Body {
  detail::Problem problem;
  detail::SystemCoeffs solve;
};

/// Seven bodies of different sizes (1 to 2,970 elements; element and node counts that are not
/// multiples of 8, 32 or 64, or odd), materials, densities, Rayleigh coefficients, constraints
/// (none, 3-2-1, two components of a face, a clamped face) and one linear formulation.
inline const std::vector<Body>& suiteBodies() {
  static const std::vector<Body> bodies = [] {
    std::vector<Body> out;
    auto clampBelow = [](detail::Problem& p, int axis, double limit, int components) {
      for (std::size_t n = 0; n < p.mesh.nodeCount(); ++n)
        if (p.mesh.nodes[3 * n + axis] < limit)
          for (int k = 0; k < components; ++k) p.constrained[3 * n + k] = 1;
    };
    std::mt19937 rng(2024);
    {  // 0: one element (4 nodes) held 3-2-1: node 0 fixed, node 1 in y and z, node 2 in z; static
      detail::Problem p = makeProblem(randomSoup(1, rng), 2e5, 0.25, 900.0);
      p.name = "single-element";
      for (int d : {0, 1, 2, 4, 5, 8}) p.constrained[static_cast<std::size_t>(d)] = 1;
      out.push_back({std::move(p), {0.0, 0.0, 1.0}});
    }
    {  // 1: a handful (5 free elements, 20 nodes), both Rayleigh terms; dynamic
      detail::Problem p = makeProblem(randomSoup(5, rng), 5e4, 0.35, 1100.0);
      p.name = "handful";
      p.rayleighMass = 0.3;
      p.rayleighStiffness = 0.005;
      out.push_back({std::move(p), {14400.0, 120.0, 1.0}});
    }
    {  // 2: 37 free elements (148 nodes), mass damping; dynamic
      detail::Problem p = makeProblem(randomSoup(37, rng), 2e4, 0.2, 1500.0);
      p.name = "soup";
      p.rayleighMass = 0.05;
      out.push_back({std::move(p), {900.0, 30.0, 1.0}});
    }
    {  // 3: linear formulation, 108 elements, 48 nodes, clamped at x = 0, mass damping; static
      detail::Problem p = makeProblem(cellBox(3, 3, 2, 0.1, 0.1, 0.1), 1e6, 0.35, 800.0, Formulation::Linear);
      p.name = "linear-cube";
      p.rayleighMass = 0.1;
      clampBelow(p, 0, 1e-9, 3);
      out.push_back({std::move(p), {0.0, 0.0, 1.0}});
    }
    {  // 4: a stiff light slab, 144 elements, 63 nodes, x and y held on z = 0; dynamic
      detail::Problem p = makeProblem(cellBox(6, 2, 2, 0.2, 0.3, 0.05), 3e6, 0.3, 500.0);
      p.name = "slab";
      clampBelow(p, 2, 1e-9, 2);
      out.push_back({std::move(p), {3600.0, 60.0, 1.0}});
    }
    {  // 5: a nearly incompressible beam, 540 elements, 176 nodes, clamped at x = 0, both Rayleigh
       // terms; dynamic
      detail::Problem p = makeProblem(cellBox(10, 3, 3, 0.2, 0.1, 0.1), 1e5, 0.45, 1000.0);
      p.name = "beam";
      p.rayleighMass = 0.2;
      p.rayleighStiffness = 0.01;
      clampBelow(p, 0, 1e-9, 3);
      out.push_back({std::move(p), {14400.0, 120.0, 1.0}});
    }
    {  // 6: a block of 2,970 elements, 720 nodes, clamped at x = 0, stiffness damping; static
      detail::Problem p = makeProblem(cellBox(11, 9, 5, 0.1, 0.1, 0.1), 5e5, 0.3, 1200.0);
      p.name = "block";
      p.rayleighStiffness = 0.02;
      clampBelow(p, 0, 1e-9, 3);
      out.push_back({std::move(p), {0.0, 0.0, 1.0}});
    }
    return out;
  }();
  return bodies;
}

inline std::vector<const detail::Problem*> problemsOf(const std::vector<Body>& bodies) {
  std::vector<const detail::Problem*> out;
  for (const Body& b : bodies) out.push_back(&b.problem);
  return out;
}

/// Random positions of a body: its rest shape bent smoothly (strains of a few %), jittered per node
/// (~1 % of the body's size over its element count's cube root, i.e. of an element), rotated by a
/// random rotation and moved by up to its size. Never the rest shape, never zero.
inline Eigen::VectorXd randomPositions(const detail::Problem& p, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::size_t n = p.mesh.nodeCount();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (std::size_t i = 0; i < n; ++i) {
    lo = lo.cwiseMin(p.restPositions.segment<3>(3 * i));
    hi = hi.cwiseMax(p.restPositions.segment<3>(3 * i));
  }
  const double L = (hi - lo).norm();
  const double h = L / std::cbrt(static_cast<double>(std::max<std::size_t>(1, p.mesh.tetCount())));
  const Eigen::Matrix3d R = randomRotation(rng);
  const Eigen::Vector3d t(L * u(rng), L * u(rng), L * u(rng));
  const Eigen::Vector3d phase(3 * u(rng), 3 * u(rng), 3 * u(rng));
  Eigen::VectorXd x(static_cast<Eigen::Index>(3 * n));
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d X = p.restPositions.segment<3>(3 * i);
    const Eigen::Vector3d s = (X - lo) / L * 2.0 * M_PI;
    const Eigen::Vector3d bend(std::sin(s.y() + phase.x()), std::sin(s.z() + phase.y()), std::sin(s.x() + phase.z()));
    const Eigen::Vector3d jitter(u(rng), u(rng), u(rng));
    x.segment<3>(3 * i) = R * (X + 0.02 * L * bend + 0.01 * h * jitter) + t;
  }
  return x;
}

/// The free dofs of v (constrained entries zeroed).
inline Eigen::VectorXd freeOnly(const detail::Problem& p, Eigen::VectorXd v) {
  for (std::size_t d = 0; d < p.dofCount(); ++d)
    if (p.constrained[d]) v[static_cast<Eigen::Index>(d)] = 0.0;
  return v;
}

inline std::size_t freeCount(const detail::Problem& p) {
  return static_cast<std::size_t>(std::count(p.constrained.begin(), p.constrained.end(), 0));
}

/// max |a - b| / max |b|.
inline double maxRel(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(b.cwiseAbs().maxCoeff(), 1e-300);
}

/// |a - b| / |b| (2-norms).
inline double relErr(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(b.norm(), 1e-300);
}

/// The extreme eigenvalues of a body's A on its free dofs, estimated on the reference device by
/// power iteration (apply, projected) and inverse iteration (its direct solve).
struct Spectrum {
  double lambdaMin = 0.0, lambdaMax = 0.0;
  double kappa() const { return lambdaMax / lambdaMin; }
};

inline Spectrum spectrum(detail::Device& reference, std::size_t body, const detail::SystemCoeffs& c, int steps = 40) {
  const detail::Problem& p = reference.problem(body);
  Spectrum s;
  Eigen::VectorXd v = freeOnly(p, randomVector(p.dofCount(), 77 + static_cast<unsigned>(body))), y;
  for (int k = 0; k < steps; ++k) {
    v /= v.norm();
    reference.apply({body}, {c}, {&v}, {&y});
    y = freeOnly(p, y);
    s.lambdaMax = v.dot(y);
    v = y;
  }
  v = freeOnly(p, randomVector(p.dofCount(), 99 + static_cast<unsigned>(body)));
  double mu = 0.0;
  for (int k = 0; k < steps; ++k) {
    v /= v.norm();
    Eigen::VectorXd x = Eigen::VectorXd::Zero(v.size());
    reference.solveDirect(body, c, v, x);
    mu = v.dot(x);
    v = freeOnly(p, x);
  }
  s.lambdaMin = 1.0 / mu;
  return s;
}

/// |free (b - A x)| / |free b| with the reference's A (double).
inline double trueResidual(detail::Device& reference, std::size_t body, const detail::SystemCoeffs& c,
                           const Eigen::VectorXd& b, const Eigen::VectorXd& x) {
  const detail::Problem& p = reference.problem(body);
  Eigen::VectorXd xf = freeOnly(p, x), Ax;
  reference.apply({body}, {c}, {&xf}, {&Ax});
  return freeOnly(p, b - Ax).norm() / freeOnly(p, b).norm();
}

// ---------------------------------------------------------------------------------- the fixture

/// A test of one case: the suite's bodies on a device of the case (`device()`) and on the
/// reference device (`reference()`), both made through the registry with the standard solver.
class ConformanceBase : public testing::TestWithParam<ConformanceCase> {
 protected:
  bool isDouble() const { return GetParam().precision == Precision::Double; }
  double opTolerance() const { return isDouble() ? kOpDouble : kOpFloat; }
  double productTolerance() const { return isDouble() ? kProductDouble : kProductFloat; }
  double unit() const { return isDouble() ? kUnitDouble : kUnitFloat; }

  SolverDesc solver(PreconditionerKind pc = PreconditionerKind::BlockDiagonal) const {
    SolverDesc s;
    s.precision = GetParam().precision;
    s.preconditioner = pc;
    s.tolerance = isDouble() ? 1e-10 : 1e-5;
    s.maxIterations = 5000;
    s.checkEvery = 4;
    return s;
  }
  static detail::DeviceOptions options() {
    detail::DeviceOptions o;
    o.opencl = morton();
    o.vulkan.localityOrder = o.opencl.localityOrder;
    return o;
  }
  /// A device of the case holding `problems`, made by the registry entry's create.
  std::unique_ptr<detail::Device> makeDevice(const std::vector<const detail::Problem*>& problems,
                                             const SolverDesc& s) const {
    const auto entry = detail::findBackend(GetParam().backend);
    if (!entry) detail::fail(ErrorCode::Internal, "backend '", GetParam().backend, "' is no longer registered");
    detail::Candidate c;
    bool found = false;
    for (const detail::Candidate& k : entry->candidates())
      if (k.selector == GetParam().selector) {
        c = k;
        found = true;
      }
    if (!found) c = entry->resolve(GetParam().selector);
    return entry->create(problems, s, c, options());
  }
  /// Why the backend under test refuses some body of the suite with `s` ("" where it takes them
  /// all, as its registry entry says): a solver setting a backend does not offer (the Vulkan
  /// backend's multigrid) is a skip naming the reason, not a failure.
  static std::string refusal(const SolverDesc& s) {
    const auto entry = detail::findBackend(GetParam().backend);
    if (!entry || !entry->refuses) return "";
    for (const Body& b : suiteBodies())
      if (std::string why = entry->refuses(b.problem, s); !why.empty()) return why;
    return "";
  }
  static std::unique_ptr<detail::Device> makeReference(const std::vector<const detail::Problem*>& problems,
                                                       const SolverDesc& s) {
    const auto entry = detail::findBackend("reference");
    return entry->create(problems, s, detail::referenceCandidate(), options());
  }

  void SetUp() override {
    const std::vector<const detail::Problem*> problems = problemsOf(suiteBodies());
    try {
      device_ = makeDevice(problems, solver());
    } catch (const detail::Error& e) {
      // A device without double precision says so at creation (DeviceError); it is a skip where the
      // same device takes the bodies in float, a failure otherwise.
      if (e.code() == ErrorCode::DeviceError && GetParam().precision != Precision::Float) {
        SolverDesc f = solver();
        f.precision = Precision::Float;
        bool floatWorks = false;
        try {
          floatWorks = makeDevice(problems, f) != nullptr;
        } catch (const std::exception&) {
        }
        if (floatWorks) GTEST_SKIP() << GetParam().describe() << " runs float only: " << e.what();
      }
      FAIL() << "creating " << GetParam().describe() << ": " << e.what();
    }
    reference_ = makeReference(problems, solver());
    ASSERT_EQ(device_->bodyCount(), problems.size());
    EXPECT_EQ(device_->name(), GetParam().backend);
  }

  const std::vector<Body>& bodies() const { return suiteBodies(); }
  const detail::Problem& problem(std::size_t i) const { return suiteBodies().at(i).problem; }
  std::size_t count() const { return suiteBodies().size(); }
  detail::Device& device() { return *device_; }
  detail::Device& reference() { return *reference_; }

  /// Sets random positions (seed + body) on every body of both devices; returns them.
  std::vector<Eigen::VectorXd> setRandomPositions(unsigned seed) {
    return setRandomPositionsOn({&device(), &reference()}, seed);
  }
  /// The same on each of `devices`.
  std::vector<Eigen::VectorXd> setRandomPositionsOn(const std::vector<detail::Device*>& devices, unsigned seed) const {
    std::vector<Eigen::VectorXd> x(count());
    detail::ConstVectors in;
    for (std::size_t i = 0; i < count(); ++i) {
      x[i] = randomPositions(problem(i), seed + static_cast<unsigned>(i));
      in.push_back(&x[i]);
    }
    for (detail::Device* d : devices) d->setPositions(detail::allBodies(count()), in);
    return x;
  }

  /// Within the iteration margin of the reference's count (see the header); nFree, kappa, tau:
  /// the system's free dofs, condition number and tolerance.
  bool iterationsClose(int k, int kRef, std::size_t nFree, double kappa, double tau) const {
    if (isDouble()) return std::abs(k - kRef) <= 1.0 + kRef / 50.0;
    const double margin = 2.0 + kRef / 4.0;
    if (k < kRef - margin) return false;
    if (k <= kRef + margin) return true;
    const double rateBound = std::sqrt(kappa) / 2.0 * std::log(2.0 * std::sqrt(kappa) / tau);
    return static_cast<std::size_t>(kRef) >= nFree && k <= rateBound;
  }

  /// Checks one solve of body `i` (device: x, stats; reference: xRef, statsRef) as the header
  /// derives; `what` names it in failures.
  void expectSolveMatches(std::size_t i, const detail::SystemCoeffs& c, const Eigen::VectorXd& b,
                          const Eigen::VectorXd& x, const detail::LinearSolveStats& st, const Eigen::VectorXd& xRef,
                          const detail::LinearSolveStats& stRef, double tau, const std::string& what,
                          const Eigen::VectorXd* x0 = nullptr, double roundingSensitive = 0.0) {
    const detail::Problem& p = problem(i);
    SCOPED_TRACE(what + ", body '" + p.name + "'");
    const Spectrum s = spectrum(reference(), i, c);
    const double res = trueResidual(reference(), i, c, b, x), resRef = trueResidual(reference(), i, c, b, xRef);
    const double bNorm = freeOnly(p, b).norm(), xNorm = freeOnly(p, xRef).norm();
    const double x0Norm = x0 ? freeOnly(p, *x0).norm() : 0.0;
    const double resBound =
        tau + (64.0 + st.iterations) * unit() * (1.0 + s.lambdaMax * (xNorm + 2.0 * x0Norm) / bNorm);
    const double reportBound = 64.0 * unit() * (1.0 + s.lambdaMax * xNorm / bNorm);
    const double xBound = 2.0 * s.kappa() * (res + resRef);
    std::printf("[info] %s, %s: %d iterations (reference %d), true residual %.2e (bound %.2e), |x - x_ref| / |x_ref| "
                "%.2e (bound %.2e, kappa %.1e)\n",
                what.c_str(), p.name.c_str(), st.iterations, stRef.iterations, res, resBound, relErr(x, xRef), xBound,
                s.kappa());
    EXPECT_TRUE(stRef.converged) << "the reference must converge for the comparison to mean anything";
    EXPECT_EQ(st.converged, stRef.converged);
    // roundingSensitive k > 0: a preconditioner applied in float whose iterates depend more on its
    // rounding than the diagonal's (a warped rest operator on a body it fits poorly): at most k
    // times the reference's count and the margin.
    if (roundingSensitive > 0.0 && !isDouble())
      EXPECT_LE(st.iterations, roundingSensitive * stRef.iterations + 2.0 + stRef.iterations / 4.0)
          << st.iterations << " iterations, reference " << stRef.iterations;
    else
      EXPECT_TRUE(iterationsClose(st.iterations, stRef.iterations, freeCount(p), s.kappa(), tau))
          << st.iterations << " iterations, reference " << stRef.iterations;
    EXPECT_LE(res, resBound) << "the true residual of the device's x";
    EXPECT_NEAR(st.relativeResidual, res, reportBound) << "the residual the device reports";
    EXPECT_LE(relErr(x, xRef), xBound);
    for (std::size_t d = 0; d < p.dofCount(); ++d) {
      if (p.constrained[d]) {
        EXPECT_EQ(x[static_cast<Eigen::Index>(d)], 0.0) << "constrained dof " << d;
      }
    }
  }

  /// solvePcg of `set` (indices into the bodies) with each body's own system, from `start`.
  struct SetSolve {
    std::vector<Eigen::VectorXd> x;
    std::vector<detail::PcgSolve> solves;
  };
  static SetSolve solveSet(detail::Device& dev, const detail::BodySet& set, const std::vector<Eigen::VectorXd>& b,
                           const std::vector<Eigen::VectorXd>& start, const SolverDesc& s,
                           const std::vector<detail::SystemCoeffs>& coeffs) {
    SetSolve out;
    out.x = start;
    out.solves.resize(set.size());
    for (std::size_t k = 0; k < set.size(); ++k) {
      out.solves[k].coeffs = coeffs[k];
      out.solves[k].b = &b[k];
      out.solves[k].x = &out.x[k];
    }
    detail::solvePcg(dev, set, out.solves, s);
    return out;
  }

 private:
  std::unique_ptr<detail::Device> device_, reference_;
};

/// Declares the suite `fixture` (a ConformanceBase) over every case; an empty list is allowed
/// (ConformanceBackends.ListedByTheRegistry says why there is none, with one skip).
#define COROFEM_CONFORMANCE_SUITE(fixture)                                                                   \
  GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(fixture);                                                    \
  INSTANTIATE_TEST_SUITE_P(Backends, fixture, ::testing::ValuesIn(::corofem::test::conformanceCases()), \
                           ::corofem::test::caseName)

}  // namespace corofem::test
