// include/msgs/io/file.hpp
// Whole-file reads and atomic writes (temporary name in the same directory, then rename), so a
// crash or an error never leaves a half-written output behind.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "msgs/io/error.hpp"

namespace msgs::io {

/// Read a whole file into memory; IoError when it is missing or unreadable.
inline std::vector<unsigned char> read_bytes(const std::filesystem::path& p) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(p, ec)) fail(p, "file does not exist or is not a regular file");
  std::ifstream in(p, std::ios::binary);
  if (!in) fail(p, "cannot open for reading");
  in.seekg(0, std::ios::end);
  const std::streamoff n = in.tellg();
  if (n < 0) fail(p, "cannot determine the file size");
  in.seekg(0, std::ios::beg);
  std::vector<unsigned char> bytes(static_cast<std::size_t>(n));
  if (n > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), n)) fail(p, "read error");
  return bytes;
}

/// Read a whole text file.
inline std::string read_text(const std::filesystem::path& p) {
  const auto b = read_bytes(p);
  return std::string(b.begin(), b.end());
}

/// A temporary path beside `target` (same directory, so the final rename is atomic). The temporary
/// is removed on destruction unless commit() succeeded.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path target) : target_(std::move(target)) {
    static std::atomic<std::uint64_t> counter{0};
    const auto stamp = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
    const auto tid = static_cast<std::uint64_t>(std::hash<std::thread::id>{}(std::this_thread::get_id()));
    const std::uint64_t id = stamp ^ (tid << 1) ^ (counter.fetch_add(1) * 0x9E3779B97F4A7C15ull);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(id));
    temp_ = target_.parent_path() / cat(".", target_.filename().string(), ".tmp-", buf);
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile() {
    if (!committed_) {
      std::error_code ec;
      std::filesystem::remove(temp_, ec);
    }
  }

  /// Where to write.
  const std::filesystem::path& temp() const { return temp_; }
  const std::filesystem::path& target() const { return target_; }

  /// Move the finished temporary onto the target.
  void commit() {
    std::error_code ec;
    std::filesystem::rename(temp_, target_, ec);
    if (ec) fail(target_, cat("cannot rename temporary file into place: ", ec.message()));
    committed_ = true;
  }

 private:
  std::filesystem::path target_, temp_;
  bool committed_ = false;
};

/// Write `n` bytes to `p` atomically.
inline void write_bytes_atomic(const std::filesystem::path& p, const void* data, std::size_t n) {
  AtomicFile f(p);
  {
    std::ofstream out(f.temp(), std::ios::binary | std::ios::trunc);
    if (!out) fail(p, "cannot open for writing (directory missing or not writable?)");
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(n));
    out.flush();
    if (!out) fail(p, "write error (disk full?)");
  }
  f.commit();
}

/// Write a string to `p` atomically.
inline void write_text_atomic(const std::filesystem::path& p, const std::string& s) {
  write_bytes_atomic(p, s.data(), s.size());
}

}  // namespace msgs::io
