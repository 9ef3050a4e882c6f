// include/msgs/adam.hpp
// Adam over a GaussianModel with per-group learning rates, per-group/per-channel step counters and update masks.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "msgs/colour_gradient_sink.hpp"
#include "msgs/gaussian.hpp"

namespace msgs {

/// Hyper-parameters of the Gaussian optimiser; defaults are those of the multi-spectral
/// implementation (REFERENCE §3).
struct AdamConfig {
  double lr_means = 1.6e-4;          ///< position lr at step 0 (times scene_scale)
  double lr_means_final = 1.6e-6;    ///< position lr reached at step lr_means_steps (times scene_scale)
  std::int64_t lr_means_steps = 30000;  ///< T of the exponential decay: the length of the run
  double scene_scale = 1.0;          ///< positions live in scene units; the position lr scales with them
  double lr_sh_dc = 2.5e-3;          ///< SH coefficient 0 of every channel
  double lr_sh_rest = 1.25e-4;       ///< SH coefficients 1.. of every channel
  double lr_opacities = 0.05;
  double lr_scales = 5e-3;
  double lr_quats = 1e-3;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-15;  ///< 3DGS uses 1e-15 instead of torch's 1e-8: gradients here are tiny
};

/// Which parameters one `Adam::step` updates. SH updates are restricted to the colour channels
/// [sh_first, sh_first + sh_count) — the band that was rendered this step.
struct AdamMask {
  bool means = true;
  bool scales = true;
  bool quats = true;
  bool opacities = true;
  bool sh = true;
  int sh_first = 0;   ///< first colour channel whose SH updates
  int sh_count = -1;  ///< number of channels; -1 means all channels from sh_first on

  /// The number of SH channels the mask updates in a model of `bands` channels (sh_count resolved).
  int sh_channels(int bands) const { return sh_count < 0 ? bands - sh_first : sh_count; }

  /// Everything, all channels.
  static AdamMask all() { return {}; }
  /// Colour (SH) of channels [first, first + count) only; geometry and opacity frozen.
  static AdamMask colour_only(int first, int count) {
    AdamMask m;
    m.means = m.scales = m.quats = m.opacities = false;
    m.sh_first = first;
    m.sh_count = count;
    return m;
  }
  /// All groups, SH of channels [first, first + count) only.
  static AdamMask band(int first, int count) {
    AdamMask m;
    m.sh_first = first;
    m.sh_count = count;
    return m;
  }
};

/// What Adam::step does with the rows a row list leaves out.
enum class Unlisted {
  untouched,      ///< sparse Adam: parameters and moments stay as they are
  zero_gradient,  ///< dense Adam: they take the update of a zero gradient (moments decay, parameters coast)
};

/// Adam over the parameters of a `GaussianModel<G, S>`.
///
/// The moments are two models of the same layout as the parameters (`exp_avg`, `exp_avg_sq`), so
/// densification gathers and appends their rows exactly like the model's (zeros for new Gaussians).
///
/// Masking: a group masked off in a step, and every SH channel outside the step's band range, gets
/// NO update at all: its parameters and both moments stay bit-identical and its step counter does not
/// advance. This differs from torch Adam with zeroed gradients (which keeps moving parameters on
/// stale momentum and decays the moments): in a Joint model a band is rendered only every few steps,
/// and momentum drift on the bands not seen would move their colours without evidence. Each group
/// (means, scales, quats, opacities) keeps its own step counter and SH keeps one per colour channel
/// (shared by the DC and higher-order coefficients of that channel, which always update together),
/// so the bias correction of a band reflects how many times that band has actually been updated.
///
/// The position learning rate follows lr(t) = lr0 (lr1 / lr0)^(t / T), t = `iteration` (the number of
/// `step` calls so far, i.e. the training step, whether or not the means were updated), clamped at T.
template <class G, class S = float>
class Adam {
 public:
  /// Per-group bias-correction step counters.
  struct Steps {
    std::int64_t means = 0, scales = 0, quats = 0, opacities = 0;
    std::array<std::int64_t, G::bands> sh{};  ///< one per colour channel
  };

  AdamConfig config;
  GaussianModel<G, S> exp_avg;     ///< first moments, layout of the model
  GaussianModel<G, S> exp_avg_sq;  ///< second moments, layout of the model
  Steps steps;                     ///< updates applied to each group / SH channel so far
  std::int64_t iteration = 0;      ///< step() calls so far; drives the position lr schedule

  explicit Adam(const AdamConfig& cfg = {}, std::size_t n = 0) : config(cfg) { reset(n); }

  /// Zero state for `n` Gaussians; counters and iteration back to 0.
  void reset(std::size_t n) {
    exp_avg = GaussianModel<G, S>(n);
    exp_avg_sq = GaussianModel<G, S>(n);
    steps = Steps{};
    iteration = 0;
  }

  /// Position learning rate at training step `t`, scene scale included.
  double lr_means_at(std::int64_t t) const {
    const double lr0 = config.lr_means, lr1 = config.lr_means_final;
    if (config.lr_means_steps <= 0 || lr0 <= 0 || lr1 <= 0) return lr0 * config.scene_scale;
    const double f = std::clamp(static_cast<double>(t) / static_cast<double>(config.lr_means_steps), 0.0, 1.0);
    return std::exp(std::log(lr0) * (1.0 - f) + std::log(lr1) * f) * config.scene_scale;
  }

  /// One Adam step: `params -= lr * m_hat / (sqrt(v_hat) + eps)` for the groups and SH channels in
  /// `mask`, using `grad` (same layout). Advances `iteration` by one.
  ///
  /// `rows`: nullptr updates every Gaussian (dense Adam, torch's behaviour: a Gaussian the view did
  /// not see has a zero gradient and still moves on its momentum). A list of ascending Gaussian
  /// indices updates those rows only and reads `grad` only there (sparse or "selective" Adam, as
  /// Taming 3DGS and gsplat's sparse gradients: unseen Gaussians and their moments stay exactly as
  /// they are); the trainer passes the Gaussians the view saw, so the step costs what they cost.
  /// With `unlisted` = Unlisted::zero_gradient the other rows take the update of a zero gradient
  /// without `grad` being read there: dense Adam, bit for bit, over a gradient buffer whose rows
  /// outside `rows` were never written (GradientFill::visible), so neither the zeroing pass nor
  /// Adam's reads of those zeros cost anything.
  /// The step counters advance per group either way.
  void step(GaussianModel<G, S>& params, const GaussianModel<G, S>& grad, const AdamMask& mask = {},
            const std::vector<std::uint32_t>* rows = nullptr, Unlisted unlisted = Unlisted::untouched) {
    check_sizes(params, grad);
    const int first = mask.sh_first, count = mask.sh_channels(G::bands);
    if (mask.sh && (first < 0 || count < 0 || first + count > G::bands))
      throw std::invalid_argument("Adam::step: mask SH channel range [" + std::to_string(first) + ", " +
                                  std::to_string(first + count) + ") is outside [0, " + std::to_string(G::bands) +
                                  ")");
    if (rows && !ascending_below(*rows, params.size()))
      throw std::invalid_argument("Adam::step: rows must be ascending indices below " + std::to_string(params.size()));
    const std::int64_t t = iteration++;
    if (mask.means)
      update_group<3>(params.means, grad.means, exp_avg.means, exp_avg_sq.means, lr_means_at(t), ++steps.means, rows,
                      unlisted);
    if (mask.scales)
      update_group<3>(params.log_scales, grad.log_scales, exp_avg.log_scales, exp_avg_sq.log_scales, config.lr_scales,
                      ++steps.scales, rows, unlisted);
    if (mask.quats)
      update_group<4>(params.quats, grad.quats, exp_avg.quats, exp_avg_sq.quats, config.lr_quats, ++steps.quats, rows,
                      unlisted);
    if (mask.opacities)
      update_group<1>(params.opacity_logits, grad.opacity_logits, exp_avg.opacity_logits, exp_avg_sq.opacity_logits,
                      config.lr_opacities, ++steps.opacities, rows, unlisted);
    if (mask.sh && count > 0) update_sh(params, grad, first, count, rows, unlisted);
  }

 private:
  /// Whether `rows` are strictly ascending and below `n`: in parallel (a training step checks the
  /// visible Gaussians' list, tens of thousands of rows, every step; serially that was the second
  /// thread's idle time).
  static bool ascending_below(const std::vector<std::uint32_t>& rows, std::size_t n) {
    const std::ptrdiff_t m = static_cast<std::ptrdiff_t>(rows.size());
    const std::uint32_t* r = rows.data();
    bool ok = true;
#pragma omp parallel for schedule(static) reduction(&& : ok) if (m > 16384)
    for (std::ptrdiff_t j = 0; j < m; ++j) ok = ok & (r[j] < n) & (j == 0 || r[j] > r[j - 1]);
    return ok;
  }

  struct Coeffs {
    S step_size;     // lr / (1 - beta1^t)
    S inv_bc2_sqrt;  // 1 / sqrt(1 - beta2^t)
  };

  /// Hyper-parameters of the element update, in the scalar type.
  struct Betas {
    S b1c, b2, b2c, eps;
  };

 public:
  /// The colour (SH) half of one step, for a backward that hands over each visible Gaussian's
  /// colour gradient as soon as it is known (Rasterizer::backward with this as its sink): then
  /// the gradient is never stored and read back, and a row is updated while the backward still
  /// has it in cache. `begin_colour` advances the channels' step counters; `apply` updates one row
  /// of one channel from its gradient, what `step` does to a listed row; `finish_colour` then
  /// updates the rows not listed, as `step` does. Together with `step` under a mask without SH,
  /// the same bits as one `step`. The step holds pointers into the model and the moments: it is
  /// valid until either changes size.
  class ColourStep final : public ColourGradientSink<S> {
   public:
    /// The rasteriser's hand-over: `apply` to each lane's row.
    void consume(const std::uint32_t* ids, int n, std::uint32_t skip, int channel, const S* rows,
                 std::size_t stride) override {
      for (int l = 0; l < n; ++l)
        if (!(skip >> l & 1u)) apply(ids[l], channel, rows + std::size_t(l) * stride);
    }
    void prefetch(const std::uint32_t* ids, int n, int first, int count) const override {
      for (int c = first; c < first + count; ++c)
        for (int l = 0; l < n; ++l) prefetch(ids[l], c);
    }
    /// Update the K coefficients of channel `channel` of Gaussian `row` from their gradient `g`.
    void apply(std::size_t row, int channel, const S* g) const {
      const Channel& c = channels_[static_cast<std::size_t>(channel - first_)];
      const std::size_t o = row * std::size_t(K);
      update_rows<K>(c.p + o, c.m + o, c.v + o, g, 1, betas_, c.step_size.data(), c.inv.data());
    }
    /// Fetch the moments' rows of channel `channel` of Gaussian `row` into the cache.
    void prefetch(std::size_t row, int channel) const {
      const Channel& c = channels_[static_cast<std::size_t>(channel - first_)];
      const std::size_t o = row * std::size_t(K);
      for (const S* a : {c.m + o, c.v + o}) {
        __builtin_prefetch(a, 1);
        __builtin_prefetch(a + K - 1, 1);
      }
    }

   private:
    friend class Adam;
    static constexpr int K = G::sh_coeffs;
    struct Channel {
      S* p = nullptr;
      S* m = nullptr;
      S* v = nullptr;
      std::array<S, K> step_size{}, inv{};  // per coefficient: the DC coefficient has its own lr
    };
    std::array<Channel, G::bands> channels_{};
    int first_ = 0, count_ = 0;
    std::size_t rows_ = 0;
    Betas betas_{};
  };

  /// Start the colour half of a step on channels [first, first + count) of `params` (advances
  /// their step counters). Call `step` (with mask.sh = false) for the geometry as usual.
  ColourStep begin_colour(GaussianModel<G, S>& params, int first, int count) {
    if (first < 0 || count < 0 || first + count > G::bands)
      throw std::invalid_argument("Adam::begin_colour: channel range [" + std::to_string(first) + ", " +
                                  std::to_string(first + count) + ") is outside [0, " + std::to_string(G::bands) + ")");
    params.check_consistent();
    if (exp_avg.size() != params.size() || exp_avg_sq.size() != params.size())
      throw std::invalid_argument("Adam::begin_colour: the moments hold " + std::to_string(exp_avg.size()) +
                                  " Gaussians, the model " + std::to_string(params.size()) +
                                  " (densification must resize the optimiser state with the model)");
    ColourStep cs;
    cs.first_ = first;
    cs.count_ = count;
    cs.rows_ = params.size();
    cs.betas_ = betas();
    for (int c = first; c < first + count; ++c) {
      const std::int64_t t = ++steps.sh[static_cast<std::size_t>(c)];
      const Coeffs dc = coeffs(config.lr_sh_dc, t), rest = coeffs(config.lr_sh_rest, t);
      auto& ch = cs.channels_[static_cast<std::size_t>(c - first)];
      ch.step_size.fill(rest.step_size);
      ch.inv.fill(rest.inv_bc2_sqrt);
      ch.step_size[0] = dc.step_size;
      ch.inv[0] = dc.inv_bc2_sqrt;
      ch.p = params.sh_row(0, c);  // each array's own plane stride (their capacities may differ)
      ch.m = exp_avg.sh_row(0, c);
      ch.v = exp_avg_sq.sh_row(0, c);
    }
    return cs;
  }

  /// Finish the colour half: the rows not in `rows` (ascending) take the update of a zero
  /// gradient (Unlisted::zero_gradient, dense Adam) or stay as they are (Unlisted::untouched).
  /// Every row in `rows` must have been `apply`d, once per channel.
  void finish_colour(const ColourStep& cs, const std::vector<std::uint32_t>& rows, Unlisted unlisted) const {
    if (unlisted == Unlisted::untouched) return;
    constexpr int K = G::sh_coeffs;
    for (int i = 0; i < cs.count_; ++i) {
      const auto& ch = cs.channels_[static_cast<std::size_t>(i)];
      for_each_run<true>(cs.rows_, &rows, unlisted, [&](std::size_t row, std::size_t n, bool listed) {
        if (listed) return;
        const std::size_t o = row * K;
        update_rows<K, true>(ch.p + o, ch.m + o, ch.v + o, nullptr, n, cs.betas_, ch.step_size.data(), ch.inv.data());
      });
    }
  }

 private:
  Betas betas() const {
    return {static_cast<S>(1.0 - config.beta1), static_cast<S>(config.beta2), static_cast<S>(1.0 - config.beta2),
            static_cast<S>(config.eps)};
  }

  Coeffs coeffs(double lr, std::int64_t t) const {
    const double bc1 = 1.0 - std::pow(config.beta1, static_cast<double>(t));
    const double bc2 = 1.0 - std::pow(config.beta2, static_cast<double>(t));
    return {static_cast<S>(lr / bc1), static_cast<S>(1.0 / std::sqrt(bc2))};
  }

  /// The torch.optim.Adam element update (lerp form of the first moment) over `n` consecutive
  /// values. Restrict pointers let the compiler vectorise it (given -fno-math-errno for the square
  /// root); every value is independent, so vector and scalar code give the same bits. With
  /// `ZeroGrad` the gradient is 0 and `g` is not read: the same expressions, so the same bits as
  /// over a buffer of zeros.
  template <bool ZeroGrad = false>
  static void update_run(S* __restrict p, S* __restrict m, S* __restrict v, const S* __restrict g, std::size_t n,
                         const Betas b, const Coeffs k) {
    for (std::size_t a = 0; a < n; ++a) {
      const S ga = ZeroGrad ? S(0) : g[a];
      const S ma = m[a] + b.b1c * (ga - m[a]);
      const S va = b.b2 * v[a] + b.b2c * ga * ga;
      m[a] = ma;
      v[a] = va;
      p[a] -= k.step_size * ma / (std::sqrt(va) * k.inv_bc2_sqrt + b.eps);
    }
  }

  /// The same over `rows` consecutive rows of K values with per-coefficient step sizes (the SH
  /// DC coefficient has its own learning rate); the fixed inner length vectorises.
  template <int K, bool ZeroGrad = false>
  static void update_rows(S* __restrict p, S* __restrict m, S* __restrict v, const S* __restrict g, std::size_t rows,
                          const Betas b, const S* __restrict step_size, const S* __restrict inv_bc2_sqrt) {
    for (std::size_t r = 0; r < rows; ++r, p += K, m += K, v += K) {
      for (int a = 0; a < K; ++a) {
        const S ga = ZeroGrad ? S(0) : g[a];
        const S ma = m[a] + b.b1c * (ga - m[a]);
        const S va = b.b2 * v[a] + b.b2c * ga * ga;
        m[a] = ma;
        v[a] = va;
        p[a] -= step_size[a] * ma / (std::sqrt(va) * inv_bc2_sqrt[a] + b.eps);
      }
      if constexpr (!ZeroGrad) g += K;
    }
  }

  /// Rows per work unit of the updates over listed rows (for_each_run, update_group).
  static constexpr std::ptrdiff_t kRunChunk = 2048;

  /// f(r0, r1, lo, hi) for the fixed chunks [r0, r1) of the rows [0, n), with [lo, hi) the rows of
  /// `rows` (ascending) inside the chunk; in parallel, in two static halves (each core streams its
  /// half in order), or with `Dynamic` a chunk at a time.
  template <bool Dynamic, class F>
  static void for_each_chunk(std::size_t n, const std::vector<std::uint32_t>& rows, F&& f) {
    const std::ptrdiff_t chunks = (static_cast<std::ptrdiff_t>(n) + kRunChunk - 1) / kRunChunk;
    const std::uint32_t* const end = rows.data() + rows.size();
    const auto chunk = [&](std::ptrdiff_t c) {
      const std::size_t r0 = std::size_t(c * kRunChunk), r1 = std::min(n, std::size_t((c + 1) * kRunChunk));
      const std::uint32_t* lo = std::lower_bound(rows.data(), end, std::uint32_t(r0));
      f(r0, r1, lo, std::lower_bound(lo, end, std::uint32_t(r1)));
    };
    if constexpr (Dynamic) {
#pragma omp parallel for schedule(dynamic, 1)
      for (std::ptrdiff_t c = 0; c < chunks; ++c) chunk(c);
    } else {
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t c = 0; c < chunks; ++c) chunk(c);
    }
  }

  /// f(first_row, row_count, listed) for the runs of the listed rows [lo, hi) (ascending, inside
  /// [r0, r1)) and the runs between them, which together cover [r0, r1) in order.
  template <class F>
  static void for_each_run_in(std::size_t r0, std::size_t r1, const std::uint32_t* lo, const std::uint32_t* hi, F&& f) {
    std::size_t r = r0;
    while (r < r1) {
      if (lo != hi && *lo == r) {  // a run of listed rows
        std::size_t e = r + 1;
        ++lo;
        while (lo != hi && *lo == e) ++e, ++lo;
        f(r, e - r, true);
        r = e;
      } else {  // up to the next listed row or the chunk's end
        const std::size_t e = lo != hi ? std::size_t(*lo) : r1;
        f(r, e - r, false);
        r = e;
      }
    }
  }

  /// Call f(first_row, row_count, listed) for runs of consecutive rows: every row [0, n) as
  /// listed, or the listed ones (ascending), in parallel over fixed chunks of the list
  /// (consecutive visible Gaussians then form long runs, which vectorise like the dense update);
  /// with Unlisted::zero_gradient also the runs between them, as not listed, in parallel over
  /// fixed chunks of rows (for_each_chunk): in two static halves, or with `Dynamic` a chunk at a
  /// time, for a caller that skips the listed runs (finish_colour): visible rows cluster in the
  /// spatial order, so the halves would not be equal work. Every row is independent: the schedule
  /// does not change a bit.
  template <bool Dynamic = false, class F>
  static void for_each_run(std::size_t n, const std::vector<std::uint32_t>* rows, Unlisted unlisted, F&& f) {
    if (rows && unlisted == Unlisted::zero_gradient) {
      for_each_chunk<Dynamic>(n, *rows, [&](std::size_t r0, std::size_t r1, const std::uint32_t* lo, const std::uint32_t* hi) {
        for_each_run_in(r0, r1, lo, hi, f);
      });
      return;
    }
    const std::ptrdiff_t total = static_cast<std::ptrdiff_t>(rows ? rows->size() : n);
    const std::ptrdiff_t chunks = (total + kRunChunk - 1) / kRunChunk;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t c = 0; c < chunks; ++c) {
      const std::ptrdiff_t j1 = std::min(total, (c + 1) * kRunChunk);
      if (!rows) {
        f(std::size_t(c * kRunChunk), std::size_t(j1 - c * kRunChunk), true);
        continue;
      }
      const std::uint32_t* r = rows->data();
      for (std::ptrdiff_t j = c * kRunChunk; j < j1;) {
        std::ptrdiff_t e = j + 1;
        while (e < j1 && r[e] == r[e - 1] + 1) ++e;
        f(std::size_t(r[j]), std::size_t(e - j), true);
        j = e;
      }
    }
  }

  /// A chunk whose listed runs repeat more often than every this many rows on average is updated
  /// as one run over a copy of its gradient with zeros in the unlisted rows (update_group).
  static constexpr std::size_t kShortRunRows = 32;

  /// Update `W` consecutive values per row: every row, or the listed ones. With
  /// Unlisted::zero_gradient a chunk whose seen and unseen rows alternate in short runs (rows
  /// that densification filled since the last spatial sort, or a view that sees every other row)
  /// is not updated run by run: runs of one to a few rows of 1 to 4 values each leave the loop
  /// little to vectorise. The chunk's listed gradient rows are copied into a buffer of zeros and
  /// the whole chunk is updated as one listed run: the unlisted rows then take the update of a
  /// gradient of +0, the same expressions as the ZeroGrad update, so the same bits, and their
  /// gradient rows are still not read.
  template <int W>
  void update_group(std::vector<S>& p, const std::vector<S>& g, std::vector<S>& m, std::vector<S>& v, double lr,
                    std::int64_t t, const std::vector<std::uint32_t>* rows, Unlisted unlisted) const {
    const Coeffs k = coeffs(lr, t);
    const Betas b = betas();
    S* pp = p.data();
    S* mp = m.data();
    S* vp = v.data();
    const S* gp = g.data();
    const auto run = [&](std::size_t row, std::size_t count, bool listed) {
      const std::size_t o = row * W;
      if (listed) update_run(pp + o, mp + o, vp + o, gp + o, count * W, b, k);
      else update_run<true>(pp + o, mp + o, vp + o, nullptr, count * W, b, k);
    };
    if (!(rows && unlisted == Unlisted::zero_gradient)) {
      for_each_run(p.size() / W, rows, unlisted, run);
      return;
    }
    for_each_chunk<false>(p.size() / W, *rows, [&](std::size_t r0, std::size_t r1, const std::uint32_t* lo, const std::uint32_t* hi) {
      const std::size_t listed = std::size_t(hi - lo), n = r1 - r0;
      std::size_t runs = 0;
      for (const std::uint32_t* it = lo; it != hi; ++it) runs += (it == lo || *it != it[-1] + 1) ? 1 : 0;
      if (listed == 0 || listed == n || runs * kShortRunRows <= n) {
        for_each_run_in(r0, r1, lo, hi, run);
        return;
      }
      alignas(64) S buf[kRunChunk * W];
      std::fill_n(buf, n * W, S(0));
      for (const std::uint32_t* it = lo; it != hi; ++it)
        std::copy_n(gp + std::size_t(*it) * W, W, buf + (std::size_t(*it) - r0) * W);
      update_run(pp + r0 * W, mp + r0 * W, vp + r0 * W, buf, n * W, b, k);
    });
  }

  /// SH of channels [first, first + count): one band plane at a time, the DC coefficient with its
  /// own learning rate (the coefficients of ColourStep).
  void update_sh(GaussianModel<G, S>& params, const GaussianModel<G, S>& grad, int first, int count,
                 const std::vector<std::uint32_t>* rows, Unlisted unlisted) {
    constexpr int K = G::sh_coeffs;
    const ColourStep cs = begin_colour(params, first, count);
    for (int i = 0; i < count; ++i) {
      const auto& ch = cs.channels_[static_cast<std::size_t>(i)];
      const S* g = grad.sh_row(0, first + i);
      for_each_run(params.size(), rows, unlisted, [&](std::size_t row, std::size_t n, bool listed) {
        const std::size_t o = row * K;
        if (listed) update_rows<K>(ch.p + o, ch.m + o, ch.v + o, g + o, n, cs.betas_, ch.step_size.data(), ch.inv.data());
        else update_rows<K, true>(ch.p + o, ch.m + o, ch.v + o, nullptr, n, cs.betas_, ch.step_size.data(), ch.inv.data());
      });
    }
  }

  void check_sizes(const GaussianModel<G, S>& params, const GaussianModel<G, S>& grad) const {
    params.check_consistent();
    const std::size_t n = params.size();
    const auto check = [n](const GaussianModel<G, S>& m, const char* name) {
      m.check_consistent();
      if (m.size() != n)
        throw std::invalid_argument(std::string("Adam::step: ") + name + " holds " + std::to_string(m.size()) +
                                    " Gaussians, the model " + std::to_string(n) +
                                    " (densification must resize the optimiser state with the model)");
    };
    check(grad, "gradient");
    check(exp_avg, "exp_avg");
    check(exp_avg_sq, "exp_avg_sq");
  }
};

}  // namespace msgs
