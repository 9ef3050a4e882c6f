// include/msgs/io/rig_poses.hpp
// Poses of the images COLMAP did not register, from the other bands of their capture. A
// multi-spectral camera (MicaSense, the Mavic 3M, the Sequoia) is a rig: its lenses sit on one
// body and fire together, so in every capture the pose of a band relative to another is the same
// rigid offset. Matching across bands is where SIFT struggles (the same leaf is bright in the NIR
// and dark in the red), so on real flights some images of a band do not register while the other
// bands of their capture do. estimate_rig measures each band's offset from the reference band
// over the captures where both registered, keeps the captures that agree with the rig, and
// place_by_rig poses every missing image through a registered band of its own capture.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace msgs::io {

/// A world-to-camera pose in double: x_cam = R x_world + t.
struct RigPose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
};

/// How far a band may move against the reference band, capture to capture, and still count as
/// one rig: the boresights of a rig differ by a fixed rotation, and its lenses by centimetres,
/// where captures are metres apart. What scatters is COLMAP's registration: hundredths of a
/// degree on full-size images, up to 0.6 degrees and 6% of the spacing on 160x120 ones. A
/// misregistered image, or a camera that is not on the rig, is off by far more.
struct RigTolerance {
  double rotation_deg = 2.0;        ///< a capture's relative rotation from the rig's
  double translation_ratio = 0.15;  ///< its relative translation from the rig's, over the capture spacing
  std::size_t min_captures = 3;     ///< captures (inliers) that must agree on a band's offset
};

/// A band's offset from the reference band: x_band = R x_ref + t in camera coordinates.
struct RigOffset {
  RigPose offset;
  std::size_t samples = 0;        ///< captures where the band and the reference both registered
  std::size_t inliers = 0;        ///< those that agree with the offset within the tolerance
  double rotation_spread_deg = 0;     ///< largest angle of an inlier from the offset's rotation
  double translation_spread = 0;      ///< largest inlier distance from its translation, over the capture spacing
};

/// The rig of an import: the reference band and the offset of every band that has one.
struct Rig {
  int reference = -1;                          ///< band index; -1: no band registered
  double capture_spacing = 0;                  ///< median distance from a reference camera to its nearest one
  std::vector<std::size_t> registered;         ///< [bands]: captures where each band has a pose
  std::vector<std::optional<RigOffset>> bands; ///< [bands]: the reference's is the identity
  std::vector<std::string> problems;           ///< one line per band without an offset, saying why
};

namespace detail {

/// Angle of rotation a R b^T, in degrees.
inline double rotation_angle_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const double c = std::clamp(((a * b.transpose()).trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / 3.14159265358979323846;
}

/// Median of v (the upper one of an even count); v is reordered.
inline double median_of(std::vector<double>& v) {
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
  return v[v.size() / 2];
}

/// The median over `points` of the distance from each to its nearest other one; 0 with fewer
/// than two points.
inline double median_nearest_distance(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 2) return 0.0;
  std::vector<double> nearest;
  for (std::size_t i = 0; i < points.size(); ++i) {
    double d = INFINITY;
    for (std::size_t j = 0; j < points.size(); ++j)
      if (j != i) d = std::min(d, (points[i] - points[j]).norm());
    nearest.push_back(d);
  }
  return median_of(nearest);
}

/// The relative pose x_b = R x_a + t of two poses of one capture.
inline RigPose relative_pose(const RigPose& a, const RigPose& b) {
  RigPose r;
  r.R = b.R * a.R.transpose();
  r.t = b.t - r.R * a.t;
  return r;
}

}  // namespace detail

/// The rig of `poses` ([capture][band], empty where an image did not register). The reference is
/// the band with the most registered captures (the first of a tie). A band's offset comes from
/// the captures where it and the reference both registered: the sample whose rotation and
/// translation lie closest to the others (the medoid) anchors it, the samples within `tol` of the
/// medoid are the inliers, and the offset is their mean rotation (sign-aligned quaternions,
/// normalised) and their component-wise median translation. Too few inliers leaves the band
/// without an offset, with the reason in `problems`. Translations are measured against the
/// median distance between neighbouring reference cameras, so the tolerance does not depend on
/// the arbitrary scale of a COLMAP model.
inline Rig estimate_rig(const std::vector<std::vector<std::optional<RigPose>>>& poses, std::size_t band_count,
                        const std::vector<std::string>& band_names, const RigTolerance& tol = {}) {
  Rig rig;
  rig.bands.assign(band_count, std::nullopt);
  rig.registered.assign(band_count, 0);
  std::vector<std::size_t>& count = rig.registered;
  for (const auto& cap : poses)
    for (std::size_t b = 0; b < band_count && b < cap.size(); ++b) count[b] += cap[b].has_value();
  std::size_t best = 0;
  for (std::size_t b = 1; b < band_count; ++b)
    if (count[b] > count[best]) best = b;
  if (band_count == 0 || count[best] == 0) return rig;
  rig.reference = int(best);
  const std::size_t ref = best;
  auto has = [&](std::size_t c, std::size_t b) { return b < poses[c].size() && poses[c][b].has_value(); };

  // Capture spacing: the median distance from a reference camera to its nearest other one.
  std::vector<Eigen::Vector3d> centres;
  for (std::size_t c = 0; c < poses.size(); ++c)
    if (has(c, ref)) centres.push_back(-(poses[c][ref]->R.transpose() * poses[c][ref]->t));
  rig.capture_spacing = detail::median_nearest_distance(centres);
  // Where every capture sits at one spot (or only one registered), the translation is not checked.
  const double spacing = rig.capture_spacing > 0 && std::isfinite(rig.capture_spacing) ? rig.capture_spacing : INFINITY;

  rig.bands[ref] = RigOffset{RigPose{}, count[ref], count[ref], 0.0, 0.0};
  for (std::size_t b = 0; b < band_count; ++b) {
    if (b == ref) continue;
    const std::string& name = b < band_names.size() ? band_names[b] : std::to_string(b);
    const std::string& ref_name = ref < band_names.size() ? band_names[ref] : std::to_string(ref);
    std::vector<RigPose> s;
    for (std::size_t c = 0; c < poses.size(); ++c)
      if (has(c, b) && has(c, ref)) s.push_back(detail::relative_pose(*poses[c][ref], *poses[c][b]));
    if (s.size() < tol.min_captures) {
      rig.problems.push_back(name + ": registered together with " + ref_name + " in " + std::to_string(s.size()) +
                             " captures, " + std::to_string(tol.min_captures) + " needed to measure its offset");
      continue;
    }
    // Distance of two samples in units of the tolerance: the larger of the two ratios.
    auto distance = [&](const RigPose& x, const RigPose& y) {
      return std::max(detail::rotation_angle_deg(x.R, y.R) / tol.rotation_deg,
                      (x.t - y.t).norm() / spacing / tol.translation_ratio);
    };
    std::size_t medoid = 0;
    double medoid_cost = INFINITY;
    for (std::size_t i = 0; i < s.size(); ++i) {
      std::vector<double> d;
      for (std::size_t j = 0; j < s.size(); ++j) d.push_back(distance(s[i], s[j]));
      const double cost = detail::median_of(d);
      if (cost < medoid_cost) {
        medoid_cost = cost;
        medoid = i;
      }
    }
    std::vector<std::size_t> in;
    for (std::size_t i = 0; i < s.size(); ++i)
      if (distance(s[i], s[medoid]) <= 1.0) in.push_back(i);
    if (in.size() < tol.min_captures) {
      rig.problems.push_back(name + ": only " + std::to_string(in.size()) + " of " + std::to_string(s.size()) +
                             " captures agree on its offset from " + ref_name + " (within " +
                             std::to_string(tol.rotation_deg) + " degrees and " +
                             std::to_string(tol.translation_ratio) +
                             " of the capture spacing): the bands do not move as one rig");
      continue;
    }
    const Eigen::Quaterniond q0(s[in[0]].R);
    Eigen::Vector4d qsum = Eigen::Vector4d::Zero();
    std::vector<double> tx, ty, tz;
    for (std::size_t i : in) {
      const Eigen::Quaterniond q(s[i].R);
      qsum += (q.coeffs().dot(q0.coeffs()) < 0 ? -1.0 : 1.0) * q.coeffs();
      tx.push_back(s[i].t.x());
      ty.push_back(s[i].t.y());
      tz.push_back(s[i].t.z());
    }
    RigOffset o;
    o.offset.R = Eigen::Quaterniond(qsum.normalized()).toRotationMatrix();
    o.offset.t = Eigen::Vector3d(detail::median_of(tx), detail::median_of(ty), detail::median_of(tz));
    o.samples = s.size();
    o.inliers = in.size();
    for (std::size_t i : in) {
      o.rotation_spread_deg = std::max(o.rotation_spread_deg, detail::rotation_angle_deg(s[i].R, o.offset.R));
      if (std::isfinite(spacing))
        o.translation_spread = std::max(o.translation_spread, (s[i].t - o.offset.t).norm() / spacing);
    }
    rig.bands[b] = o;
  }
  return rig;
}

/// Where place_by_rig put an image: its capture, band, and the band of that capture it came from.
struct RigPlacement {
  std::size_t capture = 0, band = 0, from = 0;
};

/// Poses every image missing from `poses` (the poses `rig` was estimated from) whose band has an offset, through a registered band of
/// its own capture that has one too (the reference where it registered, else the band with the
/// most registered captures, the first of a tie): x_band = R_b R_f^T (x_from - t_f) + t_b, with
/// (R_b, t_b) and (R_f, t_f) the two bands' offsets from the reference. Returns what it placed,
/// by capture then band.
inline std::vector<RigPlacement> place_by_rig(std::vector<std::vector<std::optional<RigPose>>>& poses, const Rig& rig) {
  std::vector<RigPlacement> placed;
  if (rig.reference < 0) return placed;
  const std::size_t B = rig.bands.size();
  std::vector<std::size_t> order;  // source bands by preference
  const std::vector<std::size_t>& count = rig.registered;
  for (std::size_t b = 0; b < B; ++b)
    if (rig.bands[b]) order.push_back(b);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const bool ra = int(a) == rig.reference, rb = int(b) == rig.reference;
    return ra != rb ? ra : count[a] > count[b];
  });
  for (std::size_t c = 0; c < poses.size(); ++c) {
    auto& cap = poses[c];
    cap.resize(std::max(cap.size(), B));
    std::optional<std::size_t> from;
    for (std::size_t f : order)
      if (cap[f]) {
        from = f;
        break;
      }
    if (!from) continue;
    const RigPose& pf = *cap[*from];
    const RigPose& of = rig.bands[*from]->offset;
    for (std::size_t b = 0; b < B; ++b) {
      if (cap[b] || !rig.bands[b]) continue;
      const RigPose& ob = rig.bands[b]->offset;
      const Eigen::Matrix3d M = ob.R * of.R.transpose();
      RigPose p;
      p.R = M * pf.R;
      p.t = M * (pf.t - of.t) + ob.t;
      cap[b] = p;
      placed.push_back({c, b, *from});
    }
  }
  return placed;
}

}  // namespace msgs::io
