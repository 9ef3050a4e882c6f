// tests/fixtures.hpp
// Shared test fixtures: a scratch directory per test file and the `tiny` synthetic scene,
// generated once per process, for the tests that drive training end to end.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>

#include <msgs/io/dataset.hpp>
#include <msgs/synth.hpp>

namespace msgs::testing {

/// $MSGS_TEST_TMP/<sub> (or the system temp directory), created on first use.
inline std::filesystem::path scratch_dir(const std::string& sub) {
  const char* env = std::getenv("MSGS_TEST_TMP");
  std::filesystem::path d = env ? std::filesystem::path(env) : std::filesystem::temp_directory_path() / "msgs_test";
  d /= sub;
  std::filesystem::create_directories(d);
  return d;
}

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
