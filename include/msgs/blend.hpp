// include/msgs/blend.hpp
// Stage 3 of the rasteriser: front-to-back alpha blending of one 16x16 tile and its backward,
// side by side. Gaussians are the outer loop and the 16 pixels of a tile row the inner, vectorised
// loop; only the rows a splat's bounding box touches are visited. Forward and backward evaluate
// alpha through the same inline functions so their fragment decisions agree bit for bit.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include "bin.hpp"
#include "detail/math.hpp"

namespace msgs {

/// A projected Gaussian as the blend stage reads it.
template <class S>
struct Splat {
  S mx, my;     ///< screen-space mean, pixels
  S a, b, c;    ///< conic: sigma = 0.5 (a dx^2 + c dy^2) + b dx dy
  S o;          ///< opacity (after antialiasing compensation)
  S z;          ///< camera-space depth
  PixelRect rect;  ///< pixels that may receive alpha >= 1/255
};

/// Blending constants (REFERENCE §6).
/// How many tile-list entries ahead the blend loops prefetch splat data (random access by id).
inline constexpr std::uint64_t kPrefetchDistance = 4;

template <class S>
struct BlendConstants {
  static constexpr S kMaxAlpha = S(0.99);
  static constexpr S kMinAlpha = S(1.0 / 255.0);
  static constexpr S kMinTransmittance = S(1e-4);
};

/// Mahalanobis half-distance of pixel offset (dx, dy). One definition for forward and backward.
template <class S>
inline S splat_sigma(S a, S b, S c, S dx, S dy) {
  return S(0.5) * (a * dx * dx + c * dy * dy) + b * dx * dy;
}

/// Unclamped fragment opacity o * exp(-sigma).
template <class S>
inline S splat_falloff(S o, S sigma) {
  return o * detail::exp_neg(sigma);
}

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
  std::uint16_t* row_mask = nullptr;// [M] per intersection: bit r set when the splat blended into tile row r
};

/// Gradients flowing into the blend backward.
template <class S>
struct BlendGradInputs {
  const S* d_image = nullptr;  // [H, W, count]
  const S* d_alpha = nullptr;  // [H, W] or nullptr
  const S* d_depth = nullptr;  // [H, W] or nullptr
};

/// Layout of the per-intersection gradient record written by the backward.
struct BlendRecord {
  enum : int { kMeanX = 0, kMeanY, kConicA, kConicB, kConicC, kOpacity, kAbsX, kAbsY, kDepth, kBase };
  /// Record length for `count` channels (depth slot always present, zero without depth).
  static int size(int count) { return kBase + count; }
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

}  // namespace detail

/// Blend one tile front to back. `C` is the channel count when known at compile time (0 = use
/// in.count, at most MaxC). Returns the number of blended fragments.
template <class S, int C, int MaxC, bool Depth>
inline std::uint64_t blend_tile_fwd(const BlendInputs<S>& in, int tile, const BlendOutputs<S>& out) {
  constexpr int TS = TileGrid::kTileSize, TP = TileGrid::kTilePixels;
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  const int nc = C > 0 ? C : in.count;
  const detail::TileBounds<S> tb(*in.grid, tile);
  alignas(64) S T[TP], active[TP], acc[NC][TP], dacc[Depth ? TP : 1];
  alignas(64) std::uint32_t last[TP];
  for (int p = 0; p < TP; ++p) {
    T[p] = S(1);
    active[p] = ((p % TS) < tb.w && (p / TS) < tb.h) ? S(1) : S(0);
    last[p] = 0;
    for (int ch = 0; ch < NC; ++ch) acc[ch][p] = S(0);
    if constexpr (Depth) dacc[p] = S(0);
  }
  alignas(64) std::uint32_t blended[TP] = {};
  // Rows whose pixels have all stopped are skipped; the check runs every kCheckEvery splats so
  // that the hot loop carries no horizontal reductions.
  constexpr int kCheckEvery = 8;
  bool row_live[TS];
  for (int r = 0; r < TS; ++r) row_live[r] = r < tb.h;
  const std::uint64_t begin = in.bins->tile_offset[std::size_t(tile)], end = in.bins->tile_offset[std::size_t(tile) + 1];
  const std::uint32_t* list = in.bins->tile_list.data();
  std::uint64_t j = begin;
  for (; j < end; ++j) {
    if ((j - begin) % kCheckEvery == 0 && j != begin) {
      bool any = false;
      for (int r = 0; r < tb.h; ++r) {
        if (!row_live[r]) continue;
        S live = S(0);
        for (int x = 0; x < TS; ++x) live = std::max(live, active[r * TS + x]);
        row_live[r] = live > S(0);
        any = any || row_live[r];
      }
      if (!any) break;
    }
    if (j + kPrefetchDistance < end) {
      const std::uint32_t gp = list[j + kPrefetchDistance];
      __builtin_prefetch(in.splats + gp);
      __builtin_prefetch(in.colours + std::size_t(gp) * std::size_t(nc));
    }
    const std::uint32_t g = list[j];
    const Splat<S> s = in.splats[g];
    const int r0 = std::max(s.rect.y0 - tb.y0, 0), r1 = std::min(s.rect.y1 - tb.y0, tb.h - 1);
    S col[NC];
    for (int ch = 0; ch < NC; ++ch) col[ch] = ch < nc ? in.colours[std::size_t(g) * std::size_t(nc) + std::size_t(ch)] : S(0);
    const std::uint32_t pos = std::uint32_t(j - begin + 1);
    std::uint32_t rows_blended = 0;
    for (int r = r0; r <= r1; ++r) {
      if (!row_live[r]) continue;
      const S dy = S(tb.y0 + r) + S(0.5) - s.my;
      S* Tr = T + r * TS;
      S* ar = active + r * TS;
      std::uint32_t* lr = last + r * TS;
      std::uint32_t* br = blended + r * TS;
      int row_took = 0;
#pragma omp simd reduction(| : row_took)
      for (int x = 0; x < TS; ++x) {
        const S dx = S(tb.x0 + x) + S(0.5) - s.mx;
        const S sigma = splat_sigma(s.a, s.b, s.c, dx, dy);
        const S alpha = std::min(K::kMaxAlpha, splat_falloff(s.o, sigma));
        const bool ok = ar[x] > S(0) && sigma >= S(0) && alpha >= K::kMinAlpha;
        const S next_T = Tr[x] * (S(1) - alpha);
        const bool stop = ok && next_T <= K::kMinTransmittance;
        const bool take = ok && !stop;
        const S weight = take ? alpha * Tr[x] : S(0);
        for (int ch = 0; ch < NC; ++ch) acc[ch][r * TS + x] += weight * col[ch];
        if constexpr (Depth) dacc[r * TS + x] += weight * s.z;
        Tr[x] = take ? next_T : Tr[x];
        ar[x] = stop ? S(0) : ar[x];
        lr[x] = take ? pos : lr[x];
        br[x] += take ? 1u : 0u;
        row_took |= take ? 1 : 0;
      }
      rows_blended |= std::uint32_t(row_took) << r;
    }
    out.row_mask[j] = std::uint16_t(rows_blended);
  }
  for (; j < end; ++j) out.row_mask[j] = 0;  // entries after every pixel stopped
  std::uint64_t fragments = 0;
  for (int p = 0; p < TP; ++p) fragments += blended[p];
  const int W = in.grid->width;
  for (int y = 0; y < tb.h; ++y)
    for (int x = 0; x < tb.w; ++x) {
      const int p = y * TS + x;
      const std::size_t pix = std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0 + x);
      for (int ch = 0; ch < nc; ++ch) out.image[pix * std::size_t(nc) + std::size_t(ch)] = acc[ch][p] + T[p] * in.background[ch];
      out.alpha[pix] = S(1) - T[p];
      if constexpr (Depth) out.depth[pix] = dacc[p];
      out.transmittance[pix] = T[p];
      out.last[pix] = last[p];
    }
  return fragments;
}

/// Backward of blend_tile_fwd for one tile: walks the tile's list back to front, rebuilding each
/// pixel's transmittance by division (alpha <= 0.99 keeps it well conditioned), and writes one
/// gradient record per intersection into `records` ([M, BlendRecord::size(count)]). Adds the
/// tile's background gradient into `d_background` ([count]).
template <class S, int C, int MaxC, bool Depth>
inline void blend_tile_bwd(const BlendInputs<S>& in, int tile, const S* transmittance, const std::uint32_t* last_in,
                           const std::uint16_t* row_mask, const BlendGradInputs<S>& gin, S* records, S* d_background) {
  constexpr int TS = TileGrid::kTileSize, TP = TileGrid::kTilePixels;
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  const int nc = C > 0 ? C : in.count;
  const int R = BlendRecord::size(nc);
  const detail::TileBounds<S> tb(*in.grid, tile);
  const std::uint64_t begin = in.bins->tile_offset[std::size_t(tile)], end = in.bins->tile_offset[std::size_t(tile) + 1];

  alignas(64) S T[TP], t_final_terms[TP], dimg[NC][TP], buf[NC][TP], dD[Depth ? TP : 1], bufd[Depth ? TP : 1];
  alignas(64) std::uint32_t last[TP];
  std::uint32_t max_last = 0;
  S bg_grad[NC] = {};
  const int W = in.grid->width;
  for (int p = 0; p < TP; ++p) {
    const int x = p % TS, y = p / TS;
    const bool valid = x < tb.w && y < tb.h;
    const std::size_t pix = valid ? std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0 + x) : 0;
    T[p] = valid ? transmittance[pix] : S(1);
    last[p] = valid ? last_in[pix] : 0;
    max_last = std::max(max_last, last[p]);
    S bg_dot = S(0);
    for (int ch = 0; ch < NC; ++ch) {
      const S d = (valid && ch < nc) ? gin.d_image[pix * std::size_t(nc) + std::size_t(ch)] : S(0);
      dimg[ch][p] = d;
      buf[ch][p] = S(0);
      if (ch < nc) {
        bg_dot += in.background[ch] * d;
        bg_grad[ch] += T[p] * d;
      }
    }
    const S da = (valid && gin.d_alpha) ? gin.d_alpha[pix] : S(0);
    // d(1 - T_final)/d alpha_i and d(T_final bg)/d alpha_i both scale with T_final / (1 - alpha_i).
    t_final_terms[p] = valid ? T[p] * (da - bg_dot) : S(0);
    if constexpr (Depth) {
      dD[p] = (valid && gin.d_depth) ? gin.d_depth[pix] : S(0);
      bufd[p] = S(0);
    }
  }
  for (int ch = 0; ch < nc; ++ch) d_background[ch] += bg_grad[ch];
  if (begin == end) return;  // an empty tile still passes its background gradient (T = 1)

  constexpr int NL = BlendRecord::kBase + NC;  // lane accumulators per record entry
  const std::uint32_t* list = in.bins->tile_list.data();
  for (std::uint64_t jr = begin + max_last; jr-- > begin;) {
    if (jr >= begin + kPrefetchDistance) {
      const std::uint32_t gp = list[jr - kPrefetchDistance];
      __builtin_prefetch(in.splats + gp);
      __builtin_prefetch(in.colours + std::size_t(gp) * std::size_t(nc));
    }
    const std::uint32_t g = list[jr];
    const Splat<S> s = in.splats[g];
    const std::uint32_t k = std::uint32_t(jr - begin);  // pixel blends this splat iff k < last[p]
    S col[NC];
    for (int ch = 0; ch < NC; ++ch) col[ch] = ch < nc ? in.colours[std::size_t(g) * std::size_t(nc) + std::size_t(ch)] : S(0);
    alignas(64) S lane[NL][TS];
    for (int l = 0; l < NL; ++l)
      for (int x = 0; x < TS; ++x) lane[l][x] = S(0);
    // Only the rows where the forward blended this splat (its row mask) can carry gradient.
    for (std::uint32_t rows = row_mask[jr]; rows != 0; rows &= rows - 1) {
      const int r = std::countr_zero(rows);
      const S dy = S(tb.y0 + r) + S(0.5) - s.my;
#pragma omp simd
      for (int x = 0; x < TS; ++x) {
        const int p = r * TS + x;
        const S dx = S(tb.x0 + x) + S(0.5) - s.mx;
        const S sigma = splat_sigma(s.a, s.b, s.c, dx, dy);
        const S e = detail::exp_neg(sigma);
        const S falloff = s.o * e;  // == splat_falloff(s.o, sigma), bit for bit
        const S alpha = std::min(K::kMaxAlpha, falloff);
        const bool ok = k < last[p] && sigma >= S(0) && alpha >= K::kMinAlpha;
        const S ra = S(1) / (S(1) - alpha);
        const S Ti = ok ? T[p] * ra : T[p];
        const S fac = alpha * Ti;
        S v_alpha = t_final_terms[p] * ra;
        for (int ch = 0; ch < NC; ++ch) v_alpha += (col[ch] * Ti - buf[ch][p] * ra) * dimg[ch][p];
        if constexpr (Depth) v_alpha += (s.z * Ti - bufd[p] * ra) * dD[p];
        v_alpha = ok ? v_alpha : S(0);
        for (int ch = 0; ch < NC; ++ch) {
          lane[BlendRecord::kBase + ch][x] += ok ? fac * dimg[ch][p] : S(0);
          buf[ch][p] += ok ? col[ch] * fac : S(0);
        }
        if constexpr (Depth) {
          lane[BlendRecord::kDepth][x] += ok ? fac * dD[p] : S(0);
          bufd[p] += ok ? s.z * fac : S(0);
        }
        // alpha = min(0.99, o e^-sigma): no gradient through the clamp.
        const bool free = falloff < K::kMaxAlpha;
        const S v_sigma = free ? -v_alpha * falloff : S(0);
        lane[BlendRecord::kOpacity][x] += free ? v_alpha * e : S(0);
        lane[BlendRecord::kConicA][x] += S(0.5) * dx * dx * v_sigma;
        lane[BlendRecord::kConicB][x] += dx * dy * v_sigma;
        lane[BlendRecord::kConicC][x] += S(0.5) * dy * dy * v_sigma;
        const S gx = -v_sigma * (s.a * dx + s.b * dy);
        const S gy = -v_sigma * (s.b * dx + s.c * dy);
        lane[BlendRecord::kMeanX][x] += gx;
        lane[BlendRecord::kMeanY][x] += gy;
        lane[BlendRecord::kAbsX][x] += std::abs(gx);
        lane[BlendRecord::kAbsY][x] += std::abs(gy);
        T[p] = Ti;
      }
    }
    S* rec = records + jr * std::uint64_t(R);
    for (int l = 0; l < BlendRecord::kBase + nc; ++l) {
      S sum = S(0);
      for (int x = 0; x < TS; ++x) sum += lane[l][x];
      rec[l] = sum;
    }
  }
  // Splats behind every pixel's last blended one received no gradient.
  for (std::uint64_t j = begin + max_last; j < end; ++j)
    for (int l = 0; l < R; ++l) records[j * std::uint64_t(R) + std::uint64_t(l)] = S(0);
}

}  // namespace msgs
