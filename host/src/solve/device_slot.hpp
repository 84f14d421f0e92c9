// The device a set of bodies runs on now, with failover: the drivers (solve/) make every device
// call through a DeviceSlot, which holds an ordered list of candidates (the scheduler's: the choice
// first, the reference backend last). When a call throws Error(DeviceError) (program build,
// allocation, launch, read-back), the next candidate's device is created for all the slot's
// bodies, given each body's last positions, and the same call is repeated on it with the same
// inputs (a solve from its saved starting vectors). Every other output is a function of the
// positions and the call's arguments, so the drivers never notice: their state simply carries on.
// The slot also counts its calls (the batch report's rounds) and the time the device spent in
// them and the host between them.
#pragma once

#include "device/registry.hpp"
#include "solve/pcg.hpp"
#include "util/error.hpp"
#include "util/log.hpp"

#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// A device failure survived by moving a body to another device.
struct FallbackEvent {
  std::string body;
  std::string when;   ///< "create", "step 3"
  std::string call;   ///< the call that failed ("solve", "setPositions", "create")
  std::string from, to;  ///< candidate labels
  std::string error;  ///< the device error's message
};

/// The calls of one kind made inside steps (DeviceSlot::stats).
struct SlotCallStats {
  long long calls = 0;         ///< device calls of this kind (a round each)
  long long bodies = 0;        ///< bodies in them
  double deviceSeconds = 0.0;  ///< wall time inside them
  /// Wall time before each since the slot's previous call inside the step (or the step's start):
  /// the drivers' host work between the device's calls, when the device is idle.
  double waitSeconds = 0.0;
};

struct SlotStats {
  enum Call { SetPositions, InternalForces, Apply, Solve, ElasticEnergy, kCalls };
  long long calls = 0;          ///< device calls (solves: one per solve of a set)
  long long bodies = 0;         ///< bodies in them
  std::size_t largestCall = 0;  ///< most bodies in one call
  double deviceSeconds = 0.0;
  SlotCallStats byCall[kCalls];
};

/// "set_positions", "internal_forces", "apply", "solve", "elastic_energy".
const char* slotCallName(std::size_t call);

class DeviceSlot {
 public:
  /// Creates the first candidate's device that can be created for `problems` (which outlive the
  /// slot). With `fallbackAtCreate` false a failure of the first candidate is thrown as is (an
  /// explicit choice that cannot start is an error).
  DeviceSlot(std::vector<const Problem*> problems, const SolverDesc& solver, std::vector<Candidate> order,
             bool fallbackAtCreate, const DeviceOptions& options = {}, const Log& log = Log::none());
  /// A slot on a device the caller made (an application's own device, a test's), with no fallback.
  DeviceSlot(std::unique_ptr<Device> device, const SolverDesc& solver, const Log& log = Log::none());
  DeviceSlot(const DeviceSlot&) = delete;
  DeviceSlot& operator=(const DeviceSlot&) = delete;

  std::size_t bodyCount() const { return problems_.size(); }
  const Problem& problem(std::size_t body) const { return *problems_[body]; }
  const SolverDesc& solver() const { return solver_; }

  // The Device's calls, with failover.
  void setPositions(const BodySet& bodies, const ConstVectors& x);
  void internalForces(const BodySet& bodies, const Vectors& f);
  void apply(const BodySet& bodies, const std::vector<SystemCoeffs>& coeffs, const ConstVectors& p, const Vectors& y);
  void elasticEnergy(const BodySet& bodies, std::vector<double>& energy);
  /// The bodies' problems have new constrained dofs (Problem::constrained, changed by the caller):
  /// the device projects its later solves with them.
  void setConstraints(const BodySet& bodies);
  /// The bodies' problems have a new material (Problem::lame, rayleighMass, rayleighStiffness,
  /// changed by the caller): the device uses it from the next call.
  void setMaterial(const BodySet& bodies);
  /// The bodies' problems have new springs (Problem::springStiffness, changed by the caller).
  void setSprings(const BodySet& bodies);
  /// Removes body `body` (later bodies' indices move down by one): in place where the device can
  /// (Device::removeBody), else the device is made again on the same candidate for the other
  /// bodies (their problems carry their constraints, material and springs), given their last
  /// positions, and the old one with every buffer of the removed body goes. Throws (with nothing
  /// changed) where the new device cannot be made, or Error(Internal) for the slot's only body.
  void removeBody(std::size_t body);
  /// The linear solves of `bodies` as the solver asks for them: PCG for the set (solvePcg), or the
  /// device's direct solve body by body (Cholesky). Per-body failures in `solves[i].failure`.
  void solve(const BodySet& bodies, std::vector<PcgSolve>& solves);

  /// The device in use now (changes on a failover); owned by the slot.
  Device& device() const { return *device_; }
  const Candidate& current() const { return order_[index_]; }
  const std::vector<Candidate>& order() const { return order_; }
  /// A step store that sets positions on the device itself (not through setPositions) names them
  /// here: `source(body, x)` gives the positions of the store's state the body's were last set
  /// from (the same numbers until the store writes that state again, which the dynamics driver does
  /// only before it sets positions again), for a device the slot makes (a failover, a removed
  /// body); positionsSetElsewhere marks the bodies whose last positions are the source's.
  using PositionSource = std::function<void(std::size_t body, Eigen::VectorXd& x)>;
  void setPositionSource(const void* owner, PositionSource source);
  /// Drops the source if `owner` set it (a store that goes leaves its successor's).
  void dropPositionSource(const void* owner);
  void positionsSetElsewhere(const BodySet& bodies);
  /// Moves the bodies to the next candidate after a DeviceError in a call the slot did not make (a
  /// step store's own call on the device): as a failing call of the slot would, or throws the
  /// slot's DeviceError when no candidate is left. While the slot reads a store's positions for a
  /// failover already, it throws `error` back to that read instead.
  void failover(const std::string& call, const Error& error);
  /// fn() counted in stats() as a call `call` of the bodies (its time; in a step its place in
  /// byCall, with the host's wait since the slot's last call), with no failover: a step store's
  /// own call on the device (the store fails over itself, failover()), so that a step's calls
  /// count the same whichever store holds its vectors.
  template <class Fn>
  void counted(SlotStats::Call call, const BodySet& bodies, Fn&& fn);

  /// Labels the events that follow ("step 3").
  void setWhen(const std::string& when) { when_ = when; }
  const std::vector<FallbackEvent>& events() const { return events_; }
  /// Every candidate failed: each call throws the slot's DeviceError.
  bool exhausted() const { return exhausted_; }
  /// Devices made since the first, by failovers and removed bodies (a surface made for the device
  /// of before must be made again).
  std::size_t generation() const { return generation_; }
  /// Failovers so far (0: the bodies run on the device they were scheduled on).
  std::size_t failovers() const { return failovers_; }

  /// Starts a step: the calls until endStep() count in stats().byCall, with the host's waits
  /// between them (waitSeconds).
  void beginStep();
  void endStep() { inStep_ = false; }
  const SlotStats& stats() const { return stats_; }

 private:
  /// fn(device), repeated on the next candidate after a DeviceError.
  template <class Fn>
  void withFailover(const std::string& call, Fn&& fn);
  template <class Fn>
  void guarded(SlotStats::Call call, const BodySet& bodies, Fn&& fn);
  /// A call from start to end in stats_.
  void count(SlotStats::Call call, const BodySet& bodies, std::chrono::steady_clock::time_point start,
             std::chrono::steady_clock::time_point end);
  /// Moves to the next candidate that can be created and given the last positions; throws
  /// Error(DeviceError) listing every failure when none is left.
  void advance(const std::string& call, const std::string& error);
  /// Throws the DeviceError of a slot whose every candidate failed, naming the failures and the fix.
  [[noreturn]] void failExhausted() const;

  std::vector<const Problem*> problems_;
  SolverDesc solver_;
  DeviceOptions options_;
  const Log& log_;
  std::vector<Candidate> order_;
  std::size_t index_ = 0;
  std::unique_ptr<Device> device_;  ///< never null once constructed
  bool exhausted_ = false;          ///< every candidate failed: each call is a DeviceError
  std::vector<Eigen::VectorXd> lastX_;  ///< per body: the last positions given (empty: none yet)
  std::vector<char> elsewhere_;         ///< per body: its last positions are the source's
  PositionSource source_;
  const void* sourceOwner_ = nullptr;
  bool refreshing_ = false;  ///< refreshPositions is reading the source
  /// lastX_ of the bodies positionsSetElsewhere marked, from the source.
  void refreshPositions();
  std::string when_ = "create";
  std::vector<FallbackEvent> events_;
  std::string failures_;  ///< every device error so far (for the final message)
  std::size_t generation_ = 0;
  std::size_t failovers_ = 0;
  bool given_ = false;  ///< the device was the caller's (no candidate to make another from)
  SlotStats stats_;
  bool inStep_ = false;
  std::chrono::steady_clock::time_point lastEnd_;
  std::vector<Eigen::VectorXd> solveStart_;  ///< the solves' starting vectors, restored before a repeat
};

template <class Fn>
void DeviceSlot::counted(SlotStats::Call call, const BodySet& bodies, Fn&& fn) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  fn();
  count(call, bodies, start, Clock::now());
}

}  // namespace corofem::detail
