// include/msgs/bin.hpp
// Stage 2 of the rasteriser: bin visible Gaussians into 16x16 screen tiles and sort each tile's
// list front to back. Deterministic for any thread count: one global depth sort (ties by index)
// followed by a stable, fixed-chunk counting sort by tile.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

namespace msgs {

/// The screen split into square tiles.
struct TileGrid {
  static constexpr int kTileSize = 16;
  static constexpr int kTilePixels = kTileSize * kTileSize;
  int width = 0, height = 0;
  int tiles_x = 0, tiles_y = 0;

  TileGrid() = default;
  TileGrid(int w, int h)
      : width(w), height(h), tiles_x((w + kTileSize - 1) / kTileSize), tiles_y((h + kTileSize - 1) / kTileSize) {}
  int count() const { return tiles_x * tiles_y; }
};

/// Inclusive pixel bounding box of a splat, already clipped to the image.
struct PixelRect {
  std::int32_t x0 = 0, y0 = 0, x1 = -1, y1 = -1;
  bool empty() const { return x1 < x0 || y1 < y0; }
};

/// Pixel rectangle whose centres (i + 0.5, j + 0.5) may lie within `extent` of `mean`. A small
/// relative margin absorbs the difference between the double-precision extent and the
/// single-precision alpha test, so no pixel that passes alpha >= 1/255 is ever left out.
inline PixelRect pixel_rect(double mx, double my, double ex, double ey, int width, int height) {
  ex = ex * (1.0 + 1e-4) + 1e-6 * std::abs(mx) + 1e-2;
  ey = ey * (1.0 + 1e-4) + 1e-6 * std::abs(my) + 1e-2;
  // Clip in double before converting, so huge extents never overflow an int.
  const double x0 = std::max(0.0, std::ceil(mx - ex - 0.5));
  const double x1 = std::min(double(width - 1), std::floor(mx + ex - 0.5));
  const double y0 = std::max(0.0, std::ceil(my - ey - 0.5));
  const double y1 = std::min(double(height - 1), std::floor(my + ey - 0.5));
  PixelRect r;
  if (!(x0 <= x1) || !(y0 <= y1)) return r;  // also catches NaN
  r.x0 = std::int32_t(x0); r.x1 = std::int32_t(x1);
  r.y0 = std::int32_t(y0); r.y1 = std::int32_t(y1);
  return r;
}

/// Tile lists of one frame. Intersection counts are 64-bit: a million large splats can exceed
/// 2^32 pixel-tile pairs.
struct Binning {
  std::vector<std::uint32_t> order;        ///< [V] visible Gaussian ids, front to back
  /// [V + 1] pairs of the v-th visible Gaussian (in the increasing id order of the visible ids
  /// passed to bin_gaussians): [pair_offset[v], pair_offset[v+1]). Id order lets the gradient
  /// reduction read the model sequentially.
  std::vector<std::uint64_t> pair_offset;
  std::vector<std::uint64_t> pair_slot;    ///< [M] position of pair m in tile_list (pairs in tile order per Gaussian)
  std::vector<std::uint32_t> tile_list;    ///< [M] Gaussian ids, grouped by tile, front to back within a tile
  std::vector<std::uint64_t> tile_offset;  ///< [tiles + 1] tile t owns tile_list[tile_offset[t] .. tile_offset[t+1])

  std::uint64_t pairs() const { return tile_list.size(); }
};

namespace detail {

/// Order-preserving unsigned key of a positive depth (float or double bit pattern).
template <class S>
inline auto depth_key(S z) {
  if constexpr (std::is_same_v<S, float>) {
    std::uint32_t k; std::memcpy(&k, &z, sizeof k); return k;
  } else {
    std::uint64_t k; std::memcpy(&k, &z, sizeof k); return k;
  }
}

/// Stable LSD radix sort of `ids` by `keys` (bytes of the key, low to high); equal keys keep their
/// input order, so ties stay ordered by Gaussian index.
template <class Key>
inline void radix_sort_by_key(std::vector<Key>& keys, std::vector<std::uint32_t>& ids) {
  const std::size_t n = keys.size();
  std::vector<Key> k2(n);
  std::vector<std::uint32_t> i2(n);
  for (unsigned shift = 0; shift < 8 * sizeof(Key); shift += 8) {
    std::size_t count[257] = {};
    for (std::size_t i = 0; i < n; ++i) ++count[((keys[i] >> shift) & 0xff) + 1];
    bool trivial = false;  // all keys share this byte: the pass would be the identity
    for (int b = 1; b <= 256; ++b) trivial = trivial || count[b] == n;
    if (trivial) continue;
    for (int b = 0; b < 256; ++b) count[b + 1] += count[b];
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t pos = count[(keys[i] >> shift) & 0xff]++;
      k2[pos] = keys[i];
      i2[pos] = ids[i];
    }
    keys.swap(k2);
    ids.swap(i2);
  }
}

}  // namespace detail

/// Bin the visible Gaussians. `visible_ids` [V] in increasing order, `depth` [N] camera z,
/// `rects` [N] pixel rectangles (non-empty for every visible id).
template <class S>
inline void bin_gaussians(const std::vector<std::uint32_t>& visible_ids, const S* depth, const PixelRect* rects,
                          const TileGrid& grid, Binning& out) {
  constexpr int TS = TileGrid::kTileSize;
  const std::size_t V = visible_ids.size();
  const int tiles = grid.count();

  // 1. Front-to-back order of the visible Gaussians.
  using Key = decltype(detail::depth_key(S(0)));
  // Sorted are positions v into visible_ids (increasing ids, so ties stay ordered by id).
  std::vector<Key> keys(V);
  std::vector<std::uint32_t> pos(V);
  for (std::size_t v = 0; v < V; ++v) {
    keys[v] = detail::depth_key(depth[visible_ids[v]]);
    pos[v] = std::uint32_t(v);
  }
  detail::radix_sort_by_key(keys, pos);
  out.order.resize(V);
  for (std::size_t s = 0; s < V; ++s) out.order[s] = visible_ids[pos[s]];

  // 2. Pairs per Gaussian (tile-rectangle area), prefix-summed in id order.
  out.pair_offset.assign(V + 1, 0);
  for (std::size_t v = 0; v < V; ++v) {
    const PixelRect& r = rects[visible_ids[v]];
    const std::uint64_t nx = std::uint64_t(r.x1 / TS - r.x0 / TS + 1), ny = std::uint64_t(r.y1 / TS - r.y0 / TS + 1);
    out.pair_offset[v + 1] = out.pair_offset[v] + nx * ny;
  }
  const std::uint64_t M = out.pair_offset[V];

  // 3. Stable counting sort by tile over a fixed number of chunks (independent of the thread
  //    count, so the result is too).
  const int chunks = int(std::clamp<std::size_t>(V / 4096, 1, 64));
  std::vector<std::uint64_t> hist(std::size_t(chunks) * std::size_t(tiles), 0);  // [chunks, tiles]
  auto chunk_begin = [&](int k) { return V * std::size_t(k) / std::size_t(chunks); };
#pragma omp parallel for schedule(static)
  for (int k = 0; k < chunks; ++k) {
    std::uint64_t* h = hist.data() + std::size_t(k) * std::size_t(tiles);
    for (std::size_t s = chunk_begin(k); s < chunk_begin(k + 1); ++s) {
      const PixelRect& r = rects[out.order[s]];
      for (int ty = r.y0 / TS; ty <= r.y1 / TS; ++ty)
        for (int tx = r.x0 / TS; tx <= r.x1 / TS; ++tx) ++h[std::size_t(ty) * std::size_t(grid.tiles_x) + std::size_t(tx)];
    }
  }
  out.tile_offset.assign(std::size_t(tiles) + 1, 0);
  for (int t = 0; t < tiles; ++t) {
    std::uint64_t sum = out.tile_offset[std::size_t(t)];
    for (int k = 0; k < chunks; ++k) {
      std::uint64_t& h = hist[std::size_t(k) * std::size_t(tiles) + std::size_t(t)];
      const std::uint64_t c = h;
      h = sum;  // becomes this chunk's write cursor for tile t
      sum += c;
    }
    out.tile_offset[std::size_t(t) + 1] = sum;
  }
  out.tile_list.resize(M);
  out.pair_slot.resize(M);
#pragma omp parallel for schedule(static)
  for (int k = 0; k < chunks; ++k) {
    std::uint64_t* cursor = hist.data() + std::size_t(k) * std::size_t(tiles);
    for (std::size_t s = chunk_begin(k); s < chunk_begin(k + 1); ++s) {
      const std::uint32_t g = out.order[s];
      const PixelRect& r = rects[g];
      std::uint64_t m = out.pair_offset[pos[s]];
      for (int ty = r.y0 / TS; ty <= r.y1 / TS; ++ty)
        for (int tx = r.x0 / TS; tx <= r.x1 / TS; ++tx) {
          const std::uint64_t slot = cursor[std::size_t(ty) * std::size_t(grid.tiles_x) + std::size_t(tx)]++;
          out.tile_list[slot] = g;
          out.pair_slot[m++] = slot;
        }
    }
  }
}

}  // namespace msgs
