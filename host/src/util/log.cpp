// Names of the log levels (corofem/log.hpp).
#include <corofem/log.hpp>

namespace corofem {

const char* toString(LogLevel level) {
  switch (level) {
    case LogLevel::Debug: return "debug";
    case LogLevel::Info: return "info";
    case LogLevel::Warning: return "warning";
  }
  return "unknown";
}

}  // namespace corofem
