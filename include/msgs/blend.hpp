// include/msgs/blend.hpp
// Stage 3 of the rasteriser: front-to-back alpha blending of one 16x16 tile and its backward,
// side by side. Gaussians are the outer loop, taken in batches of 16 (detail::BlendBatch), and the
// 16 pixels of a 4x4 block of the tile the inner, vectorised loop; only the blocks a splat's
// bounding box touches are visited. Forward and backward evaluate alpha through the same inline
// functions so their fragment decisions agree bit for bit.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "bin.hpp"
#include "detail/block_simd.hpp"

namespace msgs {

/// A projected Gaussian as the blend stage reads it.
template <class S>
struct Splat {
  S mx, my;     ///< screen-space mean, pixels
  S a, b, c;    ///< conic: sigma = 0.5 (a dx^2 + c dy^2) + b dx dy
  S o;          ///< opacity (after antialiasing compensation)
  S z;          ///< camera-space depth
  S sigma_cut;  ///< ln(255 o) + 1e-3: beyond this sigma alpha < 1/255 (see with_sigma_cut)
  PixelRect rect;  ///< pixels that may receive alpha >= 1/255
};

/// Margin of Splat::sigma_cut over ln(255 o) (set_sigma_cut).
inline constexpr double kSigmaCutMargin = 1e-3;

/// Sets s.sigma_cut from `support` = ln(255 o) (ProjectedGaussian::support): a conservative bound
/// past which o e^-sigma < 1/255, so that the blend can skip a block after sigma alone. The 1e-3
/// margin (kSigmaCutMargin) covers the rounding of s.o, of the exponential and of sigma, so the
/// exact path could only have rejected those fragments too.
template <class S>
inline void set_sigma_cut(Splat<S>& s, double support) {
  s.sigma_cut = S(support) + S(kSigmaCutMargin);
}

/// Tile-list entries a blend loop takes at once (a batch, see detail::BlendBatch). While it works
/// on one batch it prefetches the splats (and, backward, the gradient records) of the next.
inline constexpr int kBlendBatch = 16;

/// Blending constants (REFERENCE §6).
template <class S>
struct BlendConstants {
  static constexpr S kMaxAlpha = S(0.99);
  static constexpr S kMinAlpha = S(1.0 / 255.0);
  static constexpr S kMinTransmittance = S(1e-4);
};

namespace detail {

/// Prefetches every cache line of one object: a float Splat (48 bytes) straddles two lines half
/// the time, a double one (80 bytes) may touch three.
template <class T>
inline void prefetch_object(const T* p) {
  const char* b = reinterpret_cast<const char*>(p);
  for (std::size_t o = 0; o < sizeof(T); o += 64) __builtin_prefetch(b + o);
  __builtin_prefetch(b + sizeof(T) - 1);
}

/// Prefetches the cache lines of the n elements at p, for writing with `Write`.
template <bool Write, class T>
inline void prefetch_elements(const T* p, std::size_t n) {
  const char* b = reinterpret_cast<const char*>(p);
  const char* e = reinterpret_cast<const char*>(p + n);
  for (const char* c = b; c < e; c += 64) __builtin_prefetch(c, Write ? 1 : 0);
  if (n > 0) __builtin_prefetch(e - 1, Write ? 1 : 0);
}

/// A 16x16 tile is processed as 4x4 blocks of 4x4 pixels, one block being 16 lanes (one
/// BlockVec: one AVX-512 vector, two AVX or four SSE vectors). Splats are mostly a few pixels
/// wide, and a square block wastes fewer lanes on them than a 16-pixel tile row: on the benchmark
/// scenes a splat's alpha >= 1/255 region touches 21-37% fewer blocks than rows.
/// Block b = 4 by + bx holds pixels x in [4 bx, 4 bx + 4), y in [4 by, 4 by + 4) of the tile; its
/// pixel (x, y) is element k = 4 (y % 4) + x % 4, that is lane k % L of chunk k / L.
struct TileBlocks {
  static constexpr int kSide = 4;                                // pixels per block side
  static constexpr int kPerSide = TileGrid::kTileSize / kSide;  // blocks per tile side
  static constexpr int kCount = kPerSide * kPerSide;            // blocks per tile
  static_assert(kSide * kSide == kBlockLanes, "a block is one BlockVec");
  static_assert(kCount <= 16, "block masks are 16 bits");
  /// Block of tile pixel (x, y) and the element of that pixel within the block.
  static constexpr int block(int x, int y) { return (y / kSide) * kPerSide + x / kSide; }
  static constexpr int element(int x, int y) { return (y % kSide) * kSide + x % kSide; }
};

/// Block rows and columns of a tile that pixel rectangle `rect` touches (inclusive); empty
/// (last < first) when it misses the tile.
struct BlockRange {
  int bx0, bx1, by0, by1;
  template <class TB>
  BlockRange(const PixelRect& rect, const TB& tb) {
    const int c0 = std::max(rect.x0 - tb.x0, 0), c1 = std::min(rect.x1 - tb.x0, tb.w - 1);
    const int r0 = std::max(rect.y0 - tb.y0, 0), r1 = std::min(rect.y1 - tb.y0, tb.h - 1);
    constexpr int B = TileBlocks::kSide;
    bx0 = c0 / B;
    by0 = r0 / B;
    bx1 = c1 < c0 ? bx0 - 1 : c1 / B;
    by1 = r1 < r0 ? by0 - 1 : r1 / B;
  }
  /// The blocks of the range as a bit set, bit b = by * kPerSide + bx (TileBlocks::block order).
  std::uint32_t blocks() const {
    constexpr int P = TileBlocks::kPerSide;
    if (bx1 < bx0 || by1 < by0) return 0;
    const std::uint32_t columns = (2u << bx1) - (1u << bx0);  // bits bx0 .. bx1
    // One bit per row of the range, at the row's first block: sum of 2^(P by) = (2^(P (by1 + 1)) - 2^(P by0)) / (2^P - 1).
    const std::uint64_t rows = ((std::uint64_t(1) << (P * (by1 + 1))) - (std::uint64_t(1) << (P * by0))) / ((1u << P) - 1u);
    return columns * std::uint32_t(rows);
  }
};

/// The rows of a tile's blocks that lie in the image, for moving a block's 16 elements (contiguous
/// in element order, TileBlocks::element) to and from row-major images: block row r of a block is
/// elements 4 r .. 4 r + 3, one run of `n` consecutive pixels of image row `y`. Called as
/// f(block, r, first pixel of the run in the image, n), blocks in order, rows in order.
template <class TB, class F>
inline void for_each_block_row(const TB& tb, int width, F&& f) {
  constexpr int B = TileBlocks::kSide;
  for (int b = 0; b < TileBlocks::kCount; ++b) {
    const int x0 = B * (b % TileBlocks::kPerSide), y0 = B * (b / TileBlocks::kPerSide);
    if (x0 >= tb.w || y0 >= tb.h) continue;
    const int n = std::min(B, tb.w - x0), rows = std::min(B, tb.h - y0);
    for (int r = 0; r < rows; ++r)
      f(b, r, std::size_t(tb.y0 + y0 + r) * std::size_t(width) + std::size_t(tb.x0 + x0), n);
  }
}

/// The first element of block row r of block b in an array of block vectors ([blocks * NH], NH
/// vectors a block): the 16 elements of a block are contiguous, block row r is elements 4 r .. 4 r + 3.
template <int NH, class Vec>
inline auto* block_row(Vec* blocks, int b, int r) {
  using E = std::remove_reference_t<decltype(blocks[0][0])>;
  return reinterpret_cast<E*>(blocks + b * NH) + TileBlocks::kSide * r;
}

/// Copies the `n` (<= 4) elements of a block row; a whole row (the common case) as one fixed-size
/// copy.
template <class T>
inline void copy_block_row(T* dst, const T* src, int n) {
  if (n == TileBlocks::kSide) std::memcpy(dst, src, sizeof(T) * TileBlocks::kSide);
  else std::memcpy(dst, src, sizeof(T) * std::size_t(n));
}

/// The pixel centres of one tile's blocks: x[bx][h] holds the x of the lanes of chunk h in block
/// column bx, y[by][h] the y in block row by (exact in S). Set up once per tile.
template <class S>
struct TileCentres {
  using V = typename BlockVec<S>::V;
  static constexpr int NH = BlockVec<S>::kChunks, P = TileBlocks::kPerSide;
  V x[P][NH], y[P][NH];

  /// `lx`, `ly`: the pixel-centre offsets (0.5 .. 3.5) of each lane within a block; `x0`, `y0`:
  /// the tile's corner.
  TileCentres(const V* lx, const V* ly, int x0, int y0) {
    constexpr int B = TileBlocks::kSide;
    for (int b = 0; b < P; ++b)
      for (int h = 0; h < NH; ++h) {
        x[b][h] = S(x0 + B * b) + lx[h];
        y[b][h] = S(y0 + B * b) + ly[h];
      }
  }
};

/// A splat's Mahalanobis half-distance sigma = 0.5 (a dx^2 + c dy^2) + b dx dy over the chunks of
/// a tile, evaluated per chunk where it is needed from the tile's pixel centres. No per-splat
/// tables of column and row terms: filling them (up to 40 vectors stored per intersection) cost
/// more than the operations they saved (a sixth of the blend forward with AVX2). Forward and
/// backward both evaluate sigma through at(), so their fragment decisions agree bit for bit.
template <class S>
struct SplatSigma {
  using V = typename BlockVec<S>::V;
  S half_a, half_c, b, mx, my;

  SplatSigma() = default;
  explicit SplatSigma(const Splat<S>& s) : half_a(S(0.5) * s.a), half_c(S(0.5) * s.c), b(s.b), mx(s.mx), my(s.my) {}
  /// Pixel centre x - mean x at chunk h of block column bx; dy likewise for block row by.
  V dx(const TileCentres<S>& c, int bx, int h) const { return c.x[bx][h] - mx; }
  V dy(const TileCentres<S>& c, int by, int h) const { return c.y[by][h] - my; }
  /// sigma at chunk h of block (bx, by).
  V at(const TileCentres<S>& c, int bx, int by, int h) const {
    const V x = dx(c, bx, h), y = dy(c, by, h);
    return (half_a * x * x + half_c * y * y) + (b * x) * y;
  }
};

/// The pixel-centre offsets within a block of each lane: lx = x % 4 + 0.5, ly = y % 4 + 0.5.
template <class S>
inline void block_lane_offsets(typename BlockVec<S>::V* lx, typename BlockVec<S>::V* ly) {
  constexpr int NH = BlockVec<S>::kChunks, L = BlockVec<S>::kLanes, B = TileBlocks::kSide;
  for (int h = 0; h < NH; ++h)
    for (int i = 0; i < L; ++i) {
      const int k = h * L + i;
      lx[h][i] = S(k % B) + S(0.5);
      ly[h][i] = S(k / B) + S(0.5);
    }
}

/// kSetBits[m]: the indices of the set bits of the byte m, ascending, then zeros.
inline constexpr auto kSetBits = [] {
  std::array<std::array<std::uint8_t, 8>, 256> t{};
  for (int m = 0; m < 256; ++m) {
    int n = 0;
    for (int b = 0; b < 8; ++b)
      if (m >> b & 1) t[std::size_t(m)][std::size_t(n++)] = std::uint8_t(b);
  }
  return t;
}();

/// Appends the indices of the set bits of `bits` (< 2^16), ascending, to `out`, and as many
/// copies of `tag` to `tags`; returns how many. Both arrays need room for 16 entries past the
/// current end: they are written 16 (or twice 8) at a time, without a branch per bit. This is the
/// portable form, by a table per byte; append_set_bits uses AVX-512's compress where it can.
inline int append_set_bits_by_table(std::uint32_t bits, std::uint8_t tag, std::uint8_t* out, std::uint8_t* tags) {
  const std::uint32_t lo = bits & 0xffu, hi = bits >> 8 & 0xffu;
  // The upper byte's indices plus 8, all eight in one 64-bit addition: no byte exceeds 7 + 8, so
  // none carries into the next, whatever the byte order. (Added byte by byte, the word was
  // assembled by GCC 12 from eight byte stores and masks per splat.)
  std::uint64_t upper;
  std::memcpy(&upper, kSetBits[hi].data(), 8);
  upper += 0x0808080808080808ull;
  std::memcpy(out, kSetBits[lo].data(), 8);
  std::memcpy(out + std::popcount(lo), &upper, 8);
  std::memset(tags, tag, 16);
  return std::popcount(lo) + std::popcount(hi);
}

/// append_set_bits_by_table, as one compress instruction with AVX-512 (in a blend forward on the
/// demo's views the table's overlapping stores cost a fifth of the time).
inline int append_set_bits(std::uint32_t bits, std::uint8_t tag, std::uint8_t* out, std::uint8_t* tags) {
#if defined(__AVX512F__)
  const __m512i iota = _mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
  // The masked conversion with a full mask: GCC 12's plain _mm512_cvtepi32_epi8 trips
  // -Wmaybe-uninitialized on its undefined pass-through operand.
  const __m128i packed = _mm512_maskz_cvtepi32_epi8(__mmask16(0xffff), _mm512_maskz_compress_epi32(__mmask16(bits), iota));
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), packed);
  _mm_storeu_si128(reinterpret_cast<__m128i*>(tags), _mm_set1_epi8(char(tag)));
  return std::popcount(bits & 0xffffu);
#else
  return append_set_bits_by_table(bits, tag, out, tags);
#endif
}

/// The work of one batch of a tile's list (kBlendBatch splats), which the blend loops do in
/// passes over the whole batch: (1) each splat's blocks as one list of (block, splat) items,
/// (2) the chunks of those blocks to visit, with their sigma, (3) their alpha, (4) blending or its
/// gradient, chunk by chunk. Each pass is one loop over the batch, so that the branches that end
/// the loops are taken once per batch, not once per splat: splats are mostly a few pixels wide,
/// and taken one at a time, the data-dependent ends of their short loops were mispredicted so
/// often that they bounded the blend (batches made the forward 1.46x faster on the demo's views).
/// Within a chunk the splats still come in list order, so every value keeps its bits.
template <class S, int NC>
struct BlendBatch {
  using V = typename BlockVec<S>::V;
  static constexpr int kChunksPerTile = TileBlocks::kCount * BlockVec<S>::kChunks;
  Splat<S> splat[kBlendBatch];
  SplatSigma<S> sigma_of[kBlendBatch];
  S colour[kBlendBatch][NC];  // the rendered channels, zeros past them
  // Pass 1: (block, splat) items; 16 entries of room for append_set_bits.
  std::uint8_t block[kBlendBatch * TileBlocks::kCount + 16], block_splat[kBlendBatch * TileBlocks::kCount + 16];
  int blocks = 0;
  // Pass 2: the listed chunks (chunk index q of the tile, splat k of the batch) and their sigma;
  // pass 3: their alpha.
  V sigma[kBlendBatch * kChunksPerTile], alpha[kBlendBatch * kChunksPerTile];
  std::uint8_t chunk[kBlendBatch * kChunksPerTile], chunk_splat[kBlendBatch * kChunksPerTile];
  int chunks = 0;

  /// Splat k of the batch is `s` with the `nc` channels of `colour_row`, its blocks to visit
  /// `block_bits` (TileBlocks order).
  void add(int k, const Splat<S>& s, const S* colour_row, int nc, std::uint32_t block_bits) {
    splat[k] = s;
    sigma_of[k] = SplatSigma<S>(s);
    for (int ch = 0; ch < NC; ++ch) colour[k][ch] = ch < nc ? colour_row[ch] : S(0);
    blocks += append_set_bits(block_bits, std::uint8_t(k), block + blocks, block_splat + blocks);
  }
  /// Lists chunk q of splat k with its sigma where `keep`; a chunk left out changes nothing.
  void list(int q, int k, const V& sig, bool keep) {
    sigma[chunks] = sig;
    chunk[chunks] = std::uint8_t(q);
    chunk_splat[chunks] = std::uint8_t(k);
    chunks += int(keep);
  }
  /// alpha = min(0.99, o e^-sigma) of every listed chunk. The forward and the backward both
  /// evaluate it here, so that they take and skip exactly the same fragments. Its loop of its own
  /// has independent iterations, so the core overlaps their exponentials, where inside a blending
  /// loop each one would start a long dependency chain.
  void alphas(const V& max_alpha) {
    for (int i = 0; i < chunks; ++i) {
      V e;
      exp_neg_into(e, sigma[i]);
      min_into(alpha[i], splat[chunk_splat[i]].o * e, max_alpha);  // o e < 0.99 ? o e : 0.99
    }
  }
};

}  // namespace detail

/// Read-only inputs of the blend stage for one frame.
template <class S>
struct BlendInputs {
  const TileGrid* grid = nullptr;
  const Binning* bins = nullptr;
  const Splat<S>* splats = nullptr;  // [N]
  const S* colours = nullptr;        // [N, count]
  int count = 0;                     // channels rendered
  const S* background = nullptr;     // [count]
};

/// Per-pixel outputs of the blend forward (all [H, W] or [H, W, count], row-major).
template <class S>
struct BlendOutputs {
  S* image = nullptr;               // [H, W, count]
  S* alpha = nullptr;               // [H, W]
  S* depth = nullptr;               // [H, W], only with depth
  S* transmittance = nullptr;       // [H, W] final T
  std::uint32_t* last = nullptr;    // [H, W] 1 + position (in the tile list) of the last blended splat; 0 = none
  std::uint16_t* block_mask = nullptr;  // [M] per intersection: bit b set when the splat blended into block b (TileBlocks)
};

/// Gradients flowing into the blend backward.
template <class S>
struct BlendGradInputs {
  const S* d_image = nullptr;  // [H, W, count]
  const S* d_alpha = nullptr;  // [H, W] or nullptr
  const S* d_depth = nullptr;  // [H, W] or nullptr
};

/// Layout of the per-intersection gradient record written by the backward: the mean, conic and
/// opacity gradients, the `count` channel gradients, then a depth slot only with depth and two
/// absgrad slots only with absgrad, so that features that are off cost no memory traffic.
template <bool Depth, bool AbsGrad>
struct BlendRecord {
  enum : int { kMeanX = 0, kMeanY, kConicA, kConicB, kConicC, kOpacity, kBase };
  /// Record length for `count` channels.
  static constexpr int size(int count) { return kBase + count + (Depth ? 1 : 0) + (AbsGrad ? 2 : 0); }
  /// Slot of dL/d(depth) (with Depth).
  static constexpr int depth(int count) { return kBase + count; }
  /// Slots of the absgrad x and y sums (with AbsGrad): abs_x(count) and abs_x(count) + 1.
  static constexpr int abs_x(int count) { return kBase + count + (Depth ? 1 : 0); }
};

namespace detail {

template <class S>
struct TileBounds {
  int x0, y0, w, h;
  TileBounds(const TileGrid& grid, int tile) {
    const int tx = tile % grid.tiles_x, ty = tile / grid.tiles_x;
    x0 = tx * TileGrid::kTileSize;
    y0 = ty * TileGrid::kTileSize;
    w = std::min(TileGrid::kTileSize, grid.width - x0);
    h = std::min(TileGrid::kTileSize, grid.height - y0);
  }
};

/// Prefetches what a blend loop reads of splat g: its Splat and its colour row.
template <class S>
inline void prefetch_splat(const BlendInputs<S>& in, std::uint32_t g) {
  prefetch_object(in.splats + g);
  __builtin_prefetch(in.colours + std::size_t(g) * std::size_t(in.count));
}

}  // namespace detail

/// What blend_tile_fwd did in a tile: the fragments it blended and the lanes it evaluated (a
/// vector of lanes per listed chunk). fragments / lanes is the share of the blend's vector work
/// that blends; the rest falls outside a splat's alpha >= 1/255 region or on stopped pixels.
struct BlendTileCount {
  std::uint64_t fragments = 0, lanes = 0;
};

/// Blend one tile front to back. `C` is the channel count when known at compile time (0 = use
/// in.count, at most MaxC). Returns the blended fragments and evaluated lanes. Pixel state lives in
/// block vectors (detail::TileBlocks: 16 blocks of 4x4 pixels, detail::BlockVec: kChunks vectors
/// per block); a splat visits only the blocks its pixel rectangle touches.
template <class S, int C, int MaxC, bool Depth>
inline BlendTileCount blend_tile_fwd(const BlendInputs<S>& in, int tile, const BlendOutputs<S>& out) {
  using TBk = detail::TileBlocks;
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  using BV = detail::BlockVec<S>;
  using V = typename BV::V;
  using M = typename BV::M;
  using U = typename BV::U;
  using I = typename BV::I;
  constexpr int NH = BV::kChunks, L = BV::kLanes, NB = TBk::kCount, Q = NB * NH;  // vectors per block, lanes each, per tile
  const int nc = C > 0 ? C : in.count;
  const detail::TileBounds<S> tb(*in.grid, tile);
  // Pixel (x, y) of the tile is lane k % L of vector b NH + k / L, with b = TBk::block(x, y) and
  // k = TBk::element(x, y). T > 0 marks a live pixel: a pixel that has stopped keeps -T
  // (T > 1e-4 there, so the sign is unambiguous), lanes outside the image hold -1.
  V T[Q], acc[NC][Q], dacc[Depth ? Q : 1];
  U last[Q];
  V zero, one, lx[NH], ly[NH], max_alpha, min_alpha, min_T;
  detail::broadcast(zero, S(0));
  detail::broadcast(one, S(1));
  detail::broadcast(max_alpha, K::kMaxAlpha);
  detail::broadcast(min_alpha, K::kMinAlpha);
  detail::broadcast(min_T, K::kMinTransmittance);
  detail::block_lane_offsets<S>(lx, ly);
  for (int b = 0; b < NB; ++b)
    for (int h = 0; h < NH; ++h) {
      const int q = b * NH + h;
      for (int i = 0; i < L; ++i) {
        const int x = TBk::kSide * (b % TBk::kPerSide) + int(lx[h][i]), y = TBk::kSide * (b / TBk::kPerSide) + int(ly[h][i]);
        T[q][i] = (x < tb.w && y < tb.h) ? S(1) : S(-1);
      }
      detail::broadcast(last[q], 0u);
      for (int ch = 0; ch < NC; ++ch) acc[ch][q] = zero;
      if constexpr (Depth) dacc[q] = zero;
    }
  // The output rows of the tile are written at the end: fetch their cache lines for writing now,
  // so that the stores then do not wait on them (the images of a frame exceed the L2 cache).
  {
    const int W = in.grid->width;
    for (int y = 0; y < tb.h; ++y) {
      const std::size_t pix = std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0);
      detail::prefetch_elements<true>(out.image + pix * std::size_t(nc), std::size_t(tb.w) * std::size_t(nc));
      detail::prefetch_elements<true>(out.alpha + pix, std::size_t(tb.w));
      detail::prefetch_elements<true>(out.transmittance + pix, std::size_t(tb.w));
      detail::prefetch_elements<true>(out.last + pix, std::size_t(tb.w));
      if constexpr (Depth) detail::prefetch_elements<true>(out.depth + pix, std::size_t(tb.w));
    }
  }
  const detail::TileCentres<S> centres(lx, ly, tb.x0, tb.y0);
  // Blocks whose pixels have all stopped are skipped (bit b of `live`: block b may still have a
  // live pixel); the check runs once per batch so that the hot loops carry no horizontal
  // reductions.
  std::uint32_t live = 0;
  for (int b = 0; b < NB; ++b)
    live |= std::uint32_t(TBk::kSide * (b % TBk::kPerSide) < tb.w && TBk::kSide * (b / TBk::kPerSide) < tb.h) << b;
  const std::uint64_t begin = in.bins->tile_offset[std::size_t(tile)], end = in.bins->tile_offset[std::size_t(tile) + 1];
  const std::uint32_t* list = in.bins->tile_list.data();
  std::uint64_t j = begin, fragments = 0, chunks = 0;
  detail::BlendBatch<S, NC> batch;
  for (; j < end; j += kBlendBatch) {
    if (j != begin) {
      for (std::uint32_t bits = live; bits != 0; bits &= bits - 1) {
        const int b = std::countr_zero(bits);
        M m = T[b * NH] > zero;
        for (int h = 1; h < NH; ++h) m |= T[b * NH + h] > zero;
        if (!detail::any_lane(m)) live &= ~(1u << b);
      }
      if (live == 0) break;
    }
    const int nb = int(std::min<std::uint64_t>(kBlendBatch, end - j));
    for (std::uint64_t p = j + kBlendBatch, pe = std::min<std::uint64_t>(p + kBlendBatch, end); p < pe; ++p)
      detail::prefetch_splat(in, list[p]);
    // Pass 1: the splats, and the blocks of each one's rectangle that may still be live.
    batch.blocks = batch.chunks = 0;
    for (int k = 0; k < nb; ++k) {
      const std::uint32_t g = list[j + std::uint64_t(k)];
      const Splat<S>& s = in.splats[g];
      batch.add(k, s, in.colours + std::size_t(g) * std::size_t(nc), nc, detail::BlockRange(s.rect, tb).blocks() & live);
    }
    // Pass 2: the chunks to visit and their sigma. A chunk with no lane inside the splat's cut
    // whose pixel is still live (T > 0 at the start of the batch; this also leaves out every chunk
    // of a block whose pixels have all stopped) is left out: none of its lanes could pass `ok`
    // below, so leaving it out changes no bit. Blocks of the bounding box that the alpha >= 1/255
    // ellipse misses are so skipped after sigma alone; the cut is conservative (set_sigma_cut).
    for (int i = 0; i < batch.blocks; ++i) {
      const int b = batch.block[i], k = batch.block_splat[i], bx = b % TBk::kPerSide, by = b / TBk::kPerSide;
      V sigma_cut;
      detail::broadcast(sigma_cut, batch.splat[k].sigma_cut);
      for (int h = 0; h < NH; ++h) {
        const int q = b * NH + h;
        const V sig = batch.sigma_of[k].at(centres, bx, by, h);
        batch.list(q, k, sig, detail::any_le_and_gt(sig, sigma_cut, T[q], zero));
      }
    }
    // Pass 3: the alpha of every listed chunk.
    batch.alphas(max_alpha);
    chunks += std::uint64_t(batch.chunks);
    // Pass 4: blend the listed chunks, in list order.
    std::uint32_t blocks_blended[kBlendBatch] = {};
    for (int i = 0; i < batch.chunks; ++i) {
      const int q = batch.chunk[i], k = batch.chunk_splat[i];
      const V alpha = batch.alpha[i];
      const V t = T[q];
      const M ok = (t > zero) & (batch.sigma[i] >= zero) & (alpha >= min_alpha);
      const V next_T = t * (one - alpha);
      const M stop = ok & (next_T <= min_T);
      const M take = ok & ~stop;
      const V weight = take ? alpha * t : zero;
      for (int ch = 0; ch < NC; ++ch) {
        V col;
        detail::broadcast(col, batch.colour[k][ch]);
        detail::fmadd_into(acc[ch][q], weight, col, acc[ch][q]);
      }
      if constexpr (Depth) {
        V z;
        detail::broadcast(z, batch.splat[k].z);
        detail::fmadd_into(dacc[q], weight, z, dacc[q]);
      }
      T[q] = take ? next_T : (stop ? -t : t);
      U pos;  // 1 + the splat's position in the tile list
      detail::broadcast(pos, std::uint32_t(j - begin) + std::uint32_t(k + 1));
      last[q] = __builtin_convertvector(take, I) ? pos : last[q];
      const std::uint32_t took = detail::lane_bits(take);
      fragments += std::uint64_t(std::popcount(took));
      blocks_blended[k] |= std::uint32_t(took != 0) << (q / NH);
    }
    for (int k = 0; k < nb; ++k) out.block_mask[j + std::uint64_t(k)] = std::uint16_t(blocks_blended[k]);
  }
  for (; j < end; ++j) out.block_mask[j] = 0;  // entries after every pixel stopped
  // The outputs, computed a vector at a time in block order and written a block row (4 pixels) at
  // a time: T and the colours become |T|, 1 - |T| and acc + |T| background in place.
  V bg[NC];
  for (int ch = 0; ch < NC; ++ch) detail::broadcast(bg[ch], ch < nc ? in.background[ch] : S(0));
  V alpha_out[Q];
  for (int q = 0; q < Q; ++q) {
    detail::abs_into(T[q], T[q]);
    alpha_out[q] = one - T[q];
    for (int ch = 0; ch < NC; ++ch) acc[ch][q] = acc[ch][q] + T[q] * bg[ch];
  }
  detail::for_each_block_row(tb, in.grid->width, [&](int b, int r, std::size_t pix, int n) {
    detail::copy_block_row(out.transmittance + pix, detail::block_row<NH>(T, b, r), n);
    detail::copy_block_row(out.alpha + pix, detail::block_row<NH>(alpha_out, b, r), n);
    detail::copy_block_row(out.last + pix, detail::block_row<NH>(last, b, r), n);
    if constexpr (Depth) detail::copy_block_row(out.depth + pix, detail::block_row<NH>(dacc, b, r), n);
    S* img = out.image + pix * std::size_t(nc);
    for (int i = 0; i < n; ++i) {
      const int k = TBk::kSide * r + i, q = b * NH + k / L;
      for (int ch = 0; ch < nc; ++ch) img[i * nc + ch] = acc[ch][q][k % L];
    }
  });
  return BlendTileCount{fragments, chunks * std::uint64_t(L)};
}

/// Backward of blend_tile_fwd for one tile: walks the tile's list back to front, rebuilding each
/// pixel's transmittance by division (alpha <= 0.99 keeps it well conditioned), and writes one
/// gradient record per intersection of the tile into `records` ([M, BlendRecord<Depth,
/// AbsGrad>::size(count)], row = the pair's index in Gaussian order, Binning::pair), and sets
/// that pair's flag in `blended` ([M], the caller zeroes it first), except where the block mask
/// is 0: the records of the splats that blended nowhere (in a deep scene most of them: 92% in
/// bench_train_step's frame of a million Gaussians at 1280x960) are not written, and the
/// reduction reads zeros in their place. Adds
/// the tile's background gradient into `d_background` ([count]). Alpha is evaluated by the same
/// expressions as in the forward, so both make the same fragment decisions.
template <class S, int C, int MaxC, bool Depth, bool AbsGrad>
inline void blend_tile_bwd(const BlendInputs<S>& in, int tile, const S* transmittance, const std::uint32_t* last_in,
                           const std::uint16_t* block_mask, const BlendGradInputs<S>& gin, S* records,
                           std::uint8_t* blended, S* d_background) {
  using TBk = detail::TileBlocks;
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  using BV = detail::BlockVec<S>;
  using V = typename BV::V;
  using M = typename BV::M;
  using U = typename BV::U;
  constexpr int NH = BV::kChunks, L = BV::kLanes, NB = TBk::kCount, Q = NB * NH;
  const int nc = C > 0 ? C : in.count;
  using Rec = BlendRecord<Depth, AbsGrad>;
  const int R = Rec::size(nc);
  const detail::TileBounds<S> tb(*in.grid, tile);
  const std::uint64_t begin = in.bins->tile_offset[std::size_t(tile)], end = in.bins->tile_offset[std::size_t(tile) + 1];

  // Per pixel: T (rebuilt back to front), the final-transmittance terms, dL/dimage and
  // B = sum over the splats behind of w_j (colour_j . dL/dimage [+ z_j dL/ddepth]), which is what
  // the colour of those splats contributes to dL/dalpha of this one.
  V T[Q], t_final_terms[Q], dimg[NC][Q], B[Q], dD[Depth ? Q : 1];
  U last[Q];
  V zero, one, lx[NH], ly[NH], max_alpha, min_alpha;
  detail::broadcast(zero, S(0));
  detail::broadcast(one, S(1));
  detail::broadcast(max_alpha, K::kMaxAlpha);
  detail::broadcast(min_alpha, K::kMinAlpha);
  detail::block_lane_offsets<S>(lx, ly);
  const detail::TileCentres<S> centres(lx, ly, tb.x0, tb.y0);
  // Per-pixel state in block order, read a block row (4 pixels) at a time; lanes outside the image
  // hold T = 1 and zero gradients, so that they take no part.
  V d_alpha[Q];
  U zero_u;
  detail::broadcast(zero_u, 0u);
  for (int q = 0; q < Q; ++q) {
    T[q] = one;
    B[q] = zero;
    last[q] = zero_u;
    d_alpha[q] = zero;
    for (int ch = 0; ch < NC; ++ch) dimg[ch][q] = zero;
    if constexpr (Depth) dD[q] = zero;
  }
  const int W = in.grid->width;
  detail::for_each_block_row(tb, W, [&](int b, int r, std::size_t pix, int n) {
    detail::copy_block_row(detail::block_row<NH>(T, b, r), transmittance + pix, n);
    detail::copy_block_row(detail::block_row<NH>(last, b, r), last_in + pix, n);
    if (gin.d_alpha) detail::copy_block_row(detail::block_row<NH>(d_alpha, b, r), gin.d_alpha + pix, n);
    if constexpr (Depth)
      if (gin.d_depth) detail::copy_block_row(detail::block_row<NH>(dD, b, r), gin.d_depth + pix, n);
    const S* d = gin.d_image + pix * std::size_t(nc);
    for (int i = 0; i < n; ++i) {
      const int k = TBk::kSide * r + i, q = b * NH + k / L;
      for (int ch = 0; ch < nc; ++ch) dimg[ch][q][k % L] = d[i * nc + ch];
    }
  });
  U max_lane = last[0];
  for (int q = 1; q < Q; ++q) max_lane = max_lane > last[q] ? max_lane : last[q];
  std::uint32_t max_last = 0;
  for (int i = 0; i < L; ++i) max_last = std::max(max_last, max_lane[i]);
  V bg[NC];
  for (int ch = 0; ch < NC; ++ch) detail::broadcast(bg[ch], ch < nc ? in.background[ch] : S(0));
  for (int q = 0; q < Q; ++q) {
    V bg_dot = zero;
    for (int ch = 0; ch < NC; ++ch) bg_dot = bg_dot + bg[ch] * dimg[ch][q];
    // d(1 - T_final)/d alpha_i and d(T_final bg)/d alpha_i both scale with T_final / (1 - alpha_i).
    t_final_terms[q] = T[q] * (d_alpha[q] - bg_dot);
  }
  // The background's gradient sum(T_final dL/dimage), in row-major pixel order.
  for (int ch = 0; ch < nc; ++ch) {
    S bg_grad = S(0);
    for (int y = 0; y < tb.h; ++y) {
      const std::size_t row = std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0);
      for (int x = 0; x < tb.w; ++x)
        bg_grad += transmittance[row + std::size_t(x)] * gin.d_image[(row + std::size_t(x)) * std::size_t(nc) + std::size_t(ch)];
    }
    d_background[ch] += bg_grad;
  }
  if (begin == end) return;  // an empty tile still passes its background gradient (T = 1)

  // Lane accumulators of one splat, summed over the blocks it blended into. With u = -dL/dsigma
  // per pixel (zero where the alpha clamp holds), dL/dsigma enters the conic and mean gradients
  // through the sums of u, u dx, u dy, u dx^2, u dx dy and u dy^2. Since falloff = o e, the opacity
  // gradient sum dL/dalpha e = sum(u) / o needs no accumulator of its own.
  enum : int { kU = 0, kUx, kUy, kUxx, kUxy, kUyy, kCol };
  constexpr int kDep = kCol + NC, kAbsX = kDep + (Depth ? 1 : 0), kAbsY = kAbsX + 1;
  constexpr int NL = kAbsX + (AbsGrad ? 2 : 0);  // only the accumulators this instantiation uses
  constexpr int P = TBk::kPerSide;
  const std::uint32_t* list = in.bins->tile_list.data();
  const Binning& bins = *in.bins;
  const std::uint64_t* first_pair_of = bins.first_pair_of.data();
  const int tile_x = tile % in.grid->tiles_x, tile_y = tile / in.grid->tiles_x;
  // The list is taken kBlendBatch entries at a time, back to front (detail::BlendBatch).
  detail::BlendBatch<S, NC> batch;
  std::uint32_t position[kBlendBatch];  // in the tile list
  std::uint64_t entry[kBlendBatch];
  std::uint64_t pair[kBlendBatch];  // the pair each entry's record belongs to (Binning::pair)
  int chunks_end[kBlendBatch];  // splat k's listed chunks end here (they follow those of k - 1)
  for (std::uint64_t top = begin + max_last; top > begin;) {
    const int nb = int(std::min<std::uint64_t>(kBlendBatch, top - begin));
    // The batch's entries that blended somewhere (block mask not 0), back to front: a splat the
    // forward blended into no pixel of this tile (its box touches the tile, its alpha >= 1/255
    // region does not, or every pixel had stopped) has no gradient here, and its record keeps
    // the zeros the caller wrote.
    int m = 0;
    for (int k = 0; k < nb; ++k) {
      const std::uint64_t jr = top - 1 - std::uint64_t(k);
      entry[m] = jr;
      m += int(block_mask[jr] != 0);
      if (jr >= begin + kBlendBatch) {  // the next batch's splat and its first pair
        const std::uint64_t jn = jr - kBlendBatch;
        detail::prefetch_splat(in, list[jn]);
        if (block_mask[jn] != 0) __builtin_prefetch(&first_pair_of[list[jn]]);
      }
    }
    top -= std::uint64_t(nb);
    // Pass 1: the splats, and the blocks where the forward blended each one (its block mask): only
    // those can carry gradient.
    batch.blocks = batch.chunks = 0;
    for (int k = 0; k < m; ++k) {
      const std::uint64_t jr = entry[k];
      const std::uint32_t g = list[jr];
      position[k] = std::uint32_t(jr - begin);
      const Splat<S>& s = in.splats[g];
      batch.add(k, s, in.colours + std::size_t(g) * std::size_t(nc), nc, block_mask[jr]);
      // The record is written after passes 2 to 4: fetched for writing now (records scatter).
      pair[k] = bins.pair(g, s.rect, tile_x, tile_y);
      const S* rp = records + pair[k] * std::uint64_t(R);
      __builtin_prefetch(rp, 1);
      __builtin_prefetch(rp + R - 1, 1);
    }
    // Pass 2: the chunks to visit and their sigma, in block order per splat. As in the forward, a
    // chunk without a lane inside the cut and in front of its pixel's last blended splat adds
    // nothing (every lane fails `ok`): it is left out.
    for (int i = 0; i < batch.blocks; ++i) {
      const int b = batch.block[i], k = batch.block_splat[i], bx = b % P, by = b / P;
      [[maybe_unused]] V sigma_cut;
      detail::broadcast(sigma_cut, batch.splat[k].sigma_cut);
      [[maybe_unused]] U kv;  // a pixel blended this splat iff kv < last
      detail::broadcast(kv, position[k]);
      for (int h = 0; h < NH; ++h) {
        const int q = b * NH + h;
        const V sig = batch.sigma_of[k].at(centres, bx, by, h);
        if constexpr (NH > 1) batch.list(q, k, sig, detail::any_lane((sig <= sigma_cut) & __builtin_convertvector(kv < last[q], M)));
        else batch.list(q, k, sig, true);
      }
      chunks_end[k] = batch.chunks;  // every splat here has a block, so every end is set
    }
    // Pass 3: the alpha of every listed chunk, as in the forward.
    batch.alphas(max_alpha);
    // Pass 4: the gradient of each listed chunk, splat by splat (one loop per splat: its sums
    // stay in registers, and a large splat does not pay for the batch). Each pixel's state (T, B)
    // is touched once per splat and each sum takes its chunks in block order, whatever the vector
    // width.
    for (int k = 0, i = 0; k < m; ++k) {
      const Splat<S>& s = batch.splat[k];
      const detail::SplatSigma<S>& sg = batch.sigma_of[k];
      U kv;  // a pixel blended this splat iff kv < last
      detail::broadcast(kv, position[k]);
      V col[NC];
      for (int ch = 0; ch < NC; ++ch) detail::broadcast(col[ch], batch.colour[k][ch]);
      [[maybe_unused]] V z;
      detail::broadcast(z, s.z);
      V lane[NL * NH];  // [accumulator][chunk]
      // Unrolled, so that GCC does not turn it into a call to memset per splat (with AVX2 that
      // call and its vzeroupper took 5% of a training step).
#pragma GCC unroll 64
      for (int l = 0; l < NL * NH; ++l) lane[l] = zero;
      for (; i < chunks_end[k]; ++i) {
        const int q = batch.chunk[i], b = q / NH, h = q % NH, bx = b % P, by = b / P;
        const V alpha = batch.alpha[i];
        const M ok = __builtin_convertvector(kv < last[q], M) & (batch.sigma[i] >= zero) & (alpha >= min_alpha);
        const V ra = one / (one - alpha);
        const V Ti = ok ? T[q] * ra : T[q];
        const V fac = alpha * Ti;
        V cd = col[0] * dimg[0][q];  // colour . dL/dimage of this pixel
        for (int ch = 1; ch < NC; ++ch) detail::fmadd_into(cd, col[ch], dimg[ch][q], cd);
        if constexpr (Depth) detail::fmadd_into(cd, z, dD[q], cd);
        V v_alpha;
        detail::fmadd_into(v_alpha, Ti, cd, ra * (t_final_terms[q] - B[q]));
        detail::fmadd_where(B[q], ok, fac, cd);
        for (int ch = 0; ch < NC; ++ch) detail::fmadd_where(lane[(kCol + ch) * NH + h], ok, fac, dimg[ch][q]);
        if constexpr (Depth) detail::fmadd_where(lane[kDep * NH + h], ok, fac, dD[q]);
        // alpha = min(0.99, o e^-sigma): no gradient through the clamp. u = -dL/dsigma = dL/dalpha
        // o e^-sigma, and where the clamp does not hold (alpha < 0.99) o e^-sigma is alpha itself.
        const M free = ok & (alpha < max_alpha);
        const V u = free ? v_alpha * alpha : zero;
        const V dx = sg.dx(centres, bx, h), dy = sg.dy(centres, by, h);
        const V ux = u * dx, uy = u * dy;
        lane[kU * NH + h] += u;
        lane[kUx * NH + h] += ux;
        lane[kUy * NH + h] += uy;
        detail::fmadd_into(lane[kUxx * NH + h], ux, dx, lane[kUxx * NH + h]);
        detail::fmadd_into(lane[kUxy * NH + h], ux, dy, lane[kUxy * NH + h]);
        detail::fmadd_into(lane[kUyy * NH + h], uy, dy, lane[kUyy * NH + h]);
        if constexpr (AbsGrad) {
          // +-dL/dmean per pixel: -u (a dx + b dy, b dx + c dy)
          V gx = u * (s.a * dx + s.b * dy), gy = u * (s.b * dx + s.c * dy);
          detail::abs_into(gx, gx);
          detail::abs_into(gy, gy);
          lane[kAbsX * NH + h] += gx;
          lane[kAbsY * NH + h] += gy;
        }
        T[q] = Ti;
      }
      S sum[NL];
      detail::sum_rows(lane, NL, sum);
      // dL/dsigma = -u: dL/dmean = -(conic (sum v dx, sum v dy)) with v = dL/dsigma, and so on.
      S* rec = records + pair[k] * std::uint64_t(R);
      blended[pair[k]] = 1;
      rec[Rec::kMeanX] = s.a * sum[kUx] + s.b * sum[kUy];
      rec[Rec::kMeanY] = s.b * sum[kUx] + s.c * sum[kUy];
      rec[Rec::kConicA] = S(-0.5) * sum[kUxx];
      rec[Rec::kConicB] = -sum[kUxy];
      rec[Rec::kConicC] = S(-0.5) * sum[kUyy];
      rec[Rec::kOpacity] = sum[kU] / s.o;
      for (int ch = 0; ch < nc; ++ch) rec[Rec::kBase + ch] = sum[kCol + ch];
      if constexpr (Depth) rec[Rec::depth(nc)] = sum[kDep];
      if constexpr (AbsGrad) {
        rec[Rec::abs_x(nc)] = sum[kAbsX];
        rec[Rec::abs_x(nc) + 1] = sum[kAbsY];
      }
    }
  }
  // Splats behind every pixel's last blended one (block mask 0, see blend_tile_fwd) keep their flag 0.
}

}  // namespace msgs

