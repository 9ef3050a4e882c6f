// examples/study_convergence.hpp: the report of `msgs study convergence`: every run's anytime
// evaluation curves (quality against training seconds) as CSV, one gnuplot figure per band and for
// All with a line per run, the final table, and where each pair of All curves crosses.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <msgs/curve.hpp>
#include <msgs/io/dataset.hpp>
#include <msgs/io/file.hpp>
#include "study_report.hpp"

namespace msgs::cli {

/// One run's curves: per column key ("All", "D", "MS_G", ...) the (seconds, PSNR, SSIM) series.
struct RunCurves {
  std::string id, label;
  std::map<std::string, std::vector<std::array<double, 3>>> series;
  double final_seconds = std::nan("");  ///< training clock at the end (train_seconds)
};

/// The curves of a run from its result.json ("curve": points and all); empty when it has none.
inline RunCurves read_run_curves(const std::filesystem::path& dir, const study::StudyRun& run) {
  RunCurves rc;
  rc.id = run.id;
  rc.label = run.labels.empty() ? run.id : run.labels[0].value;
  const auto file = dir / "result.json";
  if (!std::filesystem::exists(file)) return rc;
  const nlohmann::json j = io::detail::parse_json_file(file);
  if (j.contains("train_seconds") && j["train_seconds"].is_number()) rc.final_seconds = j["train_seconds"].get<double>();
  if (!j.contains("curve") || !j["curve"].is_object()) return rc;
  auto num = [](const nlohmann::json& v) { return v.is_number() ? v.get<double>() : std::nan(""); };
  const auto& c = j["curve"];
  if (c.contains("points") && c["points"].is_array())
    for (const auto& p : c["points"]) {
      if (!p.contains("psnr") || !p["psnr"].is_object()) continue;
      for (const auto& [band, v] : p["psnr"].items())
        rc.series[band].push_back({num(p.value("seconds", nlohmann::json())), num(v),
                                   p.contains("ssim") && p["ssim"].contains(band) ? num(p["ssim"][band]) : std::nan("")});
    }
  if (c.contains("all") && c["all"].is_array())
    for (const auto& a : c["all"])
      rc.series["All"].push_back({num(a.value("seconds", nlohmann::json())), num(a.value("psnr", nlohmann::json())),
                                  num(a.value("ssim", nlohmann::json()))});
  return rc;
}

namespace detail {
inline std::string fmt(double v, const char* f) {
  if (!std::isfinite(v)) return "-";
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}
inline std::vector<double> column(const std::vector<std::array<double, 3>>& s, std::size_t k) {
  std::vector<double> v;
  for (const auto& p : s) v.push_back(p[k]);
  return v;
}
/// First training second from which the series stays within `tol` dB of its final value.
inline double settle_seconds(const std::vector<std::array<double, 3>>& s, double tol) {
  if (s.empty()) return std::nan("");
  const double last = s.back()[1];
  double t = s.back()[0];
  for (std::size_t i = s.size(); i-- > 0;) {
    if (!(std::abs(s[i][1] - last) <= tol)) break;
    t = s[i][0];
  }
  return t;
}
}  // namespace detail

/// Long-format CSV of every curve: run,label,band,seconds,psnr,ssim (band "All" = the run's All).
inline std::string convergence_csv(const std::vector<RunCurves>& runs) {
  std::string s = "run,label,band,seconds,psnr,ssim\n";
  for (const auto& r : runs)
    for (const auto& [band, pts] : r.series)
      for (const auto& p : pts)
        s += r.id + "," + study::detail::csv_field(r.label) + "," + band + "," + detail::fmt(p[0], "%.3f") + "," +
             detail::fmt(p[1], "%.4f") + "," + detail::fmt(p[2], "%.5f") + "\n";
  return s;
}

/// Markdown: per run its final All PSNR on the curve's subset, training seconds, and when it
/// settled (within 0.5 dB of its final value); then, for every pair of runs, where their All
/// PSNR curves cross. A run that has finished keeps its final quality from then on (the model one
/// would have at that time), so a fast run and a slow one are compared over the slow one's time.
inline std::string convergence_markdown(const std::vector<RunCurves>& runs) {
  std::string out = "## Quality against training time (All PSNR on the anytime-evaluation subset)\n\n";
  out += "| run | final All PSNR | training s | settled (within 0.5 dB of final) from s |\n|---|---|---|---|\n";
  for (const auto& r : runs) {
    const auto it = r.series.find("All");
    const bool has = it != r.series.end() && !it->second.empty();
    out += "| " + r.label + " | " + (has ? detail::fmt(it->second.back()[1], "%.2f") : "-") + " | " +
           detail::fmt(r.final_seconds, "%.0f") + " | " + (has ? detail::fmt(detail::settle_seconds(it->second, 0.5), "%.0f") : "-") +
           " |\n";
  }
  out += "\n## Crossings of the All PSNR curves\n\n";
  out += "Curves are piecewise linear through the evaluations, from the first time both runs have an All "
         "value (Separate and Split have one once their last band's model starts); a finished run keeps its "
         "final value.\n\n";
  out += "| run A | run B | A - B at the end | crossings (s: leader after) |\n|---|---|---|---|\n";
  for (std::size_t a = 0; a < runs.size(); ++a)
    for (std::size_t b = a + 1; b < runs.size(); ++b) {
      const auto ia = runs[a].series.find("All"), ib = runs[b].series.find("All");
      if (ia == runs[a].series.end() || ib == runs[b].series.end() || ia->second.empty() || ib->second.empty()) continue;
      auto ta = detail::column(ia->second, 0), va = detail::column(ia->second, 1);
      auto tb = detail::column(ib->second, 0), vb = detail::column(ib->second, 1);
      const double end = std::max(ta.back(), tb.back());
      for (auto tv : {std::make_pair(&ta, &va), std::make_pair(&tb, &vb)})
        if (tv.first->back() < end) { tv.first->push_back(end); tv.second->push_back(tv.second->back()); }
      const std::vector<Crossing> xs = crossings(ta, va, tb, vb, 1e-3);
      const double d = curve_at(ta, va, end) - curve_at(tb, vb, end);
      std::string xl;
      for (const auto& x : xs) xl += (xl.empty() ? "" : ", ") + detail::fmt(x.seconds, "%.0f") + ": " + (x.a_ahead_after ? runs[a].label : runs[b].label);
      out += "| " + runs[a].label + " | " + runs[b].label + " | " + detail::fmt(d, "%+.2f") + " dB at " +
             detail::fmt(end, "%.0f") + " s | " + (xl.empty() ? "none" : xl) + " |\n";
    }
  return out;
}

/// gnuplot script: curves_<All|RGB|G|...>.png, PSNR against training seconds, a line per run.
inline std::string convergence_gnuplot(const std::vector<RunCurves>& runs, const std::string& title) {
  std::string gp = "# Generated by msgs study convergence: PSNR against training time, a line per run.\n"
                   "if (strstrt(GPVAL_TERMINALS, \"pngcairo\") > 0) {\n"
                   "  set terminal pngcairo size 860,540 font \"sans,10\"\n"
                   "} else {\n"
                   "  set terminal png size 860,540\n"
                   "}\n"
                   "set termoption noenhanced\nset grid\nset key outside right top\n"
                   "set xlabel \"training time (s; evaluations excluded)\"\nset ylabel \"PSNR (dB), eval subset\"\n";
  const std::vector<std::pair<std::string, std::string>> cols = {
      {"All", "All"}, {"D", "RGB"}, {"MS_G", "G"}, {"MS_R", "R"}, {"MS_RE", "RE"}, {"MS_NIR", "NIR"}};
  for (std::size_t r = 0; r < runs.size(); ++r)
    for (const auto& [key, lab] : cols) {
      const auto it = runs[r].series.find(key);
      if (it == runs[r].series.end()) continue;
      gp += "$r" + std::to_string(r) + "_" + lab + " << EOD\n";
      for (const auto& p : it->second)
        if (std::isfinite(p[0]) && std::isfinite(p[1])) gp += detail::fmt(p[0], "%.3f") + " " + detail::fmt(p[1], "%.4f") + "\n";
      gp += "EOD\n";
    }
  for (const auto& [key, lab] : cols) {
    std::string plot;
    for (std::size_t r = 0; r < runs.size(); ++r) {
      if (!runs[r].series.count(key)) continue;
      std::string name = runs[r].label;
      for (char& c : name) if (c == '"' || c == '\\') c = '\'';
      plot += std::string(plot.empty() ? "plot " : ", \\\n     ") + "$r" + std::to_string(r) + "_" + lab +
              " using 1:2 with linespoints lw 2 pt 7 ps 0.6 lc " + std::to_string(r + 1) + " title \"" + name + "\"";
    }
    if (plot.empty()) continue;
    gp += "set output \"curves_" + lab + ".png\"\nset title \"" + title + ": PSNR " + lab + "\"\n" + plot + "\nunset output\n";
  }
  return gp;
}

/// Write convergence.csv, convergence.md and convergence.gp for the study in `out`.
inline std::vector<RunCurves> write_convergence_report(const std::filesystem::path& out,
                                                       const std::vector<study::RunSummary>& rows) {
  std::vector<RunCurves> runs;
  for (const auto& s : rows) runs.push_back(read_run_curves(out / "runs" / s.run.id, s.run));
  io::write_text_atomic(out / "convergence.csv", convergence_csv(runs));
  io::write_text_atomic(out / "convergence.md", "# msgs study convergence\n\n" + convergence_markdown(runs));
  io::write_text_atomic(out / "convergence.gp", convergence_gnuplot(runs, "msgs study convergence"));
  return runs;
}

}  // namespace msgs::cli
