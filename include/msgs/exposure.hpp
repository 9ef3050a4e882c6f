// include/msgs/exposure.hpp
// Exposure compensation: a learned affine colour correction per training image (3DGS's per-image
// affine appearance, gsplat's / nerfstudio's appearance options in their simplest form). Multi-band
// drone captures vary in exposure and gain from image to image; without a correction the model
// averages them and renders bright and dark stripes. With it, the training step compares
//
//   I'_c = g_c * I_c + b_c,   g_c = exp(a_c),   c = each channel of the image's band,
//
// with the ground truth, where I is the rendered image and (a, b) belong to that training image.
//
// Choices (README material, recorded here):
//  * The gain is parametrised by its logarithm a = log g: g > 0 always, a multiplicative change of
//    exposure is an additive step in a, and g = 1 (a = 0), b = 0 is the identity start.
//    a is clamped to [-max_log_gain, max_log_gain] and b to [-max_offset, max_offset] after every
//    update, so a gain can neither vanish nor overflow (g in [0.018, 55] by default).
//  * Adam (beta 0.9 / 0.999, eps 1e-15 as the Gaussians) with its own learning rate, sparse per
//    image: a step updates only the sampled image's parameters and moments, and each image keeps
//    its own step counter for the bias correction (like the SH channels in adam.hpp). Parameter
//    gradients are summed in double and clamped to +-1e18 before the update, so the second moment
//    (float) stays finite; a non-finite gradient leaves the image's parameters untouched.
//  * Evaluation images have no learned parameters: they are rendered with the identity. The
//    colour-corrected metric (Zip-NeRF / RawNeRF evaluation) instead fits, per eval image and
//    channel, the affine a*I + b that best maps the render onto the ground truth in the least
//    squares sense (closed form, in double): see fit_affine / colour_correct.
//  * The overall scale is a gauge freedom (all gains x s, all colours / s), which nothing pins
//    down; eval renders with the identity therefore carry whatever scale the gains drifted to.
//    The colour-corrected metric is blind to it; result.json reports the learned gain range.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "image.hpp"

namespace msgs {

/// Hyper-parameters of the exposure parameters' optimiser.
struct ExposureConfig {
  double lr = 1e-3;            ///< Adam learning rate of log-gains and offsets
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-15;
  float max_log_gain = 4.0f;   ///< |log g| <= this after every update (g in [e^-4, e^4])
  float max_offset = 1.0f;     ///< |b| <= this after every update (images live in [0, 1])

  void validate() const {
    if (!(std::isfinite(lr) && lr >= 0)) throw std::invalid_argument("exposure: learning rate must be finite and >= 0, got " + std::to_string(lr));
    if (!(beta1 >= 0 && beta1 < 1 && beta2 >= 0 && beta2 < 1)) throw std::invalid_argument("exposure: Adam betas must be in [0, 1)");
    if (!(eps > 0 && std::isfinite(eps))) throw std::invalid_argument("exposure: Adam eps must be finite and > 0");
    if (!(max_log_gain > 0 && std::isfinite(max_log_gain)) || !(max_offset >= 0 && std::isfinite(max_offset)))
      throw std::invalid_argument("exposure: max_log_gain must be finite and > 0, max_offset finite and >= 0");
  }
};

/// Largest magnitude of a parameter gradient fed to Adam: its square (the second moment, a float)
/// stays finite. Adam's step is invariant to the gradient's scale, so the clamp changes nothing
/// that a finite float could represent usefully.
inline constexpr double kExposureMaxGrad = 1e18;

// ---------------------------------------------------------------------------------------------
// Forward and backward of the affine map of one image
// ---------------------------------------------------------------------------------------------

namespace detail {
template <class S>
void check_exposure_args(const char* fn, const Image<S>& img, std::size_t gains, std::size_t offsets) {
  if (img.channels < 1 || img.size() != img.pixels() * std::size_t(img.channels))
    throw std::invalid_argument(std::string(fn) + ": image has an inconsistent shape");
  if (gains != std::size_t(img.channels) || offsets != std::size_t(img.channels))
    throw std::invalid_argument(std::string(fn) + ": " + std::to_string(gains) + " log-gains and " + std::to_string(offsets) +
                                " offsets for an image of " + std::to_string(img.channels) + " channels");
}
}  // namespace detail

/// out_c = exp(log_gain_c) * in_c + offset_c for every pixel (out may not alias in).
template <class S>
void exposure_forward(const Image<S>& in, std::span<const S> log_gain, std::span<const S> offset, Image<S>& out) {
  detail::check_exposure_args("exposure_forward", in, log_gain.size(), offset.size());
  const std::size_t C = std::size_t(in.channels), P = in.pixels();
  if (C > 8) throw std::invalid_argument("exposure_forward: at most 8 channels");
  out.reshape(in.width, in.height, in.channels);
  S g[8], b[8];
  for (std::size_t c = 0; c < C; ++c) { g[c] = std::exp(log_gain[c]); b[c] = offset[c]; }
  for (std::size_t p = 0; p < P; ++p)
    for (std::size_t c = 0; c < C; ++c) out.data[p * C + c] = g[c] * in.data[p * C + c] + b[c];
}

/// Backward of exposure_forward. Given dL/d out (`d_out`), writes dL/d in = g_c * dL/d out into
/// `d_in` (may be the same image as d_out: updated in place) and sets
///   dL/d log_gain_c = g_c * sum_p in_pc * dL/d out_pc,   dL/d offset_c = sum_p dL/d out_pc,
/// summed in double in pixel order (deterministic, independent of the thread count). The image
/// gradient saturates at +-max float instead of overflowing.
template <class S>
void exposure_backward(const Image<S>& in, std::span<const S> log_gain, const Image<S>& d_out, Image<S>& d_in,
                       std::span<double> d_log_gain, std::span<double> d_offset) {
  detail::check_exposure_args("exposure_backward", in, log_gain.size(), log_gain.size());
  if (d_out.width != in.width || d_out.height != in.height || d_out.channels != in.channels || d_out.size() != in.size())
    throw std::invalid_argument("exposure_backward: d_out does not have the shape of the image");
  const std::size_t C = std::size_t(in.channels), P = in.pixels();
  if (d_log_gain.size() != C || d_offset.size() != C)
    throw std::invalid_argument("exposure_backward: parameter gradients need one value per channel");
  if (C > 8) throw std::invalid_argument("exposure_backward: at most 8 channels");
  double sum_xd[8] = {}, sum_d[8] = {};
  S g[8];
  for (std::size_t c = 0; c < C; ++c) g[c] = std::exp(log_gain[c]);
  for (std::size_t p = 0; p < P; ++p)
    for (std::size_t c = 0; c < C; ++c) {
      const double d = static_cast<double>(d_out.data[p * C + c]);
      sum_xd[c] += static_cast<double>(in.data[p * C + c]) * d;
      sum_d[c] += d;
    }
  if (&d_in != &d_out) d_in.reshape(in.width, in.height, in.channels);
  constexpr S big = std::numeric_limits<S>::max();
  for (std::size_t p = 0; p < P; ++p)
    for (std::size_t c = 0; c < C; ++c) d_in.data[p * C + c] = std::clamp(g[c] * d_out.data[p * C + c], -big, big);
  for (std::size_t c = 0; c < C; ++c) {
    d_log_gain[c] = static_cast<double>(g[c]) * sum_xd[c];
    d_offset[c] = sum_d[c];
  }
}

// ---------------------------------------------------------------------------------------------
// The parameters of every training image, with their Adam state
// ---------------------------------------------------------------------------------------------

/// Log-gains and offsets of a set of training images (identified by their index in the dataset's
/// frames), with Adam moments and a step counter per image. Stored flat: image k owns the values
/// [first[k], first[k] + channels[k]) of every per-channel array.
struct ExposureState {
  std::vector<std::uint64_t> frames;     ///< dataset frame index of each image, ascending
  std::vector<std::int32_t> channels;    ///< channel count of each image
  std::vector<float> log_gain, offset;   ///< [sum of channels]
  std::vector<float> m_log_gain, v_log_gain, m_offset, v_offset;  ///< Adam moments, same layout
  std::vector<std::int64_t> steps;       ///< Adam steps taken per image

  bool empty() const { return frames.empty(); }
  std::size_t values() const { return log_gain.size(); }

  /// Whether the arrays agree with each other (sizes, ascending frames, channel counts >= 1).
  void validate(const std::string& where) const {
    std::size_t total = 0;
    if (channels.size() != frames.size() || steps.size() != frames.size())
      throw std::runtime_error(where + ": exposure state has " + std::to_string(frames.size()) + " frames but " +
                               std::to_string(channels.size()) + " channel counts and " + std::to_string(steps.size()) + " step counters");
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (channels[k] < 1 || channels[k] > 8) throw std::runtime_error(where + ": exposure state has a frame with " + std::to_string(channels[k]) + " channels");
      if (k > 0 && frames[k] <= frames[k - 1]) throw std::runtime_error(where + ": exposure frames are not ascending");
      if (steps[k] < 0) throw std::runtime_error(where + ": exposure step counter is negative");
      total += std::size_t(channels[k]);
    }
    for (const auto* v : {&log_gain, &offset, &m_log_gain, &v_log_gain, &m_offset, &v_offset})
      if (v->size() != total)
        throw std::runtime_error(where + ": exposure arrays hold " + std::to_string(v->size()) + " values, expected " + std::to_string(total));
    for (const auto* v : {&log_gain, &offset, &m_log_gain, &v_log_gain, &m_offset, &v_offset})
      for (float x : *v)
        if (!std::isfinite(x)) throw std::runtime_error(where + ": exposure state holds a non-finite value");
  }
};

/// The learned correction of the training images: parameters, Adam, lookup by dataset frame.
class Exposure {
 public:
  Exposure() = default;

  /// One identity correction (g = 1, b = 0) per (frame, channels) pair; `num_frames` is the
  /// dataset's frame count (frame indices must be below it and distinct).
  Exposure(std::size_t num_frames, std::vector<std::pair<std::size_t, int>> frames, ExposureConfig cfg)
      : cfg_(cfg), slot_(num_frames, -1) {
    cfg_.validate();
    std::sort(frames.begin(), frames.end());
    for (const auto& [f, c] : frames) {
      if (f >= num_frames) throw std::invalid_argument("Exposure: frame " + std::to_string(f) + " is not in the dataset");
      if (c < 1 || c > 8) throw std::invalid_argument("Exposure: frame " + std::to_string(f) + " has " + std::to_string(c) + " channels (1..8)");
      if (slot_[f] >= 0) throw std::invalid_argument("Exposure: frame " + std::to_string(f) + " is listed twice");
      slot_[f] = std::int64_t(st_.frames.size());
      st_.frames.push_back(f);
      st_.channels.push_back(c);
      st_.steps.push_back(0);
      first_.push_back(st_.log_gain.size());
      group_.push_back(-1);
      for (int i = 0; i < c; ++i)
        for (auto* v : {&st_.log_gain, &st_.offset, &st_.m_log_gain, &st_.v_log_gain, &st_.m_offset, &st_.v_offset}) v->push_back(0.0f);
    }
  }

  /// Fix the gauge of a group of images (the training images of one band): after every update of
  /// one of them, the group's mean log-gain and mean offset per channel are subtracted from each of
  /// them (a projected Adam step), so both means stay 0. The affine correction has a free common
  /// scale (every gain times s and every colour of the model divided by s render the same): left
  /// free, the gains of all images drift together, the model's brightness drifts the other way and
  /// every render of a new view (eval, `msgs render`) carries it. With the group's mean held at
  /// the identity, the model keeps the images' average radiometry and each gain says how much
  /// brighter than that average its image is. Costs O(group size) per step. The images of a group
  /// must have the same channel count and belong to no other group.
  void add_gauge_group(const std::vector<std::size_t>& frames) {
    std::vector<std::size_t> slots;
    for (std::size_t f : frames) {
      const std::size_t k = slot(f);
      if (group_[k] >= 0) throw std::invalid_argument("Exposure: frame " + std::to_string(f) + " is in two gauge groups");
      if (!slots.empty() && st_.channels[k] != st_.channels[slots.front()])
        throw std::invalid_argument("Exposure: a gauge group mixes channel counts");
      slots.push_back(k);
    }
    for (std::size_t k : slots) group_[k] = std::int64_t(groups_.size());
    groups_.push_back(std::move(slots));
  }

  const ExposureConfig& config() const { return cfg_; }
  const ExposureState& state() const { return st_; }
  std::size_t size() const { return st_.frames.size(); }
  bool has(std::size_t frame) const { return frame < slot_.size() && slot_[frame] >= 0; }

  /// Replace the state by a saved one; it must describe the same frames and channel counts.
  void restore(ExposureState s, const std::string& where = "exposure") {
    s.validate(where);
    if (s.frames != st_.frames || s.channels != st_.channels)
      throw std::runtime_error(where + ": the saved exposure parameters are for " + std::to_string(s.frames.size()) +
                               " other training images than this run's " + std::to_string(st_.frames.size()));
    st_ = std::move(s);
  }

  std::span<const float> log_gain(std::size_t frame) const { return span_of(st_.log_gain, frame); }
  std::span<const float> offset(std::size_t frame) const { return span_of(st_.offset, frame); }

  /// Set one image's parameters (tests, initialisation from elsewhere); clamped like an update.
  void set(std::size_t frame, std::span<const float> log_gain, std::span<const float> offset) {
    const std::size_t k = slot(frame), n = std::size_t(st_.channels[k]);
    if (log_gain.size() != n || offset.size() != n) throw std::invalid_argument("Exposure::set: wrong channel count");
    for (std::size_t c = 0; c < n; ++c) {
      if (!std::isfinite(log_gain[c]) || !std::isfinite(offset[c])) throw std::invalid_argument("Exposure::set: non-finite value");
      st_.log_gain[first_[k] + c] = std::clamp(log_gain[c], -cfg_.max_log_gain, cfg_.max_log_gain);
      st_.offset[first_[k] + c] = std::clamp(offset[c], -cfg_.max_offset, cfg_.max_offset);
    }
  }

  /// Apply the correction of training image `frame` to a render of it.
  void forward(std::size_t frame, const Image<float>& render, Image<float>& out) const {
    exposure_forward<float>(render, log_gain(frame), offset(frame), out);
  }

  /// Chain dL/d(corrected render) `d_image` in place into dL/d render and take one Adam step on
  /// the frame's parameters (the only ones touched).
  void backward_and_step(std::size_t frame, const Image<float>& render, Image<float>& d_image) {
    const std::size_t k = slot(frame), n = std::size_t(st_.channels[k]);
    double dg[8], db[8];
    exposure_backward<float>(render, log_gain(frame), d_image, d_image, std::span<double>(dg, n), std::span<double>(db, n));
    adam_update(k, std::span<const double>(dg, n), std::span<const double>(db, n));
  }

  /// One Adam step of image `frame` with the given parameter gradients.
  void adam_step(std::size_t frame, std::span<const double> d_log_gain, std::span<const double> d_offset) {
    const std::size_t k = slot(frame);
    if (d_log_gain.size() != std::size_t(st_.channels[k]) || d_offset.size() != std::size_t(st_.channels[k]))
      throw std::invalid_argument("Exposure::adam_step: wrong channel count");
    adam_update(k, d_log_gain, d_offset);
  }

 private:
  std::size_t slot(std::size_t frame) const {
    if (!has(frame)) throw std::out_of_range("Exposure: frame " + std::to_string(frame) + " has no exposure parameters");
    return std::size_t(slot_[frame]);
  }
  std::span<const float> span_of(const std::vector<float>& v, std::size_t frame) const {
    const std::size_t k = slot(frame);
    return std::span<const float>(v.data() + first_[k], std::size_t(st_.channels[k]));
  }

  void adam_update(std::size_t k, std::span<const double> dg, std::span<const double> db) {
    const std::size_t n = std::size_t(st_.channels[k]);
    for (std::size_t c = 0; c < n; ++c)
      if (!std::isfinite(dg[c]) || !std::isfinite(db[c])) return;  // NaN never enters the state
    const std::int64_t t = ++st_.steps[k];
    const double bc1 = 1.0 - std::pow(cfg_.beta1, double(t)), bc2 = 1.0 - std::pow(cfg_.beta2, double(t));
    auto update = [&](float& x, float& m, float& v, double grad, float lim) {
      const double gr = std::clamp(grad, -kExposureMaxGrad, kExposureMaxGrad);
      const double m1 = cfg_.beta1 * double(m) + (1.0 - cfg_.beta1) * gr;
      const double m2 = cfg_.beta2 * double(v) + (1.0 - cfg_.beta2) * gr * gr;
      m = float(m1);
      v = float(m2);
      const double upd = cfg_.lr * (m1 / bc1) / (std::sqrt(m2 / bc2) + cfg_.eps);
      x = std::clamp(float(double(x) - upd), -lim, lim);
    };
    for (std::size_t c = 0; c < n; ++c) {
      const std::size_t i = first_[k] + c;
      update(st_.log_gain[i], st_.m_log_gain[i], st_.v_log_gain[i], dg[c], cfg_.max_log_gain);
      update(st_.offset[i], st_.m_offset[i], st_.v_offset[i], db[c], cfg_.max_offset);
    }
    if (group_[k] >= 0) recentre(groups_[std::size_t(group_[k])], n);
  }

  /// Subtract the group's mean log-gain and offset per channel from each of its images (summed in
  /// double in a fixed order: deterministic).
  void recentre(const std::vector<std::size_t>& slots, std::size_t n) {
    for (std::vector<float>* v : {&st_.log_gain, &st_.offset}) {
      const float lim = v == &st_.log_gain ? cfg_.max_log_gain : cfg_.max_offset;
      for (std::size_t c = 0; c < n; ++c) {
        double mean = 0;
        for (std::size_t k : slots) mean += double((*v)[first_[k] + c]);
        mean /= double(slots.size());
        for (std::size_t k : slots) {
          float& x = (*v)[first_[k] + c];
          x = std::clamp(float(double(x) - mean), -lim, lim);
        }
      }
    }
  }

  ExposureConfig cfg_{};
  ExposureState st_;
  std::vector<std::int64_t> slot_;   ///< per dataset frame: index into st_.frames, or -1
  std::vector<std::size_t> first_;   ///< per image: first value in the per-channel arrays
  std::vector<std::int64_t> group_;  ///< per image: its gauge group (add_gauge_group), or -1
  std::vector<std::vector<std::size_t>> groups_;  ///< the images (slots) of each gauge group
};

// ---------------------------------------------------------------------------------------------
// Evaluation: the least-squares affine colour correction of a render onto its ground truth
// ---------------------------------------------------------------------------------------------

/// Per channel c, the (a_c, b_c) minimising sum_p (a_c * render_pc + b_c - gt_pc)^2, in double:
/// a = cov(render, gt) / var(render), b = mean(gt) - a mean(render). A channel whose render is
/// constant (variance below 1e-12 of the mean square, or zero) gets a = 0, b = mean(gt).
struct AffineFit {
  std::vector<double> gain, offset;
};

template <class S>
AffineFit fit_affine(const Image<S>& render, const Image<S>& gt) {
  if (render.width != gt.width || render.height != gt.height || render.channels != gt.channels || render.size() != gt.size())
    throw std::invalid_argument("fit_affine: render and ground truth differ in shape");
  const std::size_t C = std::size_t(std::max(render.channels, 0)), P = render.pixels();
  AffineFit fit{std::vector<double>(C, 0.0), std::vector<double>(C, 0.0)};
  if (P == 0) { std::fill(fit.gain.begin(), fit.gain.end(), 1.0); return fit; }
  for (std::size_t c = 0; c < C; ++c) {
    // Two passes (means, then centred sums): no cancellation on near-constant images.
    double mx = 0, my = 0;
    for (std::size_t p = 0; p < P; ++p) { mx += double(render.data[p * C + c]); my += double(gt.data[p * C + c]); }
    mx /= double(P);
    my /= double(P);
    double sxx = 0, sxy = 0, sq = 0;
    for (std::size_t p = 0; p < P; ++p) {
      const double dx = double(render.data[p * C + c]) - mx, dy = double(gt.data[p * C + c]) - my;
      sxx += dx * dx;
      sxy += dx * dy;
      sq += double(render.data[p * C + c]) * double(render.data[p * C + c]);
    }
    const bool flat = !(sxx > 1e-12 * sq) || !(sxx > 0);
    fit.gain[c] = flat ? 0.0 : sxy / sxx;
    fit.offset[c] = my - fit.gain[c] * mx;
    if (!std::isfinite(fit.gain[c]) || !std::isfinite(fit.offset[c])) { fit.gain[c] = 1.0; fit.offset[c] = 0.0; }
  }
  return fit;
}

/// The render mapped by its least-squares affine onto `gt` (fit_affine), clamped to [0, 1]:
/// what the colour-corrected PSNR / SSIM compare with the ground truth.
template <class S>
Image<S> colour_correct(const Image<S>& render, const Image<S>& gt) {
  const AffineFit fit = fit_affine(render, gt);
  Image<S> out(render.width, render.height, render.channels);
  const std::size_t C = std::size_t(std::max(render.channels, 0)), P = render.pixels();
  for (std::size_t p = 0; p < P; ++p)
    for (std::size_t c = 0; c < C; ++c)
      out.data[p * C + c] = static_cast<S>(std::clamp(fit.gain[c] * double(render.data[p * C + c]) + fit.offset[c], 0.0, 1.0));
  return out;
}

}  // namespace msgs
