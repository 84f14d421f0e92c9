// The backend registry (registry.hpp).
#include "device/registry.hpp"

#include "util/error.hpp"

#include <algorithm>
#include <cctype>
#include <mutex>

namespace corofem::detail {

namespace {

struct Registry {
  std::mutex mutex;
  std::vector<std::shared_ptr<const BackendEntry>> entries;  ///< the reference backend last
  bool builtins = false;
};

Registry& registry() {
  static Registry r;
  return r;
}

/// Set on the thread registering the built-in backends (their registerBackend calls must not wait
/// for the registration they are part of).
thread_local bool registeringBuiltins = false;

/// The registry with the built-in backends in it (registered on first use, outside the lock:
/// registerBuiltinBackends calls registerBackend), so that a backend an application registers
/// before the first Simulation replaces a built-in one of its name instead of being replaced.
Registry& ready() {
  static std::once_flag once;
  if (!registeringBuiltins)
    std::call_once(once, [] {
      struct Flag {
        Flag() { registeringBuiltins = true; }
        ~Flag() { registeringBuiltins = false; }
      } flag;
      registerBuiltinBackends();
    });
  return registry();
}

}  // namespace

std::string Candidate::label() const {
  if (backend == "reference" && (device.empty() || device == referenceCandidate().device)) return "reference";
  return backend + ":" + selector + " (" + device + ")";
}

std::size_t selectDeviceIndex(const std::vector<std::string>& names, const std::vector<bool>& gpu,
                              const std::string& selector) {
  if (selector.empty()) {
    for (std::size_t i = 0; i < names.size(); ++i)
      if (i < gpu.size() && gpu[i]) return i;
    return names.empty() ? names.size() : 0;
  }
  if (std::all_of(selector.begin(), selector.end(), [](unsigned char c) { return std::isdigit(c) != 0; })) {
    const unsigned long index = selector.size() > 9 ? names.size() : std::stoul(selector);
    return index < names.size() ? index : names.size();
  }
  auto lower = [](std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
  };
  const std::string want = lower(selector);
  for (std::size_t i = 0; i < names.size(); ++i)
    if (lower(names[i]).find(want) != std::string::npos) return i;
  return names.size();
}

BackendEntry unavailableBackend(const std::string& name, const std::string& why) {
  BackendEntry e;
  e.name = name;
  e.candidates = [] { return std::vector<Candidate>{}; };
  e.resolve = [why](const std::string&) -> Candidate { fail(ErrorCode::NotCompiledIn, why); };
  e.refuses = [why](const Problem&, const SolverDesc&) -> std::string { fail(ErrorCode::NotCompiledIn, why); };
  e.create = [why](const std::vector<const Problem*>&, const SolverDesc&, const Candidate&,
                   const DeviceOptions&) -> std::unique_ptr<Device> { fail(ErrorCode::NotCompiledIn, why); };
  return e;
}

std::string hostOnlyFeature(const Problem& p, const SolverDesc& s) {
  if (isHyperelastic(p.formulation))
    return std::string("the ") + toString(p.formulation) + " formulation runs only on the reference backend; set "
           "\"backend\": \"reference\" or use the \"corotational\" or \"linear\" formulation";
  if (s.linearSolver == LinearSolverKind::Cholesky)
    return "the Cholesky solver runs only on the reference backend; set \"backend\": \"reference\" or the solver "
           "\"pcg\"";
  return "";
}

Candidate referenceCandidate() {
  Candidate c;
  c.backend = "reference";
  c.device = "host (Eigen, double)";
  c.driver = "corofem";
  return c;
}

void registerBackend(BackendEntry entry) {
  if (entry.name.empty() || !entry.candidates || !entry.create)
    fail(ErrorCode::BadInput, "registering a backend: it needs a name, a candidates function and a create function");
  Registry& r = ready();
  std::lock_guard<std::mutex> lock(r.mutex);
  auto made = std::make_shared<const BackendEntry>(std::move(entry));
  for (auto& e : r.entries)
    if (e->name == made->name) {
      e = made;
      return;
    }
  // Before the reference backend, which stays last (the fallback of every body).
  auto at = r.entries.end();
  if (!r.entries.empty() && r.entries.back()->name == "reference" && made->name != "reference") --at;
  r.entries.insert(at, made);
}

void unregisterBackend(const std::string& name) {
  if (name == "reference") fail(ErrorCode::BadInput, "the reference backend cannot be unregistered");
  Registry& r = ready();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (auto it = r.entries.begin(); it != r.entries.end(); ++it)
    if ((*it)->name == name) {
      r.entries.erase(it);
      return;
    }
}

std::vector<BackendEntry> registeredBackends() {
  Registry& r = ready();
  std::lock_guard<std::mutex> lock(r.mutex);
  std::vector<BackendEntry> out;
  for (const auto& e : r.entries) out.push_back(*e);
  return out;
}

std::shared_ptr<const BackendEntry> findBackend(const std::string& name) {
  Registry& r = ready();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (const auto& e : r.entries)
    if (e->name == name) return e;
  return nullptr;
}

std::shared_ptr<const BackendEntry> backendOf(const Candidate& c) {
  if (auto e = findBackend(c.backend)) return e;
  std::string names;
  for (const BackendEntry& e : registeredBackends()) names += (names.empty() ? "" : ", ") + e.name;
  fail(ErrorCode::BadInput, "no backend named '", c.backend, "' is registered (registered: ", names, ")");
}

}  // namespace corofem::detail
