// Shared pieces of corofem_tradeoff: command-line options and the two sub-commands.
#pragma once

#include <string>

namespace corofem::tradeoff {

struct Options {
  bool quick = false;        ///< ~1 minute instead of ~10
  std::string out;           ///< CSV path
  std::string dataDir;       ///< ../shared/data by default (COROFEM_DATA_DIR overrides)
  std::string only;          ///< sweep: run only this scene ("" = all)
  double forceMax = 0.0;     ///< fig5: largest force magnitude (N), 0 = the built-in default
  int increments = 0;        ///< fig5: load increments, 0 = the built-in default
  bool skipOpenCL = false;   ///< sweep: reference backend only
};

/// The knob sweep over the three scenes; writes one CSV row per configuration. Returns the exit code.
int runSweep(const Options& options);

/// Static load-displacement curves on the pipe elbow for linear, co-rotational, St. Venant-Kirchhoff
/// and Neo-Hookean; writes one CSV row per formulation and load increment. Returns the exit code.
int runFig5(const Options& options);

}  // namespace corofem::tradeoff
