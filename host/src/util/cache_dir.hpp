// Where corofem keeps what it learns between runs (built OpenCL programs, the scheduler's
// calibrations): $COROFEM_CACHE_DIR, else (on Windows) %LOCALAPPDATA%\corofem, else
// $XDG_CACHE_HOME/corofem, else ~/.cache/corofem.
#pragma once

#include <string>

namespace corofem::detail {

/// The cache folder, or "" when there is none: COROFEM_CACHE_DIR=off, or none of LOCALAPPDATA
/// (Windows), XDG_CACHE_HOME and HOME is set. Read at each call (not created here).
std::string cacheDirectory();

}  // namespace corofem::detail
