// examples/data_options.hpp: the dataset options every command that takes --data shares
// (--images, --eval-every, --orient), and loading whichever layout the folder holds.
#pragma once

#include <cstdio>
#include <string>
#include <system_error>

#include <msgs/io/load_scene.hpp>

#include "commands.hpp"

namespace msgs::cli {

/// Usage lines of the shared dataset options (a string literal, to join a command's usage text).
#define MSGS_DATA_OPTIONS_USAGE \
    "  --data DIR        a nerfstudio multi-spectral layout (transforms.json) or a COLMAP scene\n" \
    "                    (images/ + sparse/0 or sparse/, text or binary; trains as one RGB band D)\n" \
    "  --images NAME     image folder: images_<f> = the copies downscaled by f next to images/;\n" \
    "                    for COLMAP any folder of resized images (intrinsics follow their size)\n" \
    "  --eval-every N    every N-th image (per band, by name) is held out for evaluation, the\n" \
    "                    rest trains; default 8 for COLMAP scenes (3DGS convention), and for the\n" \
    "                    nerfstudio layout train_split.json when present, else 10; 0 = no eval\n"

/// "1st", "2nd", "3rd", "4th", ..., "11th", "12th", "13th", ..., "21st", ...
inline std::string ordinal(int n) {
  const int tens = n % 100, ones = n % 10;
  const char* suffix = (tens >= 11 && tens <= 13) ? "th" : ones == 1 ? "st" : ones == 2 ? "nd" : ones == 3 ? "rd" : "th";
  return std::to_string(n) + suffix;
}

/// Load --data with --images and --eval-every on top of `lo` (orientation, bands, points), and
/// say on stderr which layout was found and how the split was made.
inline io::Dataset load_data(const Args& args, io::LoadOptions lo, const char* command) {
  const std::filesystem::path root = args.require("data");
  const io::SceneInfo info = io::detect_scene(root);
  const bool colmap = info.layout == io::SceneLayout::colmap;
  const bool explicit_every = args.has("eval-every");
  if (explicit_every) {
    const long n = args.integer("eval-every", 0);
    if (n < 0 || n > 1000000) throw UsageError("--eval-every must be between 0 (no eval images) and 1000000");
    lo.eval_every = int(n);
    lo.use_split_file = false;
  } else if (colmap) {
    lo.eval_every = 8;
  }
  const std::string images = args.get("images", "images");
  io::Dataset ds = io::load_scene(root, lo, images);
  std::error_code ec;
  const bool split_file = !colmap && lo.use_split_file && std::filesystem::exists(root / "train_split.json", ec);
  std::size_t eval = 0;
  for (const auto& f : ds.frames) eval += f.split == io::Split::eval;
  std::string split = split_file ? std::string("split from train_split.json")
                                 : lo.eval_every == 1 ? std::string("every image held out")
                                 : lo.eval_every > 0 ? "every " + ordinal(lo.eval_every) + " image per band held out"
                                                     : std::string("no eval images");
  if (!colmap && explicit_every && std::filesystem::exists(root / "train_split.json", ec))
    split += " (train_split.json ignored: --eval-every given)";
  std::fprintf(stderr, "msgs %s: %s at %s: %zu images (%zu eval; %s)%s\n", command, info.describe(root).c_str(),
               root.string().c_str(), ds.frames.size(), eval, split.c_str(),
               ds.downscale > 1 ? (", images downscaled by " + std::to_string(ds.downscale)).c_str() : "");
  for (const auto& f : ds.frames) {
    if (f.camera.width > 3200 && ds.downscale == 1) {
      std::fprintf(stderr, "msgs %s: note: images are %d px wide; --images images_2 (or _4) trains much faster "
                           "(3DGS downscales to 1600 px)\n", command, f.camera.width);
      break;
    }
  }
  return ds;
}

}  // namespace msgs::cli
