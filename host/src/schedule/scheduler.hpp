// Host scheduler: where each body runs (reference backend, an OpenCL GPU, the PoCL CPU device),
// failover to the next candidate when a device fails, and the plan of a scene.
//
// Decision for one body (scheduleBody), over the backends of the registry (device/registry.hpp):
//   1. An order the application gives (SimulationOptions::devices) is taken as it is.
//   2. An explicit choice wins: the scene's / API's "backend" when it is not "auto", else the
//      COROFEM_DEVICE environment variable ("reference", "opencl", "opencl:1", "opencl:pthread";
//      any registered backend's name, with ":" and its device selector).
//   3. "auto": a body that no device backend can run (hyperelastic formulations, the Cholesky
//      solver) goes to the reference backend; so does a body below BackendDesc::minDeviceElements
//      elements (a device launch then costs more than the whole step; docs/scene-format.md).
//   4. Otherwise every candidate runs a short calibration: a fresh backend and driver on the body's
//      own problem take the scene's first step (one warm-up, then up to kCalibrationRepeats timed
//      repetitions, each undone with rollback()), and the median wall time per step decides. The
//      times are kept in a cache file keyed by backend, device name, driver version, analysis kind,
//      precision, linear solver and log2 of the element count, so that the next run of a scene of
//      the same size decides without calibrating.
//
// Failover runs on the order a schedule gives (the choice first, the reference backend last): a
// DeviceSlot (solve/device_slot.hpp) moves its bodies to the next candidate when a device fails.
#pragma once

#include "device/registry.hpp"
#include "model/problem.hpp"
#include "solve/device_slot.hpp"

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

/// The candidates of this build and machine, over every registered backend: GPUs first, then
/// the other devices (the PoCL CPU device), then the reference backend (always present, last).
std::vector<Candidate> listCandidates();

/// An explicit backend request (scene, API or COROFEM_DEVICE).
struct DeviceRequest {
  std::string backend;  ///< the registered backend's name; "" = no explicit request ("auto")
  std::string device;   ///< the backend's device selector (OpenCL: index or name substring; "" = default)
  std::string source;   ///< "scene", "COROFEM_DEVICE"
};

/// Parses "auto", "<backend>" or "<backend>:<device selector>" for a registered backend
/// ("reference", "opencl", "opencl:1", "opencl:pthread"). Throws Error(BadInput) naming `source`
/// and listing the choices for anything else.
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

/// Decides where one body runs (see the top of this file). Never calibrates for an explicit
/// choice. `devices`: an order the application gives ("<backend>[:<selector>]" each), else empty.
/// Throws Error(BadInput) for a bad COROFEM_DEVICE or device entry, or a body the explicit backend
/// cannot run.
BodySchedule scheduleBody(const BodyDesc& desc, const Problem& problem, const Scene& scene,
                          const DeviceOptions& options = {}, const std::vector<std::string>& devices = {});

/// scheduler.json in the cache folder (util/cache_dir.hpp: $COROFEM_CACHE_DIR, else
/// %LOCALAPPDATA%\corofem on Windows, else $XDG_CACHE_HOME/corofem, else ~/.cache/corofem; "" when
/// there is none).
std::string schedulerCachePath();

/// What the calibration cache's times were measured with: corofem's version and every registered
/// backend's build id (a hash of its kernel source); part of every cache key, so that another build
/// (a new release or kernel may change which candidate is faster) measures again, while the entries
/// of builds sharing the file stay.
std::string calibrationBuild();

/// log2 of the element count, rounded down (the cache's size bucket).
int sizeBucket(std::size_t elements);

/// JSON text of a schedule: {"body", "choice", "backend", "device", "reason", "from_cache",
/// "candidates": [{"backend", "device", "ms_per_step", "from_cache", "error"}], "fallback_order"}.
std::string scheduleJson(const BodySchedule& s);
std::string fallbackJson(const FallbackEvent& e);

/// The plan of one body as JSON text: backend, features in use, buffers with their sizes and the
/// estimated bytes moved per step (model in plan.cpp). `batchMates`: the names of the bodies
/// (this one included) that share the device's buffers and launches with it, empty when it runs
/// alone (a batch: solve/driver.hpp).
std::string planJson(const BodyDesc& desc, const Problem& problem, const Scene& scene,
                     const BodySchedule& schedule, const std::vector<std::string>& batchMates = {});

}  // namespace corofem::detail
