// include/msgs/schedule.hpp
// Training schedules as pure functions of the step (SH growth, warm-up, resolution, learning rate,
// backgrounds, round-robin band sampling) so that a resumed run replays exactly the same choices.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace msgs {

namespace detail {

/// SplitMix64 finaliser: a bijective 64-bit mix. Schedules and densification draw their random
/// numbers from hashes of (seed, step, index, ...) rather than from a stateful generator, so that
/// any step can be replayed without replaying the steps before it. The standard library
/// distributions are implementation-defined, hence everything is written out.
constexpr std::uint64_t sched_mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

/// Hash of a tuple of integers (seed, a, b, ...).
template <class... Ts>
constexpr std::uint64_t sched_hash(std::uint64_t seed, Ts... vs) {
  std::uint64_t h = sched_mix(seed);
  ((h = sched_mix(h ^ sched_mix(static_cast<std::uint64_t>(vs) + 0x632be59bd9b4e019ULL))), ...);
  return h;
}

/// Uniform double in [0, 1) from the top 53 bits of a hash.
constexpr double sched_uniform(std::uint64_t h) { return double(h >> 11) * (1.0 / 9007199254740992.0); }

/// Standard normal from two hashes by Box-Muller (cosine branch only: simple beats fast here).
inline double sched_normal(std::uint64_t h1, std::uint64_t h2) {
  const double u1 = 1.0 - sched_uniform(h1);  // (0, 1], keeps the log finite
  const double u2 = sched_uniform(h2);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
}

}  // namespace detail

/// One factor that multiplies every iteration count of a run, so that a short run keeps the shape
/// of the long one: 0.05 turns the 120k-step Joint schedule into 6k steps (refine every 15,
/// SH degree every 250, ...). Counts are rounded to the nearest integer; a positive count never
/// becomes 0 (a period of 0 would divide by zero), and 0 stays 0 (a disabled window stays disabled).
struct ScheduleScale {
  double factor = 1.0;

  /// Throw std::invalid_argument unless the factor is finite and > 0.
  void validate() const {
    if (!(std::isfinite(factor) && factor > 0.0))
      throw std::invalid_argument("ScheduleScale: factor must be finite and > 0, got " + std::to_string(factor));
  }

  /// `steps` scaled by the factor.
  int operator()(int steps) const {
    validate();
    if (steps == 0) return 0;
    const double v = std::round(double(steps) * factor);
    if (v > double(std::numeric_limits<int>::max()) || v < double(std::numeric_limits<int>::min())) {
      std::ostringstream os;  // %g-style: a factor of 1e300 is not printed as 301 digits
      os << "ScheduleScale: " << steps << " steps x " << factor << " is more steps than an int holds (at most "
         << std::numeric_limits<int>::max() << "); a factor up to "
         << double(std::numeric_limits<int>::max()) / std::abs(double(steps)) << " fits";
      throw std::invalid_argument(os.str());
    }
    const int r = static_cast<int>(v);
    if (steps > 0 && r < 1) return 1;
    return r;
  }
};

/// Active SH degree at `step`: one degree more every `every` steps, capped at `max_degree`
/// (splatfacto's min(step // interval, degree)). `every` <= 0 means the full degree from the start.
constexpr int sh_degree_at(long long step, int max_degree, int every = 5000) {
  if (every <= 0) return max_degree;
  if (step < 0) return 0;
  const long long d = step / every;
  return d < max_degree ? static_cast<int>(d) : max_degree;
}

/// Colour-only warm-up: positions, scales and rotations get no update while `step < warmup`
/// (steps 0 .. warmup-1 are frozen).
constexpr bool geometry_frozen_at(long long step, int warmup = 500) { return step < warmup; }

/// Training-image downscale factor at `step`: 2^max(num_downscales - step / every, 0), i.e. with the
/// defaults 4 until step 3000, 2 until 6000, then 1 (splatfacto's resolution schedule).
constexpr int downscale_at(long long step, int every = 3000, int num_downscales = 2) {
  if (every <= 0 || num_downscales <= 0) return 1;
  if (step < 0) step = 0;
  const long long level = num_downscales - step / every;
  return level > 0 ? (1 << level) : 1;
}

/// Exponential learning-rate decay: log-linear from `lr_init` at step 0 to `lr_final` at
/// `max_steps`, constant afterwards (nerfstudio's ExponentialDecayScheduler without warm-up).
struct ExponentialDecay {
  double lr_init = 1.6e-4;
  double lr_final = 1.6e-6;
  int max_steps = 120000;

  /// Learning rate at `step`.
  double operator()(long long step) const {
    if (!(lr_init > 0.0) || !(lr_final > 0.0))
      throw std::invalid_argument("ExponentialDecay: lr_init and lr_final must be > 0");
    if (max_steps <= 0) return lr_final;
    double t = double(step) / double(max_steps);
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    return std::exp(std::log(lr_init) * (1.0 - t) + std::log(lr_final) * t);
  }

  /// The same decay over a scaled run.
  ExponentialDecay scaled(const ScheduleScale& s) const { return {lr_init, lr_final, s(max_steps)}; }
};

/// The step-indexed schedules of a training run (REFERENCE §3), all iteration counts in one place
/// so that `scaled()` shortens every one of them together.
struct TrainSchedule {
  int total_steps = 120000;   ///< length of the run
  int sh_degree_every = 5000; ///< one more SH degree every this many steps
  int warmup_steps = 500;     ///< colour-only warm-up: geometry frozen for steps < this
  int resolution_every = 3000;///< the downscale factor halves every this many steps
  int num_downscales = 2;     ///< initial downscale 2^num_downscales (not an iteration count)

  /// Every iteration count multiplied by `s`.
  TrainSchedule scaled(const ScheduleScale& s) const {
    TrainSchedule r = *this;
    r.total_steps = s(total_steps);
    r.sh_degree_every = s(sh_degree_every);
    r.warmup_steps = s(warmup_steps);
    r.resolution_every = s(resolution_every);
    return r;
  }
  /// Active SH degree at `step` for a model of degree `max_degree`.
  int sh_degree(long long step, int max_degree) const { return sh_degree_at(step, max_degree, sh_degree_every); }
  /// Whether positions, scales and rotations are frozen at `step`.
  bool geometry_frozen(long long step) const { return geometry_frozen_at(step, warmup_steps); }
  /// Training-image downscale factor at `step`.
  int downscale(long long step) const { return downscale_at(step, resolution_every, num_downscales); }
};

/// Random training background for `step`: `channels` values uniform in [0, 1), a pure function
/// of (seed, step, channel) so a resumed run draws the same colours.
template <class S = float>
std::vector<S> random_background(long long step, int channels, std::uint64_t seed = 0) {
  if (channels < 0) throw std::invalid_argument("random_background: channels must be >= 0");
  std::vector<S> bg(static_cast<std::size_t>(channels));
  for (int c = 0; c < channels; ++c)
    bg[static_cast<std::size_t>(c)] =
        static_cast<S>(detail::sched_uniform(detail::sched_hash(seed, 0xB6ULL, step, c)));
  return bg;
}

/// Evaluation background of the RGB band: splatfacto's grey, torch.tensor([0.1490, 0.1647, 0.2157]).
inline constexpr double eval_background_rgb[3] = {0.1490, 0.1647, 0.2157};
/// Luminance weights used to turn an RGB background into a single-channel one: ITU-R BT.601
/// (0.299, 0.587, 0.114), the weights of PIL's convert("L") and torchvision's rgb_to_grayscale.
inline constexpr double luminance_weights[3] = {0.299, 0.587, 0.114};
/// The evaluation background of a 1-channel band: BT.601 luminance of the grey, about 0.16581.
inline constexpr double eval_background_luminance =
    luminance_weights[0] * eval_background_rgb[0] + luminance_weights[1] * eval_background_rgb[1] +
    luminance_weights[2] * eval_background_rgb[2];

/// Evaluation background for a band with `channels` channels: the grey for 3, its luminance for 1.
template <class S = float>
std::vector<S> eval_background(int channels) {
  if (channels == 3)
    return {S(eval_background_rgb[0]), S(eval_background_rgb[1]), S(eval_background_rgb[2])};
  if (channels == 1) return {S(eval_background_luminance)};
  throw std::invalid_argument("eval_background: a band has 1 or 3 channels, got " + std::to_string(channels));
}

/// How a band's image list is ordered over a long run.
enum class Shuffle {
  once,        ///< shuffled once with the seed, then repeated (msgs before 2026-11)
  every_pass,  ///< reshuffled every time it is used up, as the reference implementation
};

/// Round-robin band sampling (REFERENCE §3 and §9). Each band's image list is shuffled with a fixed
/// seed; the B lists are interleaved so that step t renders band t mod B, with draw k = t div B of
/// that band.
/// - Shuffle::once: shorter lists are repeated (cyclically) to the length L of the longest and draw
///   k takes entry k mod L; the sequence repeats with period B * L.
/// - Shuffle::every_pass (the reference implementation): band b's list of n_b images is reshuffled
///   each time it is used up, so draw k takes entry k mod n_b of the pass k div n_b's own order.
///   The first pass equals Shuffle::once's order.
/// Everything is a function of t, so resuming at any step continues the same sequence.
class BandSampler {
 public:
  /// One draw: the band (index into the lists given to the constructor) and the image id (an
  /// element of that band's list).
  struct Draw {
    int band = 0;
    int image = 0;
    bool operator==(const Draw&) const = default;
  };

  BandSampler() = default;

  /// `band_images[b]` lists the image ids of band b (for example indices into the train split).
  explicit BandSampler(std::vector<std::vector<int>> band_images, std::uint64_t seed = 42, Shuffle mode = Shuffle::once)
      : seed_(seed), mode_(mode) {
    if (band_images.empty()) throw std::invalid_argument("BandSampler: need at least one band");
    std::size_t longest = 0;
    for (std::size_t b = 0; b < band_images.size(); ++b) {
      if (band_images[b].empty())
        throw std::invalid_argument("BandSampler: band " + std::to_string(b) + " has no images");
      longest = std::max(longest, band_images[b].size());
    }
    order_.resize(band_images.size());
    lists_.resize(band_images.size());
    for (std::size_t b = 0; b < band_images.size(); ++b) {
      lists_[b] = std::move(band_images[b]);
      const std::vector<int> list = shuffled(b, 0);
      auto& out = order_[b];
      out.resize(longest);
      for (std::size_t k = 0; k < longest; ++k) out[k] = list[k % list.size()];
    }
  }

  /// Sampler over images 0 .. counts[b]-1 of each band.
  static BandSampler from_counts(const std::vector<int>& counts, std::uint64_t seed = 42, Shuffle mode = Shuffle::once) {
    std::vector<std::vector<int>> lists(counts.size());
    for (std::size_t b = 0; b < counts.size(); ++b) {
      if (counts[b] < 0) throw std::invalid_argument("BandSampler: negative image count for band " + std::to_string(b));
      lists[b].resize(static_cast<std::size_t>(counts[b]));
      for (int i = 0; i < counts[b]; ++i) lists[b][static_cast<std::size_t>(i)] = i;
    }
    return BandSampler(std::move(lists), seed, mode);
  }

  /// Number of bands.
  int num_bands() const { return static_cast<int>(order_.size()); }
  /// Length of every band's (repeated) list.
  std::size_t list_length() const { return order_.empty() ? 0 : order_[0].size(); }
  /// Steps after which the sequence repeats (Shuffle::once): bands x list length.
  long long period() const { return static_cast<long long>(order_.size() * list_length()); }
  Shuffle mode() const { return mode_; }

  /// The (band, image) that step `step` renders.
  Draw at(long long step) const {
    if (order_.empty()) throw std::logic_error("BandSampler::at: sampler has no bands");
    if (step < 0) throw std::invalid_argument("BandSampler::at: step must be >= 0, got " + std::to_string(step));
    const auto nb = static_cast<long long>(order_.size());
    const auto b = static_cast<std::size_t>(step % nb);
    const long long draw = step / nb;
    if (mode_ == Shuffle::every_pass) {
      const auto n = static_cast<long long>(lists_[b].size());
      const long long pass = draw / n;
      const auto k = static_cast<std::size_t>(draw % n);
      if (pass == 0) return {static_cast<int>(b), order_[b][k]};
      return {static_cast<int>(b), shuffled(b, static_cast<std::uint64_t>(pass))[k]};
    }
    const auto k = static_cast<std::size_t>(draw % static_cast<long long>(list_length()));
    return {static_cast<int>(b), order_[b][k]};
  }

 private:
  /// Band b's list in the order of pass `pass`: Fisher-Yates driven by hashes of (seed, band,
  /// [pass,] position), portable across toolchains. Pass 0 keeps the hash of the shuffle-once order.
  std::vector<int> shuffled(std::size_t b, std::uint64_t pass) const {
    std::vector<int> list = lists_[b];
    for (std::size_t i = list.size(); i > 1; --i) {
      const std::uint64_t h = pass == 0 ? detail::sched_hash(seed_, 0x5A3ULL, b, i) : detail::sched_hash(seed_, 0x5A4ULL, b, pass, i);
      const std::size_t j = static_cast<std::size_t>(h % i);
      std::swap(list[i - 1], list[j]);
    }
    return list;
  }

  std::uint64_t seed_ = 42;
  Shuffle mode_ = Shuffle::once;
  std::vector<std::vector<int>> lists_;  // [B][n_b] image ids as given
  std::vector<std::vector<int>> order_;  // [B][L] pass-0 order, repeated to the longest list
};

}  // namespace msgs
