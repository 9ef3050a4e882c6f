// tests/fixtures.hpp
// Shared test fixtures: the `tiny` synthetic scene, generated once per process, for the tests
// that drive training end to end (scratch directories: scratch.hpp).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include <msgs/io/dataset.hpp>
#include <msgs/synth.hpp>

#include "scratch.hpp"

namespace msgs::testing {

/// The `tiny` synthetic scene with `seed`, written under scratch_dir(sub) and loaded once per
/// process (a test file uses one scene: later calls return the first one whatever they pass).
inline const io::Dataset& tiny_scene(const std::string& sub, std::uint64_t seed) {
  static const io::Dataset ds = [&] {
    SynthOptions opt;
    opt.preset = "tiny";
    opt.seed = seed;
    opt.overwrite = true;
    const std::filesystem::path root = scratch_dir(sub) / "tiny";
    write_synthetic_dataset(root, opt);
    return io::load_dataset(root);
  }();
  return ds;
}

}  // namespace msgs::testing
