// include/msgs/io/light_sensor_tilt.hpp
// A downwelling light sensor rides on the drone and tilts with it: it reads the sunlight on its
// own tilted face, not on level ground, which is what reflectance is taken against. MicaSense's
// DLS 1 (RedEdge, RedEdge-M) records only that reading and the sensor's attitude; a DLS 2 records
// the direct and scattered parts of the light besides, from which some firmware computed the
// level-ground irradiance wrongly. Both are levelled here as MicaSense's image-processing library
// and OpenDroneMap level them:
//
//   reading = T(theta) (D cos(theta) + S)     (the tilted sensor, a clear sky)
//   E       = D sin(elevation) + S            (level ground)
//
// with D the direct sunlight on a surface facing the sun, S the scattered light (taken as D / 6
// for a DLS 1, which cannot tell them apart), theta the angle between the sensor's normal and the
// sun, elevation the sun's above the horizon (msgs/io/sun_position.hpp) and T the Fresnel
// transmission of the sensor's diffuser at theta: air (n = 1.000277) to polycarbonate (1.6) to
// PTFE (1.38), unpolarised light.
//
// The attitude is the sensor's yaw, pitch and roll in the local north-east-down frame (MicaSense's
// Xmp.DLS.Yaw/Pitch/Roll, radians): the body turned by yaw about down, then pitch about its right
// axis (nose up positive), then roll about its forward axis. The sensor faces up out of the body.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <string>

#include "msgs/io/error.hpp"
#include "msgs/io/sun_position.hpp"

namespace msgs::io {

/// The direct-to-scattered ratio of a clear sky that a DLS 1's reading is levelled with.
inline constexpr double kDirectToScattered = 6.0;
/// Beyond this angle between the sun and the sensor's normal (degrees) a reading is not levelled:
/// the sensor then sees mostly scattered light, and the model's 1 / (cos(theta) + 1/6) would
/// amplify its errors several times.
inline constexpr double kMaxSunSensorAngleDeg = 80.0;

/// Unit vector towards the sun in the local north-east-down frame.
inline std::array<double, 3> sun_direction_ned(const SunPosition& s) {
  return {std::cos(s.azimuth) * std::cos(s.elevation), std::sin(s.azimuth) * std::cos(s.elevation), -std::sin(s.elevation)};
}

/// The upward normal, in north-east-down, of a sensor mounted level on a body with attitude
/// (yaw, pitch, roll) in radians: minus the body's down axis, R = Rz(yaw) Ry(pitch) Rx(roll).
inline std::array<double, 3> light_sensor_normal_ned(double yaw, double pitch, double roll) {
  const double cy = std::cos(yaw), sy = std::sin(yaw), cp = std::cos(pitch), sp = std::sin(pitch);
  const double cr = std::cos(roll), sr = std::sin(roll);
  return {-(cy * sp * cr + sy * sr), -(sy * sp * cr - cy * sr), -(cp * cr)};
}

/// The angle (radians) between the sun and a sensor's normal.
inline double sun_sensor_angle(const SunPosition& sun, double yaw, double pitch, double roll) {
  const auto s = sun_direction_ned(sun);
  const auto n = light_sensor_normal_ned(yaw, pitch, roll);
  return std::acos(std::clamp(s[0] * n[0] + s[1] * n[1] + s[2] * n[2], -1.0, 1.0));
}

/// The fraction of unpolarised light at incidence `theta` (radians) that passes the light
/// sensor's diffuser: the Fresnel transmission of its two interfaces, each at the angle the light
/// has in the layer before it (0 where the formulas leave [0, 1]).
inline double diffuser_transmission(double theta) {
  const double n[] = {1.000277, 1.6, 1.38};
  double t = 1.0, phi = theta;
  for (int i = 0; i < 2; ++i) {
    const double n1 = n[i], n2 = n[i + 1];
    phi = std::asin(std::sin(phi) / n1);
    const double c1 = std::cos(phi), s2 = n1 / n2 * std::sin(phi);
    const double c2 = std::sqrt(std::max(0.0, 1.0 - s2 * s2));
    const double rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2), rp = (n1 * c2 - n2 * c1) / (n1 * c2 + n2 * c1);
    const double ti = 1.0 - 0.5 * rs * rs - 0.5 * rp * rp;
    t *= std::isfinite(ti) ? std::clamp(ti, 0.0, 1.0) : 0.0;
  }
  return t;
}

/// Why the sun's place does not allow levelling a reading (empty when it does): below the
/// horizon, or too far from the sensor's normal.
inline std::string levelling_problem(double elevation, double theta) {
  if (!(elevation > 0.0))
    return cat("the sun was ", short_number(elevation * 180.0 / std::numbers::pi, 3),
               " degrees above the horizon (expected > 0: is the capture time UTC?)");
  if (!(theta <= kMaxSunSensorAngleDeg * std::numbers::pi / 180.0))
    return cat("the sun was ", short_number(theta * 180.0 / std::numbers::pi, 3),
               " degrees from the light sensor's normal (at most ", kMaxSunSensorAngleDeg, " can be levelled)");
  return {};
}

/// The irradiance on level ground from a tilted DLS 1's `reading` (any unit; the result has it),
/// with the sun `theta` from the sensor's normal and `elevation` above the horizon (radians):
/// reading / T(theta) / (cos(theta) + 1/6) x (sin(elevation) + 1/6). Use levelling_problem first.
inline double level_tilted_reading(double reading, double theta, double elevation) {
  const double scattered = 1.0 / kDirectToScattered;
  const double direct = reading / diffuser_transmission(theta) / (std::cos(theta) + scattered);
  return direct * (std::sin(elevation) + scattered);
}

/// The irradiance on level ground from a DLS 2's direct (on a surface facing the sun) and
/// scattered parts, with the sun `elevation` radians above the horizon.
inline double level_direct_scattered(double direct, double scattered, double elevation) {
  return direct * std::sin(elevation) + scattered;
}

}  // namespace msgs::io
