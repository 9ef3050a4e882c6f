// examples/cmd_eval.cpp
// `msgs eval`: per-band PSNR / SSIM of a trained model on the eval split, in the paper's table
// layout, with a contact sheet (ground truth | render | error) per eval capture.
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "data_options.hpp"
#include "render_dispatch.hpp"
#include "report.hpp"

namespace cmd_eval {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs eval --data DIR --model PLY|DIR [--out DIR] [--bands LIST] [--orient none|center] [--no-sheets]\n"
    "                 [--images NAME] [--eval-every N] [--ssim valid|same]\n"
    "\n"
    "Evaluate a trained model on the dataset's eval split at full resolution, with the reference\n"
    "evaluation background (grey 0.1490, 0.1647, 0.2157; its luminance for single bands) and renders\n"
    "clamped to [0, 1]. Writes to DIR (default: <model directory>/eval):\n"
    "  eval.json           per-band PSNR / SSIM (every image, mean, std), per-frame values\n"
    "  eval.md             the table in the paper's layout (All, RGB, G, R, RE, NIR)\n"
    "  sheets/sheet_<n>.png  per eval capture: a row per band of ground truth | render | error,\n"
    "                      then CIR, NDVI and NDRE of ground truth | render | difference\n"
    "LPIPS is not computed: it needs pretrained network weights that cannot be obtained offline.\n"
    "\n"
    MSGS_DATA_OPTIONS_USAGE
    "  --model PLY|DIR     a model PLY or a directory of model_*.ply files (see `msgs render --help`)\n"
    "  --bands LIST        only these bands (comma separated ids)\n"
    "  --orient none       the model was trained with --orient none (or --no-orient)\n"
    "  --no-sheets         metrics only\n"
    "  --ssim W            valid (default: SSIM over the 11x11 windows inside the image, pytorch-msssim,\n"
    "                      as the reference implementation and `msgs train`) or same (3DGS: zero padding)\n";

constexpr const char* kLpipsNote =
    "LPIPS is not computed: it needs pretrained network weights, which cannot be obtained offline.";

using msgs::cli::split_list;

int run_eval(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(argv, {"data", "images", "eval-every", "model", "out", "bands", "orient", "ssim"}, {"help", "no-orient", "no-sheets"});
  if (args.flag("help")) { std::fputs(kUsage, stdout); return 0; }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  namespace fs = std::filesystem;
  const fs::path data = args.require("data"), model = args.require("model");
  std::error_code ec;
  const fs::path model_dir = fs::is_directory(model, ec) ? model : model.parent_path();
  const fs::path out = args.has("out") ? fs::path(args.get("out")) : (model_dir.empty() ? fs::path(".") : model_dir) / "eval";

  msgs::io::LoadOptions lo;
  lo.orient_and_center = msgs::cli::orient_and_center(args);
  lo.bands = split_list(args.get("bands"));
  lo.load_points = false;
  const msgs::io::Dataset ds = msgs::cli::load_data(args, lo, "eval");
  const msgs::ModelSet models = msgs::ModelSet::load(model, msgs::cli::make_any_renderer);

  msgs::OutputStage stage(out);
  msgs::EvalOptions opt;
  opt.sheets = !args.flag("no-sheets");
  const std::string ssim_mode = args.get("ssim", "valid");
  if (ssim_mode != "valid" && ssim_mode != "same") throw msgs::cli::UsageError("--ssim must be valid or same, got '" + ssim_mode + "'");
  opt.ssim_border = ssim_mode == "valid" ? msgs::SsimBorder::valid : msgs::SsimBorder::same;
  opt.on_progress = [](std::size_t done, std::size_t total) {
    std::fprintf(stderr, "\revaluating capture %zu/%zu ", done, total);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };
  if (opt.sheets) fs::create_directories(stage.dir() / "sheets");
  const msgs::EvalResult res = msgs::evaluate_models(ds, models, opt.sheets ? stage.dir() / "sheets" : fs::path{}, opt);

  nlohmann::json j;
  j["data"] = data.string();
  nlohmann::json jm = nlohmann::json::array();
  for (const auto& m : models.models())
    jm.push_back({{"path", m->path.string()}, {"channels", m->channels()}, {"sh_degree", m->sh_degree()},
                  {"gaussians", m->size()}, {"band_names", m->info.band_names}});
  j["models"] = jm;
  j["background"] = {{"rgb", msgs::eval_background<double>(3)}, {"single_band", msgs::eval_background<double>(1)}};
  j["metrics"] = msgs::cli::metrics_json(res.metrics);
  nlohmann::json frames = nlohmann::json::object();
  for (std::size_t b = 0; b < res.metrics.size(); ++b) {
    nlohmann::json list = nlohmann::json::array();
    for (std::size_t i = 0; i < res.frames[b].size(); ++i)
      list.push_back({{"file_path", res.frames[b][i]}, {"psnr", res.metrics[b].psnr[i]}, {"ssim", res.metrics[b].ssim[i]}});
    frames[res.metrics[b].band] = list;
  }
  j["frames"] = frames;
  j["skipped_bands"] = res.skipped_bands;
  j["sheets"] = res.files;
  msgs::io::write_text_atomic(stage.dir() / "eval.json", j.dump(2) + "\n");

  const std::string table = msgs::cli::metrics_markdown(res.metrics);
  std::string md = "# Evaluation\n\nData: `" + data.string() + "`, model: `" + model.string() +
                   "`. Eval split at full resolution, evaluation background grey (0.1490, 0.1647, 0.2157) "
                   "and its BT.601 luminance for single bands, renders clamped to [0, 1], SSIM over " + ssim_mode +
                   " windows; mean ± standard deviation "
                   "over the eval images of each band; All is the mean of the band means.\n\n" +
                   table + "\n" + kLpipsNote + "\n";
  if (!res.skipped_bands.empty()) {
    md += "\nNot evaluated (no model renders them):";
    for (const auto& b : res.skipped_bands) md += " " + b;
    md += "\n";
  }
  if (!res.files.empty())
    md += "\nContact sheets (`sheets/`): one per eval capture; a row per band of ground truth | render | error "
          "(mean absolute error, black 0 to white 0.25), then colour infrared (NIR, R, G as RGB), NDVI and NDRE "
          "(red -1, yellow 0, green +1) of ground truth | render from the NIR camera | difference (white 0.5).\n";
  msgs::io::write_text_atomic(stage.dir() / "eval.md", md);
  stage.commit();

  std::printf("%s%s\n", table.c_str(), kLpipsNote);
  if (!res.skipped_bands.empty()) {
    std::printf("not evaluated (no model renders them):");
    for (const auto& b : res.skipped_bands) std::printf(" %s", b.c_str());
    std::printf("\n");
  }
  std::printf("wrote %s, %s and %zu contact sheet(s)\n", (out / "eval.json").string().c_str(),
              (out / "eval.md").string().c_str(), res.files.size());
  return 0;
}

}  // namespace
}  // namespace cmd_eval

MSGS_COMMAND("eval", "Per-band PSNR / SSIM of a model on the eval split, with contact sheets", cmd_eval::run_eval);
