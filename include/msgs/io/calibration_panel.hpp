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
#include <string>
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
      sum += (dn - dark_level(r, x, y)) / sensor_response(r, x, y);
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

/// The session of each panel picture taken at `time_s` (in its order): 0, 1, .. in time, a new one
/// after a gap of more than kPanelSessionGap; all 0 when some picture has no time.
inline std::vector<std::size_t> panel_sessions(const std::vector<std::optional<double>>& time_s) {
  std::vector<std::size_t> session(time_s.size(), 0);
  if (!std::all_of(time_s.begin(), time_s.end(), [](const auto& t) { return t.has_value(); })) return session;
  std::vector<std::size_t> order(time_s.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return *time_s[a] < *time_s[b]; });
  for (std::size_t k = 1; k < order.size(); ++k)
    session[order[k]] = session[order[k - 1]] + (*time_s[order[k]] - *time_s[order[k - 1]] > kPanelSessionGap ? 1 : 0);
  return session;
}

/// Panels of several reflectances in one session: their mean response over the area against the
/// reflectance rho is a line, response = E (rho + offset), whose offset (haze between camera and
/// ground, which adds light in proportion to the sunlight as if every surface reflected that much
/// more; a black level a little off) a panel of one reflectance cannot tell from E. The lowest
/// reflectance of a session has to lie this many times below its highest for the line to be fitted.
inline constexpr double kPanelLineAlbedoRatio = 2.0;
/// The largest offset, in reflectance, the line may have: haze adds a few hundredths, a black
/// level a little off less; more says a panel's reflectance or area is mistaken.
inline constexpr double kMaxPanelLineOffset = 0.25;

/// One panel picture's mean response over its area, its panel's reflectance and its time.
struct PanelResponse {
  double response = 0.0;
  double albedo = 0.0;
  std::optional<double> time_s;
};

/// The empirical line's offset of a band, in reflectance: the reflectance of a pixel is
/// response / E - offset, and a panel picture's E = response / (albedo + offset).
struct PanelLine {
  double offset = 0.0;
  std::size_t sessions = 0;     ///< the sessions whose panels of several reflectances gave it
  double low_albedo = 0.0, high_albedo = 0.0;  ///< the reflectances they spanned
  /// Why panels of several reflectances gave no line (empty when one was fitted, or when the
  /// reflectances do not lie kPanelLineAlbedoRatio apart at all and no line was to be had)
  std::string problem;
  bool fitted() const { return sessions > 0 && problem.empty(); }
};

/// Fit the offset of `pictures` (responses > 0, albedos in (0, 1]): in each session (panel_sessions)
/// whose reflectances span kPanelLineAlbedoRatio, the least-squares line response = a rho + b gives
/// offset b / a; the offset is their mean, weighted by the pictures. Offset 0 (the line through
/// zero) where no session spans the ratio, with a problem where the pictures as a whole do (the
/// panels were photographed at different times); a line that falls with the reflectance, an
/// offset beyond kMaxPanelLineOffset or one that would leave a panel's albedo + offset not
/// positive is a problem too.
inline PanelLine panel_line(const std::vector<PanelResponse>& pictures) {
  PanelLine line;
  std::vector<std::optional<double>> times;
  for (const PanelResponse& p : pictures) times.push_back(p.time_s);
  const std::vector<std::size_t> session = panel_sessions(times);
  const std::size_t sessions = pictures.empty() ? 0 : *std::max_element(session.begin(), session.end()) + 1;
  double weighted = 0.0, weight = 0.0, low = 1e300, high = 0.0;
  for (std::size_t s = 0; s < sessions; ++s) {
    double n = 0.0, sr = 0.0, sv = 0.0, lo = 1e300, hi = 0.0;
    for (std::size_t i = 0; i < pictures.size(); ++i)
      if (session[i] == s) {
        n += 1.0;
        sr += pictures[i].albedo;
        sv += pictures[i].response;
        lo = std::min(lo, pictures[i].albedo);
        hi = std::max(hi, pictures[i].albedo);
      }
    if (!(hi >= kPanelLineAlbedoRatio * lo)) continue;
    double srr = 0.0, srv = 0.0;  // centred sums
    for (std::size_t i = 0; i < pictures.size(); ++i)
      if (session[i] == s) {
        const double dr = pictures[i].albedo - sr / n;
        srr += dr * dr;
        srv += dr * (pictures[i].response - sv / n);
      }
    const double a = srv / srr, b = sv / n - a * sr / n;
    if (!(a > 0.0) || !std::isfinite(b)) {
      line.problem = cat("the panels of reflectance ", short_number(lo, 3), " to ", short_number(hi, 3),
                         " read no brighter for the higher reflectance: a panel's reflectance or area mistaken?");
      line.offset = 0.0;
      return line;
    }
    weighted += n * (b / a);
    weight += n;
    ++line.sessions;
    low = std::min(low, lo);
    high = std::max(high, hi);
  }
  if (line.sessions == 0) {
    const auto [lowest, highest] = std::minmax_element(
        pictures.begin(), pictures.end(), [](const PanelResponse& a, const PanelResponse& b) { return a.albedo < b.albedo; });
    if (!pictures.empty() && highest->albedo >= kPanelLineAlbedoRatio * lowest->albedo)
      line.problem = cat("no session holds panels whose reflectances lie ", short_number(kPanelLineAlbedoRatio),
                         " times apart (panels photographed more than ", short_number(kPanelSessionGap),
                         " s apart do not make one line)");
    return line;
  }
  line.offset = weighted / weight;
  line.low_albedo = low;
  line.high_albedo = high;
  if (!(std::abs(line.offset) <= kMaxPanelLineOffset)) {
    line.problem = cat("the fitted offset, ", short_number(line.offset, 3), ", is more than haze or a black level",
                       " gives (at most ", short_number(kMaxPanelLineOffset), " either way): a panel's reflectance or",
                       " area mistaken?");
    line.offset = 0.0;
    return line;
  }
  for (const PanelResponse& p : pictures)
    if (!(p.albedo + line.offset > 0.0)) {
      line.problem = cat("the fitted offset, ", short_number(line.offset, 3), ", would leave the panel of reflectance ",
                         short_number(p.albedo, 3), " no light: the line does not describe these panels");
      line.offset = 0.0;
      return line;
    }
  return line;
}

/// A band's irradiance through the flight, from its panel pictures.
struct PanelSchedule {
  /// One node per session, (mean time, mean E), in time order; a single node when some picture
  /// has no time or all of them make one session.
  std::vector<std::array<double, 2>> nodes;
  double mean = 0.0;  ///< E over all the pictures
  /// The empirical line's offset (panel_line): a pixel's reflectance is response / at(t) - offset.
  double offset = 0.0;
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
inline PanelSchedule panel_schedule(const std::vector<PanelIrradiance>& pictures) {
  PanelSchedule s;
  if (pictures.empty()) return s;
  for (const PanelIrradiance& p : pictures) s.mean += p.e;
  s.mean /= double(pictures.size());
  std::vector<std::optional<double>> times;
  for (const PanelIrradiance& p : pictures) times.push_back(p.time_s);
  const std::vector<std::size_t> session = panel_sessions(times);
  const std::size_t sessions = *std::max_element(session.begin(), session.end()) + 1;
  if (sessions == 1 && !std::all_of(times.begin(), times.end(), [](const auto& t) { return t.has_value(); })) {
    s.nodes.push_back({0.0, s.mean});
    return s;
  }
  std::vector<std::size_t> order(pictures.size());  // summed in time order
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return *times[a] < *times[b]; });
  for (std::size_t k = 0; k < sessions; ++k) {
    double t_sum = 0.0, e_sum = 0.0;
    int n = 0;
    for (std::size_t i : order)
      if (session[i] == k) {
        t_sum += *pictures[i].time_s;
        e_sum += pictures[i].e;
        ++n;
      }
    s.nodes.push_back({t_sum / n, e_sum / n});
  }
  return s;
}

}  // namespace msgs::io
