// include/msgs/render_dataset.hpp
// Rendering a dataset with a ModelSet: frames grouped into captures, per-band backgrounds, an
// all-or-nothing output directory (OutputStage), and render_dataset (every frame with its own
// camera, plus per-capture CIR / NDVI / NDRE composites).
#pragma once

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "colormap.hpp"
#include "image.hpp"
#include "io/bands.hpp"
#include "io/dataset.hpp"
#include "io/error.hpp"
#include "io/image_io.hpp"
#include "model_set.hpp"
#include "spectral_index.hpp"

namespace msgs {

/// The capture a frame belongs to: the trailing digits of its file name's stem, which the frames
/// of one exposure share ("images/MS_NIR_00007.TIF" -> "00007"); empty when the stem ends in none.
inline std::string capture_key(std::string_view file_path) {
  const std::string stem = std::filesystem::path(file_path).stem().string();
  std::size_t i = stem.size();
  while (i > 0 && std::isdigit(static_cast<unsigned char>(stem[i - 1]))) --i;
  return stem.substr(i);
}

/// Frames of one exposure of the rig: band id -> index into Dataset::frames.
struct Capture {
  std::string key;  ///< capture_key of its frames, or a frame's stem when it has no numeric suffix
  std::map<std::string, std::size_t> frames;
};

/// Group `frames` (indices into ds.frames) by capture, in order of first appearance. A second
/// frame of the same band and key (another folder) starts a capture of its own.
inline std::vector<Capture> group_captures(const io::Dataset& ds, const std::vector<std::size_t>& frames) {
  std::vector<Capture> out;
  std::map<std::string, std::vector<std::size_t>> by_key;  // key -> captures with that key
  for (std::size_t f : frames) {
    const io::Frame& fr = ds.frames[f];
    std::string key = capture_key(fr.file_path);
    if (key.empty()) key = std::filesystem::path(fr.file_path).stem().string();
    Capture* cap = nullptr;
    for (std::size_t c : by_key[key])
      if (!out[c].frames.count(fr.band)) { cap = &out[c]; break; }
    if (!cap) {
      by_key[key].push_back(out.size());
      out.push_back(Capture{key, {}});
      cap = &out.back();
    }
    cap->frames[fr.band] = f;
  }
  return out;
}

/// Resolve a background given on the command line for one band: no values (0), one value (every
/// channel), one per channel of the band, or one per Joint channel (D_R D_G D_B MS_G MS_R MS_RE
/// MS_NIR) from which the band's slice is taken. std::invalid_argument otherwise.
inline std::vector<float> band_background(const std::vector<float>& values, std::string_view band) {
  const io::BandInfo* b = io::find_band(band);
  if (!b) throw std::invalid_argument("band_background: unknown band '" + std::string(band) + "'");
  for (float v : values)
    if (!std::isfinite(v)) throw std::invalid_argument("background values must be finite");
  if (values.size() <= 1) return values;
  if (int(values.size()) == io::joint_channels())
    return {values.begin() + b->first_channel_in_joint, values.begin() + b->first_channel_in_joint + b->channels};
  if (int(values.size()) == b->channels) return values;
  throw std::invalid_argument("background: " + std::to_string(values.size()) + " values do not fit band " + b->id +
                              " (" + std::to_string(b->channels) + " channel(s)); give 1 value, " +
                              std::to_string(b->channels) + ", or " + std::to_string(io::joint_channels()) +
                              " in Joint channel order");
}

/// A hidden staging directory inside `out`: write everything there, then commit() moves the
/// files into `out` (keeping subfolders, replacing files of the same name). Without commit (an
/// error), the staging directory is removed, and so is `out` if this created it; earlier
/// contents of `out` are never touched.
class OutputStage {
 public:
  explicit OutputStage(std::filesystem::path out) : out_(std::move(out)) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(out_, ec) && !fs::is_directory(out_, ec)) io::fail(out_, "output path exists and is not a directory");
    created_ = !fs::exists(out_, ec);
    fs::create_directories(out_, ec);
    if (ec) io::fail(out_, io::cat("cannot create output directory: ", ec.message()));
    std::random_device rd;
    char buf[32];
    std::snprintf(buf, sizeof buf, ".msgs-stage-%08x", unsigned(rd()));
    stage_ = out_ / buf;
    fs::create_directory(stage_, ec);
    if (ec) io::fail(stage_, io::cat("cannot create staging directory: ", ec.message()));
  }
  OutputStage(const OutputStage&) = delete;
  OutputStage& operator=(const OutputStage&) = delete;
  ~OutputStage() {
    std::error_code ec;
    std::filesystem::remove_all(stage_, ec);
    if (!committed_ && created_) std::filesystem::remove(out_, ec);  // only succeeds when empty
  }

  /// Where to write.
  const std::filesystem::path& dir() const { return stage_; }
  /// The final directory.
  const std::filesystem::path& out() const { return out_; }

  /// Move every staged file into place. Each file appears whole (rename); returns their final paths.
  std::vector<std::filesystem::path> commit() {
    namespace fs = std::filesystem;
    std::vector<fs::path> moved;
    std::vector<fs::path> files;
    for (auto it = fs::recursive_directory_iterator(stage_); it != fs::recursive_directory_iterator(); ++it)
      if (it->is_regular_file()) files.push_back(it->path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      const fs::path target = out_ / f.lexically_relative(stage_);
      std::error_code ec;
      fs::create_directories(target.parent_path(), ec);
      if (ec) io::fail(target.parent_path(), io::cat("cannot create directory: ", ec.message()));
      fs::rename(f, target, ec);
      if (ec) io::fail(target, io::cat("cannot move the finished file into place: ", ec.message()));
      moved.push_back(target);
    }
    committed_ = true;
    return moved;
  }

 private:
  std::filesystem::path out_, stage_;
  bool created_ = false, committed_ = false;
};

/// What render_dataset does.
struct DatasetRenderOptions {
  std::optional<io::Split> split;  ///< frames of this split only; nullopt = every frame
  bool write_float = false;        ///< also write float32 .npy [H, W, C], unclamped, for exact comparisons
  std::vector<float> background;   ///< see band_background; empty = black
  int sh_degree = -1;              ///< render at most this SH degree; -1 = each model's own
  bool composites = true;          ///< CIR / NDVI / NDRE per capture where the bands exist
  bool legend = true;              ///< colour bar under NDVI / NDRE maps
  /// Called after each rendered frame with (frames done, frames selected); may be empty.
  std::function<void(std::size_t, std::size_t)> on_progress;
};

/// What render_dataset wrote.
struct DatasetRenderSummary {
  std::size_t frames = 0;              ///< frames rendered
  std::vector<std::string> skipped;    ///< frames whose band no model renders (file_path)
  std::size_t composite_captures = 0;  ///< captures with at least one composite
  std::vector<std::string> files;      ///< names written, relative to the output directory
};

/// Render every selected frame of `ds` with its own full-resolution camera into `dir`:
/// `<stem>.png` (8-bit for RGB, 16-bit for single bands; + `<stem>.npy` with write_float).
/// Per capture whose MS_NIR frame is selected and whose bands the models name, everything is
/// rendered from the NIR camera (the cameras of one capture differ slightly, and per-pixel ratios
/// need one viewpoint): `CIR_<key>.png` (NIR, R, G as RGB), `NDVI_<key>.png`, `NDRE_<key>.png`
/// on the diverging scale over [-1, 1] (+ raw `.npy` with write_float). Everything is checked
/// before the first file is written; writes go straight into `dir` (stage it with OutputStage).
inline DatasetRenderSummary render_dataset(const io::Dataset& ds, const ModelSet& models,
                                           const std::filesystem::path& dir, const DatasetRenderOptions& opt = {}) {
  namespace fs = std::filesystem;
  DatasetRenderSummary sum;
  std::vector<std::size_t> selected;
  std::map<std::string, std::size_t> stems;  // output stem -> frame, to refuse collisions
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    const io::Frame& f = ds.frames[i];
    if (opt.split && f.split != *opt.split) continue;
    if (!models.renders(f.band)) { sum.skipped.push_back(f.file_path); continue; }
    (void)band_background(opt.background, f.band);  // throws on a background that does not fit
    const std::string stem = fs::path(f.file_path).stem().string();
    if (auto [it, ok] = stems.emplace(stem, i); !ok)
      io::fail(ds.root / "transforms.json", "file_path",
               io::cat("frames '", ds.frames[it->second].file_path, "' and '", f.file_path,
                       "' would both be rendered to ", stem, ".png"));
    selected.push_back(i);
  }
  if (selected.empty())
    io::fail(ds.root / "transforms.json", "frames",
             "no selected frame shows a band the model renders (check --split, --bands and the model's bands)");
  if (opt.sh_degree > 3) throw std::invalid_argument("render_dataset: sh_degree must be <= 3");

  for (std::size_t i : selected) {
    const io::Frame& f = ds.frames[i];
    const Image<float> img = models.render(f.band, io::frame_camera(ds, f, 1), band_background(opt.background, f.band),
                                           opt.sh_degree);
    const std::string stem = fs::path(f.file_path).stem().string();
    if (img.channels == 1) io::write_png16(dir / (stem + ".png"), img);
    else io::write_png8(dir / (stem + ".png"), img);
    sum.files.push_back(stem + ".png");
    if (opt.write_float) {
      io::write_npy(dir / (stem + ".npy"), img);
      sum.files.push_back(stem + ".npy");
    }
    ++sum.frames;
    if (opt.on_progress) opt.on_progress(sum.frames, selected.size());
  }

  if (!opt.composites) return sum;
  for (const Capture& cap : group_captures(ds, selected)) {
    auto nir_it = cap.frames.find("MS_NIR");
    if (nir_it == cap.frames.end() || !models.named_source("MS_NIR")) continue;
    std::vector<std::string> bands = {"MS_NIR"};
    for (const char* b : {"MS_R", "MS_G", "MS_RE"})
      if (models.named_source(b)) bands.push_back(b);
    if (bands.size() == 1) continue;
    std::vector<std::vector<float>> bgs;
    for (const auto& b : bands) bgs.push_back(band_background(opt.background, b));
    const io::Frame& nir_frame = ds.frames[nir_it->second];
    const std::vector<Image<float>> views =
        models.render_bands(bands, io::frame_camera(ds, nir_frame, 1), bgs, opt.sh_degree);
    auto view = [&](const char* b) -> const Image<float>* {
      for (std::size_t k = 0; k < bands.size(); ++k)
        if (bands[k] == b) return &views[k];
      return nullptr;
    };
    auto write_index = [&](const std::string& name, const Image<float>& index) {
      Image<float> rgb = colourize(index, Colormap::diverging, index_scale_lo, index_scale_hi);
      if (opt.legend) rgb = with_legend(rgb, Colormap::diverging, index_scale_lo, index_scale_hi);
      io::write_png8(dir / (name + ".png"), rgb);
      sum.files.push_back(name + ".png");
      if (opt.write_float) {
        io::write_npy(dir / (name + ".npy"), index);
        sum.files.push_back(name + ".npy");
      }
    };
    const Image<float>* nir = view("MS_NIR");
    if (view("MS_R") && view("MS_G")) {
      const Image<float> cir = cir_composite(*nir, *view("MS_R"), *view("MS_G"));
      io::write_png8(dir / ("CIR_" + cap.key + ".png"), cir);
      sum.files.push_back("CIR_" + cap.key + ".png");
      if (opt.write_float) {
        io::write_npy(dir / ("CIR_" + cap.key + ".npy"), cir);
        sum.files.push_back("CIR_" + cap.key + ".npy");
      }
    }
    if (view("MS_R")) write_index("NDVI_" + cap.key, ndvi(*nir, *view("MS_R")));
    if (view("MS_RE")) write_index("NDRE_" + cap.key, ndre(*nir, *view("MS_RE")));
    ++sum.composite_captures;
  }
  return sum;
}

}  // namespace msgs
