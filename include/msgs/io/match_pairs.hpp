// include/msgs/io/match_pairs.hpp
// Which image pairs COLMAP matches when `msgs import` builds a dataset. Matching every pair costs
// the square of the image count: on two cores COLMAP matched a pair of 320x240 images in 0.025 s
// and of 1024x768 in 0.4 s, and a flight of 200 captures with five bands has 500k pairs (3.5 hours
// to 2 days). A drone flies its captures in order, so the pairs that can share a view are mostly those of
// nearby captures: window_pairs keeps every pair within a capture (the bands of one capture see the
// same ground, and these pairs tie the bands' cameras together) and, across captures at most
// `window` apart, the pairs of one band (the same camera, the same spectrum: the matches SIFT finds
// most easily), a number of pairs that grows with the image count, not with its square. A window
// misses the views a path comes back to (the next line of a survey grid); where the files carry
// GPS positions, neighbour_pairs links each capture with its nearest ones on the ground instead.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace msgs::io {

/// An image of an import as pair selection sees it: its capture's position in flight order (the
/// sorted capture names) and its band.
struct PairImage {
  std::size_t capture = 0;
  std::string band;
};

/// Every unordered pair of n images: n (n - 1) / 2.
inline std::size_t exhaustive_pair_count(std::size_t n) { return n < 2 ? 0 : n * (n - 1) / 2; }

/// The pairs (i, j), i < j, of indices into `images` of two images of one capture, or of two
/// images of the same band whose captures are `linked(a, b)` (asked with a < b). Ascending in
/// (i, j); no pair twice.
template <class Linked>
std::vector<std::pair<std::size_t, std::size_t>> capture_pairs(const std::vector<PairImage>& images, Linked&& linked) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < images.size(); ++i)
    for (std::size_t j = i + 1; j < images.size(); ++j) {
      const std::size_t a = images[i].capture, b = images[j].capture;
      if (a == b || (images[i].band == images[j].band && (a < b ? linked(a, b) : linked(b, a)))) pairs.emplace_back(i, j);
    }
  return pairs;
}

/// Windowed matching: two images of one capture, and two images of the same band whose captures
/// are at most `window` apart. With window 0 only the pairs within a capture remain.
inline std::vector<std::pair<std::size_t, std::size_t>> window_pairs(const std::vector<PairImage>& images,
                                                                     std::size_t window) {
  return capture_pairs(images, [window](std::size_t a, std::size_t b) { return b - a <= window; });
}

/// The sphere local_metres and local_to_gps map on: the Earth's mean radius, in metres.
inline constexpr double kEarthRadius = 6371008.8;
inline constexpr double kRadiansPerDegree = 3.14159265358979323846 / 180.0;

/// A GPS position (latitude, longitude in degrees, altitude in metres) as metres east, north and up
/// of (lat0, lon0) on a sphere of the Earth's mean radius: exact enough for the distances between
/// the captures of one flight (under 0.1 % over a few kilometres).
inline std::array<double, 3> local_metres(const std::array<double, 3>& gps, double lat0, double lon0) {
  return {kEarthRadius * (gps[1] - lon0) * kRadiansPerDegree * std::cos(lat0 * kRadiansPerDegree),
          kEarthRadius * (gps[0] - lat0) * kRadiansPerDegree, gps[2]};
}

/// The inverse of local_metres: metres east, north and up of (lat0, lon0) as latitude, longitude
/// (degrees) and altitude (metres).
inline std::array<double, 3> local_to_gps(const std::array<double, 3>& enu, double lat0, double lon0) {
  return {lat0 + enu[1] / (kEarthRadius * kRadiansPerDegree),
          lon0 + enu[0] / (kEarthRadius * kRadiansPerDegree * std::cos(lat0 * kRadiansPerDegree)), enu[2]};
}

/// Neighbour matching: two images of one capture, and two images of the same band whose captures
/// are among each other's `k` nearest (either way round) by position (`positions[c]`, metres, one
/// per capture; equal distances go to the lower capture index). Unlike a window it follows the
/// ground, not the order of the files: the next line of a survey grid is near.
inline std::vector<std::pair<std::size_t, std::size_t>> neighbour_pairs(
    const std::vector<PairImage>& images, const std::vector<std::array<double, 3>>& positions, std::size_t k) {
  const std::size_t C = positions.size();
  std::vector<std::vector<bool>> near(C, std::vector<bool>(C, false));
  std::vector<std::pair<double, std::size_t>> by_distance;
  for (std::size_t a = 0; a < C; ++a) {
    by_distance.clear();
    for (std::size_t b = 0; b < C; ++b) {
      if (b == a) continue;
      double d2 = 0;
      for (int i = 0; i < 3; ++i) d2 += (positions[a][i] - positions[b][i]) * (positions[a][i] - positions[b][i]);
      by_distance.emplace_back(d2, b);
    }
    const std::size_t n = std::min(k, by_distance.size());
    std::partial_sort(by_distance.begin(), by_distance.begin() + std::ptrdiff_t(n), by_distance.end());
    for (std::size_t i = 0; i < n; ++i) near[a][by_distance[i].second] = near[by_distance[i].second][a] = true;
  }
  return capture_pairs(images, [&](std::size_t a, std::size_t b) { return a < C && b < C && near[a][b]; });
}

}  // namespace msgs::io
