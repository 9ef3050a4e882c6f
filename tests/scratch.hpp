// tests/scratch.hpp
// Scratch directories for tests that write files, and the message of an expected io::IoError.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>

#include <msgs/io/error.hpp>

namespace msgs::testing {

/// $MSGS_TEST_TMP/<sub> (or the system temp directory), created on first use.
inline std::filesystem::path scratch_dir(const std::string& sub) {
  const char* env = std::getenv("MSGS_TEST_TMP");
  std::filesystem::path d = env ? std::filesystem::path(env) : std::filesystem::temp_directory_path() / "msgs_test";
  d /= sub;
  std::filesystem::create_directories(d);
  return d;
}

/// scratch_dir(sub), emptied first: a test that writes files starts from nothing.
inline std::filesystem::path fresh_scratch_dir(const std::string& sub) {
  std::filesystem::remove_all(scratch_dir(sub));
  return scratch_dir(sub);
}

/// The message of the io::IoError that `fn` throws, or "<no error>".
inline std::string io_error_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const io::IoError& e) {
    return e.what();
  }
  return "<no error>";
}

}  // namespace msgs::testing
