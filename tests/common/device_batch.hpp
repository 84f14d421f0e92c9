// Rounds of requests over a device's bodies, as the OpenCL batch tests make them: at most one
// request per body, each kind of call one device call for the bodies that made it, the solves through
// solvePcg (solve/pcg.hpp). A request whose vectors do not fit its body fails alone; a device
// failure fails every request of the round.
#pragma once

#include "device/device.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <array>
#include <exception>
#include <string>
#include <vector>

namespace corofem::test {

using detail::LinearSolveStats;
using detail::SystemCoeffs;

enum class BatchOp { SetPositions, InternalForces, Apply, Solve, ElasticEnergy };

/// One call of one body. Inputs point at the caller's data, alive and unchanged until the round returns.
struct BatchRequest {
  BatchOp op = BatchOp::SetPositions;
  std::size_t body = 0;                  ///< index into the device's bodies
  SystemCoeffs coeffs;                   ///< Apply, Solve
  const Eigen::VectorXd* in = nullptr;   ///< SetPositions: x; Apply: p; Solve: b
  Eigen::VectorXd* out = nullptr;        ///< InternalForces: f; Apply: y; Solve: x (warm start in, solution out)
  LinearSolveStats stats;                ///< Solve: filled by the round
  double energy = 0.0;                   ///< ElasticEnergy: filled by the round
  std::exception_ptr error;              ///< set when this request failed
};

class DeviceBatch {
 public:
  DeviceBatch(detail::Device& device, const SolverDesc& solver) : device_(device), solver_(solver) {}
  std::size_t bodyCount() const { return device_.bodyCount(); }

  void run(std::vector<BatchRequest*>& round) {
    constexpr std::size_t kOps = 5;  // BatchOp values, in the order they run
    std::array<std::vector<BatchRequest*>, kOps> byOp;
    std::vector<char> seen(device_.bodyCount(), 0);
    for (BatchRequest* r : round) {
      r->error = nullptr;
      if (r->body >= seen.size() || seen[r->body]) {
        r->error = errorOf(ErrorCode::Internal, "batch: " + std::string(r->body >= seen.size() ? "no body " : "a second "
                           "request for body ") + std::to_string(r->body) + " in one round (at most one request each)");
        continue;
      }
      seen[r->body] = 1;
      byOp[static_cast<std::size_t>(r->op)].push_back(r);
    }
    try {
      for (std::size_t op = 0; op < kOps; ++op)
        if (!byOp[op].empty()) runOp(static_cast<BatchOp>(op), byOp[op]);
    } catch (...) {
      // A device failure (DeviceError) fails every request of the round.
      const std::exception_ptr error = std::current_exception();
      for (BatchRequest* r : round) r->error = error;
    }
  }

  void runOp(BatchOp op, std::vector<BatchRequest*>& all) {
    static const char* const what[] = {"the positions", "the forces", "the vector p of apply", "the right-hand side b",
                                       "the energy"};
    std::sort(all.begin(), all.end(), [](const BatchRequest* a, const BatchRequest* b) { return a->body < b->body; });
    // Requests whose vectors fit their bodies; the others fail alone.
    std::vector<BatchRequest*> ok;
    for (BatchRequest* r : all) {
      const std::size_t dofs = device_.problem(r->body).dofCount();
      const bool needsIn = op == BatchOp::SetPositions || op == BatchOp::Apply || op == BatchOp::Solve;
      const bool needsOut = op != BatchOp::SetPositions && op != BatchOp::ElasticEnergy;
      if ((needsIn && (!r->in || static_cast<std::size_t>(r->in->size()) != dofs)) || (needsOut && !r->out)) {
        r->error = errorOf(ErrorCode::Internal, "body '" + device_.problem(r->body).name + "': " +
                           what[static_cast<int>(op)] + " has " + std::to_string(r->in ? r->in->size() : 0) +
                           " entries or no output, expected 3N = " + std::to_string(dofs));
        continue;
      }
      ok.push_back(r);
    }
    if (ok.empty()) return;
    detail::BodySet set;
    detail::ConstVectors in;
    detail::Vectors out;
    std::vector<SystemCoeffs> coeffs;
    for (BatchRequest* r : ok) {
      set.push_back(r->body);
      in.push_back(r->in);
      out.push_back(r->out);
      coeffs.push_back(r->coeffs);
    }
    switch (op) {
      case BatchOp::SetPositions: device_.setPositions(set, in); break;
      case BatchOp::InternalForces: device_.internalForces(set, out); break;
      case BatchOp::Apply: device_.apply(set, coeffs, in, out); break;
      case BatchOp::ElasticEnergy: {
        std::vector<double> energy;
        device_.elasticEnergy(set, energy);
        for (std::size_t i = 0; i < ok.size(); ++i) ok[i]->energy = energy[i];
        break;
      }
      case BatchOp::Solve: {
        if (solver_.linearSolver == LinearSolverKind::Cholesky) {
          for (BatchRequest* r : ok) {
            try {
              r->stats = device_.solveDirect(r->body, r->coeffs, *r->in, *r->out);
            } catch (const detail::Error& e) {
              if (e.code() == ErrorCode::DeviceError) throw;
              r->error = std::current_exception();
            }
          }
          break;
        }
        std::vector<detail::PcgSolve> solves(ok.size());
        for (std::size_t i = 0; i < ok.size(); ++i) {
          solves[i].coeffs = ok[i]->coeffs;
          solves[i].b = ok[i]->in;
          solves[i].x = ok[i]->out;
        }
        detail::solvePcg(device_, set, solves, solver_);
        for (std::size_t i = 0; i < ok.size(); ++i) {
          ok[i]->stats = solves[i].stats;
          if (!solves[i].failure.empty()) ok[i]->error = errorOf(ErrorCode::SolveFailed, solves[i].failure);
        }
        break;
      }
    }
  }

 private:
  static std::exception_ptr errorOf(ErrorCode code, const std::string& message) {
    return std::make_exception_ptr(detail::Error(code, message));
  }
  detail::Device& device_;
  SolverDesc solver_;
};

}  // namespace corofem::test
