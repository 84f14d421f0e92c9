// BatchGroup: one Backend view per body over a shared BatchDevice, and the rendezvous that turns
// the bodies' concurrent Backend calls into rounds (solve/batch.hpp explains the design).
//
// Rendezvous (all under one mutex; a body is Out, Running or Waiting):
//   startStep(bodies, step)  every listed body whose view is alive becomes Running, and step(k) runs
//                            for each as a fiber (util/fiber.hpp) on one of a few worker threads
//                            (a thread per usable CPU), which resumes each of its fibers whenever
//                            it can go on; or, without fibers, on a worker thread of its own. The
//                            pool is persistent: no thread or fiber stack is created per step once
//                            it has grown to the largest step.
//   a view call              Running -> Waiting with its request posted. When no body is Running
//                            any more (every body still inside the step is Waiting) and no round is
//                            in progress, one Waiting thread takes every posted request, runs the
//                            round on the device without holding the lock, marks the answered
//                            bodies Running again and wakes them.
//   step(k) returns/throws   the body leaves (Running -> Out): the others no longer wait for it.
//   the view is destroyed    (a FailoverBackend replaced it) the body leaves the same way and its
//                            further calls go to its new backend, outside the group.
//   a call by an Out body    a round of one, serialised with every other round on the device.
// Invariant: Running + Waiting bodies are exactly the attached bodies inside the step that have
// neither finished nor left; a round starts only when Running == 0, so every round holds the call
// each of them makes next (at most one per body), and the step ends because every body either
// posts (and is answered by the next round), finishes or leaves.
#pragma once

#include "solve/batch.hpp"

#include <exception>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// The rounds of one kind of call inside steps (BatchGroupStats::byCall).
struct BatchCallStats {
  long long rounds = 0;        ///< rounds inside a step whose requests were all this call
  long long requests = 0;      ///< their requests
  double deviceSeconds = 0.0;  ///< wall time inside BatchDevice::run
  /// Wall time before each of them since the end of the group's previous round inside the step (or
  /// the step's start): the bodies' host work between their calls and the rendezvous, when the
  /// device is idle (or busy with a round of one for a body outside the step, which is counted here).
  double waitSeconds = 0.0;
};

/// What a group's device has done so far.
struct BatchGroupStats {
  long long rounds = 0;         ///< rounds run (batched rounds and rounds of one)
  long long requests = 0;       ///< requests answered
  std::size_t largestRound = 0; ///< most requests in one round
  double deviceSeconds = 0.0;   ///< wall time inside BatchDevice::run (the rest of a step is the drivers' host work and the rendezvous)
  /// The rounds inside steps by call, indexed by BatchOp; a round of several kinds of call (bodies
  /// at different points of their step) counts under kMixedCalls.
  static constexpr std::size_t kMixedCalls = 5;
  BatchCallStats byCall[kMixedCalls + 1];
};

/// The name of BatchGroupStats::byCall[i] in reports: "set_positions", "internal_forces", "apply",
/// "solve", "elastic_energy", "mixed".
const char* batchCallName(std::size_t i);

class BatchGroup {
 public:
  explicit BatchGroup(std::unique_ptr<BatchDevice> device);
  /// Joins the worker threads. Views may outlive the group (their calls are then rounds of one).
  ~BatchGroup();
  BatchGroup(const BatchGroup&) = delete;
  BatchGroup& operator=(const BatchGroup&) = delete;

  std::size_t bodyCount() const;
  std::string name() const;
  std::string deviceName() const;
  std::size_t allocatedBytes() const;
  std::vector<DeviceBuffer> deviceBuffers() const;  ///< the buffers its bodies share
  BatchGroupStats stats() const;

  /// The Backend of body `body` (< bodyCount()): its calls are requests of the group's rounds.
  /// At most one view of a body is alive at a time (Error(Internal) otherwise). One thread at a
  /// time calls a view (the body's driver).
  std::unique_ptr<Backend> view(std::size_t body);
  /// True while the body's view is alive.
  bool attached(std::size_t body) const;
  /// BatchDevice::devicePositions of `body` (whether or not it is still attached).
  bool devicePositions(std::size_t body, DevicePositions& out) const;

  /// Starts step(k) for every k in `bodies` (distinct, < bodyCount()), each as a fiber of one of
  /// fiberWorkers() threads (or on a thread of its own), and returns at once. A step(k) must not
  /// hold a lock across a view call: as a fiber it suspends there and its thread runs others. One step at a time: finishStep() before the next startStep().
  void startStep(const std::vector<std::size_t>& bodies, std::function<void(std::size_t)> step);
  /// Waits for every step(k) of the step started last; returns what each threw (null = returned
  /// normally), in the order of `bodies`.
  std::vector<std::exception_ptr> finishStep();
  /// startStep + finishStep.
  std::vector<std::exception_ptr> runStep(const std::vector<std::size_t>& bodies, std::function<void(std::size_t)> step);

  /// The threads that run a step's bodies as fibers (0: a thread per body, as where fibers are not
  /// available, which makes this 0 whatever is asked). Default: COROFEM_BATCH_FIBERS if set, else
  /// the usable CPUs. `stackBytes`: each fiber's stack (0: 8 MiB, a thread's default). Where a
  /// step cannot map the stacks, the group gives each body a thread from then on (fiberWorkers()
  /// then says 0). Between steps only.
  void setFiberWorkers(std::size_t workers, std::size_t stackBytes = 0);
  std::size_t fiberWorkers() const;

  struct Shared;  ///< rendezvous state, shared with the views (batch_group.cpp)
  struct Pool;    ///< the worker threads

 private:
  std::shared_ptr<Shared> shared_;
  std::unique_ptr<Pool> pool_;
};

/// Creates the batch device for bodies scheduled on one OpenCL device: createOpenCLBatchDevice, or
/// the factory set by setBatchDeviceFactoryForTesting.
std::unique_ptr<BatchDevice> createBatchDeviceFor(const std::vector<const Problem*>& problems, const SolverDesc& solver,
                                                  const std::string& deviceSelector, const OpenCLTuning& tuning = {});

using BatchDeviceFactory = std::function<std::unique_ptr<BatchDevice>(
    const std::vector<const Problem*>& problems, const SolverDesc& solver, const std::string& deviceSelector)>;
/// Test hook (not thread-safe; reset with an empty function). While set, the Simulation also
/// batches bodies whose first candidate is not an OpenCL device (fake candidates of the tests).
void setBatchDeviceFactoryForTesting(BatchDeviceFactory factory);
bool batchDeviceFactoryForTesting();

}  // namespace corofem::detail
