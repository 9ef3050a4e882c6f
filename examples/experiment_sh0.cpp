// examples/experiment_sh0.cpp: instantiates run_experiment for SH degree 0.
#include "experiment.hpp"

namespace msgs::cli {
RunResult run_experiment_sh0(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out) {
  return run_experiment<0>(ds, cfg, out);
}
}  // namespace msgs::cli
