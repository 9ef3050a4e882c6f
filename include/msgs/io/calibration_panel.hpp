// include/msgs/io/calibration_panel.hpp
// Reflectance from pictures of a calibration panel (`msgs import --radiometry panel` and
// `panel+dls`). A panel of known reflectance rho (its albedo, which MicaSense cameras read from
// the panel's QR code into Xmp.Camera.Albedo) photographed on the ground before or after the
// flight gives each band's irradiance in the sensor's own units,
//
//   E = mean over the panel's reflecting area of (DN - black_level) / response(x, y) / rho,
//
// with response(x, y) = exposure x gain x vignetting fall-off x row gradient (x the light
// sensor's irradiance, for panel+dls) as in radiometry.hpp, and every image of the band becomes
// reflectance = (DN - black_level) / (response x E): the band's scale is 1 / E. The area is the
// quadrilateral the camera found (Xmp.Camera.ReflectArea, pixel coordinates of its corners);
// pixels count when their integer coordinates lie inside or on it, as in MicaSense's library.
//
// Panel pictures taken before and after the flight give the sunlight at both ends of it: the
// band's irradiance at an image's time is then interpolated linearly between the sessions of
// panel pictures around it (PanelSchedule), which follows a sun climbing or sinking during the
// flight; clouds passing in between need the light sensor (panel+dls).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <vector>

#include "msgs/image.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/radiometry.hpp"

namespace msgs::io {

/// The corners of a panel's reflecting area, (x, y) in pixels, in order around it.
using PanelArea = std::array<std::array<double, 2>, 4>;

namespace detail {

/// (b - a) x (c - a).
inline double cross(const std::array<double, 2>& a, const std::array<double, 2>& b, double cx, double cy) {
  return (b[0] - a[0]) * (cy - a[1]) - (b[1] - a[1]) * (cx - a[0]);
}

}  // namespace detail

/// Whether the corners go once around a convex quadrilateral of non-zero area (either direction).
inline bool convex_quad(const PanelArea& q) {
  double sign = 0.0;
  for (std::size_t i = 0; i < 4; ++i) {
    const auto& a = q[i];
    const auto& b = q[(i + 1) % 4];
    const auto& c = q[(i + 2) % 4];
    const double t = detail::cross(a, b, c[0], c[1]);
    if (!(std::abs(t) > 0.0) || !std::isfinite(t)) return false;
    if (sign == 0.0) sign = t;
    else if (t * sign < 0.0) return false;
  }
  return true;
}

/// Whether (x, y) lies inside the convex quadrilateral q or on its edge.
inline bool inside_quad(const PanelArea& q, double x, double y) {
  bool pos = false, neg = false;
  for (std::size_t i = 0; i < 4; ++i) {
    const double t = detail::cross(q[i], q[(i + 1) % 4], x, y);
    pos = pos || t > 0.0;
    neg = neg || t < 0.0;
  }
  return !(pos && neg);
}

/// What a panel picture gives in one band.
struct PanelReading {
  double mean = 0.0;       ///< mean of (DN - black level) / response over the area
  std::size_t pixels = 0;  ///< pixels in the area
  std::size_t saturated = 0;  ///< of them, at or above kSaturatedShareOfMax of the largest DN
};

/// A pixel this close to the largest digital number has clipped (MicaSense's library: 65000 of 65535).
inline constexpr double kSaturatedShareOfMax = 65000.0 / 65535.0;
/// The fewest pixels a panel area may hold.
inline constexpr std::size_t kMinPanelPixels = 16;
/// The largest share of clipped pixels a panel area may hold: a clipped panel reads too dark, and
/// every reflectance computed from it too high.
inline constexpr double kMaxSaturatedPanelShare = 0.01;

/// Read the panel's area of picture `raw` (values in [0, 1]; x dn_max = DN) under `r` (its scale is
/// not used). IoError naming `file` for an area that is not a convex quadrilateral, holds fewer
/// than kMinPanelPixels pixels of the image, has clipped, or is no brighter than the black level.
inline PanelReading read_panel(const Image<float>& raw, const FrameRadiometry& r, const PanelArea& area,
                               const std::filesystem::path& file) {
  check_radiometry(r, raw.width, raw.height, file);
  const auto corners = [&] {
    std::string s;
    for (const auto& c : area) s += cat(s.empty() ? "" : " ", "(", short_number(c[0]), ", ", short_number(c[1]), ")");
    return s;
  };
  if (!convex_quad(area))
    fail(file, "Xmp.Camera.ReflectArea",
         cat("the corners ", corners(), " do not go around a convex area (leave this panel picture out of --images)"));
  double x0 = area[0][0], x1 = x0, y0 = area[0][1], y1 = y0;
  for (const auto& c : area) {
    x0 = std::min(x0, c[0]);
    x1 = std::max(x1, c[0]);
    y0 = std::min(y0, c[1]);
    y1 = std::max(y1, c[1]);
  }
  const int ix0 = int(std::max(0.0, std::ceil(x0))), ix1 = int(std::min(double(raw.width - 1), std::floor(x1)));
  const int iy0 = int(std::max(0.0, std::ceil(y0))), iy1 = int(std::min(double(raw.height - 1), std::floor(y1)));
  PanelReading p;
  double sum = 0.0;
  for (int y = iy0; y <= iy1; ++y)
    for (int x = ix0; x <= ix1; ++x) {
      if (!inside_quad(area, x, y)) continue;
      const double dn = double(raw.at(x, y, 0)) * r.dn_max;
      sum += (dn - r.black_level) / sensor_response(r, x, y);
      ++p.pixels;
      p.saturated += dn >= kSaturatedShareOfMax * r.dn_max;
    }
  if (p.pixels < kMinPanelPixels)
    fail(file, "Xmp.Camera.ReflectArea",
         cat("the panel area ", corners(), " holds ", p.pixels, " pixels of the ", raw.width, "x", raw.height,
             " image (need at least ", kMinPanelPixels, "; leave this panel picture out of --images)"));
  if (double(p.saturated) > kMaxSaturatedPanelShare * double(p.pixels))
    fail(file, cat(p.saturated, " of the ", p.pixels, " pixels of the panel area have clipped (DN near ",
                   short_number(r.dn_max), "): the panel would read too dark and every reflectance too high; leave this",
                   " panel picture out of --images, or use --radiometry reflectance"));
  p.mean = sum / double(p.pixels);
  if (!(p.mean > 0.0) || !std::isfinite(p.mean))
    fail(file, cat("the panel area is no brighter than the black level (mean ", short_number(p.mean),
                   " above it): not a picture of the panel; leave it out of --images"));
  return p;
}

/// Panel pictures taken within this many seconds of the one before form one session (a panel is
/// photographed a few times in a row); sessions are the nodes of a PanelSchedule.
inline constexpr double kPanelSessionGap = 120.0;

/// One panel picture's irradiance E and when it was taken.
struct PanelIrradiance {
  double e = 0.0;
  std::optional<double> time_s;
};

/// A band's irradiance through the flight, from its panel pictures.
struct PanelSchedule {
  /// One node per session, (mean time, mean E), in time order; a single node when some picture
  /// has no time or all of them make one session.
  std::vector<std::array<double, 2>> nodes;
  double mean = 0.0;  ///< E over all the pictures
  /// Whether the irradiance follows time (two sessions or more).
  bool timed() const { return nodes.size() > 1; }
  /// E at time t: linear between the sessions around it, the nearest session's before the first
  /// and after the last, the mean when t is unknown or the schedule is not timed.
  double at(std::optional<double> t) const {
    if (!timed() || !t) return mean;
    if (*t <= nodes.front()[0]) return nodes.front()[1];
    if (*t >= nodes.back()[0]) return nodes.back()[1];
    std::size_t i = 1;
    while (nodes[i][0] < *t) ++i;
    const auto& a = nodes[i - 1];
    const auto& b = nodes[i];
    const double w = (*t - a[0]) / (b[0] - a[0]);
    return a[1] + w * (b[1] - a[1]);
  }
};

/// The schedule of a band's panel pictures (at least one, each E > 0).
inline PanelSchedule panel_schedule(std::vector<PanelIrradiance> pictures) {
  PanelSchedule s;
  if (pictures.empty()) return s;
  for (const PanelIrradiance& p : pictures) s.mean += p.e;
  s.mean /= double(pictures.size());
  const bool all_timed =
      std::all_of(pictures.begin(), pictures.end(), [](const PanelIrradiance& p) { return p.time_s.has_value(); });
  if (!all_timed) {
    s.nodes.push_back({0.0, s.mean});
    return s;
  }
  std::stable_sort(pictures.begin(), pictures.end(),
                   [](const PanelIrradiance& a, const PanelIrradiance& b) { return *a.time_s < *b.time_s; });
  double t_sum = 0.0, e_sum = 0.0, last = *pictures.front().time_s;
  int n = 0;
  for (const PanelIrradiance& p : pictures) {
    if (n > 0 && *p.time_s - last > kPanelSessionGap) {
      s.nodes.push_back({t_sum / n, e_sum / n});
      t_sum = e_sum = 0.0;
      n = 0;
    }
    t_sum += *p.time_s;
    e_sum += p.e;
    ++n;
    last = *p.time_s;
  }
  s.nodes.push_back({t_sum / n, e_sum / n});
  return s;
}

}  // namespace msgs::io
