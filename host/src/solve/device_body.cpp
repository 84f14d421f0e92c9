// DeviceBody (solve/backend.hpp) and the reference backend's factory.
#include "backends/reference/reference_device.hpp"
#include "solve/backend.hpp"
#include "solve/batch.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"

#include <algorithm>
#include <array>
#include <exception>
#include <utility>

namespace corofem::detail {

DeviceBody::DeviceBody(std::shared_ptr<Device> device, std::size_t body, const SolverDesc& solver)
    : device_(std::move(device)), body_(body), solver_(solver) {
  if (!device_ || body_ >= device_->bodyCount()) fail(ErrorCode::Internal, "DeviceBody: no body ", body_);
}

void DeviceBody::setPositions(const Eigen::VectorXd& x) { device_->setPositions({body_}, {&x}); }

void DeviceBody::internalForces(Eigen::VectorXd& f) { device_->internalForces({body_}, {&f}); }

void DeviceBody::apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
  device_->apply({body_}, {c}, {&p}, {&y});
}

LinearSolveStats DeviceBody::solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  return solveLinear(*device_, body_, c, b, x, solver_);
}

double DeviceBody::elasticEnergy() {
  std::vector<double> e;
  device_->elasticEnergy({body_}, e);
  return e.at(0);
}

std::vector<DeviceBuffer> DeviceBody::deviceBuffers() const {
  return device_->bodyCount() == 1 ? device_->buffers() : std::vector<DeviceBuffer>{};
}

std::unique_ptr<Backend> createReferenceBackend(const Problem& problem, const SolverDesc& solver) {
  return std::make_unique<DeviceBody>(createReferenceDevice({&problem}, solver), 0, solver);
}

namespace {

/// The Error a request fails with (set into BatchRequest::error, rethrown by the body's view).
std::exception_ptr errorOf(ErrorCode code, const std::string& message) {
  return std::make_exception_ptr(Error(code, message));
}

}  // namespace

DeviceBatch::DeviceBatch(std::shared_ptr<Device> device, const SolverDesc& solver)
    : device_(std::move(device)), solver_(solver) {}

std::size_t DeviceBatch::allocatedBytes() const {
  std::size_t sum = 0;
  for (const DeviceBuffer& b : device_->buffers()) sum += b.bytes;
  return sum;
}

void DeviceBatch::run(std::vector<BatchRequest*>& round) {
  constexpr std::size_t kOps = 5;  // BatchOp values, in the order they run
  std::array<std::vector<BatchRequest*>, kOps> byOp;
  std::vector<char> seen(device_->bodyCount(), 0);
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

void DeviceBatch::runOp(BatchOp op, std::vector<BatchRequest*>& all) {
  static const char* const what[] = {"the positions", "the forces", "the vector p of apply", "the right-hand side b",
                                     "the energy"};
  std::sort(all.begin(), all.end(), [](const BatchRequest* a, const BatchRequest* b) { return a->body < b->body; });
  // Requests whose vectors fit their bodies; the others fail alone.
  std::vector<BatchRequest*> ok;
  for (BatchRequest* r : all) {
    const std::size_t dofs = device_->problem(r->body).dofCount();
    const bool needsIn = op == BatchOp::SetPositions || op == BatchOp::Apply || op == BatchOp::Solve;
    const bool needsOut = op != BatchOp::SetPositions && op != BatchOp::ElasticEnergy;
    if ((needsIn && (!r->in || static_cast<std::size_t>(r->in->size()) != dofs)) || (needsOut && !r->out)) {
      r->error = errorOf(ErrorCode::Internal, "body '" + device_->problem(r->body).name + "': " +
                         what[static_cast<int>(op)] + " has " + std::to_string(r->in ? r->in->size() : 0) +
                         " entries or no output, expected 3N = " + std::to_string(dofs));
      continue;
    }
    ok.push_back(r);
  }
  if (ok.empty()) return;
  BodySet set;
  ConstVectors in;
  Vectors out;
  std::vector<SystemCoeffs> coeffs;
  for (BatchRequest* r : ok) {
    set.push_back(r->body);
    in.push_back(r->in);
    out.push_back(r->out);
    coeffs.push_back(r->coeffs);
  }
  switch (op) {
    case BatchOp::SetPositions: device_->setPositions(set, in); break;
    case BatchOp::InternalForces: device_->internalForces(set, out); break;
    case BatchOp::Apply: device_->apply(set, coeffs, in, out); break;
    case BatchOp::ElasticEnergy: {
      std::vector<double> energy;
      device_->elasticEnergy(set, energy);
      for (std::size_t i = 0; i < ok.size(); ++i) ok[i]->energy = energy[i];
      break;
    }
    case BatchOp::Solve: {
      if (solver_.linearSolver == LinearSolverKind::Cholesky) {
        for (BatchRequest* r : ok) {
          try {
            r->stats = device_->solveDirect(r->body, r->coeffs, *r->in, *r->out);
          } catch (const Error& e) {
            if (e.code() == ErrorCode::DeviceError) throw;
            r->error = std::current_exception();
          }
        }
        break;
      }
      std::vector<PcgSolve> solves(ok.size());
      for (std::size_t i = 0; i < ok.size(); ++i) {
        solves[i].coeffs = ok[i]->coeffs;
        solves[i].b = ok[i]->in;
        solves[i].x = ok[i]->out;
      }
      solvePcg(*device_, set, solves, solver_);
      for (std::size_t i = 0; i < ok.size(); ++i) {
        ok[i]->stats = solves[i].stats;
        if (!solves[i].failure.empty()) ok[i]->error = errorOf(ErrorCode::SolveFailed, solves[i].failure);
      }
      break;
    }
  }
}

}  // namespace corofem::detail
