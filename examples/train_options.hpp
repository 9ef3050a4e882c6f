// examples/train_options.hpp: the training options `msgs train` takes and `msgs study` passes on to
// its runs: the preset (reference or fast), the reference-parity switches on top of it, and the
// anytime evaluation (quality against training time).
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include <msgs/presets.hpp>
#include <msgs/run.hpp>

#include "commands.hpp"

namespace msgs::cli {

/// Usage lines of the shared training options (a string literal, to join a command's usage text).
#define MSGS_TRAIN_OPTIONS_USAGE \
    "  --preset P        reference (default: the multi-spectral reference implementation in every\n" \
    "                    detail: renders clamped to [0, 1] before the loss, SSIM over valid 11x11\n" \
    "                    windows, each band's images reshuffled on every pass) or fast (CPU budgets:\n" \
    "                    the reference plus a colour learning rate that follows --scale and narrow\n" \
    "                    bands started from the geometry band's colours; see README)\n" \
    "  --ssim W          valid (reference, pytorch-msssim) or same (3DGS: zero-padded borders), in\n" \
    "                    the loss and the evaluation\n" \
    "  --no-clamp        the loss sees the raw render (3DGS) instead of the render clamped to [0, 1]\n" \
    "  --shuffle S       every-pass (reference: each band's images reshuffled when used up) or once\n" \
    "  --lr-sh-dc X      Adam learning rate of the SH DC (base colour) coefficients (reference\n" \
    "                    0.0025; the fast preset scales it with --scale)\n" \
    "  --spectral-init S on (the fast preset: narrow bands start from the geometry band's\n" \
    "                    luminance at their own brightness when they start training) or off\n" \
    "                    (reference: random colours)\n" \
    "  --adam MODE       dense (reference: every Gaussian each step, zero gradient where the view did\n" \
    "                    not see it, as torch's Adam) or sparse (gradients, Adam and the scale\n" \
    "                    regulariser only for the Gaussians the view saw: faster, a different\n" \
    "                    optimisation, which trains worse at CPU schedules: see README)\n" \
    "  --num-downscales N  training images start at 1/2^N of their resolution and double every 3000\n" \
    "                    steps (scaled; default 2, splatfacto's); 0 = full resolution throughout\n" \
    "  --eval-every-seconds T  anytime evaluation: every T seconds of training, PSNR / SSIM per band\n" \
    "                    on a fixed subset of the eval split (its time is kept off the training\n" \
    "                    clock); result.json gets the curve, and curve.csv is written\n" \
    "  --eval-every-steps N    the same every N steps (both may be given)\n" \
    "  --eval-images K   eval images per band of the anytime evaluation, spread evenly over the\n" \
    "                    eval split (default 4; 0 = all)\n"

/// The option names of MSGS_TRAIN_OPTIONS_USAGE that take a value, and the flags.
inline const std::vector<std::string>& train_option_values() {
  static const std::vector<std::string> v = {"preset", "ssim", "shuffle", "lr-sh-dc", "spectral-init", "adam",
                                             "eval-every-seconds", "eval-every-steps", "eval-images",
                                             "num-downscales"};
  return v;
}
inline const std::vector<std::string>& train_option_flags() {
  static const std::vector<std::string> v = {"no-clamp"};
  return v;
}

/// Set cfg.train from the preset and the switches given in `args` (cfg.scale must be set).
inline void apply_train_options(const Args& args, RunConfig& cfg) {
  Preset preset;
  try {
    preset = parse_preset(args.get("preset", "reference"));
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
  apply_preset(preset, cfg.train, cfg.scale);
  if (args.has("ssim")) {
    const std::string s = args.get("ssim");
    if (s != "valid" && s != "same") throw UsageError("--ssim must be valid or same, got '" + s + "'");
    cfg.train.loss.ssim_border = cfg.train.eval_ssim = s == "valid" ? SsimBorder::valid : SsimBorder::same;
  }
  if (args.flag("no-clamp")) cfg.train.clamp_render = false;
  if (args.has("shuffle")) {
    const std::string s = args.get("shuffle");
    if (s != "every-pass" && s != "once") throw UsageError("--shuffle must be every-pass or once, got '" + s + "'");
    cfg.train.shuffle = s == "once" ? Shuffle::once : Shuffle::every_pass;
  }
  cfg.train.adam.lr_sh_dc = args.number("lr-sh-dc", cfg.train.adam.lr_sh_dc);
  if (!(std::isfinite(cfg.train.adam.lr_sh_dc) && cfg.train.adam.lr_sh_dc > 0))
    throw UsageError("--lr-sh-dc must be a finite number > 0");
  if (args.has("spectral-init")) {
    const std::string s = args.get("spectral-init");
    if (s != "on" && s != "off") throw UsageError("--spectral-init must be on or off, got '" + s + "'");
    cfg.train.spectral_colour_init = s == "on";
  }
  if (args.has("adam")) {
    const std::string m = args.get("adam");
    if (m != "sparse" && m != "dense") throw UsageError("--adam must be sparse or dense, got '" + m + "'");
    cfg.train.sparse = m == "sparse";
  }
  cfg.train.curve.every_seconds = args.number("eval-every-seconds", 0);
  if (!(std::isfinite(cfg.train.curve.every_seconds) && cfg.train.curve.every_seconds >= 0))
    throw UsageError("--eval-every-seconds must be a number >= 0 (0 = off)");
  const long steps = args.integer("eval-every-steps", 0);
  if (steps < 0) throw UsageError("--eval-every-steps must be >= 0 (0 = off)");
  cfg.train.curve.every_steps = steps;
  const long images = args.integer("eval-images", 4);
  if (images < 0 || images > 100000) throw UsageError("--eval-images must be between 0 (all) and 100000");
  cfg.train.curve.images = int(images);
  if (args.has("num-downscales")) {
    const long d = args.integer("num-downscales", 2);
    if (d < 0 || d > 8) throw UsageError("--num-downscales must be 0..8 (0 = full resolution from the first step)");
    cfg.num_downscales = int(d);
  }
}

/// The training options of `args` as command-line words, to pass on to a run (job lines).
inline std::vector<std::string> train_option_words(const Args& args) {
  std::vector<std::string> w;
  for (const auto& k : train_option_values())
    if (args.has(k)) { w.push_back("--" + k); w.push_back(args.get(k)); }
  for (const auto& k : train_option_flags())
    if (args.flag(k)) w.push_back("--" + k);
  return w;
}

/// What result.json records of the options: preset, its departures, the switches, the curve's period.
inline nlohmann::json train_options_json(const Args& args, const RunConfig& cfg) {
  const Preset preset = parse_preset(args.get("preset", "reference"));
  nlohmann::json dep = nlohmann::json::array();
  for (const auto& d : preset_departures(preset, cfg.scale)) dep.push_back({{"name", d.name}, {"what", d.what}});
  return {{"preset", to_string(preset)},
          {"departures", dep},
          {"ssim", cfg.train.loss.ssim_border == SsimBorder::valid ? "valid" : "same"},
          {"clamp_render", cfg.train.clamp_render},
          {"shuffle", cfg.train.shuffle == Shuffle::once ? "once" : "every-pass"},
          {"lr_sh_dc", cfg.train.adam.lr_sh_dc},
          {"adam", cfg.train.sparse ? "sparse" : "dense"},
          {"spectral_colour_init", cfg.train.spectral_colour_init},
          {"eval_every_seconds", cfg.train.curve.every_seconds},
          {"eval_every_steps", cfg.train.curve.every_steps},
          {"eval_images", cfg.train.curve.images}};
}

}  // namespace msgs::cli
