// examples/memory_guard.hpp
// `msgs train`'s guard against runaway densification: the most Gaussians a model may reach before
// the run stops with a clear error instead of running out of memory (DensifyConfig::stop_gaussians).
// The limit only ends runs that would not fit; it never changes a result.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <msgs/io/bands.hpp>
#include <msgs/gaussian.hpp>
#include <msgs/strategy.hpp>

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
/// floats and the colour floats), the spare colour planes refinement gathers into (one more copy
/// of the colour floats), plus the rasteriser's projection buffers and the density statistics (at
/// most 256 bytes).
inline std::size_t training_bytes_per_gaussian(int channels, int sh_coeffs) {
  const std::size_t colour = std::size_t(channels) * std::size_t(sh_coeffs);
  return sizeof(float) * (4 * (11 + colour) + colour) + 256;
}

/// The model size at which a run stops: three quarters of the available memory at the start, over
/// the bytes per Gaussian (0 = unknown memory: no limit).
inline std::size_t stop_gaussians_for(std::uint64_t available_bytes, std::size_t bytes_per_gaussian) {
  if (available_bytes == 0 || bytes_per_gaussian == 0) return 0;
  return std::size_t(available_bytes / 4 * 3 / bytes_per_gaussian);
}

/// The stop limit of a run of `strategy` on `band_ids` at SH degree `sh_degree` when `share` runs
/// train at once: the largest model it trains (Joint's 7 channels, else the widest band) against
/// 1/share of the memory available now.
inline std::size_t default_stop_gaussians(const std::string& strategy, const std::vector<std::string>& band_ids,
                                          int sh_degree, int share = 1) {
  int channels = 1;
  if (parse_strategy(strategy).plan.kind == StrategyKind::Joint) channels = io::joint_channels();
  else
    for (const auto& id : band_ids)
      if (const io::BandInfo* b = io::find_band(id)) channels = std::max(channels, b->channels);
  return stop_gaussians_for(available_memory_bytes() / std::uint64_t(std::max(share, 1)),
                            training_bytes_per_gaussian(channels, sh_coeffs_for_degree(sh_degree)));
}

}  // namespace msgs::cli
