// include/msgs/io/model_alignment.hpp
// A second COLMAP model in the frame of the main one, through the captures both hold. When a
// band matches its own images but not the other bands (a leaf is bright in the NIR and dark in
// the red), COLMAP reconstructs that band apart, in a frame of its own: its own origin, rotation
// and scale. The lenses of a multi-spectral camera fire together from one body, centimetres
// apart, while captures lie metres apart, so a capture sits at one place in both models: the
// similarity that maps the second model's capture centres onto the main model's carries every
// camera of the second model into the main frame.
#pragma once

#include <Eigen/Core>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "rig_poses.hpp"
#include "similarity.hpp"

namespace msgs::io {

/// How closely a second model must agree with the main one to be carried into its frame.
struct AlignTolerance {
  /// A shared capture's centre, mapped into the main frame, lies within this share of the capture
  /// spacing from the main model's centre of that capture. Lens offsets (centimetres) and
  /// registration scatter stay well inside it; an image registered in the wrong place does not.
  double residual_ratio = 0.15;
  std::size_t min_captures = 3;  ///< shared captures that must agree
  /// The agreeing captures must spread at least this share of the capture spacing away from the
  /// line that fits them best (RMS): captures along one straight line leave the rotation about
  /// that line unknown.
  double min_breadth_ratio = 0.5;
};

/// A model's cameras by capture: the mean camera centre of each capture's images; nullopt where
/// the model has no image of the capture.
using CaptureCentres = std::vector<std::optional<Eigen::Vector3d>>;

/// The capture centres of `cameras` (capture index, world-to-camera pose) over `captures` captures.
/// Cameras of captures outside [0, captures) are ignored.
inline CaptureCentres capture_centres(const std::vector<std::pair<std::size_t, RigPose>>& cameras, std::size_t captures) {
  std::vector<Eigen::Vector3d> sum(captures, Eigen::Vector3d::Zero());
  std::vector<std::size_t> n(captures, 0);
  for (const auto& [c, pose] : cameras) {
    if (c >= captures) continue;
    sum[c] += -(pose.R.transpose() * pose.t);
    ++n[c];
  }
  CaptureCentres out(captures);
  for (std::size_t c = 0; c < captures; ++c)
    if (n[c] > 0) out[c] = sum[c] / double(n[c]);
  return out;
}

/// The outcome of align_by_captures.
struct ModelAlignment {
  std::optional<Similarity> to_main;  ///< the second model's world -> the main model's; nullopt: not aligned
  std::size_t shared = 0;             ///< captures both models hold
  std::size_t agreeing = 0;           ///< of those, the ones the similarity maps within the tolerance
  /// The shared captures that do not agree (capture indices): a camera of the second model
  /// registered in the wrong place, or one of the main model's. Their cameras are not to be
  /// carried over.
  std::vector<std::size_t> disagreeing;
  double capture_spacing = 0;         ///< of the main model: median distance to the nearest other capture
  double median_residual = 0;         ///< over the agreeing captures, as a share of the spacing
  double max_residual = 0;
  std::string problem;                ///< why not aligned (empty when aligned)
};

namespace detail {

/// RMS distance of `points` from the straight line that fits them best.
inline double line_residual_rms(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 3) return 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p / double(points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points) cov += (p - mean) * (p - mean).transpose() / double(points.size());
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov);
  const Eigen::Vector3d s = svd.singularValues();  // descending: the line takes the first
  return std::sqrt(std::max(0.0, s[1] + s[2]));
}

}  // namespace detail

/// The similarity from `other`'s frame into `main`'s, fitted (fit_similarity) to the centres of
/// the captures both hold (non-finite centres count as absent). Captures that do not fit are dropped one at a time, the worst first,
/// and the fit repeated, until every remaining capture lies within the tolerance; the alignment
/// holds when at least `min_captures` and at least half of the shared captures remain and they do
/// not lie along one line. Otherwise `to_main` is empty and `problem` says why.
inline ModelAlignment align_by_captures(const CaptureCentres& main, const CaptureCentres& other, const AlignTolerance& tol = {}) {
  ModelAlignment a;
  std::vector<Eigen::Vector3d> all_main, m, o;
  std::vector<std::size_t> capture;  // of m[i] and o[i]
  const auto usable = [](const std::optional<Eigen::Vector3d>& p) { return p && p->allFinite(); };
  for (std::size_t c = 0; c < main.size(); ++c) {
    if (!usable(main[c])) continue;
    all_main.push_back(*main[c]);
    if (c < other.size() && usable(other[c])) {
      m.push_back(*main[c]);
      o.push_back(*other[c]);
      capture.push_back(c);
    }
  }
  a.shared = m.size();
  a.capture_spacing = detail::median_nearest_distance(all_main);
  if (a.shared < tol.min_captures) {
    a.problem = "shares " + std::to_string(a.shared) + " capture" + (a.shared == 1 ? "" : "s") +
                " with the main model, " + std::to_string(tol.min_captures) + " needed to align it";
    return a;
  }
  if (!(a.capture_spacing > 0) || !std::isfinite(a.capture_spacing)) {
    a.problem = "the main model's captures do not spread (all at one place): no scale to align by";
    return a;
  }
  std::vector<double> residual;
  Similarity s;
  for (;;) {
    try {
      s = fit_similarity(o, m);
    } catch (const std::invalid_argument&) {
      a.problem = "its captures do not spread (all at one place): no scale to align by";
      return a;
    }
    residual.assign(m.size(), 0.0);
    std::size_t worst = 0;
    for (std::size_t i = 0; i < m.size(); ++i) {
      residual[i] = (s(o[i]) - m[i]).norm() / a.capture_spacing;
      if (!(residual[i] <= residual[worst])) worst = i;  // a NaN residual counts as the worst
    }
    if (residual[worst] <= tol.residual_ratio) break;
    if (m.size() <= tol.min_captures || 2 * (m.size() - 1) < a.shared) {
      a.agreeing = 0;
      char why[160];
      std::snprintf(why, sizeof why, "does not fit the main model: after the best similarity, a capture is still %.2f of the capture spacing away (%.2f allowed)",
                    residual[worst], tol.residual_ratio);
      a.problem = why;
      return a;
    }
    a.disagreeing.push_back(capture[worst]);
    m.erase(m.begin() + std::ptrdiff_t(worst));
    o.erase(o.begin() + std::ptrdiff_t(worst));
    capture.erase(capture.begin() + std::ptrdiff_t(worst));
  }
  a.agreeing = m.size();
  std::sort(a.disagreeing.begin(), a.disagreeing.end());
  if (detail::line_residual_rms(m) < tol.min_breadth_ratio * a.capture_spacing) {
    a.problem = "the captures it shares with the main model lie along one line: the rotation about that line is unknown";
    return a;
  }
  a.max_residual = *std::max_element(residual.begin(), residual.end());
  a.median_residual = detail::median_of(residual);
  a.to_main = s;
  return a;
}

/// A world-to-camera pose of the second model's world, in the main model's: with x_main =
/// s Q x + u, x_cam = R x + t becomes, scaled by s (which moves no pixel), R Q^T x_main +
/// (s t - R Q^T u).
inline RigPose pose_in_main_frame(const RigPose& p, const Similarity& s) {
  RigPose r;
  r.R = p.R * s.R.transpose();
  r.t = s.scale * p.t - r.R * s.t;
  return r;
}

}  // namespace msgs::io
