// The statics driver (one body at a time) and the drivers' factory (driver.hpp).
#include "solve/driver.hpp"

#include "solve/dynamics.hpp"
#include "util/error.hpp"

namespace corofem::detail {

namespace {

class StaticsDriver final : public Driver {
 public:
  StaticsDriver(DeviceSlot& slot, const StaticDesc& desc, const Log& log) {
    for (std::size_t i = 0; i < slot.bodyCount(); ++i)
      solvers_.push_back(std::make_unique<StaticSolver>(slot.problem(i), BodyView(slot, i), desc, log));
  }

  std::vector<BodyOutcome> step(const BodySet& bodies, const StepCall& call) override {
    std::vector<BodyOutcome> out(bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      try {
        out[i].stats = at(bodies[i]).step(call.index, call.count);
      } catch (...) {
        out[i].error = std::current_exception();
      }
    }
    return out;
  }
  void idleStep(std::size_t, double) override { fail(ErrorCode::Internal, "statics have no idle steps"); }
  void rollback(std::size_t body) override { at(body).rollback(); }
  void setState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) override {
    at(body).setInitialState(x, v);
  }
  void constraintsChanged(std::size_t) override { needsDynamics(); }
  void materialChanged(std::size_t) override { needsDynamics(); }
  void loadsChanged(std::size_t) override {}  // each solve reads the loads
  void setControls(std::size_t, const BodyControls&) override { needsDynamics(); }
  void removeBody(std::size_t body) override {
    solvers_.erase(solvers_.begin() + static_cast<std::ptrdiff_t>(body));
    for (std::size_t k = body; k < solvers_.size(); ++k) solvers_[k]->moveTo(k);
  }
  const Eigen::VectorXd& positions(std::size_t body) const override { return at(body).positions(); }
  const Eigen::VectorXd& velocities(std::size_t body) const override { return at(body).velocities(); }
  double externalWork(std::size_t body) const override { return at(body).externalWork(); }
  double kineticEnergy(std::size_t body) const override { return at(body).kineticEnergy(); }
  double elasticEnergy(std::size_t body) override { return at(body).elasticEnergy(); }
  void syncDevicePositions(const BodySet& bodies) override {
    for (std::size_t b : bodies) at(b).syncDevicePositions();
  }

 private:
  [[noreturn]] static void needsDynamics() {
    fail(ErrorCode::BadInput, "handles, pins and applied forces act on a dynamic analysis; this scene's is static "
         "(analysis.type \"static\"): use \"dynamic\" to hold bodies at run time");
  }
  StaticSolver& at(std::size_t body) const { return *solvers_.at(body); }
  std::vector<std::unique_ptr<StaticSolver>> solvers_;
};

}  // namespace

std::unique_ptr<Driver> createDriver(DeviceSlot& slot, const AnalysisDesc& analysis, const Log& log) {
  if (analysis.kind == AnalysisDesc::Kind::Static) return std::make_unique<StaticsDriver>(slot, analysis.statics, log);
  return std::make_unique<DynamicsDriver>(slot, analysis.dynamics, log);
}

}  // namespace corofem::detail
