// examples/cmd_train.cpp
// `msgs train`: train a strategy on a dataset and write models, configuration and per-band metrics.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <msgs/io/file.hpp>

#include "commands.hpp"
#include "data_options.hpp"
#include "experiment.hpp"
#include "live_view.hpp"
#include "memory_guard.hpp"
#include "render_dispatch.hpp"
#include "report.hpp"
#include "run_sheets.hpp"
#include "train_options.hpp"

namespace cmd_train {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs train --data DIR --out DIR [--strategy NAME] [--scale F] [--sh-degree D]\n"
    "                  [--bands D,MS_G,...] [--seed S] [--orient none|center] [--resume] [--checkpoint-every N]\n"
    "                  [--sheets N] [--max-gaussians N] [--stop-gaussians N] [--images NAME] [--eval-every N]\n"
    "                  [--geometry-band ID] [--reorder-every N] [--densify msgs|gsplat] [--num-downscales N]\n"
    "                  [--exposure [--lr-exposure X]] [--preset reference|fast] [--ssim valid|same]\n"
    "                  [--no-clamp] [--shuffle every-pass|once] [--adam sparse|dense] [--lr-sh-dc X]\n"
    "                  [--spectral-init on|off]\n"
    "                  [--eval-every-seconds T] [--eval-every-steps N] [--eval-images K]\n"
    "                  [--view [PORT] [--host H]]\n"
    "\n"
    "Train Gaussian splats on a multi-spectral dataset (nerfstudio-style layout, or a COLMAP scene) with one of the\n"
    "paper's strategies, evaluate every band on the eval split and write to DIR:\n"
    "  model_<key>.ply   one per model (joint, or one per band for separate/split)\n"
    "  result.json       configuration, per-band metrics, Gaussian counts, time per stage\n"
    "  metrics.md        the per-band table in the paper's layout\n"
    "  curve.csv         with --eval-every-seconds/-steps: seconds, step, model, Gaussians, band,\n"
    "                    PSNR, SSIM of every anytime evaluation, plus the run's All rows\n"
    "  sheets/sheet_<n>.png  contact sheets of the first N eval captures (see --sheets), after a\n"
    "                    finished run: a row per band of ground truth | render | error, then CIR,\n"
    "                    NDVI and NDRE of ground truth | render | difference (as `msgs eval`)\n"
    "\n"
    MSGS_DATA_OPTIONS_USAGE
    "  --strategy NAME   separate | split | split+extadc | joint[+sig][+specdelay][+extadc|+msad]\n"
    "                    or joint-optimized (= joint+specdelay+msad, the default)\n"
    "  --scale F         multiply every iteration count of the paper's schedule (default 0.05:\n"
    "                    a 6000-step Joint run)\n"
    "  --sh-degree D     spherical-harmonics degree 0..3 (default 3)\n"
    "  --densify P       msgs (default: the multi-spectral implementation's ADC, absgrad 0.0008, prune\n"
    "                    opacity < 0.1, reset to 0.2) or gsplat (3DGS/gsplat: grad 0.0002, prune < 0.005,\n"
    "                    reset to 0.01); MSAD and ExtADC modify either as in the paper\n"
    "  --bands LIST      train only these bands (comma separated ids)\n"
    "  --geometry-band ID  the band SpecDelay trains first, SIG lets move geometry and Split copies\n"
    "                    geometry from (default D, the RGB camera; a capture without one names\n"
    "                    another, e.g. MS_NIR); other strategies ignore it\n"
    "  --max-gaussians N densification grows each model to at most N Gaussians, largest\n"
    "                    gradients first (default 0: no limit)\n"
    "  --stop-gaussians N stop the run with an error when a refinement would grow a model beyond\n"
    "                    N Gaussians (default: what fits in three quarters of the memory available\n"
    "                    at the start; 0 = never). Runaway densification then ends with a message\n"
    "                    instead of running out of memory; below the limit results are unchanged\n"
    "  --reorder-every N sort the Gaussians into spatial order at every N-th refinement and at the\n"
    "                    last before a pause or the end of densification, so that the Gaussians a\n"
    "                    view sees are neighbours in memory (default 8; 0 keeps gsplat's row\n"
    "                    order). A speed setting only: the trained Gaussians are the same, bit\n"
    "                    for bit, in another order\n"
    MSGS_TRAIN_OPTIONS_USAGE
    "  --exposure        learn a per-image exposure correction: a gain exp(a_c) and an offset b_c per\n"
    "                    channel of every training image, applied to its render before the loss\n"
    "                    (Adam, only the sampled image's values per step; each band's mean log-gain\n"
    "                    and offset are held at 0, so the model keeps the images' average\n"
    "                    radiometry). Eval images have no correction: they\n"
    "                    are scored on the plain render and, in addition, colour-corrected (PSNR/SSIM\n"
    "                    after the least-squares affine per image and channel onto the ground truth);\n"
    "                    result.json gets the learned gains and offsets. Default off\n"
    "  --lr-exposure X   Adam learning rate of the log-gains and offsets (default 0.001; each image\n"
    "                    is stepped only when it is sampled, so short schedules need more, e.g. 0.02)\n"
    "  --seed S          seed of sampling, backgrounds and initial colours (default 0)\n"
    "  --orient MODE     center (default: mean camera up -> +z, mean camera position -> origin,\n"
    "                    recorded as `transform` in result.json) or none (keep the dataset's coordinates;\n"
    "                    --no-orient is the same)\n"
    "  --checkpoint-every N  also checkpoint every N steps (always at the end and on Ctrl-C)\n"
    "  --sheets N        contact sheets of the first N eval captures in the dataset's frame order\n"
    "                    (default 3; 0 = none); written after result.json, which they do not change\n"
    "  --resume          continue from DIR/checkpoints/*.ckpt; the result equals an uninterrupted run\n"
    "  --view [PORT]     serve the `msgs view` page on the models while they train, at\n"
    "                    http://127.0.0.1:PORT/ (default 8080; 0 = any free port, printed): a snapshot\n"
    "                    of the model at most every second, the dataset's cameras and ground truth;\n"
    "                    with separate/split, the band models trained so far. Results are the same\n"
    "                    with and without it. When the run finishes the viewer keeps serving until\n"
    "                    Ctrl-C; a busy port is an error before training starts. The msgs view\n"
    "                    API, plus /api/live: state, step and models so far as JSON\n"
    "  --host H          address --view listens on (default 127.0.0.1; see msgs view --help)\n"
    "Ctrl-C stops after the current step, writes a checkpoint, the models and the metrics (no sheets);\n"
    "run the same command with --resume to continue (with --view, Ctrl-C during training also stops the\n"
    "viewer).\n"
    "Threads: OMP_NUM_THREADS (default: every core); the result is the same, bit for bit, for any count.\n";

std::atomic<bool> g_stop{false};
void on_sigint(int) { g_stop.store(true); }

using msgs::cli::split_list;

int run_train(const std::vector<std::string>& argv) {
  std::vector<std::string> values = {"data", "images", "eval-every", "out", "strategy", "scale", "sh-degree", "bands", "seed",
                                     "checkpoint-every", "orient", "densify", "sheets", "max-gaussians", "stop-gaussians", "reorder-every", "geometry-band",
                                     "lr-exposure", "view", "host"};
  std::vector<std::string> flags = {"help", "no-orient", "quiet", "resume", "exposure"};
  for (const auto& k : msgs::cli::train_option_values()) values.push_back(k);
  for (const auto& k : msgs::cli::train_option_flags()) flags.push_back(k);
  const msgs::cli::Args args(msgs::cli::view_option_argv(argv), values, flags);
  if (args.flag("help")) { std::fputs(kUsage, stdout); return 0; }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  const std::filesystem::path data = args.require("data"), out = args.require("out");
  msgs::RunConfig cfg;
  cfg.strategy = args.get("strategy", "joint+specdelay+msad");
  cfg.scale = args.number("scale", 0.05);
  if (!(cfg.scale > 0)) throw msgs::cli::UsageError("--scale must be > 0");
  const long deg = args.integer("sh-degree", 3);
  if (deg < 0 || deg > 3) throw msgs::cli::UsageError("--sh-degree must be 0..3");
  cfg.bands = split_list(args.get("bands"));
  cfg.geometry_band = args.get("geometry-band", "D");
  msgs::cli::apply_train_options(args, cfg);
  cfg.train.seed = std::uint64_t(args.integer("seed", 0));
  cfg.train.exposure = args.flag("exposure");
  if (args.has("lr-exposure") && !cfg.train.exposure) throw msgs::cli::UsageError("--lr-exposure needs --exposure");
  cfg.train.lr_exposure = args.number("lr-exposure", cfg.train.lr_exposure);
  if (!(std::isfinite(cfg.train.lr_exposure) && cfg.train.lr_exposure >= 0))
    throw msgs::cli::UsageError("--lr-exposure must be a finite number >= 0");
  cfg.init.seed = std::uint32_t(cfg.train.seed);
  cfg.resume = args.flag("resume");
  try {
    cfg.densify = msgs::parse_densify_preset(args.get("densify", "msgs"));
  } catch (const std::invalid_argument& e) {
    throw msgs::cli::UsageError(e.what());
  }
  const long cap = args.integer("max-gaussians", 0);
  if (cap < 0) throw msgs::cli::UsageError("--max-gaussians must be >= 0 (0 = no limit)");
  cfg.max_gaussians = std::size_t(cap);
  const long stop = args.integer("stop-gaussians", 0);
  if (stop < 0) throw msgs::cli::UsageError("--stop-gaussians must be >= 0 (0 = never)");
  cfg.stop_gaussians = std::size_t(stop);
  const long reorder = args.integer("reorder-every", cfg.reorder_every);
  if (reorder < 0 || reorder > 1000000) throw msgs::cli::UsageError("--reorder-every must be in 0..1000000 (0 = never)");
  cfg.reorder_every = int(reorder);
  const long every = args.integer("checkpoint-every", 0);
  if (every < 0) throw msgs::cli::UsageError("--checkpoint-every must be >= 0");
  cfg.train.checkpoint_every = int(every);
  const long sheets = args.integer("sheets", msgs::cli::default_run_sheets);
  if (sheets < 0) throw msgs::cli::UsageError("--sheets must be >= 0 (0 = no contact sheets)");
  const int max_sheets = int(std::min<long>(sheets, std::numeric_limits<int>::max()));
  try {
    (void)msgs::parse_strategy(cfg.strategy, msgs::ScheduleScale{cfg.scale});
  } catch (const std::invalid_argument& e) {
    throw msgs::cli::UsageError(e.what());
  }

  msgs::io::LoadOptions lo;
  lo.orient_and_center = msgs::cli::orient_and_center(args);
  const msgs::io::Dataset ds = msgs::cli::load_data(args, lo, "train");

  msgs::validate_run(ds, cfg);  // before anything is written: missing bands, no geometry band
  std::vector<std::string> band_ids = cfg.bands.empty() ? ds.bands() : cfg.bands;
  // Runaway densification stops with an error before memory runs out (--stop-gaussians, parsed
  // above, replaces the limit derived from the available memory).
  if (!args.has("stop-gaussians")) cfg.stop_gaussians = msgs::cli::default_stop_gaussians(cfg.strategy, band_ids, int(deg));
  msgs::SnapshotStore snapshots;  // --view: the models as they train
  const std::unique_ptr<msgs::cli::LiveView> live = msgs::cli::start_live_view(args, ds, snapshots, cfg, band_ids.size());
  const bool quiet = args.flag("quiet");
  cfg.train.on_progress = [&](const msgs::TrainProgress& p) {
    if (!quiet) msgs::cli::print_progress(p);
  };
  cfg.train.stop = &g_stop;
  std::signal(SIGINT, on_sigint);

  std::filesystem::create_directories(out);
  std::fprintf(stderr, "msgs train: %s on %s (%zu frames, bands", msgs::parse_strategy(cfg.strategy).plan.name.c_str(),
               data.string().c_str(), ds.frames.size());
  for (const auto& b : band_ids) std::fprintf(stderr, " %s", b.c_str());
  std::fprintf(stderr, "), schedule scale %g, SH degree %ld\n", cfg.scale, deg);
  const msgs::RunResult res = msgs::cli::run_experiment_any(int(deg), ds, cfg, out);
  std::signal(SIGINT, SIG_DFL);

  nlohmann::json j = msgs::cli::result_json(res);
  j["data"] = data.string();
  j["sh_degree"] = deg;
  j["seed"] = cfg.train.seed;
  j["lr_sh_dc"] = cfg.train.adam.lr_sh_dc;
  j["adam"] = cfg.train.sparse ? "sparse" : "dense";
  j["options"] = msgs::cli::train_options_json(args, cfg);
  j["geometry_band"] = cfg.geometry_band;
  j["layout"] = msgs::io::detect_scene(data).describe(data);
  j["images"] = args.get("images", "images");
  j["eval_images"] = std::count_if(ds.frames.begin(), ds.frames.end(),
                                   [](const msgs::io::Frame& f) { return f.split == msgs::io::Split::eval; });
  if (cfg.train.exposure) j["lr_exposure"] = cfg.train.lr_exposure;
  j["transform"] = std::vector<float>(ds.transform.data(), ds.transform.data() + 16);
  if (!res.curve.empty()) msgs::io::write_text_atomic(out / "curve.csv", msgs::cli::curve_csv(res));
  msgs::io::write_text_atomic(out / "result.json", j.dump(2) + "\n");
  const std::string table = msgs::cli::metrics_markdown(res.metrics);
  msgs::io::write_text_atomic(out / "metrics.md", "# " + res.strategy + "\n\n" + table);
  std::printf("\n%s  (%lld steps, %.1f s; %.1f s of training)\n%s", res.strategy.c_str(), res.steps, res.seconds,
              res.train_seconds, table.c_str());
  std::printf("Gaussians:");
  for (const auto& [k, n] : res.gaussians) std::printf(" %s %zu", k.c_str(), n);
  const auto& t = res.times;
  std::printf("\ntime (s): project %.1f  bin %.1f  blend %.1f  loss %.1f  backward %.1f (blend %.1f, Gaussians %.1f)  adam %.1f  "
              "densify %.1f (refine %.1f)  load %.1f  eval %.1f\n",
              t.project, t.bin, t.blend, t.loss, t.backward, t.backward_blend, t.backward_gaussians, t.adam, t.densify,
              t.refine, t.load, t.eval);
  for (const auto& [model, e] : res.exposure_params) {
    double gmin = 1e300, gmax = -1e300;
    for (const auto& g : e.gain)
      for (double x : g) { gmin = std::min(gmin, x); gmax = std::max(gmax, x); }
    std::printf("exposure gains %s/%s: %.3f .. %.3f over %zu training images\n", model.c_str(), e.band.c_str(), gmin, gmax,
                e.files.size());
  }
  std::printf("LPIPS: not computed (needs pretrained network weights, unavailable offline)\n");
  if (res.interrupted)
    std::printf("interrupted: models and metrics reflect the state at the stop; continue with --resume\n");
  std::printf("wrote %s\n", (out / "result.json").string().c_str());
  std::fflush(stdout);

  // After result.json: the sheets are extra, a failure here must not lose the run's record.
  try {
    const msgs::cli::RunSheets sh = msgs::cli::write_run_sheets(ds, res, out, max_sheets, msgs::cli::make_any_renderer);
    if (!sh.files.empty()) std::printf("wrote %zu contact sheet(s) to %s\n", sh.files.size(), (out / "sheets").string().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "msgs train: warning: contact sheets not written: %s\n", e.what());
  }
  if (live) msgs::cli::serve_after_run(*live, snapshots, res.interrupted, g_stop, on_sigint);
  return res.interrupted ? 130 : 0;
}

}  // namespace
}  // namespace cmd_train

MSGS_COMMAND("train", "Train a strategy (separate, split, joint+...) on a dataset", cmd_train::run_train);
