// Scheduler: candidates, explicit requests, calibration and its cache (see scheduler.hpp).
#include "schedule/scheduler.hpp"

#include "solve/body_solver.hpp"
#include "util/cache_dir.hpp"
#include "util/error.hpp"

#ifdef COROFEM_WITH_OPENCL
#include "backends/opencl/cl_context.hpp"
#include "backends/opencl/program_cache.hpp"
#endif

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

namespace corofem::detail {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

SchedulerHooks& hooks() {
  static SchedulerHooks h;
  return h;
}

bool isHyperelastic(Formulation f) {
  return f == Formulation::StVenantKirchhoff || f == Formulation::NeoHookean;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

const char* kindName(BackendKind k) { return k == BackendKind::OpenCL ? "opencl" : "reference"; }

Candidate referenceCandidate() {
  Candidate c;
  c.kind = BackendKind::Reference;
  c.device = "host (Eigen, double)";
  c.driver = "corofem";
  return c;
}

std::string choicesText() {
  std::string s = "choices: \"auto\", \"reference\", \"opencl\" (first GPU, else first device), "
                  "\"opencl:<index>\" or \"opencl:<device name substring>\"";
  std::vector<Candidate> cands = listCandidates();
  std::string devices;
  for (const Candidate& c : cands)
    if (c.kind == BackendKind::OpenCL) devices += (devices.empty() ? "" : ", ") + c.label();
  s += devices.empty() ? "; this build/machine has no OpenCL device" : "; devices here: " + devices;
  return s;
}

// ------------------------------------------------------------------ cache
std::string cacheKey(const Candidate& c, const Scene& scene, std::size_t elements) {
  std::ostringstream os;
  os << kindName(c.kind) << '|' << c.device << '|' << c.driver << '|'
     << (scene.analysis.kind == AnalysisDesc::Kind::Static ? "static" : "dynamic") << '|'
     << (scene.solver.precision == Precision::Float ? "float" : "double") << '|'
     << (scene.solver.linearSolver == LinearSolverKind::Cholesky ? "cholesky" : "pcg") << "|log2e="
     << sizeBucket(elements) << "|build=" << calibrationBuild();
  return os.str();
}

json readCache(const std::string& path) {
  if (path.empty()) return json::object();
  std::ifstream in(path);
  if (!in) return json::object();
  try {
    json j = json::parse(in);
    if (j.is_object() && j.contains("entries") && j["entries"].is_object()) return j;
  } catch (const std::exception&) {
    // A damaged cache is only a lost measurement: calibrate again and rewrite it.
  }
  return json::object();
}

void writeCache(const std::string& path, const json& j) {
  if (path.empty()) return;
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  // Written to a temporary and renamed, so that a concurrent reader never sees half a file.
  const std::string tmp = path + ".tmp" + std::to_string(static_cast<long long>(
                                              std::chrono::steady_clock::now().time_since_epoch().count() % 1000000007));
  {
    std::ofstream out(tmp);
    if (!out) return;
    out << j.dump(2) << '\n';
    if (!out) return;
  }
  fs::rename(tmp, path, ec);
  if (ec) fs::remove(tmp, ec);
}

// ------------------------------------------------------------------ calibration
/// Median wall time (ms) of the body's first step on candidate c: one warm-up, then up to
/// kCalibrationRepeats repetitions, each undone by rollback() so that every repetition is the
/// same step. Throws whatever the backend or the driver throws.
double calibrate(const Problem& problem, const Scene& scene, const Candidate& c, const OpenCLTuning& tuning) {
  std::unique_ptr<Backend> backend = createBackendFor(problem, scene.solver, c, tuning);
  std::unique_ptr<BodySolver> solver = createBodySolver(problem, *backend, scene.analysis);
  const int count = scene.analysis.kind == AnalysisDesc::Kind::Static ? std::max(1, scene.analysis.statics.increments)
                                                                      : std::max(1, scene.analysis.dynamics.steps);
  using Clock = std::chrono::steady_clock;
  const auto begin = Clock::now();
  auto timeStep = [&] {
    const auto t0 = Clock::now();
    solver->step(1, count);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    solver->rollback();
    return ms;
  };
  std::vector<double> samples{timeStep()};  // warm-up (first launches, lazy set-up)
  for (int i = 0; i < kCalibrationRepeats; ++i) {
    if (std::chrono::duration<double>(Clock::now() - begin).count() > kCalibrationBudgetSeconds) break;
    if (i == 0) samples.clear();  // the warm-up counts only when there is no time for more
    samples.push_back(timeStep());
  }
  std::sort(samples.begin(), samples.end());
  const std::size_t n = samples.size();
  return n % 2 ? samples[n / 2] : 0.5 * (samples[n / 2 - 1] + samples[n / 2]);
}

std::string formatMs(double ms) {
  std::ostringstream os;
  os.precision(3);
  os << ms << " ms/step";
  return os.str();
}

}  // namespace

std::string calibrationBuild() {
  std::string build = std::string("corofem ") + COROFEM_VERSION;
#ifdef COROFEM_WITH_OPENCL
  std::ostringstream hex;
  hex << std::hex << cl::fnv1a64(cl::corofemProgramSource());
  build += ", kernels " + hex.str();
#endif
  return build;
}

std::string Candidate::label() const {
  if (kind == BackendKind::Reference)
    return device.empty() || device == referenceCandidate().device ? "reference" : "reference (" + device + ")";
  return "opencl:" + selector + " (" + device + ")";
}

std::vector<Candidate> listCandidates() {
  if (!hooks().candidates.empty()) return hooks().candidates;
  std::vector<Candidate> out;
#ifdef COROFEM_WITH_OPENCL
  const std::vector<cl::DeviceInfo> devices = cl::listDevices();
  for (int pass = 0; pass < 2; ++pass)  // GPUs first
    for (std::size_t i = 0; i < devices.size(); ++i) {
      if (devices[i].gpu != (pass == 0)) continue;
      Candidate c;
      c.kind = BackendKind::OpenCL;
      c.device = devices[i].name;
      c.selector = std::to_string(i);
      c.driver = devices[i].platformName + " " + devices[i].driverVersion;
      c.gpu = devices[i].gpu;
      out.push_back(c);
    }
#endif
  out.push_back(referenceCandidate());
  return out;
}

DeviceRequest parseDeviceSpec(const std::string& spec, const std::string& source) {
  DeviceRequest r;
  r.source = source;
  const std::string s = lower(spec);
  const std::size_t colon = s.find(':');
  const std::string head = s.substr(0, colon);
  const std::string tail = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (head == "auto" && colon == std::string::npos) return r;
  if (head == "reference" && colon == std::string::npos) {
    r.kind = BackendKind::Reference;
    return r;
  }
  if (head == "opencl" && (colon == std::string::npos || !tail.empty())) {
    r.kind = BackendKind::OpenCL;
    r.device = tail;
    return r;
  }
  fail(ErrorCode::BadInput, source, "=\"", spec, "\" is not a backend; ", choicesText());
}

DeviceRequest requestedDevice(const Scene& scene) {
  if (scene.backend.kind != BackendKind::Auto) {
    DeviceRequest r;
    r.kind = scene.backend.kind;
    r.device = scene.backend.device;
    r.source = "scene";
    return r;
  }
  // "auto" with a device named: the user chose that OpenCL device ("" is the scheduler's choice).
  if (!scene.backend.device.empty()) {
    DeviceRequest r;
    r.kind = BackendKind::OpenCL;
    r.device = scene.backend.device;
    r.source = "the scene (\"backend.device\": \"" + scene.backend.device + "\")";
    return r;
  }
  if (const char* env = std::getenv("COROFEM_DEVICE"); env && *env) return parseDeviceSpec(env, "COROFEM_DEVICE");
  return {};
}

std::unique_ptr<Backend> createBackendFor(const Problem& problem, const SolverDesc& solver, const Candidate& c,
                                          const OpenCLTuning& tuning) {
  if (hooks().factory) return hooks().factory(problem, solver, c);
  if (c.kind == BackendKind::OpenCL) return createOpenCLBackend(problem, solver, c.selector, tuning);
  return createReferenceBackend(problem, solver);
}

void setSchedulerHooksForTesting(SchedulerHooks h) { hooks() = std::move(h); }

int sizeBucket(std::size_t elements) {
  int b = 0;
  while (elements > 1) {
    elements >>= 1;
    ++b;
  }
  return b;
}

std::string schedulerCachePath() {
  const std::string dir = cacheDirectory();
  return dir.empty() ? dir : (fs::path(dir) / "scheduler.json").string();
}

BodySchedule scheduleBody(const BodyDesc& desc, const Problem& problem, const Scene& scene,
                          const OpenCLTuning& tuning) {
  BodySchedule s;
  s.body = desc.name;
  const Candidate reference = referenceCandidate();

  if (!hooks().forcedOrder.empty()) {
    s.order = hooks().forcedOrder;
    s.reason = "order forced by a test hook";
    s.explicitChoice = false;  // falls back at create too (the build-failure test)
    return s;
  }

  const DeviceRequest req = requestedDevice(scene);
  if (req.kind == BackendKind::Reference) {
    s.order = {reference};
    s.reason = "requested by " + (req.source == "scene" ? std::string("the scene (\"backend\": \"reference\")") : req.source);
    s.explicitChoice = true;
    return s;
  }
  if (req.kind == BackendKind::OpenCL) {
    if (isHyperelastic(desc.formulation))
      fail(ErrorCode::BadInput, "body '", desc.name, "': the ", toString(desc.formulation),
           " formulation runs only on the reference backend; set \"backend\": \"reference\" "
           "or use the \"corotational\" or \"linear\" formulation");
    Candidate c;
    c.kind = BackendKind::OpenCL;
    c.selector = req.device;
    c.device = req.device.empty() ? "default OpenCL device" : req.device;
#ifdef COROFEM_WITH_OPENCL
    // Resolve the selector to the device's index so that the label and the cache name it. An
    // unknown selector is left as given: the backend's DeviceError lists the devices.
    if (hooks().candidates.empty()) {
      try {
        const cl::DeviceInfo info = cl::selectDevice(req.device);
        const std::vector<cl::DeviceInfo> all = cl::listDevices();
        for (std::size_t i = 0; i < all.size(); ++i)
          if (all[i].device == info.device) {
            c.selector = std::to_string(i);
            c.device = info.name;
            c.driver = info.platformName + " " + info.driverVersion;
            c.gpu = info.gpu;
          }
      } catch (const Error&) {
      }
    }
#endif
    s.order = {c, reference};
    s.reason = "requested by " + (req.source == "scene" ? std::string("the scene (\"backend\": \"opencl\")") : req.source);
    s.explicitChoice = true;
    return s;
  }

  // "auto"
  std::vector<Candidate> candidates = listCandidates();
  auto onlyReference = [&](const std::string& why) {
    s.order = {reference};
    s.reason = why;
    return s;
  };
  if (isHyperelastic(desc.formulation))
    return onlyReference(std::string("the ") + toString(desc.formulation) + " formulation runs only on the reference backend");
  if (scene.solver.linearSolver == LinearSolverKind::Cholesky)
    return onlyReference("the Cholesky solver runs only on the reference backend");
  if (candidates.size() == 1) return onlyReference("no OpenCL device in this build or on this machine");
  const std::size_t elements = problem.elements.size();
  const std::size_t minElements = scene.backend.minDeviceElements;
  if (elements < minElements && hooks().candidates.empty())
    return onlyReference(std::to_string(elements) + " elements is below " + std::to_string(minElements) +
                         " (backend.min_device_elements): a device launch costs more than the whole step");

  const std::string path = schedulerCachePath();
  json cache = readCache(path);
  if (!cache.contains("entries")) cache = json{{"version", 1}, {"entries", json::object()}};
  bool allCached = true, wroteAny = false;
  for (const Candidate& c : candidates) {
    CandidateTiming t;
    t.candidate = c;
    const std::string key = cacheKey(c, scene, elements);
    const json& entries = cache["entries"];
    if (entries.contains(key)) {
      const json& e = entries[key];
      t.fromCache = true;
      if (e.contains("ms_per_step") && e["ms_per_step"].is_number()) t.msPerStep = e["ms_per_step"].get<double>();
      if (e.contains("error") && e["error"].is_string()) t.error = e["error"].get<std::string>();
      if (!std::isnan(t.msPerStep) || !t.error.empty()) {
        s.timings.push_back(t);
        continue;
      }
    }
    t.fromCache = false;
    allCached = false;
    try {
      t.msPerStep = calibrate(problem, scene, c, tuning);
    } catch (const Error& e) {
      t.error = std::string(toString(e.code())) + ": " + e.what();
    } catch (const std::exception& e) {
      t.error = e.what();
    }
    // Solve failures depend on the body, not the device: they are not cached.
    if (t.error.empty() || t.error.rfind(toString(ErrorCode::SolveFailed), 0) != 0) {
      json e = json::object();
      if (t.error.empty()) e["ms_per_step"] = t.msPerStep;
      else e["error"] = t.error;
      cache["entries"][key] = e;
      wroteAny = true;
    }
    s.timings.push_back(t);
  }
  if (wroteAny) writeCache(path, cache);
  s.fromCache = allCached;

  // Rank the candidates that ran by time; the reference backend is always the last fallback.
  std::vector<const CandidateTiming*> ok;
  for (const CandidateTiming& t : s.timings)
    if (t.error.empty() && !std::isnan(t.msPerStep)) ok.push_back(&t);
  std::stable_sort(ok.begin(), ok.end(), [](auto* a, auto* b) { return a->msPerStep < b->msPerStep; });
  // Devices in order of speed, then the reference backend (the last resort of every body; when it
  // is the fastest it is the only entry: nothing falls back from it).
  const bool referenceFirst = !ok.empty() && ok.front()->candidate.kind == BackendKind::Reference;
  for (const CandidateTiming* t : ok)
    if (!referenceFirst && t->candidate.kind != BackendKind::Reference) s.order.push_back(t->candidate);
  s.order.push_back(reference);
  if (ok.empty()) {
    s.reason = "calibration failed on every candidate (see candidates); the reference backend reports the error";
    return s;
  }
  std::ostringstream why;
  why << "fastest " << (s.fromCache ? "in the cached calibration" : "in calibration") << ": "
      << ok.front()->candidate.label() << " " << formatMs(ok.front()->msPerStep);
  for (std::size_t i = 1; i < ok.size(); ++i) why << (i == 1 ? " vs " : ", ") << ok[i]->candidate.label() << " " << formatMs(ok[i]->msPerStep);
  why << " (" << elements << " elements)";
  s.reason = why.str();
  return s;
}

std::string scheduleJson(const BodySchedule& s) {
  json j;
  j["body"] = s.body;
  j["choice"] = s.choice().label();
  j["backend"] = kindName(s.choice().kind);
  j["device"] = s.choice().device;
  j["reason"] = s.reason;
  j["from_cache"] = s.fromCache;
  j["explicit"] = s.explicitChoice;
  json cands = json::array();
  for (const CandidateTiming& t : s.timings) {
    json c{{"backend", kindName(t.candidate.kind)}, {"device", t.candidate.device},
           {"label", t.candidate.label()}, {"from_cache", t.fromCache}};
    c["ms_per_step"] = std::isnan(t.msPerStep) ? json(nullptr) : json(t.msPerStep);
    if (!t.error.empty()) c["error"] = t.error;
    cands.push_back(c);
  }
  j["candidates"] = cands;
  json order = json::array();
  for (const Candidate& c : s.order) order.push_back(c.label());
  j["fallback_order"] = order;
  return j.dump();
}

std::string fallbackJson(const FallbackEvent& e) {
  return json{{"body", e.body}, {"when", e.when}, {"call", e.call}, {"from", e.from}, {"to", e.to}, {"error", e.error}}
      .dump();
}

}  // namespace corofem::detail
