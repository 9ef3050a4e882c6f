// include/msgs/spatial_order.hpp
// Gaussians in spatial order: rows sorted by the Morton (Z-order) code of their means, so that
// Gaussians near each other in space are near each other in memory. A view sees a region of
// space; with the rows in this order the Gaussians it sees form runs of consecutive rows instead
// of being scattered over the whole model, so the stages that work on the rows a view saw (the
// gradient reduction, the projection and colour backward, the zeroing of unseen gradients, the
// statistics) read and write whole cache lines, and the projection rejects whole vectors of
// Gaussians that are all out of view before their covariance and colour. Densification keeps a
// model in this order when DensifyConfig::reorder_every asks for it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "msgs/bin.hpp"

namespace msgs {

namespace detail {
/// The low 21 bits of v spread to every third bit (bit i to bit 3 i).
inline std::uint64_t spread_bits3(std::uint64_t v) {
  v &= 0x1FFFFFull;
  v = (v | v << 32) & 0x1F00000000FFFFull;
  v = (v | v << 16) & 0x1F0000FF0000FFull;
  v = (v | v << 8) & 0x100F00F00F00F00Full;
  v = (v | v << 4) & 0x10C30C30C30C30C3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

/// All three coordinates of p finite.
template <class S>
inline bool finite_point(const S* p) {
  return std::isfinite(double(p[0])) && std::isfinite(double(p[1])) && std::isfinite(double(p[2]));
}
}  // namespace detail

/// Morton codes of `n` points (`means`, [n, 3]): 21 bits per axis over the bounding box of the
/// finite points, x in the lowest bit of each triple. A point with a non-finite coordinate gets the
/// largest code, so it sorts last. Depends on the values only (no threads, no state).
template <class S>
std::vector<std::uint64_t> morton_codes(const S* means, std::size_t n) {
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  bool any = false;
  for (std::size_t i = 0; i < n; ++i) {
    const S* p = means + 3 * i;
    if (!detail::finite_point(p)) continue;
    for (int a = 0; a < 3; ++a) {
      lo[a] = any ? std::min(lo[a], double(p[a])) : double(p[a]);
      hi[a] = any ? std::max(hi[a], double(p[a])) : double(p[a]);
    }
    any = true;
  }
  constexpr double kCells = double(1u << 21);
  double scale[3];
  for (int a = 0; a < 3; ++a) {
    // An extent beyond double's range (hi - lo overflows) collapses the axis to one cell.
    const double extent = hi[a] - lo[a];
    scale[a] = extent > 0.0 && std::isfinite(extent) ? (kCells - 1.0) / extent : 0.0;
  }
  std::vector<std::uint64_t> code(n);
  for (std::size_t i = 0; i < n; ++i) {
    const S* p = means + 3 * i;
    if (!detail::finite_point(p)) {
      code[i] = ~std::uint64_t(0);
      continue;
    }
    std::uint64_t c = 0;
    for (int a = 0; a < 3; ++a) {
      // (On a collapsed axis p - lo may itself overflow, and inf x 0 would be NaN.)
      const double q = scale[a] > 0.0 ? std::clamp((double(p[a]) - lo[a]) * scale[a], 0.0, kCells - 1.0) : 0.0;
      c |= detail::spread_bits3(std::uint64_t(q)) << a;
    }
    code[i] = c;
  }
  return code;
}

/// The rows 0 .. code.size() - 1 ordered by ascending code; equal codes keep their row order.
inline std::vector<std::uint32_t> order_by_code(std::vector<std::uint64_t> code) {
  std::vector<std::uint32_t> order(code.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = std::uint32_t(i);
  std::vector<detail::KeyedId<std::uint64_t>> items, scratch;
  std::vector<std::uint64_t> hist;
  detail::radix_sort_by_key(code, order, items, scratch, hist);
  return order;
}

}  // namespace msgs
