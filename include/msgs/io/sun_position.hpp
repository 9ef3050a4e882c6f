// include/msgs/io/sun_position.hpp
// Where the sun stands in the sky at a place and a moment: its elevation above the horizon
// (corrected for atmospheric refraction) and its azimuth, clockwise from north. This is the
// low-precision solar position of NOAA's solar calculator (after Meeus, "Astronomical
// Algorithms"): about 0.01 degrees between 1800 and 2100, enough to level a light sensor's
// reading (an error of 0.01 degrees changes the sine of a 30-degree elevation by 0.03%).
//
//   T      Julian centuries of 36525 days since 2000-01-01 12:00 UTC
//   L0, M  the sun's geometric mean longitude and mean anomaly; e the orbit's eccentricity
//   C      the equation of the centre; lambda the apparent longitude (nutation and aberration)
//   eps    the obliquity of the ecliptic; delta = asin(sin eps sin lambda) the declination
//   E      the equation of time; the hour angle H from the true solar time at the longitude
//   cos(zenith) = sin(lat) sin(delta) + cos(lat) cos(delta) cos(H)
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>

namespace msgs::io {

/// The sun's place in the sky, in radians: elevation above the horizon (refraction included;
/// negative below it) and azimuth clockwise from north (0 north, pi/2 east).
struct SunPosition {
  double elevation = 0.0;
  double azimuth = 0.0;
};

namespace detail {

inline constexpr double kDegree = std::numbers::pi / 180.0;

/// Atmospheric refraction in degrees at a true elevation of `e` degrees (NOAA's approximation
/// for a standard atmosphere).
inline double refraction_deg(double e) {
  if (e > 85.0) return 0.0;
  const double t = std::tan(e * kDegree);
  double arcsec;
  if (e > 5.0) arcsec = 58.1 / t - 0.07 / (t * t * t) + 0.000086 / std::pow(t, 5);
  else if (e > -0.575) arcsec = 1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)));
  else arcsec = -20.772 / t;
  return arcsec / 3600.0;
}

}  // namespace detail

/// The sun's position at `unix_utc_s` (seconds since 1970-01-01 00:00 UTC) seen from latitude
/// `lat_deg` (north positive) and longitude `lon_deg` (east positive).
inline SunPosition sun_position(double unix_utc_s, double lat_deg, double lon_deg) {
  using detail::kDegree;
  const double jd = unix_utc_s / 86400.0 + 2440587.5;
  const double T = (jd - 2451545.0) / 36525.0;
  const double L0 = std::fmod(280.46646 + T * (36000.76983 + T * 0.0003032), 360.0);
  const double M = 357.52911 + T * (35999.05029 - 0.0001537 * T);
  const double e = 0.016708634 - T * (0.000042037 + 0.0000001267 * T);
  const double Mr = M * kDegree;
  const double C = std::sin(Mr) * (1.914602 - T * (0.004817 + 0.000014 * T)) +
                   std::sin(2 * Mr) * (0.019993 - 0.000101 * T) + std::sin(3 * Mr) * 0.000289;
  const double omega = (125.04 - 1934.136 * T) * kDegree;
  const double lambda = (L0 + C - 0.00569 - 0.00478 * std::sin(omega)) * kDegree;
  const double eps0 = 23.0 + (26.0 + (21.448 - T * (46.815 + T * (0.00059 - T * 0.001813))) / 60.0) / 60.0;
  const double eps = (eps0 + 0.00256 * std::cos(omega)) * kDegree;
  const double delta = std::asin(std::sin(eps) * std::sin(lambda));
  const double y = std::tan(eps / 2) * std::tan(eps / 2);
  const double L0r = L0 * kDegree;
  const double eq_time_min =
      4.0 / kDegree *
      (y * std::sin(2 * L0r) - 2 * e * std::sin(Mr) + 4 * e * y * std::sin(Mr) * std::cos(2 * L0r) -
       0.5 * y * y * std::sin(4 * L0r) - 1.25 * e * e * std::sin(2 * Mr));
  const double day_min = std::fmod(unix_utc_s / 60.0, 1440.0);
  const double solar_min = (day_min < 0 ? day_min + 1440.0 : day_min) + eq_time_min + 4.0 * lon_deg;
  double H = solar_min / 4.0 - 180.0;  // degrees, 0 at solar noon
  H = std::remainder(H, 360.0);
  const double lat = lat_deg * kDegree, h = H * kDegree;
  const double cos_zenith =
      std::clamp(std::sin(lat) * std::sin(delta) + std::cos(lat) * std::cos(delta) * std::cos(h), -1.0, 1.0);
  const double elevation_deg = 90.0 - std::acos(cos_zenith) / kDegree;
  SunPosition s;
  s.elevation = (elevation_deg + detail::refraction_deg(elevation_deg)) * kDegree;
  // Measured from south towards west, then turned to be from north.
  double az = std::atan2(std::sin(h), std::cos(h) * std::sin(lat) - std::tan(delta) * std::cos(lat)) + std::numbers::pi;
  if (az >= 2 * std::numbers::pi) az -= 2 * std::numbers::pi;
  s.azimuth = az;
  return s;
}

}  // namespace msgs::io
