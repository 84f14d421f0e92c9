// FailoverBackend: a body's backend that survives device failures (see scheduler.hpp).
//
// Why repeating the failed call is enough: the Backend interface has one piece of state, the
// positions given to setPositions(); internalForces, apply, solve and elasticEnergy are functions of
// those positions and of their arguments (solve's x is its warm start, restored before the
// repeat). A new backend given the last positions therefore answers the repeated call as the old
// one would have, and the driver (which owns positions, velocities and accelerations) carries on
// with its state untouched. Between two backends of the same kind the answer is bit-identical.
#include "schedule/scheduler.hpp"

#include "util/error.hpp"

#include <iostream>
#include <mutex>
#include <utility>

namespace corofem::detail {

FailoverBackend::FailoverBackend(const Problem& problem, const SolverDesc& solver, std::vector<Candidate> order,
                                 bool fallbackAtCreate, const OpenCLTuning& tuning)
    : problem_(problem), solver_(solver), tuning_(tuning), order_(std::move(order)) {
  if (order_.empty()) fail(ErrorCode::Internal, "body '", problem_.name, "': no backend candidate");
  try {
    current_ = createBackendFor(problem_, solver_, order_[0], tuning_);
  } catch (const Error& e) {
    if (!fallbackAtCreate || e.code() != ErrorCode::DeviceError || order_.size() < 2) throw;
    advance("create", e.what());
  }
}

FailoverBackend::FailoverBackend(const Problem& problem, const SolverDesc& solver, std::vector<Candidate> order,
                                 std::unique_ptr<Backend> first, const OpenCLTuning& tuning)
    : problem_(problem), solver_(solver), tuning_(tuning), order_(std::move(order)), current_(std::move(first)) {
  if (order_.empty()) fail(ErrorCode::Internal, "body '", problem_.name, "': no backend candidate");
  if (!current_) fail(ErrorCode::Internal, "body '", problem_.name, "': no first backend");
}

FailoverBackend::~FailoverBackend() = default;

void FailoverBackend::advance(const std::string& call, const std::string& error) {
  failures_ += "\n  " + order_[index_].label() + " (" + call + "): " + error;
  while (index_ + 1 < order_.size()) {
    const std::size_t from = index_;
    ++index_;
    try {
      std::unique_ptr<Backend> next;
      {
        // Bodies of a batch fail over together, on the batch's threads (solve/batch_group.hpp):
        // one backend is created at a time (device and program set-up is not known to be
        // re-entrant in every driver). Nothing here waits for a round, so a fiber never suspends
        // while it holds the lock.
        static std::mutex creating;
        std::lock_guard<std::mutex> lock(creating);
        next = createBackendFor(problem_, solver_, order_[index_], tuning_);
      }
      if (havePositions_) next->setPositions(lastX_);
      // Replacing a batch view makes the body leave its group's rendezvous (its destructor).
      current_ = std::move(next);
    } catch (const Error& e) {
      if (e.code() != ErrorCode::DeviceError) throw;
      failures_ += "\n  " + order_[index_].label() + " (create): " + e.what();
      continue;
    }
    FallbackEvent ev{problem_.name, when_, call, order_[from].label(), order_[index_].label(), error};
    events_.push_back(ev);
    // One write, so that the lines of bodies failing over at once do not interleave.
    std::clog << ("corofem: body '" + ev.body + "': device failure on " + ev.from +
                  (ev.call == ev.when ? " at " + ev.when : " in " + ev.call + " (" + ev.when + ")") + ": " + ev.error +
                  "; continuing on " + ev.to + "\n")
              << std::flush;
    return;
  }
  current_.reset();
  fail(ErrorCode::DeviceError, "body '", problem_.name, "': every backend failed:", failures_);
}

template <class Fn>
auto FailoverBackend::guarded(const char* call, Fn&& fn) -> decltype(fn(std::declval<Backend&>())) {
  for (;;) {
    if (!current_) fail(ErrorCode::DeviceError, "body '", problem_.name, "': every backend failed:", failures_);
    try {
      return fn(*current_);
    } catch (const Error& e) {
      if (e.code() != ErrorCode::DeviceError) throw;
      advance(call, e.what());
    }
  }
}

std::string FailoverBackend::name() const { return current_ ? current_->name() : "none"; }
std::string FailoverBackend::deviceName() const { return current_ ? current_->deviceName() : "none"; }

void FailoverBackend::setPositions(const Eigen::VectorXd& x) {
  lastX_ = x;
  havePositions_ = true;
  // advance() already gives a new backend lastX_, so a repeat after a failover is harmless.
  guarded("setPositions", [&](Backend& b) { b.setPositions(x); });
}

void FailoverBackend::internalForces(Eigen::VectorXd& f) {
  guarded("internalForces", [&](Backend& b) { b.internalForces(f); });
}

void FailoverBackend::apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) {
  guarded("apply", [&](Backend& b) { b.apply(c, p, y); });
}

LinearSolveStats FailoverBackend::solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  solveStart_ = x;  // the warm start, restored before a repeat (a member: no allocation per solve)
  return guarded("solve", [&](Backend& be) {
    x = solveStart_;
    return be.solve(c, b, x);
  });
}

double FailoverBackend::elasticEnergy() {
  return guarded("elasticEnergy", [&](Backend& b) { return b.elasticEnergy(); });
}

std::vector<DeviceBuffer> FailoverBackend::deviceBuffers() const {
  return current_ ? current_->deviceBuffers() : std::vector<DeviceBuffer>{};
}

bool FailoverBackend::devicePositions(DevicePositions& out) const {
  return current_ && current_->devicePositions(out);
}

}  // namespace corofem::detail
