// include/msgs/rasterize.hpp
// The differentiable rasteriser: project -> bin/sort -> blend, and the analytic backward in
// reverse. Exact (no 3-sigma cut-off), deterministic for any OpenMP thread count, any band count
// and band subset; optional features (depth, antialiasing) are compile-time and cost nothing off.
#pragma once

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "bin.hpp"
#include "blend.hpp"
#include "camera.hpp"
#include "colour_gradient_sink.hpp"
#include "detail/overwrite_vector.hpp"
#include "gaussian.hpp"
#include "image.hpp"
#include "project.hpp"

namespace msgs {

namespace detail {

/// pixel_rect of a vector of splats (ProjVec lanes, doubles): the same rectangles, lane by lane.
/// Exact: each bound is computed by the same IEEE operations, clamped to [-2, size + 1] before
/// rounding (which changes no bound inside the image and keeps an empty rectangle empty), then
/// rounded through 64-bit integers, where ceil and floor of such small values are exact. Lanes with
/// a non-finite mean or a NaN extent compute on zeros and give the empty rectangle.
inline void pixel_rect_lanes(const ProjVec& mx, const ProjVec& my, const ProjVec& ex, const ProjVec& ey, int width,
                             int height, PixelRect* out) {
  using L = Lanes<ProjVec>;
  using I = L::M;  // signed 64-bit lanes
  const auto abs = [](const ProjVec& x) {
    return std::bit_cast<ProjVec>(std::bit_cast<I>(x) & (std::numeric_limits<std::int64_t>::max() - I{}));
  };
  const I ok = lfinite(mx) & lfinite(my) & (ex == ex) & (ey == ey);
  const ProjVec zero = L::splat(0.0);
  const ProjVec ax = L::sel(ok, (ex * (1.0 + 1e-4) + 1e-6 * abs(mx)) + 1e-2, zero);
  const ProjVec ay = L::sel(ok, (ey * (1.0 + 1e-4) + 1e-6 * abs(my)) + 1e-2, zero);
  const ProjVec cx = L::sel(ok, mx, zero), cy = L::sel(ok, my, zero);
  // ceil(a) and floor(b) of a, b in [-2, size + 1]: t = trunc(a) as an integer, then up or down.
  const auto ceil_clamped = [&](const ProjVec& a, double size) {
    const ProjVec c = lclamp(a, -2.0, size + 1.0);
    const I t = __builtin_convertvector(c, I);
    return t + LaneInts<ProjVec>::one_where(__builtin_convertvector(t, ProjVec) < c);
  };
  const auto floor_clamped = [&](const ProjVec& b, double size) {
    const ProjVec c = lclamp(b, -2.0, size + 1.0);
    const I t = __builtin_convertvector(c, I);
    return t - LaneInts<ProjVec>::one_where(__builtin_convertvector(t, ProjVec) > c);
  };
  const I zero_i = I{}, wmax = std::int64_t(width - 1) - I{}, hmax = std::int64_t(height - 1) - I{};
  const auto imax = [](const I& a, const I& b) { return a < b ? b : a; };
  const auto imin = [](const I& a, const I& b) { return b < a ? b : a; };
  const I x0 = imax(zero_i, ceil_clamped((cx - ax) - 0.5, double(width)));
  const I x1 = imin(wmax, floor_clamped((cx + ax) - 0.5, double(width)));
  const I y0 = imax(zero_i, ceil_clamped((cy - ay) - 0.5, double(height)));
  const I y1 = imin(hmax, floor_clamped((cy + ay) - 0.5, double(height)));
  const I on = ok & (x0 <= x1) & (y0 <= y1);
  for (int l = 0; l < L::kCount; ++l)
    out[l] = on[l] ? PixelRect{std::int32_t(x0[l]), std::int32_t(y0[l]), std::int32_t(x1[l]), std::int32_t(y1[l])}
                   : PixelRect{};
}

/// The lanes of a projection vector as ProjVec doubles: itself, or the two halves of a float vector.
inline void to_double_lanes(const ProjVec& v, ProjVec* out) { out[0] = v; }
template <int... K>
inline void to_double_lanes(const ProjVecF& v, ProjVec* out, std::integer_sequence<int, K...>) {
  out[0] = __builtin_convertvector(__builtin_shufflevector(v, v, K...), ProjVec);
  out[1] = __builtin_convertvector(__builtin_shufflevector(v, v, (K + kProjLanes)...), ProjVec);
}
inline void to_double_lanes(const ProjVecF& v, ProjVec* out) {
  to_double_lanes(v, out, std::make_integer_sequence<int, kProjLanes>{});
}

}  // namespace detail

/// Compile-time rasteriser features; each costs nothing when off. `depth`: also output the
/// accumulated depth sum_i w_i z_i. `antialiased`: gsplat's antialiased mode (opacity times
/// sqrt(det cov2d / det(cov2d + 0.3 I))). `absgrad`: the backward also fills Gradients::absgrad
/// (sum over pixels of |per-pixel dL/dmean2d|, what absgrad densification reads; as in gsplat it
/// is opt-in: it adds about 13% to the backward of the benchmark frame). `single_precision`: project
/// and shade in single precision, twice as many Gaussians per vector instruction, handing the
/// Gaussians that need it to the double-precision projection (ProjectPrecisionLimits); off, every
/// Gaussian is projected in double, the reference behaviour. `ties_by_mean`: Gaussians at exactly
/// the same depth blend in the order of the bits of their means instead of their rows (gsplat's
/// order, the default), so that an image does not depend on the order of the model's rows
/// (training, which sorts the rows into spatial order; see DensifyConfig::reorder_every). The
/// price: at an exact tie the image also jumps when a mean moves along the tie, which with the
/// row order it does not (test_rasterize_hard_cases checks gradients at such ties).
struct RasterOptions {
  bool depth = false;
  bool antialiased = false;
  bool absgrad = false;
  bool single_precision = false;
  bool ties_by_mean = false;
};

/// Wall-clock seconds spent in each stage, accumulated over calls (reset with `reset()`).
struct RasterTimings {
  double project = 0, bin = 0, blend = 0, blend_backward = 0, project_backward = 0;
  void reset() { *this = RasterTimings{}; }
};

/// Run-time settings of one render.
template <class S>
struct RenderSettings {
  int band_first = 0;         ///< first model channel rendered
  int band_count = -1;        ///< channels rendered; -1 = every channel from band_first on
  int sh_degree = -1;         ///< active SH degree (<= the model's); -1 = the model's
  std::vector<S> background;  ///< empty = 0, one value = broadcast, or band_count values
};

/// Which gradient rows Rasterizer::backward writes: `dense`, every row (zero where the view did
/// not see a Gaussian); `visible`, only the rows of Rasterizer::visible().
enum class GradientFill { dense, visible };

/// Gradients produced by Rasterizer::backward.
template <class G, class S>
struct Gradients {
  /// dL/d parameters. SH of channels outside the rendered range are left as they were, or
  /// unspecified when the model's size changed since the previous backward into this object.
  GaussianModel<G, S> model;
  std::vector<S> mean2d;      ///< [N, 2] dL/d(projected mean, pixels)
  std::vector<S> absgrad;     ///< [N, 2] sum over pixels of |per-pixel dL/d(mean2d)|, per component; empty
                              ///< unless RasterOptions::absgrad
  std::vector<S> background;  ///< [band_count] dL/d(background) per channel (sum them for a broadcast value)
};

/// Tile rasteriser for models of Gaussian type `G` in scalar `S`. Holds the buffers of the last
/// forward so that backward can reuse them and repeated renders do not allocate.
template <class G, class S = float, RasterOptions Opt = RasterOptions{}>
class Rasterizer {
 public:
  using Model = GaussianModel<G, S>;
  static constexpr int kBands = G::bands;

  /// Render `model` from `cam`. Returns the image [H, W, band_count].
  const Image<S>& forward(const Model& model, const Camera<S>& cam, const RenderSettings<S>& settings = {}) {
    using clock = std::chrono::steady_clock;
    const auto t0 = clock::now();
    prepare(model, cam, settings);
    project_all(model);
    const auto t1 = clock::now();
    if constexpr (Opt.ties_by_mean) {
      // Gaussians at the same depth blend in the order of their means' bits, not of their rows,
      // so that permuting the rows (the spatial order) leaves every image as it was.
      bin_gaussians(visible_, depth_.data(), rects_.data(), grid_, bins_, TiesByMean<S>{model.means.data()});
    } else {
      bin_gaussians(visible_, depth_.data(), rects_.data(), grid_, bins_);
    }
    const auto t2 = clock::now();
    blend_all();
    const auto t3 = clock::now();
    timings_.project += std::chrono::duration<double>(t1 - t0).count();
    timings_.bin += std::chrono::duration<double>(t2 - t1).count();
    timings_.blend += std::chrono::duration<double>(t3 - t2).count();
    model_ = &model;
    has_forward_ = true;
    return image_;
  }

  /// Backward of the last forward. `d_image` [H, W, band_count]; `d_alpha`, `d_depth` [H, W, 1]
  /// or nullptr. The model passed to forward must still be alive and unchanged.
  ///
  /// `fill`: with GradientFill::dense every gradient of a Gaussian the view did not see is zero
  /// (a pass over the whole model). With GradientFill::visible only the rows of `visible()` are
  /// written (every geometry value, mean2d, absgrad, and all K coefficients of the rendered
  /// channels); other rows keep whatever they held: the work is proportional to what the view saw,
  /// and the caller reads those rows only (sparse Adam, density statistics over `visible()`).
  ///
  /// `colour`: when given, the colour gradients of the visible Gaussians go to it instead of
  /// `grads.model.sh`, which is then not written at all (whatever `fill`). The model's colour rows
  /// of a Gaussian are read only while its own gradient is computed, before they are handed over,
  /// so the sink may update the model's rows it is given.
  void backward(const Image<S>& d_image, const Image<S>* d_alpha, const Image<S>* d_depth, Gradients<G, S>& grads,
                GradientFill fill = GradientFill::dense, ColourGradientSink<S>* colour = nullptr) {
    if (!has_forward_) throw std::logic_error("Rasterizer::backward: no forward pass to differentiate");
    check_grad_image(d_image, count_, "d_image");
    if (d_alpha) check_grad_image(*d_alpha, 1, "d_alpha");
    if (d_depth) {
      if constexpr (!Opt.depth) throw std::invalid_argument("Rasterizer::backward: d_depth given but depth is off");
      check_grad_image(*d_depth, 1, "d_depth");
    }
    using clock = std::chrono::steady_clock;
    const auto t0 = clock::now();
    const Model& model = *model_;
    const std::size_t N = model.size();
    if (grads.model.size() != N) grads.model.reshape(N);  // every row read below is written below
    detail::resize_for_overwrite(grads.mean2d, 2 * N);  // as the model's rows
    if constexpr (Opt.absgrad) detail::resize_for_overwrite(grads.absgrad, 2 * N);
    else grads.absgrad.clear();
    if (fill == GradientFill::dense) zero_unseen(grads, /*zero_colour=*/colour == nullptr);

    // Blend backward: one gradient record per intersection, per-tile background partials.
    using Rec = BlendRec;
    const int R = Rec::size(count_);
    detail::resize_for_overwrite(records_, bins_.pairs() * std::uint64_t(R));
    zero_blended();  // the blend backward writes the records, and sets the flags, of the pairs that blended only
    bg_partial_.assign(std::size_t(grid_.count()) * std::size_t(count_), S(0));
    BlendGradInputs<S> gin;
    gin.d_image = d_image.data.data();
    gin.d_alpha = d_alpha ? d_alpha->data.data() : nullptr;
    if constexpr (Opt.depth) gin.d_depth = d_depth ? d_depth->data.data() : nullptr;
    dispatch_channels([&]<int C>() {
      const BlendInputs<S> in = blend_inputs();
      const int tiles = grid_.count();
      const int* order = tile_order_.data();
#pragma omp parallel for schedule(dynamic, 1)
      for (int i = 0; i < tiles; ++i) {
        const int t = order[i];
        blend_tile_bwd<S, C, kBands, Opt.depth, Opt.absgrad>(
            in, t, transmittance_.data(), last_.data(), block_mask_.data(), gin, records_.data(), blended_.data(),
            bg_partial_.data() + std::size_t(t) * std::size_t(count_));
      }
    });
    grads.background.assign(std::size_t(count_), S(0));
    for (int t = 0; t < grid_.count(); ++t)
      for (int ch = 0; ch < count_; ++ch) grads.background[std::size_t(ch)] += bg_partial_[std::size_t(t) * std::size_t(count_) + std::size_t(ch)];

    const auto t1 = clock::now();
    // Per-Gaussian reduction in a fixed (tile) order, then projection and colour backward.
    // Gaussians are visited in index order, and the blend backward wrote each one's intersection
    // records together, in that order (Binning::pair): model, gradients and records are
    // read and written sequentially.
    // Gaussians are projected a vector of lanes at a time (detail::project_bwd_lanes, the same bits
    // as one at a time); in single precision the lanes it hands back are redone one at a time in
    // double, as the forward did.
    // A Gaussian none of whose pairs blended (it lies behind where its tiles' pixels stopped: in a
    // deep scene most of the visible ones) has a zero gradient: its rows get +0 and its colour
    // rows a zero gradient, without the projection backward. The others are packed into full
    // vectors within each fixed run of kBackwardRun batches of consecutive visible ids, so the
    // work units, and with them every bit, do not depend on the thread count.
    using D = ProjLanes;
    constexpr int L = detail::Lanes<D>::kCount;
    const std::int64_t V = std::int64_t(visible_.size()), batches = (V + L - 1) / L;
    const std::int64_t runs = (batches + kBackwardRun - 1) / kBackwardRun;
    const int first = first_, count = count_;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t ri = 0; ri < runs; ++ri) {
      // The pending vector of Gaussians that blended, from batches that also held ones that did not.
      std::uint32_t packed_ids[L];
      double packed_acc[L][Rec::size(kBands)];
      int packed = 0;
      const auto flush = [&] {
        for (int l = packed; l < L; ++l) packed_ids[l] = packed_ids[0];  // padding repeats the first
        backward_lanes(model, packed_ids, packed, packed_acc, grads, colour);
        packed = 0;
      };
      for (std::int64_t bi = ri * kBackwardRun, b_end = std::min(batches, bi + kBackwardRun); bi < b_end; ++bi) {
        const std::int64_t v0 = bi * L;
        const int n = int(std::min<std::int64_t>(L, V - v0));
        std::uint32_t ids[L];
        for (int l = 0; l < L; ++l) ids[l] = visible_[std::size_t(v0 + (l < n ? l : 0))];
        // The batch's rows are not consecutive (ids skip what the view did not see): fetch its colour
        // rows and geometry, and for writing the gradient rows that backward_batch stores, while
        // the reduction below runs. Without the gradient rows the stores waited on them for about
        // a third of backward_batch's time.
        for (int l = 0; l < n; ++l) {
          const std::size_t g = ids[l];
          for (int ch = first; ch < first + count; ++ch) {
            detail::prefetch_elements<false>(model.sh_row(g, ch), G::sh_coeffs);
            if (!colour) detail::prefetch_elements<true>(grads.model.sh_row(g, ch), G::sh_coeffs);
          }
          __builtin_prefetch(&model.means[3 * g]);
          __builtin_prefetch(&model.log_scales[3 * g]);
          __builtin_prefetch(&model.quats[4 * g]);
          detail::prefetch_elements<true>(&grads.mean2d[2 * g], 2);
          if constexpr (Opt.absgrad) detail::prefetch_elements<true>(&grads.absgrad[2 * g], 2);
          detail::prefetch_elements<true>(&grads.model.means[3 * g], 3);
          detail::prefetch_elements<true>(&grads.model.log_scales[3 * g], 3);
          detail::prefetch_elements<true>(&grads.model.quats[4 * g], 4);
          detail::prefetch_elements<true>(&grads.model.opacity_logits[g], 1);
        }
        if (colour) colour->prefetch(ids, n, first, count);
        double acc[L][Rec::size(kBands)] = {};  // lanes past n stay zero
        std::uint32_t blended_lanes = 0;        // bit l: some pair of lane l blended
        {
          // The batch's pairs are consecutive (pair order is visible-id order). Only the pairs that
          // blended carry a record (the others were never written): their flags are scanned eight
          // at a time, and each blended pair's lane is found among the lanes' first pairs by a
          // branch-free binary search. In a deep scene most pairs lie behind where their tile's
          // pixels stopped (92% of 10M at 1M / 1280x960 in bench_train_step), and a walk over
          // every pair cost about a tenth of that step. The sums are those of every record, the
          // unwritten ones read as +0 (acc starts at +0, so it is never -0, and adding +0 leaves it
          // as it is): the bits do not depend on which pairs are skipped.
          const std::uint64_t* off = bins_.pair_offset.data() + v0;
          std::uint64_t start[L];  // lane l's first pair; past n, beyond every pair
          for (int l = 0; l < L; ++l) start[l] = l < n ? off[l] : ~std::uint64_t(0);
          const std::uint8_t* blended = blended_.data();
          const S* records = records_.data();
          const auto add = [&](std::uint64_t m) {
            int l = 0;
            for (int step = L / 2; step >= 1; step /= 2) l += start[l + step] <= m ? step : 0;
            blended_lanes |= 1u << l;
            const S* r = records + m * std::uint64_t(R);
            for (int k = 0; k < R; ++k) acc[l][k] += double(r[k]);
          };
          std::uint64_t m = off[0];
          const std::uint64_t m_end = off[n];
          if constexpr (std::endian::native == std::endian::little)
            for (; m + 8 <= m_end; m += 8) {
              std::uint64_t w;
              std::memcpy(&w, blended + m, 8);
              while (w != 0) {
                const int j = std::countr_zero(w) >> 3;
                w &= ~(std::uint64_t(0xFF) << (8 * j));
                add(m + std::uint64_t(j));
              }
            }
          for (; m < m_end; ++m)
            if (blended[m]) add(m);
        }
        const std::uint32_t all = (1u << n) - 1u;  // n <= L <= 16
        if (blended_lanes == all) {
          backward_lanes(model, ids, n, acc, grads, colour);
          continue;
        }
        zero_gradient_rows(ids, n, blended_lanes, grads, colour);
        for (int l = 0; l < n; ++l) {
          if (!(blended_lanes >> l & 1u)) continue;
          packed_ids[packed] = ids[l];
          std::copy_n(acc[l], Rec::size(kBands), packed_acc[packed]);
          if (++packed == L) flush();
        }
      }
      if (packed > 0) flush();
    }
    const auto t2 = clock::now();
    timings_.blend_backward += std::chrono::duration<double>(t1 - t0).count();
    timings_.project_backward += std::chrono::duration<double>(t2 - t1).count();
  }

  /// Accumulated stage timings; `timings().reset()` starts over.
  RasterTimings& timings() { return timings_; }
  const RasterTimings& timings() const { return timings_; }

  const Image<S>& image() const { return image_; }   ///< [H, W, band_count]
  const Image<S>& alpha() const { return alpha_; }   ///< [H, W, 1]: 1 - final transmittance
  /// [H, W, 1]: sum_i w_i z_i (not normalised by alpha). Only with RasterOptions::depth.
  const Image<S>& depth() const {
    static_assert(Opt.depth, "Rasterizer::depth() needs RasterOptions{.depth = true}");
    return depth_image_;
  }
  /// [N, 2] screen half-extent in pixels along x and y; {0, 0} for culled Gaussians.
  const std::vector<std::int32_t>& radii() const { return radii_; }
  /// Blended pixel-Gaussian pairs in the last forward.
  std::uint64_t fragments() const { return fragments_; }
  /// Lanes the blend evaluated in the last forward (BlendTileCount); fragments() of them blended.
  std::uint64_t blend_lanes() const { return blend_lanes_; }
  /// Gaussian-tile pairs in the last forward.
  std::uint64_t intersections() const { return bins_.pairs(); }
  /// Number of Gaussians that survived culling in the last forward.
  std::size_t visible_count() const { return visible_.size(); }
  /// Their indices, ascending: the rows a GradientFill::visible backward writes.
  const std::vector<std::uint32_t>& visible() const { return visible_; }
  /// The tile lists of the last forward.
  const Binning& binning() const { return bins_; }
  /// Channels rendered by the last forward.
  int band_first() const { return first_; }
  int band_count() const { return count_; }

 private:
  using BlendRec = BlendRecord<Opt.depth, Opt.absgrad>;
  /// Lane type of the projection: a vector of floats or of doubles (RasterOptions::single_precision).
  using ProjLanes = std::conditional_t<Opt.single_precision, detail::ProjVecF, detail::ProjVec>;

  /// Bits of the set lanes of a projection mask (bit 0 for one lane).
  template <class Mask>
  static std::uint32_t mask_bits(const Mask& m) {
    if constexpr (std::is_same_v<Mask, bool>) return m ? 1u : 0u;
    else return detail::lane_bits(m);
  }

  /// Batches of consecutive visible ids per work unit of the per-Gaussian backward.
  static constexpr std::int64_t kBackwardRun = 32;

  /// Projection and colour backward of ids[0 .. n) from their reduced records `acc`, a vector of
  /// lanes at a time, with the lanes handed back (single precision) redone in double.
  void backward_lanes(const Model& model, const std::uint32_t* ids, int n, const double (*acc)[BlendRec::size(kBands)],
                      Gradients<G, S>& grads, ColourGradientSink<S>* colour) const {
    const std::uint32_t hard = backward_batch<ProjLanes>(model, ids, n, acc, grads, colour);
    if constexpr (Opt.single_precision)
      for (int l = 0; l < n; ++l)
        if (hard >> l & 1u) backward_batch<double>(model, &ids[l], 1, &acc[l], grads, colour);
  }

  /// The gradient of the lanes of ids[0 .. n) whose bit in `keep` is clear, none of whose pairs
  /// blended: +0 in every row the backward writes, and a zero colour gradient to the sink.
  void zero_gradient_rows(const std::uint32_t* ids, int n, std::uint32_t keep, Gradients<G, S>& grads,
                          ColourGradientSink<S>* colour) const {
    alignas(64) static constexpr S kZeroRow[G::sh_coeffs] = {};
    for (int l = 0; l < n; ++l)
      if (!(keep >> l & 1u)) zero_gradient_row(grads, ids[l], /*zero_colour=*/colour == nullptr);
    if (colour)
      for (int ch = first_; ch < first_ + count_; ++ch) colour->consume(ids, n, keep, ch, kZeroRow, 0);
  }

  /// Projection and colour backward of the visible Gaussians ids[0 .. n) (lanes past n repeat
  /// ids[0]), from their reduced records acc[l]: writes their rows of `grads`, the colour ones to
  /// `colour` when given. Returns the lanes handed to double precision (bits; their rows are not
  /// written).
  template <class D>
  std::uint32_t backward_batch(const Model& model, const std::uint32_t* ids, int n,
                               const double (*acc)[BlendRec::size(kBands)], Gradients<G, S>& grads,
                               ColourGradientSink<S>* colour) const {
    using Rec = BlendRec;
    using LD = detail::Lanes<D>;
    using T = typename LD::T;
    const ProjectCamera& pcam = pcam_;
    const int first = first_, count = count_, deg = sh_degree_;
    detail::GeometryLanes<D> geo;
    detail::gather_geometry(model, ids, geo);
    detail::ProjectedGradLanes<D> pg{};
    detail::GeometryGradLanes<D> gg{};
    for (int l = 0; l < n; ++l) {
      detail::set_lane(pg.mean2d[0], l, T(acc[l][Rec::kMeanX]));
      detail::set_lane(pg.mean2d[1], l, T(acc[l][Rec::kMeanY]));
      detail::set_lane(pg.conic[0], l, T(acc[l][Rec::kConicA]));
      detail::set_lane(pg.conic[1], l, T(acc[l][Rec::kConicB]));
      detail::set_lane(pg.conic[2], l, T(acc[l][Rec::kConicC]));
      detail::set_lane(pg.opacity, l, T(acc[l][Rec::kOpacity]));
      if constexpr (Opt.depth) detail::set_lane(pg.depth, l, T(acc[l][Rec::depth(count)]));
    }
    const std::uint32_t hard = mask_bits(detail::project_bwd_lanes<Opt.antialiased>(geo, pcam, pg, gg, /*known_visible=*/true));
    // Colour backward for the whole vector: dL/dSH into the band planes, dL/d(mean) through the
    // view direction added to gg.mean.
    {
      const D raw[3] = {geo.mean[0] - LD::splat(pcam.position[0]), geo.mean[1] - LD::splat(pcam.position[1]),
                        geo.mean[2] - LD::splat(pcam.position[2])};
      D v_colour[kBands]{};
      for (int ch = 0; ch < count; ++ch) {
        v_colour[ch] = LD::splat(0.0);
        for (int l = 0; l < n; ++l) detail::set_lane(v_colour[ch], l, T(acc[l][Rec::kBase + ch]));
      }
      const int K = sh_coeffs_for_degree(deg);
      ShLanes<D> cf, v_sh;
      cf.gather(model, ids, first, count, K);
      detail::colour_bwd_lanes<D>(
          count, deg, raw, [&](int ch, int k) { return cf.load(ch, k); }, v_colour,
          [&](int ch, int k, const D& v) { v_sh.store(ch, k, v); }, gg.mean);
      if (colour) {
        alignas(64) S rows[ShLanes<D>::L][G::sh_coeffs];
        for (int ch = 0; ch < count; ++ch) {
          v_sh.rows(ch, K, rows);
          colour->consume(ids, n, hard, first + ch, &rows[0][0], G::sh_coeffs);
        }
      } else {
        v_sh.scatter(grads.model, ids, n, hard, first, count, K);  // coefficients above the active degree: zero
      }
    }
    for (int l = 0; l < n; ++l) {
      if (hard >> l & 1u) continue;
      const std::uint32_t g = ids[l];
      grads.mean2d[2 * g] = S(acc[l][Rec::kMeanX]);
      grads.mean2d[2 * g + 1] = S(acc[l][Rec::kMeanY]);
      if constexpr (Opt.absgrad) {
        grads.absgrad[2 * g] = S(acc[l][Rec::abs_x(count)]);
        grads.absgrad[2 * g + 1] = S(acc[l][Rec::abs_x(count) + 1]);
      }
      for (int i = 0; i < 3; ++i) {
        grads.model.means[3 * g + i] = S(detail::lane(gg.mean[i], l));
        grads.model.log_scales[3 * g + i] = S(detail::lane(gg.log_scale[i], l));
      }
      for (int i = 0; i < 4; ++i) grads.model.quats[4 * g + i] = S(detail::lane(gg.quat[i], l));
      grads.model.opacity_logits[g] = S(detail::lane(gg.opacity_logit, l));
    }
    return hard;
  }

  void check_grad_image(const Image<S>& img, int channels, const char* name) const {
    if (img.width != grid_.width || img.height != grid_.height)
      throw std::invalid_argument(std::string("Rasterizer::backward: ") + name + " is " + std::to_string(img.width) +
                                  "x" + std::to_string(img.height) + ", the render was " + std::to_string(grid_.width) +
                                  "x" + std::to_string(grid_.height));
    check_grad_image_shape(img, channels, name);
  }
  static void check_grad_image_shape(const Image<S>& img, int channels, const char* name) {
    if (img.channels != channels || img.data.size() != img.pixels() * std::size_t(channels))
      throw std::invalid_argument(std::string("Rasterizer::backward: ") + name + " must have " +
                                  std::to_string(channels) + " channel(s)");
  }

  void prepare(const Model& model, const Camera<S>& cam, const RenderSettings<S>& st) {
    model.check_consistent();
    cam.validate();
    first_ = st.band_first;
    count_ = st.band_count < 0 ? kBands - st.band_first : st.band_count;
    if (first_ < 0 || first_ >= kBands || count_ < 1 || first_ + count_ > kBands)
      throw std::invalid_argument("RenderSettings: band range [" + std::to_string(first_) + ", " +
                                  std::to_string(first_ + count_) + ") is outside the model's " +
                                  std::to_string(kBands) + " channel(s)");
    sh_degree_ = st.sh_degree < 0 ? G::sh_degree : st.sh_degree;
    if (sh_degree_ > G::sh_degree)
      throw std::invalid_argument("RenderSettings: sh_degree " + std::to_string(st.sh_degree) + " exceeds the model's " +
                                  std::to_string(G::sh_degree));
    if (st.background.empty()) background_.assign(std::size_t(count_), S(0));
    else if (st.background.size() == 1) background_.assign(std::size_t(count_), st.background[0]);
    else if (st.background.size() == std::size_t(count_)) background_ = st.background;
    else
      throw std::invalid_argument("RenderSettings: background has " + std::to_string(st.background.size()) +
                                  " values; expected 0, 1 or " + std::to_string(count_));
    for (S v : background_)
      if (!std::isfinite(double(v))) throw std::invalid_argument("RenderSettings: background must be finite");
    pcam_ = ProjectCamera::from(cam);
    grid_ = TileGrid(cam.width, cam.height);
    const std::size_t N = model.size();
    splats_.resize(N);
    colours_.resize(N * std::size_t(count_));
    depth_.resize(N);
    rects_.resize(N);  // these three are written for every Gaussian by project_all
    radii_.resize(2 * N);
    visible_flag_.resize(N);
  }

  void project_all(const Model& model) {
    // A vector of lanes at a time (detail::project_lanes: the same bits as one at a time); in
    // single precision the lanes it hands back are redone one at a time in double.
    using D = ProjLanes;
    constexpr int L = detail::Lanes<D>::kCount;
    const std::int64_t N = std::int64_t(model.size()), batches = (N + L - 1) / L;
#pragma omp parallel for schedule(dynamic, 128)
    for (std::int64_t bi = 0; bi < batches; ++bi) {
      const std::int64_t i0 = bi * L;
      const int n = int(std::min<std::int64_t>(L, N - i0));
      std::uint32_t ids[L];
      for (int l = 0; l < L; ++l) ids[l] = std::uint32_t(i0 + (l < n ? l : 0));  // padding repeats the first
      if (const std::int64_t ip = i0 + kProjectPrefetchBatches * L; ip + L <= N) prefetch_colour_rows(model, std::size_t(ip));
      const std::uint32_t hard = project_batch<D>(model, ids, n);
      if constexpr (Opt.single_precision)
        for (int l = 0; l < n; ++l)
          if (hard >> l & 1u) project_batch<double>(model, &ids[l], 1);
    }
    // The visible ids, ascending: counted per fixed chunk of rows, then each chunk writes its ids
    // from its offset (a serial pass here took 8% of the demo's projection time).
    const int chunks = detail::fixed_chunks(std::size_t(N));
    const auto chunk_begin = [&](int k) { return std::size_t(N) * std::size_t(k) / std::size_t(chunks); };
    visible_offset_.assign(std::size_t(chunks) + 1, 0);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < chunks; ++k) {
      std::size_t c = 0;
      for (std::size_t i = chunk_begin(k), e = chunk_begin(k + 1); i < e; ++i) c += visible_flag_[i];
      visible_offset_[std::size_t(k) + 1] = c;
    }
    for (int k = 0; k < chunks; ++k) visible_offset_[std::size_t(k) + 1] += visible_offset_[std::size_t(k)];
    visible_.resize(visible_offset_[std::size_t(chunks)]);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < chunks; ++k) {
      std::uint32_t* out = visible_.data() + visible_offset_[std::size_t(k)];
      for (std::size_t i = chunk_begin(k), e = chunk_begin(k + 1); i < e; ++i)
        if (visible_flag_[i]) *out++ = std::uint32_t(i);
    }
  }

  /// How many batches ahead project_all fetches the colour rows it will read. The hardware's
  /// prefetch does not keep up with them: on the demo's views the projection waited on its colour
  /// rows for about a third of its time, and fetching them 4 batches ahead made it about 1.17x
  /// faster (2 to 16 gave about the same). Fetching the geometry rows too made it slower again.
  static constexpr std::int64_t kProjectPrefetchBatches = 4;

  /// Fetches into the cache the rendered channels' colour rows of the L consecutive Gaussians from
  /// `first_row` (one batch of the projection).
  void prefetch_colour_rows(const Model& model, std::size_t first_row) const {
    constexpr int L = detail::Lanes<ProjLanes>::kCount;
    for (int ch = first_; ch < first_ + count_; ++ch)
      detail::prefetch_elements<false>(model.sh_row(first_row, ch), std::size_t(L) * G::sh_coeffs);
  }

  /// Project and shade the Gaussians ids[0 .. n) (lanes past n repeat ids[0]) and write their
  /// splats, colours, rectangles, radii and visibility. Returns the lanes handed to double
  /// precision (bits; their rows are not written).
  template <class D>
  std::uint32_t project_batch(const Model& model, const std::uint32_t* ids, int n) {
    using LD = detail::Lanes<D>;
    const int first = first_, count = count_, deg = sh_degree_;
    detail::GeometryLanes<D> geo;
    detail::gather_geometry(model, ids, geo);
    detail::ProjectedLanes<D> pl;
    const auto visible = detail::project_lanes<Opt.antialiased>(geo, pcam_, pl, nullptr, false);
    const std::uint32_t hard = mask_bits(pl.hard);
    // Colour of the rendered channels for the whole vector (SH coefficients gathered from the
    // band planes); a lane with a non-finite active coefficient is culled.
    auto drawn = visible;  // and every active coefficient of the rendered channels finite
    D col[kBands];
    if (LD::any(visible)) {
      D dir[3] = {LD::splat(0.0), LD::splat(0.0), LD::splat(1.0)};
      if constexpr (G::sh_degree > 0) {
        if (deg > 0) {
          const D raw[3] = {geo.mean[0] - LD::splat(pcam_.position[0]), geo.mean[1] - LD::splat(pcam_.position[1]),
                            geo.mean[2] - LD::splat(pcam_.position[2])};
          D len;
          detail::view_dir(raw, dir, len);
        }
      }
      ShLanes<D> cf;
      cf.gather(model, ids, first, count, sh_coeffs_for_degree(deg));
      detail::colour_fwd_lanes<D>(count, deg, dir, [&](int ch, int k) {
        const D c = cf.load(ch, k);
        drawn = detail::mand(drawn, detail::lfinite(c));
        return c;
      }, col);
    }
    // The pixel rectangles of the whole vector at once (the lanes of pixel_rect).
    PixelRect rect_of[LD::kCount];
    if constexpr (!std::is_arithmetic_v<D>) {
      if (LD::any(drawn)) {
        constexpr int H = LD::kCount / detail::kProjLanes;  // double vectors per lane vector
        detail::ProjVec mxd[H], myd[H], exd[H], eyd[H];
        detail::to_double_lanes(pl.mean2d[0], mxd);
        detail::to_double_lanes(pl.mean2d[1], myd);
        detail::to_double_lanes(pl.extent[0], exd);
        detail::to_double_lanes(pl.extent[1], eyd);
        for (int h = 0; h < H; ++h)
          detail::pixel_rect_lanes(mxd[h], myd[h], exd[h], eyd[h], grid_.width, grid_.height, rect_of + h * detail::kProjLanes);
      }
    }
    if constexpr (kWholeVectorStores<D>) {
      if (n == detail::Lanes<D>::kCount && ids[n - 1] == ids[0] + std::uint32_t(n - 1)) {
        store_batch(ids[0], pl, col, rect_of, drawn, hard);
        return hard;
      }
    }
    for (int l = 0; l < n; ++l) {
      if (hard >> l & 1u) continue;
      const std::size_t i = ids[l];
      rects_[i] = PixelRect{};  // culled until shown otherwise
      radii_[2 * i] = radii_[2 * i + 1] = 0;
      visible_flag_[i] = 0;
      if (!detail::lane_on(drawn, l)) continue;
      const double mx = detail::lane(pl.mean2d[0], l), my = detail::lane(pl.mean2d[1], l);
      const double ex = detail::lane(pl.extent[0], l), ey = detail::lane(pl.extent[1], l);
      PixelRect rect;
      if constexpr (std::is_arithmetic_v<D>) rect = pixel_rect(mx, my, ex, ey, grid_.width, grid_.height);
      else rect = rect_of[l];
      if (rect.empty()) continue;
      Splat<S>& s = splats_[i];
      s.mx = S(mx); s.my = S(my);
      s.a = S(detail::lane(pl.conic[0], l)); s.b = S(detail::lane(pl.conic[1], l)); s.c = S(detail::lane(pl.conic[2], l));
      s.o = S(detail::lane(pl.opacity, l));
      s.z = S(detail::lane(pl.depth, l));
      set_sigma_cut(s, double(detail::lane(pl.support, l)));
      s.rect = rect;
      depth_[i] = s.z;
      for (int ch = 0; ch < count; ++ch) colours_[i * std::size_t(count) + std::size_t(ch)] = S(detail::lane(col[ch], l));
      rects_[i] = rect;
      radii_[2 * i] = std::int32_t(std::min(std::ceil(ex), 1e9));
      radii_[2 * i + 1] = std::int32_t(std::min(std::ceil(ey), 1e9));
      visible_flag_[i] = 1;
    }
    return hard;
  }

  /// Whether project_batch writes a whole batch of lane type D with vector stores (store_batch):
  /// single-precision lanes of 8 or more floats into a float rasteriser.
  template <class D>
  static constexpr bool kWholeVectorStores = std::is_same_v<D, detail::ProjVecF> && std::is_same_v<S, float> &&
                                             detail::Lanes<D>::kCount >= 8;

  /// project_batch's outputs for the L consecutive rows from `i0` (none of them padding), as whole
  /// vectors where the lane loop stores one value at a time: the same values, the same rows.
  /// `drawn`: the lanes projected with finite colours; `hard`: the lanes handed to double precision,
  /// whose rows are left alone. The splats move as one transposed block (detail::transpose_square).
  template <class D>
  void store_batch(std::size_t i0, const detail::ProjectedLanes<D>& pl, const D* col, const PixelRect* rect_of,
                   const typename detail::Lanes<D>::M& drawn, std::uint32_t hard) {
    using LD = detail::Lanes<D>;
    using I = typename LD::M;  // 32-bit integer lanes
    constexpr int L = LD::kCount;
    // The lanes shown (drawn, with a rectangle in the image) and the lanes written (not hard).
    std::uint32_t shown_bits = detail::lane_bits(drawn) & ~hard;
    for (int l = 0; l < L; ++l)
      if (rect_of[l].empty()) shown_bits &= ~(1u << l);
    I iota;
    for (int l = 0; l < L; ++l) iota[l] = l;
    const I shown = -((I{} + std::int32_t(shown_bits)) >> iota & 1), written = -((I{} + std::int32_t(~hard)) >> iota & 1);
    // Visibility flags, radii and rectangles of every written row.
    {
      typedef std::int8_t Bytes __attribute__((vector_size(L)));
      Bytes flags;
      std::memcpy(&flags, &visible_flag_[i0], sizeof flags);
      flags = __builtin_convertvector(written, Bytes) ? __builtin_convertvector(shown & 1, Bytes) : flags;
      std::memcpy(&visible_flag_[i0], &flags, sizeof flags);
    }
    {
      // min(ceil(e), 1e9) of the shown lanes as integers: ceil of e clamped to [0, 1e9] by
      // truncation and a step up (exact: below 2^24 the truncation is, above it e is integral).
      const auto radius = [&](const D& e) {
        const D c = LD::sel(shown, detail::lmin(e, LD::splat(1e9)), LD::splat(0.0));
        const I t = __builtin_convertvector(c, I);
        return t - (__builtin_convertvector(t, D) < c);  // (true is -1)
      };
      const I rx = radius(pl.extent[0]), ry = radius(pl.extent[1]);
      // Lanes interleaved (x0, y0, x1, y1, ...): the first half of the lanes, then the second.
      struct Lo {
        constexpr int operator()(int l) const { return l / 2 + (l % 2) * L; }
      };
      struct Hi {
        constexpr int operator()(int l) const { return L / 2 + l / 2 + (l % 2) * L; }
      };
      const I r_lo = detail::shuffle_lanes<Lo>(rx, ry), r_hi = detail::shuffle_lanes<Hi>(rx, ry);
      const I w_lo = detail::shuffle_lanes<Lo>(written, written), w_hi = detail::shuffle_lanes<Hi>(written, written);
      I old_lo, old_hi;
      std::int32_t* r = &radii_[2 * i0];
      std::memcpy(&old_lo, r, sizeof(I));
      std::memcpy(&old_hi, r + L, sizeof(I));
      old_lo = w_lo ? r_lo : old_lo;
      old_hi = w_hi ? r_hi : old_hi;
      std::memcpy(r, &old_lo, sizeof(I));
      std::memcpy(r + L, &old_hi, sizeof(I));
    }
    for (int l = 0; l < L; ++l)
      if (!(hard >> l & 1u)) rects_[i0 + std::size_t(l)] = (shown_bits >> l & 1u) ? rect_of[l] : PixelRect{};
    if (shown_bits == 0) return;
    // Depth and the colours of the shown rows.
    {
      D d;
      std::memcpy(&d, &depth_[i0], sizeof d);
      d = LD::sel(shown, pl.depth, d);
      std::memcpy(&depth_[i0], &d, sizeof d);
    }
    if (count_ == 1) {
      D c;
      std::memcpy(&c, &colours_[i0], sizeof c);
      c = LD::sel(shown, col[0], c);
      std::memcpy(&colours_[i0], &c, sizeof c);
    } else {
      for (int l = 0; l < L; ++l)
        if (shown_bits >> l & 1u)
          for (int ch = 0; ch < count_; ++ch) colours_[(i0 + std::size_t(l)) * std::size_t(count_) + std::size_t(ch)] = col[ch][l];
    }
    // The splats: their eight float fields transposed into rows, the rectangle after them.
    static_assert(offsetof(Splat<S>, sigma_cut) == 7 * sizeof(S) && offsetof(Splat<S>, rect) == 8 * sizeof(S));
    D rows[L] = {};
    rows[0] = pl.mean2d[0];
    rows[1] = pl.mean2d[1];
    rows[2] = pl.conic[0];
    rows[3] = pl.conic[1];
    rows[4] = pl.conic[2];
    rows[5] = pl.opacity;
    rows[6] = pl.depth;
    rows[7] = pl.support + LD::splat(kSigmaCutMargin);  // set_sigma_cut, a lane at a time
    detail::transpose_square(rows);
    for (std::uint32_t bits = shown_bits; bits != 0; bits &= bits - 1) {
      const int l = std::countr_zero(bits);
      Splat<S>& sp = splats_[i0 + std::size_t(l)];
      std::memcpy(static_cast<void*>(&sp), &rows[l], 8 * sizeof(S));  // mx .. sigma_cut
      sp.rect = rect_of[l];
    }
  }

  BlendInputs<S> blend_inputs() const {
    BlendInputs<S> in;
    in.grid = &grid_;
    in.bins = &bins_;
    in.splats = splats_.data();
    in.colours = colours_.data();
    in.count = count_;
    in.background = background_.data();
    return in;
  }

  /// Call f.template operator()<C>() with C = count_ when it is a common compile-time channel
  /// count (1, 3 or all bands), else C = 0 (run-time count).
  template <class F>
  void dispatch_channels(F&& f) {
    if (count_ == 1) f.template operator()<1>();
    else if (count_ == kBands) f.template operator()<kBands>();
    else if constexpr (kBands > 3) {
      if (count_ == 3) f.template operator()<3>();
      else f.template operator()<0>();
    } else {
      f.template operator()<0>();
    }
  }

  void blend_all() {
    const int W = grid_.width, H = grid_.height;
    image_.reshape(W, H, count_);  // the tiles cover every pixel: no clearing needed
    alpha_.reshape(W, H, 1);
    if constexpr (Opt.depth) depth_image_.reshape(W, H, 1);
    transmittance_.resize(std::size_t(W) * std::size_t(H));
    last_.resize(std::size_t(W) * std::size_t(H));
    BlendOutputs<S> out;
    out.image = image_.data.data();
    out.alpha = alpha_.data.data();
    if constexpr (Opt.depth) out.depth = depth_image_.data.data();
    out.transmittance = transmittance_.data();
    out.last = last_.data();
    detail::resize_for_overwrite(block_mask_, bins_.pairs());  // written for every pair
    out.block_mask = block_mask_.data();
    order_tiles();
    std::uint64_t frags = 0, lanes = 0;
    dispatch_channels([&]<int C>() {
      const BlendInputs<S> in = blend_inputs();
      const int tiles = grid_.count();
      const int* order = tile_order_.data();
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : frags, lanes)
      for (int i = 0; i < tiles; ++i) {
        const BlendTileCount c = blend_tile_fwd<S, C, kBands, Opt.depth>(in, order[i], out);
        frags += c.fragments;
        lanes += c.lanes;
      }
    });
    fragments_ = frags;
    blend_lanes_ = lanes;
  }

  /// The order the blend passes take the tiles in: longest list first, so that the tiles taken
  /// last are short and the threads finish together (a tile's cost grows with its list). Every
  /// tile writes only its own pixels and records, so the order does not change a bit.
  void order_tiles() {
    const int tiles = grid_.count();
    tile_order_.resize(std::size_t(tiles));
    for (int t = 0; t < tiles; ++t) tile_order_[std::size_t(t)] = t;
    const std::uint64_t* off = bins_.tile_offset.data();
    std::stable_sort(tile_order_.begin(), tile_order_.end(), [off](int a, int b) {
      return off[a + 1] - off[a] > off[b + 1] - off[b];
    });
  }

  /// Size the per-pair flags of the blend backward (blended_) to this frame's pairs and clear them,
  /// in parallel over fixed chunks (each thread first touches and streams its own part).
  void zero_blended() {
    const std::size_t n = bins_.pairs();
    detail::resize_for_overwrite(blended_, n);
    const int chunks = detail::fixed_chunks(n);
    std::uint8_t* b = blended_.data();
#pragma omp parallel for schedule(static)
    for (int k = 0; k < chunks; ++k)
      std::fill(b + n * std::size_t(k) / std::size_t(chunks), b + n * std::size_t(k + 1) / std::size_t(chunks), std::uint8_t(0));
  }

  /// Zero every gradient of a culled Gaussian (the reduction writes the visible rows, all
  /// coefficients of the rendered channels included), the colour rows with `zero_colour`. In
  /// parallel, since it touches every Gaussian.
  void zero_unseen(Gradients<G, S>& grads, bool zero_colour) const {
    const std::int64_t N = std::int64_t(model_->size());
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t ii = 0; ii < N; ++ii)
      if (!visible_flag_[std::size_t(ii)]) zero_gradient_row(grads, std::size_t(ii), zero_colour);
  }

  /// Gaussian i's rows of `grads` that the backward writes, +0: geometry, mean2d, absgrad, and the
  /// rendered channels' colour rows with `zero_colour`.
  void zero_gradient_row(Gradients<G, S>& grads, std::size_t i, bool zero_colour) const {
    auto& m = grads.model;
    for (std::size_t a = 0; a < 3; ++a) m.means[3 * i + a] = m.log_scales[3 * i + a] = S(0);
    for (std::size_t a = 0; a < 4; ++a) m.quats[4 * i + a] = S(0);
    m.opacity_logits[i] = S(0);
    grads.mean2d[2 * i] = grads.mean2d[2 * i + 1] = S(0);
    if constexpr (Opt.absgrad) grads.absgrad[2 * i] = grads.absgrad[2 * i + 1] = S(0);
    if (zero_colour)
      for (int ch = first_; ch < first_ + count_; ++ch) std::fill_n(m.sh_row(i, ch), G::sh_coeffs, S(0));
  }

  /// SH coefficients of the rendered channels of a vector of Gaussians (lane type D),
  /// lane-minor ([channel, coefficient, lane]) so that a coefficient of all lanes is one vector
  /// load; gathered from and scattered to the band planes one Gaussian's contiguous row at a time.
  /// Where the lanes hold the model's scalar and a row is a whole number of vectors (single
  /// precision with SH degree 3 and 16 or 8 lanes: the training step), rows move as vectors
  /// and an L x L block transpose turns them around; otherwise one value at a time.
  template <class D>
  struct ShLanes {
    using T = typename detail::Lanes<D>::T;
    static constexpr int L = detail::Lanes<D>::kCount;
    static constexpr bool kBlocks = std::is_same_v<T, S> && L > 1 && G::sh_coeffs % L == 0;
    alignas(64) T v[kBands][G::sh_coeffs][L];

    /// Every lane's id must be a Gaussian of `m` (lanes past a batch's end repeat its first).
    template <class M>
    void gather(const M& m, const std::uint32_t* ids, int first, int count, int K) {
      if constexpr (kBlocks) {
        // Whole blocks of L coefficients: the ones from K on are loaded along, not stored.
        for (int ch = 0; ch < count; ++ch)
          for (int k0 = 0; k0 < K; k0 += L) {
            D r[L];
            for (int l = 0; l < L; ++l) std::memcpy(&r[l], m.sh_row(ids[l], first + ch) + k0, sizeof(D));
            detail::transpose_square(r);
            for (int k = 0; k < L && k0 + k < K; ++k) store(ch, k0 + k, r[k]);
          }
      } else {
        for (int ch = 0; ch < count; ++ch)
          for (int l = 0; l < L; ++l) {
            const S* row = m.sh_row(ids[l], first + ch);
            for (int k = 0; k < K; ++k) v[ch][k][l] = T(row[k]);
          }
      }
    }
    // gather() fills every coefficient below K of every channel below count, all that load() is
    // asked for; GCC 12 cannot follow that through colour_bwd_lanes for one-coefficient models
    // with 8 lanes (AVX2) and warns of an uninitialised read.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
    D load(int ch, int k) const {
      D d;
      std::memcpy(&d, v[ch][k], sizeof d);
      return d;
    }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
    void store(int ch, int k, const D& d) { std::memcpy(v[ch][k], &d, sizeof d); }
    /// Lane l's coefficients of channel ch as a row, out[l][0 .. G::sh_coeffs), zeros from K on.
    void rows(int ch, int K, S (*out)[G::sh_coeffs]) const {
      if constexpr (kBlocks) {
        for (int k0 = 0; k0 < G::sh_coeffs; k0 += L) {
          D r[L];
          for (int k = 0; k < L; ++k) r[k] = k0 + k < K ? load(ch, k0 + k) : D{};
          detail::transpose_square(r);
          for (int l = 0; l < L; ++l) std::memcpy(out[l] + k0, &r[l], sizeof(D));
        }
      } else {
        for (int l = 0; l < L; ++l) {
          for (int k = 0; k < K; ++k) out[l][k] = S(v[ch][k][l]);
          for (int k = K; k < G::sh_coeffs; ++k) out[l][k] = S(0);
        }
      }
    }
    /// Write the first n lanes' K coefficients of each channel into `g`, zeros above K; lanes
    /// whose bit is set in `skip` are left out.
    template <class M>
    void scatter(M& g, const std::uint32_t* ids, int n, std::uint32_t skip, int first, int count, int K) const {
      alignas(64) S out[L][G::sh_coeffs];
      for (int ch = 0; ch < count; ++ch) {
        rows(ch, K, out);
        for (int l = 0; l < L && l < n; ++l)  // n <= L; the first bound lets GCC see it
          if (!(skip >> l & 1u)) std::memcpy(g.sh_row(ids[l], first + ch), out[l], sizeof out[l]);
      }
    }
  };

  RasterTimings timings_;
  // Settings of the last forward.
  int first_ = 0, count_ = 0, sh_degree_ = 0;
  std::vector<S> background_;          // [count]
  ProjectCamera pcam_{};
  TileGrid grid_;
  const Model* model_ = nullptr;
  bool has_forward_ = false;

  // Projection results.
  std::vector<Splat<S>> splats_;       // [N]
  std::vector<S> colours_;             // [N, count]
  std::vector<S> depth_;               // [N]
  std::vector<PixelRect> rects_;       // [N]
  std::vector<std::int32_t> radii_;    // [N, 2]
  std::vector<std::uint8_t> visible_flag_;  // [N]
  std::vector<std::uint32_t> visible_; // [V] ascending
  std::vector<std::size_t> visible_offset_;  // [chunks + 1] scratch of project_all
  Binning bins_;

  // Blend results.
  Image<S> image_, alpha_, depth_image_;
  std::vector<S> transmittance_;       // [H, W]
  std::vector<std::uint32_t> last_;    // [H, W]
  detail::OverwriteVector<std::uint16_t> block_mask_;  // [M] tile blocks each intersection blended into
  std::uint64_t fragments_ = 0, blend_lanes_ = 0;
  std::vector<int> tile_order_;        // [tiles] the blend passes' order (order_tiles)
  detail::OverwriteVector<S> records_;  // [M, BlendRecord<depth, absgrad>::size(count)] in pair order (Binning::pair)
  detail::OverwriteVector<std::uint8_t> blended_;  // [M] in pair order: 1 where the pair blended (its record is written)
  std::vector<S> bg_partial_;          // [tiles, count]
};

}  // namespace msgs
