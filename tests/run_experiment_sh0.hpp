// tests/run_experiment_sh0.hpp: run_experiment<0> for the tests that run whole experiments. Its
// instantiation (the <7, 0>, <3, 0> and <1, 0> trainers of every strategy) is the costliest code
// of those tests to compile, so it is compiled once, in the tool's examples/experiment_sh0.cpp
// (the library msgs_experiment_sh0), and not in each.
#pragma once

#include <filesystem>

#include <msgs/run.hpp>

namespace msgs {
extern template RunResult run_experiment<0>(const io::Dataset&, const RunConfig&, const std::filesystem::path&);
}  // namespace msgs
