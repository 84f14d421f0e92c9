// corofem_tradeoff: measures the speed-accuracy trade of corofem's knobs (docs/tradeoff.md).
//
//   corofem_tradeoff sweep [--quick] [--only SCENE] [--no-opencl] --out tradeoff.csv
//   corofem_tradeoff fig5  [--quick] [--force-max N] [--increments K] --out fig5.csv
//
// Data files come from ../shared/data (relative to the source tree) unless --data DIR or the
// COROFEM_DATA_DIR environment variable says otherwise.
#include "tradeoff.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

int usage() {
  std::fprintf(stderr,
               "usage: corofem_tradeoff sweep [--quick] [--only fig8|cantilever_dyn|cantilever|coupled|coupled_tol] [--no-opencl] "
               "[--data DIR] --out FILE.csv\n"
               "       corofem_tradeoff fig5 [--quick] [--force-max N] [--increments K] [--data DIR] "
               "--out FILE.csv\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using corofem::tradeoff::Options;
  if (argc < 2) return usage();
  const std::string command = argv[1];
  Options options;
  const char* env = std::getenv("COROFEM_DATA_DIR");
  options.dataDir = env ? env : std::string(COROFEM_SOURCE_DIR) + "/../shared/data";
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "corofem_tradeoff: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (arg == "--quick") options.quick = true;
    else if (arg == "--out") options.out = next();
    else if (arg == "--data") options.dataDir = next();
    else if (arg == "--only") options.only = next();
    else if (arg == "--no-opencl") options.skipOpenCL = true;
    else if (arg == "--force-max") options.forceMax = std::atof(next().c_str());
    else if (arg == "--increments") options.increments = std::atoi(next().c_str());
    else {
      std::fprintf(stderr, "corofem_tradeoff: unknown option '%s'\n", arg.c_str());
      return usage();
    }
  }
  if (options.out.empty()) {
    std::fprintf(stderr, "corofem_tradeoff: --out FILE.csv is required\n");
    return usage();
  }
  if (command == "sweep") return corofem::tradeoff::runSweep(options);
  if (command == "fig5") return corofem::tradeoff::runFig5(options);
  return usage();
}
