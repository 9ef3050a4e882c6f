// include/msgs/study.hpp
// Studies over many runs as data: the paper's ablation and cross-talk run lists, an accuracy-
// against-time sweep of each quality knob, the convergence study's strategies x presets, Pareto
// fronts and rank correlation, and the paper's own numbers. Reading results, tables, plots and
// job files belong to the `msgs study` tool (examples/study_report.hpp).
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

#include "presets.hpp"

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

namespace detail {
/// Mean of the finite values of v[0..n), NaN when there are none.
inline double mean_finite(const double* v, std::size_t n) {
  double s = 0;
  int c = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (std::isfinite(v[i])) { s += v[i]; ++c; }
  return c ? s / c : std::numeric_limits<double>::quiet_NaN();
}
}  // namespace detail

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

}  // namespace msgs::study
