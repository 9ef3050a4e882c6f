// include/msgs/run.hpp
// One experiment end to end: a strategy (Separate, Split or Joint with modifiers) on a dataset,
// the models it trains, their per-band evaluation, Gaussian counts and time per stage.
#pragma once

#include <array>
#include <atomic>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "init.hpp"
#include "io/bands.hpp"
#include "io/dataset.hpp"
#include "io/ply.hpp"
#include "strategy.hpp"
#include "train.hpp"

namespace msgs {

/// Configuration of one experiment.
struct RunConfig {
  std::string strategy = "joint+specdelay+msad";  ///< run-time strategy name (see strategy_names())
  double scale = 1.0;                 ///< schedule scale: multiplies every iteration count
  /// Density control the modifiers start from: the multi-spectral implementation's (default) or
  /// gsplat's / 3DGS's. MSAD and ExtADC then change it as in the paper.
  DensifyPreset densify = DensifyPreset::MultiSpectral;
  std::vector<std::string> bands;     ///< bands to train (empty: every band of the dataset)
  /// The band whose steps shape the geometry where a strategy distinguishes one: SpecDelay trains it
  /// alone first, SIG lets only it move geometry, Split copies its model's geometry into the other
  /// bands' models. The RGB camera "D" by default; captures without one name another band (e.g. a
  /// MicaSense rig: "MS_NIR"). Strategies that treat every band alike ignore it.
  std::string geometry_band = "D";
  /// Most Gaussians densification may grow each model to (DensifyConfig::max_gaussians; 0 = no limit).
  std::size_t max_gaussians = 0;
  /// Stop the run with DensifyLimitError when a refinement would grow a model beyond this many
  /// Gaussians (DensifyConfig::stop_gaussians; 0 = never). Changes no result.
  std::size_t stop_gaussians = 0;
  /// Sort the models into spatial order at every reorder_every-th refinement and at the last one
  /// before a pause or the end of densification (DensifyConfig::reorder_every; 0 = never, keeping
  /// gsplat's row order). A speed setting only: the trained Gaussians are the same, bit for bit,
  /// in another row order.
  int reorder_every = 8;
  /// Resolution schedule: training images start downscaled by 2^num_downscales and double in
  /// resolution every `resolution_every` steps (TrainSchedule); -1 keeps the strategy's
  /// (splatfacto's 2, a quarter of the resolution at first), 0 trains at full resolution throughout.
  int num_downscales = -1;
  TrainOptions train{};               ///< seed, learning rates, callbacks
  InitConfig init{};                  ///< initialisation from the sparse point cloud
  std::size_t random_init_points = 20000;  ///< used when the dataset has no point cloud
  /// Keep checkpoints in <out_dir>/checkpoints/<model>.ckpt (every train.checkpoint_every steps,
  /// at the end and when stopped) and, with `resume`, continue each model from its checkpoint:
  /// the result is the same, bit for bit, as an uninterrupted run.
  bool checkpoints = true;
  bool resume = false;
};

/// Result of one experiment.
struct RunResult {
  std::string strategy;                          ///< canonical name
  TrainPlan plan;                                ///< the resolved plan
  std::vector<BandMetrics> metrics;              ///< per band, eval split
  std::map<std::string, std::size_t> gaussians;  ///< Gaussians per model ("joint", or the band id)
  std::map<std::string, std::filesystem::path> models;  ///< model files written, per model
  StageTimes times;                              ///< summed over every model
  double seconds = 0;                            ///< wall time of the whole run
  long long steps = 0;                           ///< optimisation steps over every model
  bool interrupted = false;                      ///< stopped early by TrainOptions::stop
  bool exposure = false;                         ///< per-image exposure correction learned (TrainOptions::exposure)
  /// With exposure: the learned gains and offsets per model and band (model key, as `gaussians`).
  std::vector<std::pair<std::string, BandExposure>> exposure_params;
  /// Anytime evaluations of every model in training order (TrainOptions::curve), seconds on the
  /// run's training clock.
  std::vector<CurvePoint> curve;
  /// The run's training clock at the end: seconds of training over every model, anytime
  /// evaluations and final evaluation excluded.
  double train_seconds = 0;
};

namespace detail {

/// The bands of a dataset a run trains, in the standard order, with their Joint channel layout;
/// every band but `geometry_band` counts as spectral.
inline std::vector<TrainBand> run_bands(const io::Dataset& ds, const std::vector<std::string>& wanted,
                                        const std::string& geometry_band = "D") {
  std::vector<TrainBand> out;
  for (const std::string& id : ds.bands()) {
    if (!wanted.empty() && std::find(wanted.begin(), wanted.end(), id) == wanted.end()) continue;
    const io::BandInfo* info = io::find_band(id);
    TrainBand b;
    b.id = id;
    b.first_channel = info->first_channel_in_joint;
    b.channels = info->channels;
    b.spectral = id != geometry_band;
    for (std::size_t i : ds.frames_of(id, io::Split::train)) b.train_frames.push_back(i);
    for (std::size_t i : ds.frames_of(id, io::Split::eval)) b.eval_frames.push_back(i);
    if (b.train_frames.empty()) throw std::invalid_argument("dataset " + ds.root.string() + ": band " + id + " has no training images");
    out.push_back(std::move(b));
  }
  for (const auto& w : wanted)
    if (std::none_of(out.begin(), out.end(), [&](const TrainBand& b) { return b.id == w; }))
      throw std::invalid_argument("dataset " + ds.root.string() + " has no band '" + w + "'");
  if (out.empty()) throw std::invalid_argument("dataset " + ds.root.string() + " has no bands to train");
  return out;
}

/// Why a strategy needs a geometry band ("" when it does not).
inline std::string geometry_band_role(const TrainPlan& p) {
  if (p.kind == StrategyKind::Split) return "Split trains it first and copies its geometry into every other band's model";
  if (p.sig) return "SIG lets only its steps move geometry";
  if (p.spectral_start > 0) return "SpecDelay trains it alone first";
  return "";
}

}  // namespace detail

/// Check before training that `cfg` can run on `ds`: the strategy and the schedule scale resolve,
/// the requested bands exist and have training images, and a strategy that needs a geometry band
/// (Split, SpecDelay, SIG) finds `cfg.geometry_band` among the bands it trains. Throws
/// std::invalid_argument naming what is missing and the ways out. run_experiment calls it too.
inline void validate_run(const io::Dataset& ds, const RunConfig& cfg) {
  ScheduleScale scale{cfg.scale};
  scale.validate();
  const StrategySpec spec = parse_strategy(cfg.strategy, scale, cfg.densify);
  const std::vector<TrainBand> bands = detail::run_bands(ds, cfg.bands, cfg.geometry_band);
  const std::string role = detail::geometry_band_role(spec.plan);
  if (role.empty()) return;
  std::string have;
  for (const auto& b : bands) have += (have.empty() ? "" : ", ") + b.id;
  if (std::none_of(bands.begin(), bands.end(), [&](const TrainBand& b) { return b.id == cfg.geometry_band; })) {
    const bool rgb = cfg.geometry_band == "D";
    throw std::invalid_argument(
        "strategy " + spec.plan.name + " needs a geometry band (" + role + "), and " +
        (rgb ? std::string("the default one, the RGB band D, ") : "band '" + cfg.geometry_band + "' ") +
        "is not among the bands to train (" + have + "). Ways out: --geometry-band ID with one of " + have +
        " (the band with the most texture, often MS_NIR or MS_G), or a strategy that needs none: separate, joint, "
        "joint+msad, joint+extadc");
  }
}

namespace detail {

/// Initial model from the dataset's sparse point cloud (or random points around the cameras).
template <class G>
GaussianModel<G, float> initial_model(const io::Dataset& ds, const RunConfig& cfg) {
  if (!ds.points.xyz.empty()) return init_from_points<G>(ds.points.xyz, cfg.init);
  std::array<float, 3> lo{std::numeric_limits<float>::max(), std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
  std::array<float, 3> hi{-lo[0], -lo[1], -lo[2]};
  for (const auto& f : ds.frames) {
    const auto p = f.camera.position();
    for (int a = 0; a < 3; ++a) { lo[std::size_t(a)] = std::min(lo[std::size_t(a)], p[a]); hi[std::size_t(a)] = std::max(hi[std::size_t(a)], p[a]); }
  }
  return init_random<G>(cfg.random_init_points, lo, hi, cfg.init);
}

/// Fresh colour for a band model made from another model's geometry (Split): SH DC uniform in
/// [0, 1), higher orders 0, as at initialisation.
template <class G>
void fresh_colour(GaussianModel<G, float>& m, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::fill(m.sh.begin(), m.sh.end(), 0.0f);
  for (std::size_t i = 0; i < m.size(); ++i)
    for (int c = 0; c < G::bands; ++c) m.sh_at(i, 0, c) = float(rng() >> 8) * 0x1p-24f;
}

/// Copy means, scales, rotations and opacities (Split).
template <class GA, class GB>
void copy_geometry(const GaussianModel<GA, float>& from, GaussianModel<GB, float>& to) {
  to.resize(from.size());
  to.means = from.means;
  to.log_scales = from.log_scales;
  to.quats = from.quats;
  to.opacity_logits = from.opacity_logits;
}

/// Channel names of a single-band model.
inline std::vector<std::string> channel_names(const TrainBand& b) {
  if (b.channels == 1) return {b.id};
  return {b.id + "_R", b.id + "_G", b.id + "_B"};
}

/// Train one model over `bands` for steps [begin, end), evaluate it and write its PLY.
template <class G>
GaussianModel<G, float> train_model(const io::Dataset& ds, std::vector<TrainBand> bands, GaussianModel<G, float> model,
                                    const StrategySpec& spec, const RunConfig& cfg, long long begin, long long end,
                                    const std::string& key, const std::filesystem::path& out_dir,
                                    const std::vector<std::string>& names, RunResult& res, std::int64_t adam_iteration) {
  TrainOptions topt = cfg.train;
  topt.clock_offset = res.train_seconds;
  std::filesystem::path ckpt;
  if (cfg.checkpoints && !out_dir.empty()) {
    std::filesystem::create_directories(out_dir / "checkpoints");
    ckpt = out_dir / "checkpoints" / (key + ".ckpt");
  }
  topt.checkpoint_path = ckpt;
  if (topt.on_step)  // tell the hook which model it sees
    topt.on_step = [hook = topt.on_step, key](const StepView& v) { StepView k = v; k.key = key; hook(k); };
  Trainer<G> tr(ds, std::move(bands), std::move(model), spec.plan, spec.hooks, topt);
  tr.adam().iteration = adam_iteration;
  if (cfg.resume && !ckpt.empty() && std::filesystem::exists(ckpt)) begin = tr.restore(load_checkpoint<G>(ckpt));
  const long long reached = begin >= end ? end : tr.train(begin, end);
  if (begin >= end && topt.on_step) topt.on_step(StepView::of(tr.model(), tr.bands(), end, begin, end));  // resumed, done
  res.steps += reached - begin;
  if (reached < end) res.interrupted = true;
  else tr.finish_curve(end);
  for (auto& m : tr.evaluate()) res.metrics.push_back(std::move(m));
  for (auto& e : tr.exposure_report()) res.exposure_params.emplace_back(key, std::move(e));
  for (CurvePoint p : tr.curve()) {
    p.model = key;
    res.curve.push_back(std::move(p));
  }
  res.train_seconds += tr.clock();
  res.times += tr.times();
  res.gaussians[key] = tr.model().size();
  if (!out_dir.empty()) {
    const auto path = out_dir / ("model_" + key + ".ply");
    io::write_ply<G>(path, tr.model(), names);
    res.models[key] = path;
  }
  return std::move(tr.model());
}

}  // namespace detail

/// Run one experiment with SH degree `SHDeg`. Writes model PLYs into `out_dir` (skipped when
/// empty). Joint trains one Gaussian<7, SHDeg>; Separate and Split train Gaussian<3, SHDeg> for
/// RGB and Gaussian<1, SHDeg> per narrow band.
template <int SHDeg>
RunResult run_experiment(const io::Dataset& ds, const RunConfig& cfg, const std::filesystem::path& out_dir = {}) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  ScheduleScale scale{cfg.scale};
  scale.validate();
  validate_run(ds, cfg);
  StrategySpec spec = parse_strategy(cfg.strategy, scale, cfg.densify);
  spec.plan.densify.max_gaussians = cfg.max_gaussians;
  spec.plan.densify.stop_gaussians = cfg.stop_gaussians;
  spec.plan.densify.reorder_every = cfg.reorder_every;
  if (cfg.num_downscales >= 0) spec.plan.schedule.num_downscales = cfg.num_downscales;
  RunResult res;
  res.exposure = cfg.train.exposure;
  res.strategy = spec.plan.name;
  res.plan = spec.plan;
  std::vector<TrainBand> bands = detail::run_bands(ds, cfg.bands, cfg.geometry_band);
  const long long stage = spec.plan.stage_steps;

  switch (spec.plan.kind) {
    case StrategyKind::Joint: {
      using G = Gaussian<7, SHDeg>;
      detail::train_model<G>(ds, bands, detail::initial_model<G>(ds, cfg), spec, cfg, 0, stage, "joint", out_dir,
                             io::joint_channel_names(), res, 0);
      break;
    }
    case StrategyKind::Separate: {
      for (TrainBand b : bands) {
        b.first_channel = 0;
        if (b.channels == 3) {
          using G = Gaussian<3, SHDeg>;
          detail::train_model<G>(ds, {b}, detail::initial_model<G>(ds, cfg), spec, cfg, 0, stage, b.id, out_dir,
                                 detail::channel_names(b), res, 0);
        } else {
          using G = Gaussian<1, SHDeg>;
          detail::train_model<G>(ds, {b}, detail::initial_model<G>(ds, cfg), spec, cfg, 0, stage, b.id, out_dir,
                                 detail::channel_names(b), res, 0);
        }
        if (res.interrupted) break;
      }
      break;
    }
    case StrategyKind::Split: {
      // The geometry band's model first (the RGB band D unless cfg.geometry_band names another),
      // then one model per other band from its geometry with fresh colour.
      TrainBand geo = *std::find_if(bands.begin(), bands.end(),
                                    [&](const TrainBand& b) { return b.id == cfg.geometry_band; });
      geo.first_channel = 0;
      using G3 = Gaussian<3, SHDeg>;
      using G1 = Gaussian<1, SHDeg>;
      auto band_models_from = [&](const auto& geo_model) {
        for (std::size_t i = 0; i < bands.size(); ++i) {
          TrainBand b = bands[i];
          if (b.id == geo.id || res.interrupted) continue;
          b.first_channel = 0;
          // The band model's step counter continues from the geometry stage (REFERENCE §4: "30k +
          // 30k"), so the position learning rate keeps decaying and ExtADC's 45k refers to it.
          auto train_from_geometry = [&](auto model) {
            using G = typename decltype(model)::gaussian_type;
            detail::copy_geometry(geo_model, model);
            if (cfg.train.spectral_colour_init) {
              // The fast preset: the band's colour from the geometry model's, at its brightness.
              ImageCache images(ds);
              const int factor = spec.plan.schedule.downscale(stage);
              set_colour_from_luminance(model, 0, b.channels, dc_luminance(geo_model, 0, geo.channels),
                                        mean_luminance(images, b, factor), mean_luminance(images, geo, factor));
            } else {
              detail::fresh_colour(model, cfg.init.seed + 1u + std::uint32_t(i));
            }
            detail::train_model<G>(ds, {b}, std::move(model), spec, cfg, stage, 2 * stage, b.id, out_dir,
                                   detail::channel_names(b), res, stage);
          };
          if (b.channels == 3) train_from_geometry(GaussianModel<G3, float>{});
          else train_from_geometry(GaussianModel<G1, float>{});
        }
      };
      if (geo.channels == 3)
        band_models_from(detail::train_model<G3>(ds, {geo}, detail::initial_model<G3>(ds, cfg), spec, cfg, 0, stage,
                                                 geo.id, out_dir, detail::channel_names(geo), res, 0));
      else
        band_models_from(detail::train_model<G1>(ds, {geo}, detail::initial_model<G1>(ds, cfg), spec, cfg, 0, stage,
                                                 geo.id, out_dir, detail::channel_names(geo), res, 0));
      break;
    }
  }
  res.seconds = std::chrono::duration<double>(clock::now() - t0).count();
  return res;
}

}  // namespace msgs
