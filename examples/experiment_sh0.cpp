// examples/experiment_sh0.cpp: instantiates run_experiment for SH degree 0. The instantiation is
// explicit, with the Joint trainer Trainer<Gaussian<7, 0>> whole, because the tests that run
// experiments or drive that trainer link this unit too (tests/run_experiment_sh0.hpp,
// tests/shared_trainers.hpp): the costliest code of the tool and of those tests, compiled once.
#include "experiment.hpp"

namespace msgs {
template RunResult run_experiment<0>(const io::Dataset&, const RunConfig&, const std::filesystem::path&);
template class Trainer<Gaussian<7, 0>>;
}  // namespace msgs

namespace msgs::cli {
RunResult run_experiment_sh0(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out) {
  return run_experiment<0>(ds, cfg, out);
}
}  // namespace msgs::cli
