// examples/experiment_sh3.cpp: instantiates run_experiment for SH degree 3.
#include "experiment.hpp"

namespace msgs::cli {
RunResult run_experiment_sh3(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out) {
  return run_experiment<3>(ds, cfg, out);
}
}  // namespace msgs::cli
