// Outputs of a scene run: probes.csv, the VTK series (.vtu + .pvd per body), summary.json.
// Used by `corofem run`; an embedding application may use it the same way. Every file is
// flushed or rewritten as the run goes, so a run that fails or is killed leaves readable outputs.
#pragma once

#include <corofem/simulation.hpp>

#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace corofem::detail {

class RunOutputs {
 public:
  /// Creates `dir` and opens the outputs. Throws Error(BadInput) for a probe whose node set
  /// selects nothing or names an unknown body, or a zlib vtu_compression this build or the ascii
  /// format cannot write (before creating anything); Error(IoError) when the folder cannot be written.
  RunOutputs(const Simulation& sim, const std::string& dir);
  ~RunOutputs();

  /// Records the state after a step (step 0 = the initial state, before any step).
  void record(const Simulation& sim, const StepReport& report);

  /// Writes summary.json with the run's status (call once at the end, also after a failure).
  void finish(const Simulation& sim, const Status& status, double totalWallSeconds);

  const std::string& dir() const { return dir_; }

 private:
  struct Probe {
    std::string name;
    int body = 0;
    std::vector<std::uint32_t> nodes;
  };
  void writeVtk(const Simulation& sim, int step, double time);

  std::string dir_;
  std::vector<Probe> probes_;
  std::ofstream csv_;
  std::vector<std::unique_ptr<PvdSeries>> series_;
  std::vector<std::unique_ptr<PvdSeries>> surfaceSeries_;  ///< per body; null without a surface
  std::vector<double> stepWallSeconds_;
  std::vector<StepReport> reports_;
  std::vector<double> lastProbe_;
  int lastVtkStep_ = -1;
};

}  // namespace corofem::detail
