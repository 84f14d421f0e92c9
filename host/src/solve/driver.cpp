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

  std::vector<BodyOutcome> step(const BodySet& bodies, int index, int count) override {
    std::vector<BodyOutcome> out(bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      try {
        out[i].stats = at(bodies[i]).step(index, count);
      } catch (...) {
        out[i].error = std::current_exception();
      }
    }
    return out;
  }
  void idleStep(std::size_t) override { fail(ErrorCode::Internal, "statics have no idle steps"); }
  void rollback(std::size_t body) override { at(body).rollback(); }
  void setInitialState(std::size_t body, const Eigen::VectorXd& x, const Eigen::VectorXd& v) override {
    at(body).setInitialState(x, v);
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
  StaticSolver& at(std::size_t body) const { return *solvers_.at(body); }
  std::vector<std::unique_ptr<StaticSolver>> solvers_;
};

}  // namespace

std::unique_ptr<Driver> createDriver(DeviceSlot& slot, const AnalysisDesc& analysis, const Log& log) {
  if (analysis.kind == AnalysisDesc::Kind::Static) return std::make_unique<StaticsDriver>(slot, analysis.statics, log);
  return std::make_unique<DynamicsDriver>(slot, analysis.dynamics, log);
}

}  // namespace corofem::detail
