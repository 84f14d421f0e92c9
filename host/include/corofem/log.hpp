// Messages the library has for the application: where they go is the application's choice. The
// library never writes to stderr or stdout itself.
#pragma once

#include <functional>
#include <string>

namespace corofem {

enum class LogLevel {
  Debug,    ///< per-iteration detail of the solvers (Newton residuals, step lengths, substep retries)
  Info,     ///< what the library decided (a device chosen, a fallback taken)
  Warning,  ///< something the application should know about but that did not fail a call
};

/// Receives one message (one line, no trailing newline) at a level. Called on the thread that made
/// the call producing it; it must not call back into the Simulation that logged.
using LogCallback = std::function<void(LogLevel level, const std::string& message)>;

/// Where a Simulation's messages go: `callback` (none: they are dropped) for messages at `level`
/// or above. Debug messages cost their formatting only when asked for.
struct LogDesc {
  LogCallback callback;
  LogLevel level = LogLevel::Info;
};

/// "debug", "info", "warning".
const char* toString(LogLevel level);

}  // namespace corofem
