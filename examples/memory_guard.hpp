// examples/memory_guard.hpp
// `msgs train`'s guard against runaway densification: the most Gaussians a model may reach before
// the run stops with a clear error instead of running out of memory (DensifyConfig::stop_gaussians).
// The limit only ends runs that would not fit; it never changes a result.
#pragma once

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace msgs::cli {

/// MemAvailable of /proc/meminfo in bytes; 0 when it cannot be read (no guard then).
inline std::uint64_t available_memory_bytes() {
  std::ifstream f("/proc/meminfo");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("MemAvailable:", 0) != 0) continue;
    std::istringstream in(line.substr(13));
    std::uint64_t kib = 0;
    return (in >> kib) ? kib * 1024 : 0;
  }
  return 0;
}

/// Bytes a training step keeps per Gaussian of a model with `channels` colour channels of `sh_coeffs`
/// SH coefficients each: parameters, gradients and both Adam moments (4 copies of 11 geometry
/// floats and the colour floats), plus the rasteriser's projection buffers and the density
/// statistics (at most 256 bytes).
inline std::size_t training_bytes_per_gaussian(int channels, int sh_coeffs) {
  return 4 * sizeof(float) * (11 + std::size_t(channels) * std::size_t(sh_coeffs)) + 256;
}

/// The model size at which a run stops: three quarters of the available memory at the start, over
/// the bytes per Gaussian (0 = unknown memory: no limit).
inline std::size_t stop_gaussians_for(std::uint64_t available_bytes, std::size_t bytes_per_gaussian) {
  if (available_bytes == 0 || bytes_per_gaussian == 0) return 0;
  return std::size_t(available_bytes / 4 * 3 / bytes_per_gaussian);
}

}  // namespace msgs::cli
