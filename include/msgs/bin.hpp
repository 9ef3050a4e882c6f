// include/msgs/bin.hpp
// Stage 2 of the rasteriser: bin visible Gaussians into 16x16 screen tiles and sort each tile's
// list front to back. Deterministic for any thread count: one global depth sort (ties by a key
// the caller gives, then by index) followed by a stable, fixed-chunk counting sort by tile.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <tuple>
#include <type_traits>
#include <vector>

#include "detail/overwrite_vector.hpp"

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
/// single-precision alpha test, so no pixel that passes alpha >= 1/255 is ever left out. A mean
/// that is not finite, or a NaN extent, gives the empty rectangle (std::max and std::min below
/// would turn the NaN bounds they lead to into the image's edges: the whole image).
inline PixelRect pixel_rect(double mx, double my, double ex, double ey, int width, int height) {
  if (!std::isfinite(mx) || !std::isfinite(my) || std::isnan(ex) || std::isnan(ey)) return PixelRect{};
  ex = ex * (1.0 + 1e-4) + 1e-6 * std::abs(mx) + 1e-2;
  ey = ey * (1.0 + 1e-4) + 1e-6 * std::abs(my) + 1e-2;
  // Clip in double before converting, so huge extents never overflow an int.
  const double x0 = std::max(0.0, std::ceil(mx - ex - 0.5));
  const double x1 = std::min(double(width - 1), std::floor(mx + ex - 0.5));
  const double y0 = std::max(0.0, std::ceil(my - ey - 0.5));
  const double y1 = std::min(double(height - 1), std::floor(my + ey - 0.5));
  PixelRect r;
  if (!(x0 <= x1) || !(y0 <= y1)) return r;
  r.x0 = std::int32_t(x0); r.x1 = std::int32_t(x1);
  r.y0 = std::int32_t(y0); r.y1 = std::int32_t(y1);
  return r;
}

namespace detail {
/// A sort key and the id it carries (radix_sort): one record, so that a pass scatters into one
/// stream per bucket.
template <class Key>
struct KeyedId {
  Key key;
  std::uint32_t id;
};

}  // namespace detail

/// Tile lists of one frame. Intersection counts are 64-bit: a million large splats can exceed
/// 2^32 pixel-tile pairs.
struct Binning {
  std::vector<std::uint32_t> order;        ///< [V] visible Gaussian ids, front to back
  /// [V + 1] pairs of the v-th visible Gaussian (in the increasing id order of the visible ids
  /// passed to bin_gaussians): [pair_offset[v], pair_offset[v+1]). Id order lets the gradient
  /// reduction read the model sequentially.
  std::vector<std::uint64_t> pair_offset;
  /// [last visible id + 1] first_pair_of[g] = pair_offset[v] for the v-th visible Gaussian g;
  /// unspecified for ids not visible. Within its range, a Gaussian numbers its pairs row-major over
  /// its tile rectangle (pair()): the blend backward writes each pair's gradient record there, so
  /// that the reduction reads each Gaussian's records in one sequential run. Computed where needed:
  /// storing it for every pair took about a fifth of the binning of a million Gaussians.
  detail::OverwriteVector<std::uint64_t> first_pair_of;
  detail::OverwriteVector<std::uint32_t> tile_list;  ///< [M] Gaussian ids, grouped by tile, front to back within a tile
  std::vector<std::uint64_t> tile_offset;  ///< [tiles + 1] tile t owns tile_list[tile_offset[t] .. tile_offset[t+1])

  std::uint64_t pairs() const { return tile_list.size(); }

  /// The number of the pair of visible Gaussian g, whose pixel rectangle is `rect`, and the tile
  /// (tx, ty) in g's tile rectangle: g's first pair plus the tile's row-major place in g's tiles.
  std::uint64_t pair(std::uint32_t g, const PixelRect& rect, int tx, int ty) const {
    constexpr int TS = TileGrid::kTileSize;
    const int x0 = rect.x0 / TS, y0 = rect.y0 / TS, w = rect.x1 / TS - x0 + 1;
    return first_pair_of[g] + std::uint64_t((ty - y0) * w + (tx - x0));
  }

  /// Working memory of bin_gaussians, kept between frames so that binning does not allocate (and
  /// page-fault) anew every frame. Not part of the result.
  struct Scratch {
    /// Depth keys and positions into the visible ids (radix sort), for float and double depths.
    std::vector<detail::KeyedId<std::uint32_t>> items32, items32b;
    std::vector<detail::KeyedId<std::uint64_t>> items64, items64b;
    /// The item buffers for depths of type S (detail::DepthKey).
    template <class S>
    auto item_buffers() {
      if constexpr (sizeof(S) == 4) return std::tie(items32, items32b);
      else return std::tie(items64, items64b);
    }
    struct TileRect {
      std::int32_t tx0, ty0, tx1, ty1;
    };
    std::vector<TileRect> rects;             // [V] tile rectangles in depth order
    std::vector<std::uint64_t> chunk_sums;   // [chunks + 1] pair counts of the prefix sum's chunks
    std::vector<std::uint64_t> hist;         // [chunks, tiles] or [chunks, radix buckets], rows on cache lines
  } scratch;
};

namespace detail {

/// The unsigned integer of a depth's width (32 bits for float, 64 for double).
template <class S>
using DepthKey = std::conditional_t<sizeof(S) == 4, std::uint32_t, std::uint64_t>;

/// Order-preserving unsigned key of a positive depth: its bit pattern.
template <class S>
inline DepthKey<S> depth_key(S z) {
  static_assert(sizeof(S) == sizeof(DepthKey<S>));
  DepthKey<S> k;
  std::memcpy(&k, &z, sizeof k);
  return k;
}

/// Number of fixed chunks a pass over `n` items is split into: independent of the thread count,
/// so that every result (and its bits) is too.
inline int fixed_chunks(std::size_t n) { return int(std::clamp<std::size_t>(n / 4096, 1, 64)); }

/// The number of T, at least n, that fill whole 64-byte cache lines.
template <class T>
constexpr std::size_t round_up_to_line(std::size_t n) {
  constexpr std::size_t per_line = 64 / sizeof(T);
  return (n + per_line - 1) / per_line * per_line;
}

/// The first element of `v` that starts a 64-byte cache line (`v` needs 64 / sizeof(T) - 1
/// elements of room for it).
template <class T>
T* first_on_line(std::vector<T>& v) {
  const std::uintptr_t p = reinterpret_cast<std::uintptr_t>(v.data());
  return v.data() + ((64 - p % 64) % 64) / sizeof(T);
}

/// Widest digit of radix_sort, in bits.
inline constexpr int kRadixMaxDigit = 11;

/// Stable LSD radix sort of `items` by key; equal keys keep their input order. The keys are first
/// reduced to their range (key - min, which keeps their order and their ties) and sorted in as few
/// passes as that range needs, with digits of up to kRadixMaxDigit bits: the depths of one view
/// span a few octaves, 25 bits of a float's pattern, 3 passes instead of 4 of a byte. The range is
/// found in one parallel pass; each sorting pass is a chunked counting sort (per-chunk histograms,
/// then every chunk scatters from its own cursors), parallel over a fixed number of chunks, all of
/// them in one parallel region. The keys
/// come back reduced (minus the smallest). `scratch` and `hist` are working memory. A stable sort
/// has one result, so the chunking does not change a bit.
template <class Key>
inline void radix_sort(std::vector<KeyedId<Key>>& items, std::vector<KeyedId<Key>>& scratch,
                       std::vector<std::uint64_t>& hist) {
  static_assert(std::is_unsigned_v<Key>);
  using Item = KeyedId<Key>;
  const std::size_t n = items.size();
  if (n == 0) return;
  const int chunks = fixed_chunks(n);
  auto chunk_begin = [&](int k) { return n * std::size_t(k) / std::size_t(chunks); };
  // The keys' range, per chunk (fixed_chunks gives at most 64).
  Key lo[64], hi[64];
#pragma omp parallel for schedule(static)
  for (int k = 0; k < chunks; ++k) {
    Key a = items[chunk_begin(k)].key, b = a;
    const std::size_t e = chunk_begin(k + 1);
    for (std::size_t i = chunk_begin(k); i < e; ++i) {
      a = std::min(a, items[i].key);
      b = std::max(b, items[i].key);
    }
    lo[k] = a;
    hi[k] = b;
  }
  const Key kmin = *std::min_element(lo, lo + chunks), kmax = *std::max_element(hi, hi + chunks);
  if (kmin == kmax) {  // every key equal: the input order is the sorted order
    for (Item& it : items) it.key = Key(0);
    return;
  }
  const int bits = int(std::bit_width(Key(kmax - kmin)));
  const int passes = (bits + kRadixMaxDigit - 1) / kRadixMaxDigit, digit = (bits + passes - 1) / passes;
  const std::size_t B = std::size_t(1) << digit;
  const Key mask = Key(B - 1);
  scratch.resize(n);
  const std::size_t row = round_up_to_line<std::uint64_t>(B);  // a chunk's counters start a cache line
  hist.resize(std::size_t(chunks) * row + row);                // [chunks, row >= B]
  std::uint64_t* const hist0 = first_on_line(hist);
  int scattered = 0;  // passes that scattered: the result is in `scratch` when odd
  bool skip = false;  // the current pass would be the identity
#pragma omp parallel
  {
    Item* src = items.data();
    Item* dst = scratch.data();
    for (int p = 0; p < passes; ++p) {
      const unsigned shift = unsigned(p * digit);
#pragma omp for schedule(static)
      for (int k = 0; k < chunks; ++k) {
        std::uint64_t* h = hist0 + std::size_t(k) * row;
        std::fill_n(h, B, std::uint64_t(0));
        const std::size_t e = chunk_begin(k + 1);  // (hoisted: the stores below could alias it for the compiler)
        if (p == 0)
          for (std::size_t i = chunk_begin(k); i < e; ++i) {
            const Key x = Key(src[i].key - kmin);  // the keys reduced on the first pass
            src[i].key = x;
            ++h[x & mask];
          }
        else
          for (std::size_t i = chunk_begin(k); i < e; ++i) ++h[(src[i].key >> shift) & mask];
      }
      // The cursors (bucket-major, chunk-minor: stable), unless one bucket holds every key (the
      // pass would be the identity). Written by one thread; the single's barrier publishes them.
#pragma omp single
      {
        // One serial pass: the cursors, and each bucket's total on the way (when the pass is
        // skipped, the next one counts its histograms anew).
        std::uint64_t sum = 0;
        skip = false;
        for (std::size_t b = 0; b < B; ++b) {
          const std::uint64_t start = sum;
          for (int k = 0; k < chunks; ++k) {
            std::uint64_t& h = hist0[std::size_t(k) * row + b];
            const std::uint64_t c = h;
            h = sum;
            sum += c;
          }
          skip = skip || sum - start == n;
        }
        if (!skip) ++scattered;
      }
      if (skip) continue;  // every thread read the same flag: the single's barrier came before
#pragma omp for schedule(static)
      for (int k = 0; k < chunks; ++k) {
        std::uint64_t* cursor = hist0 + std::size_t(k) * row;
        const std::size_t e = chunk_begin(k + 1);
        for (std::size_t i = chunk_begin(k); i < e; ++i) dst[cursor[(src[i].key >> shift) & mask]++] = src[i];
      }
      std::swap(src, dst);
    }
  }
  if (scattered % 2 == 1) items.swap(scratch);
}

/// radix_sort of `ids` by `keys` (equal keys keep their input order); `keys` come back sorted and
/// reduced (minus the smallest). `items` and `scratch` are working memory.
template <class Key>
inline void radix_sort_by_key(std::vector<Key>& keys, std::vector<std::uint32_t>& ids,
                              std::vector<KeyedId<Key>>& items, std::vector<KeyedId<Key>>& scratch,
                              std::vector<std::uint64_t>& hist) {
  const std::size_t n = keys.size();
  items.resize(n);
  for (std::size_t i = 0; i < n; ++i) items[i] = {keys[i], ids[i]};
  radix_sort(items, scratch, hist);
  for (std::size_t i = 0; i < n; ++i) {
    keys[i] = items[i].key;
    ids[i] = items[i].id;
  }
}

}  // namespace detail

/// How many Gaussians ahead bin_gaussians prefetches what it reads out of order.
inline constexpr std::int64_t kBinPrefetch = 16;

/// No tie key: Gaussians at exactly the same depth stay ordered by id.
struct TiesById {
  std::uint64_t operator()(std::uint32_t) const { return 0; }
};

/// Tie key from the bits of a Gaussian's mean (`means` [N, 3]): Gaussians at exactly the same
/// depth then blend in an order that does not depend on the order of the model's rows (the
/// rasteriser's RasterOptions::ties_by_mean). `prefetch` lets bin_gaussians fetch the rows of
/// later ties while it orders earlier ones.
template <class S>
struct TiesByMean {
  const S* means;
  std::uint64_t operator()(std::uint32_t g) const {
    std::uint64_t h = 0;
    for (int a = 0; a < 3; ++a) {
      std::uint64_t b = 0;
      std::memcpy(&b, &means[3 * std::size_t(g) + std::size_t(a)], sizeof(S));
      h = h * 0x9e3779b97f4a7c15ULL + b;
    }
    return h;
  }
  void prefetch(std::uint32_t g) const {
    __builtin_prefetch(&means[3 * std::size_t(g)]);
    __builtin_prefetch(&means[3 * std::size_t(g) + 2]);
  }
};

/// Bin the visible Gaussians. `visible_ids` [V] in increasing order, `depth` [N] camera z,
/// `rects` [N] pixel rectangles (non-empty for every visible id).
/// `tie_key(g)`: orders Gaussians at exactly the same depth (then by id). With a key that depends
/// on a Gaussian's parameters instead of its row (Rasterizer: the bits of its mean), the blend
/// order, and so the image, does not depend on the order of the model's rows. Called only for
/// Gaussians that tie (at 1M Gaussians about one in eight). A key type may also have
/// `prefetch(g)`, a hint to fetch what the key of g reads; it is called ahead of the key.
template <class S, class TieKey = TiesById>
inline void bin_gaussians(const std::vector<std::uint32_t>& visible_ids, const S* depth, const PixelRect* rects,
                          const TileGrid& grid, Binning& out, const TieKey& tie_key = {}) {
  constexpr int TS = TileGrid::kTileSize;
  const std::size_t V = visible_ids.size();
  const int tiles = grid.count();
  Binning::Scratch& sc = out.scratch;

  // 1. Front-to-back order of the visible Gaussians. Sorted are positions v into visible_ids
  //    (increasing ids, so ties stay ordered by id unless tie_key orders them below).
  //    The keys, and the pair count of every Gaussian (its tile-rectangle area, for step 2), are
  //    filled in one parallel pass.
  // Plain references, not a structured binding: Clang before 16 cannot name a structured binding
  // inside the OpenMP regions below.
  const auto buffers = sc.template item_buffers<S>();
  auto& items = std::get<0>(buffers);
  auto& items2 = std::get<1>(buffers);
  items.resize(V);
  out.pair_offset.resize(V + 1);
  out.pair_offset[0] = 0;
#pragma omp parallel for schedule(static)
  for (std::int64_t iv = 0; iv < std::int64_t(V); ++iv) {
    const std::size_t v = std::size_t(iv);
    const std::uint32_t g = visible_ids[v];
    items[v] = {detail::depth_key(depth[g]), std::uint32_t(v)};
    const PixelRect& r = rects[g];
    out.pair_offset[v + 1] = std::uint64_t(r.x1 / TS - r.x0 / TS + 1) * std::uint64_t(r.y1 / TS - r.y0 / TS + 1);
  }
  detail::radix_sort(items, items2, sc.hist);
  if constexpr (!std::is_same_v<TieKey, TiesById>) {
    // Runs of equal depth keys, ordered by (tie key, id); positions are increasing ids within a run.
    // In parallel over fixed chunks: a run belongs to the chunk it starts in, and may end past it.
    // (Clones share their parent's depth until they move apart, so a frame has many such runs.)
    // A chunk lists its runs first, then orders them while it fetches what the keys of later runs
    // read: their Gaussians' ids kTieFetch runs ahead, and (where the key type has a `prefetch`)
    // the Gaussians' own data half as far ahead. Without it each tied entry waited on two
    // dependent cache misses.
    const int tchunks = detail::fixed_chunks(V);
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < tchunks; ++k) {
      const std::size_t c1 = V * std::size_t(k + 1) / std::size_t(tchunks);
      std::size_t i = V * std::size_t(k) / std::size_t(tchunks);
      if (i > 0)
        while (i < c1 && items[i].key == items[i - 1].key) ++i;  // the rest of an earlier chunk's run
      std::vector<std::pair<std::size_t, std::size_t>> runs;
      while (i < c1) {
        std::size_t e = i + 1;
        while (e < V && items[e].key == items[i].key) ++e;
        if (e - i > 1) runs.emplace_back(i, e);
        i = e;
      }
      const auto by_key = [&](const auto& a, const auto& b) {
        const std::uint64_t ka = tie_key(visible_ids[a.id]), kb = tie_key(visible_ids[b.id]);
        return ka != kb ? ka < kb : a.id < b.id;
      };
      constexpr std::size_t kTieFetch = 16;
      const std::size_t nr = runs.size();
      const auto fetch_ids = [&](std::size_t r) {
        for (std::size_t x = runs[r].first; x < runs[r].second; ++x) __builtin_prefetch(&visible_ids[items[x].id]);
      };
      const auto fetch_data = [&](std::size_t r) {
        if constexpr (requires { tie_key.prefetch(std::uint32_t(0)); })
          for (std::size_t x = runs[r].first; x < runs[r].second; ++x) tie_key.prefetch(visible_ids[items[x].id]);
      };
      for (std::size_t r = 0; r < std::min(nr, kTieFetch); ++r) fetch_ids(r);
      for (std::size_t r = 0; r < std::min(nr, kTieFetch / 2); ++r) fetch_data(r);
      for (std::size_t r = 0; r < nr; ++r) {
        if (r + kTieFetch < nr) fetch_ids(r + kTieFetch);
        if (r + kTieFetch / 2 < nr) fetch_data(r + kTieFetch / 2);
        std::sort(items.begin() + std::ptrdiff_t(runs[r].first), items.begin() + std::ptrdiff_t(runs[r].second), by_key);
      }
    }
  }
  // 2. Pairs per Gaussian (counted in step 1), prefix-summed in id order: per fixed chunk, then
  //    the chunks' totals, then each chunk from its offset (integers: the same sums in any order).
  //    Each Gaussian's first pair is also written by its id (first_pair_of).
  detail::resize_for_overwrite(out.first_pair_of, V == 0 ? 0 : std::size_t(visible_ids[V - 1]) + 1);
  {
    const int pchunks = detail::fixed_chunks(V);
    sc.chunk_sums.assign(std::size_t(pchunks) + 1, 0);
    std::uint64_t* po = out.pair_offset.data() + 1;  // po[v]: pairs of v, then pairs up to v inclusive
#pragma omp parallel for schedule(static)
    for (int k = 0; k < pchunks; ++k) {
      std::uint64_t sum = 0;
      for (std::size_t v = V * std::size_t(k) / std::size_t(pchunks), e = V * std::size_t(k + 1) / std::size_t(pchunks); v < e; ++v)
        sum += po[v];
      sc.chunk_sums[std::size_t(k) + 1] = sum;
    }
    for (int k = 0; k < pchunks; ++k) sc.chunk_sums[std::size_t(k) + 1] += sc.chunk_sums[std::size_t(k)];
#pragma omp parallel for schedule(static)
    for (int k = 0; k < pchunks; ++k) {
      std::uint64_t sum = sc.chunk_sums[std::size_t(k)];
      for (std::size_t v = V * std::size_t(k) / std::size_t(pchunks), e = V * std::size_t(k + 1) / std::size_t(pchunks); v < e; ++v) {
        out.first_pair_of[visible_ids[v]] = sum;
        po[v] = sum += po[v];
      }
    }
  }
  const std::uint64_t M = out.pair_offset[V];

  // The order and the tile rectangles of the Gaussians in that order, gathered once so that the
  // passes below read them sequentially. In depth order the ids jump over the whole model: what a
  // few iterations ahead reads is prefetched (at a million Gaussians nearly every read would
  // otherwise miss the cache).
  out.order.resize(V);
  sc.rects.resize(V);
#pragma omp parallel for schedule(static)
  for (std::int64_t i = 0; i < std::int64_t(V); ++i) {
    if (i + kBinPrefetch < std::int64_t(V)) {
      const std::uint32_t vp = items[std::size_t(i + kBinPrefetch)].id;
      __builtin_prefetch(&rects[visible_ids[vp]]);
    }
    const std::uint32_t v = items[std::size_t(i)].id, g = visible_ids[v];
    out.order[std::size_t(i)] = g;
    const PixelRect& r = rects[g];
    sc.rects[std::size_t(i)] = {r.x0 / TS, r.y0 / TS, r.x1 / TS, r.y1 / TS};
  }

  // 3. Stable counting sort by tile over a fixed number of chunks, handed out one at a time: the
  //    chunks are in depth order, and the near Gaussians cover more tiles than the far ones.
  //    Most splats cover one tile or a 2x2 block of them: those are counted without a branch on
  //    their shape (the loops over a rectangle of 1 to 4 tiles were mispredicted about once per
  //    Gaussian, half the time of the count); larger ones in loops.
  //    Each chunk's row of counters starts on a cache line of its own: at low resolution (a
  //    dozen tiles) the rows of neighbouring chunks, counted by different threads, shared lines,
  //    and two threads counted slower than one.
  const int chunks = detail::fixed_chunks(V);
  const std::size_t tx = std::size_t(grid.tiles_x);
  const std::size_t row = detail::round_up_to_line<std::uint64_t>(std::size_t(tiles));
  sc.hist.assign(std::size_t(chunks) * row + row, 0);  // [chunks, row >= tiles] from a line start
  std::uint64_t* const hist = detail::first_on_line(sc.hist);
  auto chunk_begin = [&](int k) { return V * std::size_t(k) / std::size_t(chunks); };
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < chunks; ++k) {
    std::uint64_t* h = hist + std::size_t(k) * row;
    const std::size_t e = chunk_begin(k + 1);
    for (std::size_t s = chunk_begin(k); s < e; ++s) {
      const Binning::Scratch::TileRect& r = sc.rects[s];
      const std::size_t w = std::size_t(r.tx1 - r.tx0), ht = std::size_t(r.ty1 - r.ty0);  // extents - 1
      const std::size_t t = std::size_t(r.ty0) * tx + std::size_t(r.tx0);
      if ((w | ht) <= 1) {  // 1x1 to 2x2 tiles; a tile left out adds 0 to tile t
        ++h[t];
        h[t + w] += w;
        h[t + ht * tx] += ht;
        h[t + ht * tx + w] += w & ht;
      } else {
        for (int ty = r.ty0; ty <= r.ty1; ++ty)
          for (int x = r.tx0; x <= r.tx1; ++x) ++h[std::size_t(ty) * tx + std::size_t(x)];
      }
    }
  }
  out.tile_offset.resize(std::size_t(tiles) + 1);
  out.tile_offset[0] = 0;
  for (int t = 0; t < tiles; ++t) {
    std::uint64_t sum = out.tile_offset[std::size_t(t)];
    for (int k = 0; k < chunks; ++k) {
      std::uint64_t& h = hist[std::size_t(k) * row + std::size_t(t)];
      const std::uint64_t c = h;
      h = sum;  // becomes this chunk's write cursor for tile t
      sum += c;
    }
    out.tile_offset[std::size_t(t) + 1] = sum;
  }
  detail::resize_for_overwrite(out.tile_list, M);  // the scatter below writes every pair
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < chunks; ++k) {
    std::uint64_t* cursor = hist + std::size_t(k) * row;
    const std::size_t e = chunk_begin(k + 1);
    for (std::size_t s = chunk_begin(k); s < e; ++s) {
      const std::uint32_t g = out.order[s];
      const Binning::Scratch::TileRect& r = sc.rects[s];
      for (int ty = r.ty0; ty <= r.ty1; ++ty)
        for (int x = r.tx0; x <= r.tx1; ++x) out.tile_list[cursor[std::size_t(ty) * tx + std::size_t(x)]++] = g;
    }
  }
}

}  // namespace msgs
