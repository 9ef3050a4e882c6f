// include/msgs/train.hpp
// The training loop of one model: sample a band and image, render that band's channels, loss,
// backward, Adam with the strategy's masks, densification; plus per-band evaluation. Strategies
// (strategy.hpp) decide the plan and the hooks; run.hpp wires Separate / Split / Joint from it.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <typeinfo>
#include <utility>
#include <vector>

#include "adam.hpp"
#include "checkpoint.hpp"
#include "curve.hpp"
#include "densify.hpp"
#include "exposure.hpp"
#include "gaussian.hpp"
#include "io/dataset.hpp"
#include "loss.hpp"
#include "rasterize.hpp"
#include "schedule.hpp"
#include "sh.hpp"
#include "strategy.hpp"

namespace msgs {

/// The trainer's rasteriser features: absgrad on, since the default densification (and MSAD)
/// reads it; single-precision projection (the hard cases in double); ties in depth ordered by the
/// means, so that the spatial order of the rows changes no result; evaluation uses the same type
/// so the forward is compiled once.
inline constexpr RasterOptions kTrainRaster{.absgrad = true, .single_precision = true, .ties_by_mean = true};

/// A band as one trainer sees it: which model channels render it and which frames show it.
struct TrainBand {
  std::string id;                         ///< "D", "MS_G", "MS_R", "MS_RE", "MS_NIR"
  int first_channel = 0;                  ///< first model channel of the band
  int channels = 1;                       ///< 3 for RGB, 1 for a narrow band
  bool spectral = false;                  ///< narrow band (SpecDelay / SIG treat these differently)
  std::vector<std::size_t> train_frames;  ///< indices into Dataset::frames
  std::vector<std::size_t> eval_frames;   ///< indices into Dataset::frames
};

/// Wall-clock seconds per stage of training, summed over steps.
struct StageTimes {
  double load = 0, project = 0, bin = 0, blend = 0, loss = 0, backward = 0, adam = 0, densify = 0, eval = 0;
  /// Parts of `backward`: the blend backward, and the per-Gaussian gradient reduction with the
  /// projection and colour backward (the rest of `backward` is the clamp, exposure and scale
  /// regulariser).
  double backward_blend = 0, backward_gaussians = 0;
  /// Part of `densify`: the refinements (growth, pruning and the moves of model and moments); the
  /// rest is the per-step gradient statistics.
  double refine = 0;
  double total() const { return load + project + bin + blend + loss + backward + adam + densify + eval; }
  StageTimes& operator+=(const StageTimes& o) {
    load += o.load; project += o.project; bin += o.bin; blend += o.blend; loss += o.loss;
    backward += o.backward; adam += o.adam; densify += o.densify; eval += o.eval;
    backward_blend += o.backward_blend; backward_gaussians += o.backward_gaussians; refine += o.refine;
    return *this;
  }
};

/// What the progress callback receives.
struct TrainProgress {
  long long step = 0, begin = 0, end = 0;
  double loss = 0;                   ///< running mean of the loss
  std::vector<double> band_psnr;     ///< running mean of the training PSNR per band (NaN until seen)
  std::vector<std::string> band_ids; ///< the band of each band_psnr entry (this model's bands: one
                                     ///< band model of Separate or Split trains one of the run's bands)
  std::size_t gaussians = 0;
  double seconds = 0;                ///< since train() started
  DensifyReport last_refine;         ///< most recent refinement
};

/// The model right after a step, for TrainOptions::on_step: read-only and valid during the call
/// only. The model is type-erased so that the callback need not be a template; model<G>() gives
/// it back as GaussianModel<G, float> (nullptr for any other G). snapshot.hpp copies it from here.
struct StepView {
  long long step = 0, begin = 0, end = 0;        ///< steps done (the step just taken + 1), the range
  std::string key;                               ///< which model of a run ("joint" or a band id; run.hpp)
  const std::vector<TrainBand>* bands = nullptr;  ///< the bands this model trains
  int channels = 0, sh_degree = 0;               ///< G::bands, G::sh_degree
  std::size_t gaussians = 0;
  const void* model_ptr = nullptr;
  const std::type_info* model_type = nullptr;

  template <class G>
  const GaussianModel<G, float>* model() const {
    return model_type && *model_type == typeid(GaussianModel<G, float>)
               ? static_cast<const GaussianModel<G, float>*>(model_ptr) : nullptr;
  }
  template <class G>
  static StepView of(const GaussianModel<G, float>& m, const std::vector<TrainBand>& bands, long long step,
                     long long begin, long long end) {
    return {step, begin, end, {}, &bands, G::bands, G::sh_degree, m.size(), &m, &typeid(GaussianModel<G, float>)};
  }
};

/// Options of a training run that are not part of the strategy's plan. The defaults follow the
/// multi-spectral reference implementation (REFERENCE §9); presets.hpp names the departures.
struct TrainOptions {
  std::uint64_t seed = 0;            ///< band sampling, backgrounds, split samples
  AdamConfig adam{};                 ///< learning rates (lr_means_steps is set from the plan)
  /// L1 + SSIM; SSIM over the valid 11x11 windows as the reference's pytorch-msssim (same: 3DGS).
  PhotometricLossConfig loss{.ssim_weight = 0.2, .ssim_border = SsimBorder::valid};
  /// Clamp each training render to [0, 1] (after the background) before the loss, as the
  /// reference does: saturated pixels get no gradient. false: the loss sees the raw render (3DGS).
  bool clamp_render = true;
  /// Each band's image list is reshuffled whenever it is used up (the reference), or shuffled once.
  Shuffle shuffle = Shuffle::every_pass;
  /// SSIM of the evaluation (valid: pytorch-msssim, as the reference; same: zero-padded, 3DGS).
  SsimBorder eval_ssim = SsimBorder::valid;
  /// Anytime evaluation: quality against training time (curve.hpp); off by default.
  CurveConfig curve{};
  /// Seconds the run trained before this model (Separate and Split train models one after another),
  /// added to the curve's training clock.
  double clock_offset = 0;
  /// When narrow bands join a Joint run that trained its geometry band alone first (SpecDelay), or a
  /// Split band model takes the geometry band's Gaussians: start each narrow band's colour from the
  /// geometry band's luminance, scaled to the band's mean image brightness, instead of uniform random
  /// values (the `fast` preset; the reference starts from random colours).
  bool spectral_colour_init = false;
  ScaleRegConfig scale_reg{};
  int scale_reg_every = 10;          ///< the regulariser is added every this many steps (0 = never)
  bool random_background = true;     ///< random background per step (else black)
  double scene_scale = 1.0;
  int progress_every = 25;           ///< steps between progress callbacks
  std::function<void(const TrainProgress&)> on_progress;
  /// Called after every step, between steps, with the model (live viewers: snapshot.hpp). It only
  /// reads; training is bit-identical with and without it.
  std::function<void(const StepView&)> on_step;
  const std::atomic<bool>* stop = nullptr;  ///< set by a signal handler: stop after the current step
  bool check_finite = false;         ///< verify every parameter is finite after each step (soak runs)
  /// false (default): dense Adam over every Gaussian, zero gradients for the ones the view did not
  /// see (torch's Adam, the reference behaviour). true: a sparse step: gradients, Adam and the
  /// scale regulariser only for the Gaussians the view saw; the others and their Adam moments stay
  /// as they are. Cheaper per step, but a different optimisation (README: "Sparse Adam").
  bool sparse = false;
  /// Adam's colour (SH) update of each Gaussian the view saw runs inside the backward, as soon as
  /// its colour gradient is known (Adam::ColourStep): the gradient is never stored and read back and
  /// the row is still in cache. The same bits as false, which stores the colour gradients and
  /// updates after the backward (check_finite, which reads them, implies false).
  bool fused_colour = true;
  /// Where train() writes checkpoints (empty: none): every `checkpoint_every` steps, at the end,
  /// and when stopped early, so an interrupted run always leaves a usable checkpoint.
  std::filesystem::path checkpoint_path;
  int checkpoint_every = 0;          ///< 0: only at the end and when stopped
  /// Exposure compensation (exposure.hpp): learn a gain exp(a_c) and an offset b_c per channel of
  /// every training image and compare g * render + b with it. Off (default): no exposure state at
  /// all and training is bit-identical to a build without the feature.
  bool exposure = false;
  double lr_exposure = 1e-3;         ///< Adam learning rate of the log-gains and offsets
};

/// Per-band evaluation: one PSNR and SSIM per eval image.
struct BandMetrics {
  std::string band;
  std::vector<double> psnr, ssim;
  /// Colour-corrected PSNR / SSIM per eval image (exposure runs only, else empty): the render
  /// after the least-squares affine per channel onto the ground truth (colour_correct).
  std::vector<double> psnr_cc = {}, ssim_cc = {};
  static double mean(const std::vector<double>& v) {
    if (v.empty()) return std::nan("");
    double s = 0; for (double x : v) s += x; return s / double(v.size());
  }
  static double stddev(const std::vector<double>& v) {
    if (v.size() < 2) return 0.0;
    const double m = mean(v);
    double s = 0; for (double x : v) s += (x - m) * (x - m);
    return std::sqrt(s / double(v.size() - 1));
  }
};

/// The learned corrections of one band's training images, for reports (exposure runs).
struct BandExposure {
  std::string band;
  int channels = 1;
  std::vector<std::string> files;                  ///< file_path per training image
  std::vector<std::vector<double>> gain, offset;   ///< per image, per channel: exp(a_c), b_c
};

/// Caches a dataset's images at the current training resolution (one resolution at a time).
class ImageCache {
 public:
  explicit ImageCache(const io::Dataset& ds) : ds_(&ds) {}
  const Image<float>& get(std::size_t frame, int factor) {
    if (factor != factor_) { cache_.clear(); factor_ = factor; }
    auto it = cache_.find(frame);
    if (it != cache_.end()) return it->second;
    return cache_.emplace(frame, io::load_frame_image(*ds_, ds_->frames[frame], factor)).first->second;
  }
  Camera<float> camera(std::size_t frame, int factor) const { return io::frame_camera(*ds_, ds_->frames[frame], factor); }

 private:
  const io::Dataset* ds_;
  int factor_ = -1;
  std::map<std::size_t, Image<float>> cache_;
};

/// Clamp an image to [0, 1] in place (evaluation renders).
inline void clamp01(Image<float>& img) {
  for (float& v : img.data) v = std::clamp(v, 0.0f, 1.0f);
}

/// `out` = `img` clamped to [0, 1] (training renders, TrainOptions::clamp_render).
inline void clamp01(const Image<float>& img, Image<float>& out) {
  if (out.width != img.width || out.height != img.height || out.channels != img.channels || out.size() != img.size())
    out.reset(img.width, img.height, img.channels);
  for (std::size_t i = 0; i < img.data.size(); ++i) out.data[i] = std::clamp(img.data[i], 0.0f, 1.0f);
}

/// The clamp's backward: the gradient is 0 where the render was outside [0, 1] (torch.clamp's).
inline void clamp01_backward(const Image<float>& img, Image<float>& grad) {
  for (std::size_t i = 0; i < img.data.size(); ++i)
    if (!(img.data[i] >= 0.0f && img.data[i] <= 1.0f)) grad.data[i] = 0.0f;
}

/// Mean over a band's training images (at downscale `factor`) of their luminance: BT.601 for RGB,
/// the value for one channel.
inline double mean_luminance(ImageCache& images, const TrainBand& b, int factor) {
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t f : b.train_frames) {
    const Image<float>& img = images.get(f, factor);
    for (std::size_t p = 0; p < img.pixels(); ++p) {
      const float* v = img.data.data() + p * std::size_t(img.channels);
      sum += img.channels == 3 ? luminance_weights[0] * v[0] + luminance_weights[1] * v[1] + luminance_weights[2] * v[2]
                               : double(v[0]);
      ++n;
    }
  }
  return n ? sum / double(n) : 0.0;
}

/// Per Gaussian, the luminance of the view-independent colour (C0 dc + 0.5, clamped at 0) of
/// channels [first, first + channels): BT.601 for three channels, the value for one.
template <class G>
std::vector<float> dc_luminance(const GaussianModel<G, float>& m, int first, int channels) {
  std::vector<float> lum(m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    double l = 0;
    for (int c = 0; c < channels; ++c) {
      const double colour = std::max(0.0, sh::C0 * double(m.sh_at(i, 0, first + c)) + 0.5);
      l += channels == 3 ? luminance_weights[std::size_t(c)] * colour : colour;
    }
    lum[i] = float(l);
  }
  return lum;
}

/// Colour of channels [first, first + channels) from another band's luminance `lum` (dc_luminance),
/// scaled by band_mean / geometry_mean (the bands' mean image luminance, mean_luminance) so the band
/// starts at its own brightness with the geometry band's texture; higher SH orders 0. A dark
/// geometry band (mean below 1e-6) keeps the scale 1. The `fast` preset's narrow-band start.
template <class G>
void set_colour_from_luminance(GaussianModel<G, float>& m, int first, int channels, const std::vector<float>& lum,
                               double band_mean, double geometry_mean) {
  if (lum.size() != m.size())
    throw std::invalid_argument("set_colour_from_luminance: " + std::to_string(lum.size()) + " luminances for " +
                                std::to_string(m.size()) + " Gaussians");
  const double k = geometry_mean > 1e-6 && std::isfinite(band_mean) ? band_mean / geometry_mean : 1.0;
  for (int c = 0; c < channels; ++c)
    for (std::size_t i = 0; i < m.size(); ++i) {
      m.sh_at(i, 0, first + c) = float((k * double(lum[i]) - 0.5) / sh::C0);
      for (int j = 1; j < G::sh_coeffs; ++j) m.sh_at(i, j, first + c) = 0.0f;
    }
}

/// Trains one model of Gaussian type G on a set of bands.
template <class G>
class Trainer {
 public:
  using Model = GaussianModel<G, float>;

  Trainer(const io::Dataset& ds, std::vector<TrainBand> bands, Model model, TrainPlan plan, StrategyHooks hooks,
          TrainOptions opt)
      : ds_(&ds), bands_(std::move(bands)), model_(std::move(model)), plan_(std::move(plan)), hooks_(hooks),
        opt_(std::move(opt)), images_(ds), curve_images_(ds),
        density_(plan_.densify, int(bands_.size()), count_train_images(), opt_.scene_scale) {
    if (bands_.empty()) throw std::invalid_argument("Trainer: no bands to train");
    for (const auto& b : bands_) {
      if (b.first_channel < 0 || b.channels < 1 || b.first_channel + b.channels > G::bands)
        throw std::invalid_argument("Trainer: band " + b.id + " does not fit the model's " + std::to_string(G::bands) +
                                    " channels");
      if (b.train_frames.empty()) throw std::invalid_argument("Trainer: band " + b.id + " has no training images");
    }
    AdamConfig ac = opt_.adam;
    ac.lr_means_steps = plan_.schedule.total_steps;
    ac.scene_scale = opt_.scene_scale;
    adam_ = Adam<G, float>(ac, model_.size());
    band_psnr_.assign(bands_.size(), std::nan(""));
    if (opt_.exposure) {
      std::vector<std::pair<std::size_t, int>> frames;
      for (const auto& b : bands_)
        for (std::size_t f : b.train_frames) frames.emplace_back(f, b.channels);
      ExposureConfig ec;
      ec.lr = opt_.lr_exposure;
      exposure_ = Exposure(ds.frames.size(), std::move(frames), ec);
      for (const auto& b : bands_) exposure_.add_gauge_group(b.train_frames);  // mean log-gain and offset 0
    }
  }

  /// Everything needed to continue at `next_step` bit for bit.
  TrainState<G> state(long long next_step) const {
    const TrainStateView<G> v = state_view(next_step);
    TrainState<G> st;
    st.step = v.step;
    st.model.assign_shrunk(*v.model);  // band planes of N rows, as a checkpoint holds them
    st.exp_avg.assign_shrunk(*v.exp_avg);
    st.exp_avg_sq.assign_shrunk(*v.exp_avg_sq);
    st.adam_steps = v.adam_steps;
    st.adam_iteration = v.adam_iteration;
    st.stats_bands = v.stats_bands;
    st.stats_grad = *v.stats_grad;
    st.stats_count = *v.stats_count;
    st.stats_radius = *v.stats_radius;
    if (v.exposure) st.exposure = *v.exposure;
    return st;
  }

  /// The same, by reference into this trainer (what a checkpoint writes, without a copy); valid
  /// until training goes on.
  TrainStateView<G> state_view(long long next_step) const {
    const DensityStats& ds = density_.stats();
    TrainStateView<G> v;
    v.step = next_step;
    v.model = &model_;
    v.exp_avg = &adam_.exp_avg;
    v.exp_avg_sq = &adam_.exp_avg_sq;
    v.adam_steps = adam_.steps;
    v.adam_iteration = adam_.iteration;
    v.stats_bands = ds.bands();
    v.stats_grad = &ds.grad_sums();
    v.stats_count = &ds.counts();
    v.stats_radius = &ds.max_radii();
    v.exposure = opt_.exposure ? &exposure_.state() : nullptr;
    return v;
  }

  /// Continue from a saved state; returns the step to resume at. The anytime-evaluation curve and
  /// the training clock continue from the file next to the checkpoint when there is one.
  long long restore(TrainState<G> st) {
    if (opt_.curve.enabled() && !opt_.checkpoint_path.empty() && std::filesystem::exists(curve_path())) {
      auto [clock, points] = load_curve(curve_path());
      clock_ = clock;
      curve_ = std::move(points);
    }
    if (opt_.exposure != !st.exposure.empty())
      throw std::runtime_error(opt_.exposure ? "cannot resume with exposure compensation on: the checkpoint was written without it"
                                             : "cannot resume without exposure compensation: the checkpoint was written with it on");
    if (opt_.exposure) exposure_.restore(std::move(st.exposure), "checkpoint");
    model_ = std::move(st.model);
    adam_.exp_avg = std::move(st.exp_avg);
    adam_.exp_avg_sq = std::move(st.exp_avg_sq);
    adam_.steps = st.adam_steps;
    adam_.iteration = st.adam_iteration;
    density_.stats().restore(model_.size(), st.stats_bands, std::move(st.stats_grad), std::move(st.stats_count),
                             std::move(st.stats_radius));
    return st.step;
  }

  Model& model() { return model_; }
  const Model& model() const { return model_; }
  /// Anytime evaluations so far (TrainOptions::curve), seconds including clock_offset.
  const std::vector<CurvePoint>& curve() const { return curve_; }
  /// Seconds this trainer has trained (steps, callbacks, checkpoints; anytime evaluations excluded).
  double clock() const { return clock_; }
  Adam<G, float>& adam() { return adam_; }
  DensityControl& density() { return density_; }
  const StageTimes& times() const { return times_; }
  const std::vector<TrainBand>& bands() const { return bands_; }
  const TrainPlan& plan() const { return plan_; }
  /// The learned per-image corrections, or nullptr when TrainOptions::exposure is off.
  const Exposure* exposure() const { return opt_.exposure ? &exposure_ : nullptr; }
  Exposure* exposure() { return opt_.exposure ? &exposure_ : nullptr; }

  /// Gains and offsets per band and training image (empty when exposure is off).
  std::vector<BandExposure> exposure_report() const {
    std::vector<BandExposure> out;
    if (!opt_.exposure) return out;
    for (const auto& b : bands_) {
      BandExposure e;
      e.band = b.id;
      e.channels = b.channels;
      for (std::size_t f : b.train_frames) {
        e.files.push_back(ds_->frames[f].file_path);
        std::vector<double> g, o;
        for (float a : exposure_.log_gain(f)) g.push_back(std::exp(double(a)));
        for (float x : exposure_.offset(f)) o.push_back(double(x));
        e.gain.push_back(std::move(g));
        e.offset.push_back(std::move(o));
      }
      out.push_back(std::move(e));
    }
    return out;
  }

  /// Train steps [begin, end). Returns the first step not taken (end, or earlier when stopped).
  long long train(long long begin, long long end);

  /// With the anytime evaluation on: a point at `step` now (the model's last step, say), unless the
  /// curve already ends there. Its time is off the training clock.
  void finish_curve(long long step) {
    if (opt_.curve.enabled() && (curve_.empty() || curve_.back().step != step)) record_curve(step);
  }

  /// PSNR and SSIM of every eval image of every band at full resolution, with the evaluation
  /// background (REFERENCE §3) and renders clamped to [0, 1]. Rendered without any exposure
  /// correction (eval images have no learned one); with exposure on, also the colour-corrected
  /// PSNR / SSIM (least-squares affine per image and channel, BandMetrics::psnr_cc).
  std::vector<BandMetrics> evaluate(bool eval_split = true);

 private:
  static double seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  }

  /// Frame `f` of `band` as evaluation sees it: full resolution, the evaluation background,
  /// clamped to [0, 1].
  Image<float> eval_render(Rasterizer<G, float, kTrainRaster>& raster, ImageCache& images, const TrainBand& band,
                           std::size_t f) {
    RenderSettings<float> rs;
    rs.band_first = band.first_channel;
    rs.band_count = band.channels;
    rs.background = eval_background<float>(band.channels);
    Image<float> render = raster.forward(model_, images.camera(f, 1), rs);
    clamp01(render);
    return render;
  }

  std::filesystem::path curve_path() const {
    std::filesystem::path p = opt_.checkpoint_path;
    p += ".curve";
    return p;
  }

  /// Checkpoint (and the curve with its clock, when recorded) at `next_step`; `tick` brings the clock up to now.
  template <class Tick>
  void checkpoint(long long next_step, Tick&& tick) {
    save_checkpoint(opt_.checkpoint_path, state_view(next_step));
    if (opt_.curve.enabled()) {
      tick();
      save_curve(curve_path(), clock_, curve_);
    }
  }

  /// Whether an anytime evaluation is due before `step`: the first step, or a period has passed.
  bool curve_due(long long step) const {
    if (curve_.empty()) return true;
    const CurvePoint& last = curve_.back();
    if (opt_.curve.every_steps > 0 && step - last.step >= opt_.curve.every_steps) return true;
    return opt_.curve.every_seconds > 0 && opt_.clock_offset + clock_ - last.seconds >= opt_.curve.every_seconds;
  }

  /// Evaluate the fixed subset of every band's eval images (curve_subset) at full resolution, as
  /// evaluate() does, and append the point. The caller keeps its time off the training clock.
  void record_curve(long long step);

  /// TrainOptions::spectral_colour_init at `step`: every narrow band's colour starts from the
  /// geometry band's (spectral_colour_from).
  void init_spectral_colours(long long step) {
    const auto geo = std::find_if(bands_.begin(), bands_.end(), [](const TrainBand& b) { return !b.spectral; });
    if (geo == bands_.end()) return;
    const int factor = plan_.schedule.downscale(step);
    const double geo_mean = mean_luminance(images_, *geo, factor);
    const std::vector<float> lum = dc_luminance(model_, geo->first_channel, geo->channels);
    for (const TrainBand& b : bands_)
      if (b.spectral) set_colour_from_luminance(model_, b.first_channel, b.channels, lum, mean_luminance(images_, b, factor), geo_mean);
  }

  int count_train_images() const {
    std::size_t n = 0;
    for (const auto& b : bands_) n += b.train_frames.size();
    return int(n);
  }

  /// Round-robin over the bands the strategy enables at `step` (REFERENCE §3): each enabled set
  /// has its own sampler, a pure function of the step, so runs resume exactly.
  std::pair<int, std::size_t> sample(long long step) {
    std::uint32_t mask = 0;
    for (std::size_t b = 0; b < bands_.size(); ++b)
      if (hooks_.band_enabled(plan_, step, bands_[b].spectral)) mask |= 1u << b;
    if (mask == 0) throw std::logic_error("Trainer: the strategy enables no band at step " + std::to_string(step));
    auto it = samplers_.find(mask);
    if (it == samplers_.end()) {
      std::vector<std::vector<int>> lists;
      std::vector<int> ids;
      for (std::size_t b = 0; b < bands_.size(); ++b)
        if (mask & (1u << b)) {
          std::vector<int> l(bands_[b].train_frames.size());
          for (std::size_t i = 0; i < l.size(); ++i) l[i] = int(i);
          lists.push_back(std::move(l));
          ids.push_back(int(b));
        }
      it = samplers_.emplace(mask, std::make_pair(BandSampler(std::move(lists), opt_.seed ^ 0x5eedULL, opt_.shuffle), ids)).first;
    }
    const BandSampler::Draw d = it->second.first.at(step);
    const int b = it->second.second[std::size_t(d.band)];
    return {b, bands_[std::size_t(b)].train_frames[std::size_t(d.image)]};
  }

  void check_finite(long long step) const {
    auto check = [&](const std::vector<float>& v, const char* name) {
      for (float x : v)
        if (!std::isfinite(x))
          throw std::runtime_error("training produced a non-finite " + std::string(name) + " at step " +
                                   std::to_string(step));
    };
    check(model_.means, "mean");
    check(model_.log_scales, "log-scale");
    check(model_.quats, "quaternion");
    check(model_.opacity_logits, "opacity logit");
    check(model_.sh, "SH coefficient");
  }

  /// Every gradient the step will read: all rows, or the listed ones (a sparse step).
  void check_finite_gradients(long long step, const Gradients<G, float>& g, const std::vector<std::uint32_t>* rows) const {
    const std::size_t n = model_.size();
    auto check = [&](const std::vector<float>& v, std::size_t planes, const char* name) {
      const std::size_t w = v.size() / std::max<std::size_t>(n * planes, 1);
      auto row_ok = [&](std::size_t q, std::size_t i) {
        for (std::size_t a = 0; a < w; ++a)
          if (!std::isfinite(v[(q * n + i) * w + a])) return false;
        return true;
      };
      for (std::size_t q = 0; q < planes; ++q)
        for (std::size_t j = 0, m = rows ? rows->size() : n; j < m; ++j)
          if (!row_ok(q, rows ? (*rows)[j] : j))
            throw std::runtime_error("training produced a non-finite gradient of " + std::string(name) + " at step " +
                                     std::to_string(step));
    };
    check(g.model.means, 1, "means");
    check(g.model.log_scales, 1, "log-scales");
    check(g.model.quats, 1, "quaternions");
    check(g.model.opacity_logits, 1, "opacity logits");
    check(g.model.sh, std::size_t(G::bands), "SH coefficients");
    check(g.mean2d, 1, "screen-space means");
  }

  const io::Dataset* ds_;
  std::vector<TrainBand> bands_;
  Model model_;
  TrainPlan plan_;
  StrategyHooks hooks_;
  TrainOptions opt_;
  ImageCache images_;
  ImageCache curve_images_;  // full-resolution eval images of the anytime evaluation
  Adam<G, float> adam_;
  Exposure exposure_;  // empty unless opt_.exposure
  DensityControl density_;
  StageTimes times_;
  double clock_ = 0;                 // training seconds, anytime evaluations excluded
  std::vector<CurvePoint> curve_;
  std::vector<double> band_psnr_;
  std::map<std::uint32_t, std::pair<BandSampler, std::vector<int>>> samplers_;
};

// The training loop, the evaluation and the anytime evaluation are defined out of the class, so not
// inline: a translation unit that declares `extern template class Trainer<G>;` leaves them, the
// costliest code of a trainer to compile, to the one unit that instantiates Trainer<G>.
template <class G>
long long Trainer<G>::train(long long begin, long long end) {
  using clock = std::chrono::steady_clock;
  const auto t_start = clock::now();
  Rasterizer<G, float, kTrainRaster> raster;
  Gradients<G, float> grads;
  Image<float> d_image;
  Image<float> corrected;  // exposure: g * render + b, what the loss sees
  Image<float> clamped;    // clamp_render: the render in [0, 1]
  SsimWorkspace<float> ws;
  double loss_sum = 0;
  long long loss_n = 0;
  DensifyReport last_rep;
  long long step = begin;
  auto mark = clock::now();  // the training clock runs from here, paused for anytime evaluations
  auto tick = [&] {
    const auto now = clock::now();
    clock_ += seconds(mark, now);
    mark = now;
  };
  for (; step < end; ++step) {
    if (opt_.stop && opt_.stop->load()) break;
    if (opt_.curve.enabled()) {
      tick();
      if (curve_due(step)) {
        record_curve(step);
        mark = clock::now();
      }
    }
    if (!opt_.checkpoint_path.empty() && opt_.checkpoint_every > 0 && step > begin && step % opt_.checkpoint_every == 0)
      checkpoint(step, tick);
    if (opt_.spectral_colour_init && step == plan_.spectral_start && plan_.spectral_start > 0) init_spectral_colours(step);
    auto t0 = clock::now();
    // 1. Which band and image.
    const auto [bi, frame] = sample(step);
    const TrainBand& band = bands_[std::size_t(bi)];
    const int factor = plan_.schedule.downscale(step);
    const Image<float>& gt = images_.get(frame, factor);
    const Camera<float> cam = images_.camera(frame, factor);
    auto t1 = clock::now();
    times_.load += seconds(t0, t1);

    // 2. Render only this band's channels.
    RenderSettings<float> rs;
    rs.band_first = band.first_channel;
    rs.band_count = band.channels;
    rs.sh_degree = plan_.schedule.sh_degree(step, G::sh_degree);
    rs.background = opt_.random_background ? random_background<float>(step, band.channels, opt_.seed)
                                           : std::vector<float>(std::size_t(band.channels), 0.0f);
    raster.timings().reset();
    const Image<float>& raw = raster.forward(model_, cam, rs);
    auto t2 = clock::now();

    // 3. Loss and its gradient (of the clamped render, then exposure-corrected when exposure is on).
    if (opt_.clamp_render) clamp01(raw, clamped);
    const Image<float>& render = opt_.clamp_render ? clamped : raw;
    if (opt_.exposure) exposure_.forward(frame, render, corrected);
    const Image<float>& seen_image = opt_.exposure ? corrected : render;
    double mse = 0;
    const double loss = photometric_loss(seen_image, gt, &d_image, ws, opt_.loss, &mse);
    loss_sum += loss;
    ++loss_n;
    const double p = psnr_from_mse(mse);
    double& bp = band_psnr_[std::size_t(bi)];
    bp = std::isnan(bp) ? p : 0.9 * bp + 0.1 * p;
    auto t3 = clock::now();

    // 4. Backward: through the exposure correction (its Adam step on this image's parameters
    // only, taken here since nothing else reads them), then the rasteriser.
    if (opt_.exposure) exposure_.backward_and_step(frame, render, d_image);
    if (opt_.clamp_render) clamp01_backward(raw, d_image);
    // Gradient rows the view did not see: sparse Adam never reads them; dense Adam takes them as
    // zero without reading them (Unlisted::zero_gradient), except at a step of the scale
    // regulariser, which gives every Gaussian a gradient: then they are written, zeros included.
    const std::vector<std::uint32_t>& seen = raster.visible();
    const bool reg_step = opt_.scale_reg_every > 0 && step % opt_.scale_reg_every == 0;
    const bool seen_only = opt_.sparse || !reg_step;
    const std::vector<std::uint32_t>* rows = seen_only ? &seen : nullptr;
    const Unlisted unlisted = opt_.sparse ? Unlisted::untouched : Unlisted::zero_gradient;
    // The strategy's masks (they depend on the step and band only).
    StepContext ctx;
    ctx.step = step;
    ctx.band = bi;
    ctx.spectral = band.spectral;
    ctx.mask = AdamMask::band(band.first_channel, band.channels);
    hooks_.pre_backward(plan_, ctx);
    // Adam's colour update of the visible Gaussians inside the backward (fused_colour).
    const bool fuse = opt_.fused_colour && !opt_.check_finite && ctx.mask.sh;
    std::optional<typename Adam<G, float>::ColourStep> colour;
    if (fuse) colour.emplace(adam_.begin_colour(model_, ctx.mask.sh_first, ctx.mask.sh_channels(G::bands)));
    raster.backward(d_image, nullptr, nullptr, grads, seen_only ? GradientFill::visible : GradientFill::dense,
                    fuse ? &*colour : nullptr);
    if (opt_.check_finite) check_finite_gradients(step, grads, rows);
    if (reg_step)
      scale_reg<float>(std::span<const float>(model_.log_scales), std::span<float>(grads.model.log_scales),
                       opt_.scale_reg, rows);
    auto t4 = clock::now();
    times_.project += raster.timings().project;
    times_.bin += raster.timings().bin;
    times_.blend += raster.timings().blend;
    times_.loss += seconds(t2, t3);
    times_.backward += seconds(t3, t4);
    times_.backward_blend += raster.timings().blend_backward;
    times_.backward_gaussians += raster.timings().project_backward;

    // 5. Adam with the strategy's masks (the colour of the visible Gaussians already, when fused).
    AdamMask mask = ctx.mask;
    if (fuse) mask.sh = false;
    adam_.step(model_, grads.model, mask, rows, unlisted);
    if (fuse) adam_.finish_colour(*colour, seen, unlisted);
    auto t5 = clock::now();
    times_.adam += seconds(t4, t5);

    // 6. Adaptive density control.
    if (ctx.observe_density && density_.accumulates_at(step))
      density_.observe_gradients(step, bi, grads, raster.radii(), cam.width, cam.height, &seen);
    const auto t5s = clock::now();
    const DensifyReport rep = density_.step_post_backward(step, model_, adam_.exp_avg, adam_.exp_avg_sq);
    if (rep.refined || rep.opacity_reset) last_rep = rep;
    auto t6 = clock::now();
    times_.densify += seconds(t5, t6);
    if (rep.refined) times_.refine += seconds(t5s, t6);

    if (opt_.check_finite) check_finite(step);
    if (opt_.on_step) {  // off the training clock, like anytime evaluations
      tick();
      opt_.on_step(StepView::of(model_, bands_, step + 1, begin, end));
      mark = clock::now();
    }
    if (opt_.on_progress && ((step + 1 - begin) % std::max(1, opt_.progress_every) == 0 || step + 1 == end)) {
      TrainProgress pr;
      pr.step = step + 1; pr.begin = begin; pr.end = end;
      pr.loss = loss_sum / double(std::max<long long>(loss_n, 1));
      loss_sum = 0; loss_n = 0;
      pr.band_psnr = band_psnr_;
      for (const auto& b : bands_) pr.band_ids.push_back(b.id);
      pr.gaussians = model_.size();
      pr.seconds = seconds(t_start, clock::now());
      pr.last_refine = last_rep;
      opt_.on_progress(pr);
    }
  }
  tick();
  if (!opt_.checkpoint_path.empty()) checkpoint(step, tick);
  return step;
}

template <class G>
std::vector<BandMetrics> Trainer<G>::evaluate(bool eval_split) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<BandMetrics> out;
  Rasterizer<G, float, kTrainRaster> raster;
  ImageCache full(*ds_);
  for (const auto& band : bands_) {
    BandMetrics m;
    m.band = band.id;
    const auto& frames = eval_split ? band.eval_frames : band.train_frames;
    for (std::size_t f : frames) {
      const Image<float> render = eval_render(raster, full, band, f);
      const Image<float>& gt = full.get(f, 1);
      m.psnr.push_back(psnr(render, gt));
      m.ssim.push_back(ssim(render, gt, opt_.eval_ssim));
      if (opt_.exposure) {
        const Image<float> cc = colour_correct(render, gt);
        m.psnr_cc.push_back(psnr(cc, gt));
        m.ssim_cc.push_back(ssim(cc, gt, opt_.eval_ssim));
      }
    }
    out.push_back(std::move(m));
  }
  times_.eval += seconds(t0, std::chrono::steady_clock::now());
  return out;
}

template <class G>
void Trainer<G>::record_curve(long long step) {
  const auto t0 = std::chrono::steady_clock::now();
  CurvePoint p;
  p.seconds = opt_.clock_offset + clock_;
  p.step = step;
  p.gaussians = model_.size();
  Rasterizer<G, float, kTrainRaster> raster;
  for (const auto& band : bands_) {
    p.bands.push_back(band.id);
    double sp = 0, ss = 0;
    const std::vector<std::size_t> pick = curve_subset(band.eval_frames.size(), opt_.curve.images);
    for (std::size_t k : pick) {
      const std::size_t f = band.eval_frames[k];
      const Image<float> render = eval_render(raster, curve_images_, band, f);
      const Image<float>& gt = curve_images_.get(f, 1);
      sp += psnr(render, gt);
      ss += ssim(render, gt, opt_.eval_ssim);
    }
    const double n = double(pick.size());
    p.psnr.push_back(pick.empty() ? std::nan("") : sp / n);
    p.ssim.push_back(pick.empty() ? std::nan("") : ss / n);
  }
  curve_.push_back(std::move(p));
  times_.eval += seconds(t0, std::chrono::steady_clock::now());
}

}  // namespace msgs
