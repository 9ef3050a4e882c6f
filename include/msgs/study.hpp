// include/msgs/study.hpp
// Studies over many runs: the paper's ablation and cross-talk run lists, an accuracy-against-time
// sweep of each quality knob, aggregation of result.json files, Pareto fronts, CSV / Markdown /
// gnuplot writers and job files (one `msgs train` command line per run) for GNU parallel or Slurm.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "presets.hpp"

#include "io/dataset.hpp"
#include "io/error.hpp"
#include "io/file.hpp"
#include "strategy.hpp"

namespace msgs::study {

/// The studies `msgs study` knows.
enum class StudyKind { Ablation, Crosstalk, Cost, Convergence, Runs };

inline const char* to_string(StudyKind k) {
  switch (k) {
    case StudyKind::Ablation: return "ablation";
    case StudyKind::Crosstalk: return "crosstalk";
    case StudyKind::Cost: return "cost";
    case StudyKind::Convergence: return "convergence";
    case StudyKind::Runs: return "runs";
  }
  return "?";
}

/// "ablation" -> StudyKind::Ablation; std::invalid_argument otherwise.
inline StudyKind parse_study_kind(std::string_view s) {
  for (StudyKind k : {StudyKind::Ablation, StudyKind::Crosstalk, StudyKind::Cost, StudyKind::Convergence, StudyKind::Runs})
    if (s == to_string(k)) return k;
  throw std::invalid_argument("unknown study '" + std::string(s) + "'; valid: ablation, crosstalk, cost, convergence, runs");
}

/// Band ids in the paper's column order; "All" (mean over the trained bands) comes first in tables.
inline const std::array<std::string, 5>& band_ids() {
  static const std::array<std::string, 5> b = {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  return b;
}

/// Metric columns of every table: All, then the five bands.
inline constexpr std::size_t metric_columns = 6;
/// Column keys ("All", then band ids) and their labels as the paper prints them.
inline const std::array<std::string, metric_columns>& column_keys() {
  static const std::array<std::string, metric_columns> k = {"All", "D", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  return k;
}
inline const std::array<std::string, metric_columns>& column_labels() {
  static const std::array<std::string, metric_columns> l = {"All", "RGB", "G", "R", "RE", "NIR"};
  return l;
}

/// A (knob, value) label of a run: which study axis it belongs to. A run shared by several axes
/// (the cost study's baseline) carries several labels and is trained once.
struct Label {
  std::string knob;   ///< "strategy", "sh_degree", "scale", "modifiers", "bands", "subset", "run"
  std::string value;  ///< the knob's value as printed ("F/2", "+msad", "D+G+R")
  bool operator==(const Label&) const = default;
};

/// One run of a study: everything `msgs train` needs, plus its labels.
struct StudyRun {
  std::string id;                  ///< directory name under <out>/runs, unique within a study
  std::string strategy;            ///< canonical strategy name
  double scale = 1.0;              ///< schedule scale
  int sh_degree = 3;
  std::vector<std::string> bands;  ///< bands to train, standard order; empty = every band
  std::uint64_t seed = 0;
  std::vector<Label> labels;
  std::string preset = "reference";  ///< training preset (presets.hpp)
  double curve_seconds = 0;          ///< anytime evaluation every this many training seconds (0: off)
};

/// Shared settings of a study's runs.
struct StudyOptions {
  double scale = 0.01;     ///< schedule scale F of the study (the cost study varies it around F)
  int sh_degree = 3;
  std::uint64_t seed = 0;
  /// Convergence study: the strategies and presets crossed, and the anytime evaluation's period.
  std::vector<std::string> strategies = {"separate", "split", "joint", "joint-optimized"};
  std::vector<std::string> presets = {"reference"};
  double curve_seconds = 10;
};

namespace detail {
inline std::string format_number(double v, const char* fmt = "%g") {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

inline std::string join(const std::vector<std::string>& v, std::string_view sep) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) { if (i) s += sep; s += v[i]; }
  return s;
}

/// "D+G+R" from {"D", "MS_G", "MS_R"}.
inline std::string bands_label(const std::vector<std::string>& bands) {
  if (bands.empty()) return "all";
  std::vector<std::string> l;
  for (const auto& b : bands) l.push_back(b == "D" ? "RGB" : b.rfind("MS_", 0) == 0 ? b.substr(3) : b);
  return join(l, "+");
}

/// Sort band ids into the standard order (unknown ids last, in their given order).
inline std::vector<std::string> standard_order(std::vector<std::string> bands) {
  const auto& ids = band_ids();
  auto rank = [&](const std::string& b) { return std::size_t(std::find(ids.begin(), ids.end(), b) - ids.begin()); };
  std::stable_sort(bands.begin(), bands.end(), [&](const auto& a, const auto& b) { return rank(a) < rank(b); });
  return bands;
}
}  // namespace detail

/// Directory name of a run, made from its configuration so equal configurations share it:
/// "joint+specdelay+msad_sh3_x0.01_all", "..._D+MS_G".
inline std::string make_run_id(const StudyRun& r) {
  std::string id = r.strategy + "_sh" + std::to_string(r.sh_degree) + "_x" + detail::format_number(r.scale) + "_";
  id += r.bands.empty() ? std::string("all") : detail::join(r.bands, "+");
  if (r.seed != 0) id += "_seed" + std::to_string(r.seed);
  if (r.preset != "reference") id += "_" + r.preset;
  return id;
}

/// Append `r` to `runs`, or only its labels when an equal configuration is already listed.
inline void add_run(std::vector<StudyRun>& runs, StudyRun r) {
  r.strategy = parse_strategy(r.strategy).plan.name;  // canonical, and validates the name
  r.bands = detail::standard_order(r.bands);
  if (r.bands.size() == band_ids().size() && std::equal(r.bands.begin(), r.bands.end(), band_ids().begin()))
    r.bands.clear();  // every band of the standard layout: same as "all"
  r.id = make_run_id(r);
  for (auto& e : runs)
    if (e.id == r.id) {
      for (auto& l : r.labels)
        if (std::find(e.labels.begin(), e.labels.end(), l) == e.labels.end()) e.labels.push_back(l);
      return;
    }
  runs.push_back(std::move(r));
}

/// The 15 configurations of the paper's ablation table (tab:ablation), in its row order.
inline std::vector<StudyRun> ablation_runs(const StudyOptions& o) {
  std::vector<StudyRun> runs;
  for (const auto& name : strategy_names())
    add_run(runs, {"", name, o.scale, o.sh_degree, {}, o.seed, {{"strategy", name}}});
  return runs;
}

/// The 16 band subsets of the cross-talk table (tab:cross_talk_investigation): RGB plus every
/// combination of G, R, RE, NIR, in the table's row order (by size, then lexicographic in band
/// order). D is always the first element.
inline std::vector<std::vector<std::string>> crosstalk_subsets() {
  const std::vector<std::string> ms = {"MS_G", "MS_R", "MS_RE", "MS_NIR"};
  std::vector<std::vector<std::string>> out;
  for (std::size_t k = 0; k <= ms.size(); ++k) {
    // All k-combinations in lexicographic order of indices (the table's order within a size).
    std::vector<int> idx(k);
    std::iota(idx.begin(), idx.end(), 0);
    while (true) {
      std::vector<std::string> s = {"D"};
      for (int i : idx) s.push_back(ms[std::size_t(i)]);
      out.push_back(s);
      int i = int(k) - 1;
      while (i >= 0 && idx[std::size_t(i)] == int(ms.size() - k) + i) --i;
      if (i < 0) break;
      ++idx[std::size_t(i)];
      for (std::size_t j = std::size_t(i) + 1; j < k; ++j) idx[j] = idx[j - 1] + 1;
    }
  }
  return out;
}

/// Joint-Optimized on each cross-talk subset.
inline std::vector<StudyRun> crosstalk_runs(const StudyOptions& o) {
  std::vector<StudyRun> runs;
  for (const auto& s : crosstalk_subsets())
    add_run(runs, {"", "joint+specdelay+msad", o.scale, o.sh_degree, s, o.seed, {{"subset", detail::bands_label(s)}}});
  return runs;
}

/// Accuracy against time, one knob at a time around a baseline (Joint-Optimized, scale F, SH
/// degree of the options, every band): SH degree 0..3; scale F/4, F/2, F, 2F; strategy separate,
/// split, joint, joint-optimized; Joint modifiers one at a time; band count 1..5 (RGB, then G, R,
/// RE, NIR added in turn). Equal configurations are listed once with several labels.
inline std::vector<StudyRun> cost_runs(const StudyOptions& o) {
  std::vector<StudyRun> runs;
  const std::string base = "joint+specdelay+msad";
  auto add = [&](const std::string& strat, double scale, int deg, std::vector<std::string> bands, Label l) {
    add_run(runs, {"", strat, scale, deg, std::move(bands), o.seed, {std::move(l)}});
  };
  for (int d = 0; d <= 3; ++d) add(base, o.scale, d, {}, {"sh_degree", std::to_string(d)});
  const std::array<std::pair<double, const char*>, 4> scales = {{{0.25, "F/4"}, {0.5, "F/2"}, {1.0, "F"}, {2.0, "2F"}}};
  for (const auto& [f, label] : scales) add(base, o.scale * f, o.sh_degree, {}, {"scale", label});
  for (const char* s : {"separate", "split", "joint", "joint+specdelay+msad"})
    add(s, o.scale, o.sh_degree, {}, {"strategy", s == base ? std::string("joint-optimized") : std::string(s)});
  for (const char* m : {"", "+sig", "+specdelay", "+extadc", "+msad", "+specdelay+msad"})
    add(std::string("joint") + m, o.scale, o.sh_degree, {}, {"modifiers", *m ? std::string(m) : std::string("none")});
  std::vector<std::string> bands;
  for (const auto& b : band_ids()) {
    bands.push_back(b);
    add(base, o.scale, o.sh_degree, bands, {"bands", std::to_string(bands.size())});
  }
  return runs;
}

/// Quality against training time: every strategy of `o.strategies` with every preset of
/// `o.presets` at scale F on every band, each with the anytime evaluation every o.curve_seconds.
/// Labelled ("run", "<strategy>" or "<strategy> (<preset>)").
inline std::vector<StudyRun> convergence_runs(const StudyOptions& o) {
  std::vector<StudyRun> runs;
  if (!(o.curve_seconds > 0) || !std::isfinite(o.curve_seconds))
    throw std::invalid_argument("convergence study: the evaluation period must be > 0 seconds");
  for (const std::string& preset : o.presets) {
    (void)parse_preset(preset);
    for (const std::string& strat : o.strategies) {
      StudyRun r{"", strat, o.scale, o.sh_degree, {}, o.seed, {}};
      const std::string name = parse_strategy(strat).plan.name == "joint+specdelay+msad" ? "joint-optimized" : parse_strategy(strat).plan.name;
      r.labels = {{"run", o.presets.size() > 1 ? name + " (" + preset + ")" : name}};
      r.preset = preset;
      r.curve_seconds = o.curve_seconds;
      add_run(runs, std::move(r));
    }
  }
  return runs;
}

/// The run list of a study kind (StudyKind::Runs has none: it only collects).
inline std::vector<StudyRun> study_runs(StudyKind k, const StudyOptions& o) {
  switch (k) {
    case StudyKind::Ablation: return ablation_runs(o);
    case StudyKind::Crosstalk: return crosstalk_runs(o);
    case StudyKind::Cost: return cost_runs(o);
    case StudyKind::Convergence: return convergence_runs(o);
    case StudyKind::Runs: return {};
  }
  return {};
}

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

inline double mean_finite(const double* v, std::size_t n) {
  double s = 0;
  int c = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (std::isfinite(v[i])) { s += v[i]; ++c; }
  return c ? s / c : std::numeric_limits<double>::quiet_NaN();
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
// Pareto front and rank correlation

/// Indices of the points not dominated by any other, sorted by cost: a point is dominated when
/// another costs no more and scores at least as well, and is strictly better in one of the two.
/// Points with a non-finite cost or quality are never on the front.
inline std::vector<std::size_t> pareto_front(const std::vector<double>& cost, const std::vector<double>& quality) {
  if (cost.size() != quality.size()) throw std::invalid_argument("pareto_front: cost and quality differ in length");
  std::vector<std::size_t> front;
  const std::size_t n = cost.size();
  auto ok = [&](std::size_t i) { return std::isfinite(cost[i]) && std::isfinite(quality[i]); };
  for (std::size_t i = 0; i < n; ++i) {
    if (!ok(i)) continue;
    bool dominated = false;
    for (std::size_t k = 0; k < n && !dominated; ++k)
      dominated = k != i && ok(k) && cost[k] <= cost[i] && quality[k] >= quality[i] &&
                  (cost[k] < cost[i] || quality[k] > quality[i]);
    if (!dominated) front.push_back(i);
  }
  std::stable_sort(front.begin(), front.end(), [&](std::size_t a, std::size_t b) { return cost[a] < cost[b]; });
  return front;
}

/// Spearman's rank correlation of the pairs where both values are finite (ties get their mean
/// rank); NaN with fewer than 3 such pairs or when one side is constant.
inline double spearman(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> x, y;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (std::isfinite(a[i]) && std::isfinite(b[i])) { x.push_back(a[i]); y.push_back(b[i]); }
  const std::size_t n = x.size();
  if (n < 3) return std::nan("");
  auto ranks = [n](const std::vector<double>& v) {
    std::vector<std::size_t> o(n);
    std::iota(o.begin(), o.end(), 0);
    std::sort(o.begin(), o.end(), [&](std::size_t p, std::size_t q) { return v[p] < v[q]; });
    std::vector<double> r(n);
    for (std::size_t i = 0; i < n;) {
      std::size_t j = i;
      while (j + 1 < n && v[o[j + 1]] == v[o[i]]) ++j;
      for (std::size_t k = i; k <= j; ++k) r[o[k]] = 0.5 * double(i + j) + 1.0;
      i = j + 1;
    }
    return r;
  };
  const std::vector<double> rx = ranks(x), ry = ranks(y);
  const double mx = std::accumulate(rx.begin(), rx.end(), 0.0) / double(n);
  const double my = std::accumulate(ry.begin(), ry.end(), 0.0) / double(n);
  double sxy = 0, sxx = 0, syy = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sxy += (rx[i] - mx) * (ry[i] - my);
    sxx += (rx[i] - mx) * (rx[i] - mx);
    syy += (ry[i] - my) * (ry[i] - my);
  }
  if (sxx == 0 || syy == 0) return std::nan("");
  return sxy / std::sqrt(sxx * syy);
}

// ------------------------------------------------------------------------------------------------
// The paper's numbers (means over the seven scenes, 120k-step GPU runs on real captures)

/// One row of a paper table: PSNR and SSIM per column (All, RGB, G, R, RE, NIR); NaN = "-".
struct PaperRow {
  std::string key;  ///< canonical strategy name (ablation) or band-subset label (cross-talk)
  std::array<double, metric_columns> psnr, ssim;
};

/// tab:ablation of the paper, row for row.
inline const std::vector<PaperRow>& paper_ablation() {
  static const std::vector<PaperRow> t = {
      {"separate", {23.62, 20.86, 22.92, 25.23, 23.33, 25.75}, {0.721, 0.623, 0.667, 0.769, 0.730, 0.815}},
      {"split", {24.76, 20.86, 24.49, 26.56, 25.00, 26.91}, {0.743, 0.623, 0.708, 0.808, 0.757, 0.821}},
      {"split+extadc", {24.70, 20.93, 24.52, 26.61, 24.17, 27.25}, {0.746, 0.629, 0.711, 0.810, 0.747, 0.833}},
      {"joint+sig", {23.11, 19.57, 22.98, 24.76, 23.12, 25.19}, {0.673, 0.515, 0.650, 0.746, 0.683, 0.774}},
      {"joint+sig+extadc", {23.35, 19.83, 23.24, 25.07, 23.28, 25.38}, {0.680, 0.530, 0.654, 0.752, 0.690, 0.777}},
      {"joint+sig+msad", {23.54, 19.98, 23.38, 25.27, 23.45, 25.67}, {0.681, 0.545, 0.652, 0.750, 0.688, 0.774}},
      {"joint+sig+specdelay", {24.21, 21.09, 23.81, 25.81, 24.09, 26.34}, {0.725, 0.631, 0.681, 0.783, 0.730, 0.802}},
      {"joint+sig+specdelay+extadc", {24.27, 21.18, 23.90, 25.83, 24.13, 26.38}, {0.727, 0.631, 0.682, 0.784, 0.732, 0.805}},
      {"joint+sig+specdelay+msad", {24.41, 21.40, 23.94, 25.93, 24.28, 26.57}, {0.734, 0.644, 0.688, 0.789, 0.741, 0.811}},
      {"joint", {23.94, 19.88, 23.92, 25.92, 23.92, 26.15}, {0.715, 0.554, 0.694, 0.785, 0.730, 0.813}},
      {"joint+extadc", {24.21, 20.20, 24.11, 26.15, 24.17, 26.52}, {0.719, 0.570, 0.695, 0.788, 0.733, 0.813}},
      {"joint+msad", {24.48, 20.57, 24.31, 26.40, 24.41, 26.79}, {0.736, 0.599, 0.708, 0.801, 0.748, 0.824}},
      {"joint+specdelay", {24.80, 21.03, 24.62, 26.56, 24.83, 27.04}, {0.747, 0.634, 0.713, 0.807, 0.757, 0.827}},
      {"joint+specdelay+extadc", {24.90, 21.27, 24.60, 26.56, 24.96, 27.19}, {0.753, 0.639, 0.718, 0.811, 0.764, 0.834}},
      {"joint+specdelay+msad", {24.99, 21.29, 24.62, 26.61, 25.07, 27.42}, {0.755, 0.647, 0.719, 0.810, 0.766, 0.834}},
  };
  return t;
}

/// tab:cross_talk_investigation of the paper (Joint-Optimized). The table has no "All" column;
/// column 0 holds the mean of the listed bands so it lines up with measured rows.
inline const std::vector<PaperRow>& paper_crosstalk() {
  constexpr double X = std::numeric_limits<double>::quiet_NaN();
  static const std::vector<PaperRow> t = [] {
    std::vector<PaperRow> r = {
        {"RGB", {X, 21.06, X, X, X, X}, {X, 0.637, X, X, X, X}},
        {"RGB+G", {X, 21.16, 24.33, X, X, X}, {X, 0.641, 0.711, X, X, X}},
        {"RGB+R", {X, 21.22, X, 26.30, X, X}, {X, 0.644, X, 0.806, X, X}},
        {"RGB+RE", {X, 21.26, X, X, 24.77, X}, {X, 0.645, X, X, 0.758, X}},
        {"RGB+NIR", {X, 21.19, X, X, X, 27.15}, {X, 0.645, X, X, X, 0.828}},
        {"RGB+G+R", {X, 21.20, 24.45, 26.51, X, X}, {X, 0.642, 0.712, 0.807, X, X}},
        {"RGB+G+RE", {X, 21.07, 24.28, X, 24.69, X}, {X, 0.641, 0.710, X, 0.755, X}},
        {"RGB+G+NIR", {X, 21.16, 24.39, X, X, 27.00}, {X, 0.639, 0.710, X, X, 0.821}},
        {"RGB+R+RE", {X, 21.17, X, 26.45, 24.85, X}, {X, 0.644, X, 0.808, 0.759, X}},
        {"RGB+R+NIR", {X, 21.15, X, 26.62, X, 27.13}, {X, 0.645, X, 0.808, X, 0.825}},
        {"RGB+RE+NIR", {X, 21.16, X, X, 24.82, 27.15}, {X, 0.642, X, X, 0.758, 0.827}},
        {"RGB+G+R+RE", {X, 21.40, 24.63, 26.66, 25.02, X}, {X, 0.649, 0.719, 0.813, 0.766, X}},
        {"RGB+G+R+NIR", {X, 21.24, 24.59, 26.65, X, 27.25}, {X, 0.645, 0.718, 0.812, X, 0.831}},
        {"RGB+G+RE+NIR", {X, 21.22, 24.30, X, 24.81, 27.10}, {X, 0.644, 0.714, X, 0.762, 0.829}},
        {"RGB+R+RE+NIR", {X, 21.30, X, 26.53, 25.00, 27.30}, {X, 0.648, X, 0.810, 0.765, 0.832}},
        {"RGB+G+R+RE+NIR", {X, 21.29, 24.62, 26.61, 25.07, 27.42}, {X, 0.647, 0.719, 0.810, 0.766, 0.834}},
    };
    for (auto& row : r) {
      row.psnr[0] = detail::mean_finite(row.psnr.data() + 1, metric_columns - 1);
      row.ssim[0] = detail::mean_finite(row.ssim.data() + 1, metric_columns - 1);
    }
    return r;
  }();
  return t;
}

/// The paper row of a summary in a study of kind `k`, or nullptr.
inline const PaperRow* paper_row(StudyKind k, const StudyRun& r) {
  const std::vector<PaperRow>* t = k == StudyKind::Ablation ? &paper_ablation()
                                   : k == StudyKind::Crosstalk ? &paper_crosstalk() : nullptr;
  if (!t) return nullptr;
  const std::string key = k == StudyKind::Ablation ? r.strategy
                          : detail::bands_label(r.bands.empty() ? std::vector<std::string>(band_ids().begin(), band_ids().end())
                                                                : r.bands);
  for (const auto& row : *t)
    if (row.key == key) return &row;
  return nullptr;
}

/// What the paper's numbers are and are not comparable with.
inline constexpr const char* paper_note =
    "Paper values: means over seven real outdoor scenes of 120k-step runs (scale 1) on a GPU, "
    "from the paper's tables. The measured values come from short CPU runs on this dataset, so only "
    "trends (which configuration ranks above which) compare, not absolute numbers.";

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
      else if (k == "--images" || k == "--eval-every" || k == "--geometry-band") { j.data_args.push_back(k); j.data_args.push_back(v); }
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
