// include/msgs/curve.hpp
// Quality against training time: the points an anytime evaluation records while a model trains
// (seconds on the training clock, step, Gaussians, PSNR / SSIM per band on a fixed subset of the
// eval split), a run's "All" curve over its models, and where two curves cross.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "io/error.hpp"
#include "io/file.hpp"

namespace msgs {

/// One anytime evaluation of one model.
struct CurvePoint {
  double seconds = 0;        ///< training clock of the run (evaluations excluded), at the evaluation
  long long step = 0;        ///< steps the model had taken
  std::string model;         ///< model key ("joint", or the band id of a Separate / Split model)
  std::size_t gaussians = 0;
  std::vector<std::string> bands;   ///< the model's bands
  std::vector<double> psnr, ssim;   ///< per band: mean over the evaluated images
};

/// When and on what to evaluate during training (TrainOptions::curve). Off when both periods are 0.
struct CurveConfig {
  double every_seconds = 0;  ///< evaluate after this many seconds of training since the last one (0: never)
  long long every_steps = 0; ///< ... or after this many steps (0: never)
  int images = 4;            ///< eval images per band, spread evenly over its eval split (0: all)
  bool enabled() const { return every_seconds > 0 || every_steps > 0; }
};

/// The eval images of a band a curve evaluates: `k` spread evenly over its `n` eval images
/// (index floor(i n / k)), or all of them when k <= 0 or k >= n. Fixed for the whole run.
inline std::vector<std::size_t> curve_subset(std::size_t n, int k) {
  std::vector<std::size_t> out;
  if (k <= 0 || std::size_t(k) >= n) {
    for (std::size_t i = 0; i < n; ++i) out.push_back(i);
    return out;
  }
  for (std::size_t i = 0; i < std::size_t(k); ++i) out.push_back(i * n / std::size_t(k));
  return out;
}

/// A run's quality over time across its models: at each evaluation the latest value of every band
/// (a Separate run's finished RGB model keeps its final value while the next band trains); "All" is
/// their mean and is defined only once every band of `bands` has a value.
struct AllPoint {
  double seconds = 0;
  long long step = 0;
  double psnr = std::numeric_limits<double>::quiet_NaN(), ssim = std::numeric_limits<double>::quiet_NaN();
  std::size_t gaussians = 0;  ///< summed over the models
};

/// The All curve of `points` (in recording order) over `bands`.
inline std::vector<AllPoint> all_curve(const std::vector<CurvePoint>& points, const std::vector<std::string>& bands) {
  std::map<std::string, std::pair<double, double>> latest;
  std::map<std::string, std::size_t> model_gaussians;
  std::vector<AllPoint> out;
  for (const CurvePoint& p : points) {
    for (std::size_t b = 0; b < p.bands.size() && b < p.psnr.size() && b < p.ssim.size(); ++b)
      latest[p.bands[b]] = {p.psnr[b], p.ssim[b]};
    model_gaussians[p.model] = p.gaussians;
    AllPoint a;
    a.seconds = p.seconds;
    a.step = p.step;
    for (const auto& [m, n] : model_gaussians) a.gaussians += n;
    double sp = 0, ss = 0;
    bool complete = !bands.empty();
    for (const std::string& b : bands) {
      const auto it = latest.find(b);
      if (it == latest.end()) { complete = false; break; }
      sp += it->second.first;
      ss += it->second.second;
    }
    if (!complete) continue;
    a.psnr = sp / double(bands.size());
    a.ssim = ss / double(bands.size());
    out.push_back(a);
  }
  return out;
}

/// Value of a piecewise-linear curve (t[i], v[i]), t ascending, at time x inside [t.front(), t.back()].
inline double curve_at(const std::vector<double>& t, const std::vector<double>& v, double x) {
  if (t.empty()) return std::numeric_limits<double>::quiet_NaN();
  if (x <= t.front()) return v.front();
  if (x >= t.back()) return v.back();
  const auto it = std::upper_bound(t.begin(), t.end(), x);
  const std::size_t i = std::size_t(it - t.begin());  // t[i-1] <= x < t[i]
  const double w = (x - t[i - 1]) / (t[i] - t[i - 1]);
  return v[i - 1] + w * (v[i] - v[i - 1]);
}

/// A change of the leader between two curves.
struct Crossing {
  double seconds = 0;  ///< where the difference a - b changes sign (linear interpolation)
  bool a_ahead_after = false;  ///< a is ahead after the crossing
};

/// Where curve a overtakes curve b or falls behind it, on the time range both cover; each curve is
/// piecewise linear through its points (seconds ascending; non-finite values are skipped). Ties
/// (|a - b| < `tie`) are neither ahead nor behind and do not count as a crossing.
inline std::vector<Crossing> crossings(const std::vector<double>& ta, const std::vector<double>& va,
                                       const std::vector<double>& tb, const std::vector<double>& vb, double tie = 1e-9) {
  auto clean = [](const std::vector<double>& t, const std::vector<double>& v) {
    std::vector<double> ct, cv;
    for (std::size_t i = 0; i < t.size() && i < v.size(); ++i)
      if (std::isfinite(t[i]) && std::isfinite(v[i]) && (ct.empty() || t[i] > ct.back())) {
        ct.push_back(t[i]);
        cv.push_back(v[i]);
      }
    return std::make_pair(ct, cv);
  };
  const auto [a_t, a_v] = clean(ta, va);
  const auto [b_t, b_v] = clean(tb, vb);
  std::vector<Crossing> out;
  if (a_t.empty() || b_t.empty()) return out;
  const double lo = std::max(a_t.front(), b_t.front()), hi = std::min(a_t.back(), b_t.back());
  if (!(lo < hi)) return out;
  std::vector<double> grid;
  for (const auto* t : {&a_t, &b_t})
    for (double x : *t)
      if (x >= lo && x <= hi) grid.push_back(x);
  grid.push_back(lo);
  grid.push_back(hi);
  std::sort(grid.begin(), grid.end());
  grid.erase(std::unique(grid.begin(), grid.end()), grid.end());
  int sign = 0;  // sign of a - b at the last non-tied grid point
  double prev_x = grid.front(), prev_d = 0;
  for (double x : grid) {
    const double d = curve_at(a_t, a_v, x) - curve_at(b_t, b_v, x);
    const int s = d > tie ? 1 : (d < -tie ? -1 : 0);
    if (s != 0 && sign != 0 && s != sign) {
      // Between prev_x (difference prev_d, of sign `sign`) and x: both curves are linear there.
      const double t = prev_x + (x - prev_x) * (prev_d / (prev_d - d));
      out.push_back({t, s > 0});
    }
    if (s != 0) { sign = s; prev_x = x; prev_d = d; }
  }
  return out;
}

namespace detail {
inline std::string curve_join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : "|") + x;
  return s;
}
inline std::vector<std::string> curve_split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string part; std::getline(ss, part, sep);) out.push_back(part);
  return out;
}
}  // namespace detail

/// A model's curve and its training clock, kept next to its checkpoint so `--resume` continues
/// both: "clock,<seconds>" then one "point,<seconds>,<step>,<model>,<gaussians>,<bands>,<psnrs>,<ssims>"
/// line per point (lists separated by '|', numbers with 17 digits). Written atomically.
inline void save_curve(const std::filesystem::path& path, double clock, const std::vector<CurvePoint>& points) {
  std::ostringstream os;
  os.precision(17);
  os << "clock," << clock << "\n";
  for (const CurvePoint& p : points) {
    std::vector<std::string> ps, ss;
    for (double v : p.psnr) { std::ostringstream o; o.precision(17); o << v; ps.push_back(o.str()); }
    for (double v : p.ssim) { std::ostringstream o; o.precision(17); o << v; ss.push_back(o.str()); }
    os << "point," << p.seconds << "," << p.step << "," << p.model << "," << p.gaussians << ","
       << detail::curve_join(p.bands) << "," << detail::curve_join(ps) << "," << detail::curve_join(ss) << "\n";
  }
  io::write_text_atomic(path, os.str());
}

/// Read what save_curve wrote; throws io::IoError naming the file and line when it is malformed.
inline std::pair<double, std::vector<CurvePoint>> load_curve(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw io::IoError(path.string() + ": cannot open the curve file");
  double clock = 0;
  std::vector<CurvePoint> points;
  std::string line;
  int n = 0;
  auto bad = [&](const std::string& why) {
    throw io::IoError(path.string() + ": line " + std::to_string(n) + " " + why +
                      "; delete the file to restart the curve (training itself resumes from the checkpoint)");
  };
  // save_curve writes finite numbers only (PSNR is capped, psnr_from_mse); "nan" or "inf" would
  // parse, and then a NaN clock or an out-of-range cast would carry on silently.
  auto num = [&](const std::string& s) {
    double v = 0.0;
    try {
      std::size_t used = 0;
      v = std::stod(s, &used);
      if (used != s.size()) bad("has a malformed number '" + s + "'");
    } catch (const std::logic_error&) {
      bad("has a malformed number '" + s + "'");
    }
    if (!std::isfinite(v)) bad("has a number that is not finite ('" + s + "')");
    return v;
  };
  auto seconds = [&](const std::string& s) {
    const double v = num(s);
    if (v < 0.0) bad("has a negative time '" + s + "'");
    return v;
  };
  // Steps and Gaussian counts: whole numbers from 0 to 2^53, which the casts below keep exactly.
  auto count = [&](const std::string& s) {
    const double v = num(s);
    if (!(v >= 0.0 && v <= 9007199254740992.0 && v == std::floor(v)))
      bad("has '" + s + "' where a whole number >= 0 belongs");
    return v;
  };
  while (std::getline(in, line)) {
    ++n;
    if (line.empty()) continue;
    const auto f = detail::curve_split(line, ',');
    if (f.size() == 2 && f[0] == "clock") { clock = seconds(f[1]); continue; }
    if (f.size() != 8 || f[0] != "point") bad("is neither 'clock,S' nor a point of 8 fields");
    CurvePoint p;
    p.seconds = seconds(f[1]);
    p.step = (long long)count(f[2]);
    p.model = f[3];
    p.gaussians = std::size_t(count(f[4]));
    p.bands = detail::curve_split(f[5], '|');
    for (const auto& s : detail::curve_split(f[6], '|')) p.psnr.push_back(num(s));
    for (const auto& s : detail::curve_split(f[7], '|')) p.ssim.push_back(num(s));
    if (p.psnr.size() != p.bands.size() || p.ssim.size() != p.bands.size())
      bad("has " + std::to_string(p.bands.size()) + " bands but " + std::to_string(p.psnr.size()) + " PSNR and " +
          std::to_string(p.ssim.size()) + " SSIM values");
    points.push_back(std::move(p));
  }
  return {clock, std::move(points)};
}

}  // namespace msgs
