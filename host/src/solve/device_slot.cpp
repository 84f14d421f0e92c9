// The failover-aware device of a set of bodies (device_slot.hpp).
#include "solve/device_slot.hpp"

#include "util/error.hpp"

#include <mutex>

namespace corofem::detail {

const char* slotCallName(std::size_t call) {
  static const char* const names[] = {"set_positions", "internal_forces", "apply", "solve", "elastic_energy"};
  return call < SlotStats::kCalls ? names[call] : "unknown";
}

namespace {

/// The name of a call in fallback events: the per-body calls of the drivers.
const char* eventName(SlotStats::Call call) {
  static const char* const names[] = {"setPositions", "internalForces", "apply", "solve", "elasticEnergy"};
  return names[call];
}

std::unique_ptr<Device> makeDevice(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                   const Candidate& c, const DeviceOptions& options) {
  // One device is created at a time: device and program set-up is not known to be re-entrant in
  // every driver.
  static std::mutex creating;
  std::lock_guard<std::mutex> lock(creating);
  return backendOf(c)->create(problems, solver, c, options);
}

/// Gives a new device the bodies' last positions (those that have some).
void givePositions(Device& device, const std::vector<Eigen::VectorXd>& lastX) {
  BodySet known;
  ConstVectors xs;
  for (std::size_t b = 0; b < lastX.size(); ++b)
    if (lastX[b].size() > 0) {
      known.push_back(b);
      xs.push_back(&lastX[b]);
    }
  if (!known.empty()) device.setPositions(known, xs);
}

}  // namespace

DeviceSlot::DeviceSlot(std::vector<const Problem*> problems, const SolverDesc& solver, std::vector<Candidate> order,
                       bool fallbackAtCreate, const DeviceOptions& options, const Log& log)
    : problems_(std::move(problems)), solver_(resolvedSolver(solver, problems_)), options_(options), log_(log),
      order_(std::move(order)) {
  if (order_.empty() || problems_.empty()) fail(ErrorCode::Internal, "DeviceSlot: no candidate or no body");
  lastX_.resize(problems_.size());
  try {
    device_ = makeDevice(problems_, solver_, order_[0], options_);
  } catch (const std::exception& e) {
    // A device that cannot be made, or cannot take these bodies, hands them to the next.
    if (!fallbackAtCreate || order_.size() < 2) throw;
    advance("create", e.what());
  }
}

DeviceSlot::DeviceSlot(std::unique_ptr<Device> device, const SolverDesc& solver, const Log& log)
    : solver_(solver), log_(log), device_(std::move(device)) {
  if (!device_ || device_->bodyCount() == 0) fail(ErrorCode::Internal, "DeviceSlot: no device or no body");
  for (std::size_t b = 0; b < device_->bodyCount(); ++b) problems_.push_back(&device_->problem(b));
  solver_ = resolvedSolver(solver_, problems_);
  Candidate given;
  given.backend = device_->name();
  given.device = device_->deviceName();
  given.selector = "given";
  order_.push_back(given);
  given_ = true;
  lastX_.resize(problems_.size());
}

void DeviceSlot::advance(const std::string& call, const std::string& error) {
  failures_ += "\n  " + order_[index_].label() + " (" + call + "): " + error;
  // The positions a store set on the failing device, read once (a lost device may not give them:
  // those bodies then start the next device with none, and their driver restarts them).
  try {
    refreshPositions();
  } catch (const std::exception& e) {
    failures_ += "\n  " + order_[index_].label() + " (its bodies' positions): " + e.what();
    for (std::size_t b = 0; b < elsewhere_.size(); ++b)
      if (elsewhere_[b]) lastX_.at(b).resize(0);
    elsewhere_.clear();
  }
  while (index_ + 1 < order_.size()) {
    const std::size_t from = index_;
    ++index_;
    try {
      std::unique_ptr<Device> next = makeDevice(problems_, solver_, order_[index_], options_);
      givePositions(*next, lastX_);
      device_ = std::move(next);
      ++generation_;
      ++failovers_;
    } catch (const std::exception& e) {
      // Whatever keeps this candidate from taking the bodies (no device, an allocation, a tuning
      // it refuses): the next one is tried.
      failures_ += "\n  " + order_[index_].label() + " (create): " + e.what();
      continue;
    }
    for (const Problem* p : problems_) {
      FallbackEvent ev{p->name, when_, call, order_[from].label(), order_[index_].label(), error};
      log_(LogLevel::Warning, "body '", ev.body, "': device failure on ", ev.from,
           ev.call == ev.when ? " at " + ev.when : " in " + ev.call + " (" + ev.when + ")", ": ", ev.error,
           "; continuing on ", ev.to);
      events_.push_back(std::move(ev));
    }
    return;
  }
  exhausted_ = true;  // the last device stays for the reports; no call reaches it again
  failExhausted();
}

void DeviceSlot::setPositionSource(const void* owner, PositionSource source) {
  source_ = std::move(source);
  sourceOwner_ = owner;
  elsewhere_.clear();
}

void DeviceSlot::dropPositionSource(const void* owner) {
  if (owner != sourceOwner_) return;
  refreshPositions();  // what the store set last stays the slot's
  source_ = nullptr;
  sourceOwner_ = nullptr;
}

void DeviceSlot::positionsSetElsewhere(const BodySet& bodies) {
  elsewhere_.resize(problems_.size(), 0);
  for (std::size_t b : bodies) elsewhere_.at(b) = 1;
}

void DeviceSlot::refreshPositions() {
  refreshing_ = true;
  try {
    for (std::size_t b = 0; b < elsewhere_.size(); ++b)
      if (elsewhere_[b] && source_) source_(b, lastX_.at(b));
  } catch (...) {
    refreshing_ = false;
    throw;
  }
  refreshing_ = false;
  elsewhere_.clear();
}

void DeviceSlot::failover(const std::string& call, const Error& error) {
  if (error.code() != ErrorCode::DeviceError || refreshing_) throw error;  // a read of the source fails alone
  if (exhausted_) failExhausted();
  advance(call, error.what());
}

void DeviceSlot::failExhausted() const {
  std::string names;
  for (const Problem* p : problems_) names += (names.empty() ? "'" : ", '") + p->name + "'";
  fail(ErrorCode::DeviceError, problems_.size() > 1 ? "bodies " : "body ", names, ": every backend failed:", failures_,
       "\nThe bodies keep their last good state; no device is left to step them: create the Simulation again "
       "(after fixing the devices, or with other ones in SimulationOptions::devices) to go on.");
}

void DeviceSlot::beginStep() {
  inStep_ = true;
  lastEnd_ = std::chrono::steady_clock::now();
}

template <class Fn>
void DeviceSlot::withFailover(const std::string& call, Fn&& fn) {
  for (;;) {
    if (exhausted_) failExhausted();
    try {
      fn(*device_);
      return;
    } catch (const Error& e) {
      if (e.code() != ErrorCode::DeviceError) throw;
      advance(call, e.what());
    }
  }
}

template <class Fn>
void DeviceSlot::guarded(SlotStats::Call call, const BodySet& bodies, Fn&& fn) {
  counted(call, bodies, [&]() { withFailover(eventName(call), fn); });
}

void DeviceSlot::count(SlotStats::Call call, const BodySet& bodies, std::chrono::steady_clock::time_point start,
                       std::chrono::steady_clock::time_point end) {
  const double seconds = std::chrono::duration<double>(end - start).count();
  stats_.calls += 1;
  stats_.bodies += static_cast<long long>(bodies.size());
  stats_.largestCall = std::max(stats_.largestCall, bodies.size());
  stats_.deviceSeconds += seconds;
  if (inStep_) {
    SlotCallStats& c = stats_.byCall[call];
    c.calls += 1;
    c.bodies += static_cast<long long>(bodies.size());
    c.deviceSeconds += seconds;
    c.waitSeconds += std::chrono::duration<double>(start - lastEnd_).count();
    lastEnd_ = end;
  }
}

void DeviceSlot::setPositions(const BodySet& bodies, const ConstVectors& x) {
  // The positions are kept for a failover (advance gives the new device them): a repeat is harmless.
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    lastX_.at(bodies[i]) = *x[i];
    if (bodies[i] < elsewhere_.size()) elsewhere_[bodies[i]] = 0;
  }
  guarded(SlotStats::SetPositions, bodies, [&](Device& d) { d.setPositions(bodies, x); });
}

void DeviceSlot::setConstraints(const BodySet& bodies) {
  std::vector<const std::vector<std::uint8_t>*> masks;
  for (std::size_t b : bodies) masks.push_back(&problems_.at(b)->constrained);
  // A device made by a failover reads the new masks from the problems: the repeat is harmless.
  withFailover("setConstraints", [&](Device& d) { d.setConstraints(bodies, masks); });
}

void DeviceSlot::setMaterial(const BodySet& bodies) {
  std::vector<const Problem*> problems;
  for (std::size_t b : bodies) problems.push_back(problems_.at(b));
  withFailover("setMaterial", [&](Device& d) { d.setMaterial(bodies, problems); });
}

void DeviceSlot::setSprings(const BodySet& bodies) {
  std::vector<const Problem*> problems;
  for (std::size_t b : bodies) problems.push_back(problems_.at(b));
  withFailover("setSprings", [&](Device& d) { d.setSprings(bodies, problems); });
}

void DeviceSlot::removeBody(std::size_t body) {
  if (body >= problems_.size() || problems_.size() < 2)
    fail(ErrorCode::Internal, "removing body ", body, " of a device slot of ", problems_.size());
  refreshPositions();  // before the indices move
  if (!exhausted_ && device_->removeBody(body)) {  // in place: the other bodies keep what they hold
    problems_.erase(problems_.begin() + static_cast<std::ptrdiff_t>(body));
    lastX_.erase(lastX_.begin() + static_cast<std::ptrdiff_t>(body));
    solveStart_.clear();
    ++generation_;  // the bodies' indices moved: surfaces made for them are made again
    return;
  }
  if (given_ || exhausted_)
    fail(ErrorCode::DeviceError, "body '", problems_[body]->name, "' cannot leave its device: ",
         given_ ? "the device was made by the caller, and no other can be made for the bodies that stay; create the "
                  "Simulation again without the body"
                : "every device of its batch failed; create the Simulation again (after fixing the devices) to go on");
  std::vector<const Problem*> problems = problems_;
  std::vector<Eigen::VectorXd> lastX = lastX_;
  problems.erase(problems.begin() + static_cast<std::ptrdiff_t>(body));
  lastX.erase(lastX.begin() + static_cast<std::ptrdiff_t>(body));
  std::unique_ptr<Device> next = makeDevice(problems, solver_, order_[index_], options_);
  givePositions(*next, lastX);
  problems_ = std::move(problems);
  lastX_ = std::move(lastX);
  solveStart_.clear();
  device_ = std::move(next);
  ++generation_;  // surfaces made for the old device are made again
}

void DeviceSlot::internalForces(const BodySet& bodies, const Vectors& f) {
  guarded(SlotStats::InternalForces, bodies, [&](Device& d) { d.internalForces(bodies, f); });
}

void DeviceSlot::apply(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p,
                       const Vectors& y) {
  guarded(SlotStats::Apply, bodies, [&](Device& d) { d.apply(bodies, coeffs, p, y); });
}

void DeviceSlot::elasticEnergy(const BodySet& bodies, std::vector<double>& energy) {
  guarded(SlotStats::ElasticEnergy, bodies, [&](Device& d) { d.elasticEnergy(bodies, energy); });
}

void DeviceSlot::solve(const BodySet& bodies, std::vector<PcgSolve>& solves) {
  // The starting vectors, restored before a repeat (members: no allocation per solve).
  if (solveStart_.size() < solves.size()) solveStart_.resize(solves.size());
  for (std::size_t i = 0; i < solves.size(); ++i) solveStart_[i] = *solves[i].x;
  bool first = true;
  guarded(SlotStats::Solve, bodies, [&](Device& d) {
    if (!first)
      for (std::size_t i = 0; i < solves.size(); ++i) *solves[i].x = solveStart_[i];
    first = false;
    if (solver_.linearSolver == LinearSolverKind::Cholesky) {
      for (std::size_t i = 0; i < bodies.size(); ++i) {
        solves[i].failure.clear();
        try {
          solves[i].stats = d.solveDirect(bodies[i], solves[i].coeffs, *solves[i].b, *solves[i].x);
        } catch (const Error& e) {
          if (e.code() != ErrorCode::SolveFailed) throw;  // a device error fails over, the rest propagate
          solves[i].failure = e.what();
        }
      }
      return;
    }
    solvePcg(d, bodies, solves, solver_);
  });
}

}  // namespace corofem::detail
