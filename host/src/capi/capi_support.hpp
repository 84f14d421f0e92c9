// What every entry point of the C API (corofem/corofem.h) shares: the handles' contents, the
// calling thread's last error, the guard that keeps exceptions inside, and the checks of the
// caller's pointers and arrays (each error names the C function, the argument and the fix).
#pragma once

#include <corofem/corofem.h>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>
#include <corofem/status.hpp>

#include "util/error.hpp"

#include <cstddef>
#include <cstring>
#include <new>
#include <string>
#include <vector>

struct corofem_scene {
  corofem::Scene scene;
};

struct corofem_simulation {
  corofem::Simulation simulation;
};

namespace corofem::capi {

/// Sets the calling thread's last error and returns its code: an empty message with COROFEM_OK,
/// else the message, which starts with the C function's name ("corofem_simulation_pin_nodes: ...")
/// when it does not already.
corofem_status record(const char* function, ErrorCode code, const char* message) noexcept;

/// Runs fn(), which returns a Status or throws (detail::Error for the API's own checks), and
/// records the outcome: no exception leaves it.
template <class Fn>
corofem_status call(const char* function, Fn&& fn) noexcept {
  try {
    const Status status = fn();
    return record(function, status.code(), status.message().c_str());
  } catch (const detail::Error& e) {
    return record(function, e.code(), e.what());
  } catch (const std::bad_alloc&) {
    return record(function, ErrorCode::Internal, "out of memory");
  } catch (const std::exception& e) {
    return record(function, ErrorCode::Internal, (std::string("unexpected error: ") + e.what()).c_str());
  } catch (...) {
    return record(function, ErrorCode::Internal, "unexpected error of an unknown type (please report it)");
  }
}

/// BadInput "<function>: <name> is NULL; <fix>" when p is.
inline void require(const void* p, const char* function, const char* name, const char* fix) {
  if (!p) detail::fail(ErrorCode::BadInput, function, ": ", name, " is NULL; ", fix);
}

/// The C++ limits of the C API's (NULL: the defaults; a field of 0: its default).
inline InputLimits limitsOf(const corofem_input_limits* limits) {
  InputLimits out;
  if (!limits) return out;
  if (limits->max_input_bytes) out.maxInputBytes = limits->max_input_bytes;
  if (limits->max_scene_bytes) out.maxSceneBytes = limits->max_scene_bytes;
  if (limits->max_box_tets) out.maxBoxTets = limits->max_box_tets;
  return out;
}

/// `count` C strings as a vector (NULL with a count of 0: none); a NULL entry is BadInput.
inline std::vector<std::string> stringList(const char* const* strings, std::size_t count, const char* function,
                                    const char* name) {
  std::vector<std::string> out;
  if (count == 0) return out;
  require(strings, function, name, "pass an array of that many strings, or NULL with a count of 0");
  for (std::size_t i = 0; i < count; ++i) {
    if (!strings[i])
      detail::fail(ErrorCode::BadInput, function, ": ", name, "[", i, "] is NULL; each of the ", count,
                   " entries must be a string");
    out.emplace_back(strings[i]);
  }
  return out;
}

inline const Simulation& simulationOf(const corofem_simulation* s, const char* function) {
  require(s, function, "simulation", "pass the handle corofem_simulation_create gave");
  return s->simulation;
}
inline Simulation& simulationOf(corofem_simulation* s, const char* function) {
  require(s, function, "simulation", "pass the handle corofem_simulation_create gave");
  return s->simulation;
}

/// The body's index, checked (for the calls whose C++ counterpart cannot return a status).
inline void checkBody(const Simulation& sim, int body, const char* function) {
  if (body < 0 || body >= sim.bodyCount())
    detail::fail(ErrorCode::BadInput, function, ": body index ", body, " is out of range: the simulation has ",
                 sim.bodyCount(), " body(ies), numbered from 0");
}

/// The caller's array rule (corofem.h): writes `size` to *needed; false for a size query (NULL
/// with capacity 0); BadInput for NULL with a capacity or a capacity below `size`; else true.
inline bool fits(const void* out, std::size_t capacity, std::size_t size, std::size_t* needed, const char* function,
                 const char* name, const char* unit) {
  if (needed) *needed = size;
  if (!out) {
    if (capacity == 0) return false;
    detail::fail(ErrorCode::BadInput, function, ": ", name, " is NULL with capacity ", capacity,
                 "; pass an array of that many ", unit, ", or NULL with capacity 0 to ask for the size");
  }
  if (capacity < size)
    detail::fail(ErrorCode::BadInput, function, ": ", name, " holds ", capacity, " ", unit, "; ", size,
                 " are needed (the size is also written to `needed`)");
  return true;
}

/// Copies values into the caller's array under the array rule.
template <class T>
void copyOut(const std::vector<T>& values, T* out, std::size_t capacity, std::size_t* needed, const char* function,
             const char* name, const char* unit) {
  if (fits(out, capacity, values.size(), needed, function, name, unit) && !values.empty())
    std::memcpy(out, values.data(), values.size() * sizeof(T));
}

/// Copies text with its terminating NUL under the array rule (capacity in chars).
inline void copyText(const std::string& text, char* out, std::size_t capacity, std::size_t* needed,
                     const char* function) {
  if (fits(out, capacity, text.size() + 1, needed, function, "text", "chars"))
    std::memcpy(out, text.c_str(), text.size() + 1);
}

/// `count` node indices from the caller (count 0: none; NULL only then).
inline std::vector<std::uint32_t> nodeList(const std::uint32_t* nodes, std::size_t count, const char* function) {
  if (count > 0) require(nodes, function, "nodes", "pass an array of `count` node indices");
  return count ? std::vector<std::uint32_t>(nodes, nodes + count) : std::vector<std::uint32_t>();
}

}  // namespace corofem::capi
