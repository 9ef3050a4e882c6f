// examples/cmd_render.cpp
// `msgs render`: render a trained model (Joint PLY, RGB / single-band PLY or a directory of
// per-band PLYs) at every dataset camera, plus colour-infrared, NDVI and NDRE maps per capture.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "commands.hpp"
#include "data_options.hpp"
#include "render_dispatch.hpp"

namespace cmd_render {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs render --data DIR --model PLY|DIR --out DIR [--split train|eval|all] [--float]\n"
    "                   [--background V|V1,V2,..] [--sh-degree D] [--bands LIST] [--orient none|center]\n"
    "                   [--no-composites] [--no-legend] [--images NAME] [--eval-every N]\n"
    "\n"
    "Render every frame of the dataset (or one split) with its own camera at full resolution:\n"
    "  <stem>.png          8-bit PNG for the RGB band, 16-bit PNG for single bands\n"
    "  <stem>.npy          with --float: float32 [H, W, C], unclamped, for exact comparisons\n"
    "and per capture (frames sharing the numeric suffix, e.g. MS_NIR_00007 and MS_R_00007), with\n"
    "all bands rendered from that capture's NIR camera:\n"
    "  CIR_<n>.png         colour infrared: NIR, R, G shown as red, green, blue\n"
    "  NDVI_<n>.png        (NIR - R) / (NIR + R) on a red-yellow-green scale over [-1, 1]\n"
    "  NDRE_<n>.png        (NIR - RE) / (NIR + RE), same scale (+ raw .npy with --float)\n"
    "\n"
    MSGS_DATA_OPTIONS_USAGE
    "  --model PLY|DIR     a model PLY, or a directory of model_*.ply files (as `msgs train` writes)\n"
    "                      Bands come from the PLY's band names; a PLY without them renders the RGB\n"
    "                      band (3 channels), the Joint layout (7) or any single band (1).\n"
    "  --split S           train | eval | all (default all)\n"
    "  --background V      one value for every channel, or one per channel of a band, or 7 values\n"
    "                      in Joint order D_R,D_G,D_B,MS_G,MS_R,MS_RE,MS_NIR (default 0)\n"
    "  --sh-degree D       render at most SH degree D (default: the model's)\n"
    "  --bands LIST        only these bands (comma separated ids)\n"
    "  --orient none       the model was trained with --orient none (dataset coordinates as stored;\n"
    "                      --no-orient is the same)\n"
    "Nothing is written unless every output is complete.\n";

using msgs::cli::split_list;

std::vector<float> parse_background(const std::string& s) {
  std::vector<float> out;
  for (const auto& tok : split_list(s)) {
    char* end = nullptr;
    const double v = std::strtod(tok.c_str(), &end);
    if (*end != '\0' || !std::isfinite(v))
      throw msgs::cli::UsageError("--background expects numbers separated by commas, got '" + tok + "'");
    out.push_back(float(v));
  }
  if (out.empty()) throw msgs::cli::UsageError("--background needs at least one value");
  return out;
}

int run_render(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(argv, {"data", "images", "eval-every", "model", "out", "split", "background", "sh-degree", "bands", "orient"},
                             {"help", "float", "no-orient", "no-composites", "no-legend"});
  if (args.flag("help")) { std::fputs(kUsage, stdout); return 0; }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  const std::filesystem::path data = args.require("data"), model = args.require("model"), out = args.require("out");

  msgs::DatasetRenderOptions opt;
  const std::string split = args.get("split", "all");
  if (split == "train") opt.split = msgs::io::Split::train;
  else if (split == "eval") opt.split = msgs::io::Split::eval;
  else if (split != "all") throw msgs::cli::UsageError("--split must be train, eval or all, got '" + split + "'");
  opt.write_float = args.flag("float");
  opt.composites = !args.flag("no-composites");
  opt.legend = !args.flag("no-legend");
  if (args.has("background")) opt.background = parse_background(args.get("background"));
  const long deg = args.integer("sh-degree", -1);
  if (args.has("sh-degree") && (deg < 0 || deg > 3)) throw msgs::cli::UsageError("--sh-degree must be 0..3");
  opt.sh_degree = int(deg);

  msgs::io::LoadOptions lo;
  lo.orient_and_center = msgs::cli::orient_and_center(args);
  lo.bands = split_list(args.get("bands"));
  lo.load_points = false;
  const msgs::io::Dataset ds = msgs::cli::load_data(args, lo, "render");
  const msgs::ModelSet models = msgs::ModelSet::load(model, msgs::cli::make_any_renderer);
  for (const auto& b : ds.bands()) {
    if (!models.renders(b)) continue;
    try {
      (void)msgs::band_background(opt.background, b);
    } catch (const std::invalid_argument& e) {
      throw msgs::cli::UsageError("--" + std::string(e.what()));
    }
  }

  opt.on_progress = [](std::size_t done, std::size_t total) {
    std::fprintf(stderr, "\rrendering frame %zu/%zu ", done, total);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };

  msgs::OutputStage stage(out);
  const msgs::DatasetRenderSummary sum = msgs::render_dataset(ds, models, stage.dir(), opt);
  stage.commit();

  std::printf("rendered %zu frame(s) of %s (%s) with", sum.frames, data.string().c_str(), split.c_str());
  for (const auto& m : models.models())
    std::printf(" %s [%d ch, SH %d, %zu Gaussians]", m->path.filename().string().c_str(), m->channels(),
                m->sh_degree(), m->size());
  std::printf("\n");
  if (sum.composite_captures) std::printf("composites (CIR / NDVI / NDRE) for %zu capture(s)\n", sum.composite_captures);
  if (!sum.skipped.empty())
    std::printf("skipped %zu frame(s) whose band no model renders (first: %s)\n", sum.skipped.size(),
                sum.skipped.front().c_str());
  std::printf("wrote %zu file(s) to %s\n", sum.files.size(), out.string().c_str());
  return 0;
}

}  // namespace
}  // namespace cmd_render

MSGS_COMMAND("render", "Render a model at the dataset's cameras, plus CIR / NDVI / NDRE maps", cmd_render::run_render);
