// Binning (include/msgs/bin.hpp) against slow references: the radix sort against std::stable_sort,
// and the tile lists against a per-tile sort of every Gaussian that covers the tile.
#include <doctest/doctest.h>
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include "msgs/bin.hpp"

namespace test_bin {
using namespace msgs;

namespace {

/// Positions 0 .. keys.size()-1 in the order of std::stable_sort by key.
template <class Key>
std::vector<std::uint32_t> stable_order(const std::vector<Key>& keys) {
  std::vector<std::uint32_t> ids(keys.size());
  std::iota(ids.begin(), ids.end(), 0u);
  std::stable_sort(ids.begin(), ids.end(), [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
  return ids;
}

/// Radix-sorted ids of `keys` (carried ids 0, 1, ...), with `threads` threads.
template <class Key>
std::vector<std::uint32_t> radix_order(std::vector<Key> keys, int threads) {
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  std::vector<std::uint32_t> ids(keys.size());
  std::iota(ids.begin(), ids.end(), 0u);
  std::vector<detail::KeyedId<Key>> items, scratch;
  std::vector<std::uint64_t> hist;
  const std::vector<Key> original = keys;
  detail::radix_sort_by_key(keys, ids, items, scratch, hist);
  omp_set_num_threads(before);
  // The keys come back sorted, each minus the smallest.
  if (!original.empty()) {
    const Key lo = *std::min_element(original.begin(), original.end());
    for (std::size_t i = 0; i < ids.size(); ++i) REQUIRE(keys[i] == Key(original[ids[i]] - lo));
  }
  return ids;
}

template <class Key>
void check_radix(const std::vector<Key>& keys) {
  const std::vector<std::uint32_t> ref = stable_order(keys);
  CHECK(radix_order(keys, 1) == ref);
  CHECK(radix_order(keys, 2) == ref);
}

}  // namespace

TEST_CASE("radix_sort orders as std::stable_sort, ties in input order, for any range of keys") {
  std::mt19937_64 rng(7);
  SUBCASE("edge sizes and ranges") {
    check_radix(std::vector<std::uint32_t>{});
    check_radix(std::vector<std::uint32_t>{5});
    check_radix(std::vector<std::uint32_t>(10000, 42u));  // all equal: the input order
    check_radix(std::vector<std::uint32_t>{3, 1, 2, 1, 3, 0});
    check_radix(std::vector<std::uint32_t>{0u, std::numeric_limits<std::uint32_t>::max(), 0u, 1u});  // a range of 32 bits
    check_radix(std::vector<std::uint64_t>{0u, std::numeric_limits<std::uint64_t>::max(), 7u, 7u, 1u});  // 64 bits
  }
  SUBCASE("random keys, several chunks, each number of passes") {
    for (int bits : {1, 3, 8, 11, 12, 22, 23, 25, 32}) {
      std::vector<std::uint32_t> keys(std::size_t(20000 + rng() % 30000));
      const std::uint32_t base = std::uint32_t(rng());
      for (auto& k : keys) k = std::uint32_t(base + (rng() >> (64 - bits)));  // wraps for some bases
      CAPTURE(bits);
      check_radix(keys);
    }
    for (int bits : {5, 33, 44, 55, 64}) {
      std::vector<std::uint64_t> keys(std::size_t(30000 + rng() % 20000));
      for (auto& k : keys) k = bits == 64 ? rng() : rng() >> (64 - bits);
      CAPTURE(bits);
      check_radix(keys);
    }
  }
  SUBCASE("a pass whose digit every key shares is skipped") {
    std::vector<std::uint32_t> keys(30000);
    for (auto& k : keys) k = std::uint32_t(rng() % 1000) << 12;  // 22 bits: two passes, the low one all zero
    check_radix(keys);
  }
  SUBCASE("depth keys of floats") {
    std::uniform_real_distribution<float> z(0.2f, 500.f);
    std::vector<std::uint32_t> keys(60000);
    for (auto& k : keys) k = detail::depth_key(rng() % 5 == 0 ? 3.25f : z(rng));  // many ties
    check_radix(keys);
  }
}

namespace {

struct Frame {
  std::vector<std::uint32_t> visible;  // ascending ids
  std::vector<float> depth;             // [N]
  std::vector<PixelRect> rects;         // [N]
};

Frame random_frame(std::mt19937_64& rng, const TileGrid& grid, std::size_t n, double max_extent) {
  Frame f;
  f.depth.resize(n);
  f.rects.resize(n);
  std::uniform_real_distribution<double> ux(-20.0, grid.width + 20.0), uy(-20.0, grid.height + 20.0),
      ue(0.0, max_extent), uz(0.5, 60.0);
  for (std::size_t g = 0; g < n; ++g) {
    // Some depths repeat exactly (a clone and its parent): ties.
    f.depth[g] = g > 0 && rng() % 7 == 0 ? f.depth[g - 1 - rng() % std::min<std::size_t>(g, 5)] : float(uz(rng));
    const double e = rng() % 10 == 0 ? 4 * ue(rng) : ue(rng);
    f.rects[g] = pixel_rect(ux(rng), uy(rng), e, e, grid.width, grid.height);
    if (!f.rects[g].empty() && rng() % 5 != 0) f.visible.push_back(std::uint32_t(g));
  }
  return f;
}

/// The tile lists by brute force: for every tile, the visible Gaussians whose tile rectangle
/// covers it, by (depth, tie key, id).
template <class Tie>
std::vector<std::vector<std::uint32_t>> reference_lists(const Frame& f, const TileGrid& grid, const Tie& tie) {
  constexpr int TS = TileGrid::kTileSize;
  std::vector<std::vector<std::uint32_t>> lists(std::size_t(grid.count()));
  for (std::uint32_t g : f.visible) {
    const PixelRect& r = f.rects[g];
    for (int ty = r.y0 / TS; ty <= r.y1 / TS; ++ty)
      for (int tx = r.x0 / TS; tx <= r.x1 / TS; ++tx) lists[std::size_t(ty * grid.tiles_x + tx)].push_back(g);
  }
  for (auto& l : lists)
    std::sort(l.begin(), l.end(), [&](std::uint32_t a, std::uint32_t b) {
      if (f.depth[a] != f.depth[b]) return f.depth[a] < f.depth[b];
      if (tie(a) != tie(b)) return tie(a) < tie(b);
      return a < b;
    });
  return lists;
}

template <class Tie>
void check_binning(const Frame& f, const TileGrid& grid, const Tie& tie, int threads) {
  constexpr int TS = TileGrid::kTileSize;
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  Binning b;
  bin_gaussians(f.visible, f.depth.data(), f.rects.data(), grid, b, tie);
  bin_gaussians(f.visible, f.depth.data(), f.rects.data(), grid, b, tie);  // again, with the scratch of the first
  omp_set_num_threads(before);
  const auto ref = reference_lists(f, grid, tie);
  REQUIRE(b.tile_offset.size() == std::size_t(grid.count()) + 1);
  for (int t = 0; t < grid.count(); ++t) {
    const std::vector<std::uint32_t> got(b.tile_list.begin() + std::ptrdiff_t(b.tile_offset[std::size_t(t)]),
                                         b.tile_list.begin() + std::ptrdiff_t(b.tile_offset[std::size_t(t) + 1]));
    CAPTURE(t);
    CHECK(got == ref[std::size_t(t)]);
  }
  // Pair ranges in id order, each Gaussian's pairs numbered row-major over its tiles.
  const std::size_t V = f.visible.size();
  REQUIRE(b.pair_offset.size() == V + 1);
  std::vector<std::uint32_t> position(f.depth.size(), 0);
  for (std::size_t v = 0; v < V; ++v) {
    const PixelRect& r = f.rects[f.visible[v]];
    const std::uint64_t area = std::uint64_t(r.x1 / TS - r.x0 / TS + 1) * std::uint64_t(r.y1 / TS - r.y0 / TS + 1);
    CHECK(b.pair_offset[v + 1] - b.pair_offset[v] == area);
    position[f.visible[v]] = std::uint32_t(v);
  }
  for (int t = 0; t < grid.count(); ++t)
    for (std::uint64_t s = b.tile_offset[std::size_t(t)]; s < b.tile_offset[std::size_t(t) + 1]; ++s) {
      const std::uint32_t g = b.tile_list[s];
      const PixelRect& r = f.rects[g];
      const int w = r.x1 / TS - r.x0 / TS + 1;
      const std::uint64_t j = std::uint64_t((t / grid.tiles_x - r.y0 / TS) * w + (t % grid.tiles_x - r.x0 / TS));
      CHECK(b.pair(g, r, t % grid.tiles_x, t / grid.tiles_x) == b.pair_offset[position[g]] + j);
      CHECK(b.first_pair_of[g] == b.pair_offset[position[g]]);
    }
  // The depth order of the visible Gaussians.
  std::vector<std::uint32_t> order = f.visible;
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t c) {
    if (f.depth[a] != f.depth[c]) return f.depth[a] < f.depth[c];
    return tie(a) < tie(c);
  });
  CHECK(b.order == order);
}

}  // namespace

TEST_CASE("bin_gaussians: tile lists front to back, pair numbering, for 1 and 2 threads") {
  std::mt19937_64 rng(11);
  // 180 tiles; 12 (the small scene at 1/4 resolution: a chunk's counters fill less than a cache
  // line, so the rows are padded); a single tile.
  for (const TileGrid grid : {TileGrid(240, 180), TileGrid(60, 45), TileGrid(16, 16)})
    for (double extent : {6.0, 20.0, 90.0}) {  // mostly 1 to 4 tiles; larger splats; very large ones
      const Frame f = random_frame(rng, grid, 30000, extent);
      CAPTURE(grid.count());
      CAPTURE(extent);
      const TiesById by_id;
      const auto by_hash = [](std::uint32_t g) { return std::uint64_t(g) * 0x9e3779b97f4a7c15ULL >> 40; };
      // The rasteriser's key (with the prefetch hint); every third Gaussian has the same mean, so
      // that equal keys fall back to the id.
      std::vector<float> means(3 * f.depth.size());
      std::mt19937_64 mrng(5);
      for (std::size_t i = 0; i < means.size(); ++i) means[i] = (i / 3) % 3 == 0 ? 1.5f : float(mrng() % 4096) / 64.0f;
      const TiesByMean<float> by_mean{means.data()};
      for (int threads : {1, 2}) {
        check_binning(f, grid, by_id, threads);
        check_binning(f, grid, by_hash, threads);
        check_binning(f, grid, by_mean, threads);
      }
    }
  const TileGrid grid(240, 180);
  SUBCASE("nothing visible") {
    Frame f;
    Binning b;
    bin_gaussians(f.visible, f.depth.data(), f.rects.data(), grid, b);
    CHECK(b.pairs() == 0);
    CHECK(b.tile_offset.back() == 0);
  }
}

}  // namespace test_bin
