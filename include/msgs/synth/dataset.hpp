// include/msgs/synth/dataset.hpp
// Writes a synthetic scene as a dataset in exactly the public multi-spectral layout (REFERENCE.md
// §2): transforms.json, train_split.json, images/, images_<f>/ and sparse_pc.ply, all at once.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "../io/file.hpp"
#include "../io/frame_json.hpp"
#include "../io/image_io.hpp"
#include "render.hpp"
#include "scene.hpp"

namespace msgs::synth {

/// What to generate.
struct SynthOptions {
  std::string preset = "tiny";  ///< tiny | small | medium
  std::uint64_t seed = 1;       ///< same seed, same bytes
  bool overwrite = false;       ///< replace an existing output directory (only once the new one is complete)
};

/// What was generated.
struct SynthSummary {
  std::filesystem::path out;
  std::string preset;
  std::uint64_t seed = 0;
  int captures = 0;                                 ///< rig exposures (= frames per band)
  int train_captures = 0, eval_captures = 0;
  std::array<int, num_bands> frames_per_band{};     ///< images written per band (full resolution)
  std::array<int, num_bands> width{}, height{};     ///< full-resolution image size per band
  std::vector<int> downscales;                      ///< images_<f>/ folders written
  std::size_t points = 0, outliers = 0;             ///< sparse_pc.ply content
  double seconds = 0.0;                             ///< wall time of the whole generation
};

/// Captures that go to the evaluation split: every 10th, starting with the first (0-based i % 10 == 0).
constexpr bool is_eval_capture(int capture) { return capture % 10 == 0; }

/// File name of a band's image for a capture (0-based): "D_00001.png", "MS_NIR_00001.png".
inline std::string frame_file_name(Band b, int capture) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%05d.png", capture + 1);
  return std::string(band_name(b)) + buf;
}

namespace detail {

inline nlohmann::ordered_json frame_json(const Camera<float>& cam, Band b, int capture) {
  nlohmann::ordered_json f;
  f["file_path"] = "images/" + frame_file_name(b, capture);
  f["transform_matrix"] = io::transform_matrix_json(cam);
  f["mm_channel"] = std::string(band_name(b));
  io::write_intrinsics_json(f, cam);
  for (const char* k : {"k1", "k2", "k3", "k4", "p1", "p2"}) f[k] = 0.0;
  f["camera_model"] = "OPENCV";
  return f;
}

/// train_split.json written by hand: the published files end their lists with a trailing comma,
/// and loaders have to cope, so the synthetic files do the same.
inline std::string split_text(const std::vector<std::string>& train, const std::vector<std::string>& eval) {
  std::string s = "{\n";
  auto list = [&](const char* key, const std::vector<std::string>& v, bool last) {
    s += std::string("  \"") + key + "\": [\n";
    for (const auto& p : v) s += "    \"" + p + "\",\n";
    s += last ? "  ]\n" : "  ],\n";
  };
  list("train", train, false);
  list("eval", eval, true);
  s += "}\n";
  return s;
}

/// ASCII PLY with `x y z` float and `red green blue` uint8, the layout nerfstudio writes.
inline std::string ply_text(const SparsePoints& pts) {
  std::string s = "ply\nformat ascii 1.0\ncomment msgs synthetic sparse point cloud\nelement vertex " +
                  std::to_string(pts.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\n"
                  "property uint8 red\nproperty uint8 green\nproperty uint8 blue\nend_header\n";
  char buf[128];
  for (std::size_t i = 0; i < pts.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%.6f %.6f %.6f %u %u %u\n", double(pts.positions[3 * i]),
                  double(pts.positions[3 * i + 1]), double(pts.positions[3 * i + 2]), unsigned(pts.colors[3 * i]),
                  unsigned(pts.colors[3 * i + 1]), unsigned(pts.colors[3 * i + 2]));
    s += buf;
  }
  return s;
}

}  // namespace detail

/// Render the scene of `opt.preset` / `opt.seed` and write it as a dataset at `out`. Everything is
/// written into a hidden sibling directory first and renamed into place at the end, so a failed or
/// interrupted run leaves no partial dataset. An existing `out` is an error unless
/// `opt.overwrite`. Throws std::invalid_argument for an unknown preset, io::IoError for I/O errors.
inline SynthSummary write_synthetic_dataset(const std::filesystem::path& out_arg, const SynthOptions& opt) {
  namespace fs = std::filesystem;
  const auto t0 = std::chrono::steady_clock::now();
  const SynthPreset& preset = synth_preset(opt.preset);
  fs::path out = fs::absolute(out_arg).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();  // "dir/" -> "dir"
  std::error_code ec;
  if (fs::exists(out, ec) && !opt.overwrite)
    io::fail(out, "output directory already exists (choose another one, or overwrite: --force / SynthOptions::overwrite)");
  io::StagedDirectory stage(out, ".synth-tmp-");
  const fs::path& tmp = stage.dir();
  fs::create_directories(tmp / "images", ec);
  if (ec) io::fail(tmp, io::cat("cannot create temporary output directory: ", ec.message()));
  for (int f : preset.downscales) fs::create_directories(tmp / ("images_" + std::to_string(f)));

  const SynthScene scene = make_scene(preset, opt.seed);
  SynthSummary sum;
  sum.out = out;
  sum.preset = preset.name;
  sum.seed = opt.seed;
  sum.captures = int(scene.captures.size());
  sum.downscales = preset.downscales;

  nlohmann::ordered_json tf;
  tf["camera_model"] = "OPENCV";
  tf["ply_file_path"] = "sparse_pc.ply";
  tf["msgs_synthetic"] = {{"preset", preset.name}, {"seed", opt.seed}, {"world_up", {0, 0, 1}}};
  nlohmann::ordered_json frames = nlohmann::ordered_json::array();
  std::vector<std::string> train, eval;
  std::vector<int> all_captures;
  for (int ci = 0; ci < sum.captures; ++ci) {
    all_captures.push_back(ci);
    const bool ev = is_eval_capture(ci);
    (ev ? sum.eval_captures : sum.train_captures) += 1;
    for (Band b : all_bands) {
      const auto bi = static_cast<std::size_t>(b);
      const Camera<float>& cam = scene.captures[static_cast<std::size_t>(ci)].cameras[bi];
      RenderSettings rs;
      rs.aa = preset.aa;
      rs.jitter_seed = frame_jitter_seed(opt.seed, ci, b);
      const Image<float> img = render_band(scene, cam, b, rs);
      const std::string name = frame_file_name(b, ci);
      // RGB frames are 8-bit like the camera's JPEGs; the multispectral frames keep 16 bits.
      auto write = [&](const fs::path& p, const Image<float>& im) {
        if (b == Band::D) io::write_png8(p, im); else io::write_png16(p, im);
      };
      write(tmp / "images" / name, img);
      for (int f : preset.downscales) write(tmp / ("images_" + std::to_string(f)) / name, io::downscale(img, f));
      frames.push_back(detail::frame_json(cam, b, ci));
      (ev ? eval : train).push_back("images/" + name);
      sum.frames_per_band[bi] += 1;
      sum.width[bi] = cam.width;
      sum.height[bi] = cam.height;
    }
  }
  tf["frames"] = frames;
  io::write_text_atomic(tmp / "transforms.json", tf.dump(2) + "\n");
  io::write_text_atomic(tmp / "train_split.json", detail::split_text(train, eval));

  const SparsePoints pts = sample_sparse_points(scene, all_captures, preset.points, opt.seed);
  io::write_text_atomic(tmp / "sparse_pc.ply", detail::ply_text(pts));
  sum.points = pts.size();
  for (auto o : pts.outlier) sum.outliers += o;

  // Swap into place; an old dataset is moved aside first and only deleted once the new one is in.
  stage.commit();
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

}  // namespace msgs::synth

namespace msgs {
using synth::SynthOptions;
using synth::SynthSummary;
using synth::write_synthetic_dataset;
}  // namespace msgs
