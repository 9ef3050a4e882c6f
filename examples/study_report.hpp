// examples/study_report.hpp
// The `msgs study` tool's side of a study: reading finished runs' result.json into summaries,
// collecting a study directory, CSV / Markdown / JSON tables, gnuplot scripts, the study manifest
// (study.json) and job files (one `msgs train` command line per run) for GNU parallel or Slurm.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include <msgs/io/dataset.hpp>
#include <msgs/io/error.hpp>
#include <msgs/io/file.hpp>
#include <msgs/presets.hpp>
#include <msgs/strategy.hpp>
#include <msgs/study.hpp>

namespace msgs::study {

// ------------------------------------------------------------------------------------------------
// Results of finished runs

/// The numbers of one run a study table needs, read from its result.json.
struct RunSummary {
  StudyRun run;
  bool found = false;         ///< result.json was present and readable
  bool interrupted = false;   ///< the run stopped early
  std::string error;          ///< why found is false
  std::array<double, metric_columns> psnr{}, ssim{};  ///< All, D, MS_G, MS_R, MS_RE, MS_NIR; NaN if absent
  double seconds = std::numeric_limits<double>::quiet_NaN();  ///< wall time of the run
  long long steps = 0;        ///< optimisation steps over every model
  std::size_t gaussians = 0;  ///< summed over the run's models
  int threads = 0;            ///< OpenMP threads the run used (0: unknown)

  RunSummary() {
    psnr.fill(std::numeric_limits<double>::quiet_NaN());
    ssim.fill(std::numeric_limits<double>::quiet_NaN());
  }
};

namespace detail {
inline double json_double(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return std::numeric_limits<double>::quiet_NaN();
  return j[key].get<double>();
}

}  // namespace detail

/// A summary from the JSON that `msgs train` and `msgs study` write as result.json (see
/// examples/report.hpp): metrics.<band>.psnr_mean / ssim_mean, gaussians, seconds, steps, and
/// strategy, plan.schedule_scale, sh_degree, seed. `run` supplies id and labels; its
/// configuration fields are filled from the file when `fill_config`. `file` names errors.
inline RunSummary summary_from_json(const nlohmann::json& j, StudyRun run, const std::filesystem::path& file,
                                    bool fill_config = false) {
  auto bad = [&](const std::string& field, const std::string& what) {
    throw io::IoError(file.string() + ": field '" + field + "' " + what);
  };
  if (!j.is_object()) bad("(root)", "must be an object");
  if (!j.contains("metrics") || !j["metrics"].is_object()) bad("metrics", "must be an object of per-band metrics");
  RunSummary s;
  const auto& m = j["metrics"];
  std::vector<std::string> trained;
  for (std::size_t c = 1; c < metric_columns; ++c) {
    const std::string& b = column_keys()[c];
    if (!m.contains(b)) continue;
    if (!m[b].is_object()) bad("metrics." + b, "must be an object");
    trained.push_back(b);
    s.psnr[c] = detail::json_double(m[b], "psnr_mean");
    s.ssim[c] = detail::json_double(m[b], "ssim_mean");
  }
  if (trained.empty()) bad("metrics", "has no band (expected some of D, MS_G, MS_R, MS_RE, MS_NIR)");
  // "All" of the paper: mean over the trained bands of the per-band means, each band weighing the same.
  s.psnr[0] = detail::mean_finite(s.psnr.data() + 1, metric_columns - 1);
  s.ssim[0] = detail::mean_finite(s.ssim.data() + 1, metric_columns - 1);
  s.seconds = detail::json_double(j, "seconds");
  if (j.contains("steps") && j["steps"].is_number_integer()) s.steps = j["steps"].get<long long>();
  if (j.contains("gaussians")) {
    if (!j["gaussians"].is_object()) bad("gaussians", "must be an object of per-model counts");
    for (const auto& [k, v] : j["gaussians"].items()) {
      if (!v.is_number_unsigned() && !v.is_number_integer()) bad("gaussians." + k, "must be an integer");
      s.gaussians += v.get<std::size_t>();
    }
  }
  if (j.contains("interrupted") && j["interrupted"].is_boolean()) s.interrupted = j["interrupted"].get<bool>();
  if (j.contains("threads") && j["threads"].is_number_integer()) s.threads = j["threads"].get<int>();
  if (fill_config) {
    if (!j.contains("strategy") || !j["strategy"].is_string()) bad("strategy", "must be a strategy name");
    run.strategy = j["strategy"].get<std::string>();
    const double sc = j.contains("plan") ? detail::json_double(j["plan"], "schedule_scale") : std::nan("");
    if (std::isfinite(sc)) run.scale = sc;
    if (j.contains("sh_degree") && j["sh_degree"].is_number_integer()) run.sh_degree = j["sh_degree"].get<int>();
    if (j.contains("seed") && j["seed"].is_number_unsigned()) run.seed = j["seed"].get<std::uint64_t>();
    run.bands = trained.size() == band_ids().size() ? std::vector<std::string>{} : trained;
  }
  s.run = std::move(run);
  s.found = true;
  return s;
}

/// Summary of <dir>/result.json; a missing or unreadable file gives found = false and the reason.
inline RunSummary read_summary(const std::filesystem::path& dir, const StudyRun& run, bool fill_config = false) {
  const auto file = dir / "result.json";
  RunSummary s;
  s.run = run;
  if (!std::filesystem::exists(file)) { s.error = "no result.json (run not finished)"; return s; }
  try {
    return summary_from_json(io::detail::parse_json_file(file), run, file, fill_config);
  } catch (const std::exception& e) {
    s.error = e.what();
    return s;
  }
}

// ------------------------------------------------------------------------------------------------
// Writers

namespace detail {
inline std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) { if (c == '"') q += '"'; q += c; }
  return q + "\"";
}
inline std::string num_or_empty(double v, const char* fmt) { return std::isfinite(v) ? format_number(v, fmt) : ""; }
inline std::string num_or_dash(double v, const char* fmt) { return std::isfinite(v) ? format_number(v, fmt) : "-"; }
}  // namespace detail

/// Flags, per summary, of membership in the Pareto front of (seconds, PSNR of column `col`).
inline std::vector<bool> pareto_flags(const std::vector<RunSummary>& rows, std::size_t col = 0) {
  std::vector<double> c, q;
  for (const auto& r : rows) { c.push_back(r.found ? r.seconds : std::nan("")); q.push_back(r.found ? r.psnr[col] : std::nan("")); }
  std::vector<bool> f(rows.size(), false);
  for (std::size_t i : pareto_front(c, q)) f[i] = true;
  return f;
}

/// Header of the CSV written by summary_csv.
inline std::string csv_header() {
  std::string h = "id,knob,value,strategy,scale,sh_degree,bands,seed";
  for (const auto& l : column_labels()) h += ",psnr_" + l;
  for (const auto& l : column_labels()) h += ",ssim_" + l;
  return h + ",seconds,steps,gaussians,threads,pareto_All,status";
}

/// CSV, one row per (run, label): a run shared by several knobs appears once per knob. Missing
/// values are empty fields; status is "ok", "interrupted" or the reason the result is missing.
inline std::string summary_csv(const std::vector<RunSummary>& rows) {
  const std::vector<bool> front = pareto_flags(rows);
  std::string out = csv_header() + "\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const RunSummary& s = rows[i];
    std::vector<Label> labels = s.run.labels.empty() ? std::vector<Label>{{"run", s.run.id}} : s.run.labels;
    for (const Label& l : labels) {
      std::vector<std::string> f = {s.run.id, l.knob, l.value, s.run.strategy, detail::format_number(s.run.scale),
                                    std::to_string(s.run.sh_degree), detail::bands_label(s.run.bands),
                                    std::to_string(s.run.seed)};
      for (double v : s.psnr) f.push_back(detail::num_or_empty(v, "%.3f"));
      for (double v : s.ssim) f.push_back(detail::num_or_empty(v, "%.4f"));
      f.push_back(detail::num_or_empty(s.seconds, "%.2f"));
      f.push_back(s.found ? std::to_string(s.steps) : "");
      f.push_back(s.found ? std::to_string(s.gaussians) : "");
      f.push_back(s.threads ? std::to_string(s.threads) : "");
      f.push_back(front[i] ? "1" : "0");
      f.push_back(!s.found ? s.error : s.interrupted ? "interrupted" : "ok");
      for (std::size_t k = 0; k < f.size(); ++k) {
        if (k) out += ',';
        out += detail::csv_field(f[k]);
      }
      out += "\n";
    }
  }
  return out;
}

/// JSON of a study: its kind and options, and per run its configuration, labels and numbers.
inline nlohmann::json summary_json(StudyKind kind, const std::vector<RunSummary>& rows) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  const std::vector<bool> front = pareto_flags(rows);
  nlohmann::json runs = nlohmann::json::array();
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto& s = rows[i];
    nlohmann::json e = {{"id", s.run.id}, {"strategy", s.run.strategy}, {"scale", s.run.scale},
                        {"sh_degree", s.run.sh_degree}, {"bands", s.run.bands}, {"seed", s.run.seed},
                        {"found", s.found}, {"interrupted", s.interrupted}, {"pareto_All", bool(front[i])}};
    nlohmann::json labels = nlohmann::json::array();
    for (const auto& l : s.run.labels) labels.push_back({{"knob", l.knob}, {"value", l.value}});
    e["labels"] = labels;
    if (!s.found) e["error"] = s.error;
    nlohmann::json p = nlohmann::json::object(), q = nlohmann::json::object();
    for (std::size_t c = 0; c < metric_columns; ++c) { p[column_keys()[c]] = num(s.psnr[c]); q[column_keys()[c]] = num(s.ssim[c]); }
    e["psnr"] = p;
    e["ssim"] = q;
    e["seconds"] = num(s.seconds);
    e["steps"] = s.steps;
    e["gaussians"] = s.gaussians;
    e["threads"] = s.threads;
    if (const PaperRow* pr = paper_row(kind, s.run)) {
      nlohmann::json pp = nlohmann::json::object(), ps = nlohmann::json::object();
      for (std::size_t c = 0; c < metric_columns; ++c) { pp[column_keys()[c]] = num(pr->psnr[c]); ps[column_keys()[c]] = num(pr->ssim[c]); }
      e["paper"] = {{"psnr", pp}, {"ssim", ps}};
    }
    runs.push_back(e);
  }
  return {{"study", to_string(kind)}, {"runs", runs}, {"paper_note", paper_note}};
}

/// Markdown table of a study. Ablation and cross-talk print each run as a "measured" row with the
/// paper's row under it, and end with the rank correlation between the two; the cost study
/// prints knob, value, quality, time, Gaussians and Pareto membership (by All PSNR).
inline std::string summary_markdown(StudyKind kind, const std::vector<RunSummary>& rows) {
  std::string out;
  const bool paper = kind == StudyKind::Ablation || kind == StudyKind::Crosstalk;
  if (kind == StudyKind::Cost || kind == StudyKind::Convergence || kind == StudyKind::Runs) {
    const std::vector<bool> front = pareto_flags(rows);
    out += "| knob | value | PSNR All | RGB | G | R | RE | NIR | SSIM All | seconds | Gaussians | Pareto |\n";
    out += "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const auto& s = rows[i];
      std::vector<Label> labels = s.run.labels.empty() ? std::vector<Label>{{"run", s.run.id}} : s.run.labels;
      for (const auto& l : labels) {
        out += "| " + l.knob + " | " + l.value;
        for (double v : s.psnr) out += " | " + detail::num_or_dash(v, "%.2f");
        out += " | " + detail::num_or_dash(s.ssim[0], "%.3f") + " | " + detail::num_or_dash(s.seconds, "%.1f");
        out += " | " + (s.found ? std::to_string(s.gaussians) : std::string("-"));
        out += std::string(" | ") + (front[i] ? "yes" : "") + " |\n";
      }
    }
    out += "\nAll = mean over the bands a run trains (with fewer bands it averages different bands, so "
           "compare the RGB column across band counts). Pareto: no other run is both faster and better in All PSNR.\n";
  } else {
    const std::string first = kind == StudyKind::Ablation ? "configuration" : "bands";
    out += "| " + first + " | source | PSNR All | RGB | G | R | RE | NIR | SSIM All | RGB | G | R | RE | NIR | Gaussians | seconds |\n";
    out += "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const auto& s : rows) {
      const std::string name = kind == StudyKind::Ablation ? s.run.strategy : s.run.labels.empty() ? s.run.id : s.run.labels[0].value;
      out += "| " + name + " | measured";
      for (double v : s.psnr) out += " | " + detail::num_or_dash(v, "%.2f");
      for (double v : s.ssim) out += " | " + detail::num_or_dash(v, "%.3f");
      out += " | " + (s.found ? std::to_string(s.gaussians) : std::string("-")) + " | " + detail::num_or_dash(s.seconds, "%.1f") + " |\n";
      if (const PaperRow* p = paper_row(kind, s.run)) {
        out += "| | paper";
        for (double v : p->psnr) out += " | " + detail::num_or_dash(v, "%.2f");
        for (double v : p->ssim) out += " | " + detail::num_or_dash(v, "%.3f");
        out += " | | |\n";
      }
    }
    // Rank agreement on the column the table is about: All for the ablation, RGB for cross-talk.
    const std::size_t col = kind == StudyKind::Ablation ? 0 : 1;
    std::vector<double> ours, theirs;
    for (const auto& s : rows)
      if (const PaperRow* p = paper_row(kind, s.run)) { ours.push_back(s.found ? s.psnr[col] : std::nan("")); theirs.push_back(p->psnr[col]); }
    const double rho = spearman(ours, theirs);
    out += "\nSpearman rank correlation of " + std::string(col == 0 ? "All" : "RGB") +
           " PSNR, measured against paper: " + detail::num_or_dash(rho, "%.2f") + " (1 = same ranking).\n";
    if (kind == StudyKind::Crosstalk) out += "The paper's cross-talk table has no All column; its All here is the mean of the listed bands.\n";
  }
  if (paper) out += "\n" + std::string(paper_note) + "\n";
  return out;
}

// ------------------------------------------------------------------------------------------------
// gnuplot

/// A gnuplot script that plots PSNR against wall time, one PNG per column with data (cost_All.png,
/// cost_RGB.png, ...) into the script's working directory, points grouped by knob and labelled by
/// value, the Pareto front of each plot drawn as a line. The data are inline (datablocks), so the
/// script is self-contained: `gnuplot cost.gp`. Uses pngcairo when present, else png.
inline std::string gnuplot_script(const std::vector<RunSummary>& rows, const std::string& prefix = "cost",
                                  const std::string& title = "accuracy against time") {
  std::string gp;
  gp += "# Generated by msgs study: PSNR against wall time per run, Pareto front marked.\n";
  gp += "# Run it in the directory that should receive the PNGs: gnuplot " + prefix + ".gp\n";
  gp += "if (strstrt(GPVAL_TERMINALS, \"pngcairo\") > 0) {\n"
        "  set terminal pngcairo size 860,540 font \"sans,10\"\n"
        "} else {\n"
        "  set terminal png size 860,540\n"
        "}\n"
        "set termoption noenhanced\n"  // knob names such as sh_degree are not subscripts
        "set datafile missing \"?\"\n"
        "set logscale x\nset grid\nset key outside right top\n"
        "set xlabel \"wall time per run (s, log scale)\"\nset ylabel \"PSNR (dB), eval split\"\n";
  // Knobs in first-seen order; a run appears under every knob it is labelled with.
  std::vector<std::string> knobs;
  for (const auto& s : rows)
    for (const auto& l : s.run.labels.empty() ? std::vector<Label>{{"run", s.run.id}} : s.run.labels)
      if (std::find(knobs.begin(), knobs.end(), l.knob) == knobs.end()) knobs.push_back(l.knob);
  auto sanitize = [](std::string v) {
    for (char& c : v) if (c == '"' || c == '\\' || c == '\n') c = '\'';
    return v;
  };
  for (std::size_t k = 0; k < knobs.size(); ++k) {
    gp += "$knob" + std::to_string(k) + " << EOD\n# seconds psnr_All psnr_RGB psnr_G psnr_R psnr_RE psnr_NIR label\n";
    for (const auto& s : rows) {
      if (!s.found || !std::isfinite(s.seconds)) continue;
      for (const auto& l : s.run.labels.empty() ? std::vector<Label>{{"run", s.run.id}} : s.run.labels) {
        if (l.knob != knobs[k]) continue;
        gp += detail::format_number(s.seconds, "%.4f");
        for (double v : s.psnr) {
          gp += ' ';  // separate appends: GCC 12 warns falsely (-Wrestrict) on "literal" + temporary
          gp += std::isfinite(v) ? detail::format_number(v, "%.4f") : std::string("?");
        }
        gp += " \"" + sanitize(l.value) + "\"\n";
      }
    }
    gp += "EOD\n";
  }
  const std::array<int, 7> point_types = {7, 5, 9, 11, 13, 15, 3};
  const std::string label_col = std::to_string(2 + metric_columns);  // after seconds and the PSNR columns
  for (std::size_t c = 0; c < metric_columns; ++c) {
    std::vector<double> cost, q;
    for (const auto& s : rows) { cost.push_back(s.found ? s.seconds : std::nan("")); q.push_back(s.found ? s.psnr[c] : std::nan("")); }
    const std::vector<std::size_t> front = pareto_front(cost, q);
    if (front.empty()) continue;
    const std::string& lab = column_labels()[c];
    gp += "$front" + std::to_string(c) + " << EOD\n";
    for (std::size_t i : front) gp += detail::format_number(cost[i], "%.4f") + " " + detail::format_number(q[i], "%.4f") + "\n";
    gp += "EOD\n";
    gp += "set output \"" + prefix + "_" + lab + ".png\"\n";
    gp += "set title \"" + sanitize(title) + ": PSNR " + (c == 0 ? std::string("All (mean over trained bands)") : lab) + "\"\n";
    gp += "plot $front" + std::to_string(c) + " using 1:2 with lines lw 2 lc rgb \"#888888\" dt 2 title \"Pareto front\"";
    for (std::size_t k = 0; k < knobs.size(); ++k) {
      const std::string blk = "$knob" + std::to_string(k), col = std::to_string(2 + c);
      gp += ", \\\n     " + blk + " using 1:" + col + " with points pt " + std::to_string(point_types[k % point_types.size()]) +
            " ps 1.3 lc " + std::to_string(k + 1) + " title \"" + sanitize(knobs[k]) + "\"";
      gp += ", \\\n     " + blk + " using 1:" + col + ":" + label_col + " with labels offset char 0.6,0.6 left font \",7\" tc lt " +
            std::to_string(k + 1) + " notitle";
    }
    gp += "\nunset output\n";
  }
  return gp;
}

// ------------------------------------------------------------------------------------------------
// Job files and the study manifest

namespace detail {
/// Quote for a POSIX shell when the word has characters a shell would interpret.
inline std::string shell_quote(const std::string& w) {
  const bool plain = !w.empty() && std::all_of(w.begin(), w.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           std::string_view("_./+,=:@%-").find(c) != std::string_view::npos;
  });
  if (plain) return w;
  std::string q = "'";
  for (char c : w) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}
}  // namespace detail

/// The `msgs train` arguments of a run (without the program): --data, --out <out_root>/runs/<id>,
/// --strategy, --scale, --sh-degree, --seed, --bands (when not all), then `data_args` (the study's
/// --images, --eval-every, --geometry-band as given), --quiet.
inline std::vector<std::string> train_arguments(const StudyRun& r, const std::filesystem::path& data,
                                                const std::filesystem::path& out_root,
                                                const std::vector<std::string>& data_args = {}) {
  std::vector<std::string> a = {"train", "--data", data.string(), "--out", (out_root / "runs" / r.id).string(),
                                "--strategy", r.strategy, "--scale", detail::format_number(r.scale, "%.17g"),
                                "--sh-degree", std::to_string(r.sh_degree), "--seed", std::to_string(r.seed)};
  if (!r.bands.empty()) { a.push_back("--bands"); a.push_back(detail::join(r.bands, ",")); }
  if (r.preset != "reference") { a.push_back("--preset"); a.push_back(r.preset); }
  if (r.curve_seconds > 0) { a.push_back("--eval-every-seconds"); a.push_back(detail::format_number(r.curve_seconds, "%.17g")); }
  a.insert(a.end(), data_args.begin(), data_args.end());
  a.push_back("--quiet");
  return a;
}

/// One shell command line per run: `<msgs> train --data ... --out <out_root>/runs/<id> ...`.
inline std::string job_line(const StudyRun& r, const std::filesystem::path& msgs_exe, const std::filesystem::path& data,
                            const std::filesystem::path& out_root, const std::vector<std::string>& data_args = {}) {
  std::string line = detail::shell_quote(msgs_exe.string());
  for (const auto& w : train_arguments(r, data, out_root, data_args)) {
    line += ' ';
    line += detail::shell_quote(w);
  }
  return line;
}

/// Split a command line as a POSIX shell would for the quoting job_line produces: whitespace
/// separates words; '...' is literal; "..." allows \" and \\; a backslash outside quotes escapes
/// the next character. Throws std::invalid_argument on an unterminated quote.
inline std::vector<std::string> split_shell_words(std::string_view s) {
  std::vector<std::string> out;
  std::string cur;
  bool have = false;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r') {
      if (have) { out.push_back(cur); cur.clear(); have = false; }
    } else if (c == '\'') {
      const std::size_t e = s.find('\'', i + 1);
      if (e == std::string_view::npos) throw std::invalid_argument("unterminated ' in: " + std::string(s));
      cur.append(s.substr(i + 1, e - i - 1));
      have = true;
      i = e;
    } else if (c == '"') {
      std::size_t k = i + 1;
      for (; k < s.size() && s[k] != '"'; ++k) {
        if (s[k] == '\\' && k + 1 < s.size() && (s[k + 1] == '"' || s[k + 1] == '\\' || s[k + 1] == '$')) ++k;
        cur += s[k];
      }
      if (k >= s.size()) throw std::invalid_argument("unterminated \" in: " + std::string(s));
      have = true;
      i = k;
    } else if (c == '\\' && i + 1 < s.size()) {
      cur += s[++i];
      have = true;
    } else {
      cur += c;
      have = true;
    }
  }
  if (have) out.push_back(cur);
  return out;
}

/// A job line read back: the run's configuration, and its --data and --out.
struct ParsedJob {
  StudyRun run;  ///< id = the last component of --out
  std::filesystem::path data, out;
  std::vector<std::string> data_args;  ///< --images, --eval-every, --geometry-band with their values
};

/// Parse a line written by job_line. Throws std::invalid_argument naming the line and the problem.
inline ParsedJob parse_job_line(std::string_view line) {
  const std::vector<std::string> w = split_shell_words(line);
  auto fail = [&](const std::string& what) { throw std::invalid_argument("job line '" + std::string(line) + "': " + what); };
  if (w.size() < 2 || w[1] != "train") fail("expected '<msgs> train ...'");
  ParsedJob j;
  bool has_strategy = false;
  for (std::size_t i = 2; i < w.size(); ++i) {
    const std::string& k = w[i];
    if (k == "--quiet" || k == "--no-orient") continue;
    if (i + 1 >= w.size()) fail("option " + k + " needs a value");
    const std::string& v = w[++i];
    try {
      if (k == "--data") j.data = v;
      else if (k == "--out") j.out = v;
      else if (k == "--strategy") { j.run.strategy = parse_strategy(v).plan.name; has_strategy = true; }
      else if (k == "--scale") j.run.scale = std::stod(v);
      else if (k == "--sh-degree") j.run.sh_degree = std::stoi(v);
      else if (k == "--seed") j.run.seed = std::stoull(v);
      else if (k == "--preset") { (void)parse_preset(v); j.run.preset = v; }
      else if (k == "--eval-every-seconds") j.run.curve_seconds = std::stod(v);
      else if (k == "--images" || k == "--eval-every" || k == "--geometry-band" ||
               k == "--num-downscales") { j.data_args.push_back(k); j.data_args.push_back(v); }
      else if (k == "--bands") {
        j.run.bands.clear();
        std::string cur;
        for (char c : v + ",") {
          if (c == ',') { if (!cur.empty()) j.run.bands.push_back(cur); cur.clear(); }
          else cur += c;
        }
      } else fail("unknown option " + k);
    } catch (const std::logic_error& e) {  // std::stod / parse_strategy
      fail("bad value '" + v + "' for " + k + " (" + e.what() + ")");
    }
  }
  if (j.data.empty() || j.out.empty() || !has_strategy) fail("needs --data, --out and --strategy");
  j.run.id = j.out.filename().string();
  return j;
}

/// Manifest of a study (study.json): kind, options, data, and every run with its labels, so
/// `msgs study collect` can rebuild the tables from runs done elsewhere.
inline nlohmann::json manifest_json(StudyKind kind, const StudyOptions& o, const std::filesystem::path& data,
                                    const std::vector<StudyRun>& runs) {
  nlohmann::json rj = nlohmann::json::array();
  for (const auto& r : runs) {
    nlohmann::json labels = nlohmann::json::array();
    for (const auto& l : r.labels) labels.push_back({{"knob", l.knob}, {"value", l.value}});
    rj.push_back({{"id", r.id}, {"strategy", r.strategy}, {"scale", r.scale}, {"sh_degree", r.sh_degree},
                  {"bands", r.bands}, {"seed", r.seed}, {"labels", labels}, {"preset", r.preset},
                  {"curve_seconds", r.curve_seconds}});
  }
  return {{"study", to_string(kind)}, {"scale", o.scale}, {"sh_degree", o.sh_degree}, {"seed", o.seed},
          {"data", data.string()}, {"runs", rj}};
}

/// A study read back from its manifest.
struct Manifest {
  StudyKind kind = StudyKind::Runs;
  StudyOptions options;
  std::filesystem::path data;
  std::vector<StudyRun> runs;
};

/// Parse study.json; io::IoError naming the file and field when it is malformed.
inline Manifest read_manifest(const std::filesystem::path& file) {
  const nlohmann::json j = io::detail::parse_json_file(file);
  auto bad = [&](const std::string& field, const std::string& what) {
    throw io::IoError(file.string() + ": field '" + field + "' " + what);
  };
  Manifest m;
  try {
    if (!j.is_object() || !j.contains("study") || !j["study"].is_string()) bad("study", "must be a study name");
    m.kind = parse_study_kind(j["study"].get<std::string>());
    if (!j.contains("runs") || !j["runs"].is_array()) bad("runs", "must be an array");
    m.options.scale = j.value("scale", m.options.scale);
    m.options.sh_degree = j.value("sh_degree", m.options.sh_degree);
    m.options.seed = j.value("seed", m.options.seed);
    m.data = j.value("data", std::string());
    for (std::size_t i = 0; i < j["runs"].size(); ++i) {
      const auto& e = j["runs"][i];
      const std::string f = "runs[" + std::to_string(i) + "]";
      if (!e.is_object() || !e.contains("id") || !e["id"].is_string()) bad(f + ".id", "must be a string");
      if (!e.contains("strategy") || !e["strategy"].is_string()) bad(f + ".strategy", "must be a string");
      StudyRun r;
      r.id = e["id"].get<std::string>();
      r.strategy = e["strategy"].get<std::string>();
      r.scale = e.value("scale", 1.0);
      r.sh_degree = e.value("sh_degree", 3);
      r.seed = e.value("seed", std::uint64_t(0));
      r.bands = e.value("bands", std::vector<std::string>{});
      r.preset = e.value("preset", std::string("reference"));
      r.curve_seconds = e.value("curve_seconds", 0.0);
      if (e.contains("labels"))
        for (const auto& l : e["labels"]) r.labels.push_back({l.value("knob", ""), l.value("value", "")});
      m.runs.push_back(std::move(r));
    }
  } catch (const nlohmann::json::exception& e) {  // a field of the wrong type in value()
    bad("runs", std::string("has a field of the wrong type (") + e.what() + ")");
  } catch (const std::invalid_argument& e) {
    bad("study", e.what());
  }
  return m;
}

/// Summaries of a study directory: with <dir>/study.json, one per listed run (missing results
/// reported as such); without it, one per <dir>/runs/*/result.json (or <dir>/*/result.json), its
/// configuration read from the file and labelled ("run", directory name). Sorted as listed / by name.
inline std::vector<RunSummary> collect(const std::filesystem::path& dir, StudyKind* kind_out = nullptr) {
  namespace fs = std::filesystem;
  std::vector<RunSummary> out;
  if (fs::exists(dir / "study.json")) {
    const Manifest m = read_manifest(dir / "study.json");
    if (kind_out) *kind_out = m.kind;
    for (const auto& r : m.runs) out.push_back(read_summary(dir / "runs" / r.id, r));
    return out;
  }
  if (kind_out) *kind_out = StudyKind::Runs;
  const fs::path root = fs::is_directory(dir / "runs") ? dir / "runs" : dir;
  if (!fs::is_directory(root)) throw io::IoError(dir.string() + ": not a directory");
  std::vector<fs::path> dirs;
  for (const auto& e : fs::directory_iterator(root))
    if (e.is_directory() && fs::exists(e.path() / "result.json")) dirs.push_back(e.path());
  std::sort(dirs.begin(), dirs.end());
  for (const auto& d : dirs) {
    StudyRun r;
    r.id = d.filename().string();
    r.labels = {{"run", r.id}};
    out.push_back(read_summary(d, r, true));
  }
  return out;
}

}  // namespace msgs::study
