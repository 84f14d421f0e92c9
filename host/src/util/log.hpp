// The library's side of corofem/log.hpp: a sink that formats only what its callback asks for.
#pragma once

#include <corofem/log.hpp>

#include <sstream>
#include <string>
#include <utility>

namespace corofem::detail {

class Log {
 public:
  Log() = default;
  explicit Log(LogDesc desc) : desc_(std::move(desc)) {}
  /// A sink that drops everything (drivers made outside a Simulation: calibration, tests).
  static const Log& none() {
    static const Log silent;
    return silent;
  }
  /// Whether a message at `level` reaches the callback (test this before formatting a costly one).
  bool enabled(LogLevel level) const { return desc_.callback && level >= desc_.level; }
  template <class... Parts>
  void operator()(LogLevel level, const Parts&... parts) const {
    if (!enabled(level)) return;
    try {
      std::ostringstream os;
      (os << ... << parts);
      desc_.callback(level, os.str());
    } catch (...) {
      // A callback that throws loses its message, never the call that logged it.
    }
  }

 private:
  LogDesc desc_;
};

}  // namespace corofem::detail
