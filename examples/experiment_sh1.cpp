// examples/experiment_sh1.cpp: instantiates run_experiment for SH degree 1.
#include "experiment.hpp"

namespace msgs::cli {
RunResult run_experiment_sh1(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out) {
  return run_experiment<1>(ds, cfg, out);
}
}  // namespace msgs::cli
