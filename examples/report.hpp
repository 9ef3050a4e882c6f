// examples/report.hpp: turning RunResults into JSON, Markdown tables and console lines, shared
// by `msgs train`, `msgs eval` and `msgs study`.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <msgs/run.hpp>

namespace msgs::cli {

/// The paper's column order.
inline const std::vector<std::string>& report_bands() {
  static const std::vector<std::string> b = {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  return b;
}
inline std::string band_label(const std::string& id) {
  if (id == "D") return "RGB";
  if (id.rfind("MS_", 0) == 0) return id.substr(3);
  return id;
}

/// Mean over bands of the per-band means ("All" of the paper's tables: each band weighs the same);
/// `corrected`: of the colour-corrected values (exposure runs).
inline double all_bands_mean(const std::vector<BandMetrics>& m, bool use_psnr, bool corrected = false) {
  double s = 0;
  int n = 0;
  for (const auto& b : m) {
    const double v = BandMetrics::mean(corrected ? (use_psnr ? b.psnr_cc : b.ssim_cc) : (use_psnr ? b.psnr : b.ssim));
    if (std::isfinite(v)) { s += v; ++n; }
  }
  return n ? s / n : std::nan("");
}

/// Whether any band carries colour-corrected metrics (a run with exposure compensation).
inline bool has_colour_corrected(const std::vector<BandMetrics>& m) {
  return std::any_of(m.begin(), m.end(), [](const BandMetrics& b) { return !b.psnr_cc.empty(); });
}

/// The learned per-image corrections: per model and band, the range and mean of the gains and
/// offsets per channel, and every training image's values.
inline nlohmann::json exposure_json(const RunResult& r) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& entry : r.exposure_params) {
    // Named members, not a structured binding: the lambda below uses `e`, which Clang before 16
    // cannot capture from a binding.
    const auto& model = entry.first;
    const auto& e = entry.second;
    nlohmann::json jb;
    jb["model"] = model;
    jb["band"] = e.band;
    jb["images"] = e.files.size();
    auto stats = [&](const std::vector<std::vector<double>>& v) {
      nlohmann::json s = nlohmann::json::array();
      for (int c = 0; c < e.channels; ++c) {
        double lo = std::numeric_limits<double>::infinity(), hi = -lo, sum = 0;
        for (const auto& x : v) { const double y = x[std::size_t(c)]; lo = std::min(lo, y); hi = std::max(hi, y); sum += y; }
        s.push_back({{"min", lo}, {"max", hi}, {"mean", v.empty() ? std::nan("") : sum / double(v.size())}});
      }
      return s;
    };
    jb["gain"] = stats(e.gain);      // per channel
    jb["offset"] = stats(e.offset);  // per channel
    nlohmann::json frames = nlohmann::json::array();
    for (std::size_t i = 0; i < e.files.size(); ++i)
      frames.push_back({{"file_path", e.files[i]}, {"gain", e.gain[i]}, {"offset", e.offset[i]}});
    jb["frames"] = frames;
    out.push_back(jb);
  }
  return out;
}

inline nlohmann::json metrics_json(const std::vector<BandMetrics>& metrics) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& b : metrics) {
    nlohmann::json e;
    // "<name>", "<name>_mean", "<name>_std" of one per-image list.
    auto put = [&e](const std::string& name, const std::vector<double>& v) {
      e[name] = v;
      e[name + "_mean"] = BandMetrics::mean(v);
      e[name + "_std"] = BandMetrics::stddev(v);
    };
    put("psnr", b.psnr);
    put("ssim", b.ssim);
    e["images"] = b.psnr.size();
    if (!b.psnr_cc.empty()) {  // exposure runs: colour-corrected (least-squares affine per image and channel)
      put("psnr_cc", b.psnr_cc);
      put("ssim_cc", b.ssim_cc);
    }
    j[b.band] = e;
  }
  j["All"] = {{"psnr_mean", all_bands_mean(metrics, true)}, {"ssim_mean", all_bands_mean(metrics, false)}};
  if (has_colour_corrected(metrics)) {
    j["All"]["psnr_cc_mean"] = all_bands_mean(metrics, true, true);
    j["All"]["ssim_cc_mean"] = all_bands_mean(metrics, false, true);
  }
  j["lpips"] = "not computed: LPIPS needs pretrained network weights, which cannot be obtained offline";
  return j;
}

inline nlohmann::json times_json(const StageTimes& t) {
  return {{"load", t.load}, {"project", t.project}, {"bin", t.bin}, {"blend", t.blend}, {"loss", t.loss},
          {"backward", t.backward}, {"backward_blend", t.backward_blend}, {"backward_gaussians", t.backward_gaussians},
          {"adam", t.adam}, {"densify", t.densify}, {"refine", t.refine}, {"eval", t.eval}, {"total", t.total()}};
}

inline nlohmann::json plan_json(const TrainPlan& p) {
  const DensifyConfig& d = p.densify;
  return {{"strategy", p.name},
          {"kind", to_string(p.kind)},
          {"schedule_scale", p.scale.factor},
          {"stage_steps", p.stage_steps},
          {"spectral_start", p.spectral_start},
          {"spectral_geometry_start", p.spectral_geometry_start},
          {"sig", p.sig},
          {"schedule",
           {{"total_steps", p.schedule.total_steps}, {"sh_degree_every", p.schedule.sh_degree_every},
            {"warmup_steps", p.schedule.warmup_steps}, {"resolution_every", p.schedule.resolution_every},
            {"num_downscales", p.schedule.num_downscales}}},
          {"densify",
           {{"grow_grad2d", d.grow_grad2d}, {"absgrad", d.absgrad}, {"per_band", d.per_band},
            {"grow_scale3d", d.grow_scale3d}, {"grow_scale2d", d.grow_scale2d}, {"prune_opacity", d.prune_opacity},
            {"prune_scale3d", d.prune_scale3d}, {"prune_scale2d", d.prune_scale2d}, {"reset_opacity", d.reset_opacity},
            {"refine_start", d.refine_start}, {"refine_stop", d.refine_stop}, {"refine_every", d.refine_every},
            {"reset_every", d.reset_every}, {"screen_stop", d.screen_stop}, {"pause_begin", d.pause_begin},
            {"pause_end", d.pause_end}, {"max_gaussians", d.max_gaussians}, {"stop_gaussians", d.stop_gaussians},
            {"reorder_every", d.reorder_every}}}};
}

/// The anytime-evaluation curve: one object per point (seconds on the training clock, step, model,
/// Gaussians, PSNR / SSIM per band), and the run's All curve over every band (curve.hpp, all_curve).
inline nlohmann::json curve_json(const RunResult& r) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json points = nlohmann::json::array();
  for (const CurvePoint& p : r.curve) {
    nlohmann::json psnr = nlohmann::json::object(), ssim = nlohmann::json::object();
    for (std::size_t b = 0; b < p.bands.size(); ++b) {
      psnr[p.bands[b]] = num(p.psnr[b]);
      ssim[p.bands[b]] = num(p.ssim[b]);
    }
    points.push_back({{"seconds", p.seconds}, {"step", p.step}, {"model", p.model}, {"gaussians", p.gaussians},
                      {"psnr", psnr}, {"ssim", ssim}});
  }
  std::vector<std::string> bands;
  for (const auto& m : r.metrics) bands.push_back(m.band);
  nlohmann::json all = nlohmann::json::array();
  for (const AllPoint& a : all_curve(r.curve, bands))
    all.push_back({{"seconds", a.seconds}, {"step", a.step}, {"gaussians", a.gaussians}, {"psnr", num(a.psnr)},
                   {"ssim", num(a.ssim)}});
  return {{"points", points}, {"all", all}};
}

/// The curve as CSV, one row per point and band plus the run's All rows:
/// seconds,step,model,gaussians,band,psnr,ssim.
inline std::string curve_csv(const RunResult& r) {
  std::string s = "seconds,step,model,gaussians,band,psnr,ssim\n";
  char buf[256];
  for (const CurvePoint& p : r.curve)
    for (std::size_t b = 0; b < p.bands.size(); ++b) {
      std::snprintf(buf, sizeof buf, "%.3f,%lld,%s,%zu,%s,%.4f,%.5f\n", p.seconds, p.step, p.model.c_str(), p.gaussians,
                    p.bands[b].c_str(), p.psnr[b], p.ssim[b]);
      s += buf;
    }
  std::vector<std::string> bands;
  for (const auto& m : r.metrics) bands.push_back(m.band);
  for (const AllPoint& a : all_curve(r.curve, bands)) {
    std::snprintf(buf, sizeof buf, "%.3f,%lld,all,%zu,All,%.4f,%.5f\n", a.seconds, a.step, a.gaussians, a.psnr, a.ssim);
    s += buf;
  }
  return s;
}

inline nlohmann::json result_json(const RunResult& r) {
  nlohmann::json j;
  j["strategy"] = r.strategy;
  j["plan"] = plan_json(r.plan);
  j["metrics"] = metrics_json(r.metrics);
  j["gaussians"] = r.gaussians;
  nlohmann::json models = nlohmann::json::object();
  for (const auto& [k, v] : r.models) models[k] = v.string();
  j["models"] = models;
  j["times"] = times_json(r.times);
  j["seconds"] = r.seconds;
  j["train_seconds"] = r.train_seconds;
  j["steps"] = r.steps;
  j["interrupted"] = r.interrupted;
  j["exposure"] = r.exposure;
  if (r.exposure) j["exposure_correction"] = exposure_json(r);
  if (!r.curve.empty()) j["curve"] = curve_json(r);
  return j;
}

/// "| All | RGB | G | R | RE | NIR |" rows of PSNR and SSIM for the bands present.
inline std::string metrics_markdown(const std::vector<BandMetrics>& metrics, const std::string& label = "") {
  auto find = [&](const std::string& id) -> const BandMetrics* {
    for (const auto& b : metrics) if (b.band == id) return &b;
    return nullptr;
  };
  std::string head = "| " + (label.empty() ? std::string("metric") : std::string("run")) + " | All";
  std::string sep = "|---|---";
  for (const auto& id : report_bands()) if (find(id)) { head += " | " + band_label(id); sep += "|---"; }
  head += " |\n";
  sep += "|\n";
  std::string out = head + sep;
  char buf[64];
  const int rows = has_colour_corrected(metrics) ? 4 : 2;  // then PSNR / SSIM colour-corrected
  for (int m = 0; m < rows; ++m) {
    const bool p = m % 2 == 0, cc = m >= 2;
    const std::string name = std::string(p ? "PSNR" : "SSIM") + (cc ? " (colour-corrected)" : "");
    out += "| " + (label.empty() ? name : label + " " + name);
    std::snprintf(buf, sizeof buf, p ? " | %.2f" : " | %.3f", all_bands_mean(metrics, p, cc));
    out += buf;
    for (const auto& id : report_bands()) {
      const BandMetrics* b = find(id);
      if (!b) continue;
      const auto& v = cc ? (p ? b->psnr_cc : b->ssim_cc) : (p ? b->psnr : b->ssim);
      std::snprintf(buf, sizeof buf, p ? " | %.2f ± %.2f" : " | %.3f ± %.3f", BandMetrics::mean(v), BandMetrics::stddev(v));
      out += buf;
    }
    out += " |\n";
  }
  return out;
}

/// One-line progress bar on stderr: step, ETA, loss, per-band training PSNR, Gaussians.
inline void print_progress(const TrainProgress& p) {
  const double frac = double(p.step - p.begin) / double(std::max<long long>(1, p.end - p.begin));
  const double eta = frac > 0 ? p.seconds * (1 - frac) / frac : 0;
  const int width = 24, filled = int(frac * width);
  std::string bar(std::size_t(filled), '#');
  bar += std::string(std::size_t(width - filled), '.');
  std::string psnrs;
  char buf[64];
  for (std::size_t i = 0; i < p.band_psnr.size() && i < p.band_ids.size(); ++i) {
    if (std::isnan(p.band_psnr[i])) continue;
    std::snprintf(buf, sizeof buf, " %s %.1f", band_label(p.band_ids[i]).c_str(), p.band_psnr[i]);
    psnrs += buf;
  }
  std::fprintf(stderr, "\r[%s] step %lld/%lld  ETA %4.0fs  loss %.4f  PSNR%s  N %zu   ", bar.c_str(), p.step, p.end,
               eta, p.loss, psnrs.c_str(), p.gaussians);
  if (p.step == p.end) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

}  // namespace msgs::cli
