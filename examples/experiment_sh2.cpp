// examples/experiment_sh2.cpp: instantiates run_experiment for SH degree 2.
#include "experiment.hpp"

namespace msgs::cli {
RunResult run_experiment_sh2(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out) {
  return run_experiment<2>(ds, cfg, out);
}
}  // namespace msgs::cli
