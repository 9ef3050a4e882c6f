// examples/colmap_progress.hpp
// How far a running COLMAP stage has come, read from the end of its log, so that `msgs import`
// can say so while a long stage runs: a flight of a few hundred images spends minutes in
// matching and in the mapper, with nothing else on the screen.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <string_view>

namespace msgs::cli {

/// The latest progress line in `log` (the end of a COLMAP log) in words:
/// - feature_extractor "Processed file [17/48]": "17 of 48 images read";
/// - matches_importer "Matching block [3/12] in 2.1s": "3 of 12 blocks matched". COLMAP prints
///   the line's start when it begins a block and " in 2.1s" when the block is done, so a line
///   without that ending counts one block less: "2 of 12 blocks matched";
/// - exhaustive_matcher "Matching block [2/4, 3/4] in 9.8s": "7 of 16 blocks matched" (likewise);
/// - mapper "Registering image #7 (123)": "123 images registered", or "123 of `images` images
///   registered" when `images` > 0.
/// nullopt when the log holds none of them yet.
inline std::optional<std::string> colmap_progress(std::string_view log, std::size_t images = 0) {
  const std::size_t file = log.rfind("Processed file ["), block = log.rfind("Matching block ["),
                    reg = log.rfind("Registering image #");
  std::size_t last = std::string_view::npos;
  for (std::size_t p : {file, block, reg})
    if (p != std::string_view::npos && (last == std::string_view::npos || p > last)) last = p;
  if (last == std::string_view::npos) return std::nullopt;
  const std::size_t eol = log.find('\n', last);
  const std::string line(log.substr(last, eol == std::string_view::npos ? std::string_view::npos : eol - last));
  char buf[96];
  unsigned long a = 0, n = 0, b = 0, m = 0, id = 0, count = 0;
  const std::size_t close = line.find(']');
  const unsigned long done = close != std::string::npos && line.find(" in ", close) != std::string::npos ? 1 : 0;
  if (last == file && std::sscanf(line.c_str(), "Processed file [%lu/%lu]", &a, &n) == 2) {
    std::snprintf(buf, sizeof buf, "%lu of %lu images read", a, n);
  } else if (last == block && std::sscanf(line.c_str(), "Matching block [%lu/%lu, %lu/%lu]", &a, &n, &b, &m) == 4 &&
             a >= 1 && b >= 1) {
    std::snprintf(buf, sizeof buf, "%lu of %lu blocks matched", (a - 1) * m + b - 1 + done, n * m);
  } else if (last == block && std::sscanf(line.c_str(), "Matching block [%lu/%lu]", &a, &n) == 2 && a >= 1) {
    std::snprintf(buf, sizeof buf, "%lu of %lu blocks matched", a - 1 + done, n);
  } else if (last == reg && std::sscanf(line.c_str(), "Registering image #%lu (%lu)", &id, &count) == 2) {
    if (images > 0) std::snprintf(buf, sizeof buf, "%lu of %zu images registered", count, images);
    else std::snprintf(buf, sizeof buf, "%lu images registered", count);
  } else {
    return std::nullopt;
  }
  return std::string(buf);
}

/// The last `bytes` bytes of a file, of those past byte `since` ("" when it cannot be read).
inline std::string file_tail(const std::filesystem::path& p, std::size_t bytes = 16384, std::uintmax_t since = 0) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return {};
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size <= 0 || size <= std::streamoff(since)) return {};
  const std::streamoff from = std::max(std::streamoff(since), size > std::streamoff(bytes) ? size - std::streamoff(bytes) : 0);
  in.seekg(from);
  std::string s(std::size_t(size - from), '\0');
  in.read(s.data(), std::streamsize(s.size()));
  s.resize(std::size_t(in.gcount()));
  return s;
}

}  // namespace msgs::cli
