// fuzz/fuzz_common.hpp
// Shared plumbing of the libFuzzer targets: a per-process scratch directory for the file-based
// readers, and the rule for which outcomes of a malformed input are acceptable.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <new>
#include <string>
#include <system_error>

#include "msgs/io/error.hpp"

namespace msgs::fuzz {

/// A scratch directory private to this process (/dev/shm when available, so the per-input file
/// writes stay in memory), removed at exit.
class Scratch {
 public:
  Scratch() {
    std::error_code ec;
    std::filesystem::path base = "/dev/shm";
    if (!std::filesystem::is_directory(base, ec)) base = std::filesystem::temp_directory_path();
    dir_ = base / ("msgs_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

/// The process's scratch directory.
inline const std::filesystem::path& scratch_dir() {
  static Scratch s;
  return s.dir();
}

/// Write `n` bytes to `p` (truncating).
inline void put_file(const std::filesystem::path& p, const void* data, std::size_t n) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(n));
  if (!out) {
    std::fprintf(stderr, "fuzz harness: cannot write %s\n", p.c_str());
    std::abort();
  }
}

/// Run one reader on a malformed input. io::IoError (a message naming the file) is the expected
/// outcome. Anything else is a finding: std::bad_alloc means a tiny input asked for a huge
/// buffer, and any other exception type escaped the loaders' validation (its message names no
/// file), so both abort and libFuzzer records the input.
template <class F>
void expect_io_error_only(const char* what, F&& f) {
  try {
    f();
  } catch (const io::IoError&) {
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: std::bad_alloc (huge allocation from a small input)\n", what);
    std::abort();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: unexpected exception type (not io::IoError): %s\n", what, e.what());
    std::abort();
  }
}

}  // namespace msgs::fuzz
