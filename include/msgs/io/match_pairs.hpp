// include/msgs/io/match_pairs.hpp
// Which image pairs COLMAP matches when `msgs import` builds a dataset. Matching every pair costs
// the square of the image count: on two cores COLMAP matched 80 images of 1024x768 and 512x384 in
// 400 s, and a flight of 200 captures with five bands (1000 images, 500k pairs) would take about a
// day. A drone flies its captures in order, so the pairs that can share a view are mostly those of
// nearby captures: window_pairs keeps every pair within a capture (the bands of one capture see the
// same ground, and these pairs tie the bands' cameras together) and, across captures at most
// `window` apart, the pairs of one band (the same camera, the same spectrum: the matches SIFT finds
// most easily), a number of pairs that grows with the image count, not with its square.
#pragma once

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

/// The pairs (i, j), i < j, of indices into `images` that windowed matching matches: two images of
/// one capture, and two images of the same band whose captures are at most `window` apart.
/// Ascending in (i, j); no pair twice. With window 0 only the pairs within a capture remain.
inline std::vector<std::pair<std::size_t, std::size_t>> window_pairs(const std::vector<PairImage>& images,
                                                                     std::size_t window) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < images.size(); ++i)
    for (std::size_t j = i + 1; j < images.size(); ++j) {
      const std::size_t a = images[i].capture, b = images[j].capture;
      const std::size_t apart = a < b ? b - a : a - b;
      if (apart == 0 || (apart <= window && images[i].band == images[j].band)) pairs.emplace_back(i, j);
    }
  return pairs;
}

}  // namespace msgs::io
