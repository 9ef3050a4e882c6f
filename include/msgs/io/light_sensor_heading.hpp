// include/msgs/io/light_sensor_heading.hpp
// Does a drone's light sensor read differently depending on which way the drone flies? A sensor
// on the body tilts with the drone's forward pitch, towards the sun on one heading and away from
// it on the opposite one; a sensor off the drone's centre is shaded by its body on some headings.
// Levelling for the tilt (msgs/io/light_sensor_tilt.hpp, or a DJI sensor's built-in compensation)
// assumes a clear sky, and may leave part of it in: users of MicaSense's library report DLS 1
// readings that follow the drone's motion under overcast skies (micasense/imageprocessing issue
// 95). Readings divided into the images then make the same ground brighter on one flight line
// than on the next.
//
// The check fits, over one band's flight captures, the logarithm of the reading as a slow change
// in time (the sun climbing, thin haze) plus a heading term:
//
//   log E = a + b tau + c tau^2 + p cos(psi) + q sin(psi),   tau the time scaled to [-1, 1]
//
// by least squares (lines flown there and back along one axis determine only the part along it,
// which is all their captures need: there the term is p times the heading vector's component
// along the axis, and the solution the minimum-norm one). The heading term's
// spread over the headings flown is what the sensor adds; `heading_factor` divides it out of each
// reading, relative to the mean over the captures, so the level of the readings stays where it was.
//
// The fit is over flight lines, not captures: a run of consecutive captures on one heading
// (within kSameLineDeg) counts once, with its mean log reading, time and heading. A cloud that
// dims one whole line looks like a heading effect to the captures of that line, which share it;
// only from line to line does it vary at random. So the standard error, from the lines' residual
// scatter with as many degrees of freedom as lines less parameters, covers it, where one from the
// captures' scatter would count a line's cloud as many independent readings and call it a heading
// effect. Where the heading turns back at every capture each capture is a line of its own.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/SVD>

#include "msgs/io/error.hpp"

namespace msgs::io {

/// The fewest flight lines, and the least spread of headings (degrees between the two most
/// different), that a heading check takes; headings within kSameLineDeg of a line's first capture
/// continue the line.
inline constexpr std::size_t kMinHeadingLines = 6;
inline constexpr double kMinHeadingSpreadDeg = 90.0;
inline constexpr double kSameLineDeg = 20.0;
/// Lines whose unit heading vectors spread less than this across their major axis (standard
/// deviation; 0.2 is about 12 degrees) run along one axis.
inline constexpr double kAcrossAxisSpread = 0.2;

/// What the check found for one band.
struct HeadingFit {
  std::size_t captures = 0;
  /// Runs of consecutive captures (in time) on one heading, each of which counts once in the fit.
  std::size_t lines = 0;
  /// The reading on the heading where the sensor reads highest over the one where it reads lowest,
  /// among the headings flown, with the change in time taken out (1: no heading effect).
  double ratio = 1.0;
  double high_heading_deg = 0.0, low_heading_deg = 0.0;
  /// Standard error of log(ratio), from the residual scatter.
  double ratio_log_se = 0.0;
  /// The residual scatter of the lines' mean log(reading): how much the light changed in ways
  /// the fit does not follow (clouds), or the sensor's noise.
  double scatter = 0.0;
  /// Per capture, in the order given: the heading term over its mean, what a reading is divided by
  /// to take the heading out.
  std::vector<double> heading_factor;

  /// True when the lines run along one axis and the heading term was fitted along it alone.
  bool one_axis = false;
  /// The lines less the parameters the fit determines: the residual scatter's degrees of freedom.
  int degrees_of_freedom = 0;
  /// Why there is no fit (empty when there is one).
  std::string problem;

  /// True when the heading effect exceeds `min_ratio` and is as unlikely to come from the scatter
  /// as three standard errors of a normal variable (two-sided 0.27%: Student's t with the fit's
  /// degrees of freedom, 19.2 standard errors with 2, 4.9 with 6, 3.4 with 20).
  bool significant(double min_ratio = 1.02) const {
    return problem.empty() && ratio > min_ratio && std::log(ratio) > student_t_3sigma(degrees_of_freedom) * ratio_log_se;
  }

  /// The two-sided 0.27% quantile of Student's t with `dof` degrees of freedom (computed by
  /// numerical integration of its density; beyond 30 the Cornish-Fisher expansion, within 0.001).
  static double student_t_3sigma(int dof) {
    static constexpr double kTable[30] = {235.801, 19.207, 9.219, 6.620, 5.507, 4.904, 4.530, 4.277, 4.094, 3.957,
                                          3.850,   3.764,  3.694, 3.636, 3.586, 3.544, 3.507, 3.475, 3.447, 3.422,
                                          3.400,   3.380,  3.361, 3.345, 3.330, 3.316, 3.303, 3.291, 3.280, 3.270};
    if (dof < 1) return std::numeric_limits<double>::infinity();
    if (dof <= 30) return kTable[dof - 1];
    const double v = dof;
    return 3.0 + 7.5 / v + 17.25 / (v * v);  // z + (z^3 + z) / 4v + (5z^5 + 16z^3 + 3z) / 96v^2, z = 3
  }
};

namespace detail {

using Vec5 = Eigen::Matrix<double, 5, 1>;
using Mat5 = Eigen::Matrix<double, 5, 5>;

/// The Moore-Penrose pseudo-inverse of a symmetric positive semi-definite 5 x 5 matrix, from its
/// singular value decomposition (for such a matrix, its eigen-decomposition); singular values
/// below 1e-10 of the largest count as zero. `rank` receives the number kept.
inline Mat5 symmetric_pseudo_inverse(const Mat5& a, int& rank) {
  const Eigen::JacobiSVD<Mat5> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Vec5& sigma = svd.singularValues();  // in decreasing order
  Vec5 inv = Vec5::Zero();
  rank = 0;
  for (int k = 0; k < 5; ++k)
    if (sigma[k] > 1e-10 * sigma[0]) {
      inv[k] = 1.0 / sigma[k];
      ++rank;
    }
  return svd.matrixV() * inv.asDiagonal() * svd.matrixU().transpose();
}

/// The smallest angle between two headings, degrees in [0, 180].
inline double heading_gap_deg(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 360.0);
  return d > 180.0 ? 360.0 - d : d;
}

/// The largest angle between two of the headings `heading_deg`, degrees in [0, 180], in n log n
/// instead of over all n^2 pairs. The pair farthest apart, a and b, has b the first heading at or
/// after a's opposite going clockwise around the circle, or a the first after b's (any heading
/// between would lie farther from the other), so each heading needs only that one neighbour.
inline double heading_spread_deg(std::vector<double> heading_deg) {
  for (double& h : heading_deg) {
    h = std::fmod(h, 360.0);
    if (h < 0.0) h += 360.0;  // [0, 360]: -1e-17 + 360 rounds to 360, which heading_gap_deg takes
  }
  std::sort(heading_deg.begin(), heading_deg.end());
  double spread = 0.0;
  for (const double h : heading_deg) {
    const auto after = std::lower_bound(heading_deg.begin(), heading_deg.end(), h < 180.0 ? h + 180.0 : h - 180.0);
    spread = std::max(spread, heading_gap_deg(h, after == heading_deg.end() ? heading_deg.front() : *after));
  }
  return spread;
}

}  // namespace detail

/// Fit the heading term to one band's light-sensor readings (positive), capture times (seconds)
/// and drone headings (degrees clockwise from north), one each per flight capture.
inline HeadingFit fit_heading_bias(const std::vector<double>& reading, const std::vector<double>& time_s,
                                   const std::vector<double>& heading_deg) {
  HeadingFit fit;
  const std::size_t n = reading.size();
  fit.captures = n;
  if (time_s.size() != n || heading_deg.size() != n) {
    fit.problem = "readings, times and headings do not pair up";
    return fit;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!(reading[i] > 0) || !std::isfinite(reading[i]) || !std::isfinite(time_s[i]) || !std::isfinite(heading_deg[i])) {
      fit.problem = "a reading, time or heading that is not a finite positive number";
      return fit;
    }
  const double spread = detail::heading_spread_deg(heading_deg);
  // The flight lines: runs of captures, in time, within kSameLineDeg of the run's first heading.
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return time_s[a] < time_s[b]; });
  std::vector<std::vector<std::size_t>> lines;
  for (std::size_t i : order)
    if (lines.empty() || detail::heading_gap_deg(heading_deg[lines.back().front()], heading_deg[i]) > kSameLineDeg)
      lines.push_back({i});
    else
      lines.back().push_back(i);
  const std::size_t m = lines.size();
  fit.lines = m;
  if (spread < kMinHeadingSpreadDeg) {
    fit.problem = cat("the headings flown lie within ", short_number(spread, 3), " degrees (the check takes ",
                      short_number(kMinHeadingSpreadDeg), ")");
    return fit;
  }
  if (m < kMinHeadingLines) {
    fit.problem = cat(m, m == 1 ? " flight line" : " flight lines", ", runs of captures on one heading (the check takes ",
                      kMinHeadingLines, ")");
    return fit;
  }
  const auto [t_lo, t_hi] = std::minmax_element(time_s.begin(), time_s.end());
  const double mid = 0.5 * (*t_lo + *t_hi), half = 0.5 * (*t_hi - *t_lo);
  constexpr double deg = std::numbers::pi / 180.0;
  using detail::Mat5;
  using detail::Vec5;
  // Each line's mean time, the direction of its mean heading vector and its mean log reading.
  std::vector<double> line_t(m), line_c(m), line_s(m), y(m);
  for (std::size_t l = 0; l < m; ++l) {
    double t = 0.0, c = 0.0, sn = 0.0, lg = 0.0;
    for (std::size_t i : lines[l]) {
      t += time_s[i];
      c += std::cos(heading_deg[i] * deg);
      sn += std::sin(heading_deg[i] * deg);
      lg += std::log(reading[i]);
    }
    const double k = double(lines[l].size()), norm = std::hypot(c, sn);
    line_t[l] = t / k;
    line_c[l] = c / norm;
    line_s[l] = sn / norm;
    y[l] = lg / k;
  }
  // The heading columns. Lines flown along one axis, there and back, a few degrees of crabbing
  // apart (the spread across the axis under kAcrossAxisSpread), determine the heading term along
  // that axis only: its part across would rest on the crab angles' noise, and the extremes over
  // the headings flown would follow that noise. There the term is one column, the heading vector
  // along the axis; else the two, cos and sin.
  double mc = 0.0, ms = 0.0;
  for (std::size_t l = 0; l < m; ++l) {
    mc += line_c[l] / double(m);
    ms += line_s[l] / double(m);
  }
  double cxx = 0.0, cxy = 0.0, cyy = 0.0;
  for (std::size_t l = 0; l < m; ++l) {
    cxx += (line_c[l] - mc) * (line_c[l] - mc) / double(m);
    cxy += (line_c[l] - mc) * (line_s[l] - ms) / double(m);
    cyy += (line_s[l] - ms) * (line_s[l] - ms) / double(m);
  }
  const double axis = 0.5 * std::atan2(2.0 * cxy, cxx - cyy);  // the major axis of the 2 x 2 scatter
  const double ax = std::cos(axis), ay = std::sin(axis);
  const double across = std::max(0.0, 0.5 * (cxx + cyy) - std::hypot(0.5 * (cxx - cyy), cxy));
  fit.one_axis = std::sqrt(across) < kAcrossAxisSpread;
  const auto heading_columns = [&](double c, double sn) {
    return fit.one_axis ? std::array<double, 2>{c * ax + sn * ay, 0.0} : std::array<double, 2>{c, sn};
  };
  const auto row = [&](double t, double c, double sn) {
    const double tau = half > 0 ? (t - mid) / half : 0.0;
    const auto hc = heading_columns(c, sn);
    return Vec5(1.0, tau, tau * tau, hc[0], hc[1]);
  };
  // Least squares through the normal equations, (X'X)^+ X'y: the minimum-norm solution, with
  // the pseudo-inverse from the eigen-decomposition of the 5 x 5 X'X (columns of order 1; an
  // unused heading column is zero and drops out).
  std::vector<Vec5> rows(m);
  Mat5 xtx = Mat5::Zero();
  Vec5 xty = Vec5::Zero();
  for (std::size_t l = 0; l < m; ++l) {
    rows[l] = row(line_t[l], line_c[l], line_s[l]);
    xty += rows[l] * y[l];
    xtx += rows[l] * rows[l].transpose();
  }
  int rank = 0;
  const Mat5 xtx_pinv = detail::symmetric_pseudo_inverse(xtx, rank);
  const Vec5 beta = xtx_pinv * xty;
  double rss = 0.0;
  for (std::size_t l = 0; l < m; ++l) {
    const double r = y[l] - rows[l].dot(beta);
    rss += r * r;
  }
  fit.degrees_of_freedom = int(m) - rank;  // at least 1: m >= 6 lines, rank <= 5
  const double sigma2 = rss / double(std::max(1, fit.degrees_of_freedom));
  fit.scatter = std::sqrt(sigma2);
  // The heading term of each capture, and the captures where it is highest and lowest.
  std::vector<double> h(n);
  double mean = 0.0;
  std::size_t hi = 0, lo = 0;
  std::vector<std::array<double, 2>> hc(n);
  for (std::size_t i = 0; i < n; ++i) {
    hc[i] = heading_columns(std::cos(heading_deg[i] * deg), std::sin(heading_deg[i] * deg));
    h[i] = hc[i][0] * beta[3] + hc[i][1] * beta[4];
    mean += h[i] / double(n);
    if (h[i] > h[hi]) hi = i;
    if (h[i] < h[lo]) lo = i;
  }
  fit.ratio = std::exp(h[hi] - h[lo]);
  fit.high_heading_deg = heading_deg[hi];
  fit.low_heading_deg = heading_deg[lo];
  // Var(h_hi - h_lo) = v' sigma^2 (X'X)^+ v, v the difference of the two headings' columns.
  Vec5 v = Vec5::Zero();
  v[3] = hc[hi][0] - hc[lo][0];
  v[4] = hc[hi][1] - hc[lo][1];
  fit.ratio_log_se = std::sqrt(std::max(0.0, sigma2 * v.dot(xtx_pinv * v)));
  fit.heading_factor.resize(n);
  for (std::size_t i = 0; i < n; ++i) fit.heading_factor[i] = std::exp(h[i] - mean);
  // Readings that span hundreds of orders of magnitude overflow exp: no light sensor reads so.
  const bool finite = std::isfinite(fit.ratio) && std::isfinite(fit.ratio_log_se) &&
                      std::all_of(fit.heading_factor.begin(), fit.heading_factor.end(),
                                  [](double f) { return std::isfinite(f) && f > 0; });
  if (!finite) {
    fit = HeadingFit{};
    fit.captures = n;
    fit.problem = "readings too far apart to fit (a factor of more than 1e300 between headings)";
  }
  return fit;
}

}  // namespace msgs::io
