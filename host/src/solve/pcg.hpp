// PCG written once: the loop that drives any Device's PCG building blocks (device/device.hpp) for a
// set of bodies at once -- its tolerance and iteration cap, the cadence of the host's reads, the
// stop of each body, the true residual and the messages. The device tests convergence after every
// iteration and stops each body on its own, so the host may read the scalars only every
// `checkEvery` iterations: it enqueues a chunk ahead of what it has read, learns of a stop at most
// one chunk late, and that late chunk costs the stopped body nothing. The answer and the iteration
// count are those of a check after every iteration, whatever checkEvery is.
#pragma once

#include "device/device.hpp"

#include <corofem/scene.hpp>

#include <string>
#include <vector>

namespace corofem::detail {

/// One body's linear system in solvePcg.
struct PcgSolve {
  SystemCoeffs coeffs;
  const Eigen::VectorXd* b = nullptr;  ///< right-hand side (constrained rows ignored)
  Eigen::VectorXd* x = nullptr;        ///< starting vector in, solution out (constrained dofs 0)
  /// b and x are the device's own, with no host vectors (both null): a step store staged b and a
  /// zero x in the device's solve vectors and takes x from them after (Device::pcgBegin).
  bool resident = false;
  LinearSolveStats stats;              ///< filled: iterations, the true relative residual, converged
  /// Empty, or why the solve failed (non-finite right-hand side, residual or solution): the text of
  /// an Error(SolveFailed) naming the body. x is then unspecified.
  std::string failure;
};

/// Solves A x = b for every body of `bodies` (one PcgSolve each, in the set's order) with the
/// solver's tolerance, iteration cap and check cadence. Never throws for non-convergence or a
/// non-finite system (the solve's `failure` says so); a device error throws Error(DeviceError).
void solvePcg(Device& device, const BodySet& bodies, std::vector<PcgSolve>& solves, const SolverDesc& solver);

/// The whole linear solve of one body as the solver asks for it: PCG (solvePcg), or the device's
/// direct solve (Cholesky, reference backend only). Throws Error(SolveFailed) for a failure, with
/// x unspecified.
LinearSolveStats solveLinear(Device& device, std::size_t body, const SystemCoeffs& coeffs, const Eigen::VectorXd& b,
                             Eigen::VectorXd& x, const SolverDesc& solver);

}  // namespace corofem::detail
