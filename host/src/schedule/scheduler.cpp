// Scheduler: candidates, explicit requests, calibration and its cache (see scheduler.hpp).
#include "schedule/scheduler.hpp"

#include "solve/driver.hpp"
#include "util/cache_dir.hpp"
#include "util/error.hpp"
#include "util/temp_file.hpp"


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

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string choicesText() {
  std::string s = "choices: \"auto\"";
  for (const BackendEntry& e : registeredBackends())
    s += ", \"" + e.name + "\"" + (e.name == "reference" ? "" : ", \"" + e.name + ":<index>\" or \"" + e.name +
                                                                      ":<device name substring>\"");
  std::string devices;
  for (const Candidate& c : listCandidates())
    if (c.backend != "reference") devices += (devices.empty() ? "" : ", ") + c.label();
  s += devices.empty() ? "; this build/machine has no device besides the host" : "; devices here: " + devices;
  return s;
}

// ------------------------------------------------------------------ cache
std::string cacheKey(const Candidate& c, const Scene& scene, const Problem& problem) {
  const std::size_t elements = problem.mesh.tetCount();
  std::ostringstream os;
  os << c.backend << '|' << c.device << '|' << c.driver << '|'
     << (scene.analysis.kind == AnalysisDesc::Kind::Static ? "static" : "dynamic") << '|'
     << (scene.solver.precision == Precision::Float ? "float" : "double") << '|'
     << (scene.solver.linearSolver == LinearSolverKind::Cholesky ? "cholesky" : "pcg") << '|'
     << toString(preconditionerOf(scene.solver, problem)) << "|log2e="
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
  const std::string text = j.dump(2);  // before the file exists: dump throws on invalid UTF-8
  const std::string tmp = temporaryNameFor(path);
  std::ofstream out(tmp);
  if (!out) return;
  out << text << '\n';
  out.close();  // the flush that meets a full disk
  if (!out) {
    fs::remove(tmp, ec);
    return;
  }
  replaceFile(tmp, path);  // a cache not written is only a calibration made again
}

// ------------------------------------------------------------------ calibration
/// Median wall time (ms) of the body's first step on candidate c: one warm-up, then up to
/// kCalibrationRepeats repetitions, each undone by rollback() so that every repetition is the
/// same step. Throws whatever the device or the driver throws.
double calibrate(const Problem& problem, const Scene& scene, const Candidate& c, const DeviceOptions& options) {
  DeviceSlot slot({&problem}, scene.solver, {c}, false, options);
  std::unique_ptr<Driver> driver = createDriver(slot, scene.analysis);
  const int count = scene.analysis.kind == AnalysisDesc::Kind::Static ? std::max(1, scene.analysis.statics.increments)
                                                                      : std::max(1, scene.analysis.dynamics.steps);
  using Clock = std::chrono::steady_clock;
  const auto begin = Clock::now();
  auto timeStep = [&] {
    const auto t0 = Clock::now();
    const std::vector<BodyOutcome> out = driver->step({0}, StepCall{1, count, scene.analysis.dynamics.timeStep});
    if (out.at(0).error) std::rethrow_exception(out[0].error);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    driver->rollback(0);
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
  for (const BackendEntry& e : registeredBackends())
    if (e.buildId) {
      const std::string id = e.buildId();
      if (!id.empty()) build += ", " + e.name + " " + id;
    }
  return build;
}

std::vector<Candidate> listCandidates() {
  std::vector<Candidate> gpus, others;
  for (const BackendEntry& e : registeredBackends()) {
    if (e.name == "reference") continue;
    for (const Candidate& c : e.candidates()) (c.gpu ? gpus : others).push_back(c);
  }
  gpus.insert(gpus.end(), others.begin(), others.end());
  gpus.push_back(referenceCandidate());
  return gpus;
}

DeviceRequest parseDeviceSpec(const std::string& spec, const std::string& source) {
  DeviceRequest r;
  r.source = source;
  const std::size_t colon = spec.find(':');
  const std::string head = lower(spec.substr(0, colon));
  const std::string tail = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (head == "auto" && colon == std::string::npos) return r;
  const bool reference = head == "reference";
  if (findBackend(head) && (colon == std::string::npos || (!tail.empty() && !reference))) {
    r.backend = head;
    r.device = tail;
    return r;
  }
  fail(ErrorCode::BadInput, source, "=\"", spec, "\" is not a backend; ", choicesText());
}

DeviceRequest requestedDevice(const Scene& scene) {
  if (scene.backend.kind != BackendKind::Auto) {
    DeviceRequest r;
    r.backend = toString(scene.backend.kind);
    r.device = scene.backend.device;
    r.source = "scene";
    return r;
  }
  // "auto" with a device named: the user chose that OpenCL device ("" is the scheduler's choice).
  if (!scene.backend.device.empty()) {
    DeviceRequest r;
    r.backend = "opencl";
    r.device = scene.backend.device;
    r.source = "the scene (\"backend.device\": \"" + scene.backend.device + "\")";
    return r;
  }
  if (const char* env = std::getenv("COROFEM_DEVICE"); env && *env) return parseDeviceSpec(env, "COROFEM_DEVICE");
  return {};
}

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
                          const DeviceOptions& options, const std::vector<std::string>& devices) {
  BodySchedule s;
  s.body = desc.name;
  const Candidate reference = referenceCandidate();

  // The application's order: each entry resolved by its backend, the reference backend last. An
  // entry that cannot run this body (a device not on this machine, a formulation it refuses) is
  // skipped, and the report says why (its "candidates").
  if (!devices.empty()) {
    for (const std::string& spec : devices) {
      const DeviceRequest req = parseDeviceSpec(spec, "SimulationOptions::devices entry");
      if (req.backend.empty()) fail(ErrorCode::BadInput, "SimulationOptions::devices: \"auto\" cannot be part of an order");
      const auto entry = findBackend(req.backend);
      CandidateTiming t;
      t.candidate.backend = req.backend;
      t.candidate.selector = req.device;
      t.candidate.device = req.device.empty() ? "default " + req.backend + " device" : req.device;
      try {
        if (entry->resolve) t.candidate = entry->resolve(req.device);
        else if (const std::vector<Candidate> all = entry->candidates(); !all.empty()) t.candidate = all.front();
        else fail(ErrorCode::DeviceError, "backend '", req.backend, "' has no device here");
        if (const std::string why = entry->refuses ? entry->refuses(problem, scene.solver) : ""; !why.empty())
          fail(ErrorCode::BadInput, why);
      } catch (const Error& e) {
        t.error = std::string(toString(e.code())) + ": " + e.what();
        s.timings.push_back(t);
        continue;
      }
      s.order.push_back(t.candidate);
    }
    if (s.order.empty() || s.order.back().backend != "reference") s.order.push_back(reference);
    s.reason = "the order the application gave (SimulationOptions::devices)";
    if (!s.timings.empty()) s.reason += "; skipped: see candidates";
    // Falls back at create too (the application listed the fallbacks), except from a device the
    // application lent (SimulationOptions::device): handles it cannot use are its error to fix.
    s.explicitChoice = s.order.front().selector == kExternalSelector;
    return s;
  }

  const DeviceRequest req = requestedDevice(scene);
  if (req.backend == "reference") {
    s.order = {reference};
    s.reason = "requested by " + (req.source == "scene" ? std::string("the scene (\"backend\": \"reference\")") : req.source);
    s.explicitChoice = true;
    return s;
  }
  if (!req.backend.empty()) {
    const auto entry = findBackend(req.backend);
    if (const std::string why = entry->refuses ? entry->refuses(problem, scene.solver) : ""; !why.empty())
      fail(ErrorCode::BadInput, "body '", desc.name, "': ", why);
    // The selector resolved to the device's own (index and name) so that the label and the cache
    // name it; an unknown selector is left as given, for the backend's DeviceError to list the devices.
    Candidate c;
    c.backend = req.backend;
    c.selector = req.device;
    c.device = req.device.empty() ? "default " + req.backend + " device" : req.device;
    if (entry->resolve) {
      try {
        c = entry->resolve(req.device);
      } catch (const Error&) {
      }
    }
    s.order = {c, reference};
    s.reason = "requested by " + (req.source == "scene" ? "the scene (\"backend\": \"" + req.backend + "\")" : req.source);
    s.explicitChoice = true;
    return s;
  }

  // "auto": the candidates of the backends that can run this body.
  auto onlyReference = [&](const std::string& why) {
    s.order = {reference};
    s.reason = why;
    return s;
  };
  std::vector<Candidate> candidates;
  std::string refusal;
  for (const Candidate& c : listCandidates()) {
    const auto entry = findBackend(c.backend);
    const std::string why = entry && entry->refuses ? entry->refuses(problem, scene.solver) : "";
    if (why.empty()) candidates.push_back(c);
    else if (refusal.empty()) refusal = why;
  }
  if (candidates.size() == 1)
    return onlyReference(refusal.empty() ? "no device besides the host in this build or on this machine" : refusal);
  const std::size_t elements = problem.elements.size();
  const std::size_t minElements = scene.backend.minDeviceElements;
  if (elements < minElements)
    return onlyReference(std::to_string(elements) + " elements is below " + std::to_string(minElements) +
                         " (backend.min_device_elements): a device launch costs more than the whole step");

  const std::string path = schedulerCachePath();
  json cache = readCache(path);
  if (!cache.contains("entries")) cache = json{{"version", 1}, {"entries", json::object()}};
  bool allCached = true, wroteAny = false;
  for (const Candidate& c : candidates) {
    CandidateTiming t;
    t.candidate = c;
    const std::string key = cacheKey(c, scene, problem);
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
      t.msPerStep = calibrate(problem, scene, c, options);
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
  const bool referenceFirst = !ok.empty() && ok.front()->candidate.backend == "reference";
  for (const CandidateTiming* t : ok)
    if (!referenceFirst && t->candidate.backend != "reference") s.order.push_back(t->candidate);
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
  j["backend"] = s.choice().backend;
  j["device"] = s.choice().device;
  j["reason"] = s.reason;
  j["from_cache"] = s.fromCache;
  j["explicit"] = s.explicitChoice;
  json cands = json::array();
  for (const CandidateTiming& t : s.timings) {
    json c{{"backend", t.candidate.backend}, {"device", t.candidate.device},
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
