// include/msgs/synth/rig.hpp
// Size presets, the 5-camera drone rig (one RGB and four multispectral cameras with their own
// intrinsics and small mounting offsets) and the flight pattern from nadir to oblique views.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "../camera.hpp"
#include "geometry.hpp"
#include "noise.hpp"
#include "spectra.hpp"

namespace msgs::synth {

/// Image sizes and sampling of one generated dataset.
struct SynthPreset {
  std::string name;
  int rgb_width = 96, rgb_height = 72;  ///< D camera resolution (px)
  int ms_width = 64, ms_height = 48;    ///< resolution of each multispectral camera (px)
  int captures = 10;                    ///< rig exposures; each gives one image per band
  int aa = 2;                           ///< jittered rays per pixel along each axis (aa^2 per pixel)
  int points = 2000;                    ///< sparse point-cloud size (inliers + outliers)
  std::vector<int> downscales = {2};    ///< images_<f>/ folders to write
};

/// The built-in presets: `tiny` (tests), `small` (demo), `medium` (studies).
inline const std::vector<SynthPreset>& synth_presets() {
  static const std::vector<SynthPreset> presets = {
      {"tiny", 96, 72, 64, 48, 10, 2, 2000, {2}},
      {"small", 240, 180, 160, 120, 30, 2, 6000, {2, 4}},
      {"medium", 480, 360, 320, 240, 60, 2, 20000, {2, 4}},
  };
  return presets;
}

/// Comma-separated preset names, for error messages and usage text.
inline std::string synth_preset_list() {
  std::string s;
  for (const auto& p : synth_presets()) s += (s.empty() ? "" : ", ") + p.name;
  return s;
}

/// Look up a preset by name; throws std::invalid_argument naming the valid ones.
inline const SynthPreset& synth_preset(std::string_view name) {
  for (const auto& p : synth_presets())
    if (p.name == name) return p;
  throw std::invalid_argument("unknown synthetic preset '" + std::string(name) + "' (valid: " +
                              synth_preset_list() + ")");
}

/// How one camera sits in the rig. Offsets are in the rig frame (OpenCV axes: x right, y down,
/// z forward), so the four multispectral lenses form a small 2x2 block below the RGB lens.
struct RigMount {
  Vec3f offset;        ///< lens position relative to the rig centre (m)
  Vec3f boresight;     ///< small misalignment: rotations about camera x, y, z (degrees)
  float hfov_deg;      ///< nominal horizontal field of view
  float focal_scale;   ///< per-lens deviation of the focal length from nominal
  float aspect;        ///< fy / fx (non-square pixels by a hair)
  Vec2f pp_offset;     ///< principal point offset as a fraction of (width, height)
};

/// Mounting and lens data of each band's camera.
inline RigMount rig_mount(Band b) {
  switch (b) {
    case Band::D: return {Vec3f(0.f, -0.040f, 0.f), Vec3f(0.f, 0.f, 0.f), 70.f, 1.f, 1.f, Vec2f(0.010f, -0.008f)};
    case Band::MS_G: return {Vec3f(-0.025f, 0.020f, 0.f), Vec3f(0.30f, -0.20f, 0.10f), 62.f, 1.012f, 1.002f, Vec2f(0.014f, 0.009f)};
    case Band::MS_R: return {Vec3f(0.025f, 0.020f, 0.f), Vec3f(-0.25f, 0.15f, -0.10f), 62.f, 0.992f, 1.001f, Vec2f(-0.012f, 0.011f)};
    case Band::MS_RE: return {Vec3f(-0.025f, 0.045f, 0.f), Vec3f(0.20f, 0.25f, 0.05f), 62.f, 1.004f, 0.999f, Vec2f(0.008f, -0.013f)};
    case Band::MS_NIR: return {Vec3f(0.025f, 0.045f, 0.f), Vec3f(-0.15f, -0.30f, 0.15f), 62.f, 0.985f, 1.002f, Vec2f(-0.009f, -0.010f)};
  }
  throw std::invalid_argument("rig_mount: bad band");
}

/// Intrinsics of a band's camera at the preset's resolution.
inline Camera<float> rig_intrinsics(Band b, const SynthPreset& p) {
  const RigMount m = rig_mount(b);
  Camera<float> c;
  c.width = b == Band::D ? p.rgb_width : p.ms_width;
  c.height = b == Band::D ? p.rgb_height : p.ms_height;
  const double deg = 3.14159265358979323846 / 180.0;
  c.fx = float(0.5 * c.width / std::tan(0.5 * m.hfov_deg * deg) * m.focal_scale);
  c.fy = c.fx * m.aspect;
  c.cx = float(c.width) * (0.5f + m.pp_offset.x());
  c.cy = float(c.height) * (0.5f + m.pp_offset.y());
  return c;
}

/// World-to-camera rotation (OpenCV axes) of a camera at `pos` looking at `target`, with the
/// image's "up" towards the horizontal direction `ahead`. Well defined for nadir views, where the
/// forward axis is vertical and `ahead` alone fixes the image orientation.
inline Mat3f look_at_rotation(const Vec3f& pos, const Vec3f& target, const Vec3f& ahead) {
  const Vec3f f = (target - pos).normalized();
  Vec3f up = ahead - ahead.dot(f) * f;
  if (up.squaredNorm() < 1e-12f) up = Vec3f::UnitY() - f.y() * f;  // degenerate: ahead along f
  const Vec3f y = -up.normalized();  // OpenCV y points down in the image
  const Vec3f x = y.cross(f);
  Mat3f r;
  r.row(0) = x.transpose();
  r.row(1) = y.transpose();
  r.row(2) = f.transpose();
  return r;
}

/// The five cameras of one exposure, indexed by Band.
struct Capture {
  std::array<Camera<float>, num_bands> cameras;
  Vec3f rig_position = Vec3f::Zero();  ///< world position of the rig centre (m)
  float tilt_deg = 0.f;                ///< angle of the rig's optical axis from nadir
};

/// Place the rig: band cameras share the rig orientation up to their boresight misalignment and
/// sit at their mounting offsets.
inline Capture make_capture(const SynthPreset& p, const Vec3f& rig_pos, const Mat3f& rig_R) {
  Capture cap;
  cap.rig_position = rig_pos;
  for (Band b : all_bands) {
    const RigMount m = rig_mount(b);
    Camera<float> c = rig_intrinsics(b, p);
    const float deg = 3.14159265358979f / 180.f;
    const Mat3f delta = (Eigen::AngleAxisf(m.boresight.z() * deg, Vec3f::UnitZ()) *
                         Eigen::AngleAxisf(m.boresight.y() * deg, Vec3f::UnitY()) *
                         Eigen::AngleAxisf(m.boresight.x() * deg, Vec3f::UnitX()))
                            .toRotationMatrix();
    c.R = delta * rig_R;
    const Vec3f pos = rig_pos + rig_R.transpose() * m.offset;
    c.t = -(c.R * pos);
    cap.cameras[static_cast<std::size_t>(b)] = c;
  }
  return cap;
}

/// Flight pattern: one orbit around the scene centre at about 14 m, the tilt from nadir sweeping
/// 0..35 degrees one and a half times, the aim point wandering within 2.5 m of the centre, small
/// seeded jitter on everything. Capture 0 is a nadir view.
inline std::vector<Capture> make_flight(const SynthPreset& p, std::uint64_t seed) {
  std::vector<Capture> caps;
  Rng rng(hash_mix(seed, 0xF11647ULL));
  const double pi = 3.14159265358979323846;
  const int n = p.captures;
  for (int i = 0; i < n; ++i) {
    const double s = double(i) / double(n);
    const double theta = 2.0 * pi * s + 0.3 + rng.uniform(-0.05, 0.05);
    const double tilt = (35.0 * 0.5 * (1.0 - std::cos(2.0 * pi * 1.5 * s)) +
                         (i == 0 ? 0.0 : rng.uniform(-2.0, 2.0))) * pi / 180.0;
    const double alt = 14.0 + 1.2 * std::sin(2.0 * theta) + rng.uniform(-0.2, 0.2);
    const Vec3f target(float(2.5 * std::cos(3.0 * theta + 1.0)), float(2.0 * std::sin(2.0 * theta)), 0.f);
    const double reach = alt * std::tan(std::max(0.0, tilt));
    const Vec3f away(float(std::cos(theta)), float(std::sin(theta)), 0.f);
    const Vec3f pos = target + float(reach) * away + Vec3f(0.f, 0.f, float(alt));
    // Nadir: aim straight down, image up still towards -away (the heading).
    const Mat3f r = look_at_rotation(pos, tilt > 1e-6 ? target : Vec3f(pos.x(), pos.y(), 0.f), -away);
    Capture c = make_capture(p, pos, r);
    c.tilt_deg = float(std::max(0.0, tilt) * 180.0 / pi);
    caps.push_back(c);
  }
  return caps;
}

}  // namespace msgs::synth
