// Outputs of a scene run: probes.csv, the VTK series (.vtu + .pvd per body), summary.json.
// Used by `corofem run`; an embedding application may use it the same way. Every file is
// flushed or rewritten as the run goes, so a run that fails or is killed leaves readable outputs;
// every write is checked, so a write that fails (a full disk) is an IoError, never a silent loss.
// Every file is inside the output folder: body names that would make a path are refused. No NaN
// or infinity is written: probes.csv leaves such a cell empty and summary.json writes null, and
// the summary counts them (nonFiniteNote()). Steps whose linear solves did not converge make the
// summary's status "ok_unconverged" instead of "ok", counted under "convergence" (convergenceNote()).
#pragma once

#include <corofem/simulation.hpp>

#include "output/csv_file.hpp"

#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class RunOutputs {
 public:
  /// Creates `dir` and opens the outputs. Throws Error(BadInput) for a probe whose node set
  /// selects nothing or names an unknown body, or a zlib vtu_compression this build or the ascii
  /// format cannot write (before creating anything); Error(IoError) when the folder cannot be written.
  /// A probe's .bou file is read under `limits` (the run's SimulationOptions::inputLimits).
  RunOutputs(const Simulation& sim, const std::string& dir, const InputLimits& limits = {});
  ~RunOutputs();

  /// Records the state after a step (step 0 = the initial state, before any step).
  void record(const Simulation& sim, const StepReport& report);

  /// Writes summary.json with the run's status (call once at the end, also after a failure).
  void finish(const Simulation& sim, const Status& status, double totalWallSeconds);

  const std::string& dir() const { return dir_; }

  /// "" when every number written was finite; else how many were not, and the first one
  /// ("2 values were not finite (the first: probes.csv step 0, elastic_energy = inf) ...").
  std::string nonFiniteNote() const;

  /// "" when every step recorded converged (StepReport::converged); else how many did not, the
  /// worst linear residual and the fix ("30 of 30 steps finished with linear solves short of ...").
  std::string convergenceNote(const Simulation& sim) const;

 private:
  struct Probe {
    std::string name;
    int body = 0;
    std::vector<std::uint32_t> nodes;
  };
  void writeVtk(const Simulation& sim, int step, double time);

  /// The steps recorded whose linear solves did not all converge (dynamics; a static increment
  /// that does not converge fails instead).
  struct Convergence {
    int unconverged = 0;            ///< steps with StepReport::converged false
    int first = 0;                  ///< the first of them (0: none)
    double worstUnconverged = 0.0;  ///< their largest linear residual
    double worst = 0.0;             ///< the largest linear residual of every step recorded
  };
  Convergence convergence() const;

  std::string dir_;
  std::vector<Probe> probes_;
  CsvFile csv_;
  std::size_t summaryNonFinite_ = 0;  ///< numbers of the last summary.json written as null
  std::string firstSummaryNonFinite_;
  std::vector<std::unique_ptr<PvdSeries>> series_;
  std::vector<std::unique_ptr<PvdSeries>> surfaceSeries_;  ///< per body; null without a surface
  std::vector<double> stepWallSeconds_;
  std::vector<StepReport> reports_;
  std::vector<double> lastProbe_;
  int lastVtkStep_ = -1;
};

}  // namespace corofem::detail
