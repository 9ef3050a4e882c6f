// tests/run_experiment_sh0.cpp: the one instantiation of run_experiment<0> that the tests share
// (see run_experiment_sh0.hpp), and of its Joint trainer, Trainer<Gaussian<7, 0>>, which it
// compiles anyway (see shared_trainers.hpp).
#include "run_experiment_sh0.hpp"

namespace msgs {
template RunResult run_experiment<0>(const io::Dataset&, const RunConfig&, const std::filesystem::path&);
template class Trainer<Gaussian<7, 0>>;
}  // namespace msgs
