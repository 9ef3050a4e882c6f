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

/// A hidden name beside `target` that no other call (thread or process) gets:
/// <dir>/.<name><tag><16 hex digits>. Beside, so that the final rename stays on one file system.
inline std::filesystem::path unique_sibling(const std::filesystem::path& target, const char* tag) {
  static std::atomic<std::uint64_t> counter{0};
  const auto stamp = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
  const auto tid = static_cast<std::uint64_t>(std::hash<std::thread::id>{}(std::this_thread::get_id()));
  const std::uint64_t id = stamp ^ (tid << 1) ^ (counter.fetch_add(1) * 0x9E3779B97F4A7C15ull);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(id));
  return target.parent_path() / cat(".", target.filename().string(), tag, buf);
}

/// A temporary path beside `target` (same directory, so the final rename is atomic). The temporary
/// is removed on destruction unless commit() succeeded.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path target)
      : target_(std::move(target)), temp_(unique_sibling(target_, ".tmp-")) {}
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

/// A directory tree built under a hidden name beside `target` and swapped into place by commit():
/// a failed run leaves nothing at `target`, and an existing `target` is only deleted once the new
/// tree is in place. The stage is removed on destruction unless committed or kept.
class StagedDirectory {
 public:
  /// Create the parent of `target` and the stage `.<name><tag><unique>` beside it.
  StagedDirectory(std::filesystem::path target, const char* tag) : target_(std::move(target)) {
    namespace fs = std::filesystem;
    if (target_.filename().empty()) target_ = target_.parent_path();  // "dir/" -> "dir"
    std::error_code ec;
    if (!target_.parent_path().empty()) fs::create_directories(target_.parent_path(), ec);
    if (ec) fail(target_.parent_path(), cat("cannot create the parent folder: ", ec.message()));
    dir_ = unique_sibling(target_, tag);
    fs::create_directories(dir_, ec);
    if (ec) fail(dir_, cat("cannot create the temporary folder: ", ec.message()));
  }
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  ~StagedDirectory() {
    if (keep_) return;
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  const std::filesystem::path& dir() const { return dir_; }
  const std::filesystem::path& target() const { return target_; }
  /// Leave the stage on disk whatever happens (for inspecting a failure).
  void keep() { keep_ = true; }

  /// Move dir() / `sub` (dir() itself when empty) onto the target; the rest of the stage goes with
  /// the destructor. An existing target is moved aside first and put back if the rename fails.
  void commit(const std::filesystem::path& sub = {}) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::path old;
    if (fs::exists(target_, ec)) {
      old = unique_sibling(target_, ".old-");
      fs::rename(target_, old, ec);
      if (ec) fail(target_, cat("cannot move the existing folder aside: ", ec.message()));
    }
    fs::rename(sub.empty() ? dir_ : dir_ / sub, target_, ec);
    if (ec) {
      std::error_code ec2;
      if (!old.empty()) fs::rename(old, target_, ec2);
      fail(target_, cat("cannot rename the finished folder into place: ", ec.message()));
    }
    if (!old.empty()) fs::remove_all(old, ec);
  }

 private:
  std::filesystem::path target_, dir_;
  bool keep_ = false;
};

/// Write `p` atomically: write(out) fills a binary stream on a temporary beside `p`, which is
/// renamed onto `p` when complete (and removed if anything throws).
template <class Write>
void write_stream_atomic(const std::filesystem::path& p, Write&& write) {
  AtomicFile f(p);
  {
    std::ofstream out(f.temp(), std::ios::binary | std::ios::trunc);
    if (!out) fail(p, "cannot open for writing (directory missing or not writable?)");
    write(out);
    out.flush();
    if (!out) fail(p, "write error (disk full?)");
  }
  f.commit();
}

/// Write `n` bytes to `p` atomically.
inline void write_bytes_atomic(const std::filesystem::path& p, const void* data, std::size_t n) {
  write_stream_atomic(p, [&](std::ostream& out) { out.write(static_cast<const char*>(data), static_cast<std::streamsize>(n)); });
}

/// Write a string to `p` atomically.
inline void write_text_atomic(const std::filesystem::path& p, const std::string& s) {
  write_bytes_atomic(p, s.data(), s.size());
}

}  // namespace msgs::io
