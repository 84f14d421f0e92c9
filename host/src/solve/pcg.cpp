// The PCG loop over a device's building blocks (solve/pcg.hpp).
#include "solve/pcg.hpp"

#include "solve/step_store.hpp"

#include "util/error.hpp"
#include "util/finite.hpp"

#include <algorithm>
#include <cmath>
#include <deque>

namespace corofem::detail {

LinearSolveStats Device::solveDirect(std::size_t body, const SystemCoeffs&, const Eigen::VectorXd&, Eigen::VectorXd&) {
  fail(ErrorCode::BadInput, "body '", problem(body).name, "': the ", name(), " backend solves with PCG only; \"cholesky\" "
       "is available on the reference backend (\"backend\": \"reference\")");
}

void Device::setConstraints(const BodySet& bodies, const std::vector<const std::vector<std::uint8_t>*>&) {
  if (bodies.empty()) return;
  fail(ErrorCode::DeviceError, "the ", name(), " backend cannot change a body's constrained nodes at run time");
}

void Device::setMaterial(const BodySet& bodies, const std::vector<const Problem*>&) {
  if (bodies.empty()) return;
  fail(ErrorCode::DeviceError, "the ", name(), " backend cannot change a body's material at run time");
}

void Device::setSprings(const BodySet& bodies, const std::vector<const Problem*>&) {
  if (bodies.empty()) return;
  fail(ErrorCode::DeviceError, "the ", name(), " backend cannot attach springs to a body at run time");
}

std::unique_ptr<StepStore> Device::createStepStore(DeviceSlot&) { return nullptr; }

double slendernessOf(const Problem& p) {
  const Eigen::Index n = p.restPositions.size() / 3;
  if (n == 0) return 0.0;
  double extent = 0.0;
  for (Eigen::Index a = 0; a < 3; ++a) {
    double lo = p.restPositions[a], hi = lo;
    for (Eigen::Index i = 1; i < n; ++i) {
      lo = std::min(lo, p.restPositions[3 * i + a]);
      hi = std::max(hi, p.restPositions[3 * i + a]);
    }
    extent = std::max(extent, hi - lo);
  }
  double volume = 0.0;
  for (const ElementRest& e : p.elements) volume += e.volume;
  return volume > 0.0 && extent > 0.0 ? extent / std::sqrt(volume / extent) : 0.0;
}

BodySet allBodies(std::size_t n) {
  BodySet set(n);
  for (std::size_t i = 0; i < n; ++i) set[i] = i;
  return set;
}

namespace {

std::string bodyName(const Device& device, std::size_t body) { return "body '" + device.problem(body).name + "'"; }

/// One tile's solve: the bodies of `bodies`, their solves in `tile` (the same order).
void solveTile(Device& device, const BodySet& bodies, const std::vector<PcgSolve*>& tile, const SolverDesc& solver) {
  const std::size_t n = bodies.size();
  std::vector<SystemCoeffs> coeffs(n);
  ConstVectors b(n), start(n);
  Vectors x(n);
  for (std::size_t i = 0; i < n; ++i) {
    PcgSolve& s = *tile[i];
    if (s.resident ? (s.b || s.x) : (!s.b || !s.x))
      fail(ErrorCode::Internal, "solvePcg: ", bodyName(device, bodies[i]),
           s.resident ? " solves on the device's vectors but was given host vectors" : " has no vector b or x");
    if (!s.resident && s.x->size() != s.b->size()) s.x->setZero(s.b->size());
    s.stats = LinearSolveStats{};
    s.failure.clear();
    coeffs[i] = s.coeffs;
    b[i] = s.b;
    start[i] = s.x;
    x[i] = s.x;
  }
  const int cap = std::max(0, solver.maxIterations);
  const int checkEvery = std::max(1, solver.checkEvery);
  const std::vector<PcgStart> entered = device.pcgBegin(bodies, coeffs, b, start, solver.tolerance, cap);

  // Per body: still iterating as the host knows, and whether its residual stayed finite.
  std::vector<char> iterating(n, 0), finite(n, 1);
  bool anyRunning = false;
  for (std::size_t i = 0; i < n; ++i) {
    PcgSolve& s = *tile[i];
    switch (entered[i]) {
      case PcgStart::NonFiniteRhs:
        s.failure = bodyName(device, bodies[i]) + ": PCG on '" + device.deviceName() + "': the right-hand side is not "
                    "finite (NaN or Inf in b, or beyond the range of the device's precision); the state diverged "
                    "before the linear solve";
        break;
      case PcgStart::ZeroRhs:
        if (s.x) s.x->setZero();
        s.stats.converged = true;
        break;
      case PcgStart::Running:
        iterating[i] = 1;
        anyRunning = true;
        break;
    }
  }
  if (!anyRunning) return;

  std::vector<PcgScalars> scalars(n);
  std::deque<PcgTicket> reads;
  int enqueued = 0;
  // Waits for the oldest read and takes the stops it shows.
  auto collect = [&]() {
    const PcgTicket t = reads.front();
    reads.pop_front();
    device.pcgTake(t, scalars);
    for (std::size_t i = 0; i < n; ++i) {
      if (!iterating[i]) continue;
      LinearSolveStats& st = tile[i]->stats;
      st.iterations = scalars[i].iterations;
      st.relativeResidual = std::sqrt(std::max(0.0, scalars[i].rr) / scalars[i].bb);
      if (scalars[i].stop == PcgStop::Running) continue;
      iterating[i] = 0;
      st.converged = scalars[i].stop == PcgStop::Converged;
      finite[i] = scalars[i].stop != PcgStop::NonFinite && std::isfinite(st.relativeResidual);
    }
  };
  auto enqueueChunk = [&]() {
    const int k = device.pcgOneLaunch() ? cap - enqueued : std::min(checkEvery, cap - enqueued);
    device.pcgIterate(k, iterating);
    enqueued += k;
    reads.push_back(device.pcgRead());
  };
  // The reported residual is the true one, |free (b - A x)| / |free b|, not the recurrence's
  // estimate, which drifts from it in float: one more product, for the bodies that iterated. Once
  // the last allowed iteration is queued nothing can follow it, so it is queued at once for every
  // body that may have iterated, without waiting for the last scalars.
  std::vector<char> residualFor(n, 0);
  bool residualQueued = false;
  auto queueResidual = [&]() {
    for (std::size_t i = 0; i < n; ++i)
      residualFor[i] = entered[i] == PcgStart::Running &&
                       (iterating[i] || (finite[i] && tile[i]->stats.iterations > 0));
    residualQueued = true;
    if (std::any_of(residualFor.begin(), residualFor.end(), [](char c) { return c != 0; }))
      device.pcgResidual(residualFor);
  };

  if (device.pcgSetupReadable()) reads.push_back(device.pcgRead());  // a warm start may have converged
  if (enqueued < cap) enqueueChunk();  // runs while that read travels
  for (;;) {
    if (enqueued >= cap && !residualQueued && enqueued > 0) queueResidual();
    collect();
    const bool any = std::any_of(iterating.begin(), iterating.end(), [](char c) { return c != 0; });
    if (!any) break;  // all stopped
    if (enqueued < cap) enqueueChunk();
    else if (reads.empty()) break;  // the read after the last allowed iteration was taken
  }
  std::vector<int> iterations(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (iterating[i]) tile[i]->stats.iterations = cap;  // capped
    iterations[i] = tile[i]->stats.iterations;
  }
  if (!residualQueued) queueResidual();
  std::vector<PcgScalars> residual(n);
  device.pcgEnd(iterations, x, residual);

  for (std::size_t i = 0; i < n; ++i) {
    if (entered[i] != PcgStart::Running) continue;
    PcgSolve& s = *tile[i];
    // The convergence decision stays the recurrence's (the standard PCG stop test); the residual
    // reported is the true one.
    if (residualFor[i] && finite[i] && s.stats.iterations > 0) {
      s.stats.relativeResidual = std::sqrt(std::max(0.0, residual[i].rr) / residual[i].bb);
      finite[i] = std::isfinite(s.stats.relativeResidual);
    }
    if (!finite[i]) {
      s.failure = bodyName(device, bodies[i]) + ": PCG produced a non-finite residual after " +
                  std::to_string(s.stats.iterations) + " iterations on '" + device.deviceName() +
                  "' (the system matrix or the right-hand side holds NaN/Inf, or the device's precision "
                  "overflowed); check the material, time step and loads";
    } else if (s.x && !allFiniteEntries(*s.x)) {  // a resident x: its owner counts them (StepStore::update)
      s.failure = bodyName(device, bodies[i]) + ": PCG produced a non-finite solution on '" + device.deviceName() + "'";
    }
  }
}

}  // namespace

void solvePcg(Device& device, const BodySet& bodies, std::vector<PcgSolve>& solves, const SolverDesc& solver) {
  if (solves.size() != bodies.size())
    fail(ErrorCode::Internal, "solvePcg: ", solves.size(), " solves for ", bodies.size(), " bodies");
  if (bodies.empty()) return;
  std::size_t at = 0;
  for (const BodySet& tile : device.pcgTiles(bodies)) {
    std::vector<PcgSolve*> mine;
    for (std::size_t body : tile) {
      while (at < bodies.size() && bodies[at] != body) ++at;  // tiles keep the set's order
      if (at == bodies.size()) fail(ErrorCode::Internal, "solvePcg: a tile holds a body outside the set");
      mine.push_back(&solves[at]);
    }
    solveTile(device, tile, mine, solver);
  }
}

LinearSolveStats solveLinear(Device& device, std::size_t body, const SystemCoeffs& coeffs, const Eigen::VectorXd& b,
                             Eigen::VectorXd& x, const SolverDesc& solver) {
  if (solver.linearSolver == LinearSolverKind::Cholesky) return device.solveDirect(body, coeffs, b, x);
  std::vector<PcgSolve> one(1);
  one[0].coeffs = coeffs;
  one[0].b = &b;
  one[0].x = &x;
  solvePcg(device, {body}, one, solver);
  if (!one[0].failure.empty()) throw Error(ErrorCode::SolveFailed, one[0].failure);
  return one[0].stats;
}

}  // namespace corofem::detail
