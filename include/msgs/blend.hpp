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
#include "detail/row_simd.hpp"

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

/// Sets s.sigma_cut from `support` = ln(255 o) (ProjectedGaussian::support): a conservative bound
/// past which o e^-sigma < 1/255, so that the blend can skip a tile row after sigma alone. The 1e-3
/// margin covers the rounding of s.o, of the exponential and of sigma, so the exact path could only
/// have rejected those fragments too.
template <class S>
inline void set_sigma_cut(Splat<S>& s, double support) {
  s.sigma_cut = S(support) + S(1e-3);
}

/// How many tile-list entries ahead the blend loops prefetch splat data (random access by id).
inline constexpr std::uint64_t kPrefetchDistance = 4;

/// Blending constants (REFERENCE §6).
template <class S>
struct BlendConstants {
  static constexpr S kMaxAlpha = S(0.99);
  static constexpr S kMinAlpha = S(1.0 / 255.0);
  static constexpr S kMinTransmittance = S(1e-4);
};

namespace detail {

/// The terms of a splat's Mahalanobis half-distance sigma = 0.5 (a dx^2 + c dy^2) + b dx dy along
/// the rows of one tile. The pixel columns fix dx (a row vector) for the whole tile and dy is one
/// number per row, so after this set-up sigma costs two vector operations per row. Forward and
/// backward both evaluate sigma through sigma_into, so their fragment decisions agree bit for bit.
template <class S>
struct SplatRowTerms {
  using V = typename RowVec<S>::V;
  static constexpr int NH = RowVec<S>::kChunks;
  V dx[NH];          ///< pixel centre x - mean x, per column
  V half_a_dx2[NH];  ///< 0.5 a dx^2
  V b_dx[NH];        ///< b dx
  S half_c;          ///< 0.5 c

  SplatRowTerms(const Splat<S>& s, const V* px) {
    for (int h = 0; h < NH; ++h) {
      dx[h] = px[h] - s.mx;
      half_a_dx2[h] = (S(0.5) * s.a) * dx[h] * dx[h];
      b_dx[h] = s.b * dx[h];
    }
    half_c = S(0.5) * s.c;
  }
  /// out = sigma at chunk h of the row whose pixel centres are dy below the mean.
  void sigma_into(V& out, S dy, int h) const { out = (half_a_dx2[h] + half_c * dy * dy) + b_dx[h] * dy; }
};

/// A splat's fragment opacity along one chunk of a tile row: sigma, e = exp(-sigma), the unclamped
/// falloff o e and alpha = min(0.99, o e). The forward and the backward both fill it through
/// alpha_into, so that they take and skip exactly the same fragments.
template <class S>
struct RowAlpha {
  using V = typename RowVec<S>::V;
  V sigma, e, falloff, alpha;
};

/// The rest of alpha_into once out.sigma is set (the forward reuses the sigma of its row test).
template <class S>
inline void alpha_from_sigma(RowAlpha<S>& out, S opacity, const typename RowVec<S>::V& max_alpha) {
  exp_neg_into(out.e, out.sigma);
  out.falloff = opacity * out.e;
  min_into(out.alpha, out.falloff, max_alpha);  // falloff < 0.99 ? falloff : 0.99
}

template <class S>
inline void alpha_into(RowAlpha<S>& out, const SplatRowTerms<S>& terms, S opacity, S dy, int h,
                       const typename RowVec<S>::V& max_alpha) {
  terms.sigma_into(out.sigma, dy, h);
  alpha_from_sigma(out, opacity, max_alpha);
}

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
  std::uint16_t* row_mask = nullptr;// [M] per intersection: bit r set when the splat blended into tile row r
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

}  // namespace detail

/// Blend one tile front to back. `C` is the channel count when known at compile time (0 = use
/// in.count, at most MaxC). Returns the number of blended fragments. Pixel state lives in row
/// vectors (detail::RowVec: kChunks vectors per tile row); a splat visits only the rows its pixel
/// rectangle touches.
template <class S, int C, int MaxC, bool Depth>
inline std::uint64_t blend_tile_fwd(const BlendInputs<S>& in, int tile, const BlendOutputs<S>& out) {
  constexpr int TS = TileGrid::kTileSize;
  static_assert(TS == detail::kRowLanes, "a row vector is one tile row");
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  using RV = detail::RowVec<S>;
  using V = typename RV::V;
  using M = typename RV::M;
  using U = typename RV::U;
  using I = typename RV::I;
  constexpr int NH = RV::kChunks, L = RV::kLanes, Q = TS * NH;  // vectors per row, lanes each, per tile
  const int nc = C > 0 ? C : in.count;
  const detail::TileBounds<S> tb(*in.grid, tile);
  // Pixel (x, y) is lane x % L of vector y * NH + x / L. T > 0 marks a live pixel: a pixel that
  // has stopped keeps -T (T > 1e-4 there, so the sign is unambiguous), lanes outside the image hold -1.
  V T[Q], acc[NC][Q], dacc[Depth ? Q : 1];
  U last[Q];
  V zero, one, px[NH], max_alpha, min_alpha, min_T;
  detail::broadcast(zero, S(0));
  detail::broadcast(one, S(1));
  detail::broadcast(max_alpha, K::kMaxAlpha);
  detail::broadcast(min_alpha, K::kMinAlpha);
  detail::broadcast(min_T, K::kMinTransmittance);
  for (int h = 0; h < NH; ++h)
    for (int i = 0; i < L; ++i) px[h][i] = S(tb.x0 + h * L + i) + S(0.5);  // pixel centres
  for (int q = 0; q < Q; ++q) {
    const int r = q / NH, h = q % NH;
    for (int i = 0; i < L; ++i) T[q][i] = (h * L + i < tb.w && r < tb.h) ? S(1) : S(-1);
    detail::broadcast(last[q], 0u);
    for (int ch = 0; ch < NC; ++ch) acc[ch][q] = zero;
    if constexpr (Depth) dacc[q] = zero;
  }
  // Rows whose pixels have all stopped are skipped; the check runs every kCheckEvery splats so
  // that the hot loop carries no horizontal reductions.
  constexpr int kCheckEvery = 8;
  bool row_live[TS];
  for (int r = 0; r < TS; ++r) row_live[r] = r < tb.h;
  const std::uint64_t begin = in.bins->tile_offset[std::size_t(tile)], end = in.bins->tile_offset[std::size_t(tile) + 1];
  const std::uint32_t* list = in.bins->tile_list.data();
  std::uint64_t j = begin, fragments = 0;
  for (; j < end; ++j) {
    if ((j - begin) % kCheckEvery == 0 && j != begin) {
      bool any = false;
      for (int r = 0; r < tb.h; ++r) {
        if (row_live[r]) {
          M m = T[r * NH] > zero;
          for (int h = 1; h < NH; ++h) m |= T[r * NH + h] > zero;
          row_live[r] = detail::any_lane(m);
        }
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
    V col[NC];
    for (int ch = 0; ch < NC; ++ch)
      detail::broadcast(col[ch], ch < nc ? in.colours[std::size_t(g) * std::size_t(nc) + std::size_t(ch)] : S(0));
    V z;
    detail::broadcast(z, s.z);
    U pos;
    detail::broadcast(pos, std::uint32_t(j - begin + 1));
    const detail::SplatRowTerms<S> terms(s, px);
    // Rows of the bounding box that the alpha >= 1/255 ellipse misses inside this tile are skipped
    // after sigma alone (2 vector operations instead of exp, masks and accumulation). The cut is
    // conservative (set_sigma_cut): the exact path could only reject every lane too, so the
    // fragments taken are exactly those of the full evaluation.
    V sigma_cut;
    detail::broadcast(sigma_cut, s.sigma_cut);
    std::uint32_t rows_blended = 0;
    for (int r = r0; r <= r1; ++r) {
      if (!row_live[r]) continue;
      const S dy = S(tb.y0 + r) + S(0.5) - s.my;
      detail::RowAlpha<S> f[NH];
      terms.sigma_into(f[0].sigma, dy, 0);
      M near = f[0].sigma <= sigma_cut;
      for (int h = 1; h < NH; ++h) {
        terms.sigma_into(f[h].sigma, dy, h);
        near |= f[h].sigma <= sigma_cut;
      }
      if (!detail::any_lane(near)) continue;
      std::uint32_t took = 0;
      for (int h = 0; h < NH; ++h) {
        const int q = r * NH + h;
        detail::alpha_from_sigma(f[h], s.o, max_alpha);
        const V alpha = f[h].alpha;
        const V t = T[q];
        const M ok = (t > zero) & (f[h].sigma >= zero) & (alpha >= min_alpha);
        const V next_T = t * (one - alpha);
        const M stop = ok & (next_T <= min_T);
        const M take = ok & ~stop;
        const V weight = take ? alpha * t : zero;
        for (int ch = 0; ch < NC; ++ch) detail::fmadd_into(acc[ch][q], weight, col[ch], acc[ch][q]);
        if constexpr (Depth) detail::fmadd_into(dacc[q], weight, z, dacc[q]);
        T[q] = take ? next_T : (stop ? -t : t);
        last[q] = __builtin_convertvector(take, I) ? pos : last[q];
        took |= detail::lane_bits(take) << (h * L);
      }
      fragments += std::uint64_t(std::popcount(took));
      rows_blended |= std::uint32_t(took != 0) << r;
    }
    out.row_mask[j] = std::uint16_t(rows_blended);
  }
  for (; j < end; ++j) out.row_mask[j] = 0;  // entries after every pixel stopped
  const int W = in.grid->width;
  for (int y = 0; y < tb.h; ++y)
    for (int x = 0; x < tb.w; ++x) {
      const int q = y * NH + x / L, i = x % L;
      const std::size_t pix = std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0 + x);
      for (int ch = 0; ch < nc; ++ch) out.image[pix * std::size_t(nc) + std::size_t(ch)] = acc[ch][q][i] + std::abs(T[q][i]) * in.background[ch];
      const S t = std::abs(T[q][i]);
      out.alpha[pix] = S(1) - t;
      if constexpr (Depth) out.depth[pix] = dacc[q][i];
      out.transmittance[pix] = t;
      out.last[pix] = last[q][i];
    }
  return fragments;
}

/// Backward of blend_tile_fwd for one tile: walks the tile's list back to front, rebuilding each
/// pixel's transmittance by division (alpha <= 0.99 keeps it well conditioned), and writes one
/// gradient record per intersection of the tile into `records` ([M, BlendRecord<Depth,
/// AbsGrad>::size(count)], row = position in the tile list; zeros where the row mask is 0). Adds the
/// tile's background gradient into `d_background` ([count]). Alpha is evaluated by the same
/// expressions as in the forward, so both make the same fragment decisions.
template <class S, int C, int MaxC, bool Depth, bool AbsGrad>
inline void blend_tile_bwd(const BlendInputs<S>& in, int tile, const S* transmittance, const std::uint32_t* last_in,
                           const std::uint16_t* row_mask, const BlendGradInputs<S>& gin, S* records, S* d_background) {
  constexpr int TS = TileGrid::kTileSize;
  static_assert(TS == detail::kRowLanes, "a row vector is one tile row");
  constexpr int NC = C > 0 ? C : MaxC;
  using K = BlendConstants<S>;
  using RV = detail::RowVec<S>;
  using V = typename RV::V;
  using M = typename RV::M;
  using U = typename RV::U;
  constexpr int NH = RV::kChunks, L = RV::kLanes, Q = TS * NH;
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
  V zero, one, px[NH], max_alpha, min_alpha;
  detail::broadcast(zero, S(0));
  detail::broadcast(one, S(1));
  detail::broadcast(max_alpha, K::kMaxAlpha);
  detail::broadcast(min_alpha, K::kMinAlpha);
  for (int h = 0; h < NH; ++h)
    for (int i = 0; i < L; ++i) px[h][i] = S(tb.x0 + h * L + i) + S(0.5);
  std::uint32_t max_last = 0;
  S bg_grad[NC] = {};
  const int W = in.grid->width;
  for (int y = 0; y < TS; ++y)
    for (int x = 0; x < TS; ++x) {
      const int q = y * NH + x / L, i = x % L;
      const bool valid = x < tb.w && y < tb.h;
      const std::size_t pix = valid ? std::size_t(tb.y0 + y) * std::size_t(W) + std::size_t(tb.x0 + x) : 0;
      const S t = valid ? transmittance[pix] : S(1);
      T[q][i] = t;
      B[q][i] = S(0);
      last[q][i] = valid ? last_in[pix] : 0;
      max_last = std::max(max_last, last[q][i]);
      S bg_dot = S(0);
      for (int ch = 0; ch < NC; ++ch) {
        const S d = (valid && ch < nc) ? gin.d_image[pix * std::size_t(nc) + std::size_t(ch)] : S(0);
        dimg[ch][q][i] = d;
        if (ch < nc) {
          bg_dot += in.background[ch] * d;
          bg_grad[ch] += t * d;
        }
      }
      const S da = (valid && gin.d_alpha) ? gin.d_alpha[pix] : S(0);
      // d(1 - T_final)/d alpha_i and d(T_final bg)/d alpha_i both scale with T_final / (1 - alpha_i).
      t_final_terms[q][i] = valid ? t * (da - bg_dot) : S(0);
      if constexpr (Depth) dD[q][i] = (valid && gin.d_depth) ? gin.d_depth[pix] : S(0);
    }
  for (int ch = 0; ch < nc; ++ch) d_background[ch] += bg_grad[ch];
  if (begin == end) return;  // an empty tile still passes its background gradient (T = 1)

  // Lane accumulators of one splat, summed over the rows it blended into. With u = -dL/dsigma per
  // pixel (zero where the alpha clamp holds), dL/dsigma enters the conic and mean gradients through
  // sums of u dx^i dy^j; dx is fixed per lane, dy per row, so the rows accumulate only
  // U0 = sum u, U1 = sum u dy and U2 = sum u dy^2 per lane, and the dx factors are applied once per
  // splat (kU0x = U0 dx, kU0xx = U0 dx^2, kU1x = U1 dx) before the horizontal sums. Since
  // falloff = o e, the opacity gradient sum dL/dalpha e = sum(U0) / o needs no accumulator of its own.
  enum : int { kU0 = 0, kU0x, kU0xx, kU1, kU1x, kU2, kCol };
  constexpr int kDep = kCol + NC, kAbsX = kDep + (Depth ? 1 : 0), kAbsY = kAbsX + 1;
  constexpr int NL = kAbsX + (AbsGrad ? 2 : 0);  // only the accumulators this instantiation uses
  const std::uint32_t* list = in.bins->tile_list.data();
  for (std::uint64_t jr = begin + max_last; jr-- > begin;) {
    if (jr >= begin + kPrefetchDistance) {
      const std::uint32_t gp = list[jr - kPrefetchDistance];
      __builtin_prefetch(in.splats + gp);
      __builtin_prefetch(in.colours + std::size_t(gp) * std::size_t(nc));
    }
    S* rec = records + jr * std::uint64_t(R);
    // A splat the forward blended into no pixel of this tile (its box touches the tile, its
    // alpha >= 1/255 region does not, or every pixel had stopped) has no gradient here. Its record
    // is written all the same (zeros; the records are written in list order, so that is cheap),
    // so that the gradient reduction reads records only, not the row masks at scattered slots.
    if (row_mask[jr] == 0) {
      std::fill_n(rec, R, S(0));
      continue;
    }
    const std::uint32_t g = list[jr];
    const Splat<S> s = in.splats[g];
    U k;  // a pixel blended this splat iff k < last
    detail::broadcast(k, std::uint32_t(jr - begin));
    V col[NC];
    for (int ch = 0; ch < NC; ++ch)
      detail::broadcast(col[ch], ch < nc ? in.colours[std::size_t(g) * std::size_t(nc) + std::size_t(ch)] : S(0));
    V z;
    detail::broadcast(z, s.z);
    V lane[NL * NH];  // [accumulator][chunk]
    for (int l = 0; l < NL * NH; ++l) lane[l] = zero;
    const detail::SplatRowTerms<S> terms(s, px);
    [[maybe_unused]] V a_dx[NH];
    if constexpr (AbsGrad)
      for (int h = 0; h < NH; ++h) a_dx[h] = s.a * terms.dx[h];
    // Only the rows where the forward blended this splat (its row mask) can carry gradient.
    for (std::uint32_t rows = row_mask[jr]; rows != 0; rows &= rows - 1) {
      const int r = std::countr_zero(rows);
      const S dy = S(tb.y0 + r) + S(0.5) - s.my;
      V dyv, dy2v;
      detail::broadcast(dyv, dy);
      detail::broadcast(dy2v, dy * dy);
      for (int h = 0; h < NH; ++h) {
        const int q = r * NH + h;
        detail::RowAlpha<S> f;
        detail::alpha_into(f, terms, s.o, dy, h, max_alpha);
        const V alpha = f.alpha, falloff = f.falloff;
        const M ok = __builtin_convertvector(k < last[q], M) & (f.sigma >= zero) & (alpha >= min_alpha);
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
        // alpha = min(0.99, o e^-sigma): no gradient through the clamp. u = -dL/dsigma.
        const M free = ok & (falloff < max_alpha);
        const V u = free ? v_alpha * falloff : zero;
        lane[kU0 * NH + h] += u;
        detail::fmadd_into(lane[kU1 * NH + h], u, dyv, lane[kU1 * NH + h]);
        detail::fmadd_into(lane[kU2 * NH + h], u, dy2v, lane[kU2 * NH + h]);
        if constexpr (AbsGrad) {
          V gx = u * (a_dx[h] + s.b * dy), gy = u * (terms.b_dx[h] + s.c * dy);  // +-dL/dmean per pixel
          detail::abs_into(gx, gx);
          detail::abs_into(gy, gy);
          lane[kAbsX * NH + h] += gx;
          lane[kAbsY * NH + h] += gy;
        }
        T[q] = Ti;
      }
    }
    for (int h = 0; h < NH; ++h) {
      lane[kU0x * NH + h] = lane[kU0 * NH + h] * terms.dx[h];
      lane[kU0xx * NH + h] = lane[kU0x * NH + h] * terms.dx[h];
      lane[kU1x * NH + h] = lane[kU1 * NH + h] * terms.dx[h];
    }
    S sum[NL];
    detail::sum_rows(lane, NL, sum);
    // dL/dsigma = -u: dL/dmean = -(conic (sum v dx, sum v dy)) with v = dL/dsigma, and so on.
    rec[Rec::kMeanX] = s.a * sum[kU0x] + s.b * sum[kU1];
    rec[Rec::kMeanY] = s.b * sum[kU0x] + s.c * sum[kU1];
    rec[Rec::kConicA] = S(-0.5) * sum[kU0xx];
    rec[Rec::kConicB] = -sum[kU1x];
    rec[Rec::kConicC] = S(-0.5) * sum[kU2];
    rec[Rec::kOpacity] = sum[kU0] / s.o;
    for (int ch = 0; ch < nc; ++ch) rec[Rec::kBase + ch] = sum[kCol + ch];
    if constexpr (Depth) rec[Rec::depth(nc)] = sum[kDep];
    if constexpr (AbsGrad) {
      rec[Rec::abs_x(nc)] = sum[kAbsX];
      rec[Rec::abs_x(nc) + 1] = sum[kAbsY];
    }
  }
  // Splats behind every pixel's last blended one (row mask 0, see blend_tile_fwd): zero records.
  std::fill(records + (begin + max_last) * std::uint64_t(R), records + end * std::uint64_t(R), S(0));
}

}  // namespace msgs
