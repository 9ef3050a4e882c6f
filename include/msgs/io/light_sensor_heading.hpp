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
//   log E_i = a + b tau_i + c tau_i^2 + p cos(psi_i) + q sin(psi_i),   tau the time scaled to [-1, 1]
//
// by least squares (the minimum-norm solution: with flight lines on two opposite headings only
// the part along them is determined, which is all those captures need). The heading term's
// spread over the headings flown is what the sensor adds; its standard error comes from the
// residual scatter. `heading_factor` divides it out of each reading, relative to the mean over
// the captures, so the level of the readings stays where it was.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "msgs/io/error.hpp"

namespace msgs::io {

/// The fewest captures, and the least spread of headings (degrees between the two most different),
/// that a heading check takes.
inline constexpr std::size_t kMinHeadingCaptures = 6;
inline constexpr double kMinHeadingSpreadDeg = 90.0;

/// What the check found for one band.
struct HeadingFit {
  std::size_t captures = 0;
  /// The reading on the heading where the sensor reads highest over the one where it reads lowest,
  /// among the headings flown, with the change in time taken out (1: no heading effect).
  double ratio = 1.0;
  double high_heading_deg = 0.0, low_heading_deg = 0.0;
  /// Standard error of log(ratio), from the residual scatter.
  double ratio_log_se = 0.0;
  /// The residual scatter of log(reading): how much the light changed in ways the fit does not
  /// follow (clouds), or the sensor's noise.
  double scatter = 0.0;
  /// Per capture, in the order given: the heading term over its mean, what a reading is divided by
  /// to take the heading out.
  std::vector<double> heading_factor;
  /// Why there is no fit (empty when there is one).
  std::string problem;

  /// True when the heading effect exceeds both `min_ratio` and three standard errors.
  bool significant(double min_ratio = 1.02) const {
    return problem.empty() && ratio > min_ratio && std::log(ratio) > 3.0 * ratio_log_se;
  }
};

namespace detail {

using Row5 = std::array<double, 5>;
using Mat5 = std::array<Row5, 5>;

inline double dot(const Row5& a, const Row5& b) {
  double s = 0.0;
  for (int k = 0; k < 5; ++k) s += a[k] * b[k];
  return s;
}

inline Row5 times(const Mat5& m, const Row5& v) {
  Row5 r{};
  for (int k = 0; k < 5; ++k) r[k] = dot(m[k], v);
  return r;
}

/// The Moore-Penrose pseudo-inverse of a symmetric positive semi-definite 5 x 5 matrix, from its
/// eigen-decomposition by cyclic Jacobi rotations; eigenvalues below 1e-10 of the largest count as
/// zero. `rank` receives the number kept.
inline Mat5 symmetric_pseudo_inverse(Mat5 a, int& rank) {
  Mat5 v{};
  for (int k = 0; k < 5; ++k) v[k][k] = 1.0;
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = 0.0, diag = 0.0;
    for (int p = 0; p < 5; ++p) {
      diag += a[p][p] * a[p][p];
      for (int q = p + 1; q < 5; ++q) off += a[p][q] * a[p][q];
    }
    if (!(off > 1e-30 * diag)) break;
    for (int p = 0; p < 5; ++p)
      for (int q = p + 1; q < 5; ++q) {
        if (a[p][q] == 0.0) continue;
        // The rotation that zeroes a[p][q] (Golub and Van Loan, algorithm 8.4.1).
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 5; ++k) {  // a <- a J
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 5; ++k) {  // a <- J' a
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 5; ++k) {  // v <- v J
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
  }
  double largest = 0.0;
  for (int k = 0; k < 5; ++k) largest = std::max(largest, std::abs(a[k][k]));
  Row5 inv{};
  rank = 0;
  for (int k = 0; k < 5; ++k)
    if (a[k][k] > 1e-10 * largest) {
      inv[k] = 1.0 / a[k][k];
      ++rank;
    }
  Mat5 r{};
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 5; ++k) r[i][j] += v[i][k] * inv[k] * v[j][k];
  return r;
}

/// The smallest angle between two headings, degrees in [0, 180].
inline double heading_gap_deg(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 360.0);
  return d > 180.0 ? 360.0 - d : d;
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
  if (n < kMinHeadingCaptures) {
    fit.problem = cat(n, " captures (the check takes ", kMinHeadingCaptures, ")");
    return fit;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!(reading[i] > 0) || !std::isfinite(reading[i]) || !std::isfinite(time_s[i]) || !std::isfinite(heading_deg[i])) {
      fit.problem = "a reading, time or heading that is not a finite positive number";
      return fit;
    }
  double spread = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) spread = std::max(spread, detail::heading_gap_deg(heading_deg[i], heading_deg[j]));
  if (spread < kMinHeadingSpreadDeg) {
    fit.problem = cat("the headings flown lie within ", short_number(spread, 3), " degrees (the check takes ",
                      kMinHeadingSpreadDeg, ")");
    return fit;
  }
  const auto [t_lo, t_hi] = std::minmax_element(time_s.begin(), time_s.end());
  const double mid = 0.5 * (*t_lo + *t_hi), half = 0.5 * (*t_hi - *t_lo);
  constexpr double deg = std::numbers::pi / 180.0;
  using detail::Mat5;
  using detail::Row5;
  // Least squares through the normal equations, (X'X)^+ X'y: the minimum-norm solution, with
  // the pseudo-inverse from the eigen-decomposition of the 5 x 5 X'X (columns of order 1).
  std::vector<Row5> rows(n);
  std::vector<double> y(n);
  Mat5 xtx{};
  Row5 xty{};
  for (std::size_t i = 0; i < n; ++i) {
    const double tau = half > 0 ? (time_s[i] - mid) / half : 0.0;
    rows[i] = {1.0, tau, tau * tau, std::cos(heading_deg[i] * deg), std::sin(heading_deg[i] * deg)};
    y[i] = std::log(reading[i]);
    for (int r = 0; r < 5; ++r) {
      xty[r] += rows[i][r] * y[i];
      for (int c = 0; c < 5; ++c) xtx[r][c] += rows[i][r] * rows[i][c];
    }
  }
  int rank = 0;
  const Mat5 xtx_pinv = detail::symmetric_pseudo_inverse(xtx, rank);
  const Row5 beta = detail::times(xtx_pinv, xty);
  double rss = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = y[i] - detail::dot(rows[i], beta);
    rss += r * r;
  }
  const double sigma2 = rss / std::max(1.0, double(n) - double(rank));
  fit.scatter = std::sqrt(sigma2);
  // The heading term of each capture, and the captures where it is highest and lowest.
  std::vector<double> h(n);
  double mean = 0.0;
  std::size_t hi = 0, lo = 0;
  for (std::size_t i = 0; i < n; ++i) {
    h[i] = rows[i][3] * beta[3] + rows[i][4] * beta[4];
    mean += h[i] / double(n);
    if (h[i] > h[hi]) hi = i;
    if (h[i] < h[lo]) lo = i;
  }
  fit.ratio = std::exp(h[hi] - h[lo]);
  fit.high_heading_deg = heading_deg[hi];
  fit.low_heading_deg = heading_deg[lo];
  // Var(h_hi - h_lo) = v' sigma^2 (X'X)^+ v, v the difference of the two rows' heading columns.
  Row5 v{};
  v[3] = rows[hi][3] - rows[lo][3];
  v[4] = rows[hi][4] - rows[lo][4];
  fit.ratio_log_se = std::sqrt(std::max(0.0, sigma2 * detail::dot(v, detail::times(xtx_pinv, v))));
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
