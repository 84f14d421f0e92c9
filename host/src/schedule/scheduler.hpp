// Host scheduler: where each body runs (reference backend, an OpenCL GPU, the PoCL CPU device),
// failover to the next candidate when a device fails, and the plan of a scene.
//
// Decision for one body (scheduleBody):
//   1. An explicit choice wins: the scene's / API's "backend" when it is not "auto", else the
//      COROFEM_DEVICE environment variable ("reference", "opencl", "opencl:1", "opencl:pthread").
//   2. "auto": hyperelastic formulations and the Cholesky solver go to the reference backend (the
//      only one that has them); so does a body below BackendDesc::minDeviceElements elements (a device launch
//      then costs more than the whole step; measured numbers in docs/scene-format.md).
//   3. Otherwise every candidate runs a short calibration: a fresh backend and driver on the body's
//      own problem take the scene's first step (one warm-up, then up to kCalibrationRepeats timed
//      repetitions, each undone with rollback()), and the median wall time per step decides. The
//      times are kept in a cache file keyed by backend, device name, driver version, analysis kind,
//      precision, linear solver and log2 of the element count, so that the next run of a scene of
//      the same size decides without calibrating.
//
// Failover (FailoverBackend): a body's backend is a Backend decorator over an ordered list of
// candidates (the choice first, the reference backend last). When a call throws
// Error(DeviceError) (program build, allocation, launch, read-back), the next candidate is created,
// given the last positions, and the same call is repeated on it with the same inputs (solve's warm
// start is restored first). Every other Backend output is a function of the positions and the
// call's arguments, so the driver above never notices: its state (positions, velocities,
// accelerations) simply carries on.
#pragma once

#include "model/problem.hpp"
#include "solve/backend.hpp"

#include <corofem/scene.hpp>

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

/// Timed repetitions of the calibration step (after one warm-up).
constexpr int kCalibrationRepeats = 3;
/// Calibration stops early once one candidate has spent this long (s) on it.
constexpr double kCalibrationBudgetSeconds = 2.0;

/// One place a body can run.
struct Candidate {
  BackendKind kind = BackendKind::Reference;
  std::string device;    ///< device name (the reference: "host (Eigen, double)")
  std::string selector;  ///< OpenCL: the selector passed to the backend (device index as text)
  std::string driver;    ///< driver version (part of the cache key)
  bool gpu = false;
  /// "reference" or "opencl:1 (pthread-cpu)".
  std::string label() const;
};

/// The candidates of this build and machine: OpenCL GPUs, then the other OpenCL devices (the PoCL
/// CPU device), then the reference backend (always present, always last).
std::vector<Candidate> listCandidates();

/// An explicit backend request (scene, API or COROFEM_DEVICE).
struct DeviceRequest {
  BackendKind kind = BackendKind::Auto;  ///< Auto = no explicit request
  std::string device;                    ///< OpenCL device index or name substring ("" = default)
  std::string source;                    ///< "scene", "COROFEM_DEVICE"
};

/// Parses "reference", "opencl", "opencl:<index>", "opencl:<name substring>" or "auto". Throws
/// Error(BadInput) naming `source` and listing the choices for anything else.
DeviceRequest parseDeviceSpec(const std::string& spec, const std::string& source);
/// The request in force: the scene's backend when not "auto" (or "auto" with a device named: that
/// OpenCL device), else COROFEM_DEVICE when set.
DeviceRequest requestedDevice(const Scene& scene);

struct CandidateTiming {
  Candidate candidate;
  double msPerStep = std::numeric_limits<double>::quiet_NaN();  ///< median; NaN when not measured
  bool fromCache = false;
  std::string error;  ///< why the candidate cannot run this body ("" = it can)
};

/// The scheduler's decision for one body.
struct BodySchedule {
  std::string body;
  std::vector<Candidate> order;  ///< the choice first, then the fallbacks in order
  std::string reason;
  std::vector<CandidateTiming> timings;  ///< empty when no calibration was needed
  bool fromCache = false;                ///< every timing came from the cache file
  bool explicitChoice = false;
  const Candidate& choice() const { return order.front(); }
};

/// A device failure survived by moving a body to another backend.
struct FallbackEvent {
  std::string body;
  std::string when;   ///< "create", "step 3"
  std::string call;   ///< Backend call that failed ("solve", "setPositions", "create")
  std::string from, to;  ///< candidate labels
  std::string error;  ///< the device error's message
};

using BackendFactory =
    std::function<std::unique_ptr<Backend>(const Problem&, const SolverDesc&, const Candidate&)>;

/// Creates the backend of a candidate (through the test factory when one is set).
std::unique_ptr<Backend> createBackendFor(const Problem& problem, const SolverDesc& solver, const Candidate& c,
                                          const OpenCLTuning& tuning = {});

/// Test hooks (not thread-safe; reset with an empty SchedulerHooks{}).
struct SchedulerHooks {
  BackendFactory factory;             ///< replaces the real backend factory when set
  std::vector<Candidate> candidates;  ///< replaces listCandidates() when non-empty
  /// When non-empty: every body runs on this order as given, no calibration (failover tests).
  std::vector<Candidate> forcedOrder;
};
void setSchedulerHooksForTesting(SchedulerHooks hooks);

/// Decides where one body runs (see the top of this file). Never calibrates for an explicit
/// choice. Throws Error(BadInput) for a bad COROFEM_DEVICE or a formulation the explicit backend
/// lacks.
BodySchedule scheduleBody(const BodyDesc& desc, const Problem& problem, const Scene& scene,
                          const OpenCLTuning& tuning = {});

/// scheduler.json in the cache folder (util/cache_dir.hpp: $COROFEM_CACHE_DIR, else
/// $XDG_CACHE_HOME/corofem, else ~/.cache/corofem; "" when there is none).
std::string schedulerCachePath();

/// What the calibration cache's times were measured with: corofem's version and, in OpenCL builds,
/// a hash of the kernel program's source; part of every cache key, so that another build (a new
/// release or kernel may change which candidate is faster) measures again, while the entries of
/// builds sharing the file stay.
std::string calibrationBuild();

/// log2 of the element count, rounded down (the cache's size bucket).
int sizeBucket(std::size_t elements);

/// JSON text of a schedule: {"body", "choice", "backend", "device", "reason", "from_cache",
/// "candidates": [{"backend", "device", "ms_per_step", "from_cache", "error"}], "fallback_order"}.
std::string scheduleJson(const BodySchedule& s);
std::string fallbackJson(const FallbackEvent& e);

/// Backend decorator that moves to the next candidate on Error(DeviceError).
class FailoverBackend final : public Backend {
 public:
  /// Creates the first candidate that can be created. With `fallbackAtCreate` false a failure of
  /// the first candidate is thrown as is (an explicit choice that cannot start is an error).
  FailoverBackend(const Problem& problem, const SolverDesc& solver, std::vector<Candidate> order,
                  bool fallbackAtCreate, const OpenCLTuning& tuning = {});
  /// Starts on `first`, an already-made backend that stands for order[0] (a body's view of a
  /// batch, solve/batch_group.hpp); a device failure moves to order[1], order[2], ... as above.
  FailoverBackend(const Problem& problem, const SolverDesc& solver, std::vector<Candidate> order,
                  std::unique_ptr<Backend> first, const OpenCLTuning& tuning = {});
  ~FailoverBackend() override;

  std::string name() const override;
  std::string deviceName() const override;
  void setPositions(const Eigen::VectorXd& x) override;
  void internalForces(Eigen::VectorXd& f) override;
  void apply(const SystemCoeffs& c, const Eigen::VectorXd& p, Eigen::VectorXd& y) override;
  LinearSolveStats solve(const SystemCoeffs& c, const Eigen::VectorXd& b, Eigen::VectorXd& x) override;
  double elasticEnergy() override;
  std::vector<DeviceBuffer> deviceBuffers() const override;
  bool devicePositions(DevicePositions& out) const override;  ///< the active backend's

  /// Labels the events that follow ("step 3").
  void setWhen(const std::string& when) { when_ = when; }
  const Candidate& current() const { return order_[index_]; }
  /// The backend in use now (changes on a failover); owned by this object.
  Backend* active() const { return current_.get(); }
  const std::vector<FallbackEvent>& events() const { return events_; }

 private:
  template <class Fn>
  auto guarded(const char* call, Fn&& fn) -> decltype(fn(std::declval<Backend&>()));
  /// Moves to the next candidate that can be created and given the last positions; throws
  /// Error(DeviceError) listing every failure when none is left.
  void advance(const std::string& call, const std::string& error);

  const Problem& problem_;
  SolverDesc solver_;
  OpenCLTuning tuning_;
  std::vector<Candidate> order_;
  std::size_t index_ = 0;
  std::unique_ptr<Backend> current_;
  Eigen::VectorXd lastX_;
  Eigen::VectorXd solveStart_;  ///< solve()'s copy of the warm start
  bool havePositions_ = false;
  std::string when_ = "create";
  std::vector<FallbackEvent> events_;
  std::string failures_;  ///< every device error so far (for the final message)
};

/// The plan of one body as JSON text: backend, features in use, buffers with their sizes and the
/// estimated bytes moved per step (model in plan.cpp). `batchMates`: the names of the bodies
/// (this one included) that share the device's buffers and launches with it, empty when it runs
/// alone (solve/batch_group.hpp).
std::string planJson(const BodyDesc& desc, const Problem& problem, const Scene& scene,
                     const BodySchedule& schedule, const std::vector<std::string>& batchMates = {});

}  // namespace corofem::detail
