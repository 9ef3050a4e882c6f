// include/msgs/evaluate.hpp
// Evaluating models on a dataset's eval split: PSNR / SSIM per band, exactly as Trainer::evaluate,
// and contact sheets per eval capture (bands, CIR, NDVI, NDRE).
#pragma once

#include <algorithm>
#include <cstddef>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "colormap.hpp"
#include "contact_sheet.hpp"
#include "image.hpp"
#include "io/bands.hpp"
#include "io/dataset.hpp"
#include "io/error.hpp"
#include "io/image_io.hpp"
#include "loss.hpp"
#include "model_set.hpp"
#include "render_dataset.hpp"
#include "schedule.hpp"
#include "spectral_index.hpp"
#include "text.hpp"
#include "train.hpp"

namespace msgs {

/// What evaluate_models does.
struct EvalOptions {
  bool sheets = true;                     ///< write a contact sheet per eval capture
  /// Sheets for at most this many eval captures, the first ones in capture order (group_captures
  /// of the eval frames, i.e. file order); -1 = every eval capture, 0 = none. Metrics always
  /// cover every eval frame.
  int max_sheets = -1;
  float error_scale = default_error_scale; ///< mean absolute error shown as white in error maps
  float index_error_scale = 0.5f;         ///< NDVI / NDRE difference shown as white
  int gap = 4;                            ///< pixels between contact-sheet cells
  float fill = 0.35f;                     ///< grey between cells: error maps run from black to white
  /// Words on the sheets (row labels, column titles, legends with values), drawn with
  /// default_text(); without a text renderer the sheets have none.
  bool labels = true;
  /// SSIM windows: valid (pytorch-msssim, the reference implementation's evaluation, and what
  /// `msgs train` reports by default) or same (3DGS: zero-padded borders).
  SsimBorder ssim_border = SsimBorder::valid;
  /// Called after each eval capture with (captures done, eval captures); may be empty.
  std::function<void(std::size_t, std::size_t)> on_progress;
};

/// Per-band results of evaluate_models.
struct EvalResult {
  std::vector<BandMetrics> metrics;              ///< standard band order; bands with eval frames and a model
  std::vector<std::vector<std::string>> frames;  ///< per metrics entry: file_path of each value
  std::vector<std::string> skipped_bands;        ///< bands with eval frames that no model renders
  std::vector<std::string> files;                ///< sheets written, relative to the sheet directory
};

/// A band's row label on contact sheets: its colour and id, "green (MS_G)"; other ids as they are.
inline std::string band_label(const std::string& id) {
  static const std::pair<const char*, const char*> names[] = {
      {"D", "RGB"}, {"MS_G", "green"}, {"MS_R", "red"}, {"MS_RE", "red edge"}, {"MS_NIR", "NIR"}};
  for (const auto& [band, name] : names)
    if (id == band) return std::string(name) + " (" + id + ")";
  return id;
}

/// PSNR and SSIM of every eval frame whose band a model renders, at full resolution with the
/// reference evaluation background (eval_background) and renders clamped to [0, 1], exactly as
/// Trainer::evaluate. With `sheet_dir` non-empty and opt.sheets, one `sheet_<capture>.png` per
/// eval capture (the first opt.max_sheets captures when that is >= 0): a row per band of ground
/// truth | render | error map, then rows for CIR, NDVI and NDRE of ground truth | render (all from
/// the NIR camera) | difference, where the bands exist. With opt.labels and a text renderer,
/// each row is labelled (band_label, "CIR", "NDVI", "NDRE"), the columns are titled "ground truth
/// | render | error" above the first row and "GT | render | difference" above the first index
/// row, and legends give the scales: the error scale [0, error_scale] below the last error row
/// (bands and CIR), and below the index rows [-1, 1] under GT and render and
/// [0, index_error_scale] under the difference. Sheets are written straight into
/// `sheet_dir`, each file atomically (stage the directory with OutputStage for all-or-nothing).
/// Ground-truth composites combine the bands' own images (one size required; they come from
/// slightly different viewpoints, as the cameras do).
inline EvalResult evaluate_models(const io::Dataset& ds, const ModelSet& models,
                                  const std::filesystem::path& sheet_dir = {}, const EvalOptions& opt = {}) {
  if (opt.max_sheets < -1)
    throw std::invalid_argument("evaluate_models: max_sheets must be -1 (every capture) or >= 0, got " +
                                std::to_string(opt.max_sheets));
  EvalResult res;
  std::vector<std::size_t> eval_frames;
  std::set<std::string> skipped;
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    const io::Frame& f = ds.frames[i];
    if (f.split != io::Split::eval) continue;
    if (models.renders(f.band)) eval_frames.push_back(i);
    else skipped.insert(f.band);
  }
  for (const auto& b : io::standard_bands())
    if (skipped.count(b.id)) res.skipped_bands.push_back(b.id);
  if (eval_frames.empty())
    io::fail(ds.root / (ds.has_split_file ? "train_split.json" : "transforms.json"), "eval",
             "no eval frame shows a band the model renders");

  std::map<std::string, std::size_t> slot;  // band -> index into res.metrics
  for (const auto& b : io::standard_bands())
    for (std::size_t f : eval_frames)
      if (ds.frames[f].band == b.id) {
        slot[b.id] = res.metrics.size();
        res.metrics.push_back(BandMetrics{b.id, {}, {}});
        res.frames.emplace_back();
        break;
      }

  const bool sheets = opt.sheets && !sheet_dir.empty();
  const std::vector<Capture> captures = group_captures(ds, eval_frames);
  std::size_t done = 0;
  for (const Capture& cap : captures) {
    if (opt.on_progress && done > 0) opt.on_progress(done, captures.size());
    // Captures come in a fixed order, so "the first max_sheets" is the same set on every run.
    const bool sheet = sheets && (opt.max_sheets < 0 || done < std::size_t(opt.max_sheets));
    ++done;
    struct View { std::string band; Image<float> gt, render, error; };
    std::vector<View> views;
    for (const auto& b : io::standard_bands()) {
      auto it = cap.frames.find(b.id);
      if (it == cap.frames.end()) continue;
      const io::Frame& f = ds.frames[it->second];
      View v;
      v.band = b.id;
      v.render = models.render(b.id, io::frame_camera(ds, f, 1), eval_background<float>(b.channels));
      clamp01(v.render);
      v.gt = io::load_frame_image(ds, f, 1);
      BandMetrics& m = res.metrics[slot.at(b.id)];
      m.psnr.push_back(psnr(v.render, v.gt));
      m.ssim.push_back(ssim(v.render, v.gt, opt.ssim_border));
      res.frames[slot.at(b.id)].push_back(f.file_path);
      if (sheet) {
        v.error = error_map(v.render, v.gt, opt.error_scale);
        views.push_back(std::move(v));
      }
    }
    if (!sheet) continue;

    SheetCells rows;
    SheetLabels labels;
    for (const View& v : views) {
      rows.push_back({&v.gt, &v.render, &v.error});
      labels.rows.push_back(band_label(v.band));
    }
    // Composites: ground truth from each band's own image, renders from the NIR camera.
    std::deque<Image<float>> extra;  // keeps the composite images alive for `rows` (stable addresses)
    auto find_view = [&](const char* b) -> const View* {
      for (const View& v : views)
        if (v.band == b) return &v;
      return nullptr;
    };
    const View* nir = find_view("MS_NIR");
    if (nir && models.named_source("MS_NIR")) {
      std::vector<std::string> bands = {"MS_NIR"};
      for (const char* b : {"MS_R", "MS_G", "MS_RE"})
        if (find_view(b) && models.named_source(b) && find_view(b)->gt.width == nir->gt.width &&
            find_view(b)->gt.height == nir->gt.height)
          bands.push_back(b);
      const std::vector<std::vector<float>> bgs(bands.size(), eval_background<float>(1));
      std::vector<Image<float>> rendered =
          models.render_bands(bands, io::frame_camera(ds, ds.frames[cap.frames.at("MS_NIR")], 1), bgs);
      for (auto& r : rendered) clamp01(r);
      auto pick = [&](const char* b) -> std::pair<const Image<float>*, const Image<float>*> {
        for (std::size_t k = 0; k < bands.size(); ++k)
          if (bands[k] == b) return {&find_view(b)->gt, &rendered[k]};
        return {nullptr, nullptr};
      };
      const auto [gn, rn] = pick("MS_NIR");
      const auto [gr, rr] = pick("MS_R");
      const auto [gg, rg] = pick("MS_G");
      const auto [ge, re] = pick("MS_RE");
      auto add_row = [&](Image<float> g, Image<float> r, Image<float> e) {
        extra.push_back(std::move(g));
        extra.push_back(std::move(r));
        extra.push_back(std::move(e));
        const std::size_t n = extra.size();
        rows.push_back({&extra[n - 3], &extra[n - 2], &extra[n - 1]});
      };
      if (gr && gg) {
        Image<float> cg = cir_composite(*gn, *gr, *gg), cr = cir_composite(*rn, *rr, *rg);
        Image<float> ce = error_map(cr, cg, opt.error_scale);
        add_row(std::move(cg), std::move(cr), std::move(ce));
        labels.rows.push_back("CIR");
      }
      const std::size_t first_index_row = rows.size();
      for (auto [gb, rb, name] : {std::tuple{gr, rr, "NDVI"}, std::tuple{ge, re, "NDRE"}}) {
        if (!gb) continue;
        labels.rows.push_back(name);
        const Image<float> ig = normalized_difference(*gn, *gb), ir = normalized_difference(*rn, *rb);
        add_row(colourize(ig, Colormap::diverging, index_scale_lo, index_scale_hi),
                colourize(ir, Colormap::diverging, index_scale_lo, index_scale_hi),
                error_map(ir, ig, opt.index_error_scale));
      }
      if (rows.size() > first_index_row) {
        labels.headings.push_back({first_index_row, {"GT", "render", "difference"}});
        for (std::size_t c : {0, 1})
          labels.legends.push_back({rows.size() - 1, c, Colormap::diverging, index_scale_lo, index_scale_hi});
        labels.legends.push_back({rows.size() - 1, 2, Colormap::sequential, 0.0f, opt.index_error_scale});
      }
    }
    // The bands' rows and CIR end where the index rows begin (or the sheet ends).
    std::size_t last_error_row = rows.size() - 1;
    for (const auto& h : labels.headings) last_error_row = std::min(last_error_row, h.row - 1);
    labels.headings.insert(labels.headings.begin(), {0, {"ground truth", "render", "error"}});
    labels.legends.push_back({last_error_row, 2, Colormap::sequential, 0.0f, opt.error_scale});
    const std::string name = "sheet_" + cap.key + ".png";
    io::write_png8(sheet_dir / name, opt.labels ? contact_sheet(rows, labels, opt.gap, opt.fill, default_text())
                                                : contact_sheet(rows, opt.gap, opt.fill));
    res.files.push_back(name);
  }
  if (opt.on_progress) opt.on_progress(captures.size(), captures.size());
  return res;
}

}  // namespace msgs

