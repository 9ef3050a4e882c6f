// examples/experiment.hpp: run_experiment for a run-time SH degree. Each degree is instantiated in
// its own translation unit (experiment_sh<D>.cpp) so the 2-core build compiles them in parallel.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>

#include <msgs/run.hpp>

namespace msgs::cli {

RunResult run_experiment_sh0(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out);
RunResult run_experiment_sh1(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out);
RunResult run_experiment_sh2(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out);
RunResult run_experiment_sh3(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out);

inline RunResult run_experiment_any(int sh_degree, const io::Dataset& ds, const RunConfig& cfg,
                                    const std::filesystem::path& out) {
  switch (sh_degree) {
    case 0: return run_experiment_sh0(ds, cfg, out);
    case 1: return run_experiment_sh1(ds, cfg, out);
    case 2: return run_experiment_sh2(ds, cfg, out);
    case 3: return run_experiment_sh3(ds, cfg, out);
    default: throw std::invalid_argument("SH degree must be 0..3, got " + std::to_string(sh_degree));
  }
}

}  // namespace msgs::cli
