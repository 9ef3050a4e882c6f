// include/msgs/synth/scene.hpp
// The procedural outdoor scene (lawn with soil patches, trees, solar panels, a pond, a painted pad),
// its ground-truth ray tracing and its spectral shading under a sun with shadows and a sky.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string_view>
#include <vector>

#include "geometry.hpp"
#include "noise.hpp"
#include "rig.hpp"
#include "spectra.hpp"

namespace msgs::synth {

/// What a ray hit; vegetation is `Crown` (and the grassy parts of `Ground`), water is `Pond`.
enum class Surface : std::uint8_t { None = 0, Ground, Crown, Trunk, Pond, Panel, PanelLeg };

/// A tree: trunk plus a crown made of overlapping spheres, with its own leaf-vigour level.
struct Tree {
  VCylinder trunk;
  std::vector<Sphere> crown;
  Sphere bound;          ///< encloses trunk and crown (early-out for rays)
  float vigour = 0.7f;   ///< 0 = stressed (low NIR), 1 = vigorous
  std::uint64_t seed = 0;
};

/// A row of solar modules on a tilted thin box, with legs.
struct PanelRow {
  Box panel;               ///< local x along the row, y up the slope, z out of the glass
  std::array<Box, 4> legs;
  Sphere bound;
  int modules = 4;
};

/// A concrete pad with painted colour markings (detail visible in RGB, flat in red edge / NIR).
struct Pad {
  Vec2f c = Vec2f::Zero();
  float angle = 0.f;  ///< rotation about z (radians)
  Vec2f half = Vec2f(2.f, 1.5f);
};

/// A painted line on the lawn: a segment with a half width.
struct PaintLine {
  Vec2f a = Vec2f::Zero(), b = Vec2f::UnitX();
  float half_width = 0.15f;
};

/// Everything needed to render the dataset: geometry, materials, lighting and the flight.
struct SynthScene {
  SynthPreset preset;
  std::uint64_t seed = 1;
  std::vector<Tree> trees;
  std::vector<PanelRow> panels;
  Disc pond;
  Pad pad;
  PaintLine line;
  Vec3f sun_dir = Vec3f(0, 0, 1);  ///< unit vector towards the sun
  Spectrum sun{};                  ///< irradiance of the sun on a surface facing it
  Spectrum sky{};                  ///< irradiance of the sky on an upward surface
  Spectrum sky_zenith{}, sky_horizon{};  ///< radiance seen by rays that escape
  std::vector<Capture> captures;   ///< the drone flight: one 5-camera capture per exposure
};

/// Ground-truth intersection of a ray with the scene.
struct RayHit {
  bool hit = false;
  float t = 0.f;                     ///< distance along the (unit) ray
  Vec3f p = Vec3f::Zero();           ///< world hit point
  Vec3f n = Vec3f::UnitZ();          ///< geometric normal, facing the ray
  Vec3f local = Vec3f::Zero();       ///< primitive-local texture coordinates
  Surface surface = Surface::None;
  int object = -1;                   ///< tree / panel-row index where applicable
  int face = -1;                     ///< box face for panels
};

/// Build the scene for a preset: a fixed layout with seeded jitter, so every seed has the same
/// kinds of content (trees, panels, pond, pad) in view.
inline SynthScene make_scene(const SynthPreset& preset, std::uint64_t seed) {
  SynthScene s;
  s.preset = preset;
  s.seed = seed;
  Rng rng(hash_mix(seed, 0x5CE11EULL));
  const float pi = 3.14159265358979f;
  auto jit = [&](float a) { return float(rng.uniform(-a, a)); };

  s.pond.c = Vec3f(4.0f + jit(0.4f), -3.5f + jit(0.4f), 0.01f);
  s.pond.r = 2.4f + jit(0.2f);

  s.pad.c = Vec2f(-4.5f + jit(0.3f), -4.5f + jit(0.3f));
  s.pad.angle = (15.f + jit(5.f)) * pi / 180.f;
  s.pad.half = Vec2f(2.2f, 1.6f);

  s.line.a = Vec2f(-7.0f + jit(0.3f), 0.8f + jit(0.3f));
  s.line.b = Vec2f(-1.2f + jit(0.2f), 1.6f + jit(0.3f));
  s.line.half_width = 0.15f;

  // Panel rows face south (-y), tilted 25 degrees, low edge 0.5 m above the ground.
  for (int r = 0; r < 2; ++r) {
    PanelRow row;
    const float tilt = 25.f * pi / 180.f;
    row.panel.half = Vec3f(2.2f, 0.55f, 0.025f);
    row.panel.axes = Eigen::AngleAxisf(tilt, Vec3f::UnitX()).toRotationMatrix();
    const float cy = 3.5f + 2.3f * float(r) + jit(0.1f);
    const float cx = -4.5f + jit(0.2f);
    const float cz = 0.5f + row.panel.half.y() * std::sin(tilt);
    row.panel.c = Vec3f(cx, cy, cz);
    // Legs under the low and the high edge, at both ends of the row.
    int k = 0;
    for (float sx : {-1.f, 1.f})
      for (float sy : {-1.f, 1.f}) {
        const Vec3f top = row.panel.c + row.panel.axes * Vec3f(sx * 1.9f, sy * 0.45f, -row.panel.half.z());
        Box leg;
        leg.half = Vec3f(0.03f, 0.03f, 0.5f * top.z());
        leg.c = Vec3f(top.x(), top.y(), 0.5f * top.z());
        row.legs[static_cast<std::size_t>(k++)] = leg;
      }
    row.bound = Sphere{row.panel.c, row.panel.half.norm() + 0.6f};
    s.panels.push_back(row);
  }

  // Trees at fixed spots around the features, each with seeded size, shape and vigour.
  const std::array<std::array<float, 3>, 8> spots = {{{3.5f, 4.0f, 1.6f}, {7.0f, 1.5f, 1.3f}, {0.5f, 7.5f, 1.5f},
                                                      {-0.5f, -8.0f, 1.4f}, {8.0f, -7.5f, 1.5f}, {-9.0f, -0.5f, 1.6f},
                                                      {1.0f, 0.8f, 1.1f}, {-8.5f, 8.5f, 1.4f}}};
  for (std::size_t i = 0; i < spots.size(); ++i) {
    Tree t;
    t.seed = hash_tuple(seed, 0x7EEULL, i);
    const float R = spots[i][2] * float(rng.uniform(0.9, 1.15));
    const Vec2f c(spots[i][0] + jit(0.5f), spots[i][1] + jit(0.5f));
    const float trunk_h = float(rng.uniform(1.2, 2.0));
    t.trunk = VCylinder{Vec3f(c.x(), c.y(), 0.f), float(rng.uniform(0.12, 0.2)), trunk_h + 0.6f * R};
    const Vec3f crown_c(c.x(), c.y(), trunk_h + 0.8f * R);
    t.crown.push_back(Sphere{crown_c, 0.8f * R});
    const int lobes = 4 + int(rng.below(3));
    for (int l = 0; l < lobes; ++l) {
      const float az = 2.f * pi * (float(l) + float(rng.uniform(-0.3, 0.3))) / float(lobes);
      const float el = float(rng.uniform(-0.4, 0.7));
      const Vec3f dir(std::cos(az) * std::cos(el), std::sin(az) * std::cos(el), std::sin(el));
      t.crown.push_back(Sphere{crown_c + 0.55f * R * dir, R * float(rng.uniform(0.45, 0.65))});
    }
    // One clearly stressed tree so NIR-only contrast exists between trees too.
    t.vigour = i == 2 ? 0.2f : float(rng.uniform(0.55, 1.0));
    float br = 0.f;
    const Vec3f mid(c.x(), c.y(), 0.5f * (trunk_h + 1.8f * R));
    for (const auto& sp : t.crown) br = std::max(br, (sp.c - mid).norm() + sp.r);
    br = std::max(br, (t.trunk.base - mid).norm() + t.trunk.r);
    t.bound = Sphere{mid, br + 1e-3f};
    s.trees.push_back(t);
  }

  // Sun to the south-south-west at about 52 degrees elevation.
  const float el = (52.f + jit(4.f)) * pi / 180.f, az = (235.f + jit(10.f)) * pi / 180.f;
  s.sun_dir = Vec3f(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  s.sun = {1.00f, 1.00f, 1.00f, 1.00f, 1.00f, 1.00f, 1.00f};
  s.sky = {0.17f, 0.21f, 0.30f, 0.21f, 0.18f, 0.15f, 0.13f};
  s.sky_zenith = {0.30f, 0.45f, 0.80f, 0.45f, 0.30f, 0.22f, 0.18f};
  s.sky_horizon = {0.70f, 0.75f, 0.82f, 0.74f, 0.70f, 0.62f, 0.55f};

  s.captures = make_flight(preset, seed);
  return s;
}

/// make_scene by preset name ("tiny", "small", "medium").
inline SynthScene make_scene(std::string_view preset, std::uint64_t seed) {
  return make_scene(synth_preset(preset), seed);
}

namespace detail {
inline void take(RayHit& h, const PrimHit& ph, Surface s, int object) {
  h.hit = true;
  h.t = ph.t;
  h.n = ph.n;
  h.local = ph.local;
  h.face = ph.face;
  h.surface = s;
  h.object = object;
}
}  // namespace detail

/// Nearest intersection of `ray` (unit direction) with the scene; `hit` is false for sky.
inline RayHit trace(const SynthScene& s, const Ray& ray) {
  RayHit h;
  PrimHit ph;
  if (intersect_ground(ray, ph)) detail::take(h, ph, Surface::Ground, -1);
  if (intersect(s.pond, ray, ph)) detail::take(h, ph, Surface::Pond, -1);
  for (std::size_t i = 0; i < s.trees.size(); ++i) {
    const Tree& t = s.trees[i];
    if (!touches(t.bound, ray, ph.t)) continue;
    if (intersect(t.trunk, ray, ph)) detail::take(h, ph, Surface::Trunk, int(i));
    for (const auto& sp : t.crown)
      if (intersect(sp, ray, ph)) detail::take(h, ph, Surface::Crown, int(i));
  }
  for (std::size_t i = 0; i < s.panels.size(); ++i) {
    const PanelRow& r = s.panels[i];
    if (!touches(r.bound, ray, ph.t)) continue;
    if (intersect(r.panel, ray, ph)) detail::take(h, ph, Surface::Panel, int(i));
    for (const auto& leg : r.legs)
      if (intersect(leg, ray, ph)) detail::take(h, ph, Surface::PanelLeg, int(i));
  }
  if (h.hit) {
    h.p = ray.o + h.t * ray.d;
    if (h.n.dot(ray.d) > 0.f) h.n = -h.n;  // seen from inside (shadow rays leaving a crown)
  }
  return h;
}

/// Radiance of the sky in direction d (brighter towards the horizon).
inline Spectrum sky_radiance(const SynthScene& s, const Vec3f& d) {
  const float up = std::clamp(d.z(), 0.f, 1.f);
  return mix(s.sky_horizon, s.sky_zenith, std::sqrt(up));
}

namespace detail {

/// Leaf-vigour modulation: strong in red edge and NIR, barely visible in RGB, G and R.
inline Spectrum apply_vigour(const Spectrum& a, float v) {
  Spectrum r = a;
  const float vis = 1.f + 0.06f * (0.5f - v);
  for (int i = 0; i < 5; ++i) r[static_cast<std::size_t>(i)] *= vis;
  r[5] *= 0.65f + 0.7f * v;
  r[6] *= 0.55f + 0.9f * v;
  return r;
}

inline bool in_pad(const Pad& pad, float x, float y, float& u, float& v) {
  const float dx = x - pad.c.x(), dy = y - pad.c.y();
  const float c = std::cos(pad.angle), sn = std::sin(pad.angle);
  u = c * dx + sn * dy;
  v = -sn * dx + c * dy;
  return std::abs(u) <= pad.half.x() && std::abs(v) <= pad.half.y();
}

inline Spectrum pad_albedo(const SynthScene& s, float u, float v) {
  const Pad& pad = s.pad;
  const float edge = std::min(pad.half.x() - std::abs(u), pad.half.y() - std::abs(v));
  if (edge < 0.15f) return spectra::paint_white;
  const float cell = 0.7f, gap = 0.08f;
  const float fu = u + pad.half.x(), fv = v + pad.half.y();
  const float mu = std::fmod(fu, cell), mv = std::fmod(fv, cell);
  const float tex = 0.92f + 0.16f * value_noise(u * 5.f, v * 5.f, hash_mix(s.seed, 0x9ADULL));
  if (mu < gap || mv < gap) return spectra::concrete * tex;
  static const std::array<Spectrum, 6> palette = {spectra::paint_red, spectra::paint_blue, spectra::paint_yellow,
                                                  spectra::paint_white, spectra::paint_black, spectra::concrete};
  const auto k = hash_tuple(s.seed, 0xCE11ULL, int(fu / cell), int(fv / cell)) % palette.size();
  // Paint is fresh and uniform; the concrete keeps its texture.
  return palette[k] == spectra::concrete ? spectra::concrete * tex : palette[k];
}

inline float segment_distance(const PaintLine& l, float x, float y) {
  const Vec2f p(x, y), ab = l.b - l.a;
  const float t = std::clamp((p - l.a).dot(ab) / ab.squaredNorm(), 0.f, 1.f);
  return (p - (l.a + t * ab)).norm();
}

}  // namespace detail

/// Reflectance of the ground at (x, y): grass/soil mixture, dry and wet soil patches, a muddy
/// ring round the pond, the painted pad and the painted line.
inline Spectrum ground_albedo(const SynthScene& s, float x, float y) {
  float u = 0.f, v = 0.f;
  if (detail::in_pad(s.pad, x, y, u, v)) return detail::pad_albedo(s, u, v);
  const std::uint64_t sd = s.seed;
  float grass = smoothstep(0.32f, 0.55f, fbm(x * 0.12f, y * 0.12f, 4, hash_mix(sd, 1)));
  float wet = smoothstep(0.55f, 0.72f, fbm(x * 0.2f, y * 0.2f, 3, hash_mix(sd, 2)));
  const float dpond = std::hypot(x - s.pond.c.x(), y - s.pond.c.y()) - s.pond.r;
  wet = std::max(wet, 1.f - smoothstep(0.f, 1.2f, dpond));
  grass *= smoothstep(0.3f, 1.4f, dpond);
  const Spectrum soil = mix(spectra::dry_soil, spectra::wet_soil, wet) *
                        (0.85f + 0.3f * value_noise(x * 3.f, y * 3.f, hash_mix(sd, 3)));
  const float vig = fbm(x * 0.35f, y * 0.35f, 3, hash_mix(sd, 4));
  const Spectrum lawn = detail::apply_vigour(spectra::grass, vig) *
                        (0.8f + 0.4f * value_noise(x * 6.f, y * 6.f, hash_mix(sd, 5)));
  Spectrum a = mix(soil, lawn, grass);
  if (detail::segment_distance(s.line, x, y) < s.line.half_width) a = spectra::line_paint;
  return a;
}

/// Reflectance at a hit point (before lighting).
inline Spectrum albedo(const SynthScene& s, const RayHit& h) {
  switch (h.surface) {
    case Surface::Ground: return ground_albedo(s, h.p.x(), h.p.y());
    case Surface::Pond: return spectra::water;
    case Surface::Crown: {
      const Tree& t = s.trees[static_cast<std::size_t>(h.object)];
      const Vec3f& p = h.p;
      // Leaf clumps: brightness texture seen in every band.
      const float clump = 0.7f + 0.6f * fbm(p.x() * 4.f, p.y() * 4.f, p.z() * 4.f, 3, hash_mix(t.seed, 1));
      // Vigour: broad patches on the crown around the tree's own level.
      const float v = std::clamp(
          t.vigour + 0.7f * (fbm(p.x() * 0.9f, p.y() * 0.9f, p.z() * 0.9f, 2, hash_mix(t.seed, 2)) - 0.5f), 0.f, 1.f);
      return detail::apply_vigour(spectra::leaves, v) * clump;
    }
    case Surface::Trunk: {
      const Tree& t = s.trees[static_cast<std::size_t>(h.object)];
      return spectra::bark * (0.8f + 0.4f * value_noise(h.local.x() * 3.f, h.local.y() * 6.f, hash_mix(t.seed, 3)));
    }
    case Surface::Panel: {
      const PanelRow& r = s.panels[static_cast<std::size_t>(h.object)];
      if (h.face == 4) return spectra::backsheet;
      if (h.face != 5) return spectra::aluminium;
      const float hx = r.panel.half.x(), hy = r.panel.half.y();
      const float u = h.local.x() + hx, v = h.local.y() + hy;
      if (u < 0.04f || u > 2.f * hx - 0.04f || v < 0.04f || v > 2.f * hy - 0.04f) return spectra::aluminium;
      const float modw = 2.f * hx / float(r.modules);
      const float m = std::fmod(u, modw);
      if (m < 0.025f || m > modw - 0.025f) return spectra::aluminium;
      const float pitch = 0.156f;
      if (std::fmod(m, pitch) < 0.012f || std::fmod(v, pitch) < 0.012f)
        return mix(spectra::panel_glass, spectra::aluminium, 0.5f);
      return spectra::panel_glass;
    }
    case Surface::PanelLeg: return spectra::aluminium;
    case Surface::None: break;
  }
  return Spectrum{};
}

/// Is the segment from p towards direction d blocked within distance tmax?
inline bool occluded(const SynthScene& s, const Vec3f& p, const Vec3f& d, float tmax = 1e30f) {
  Ray r;
  r.o = p;
  r.d = d;
  r.tmin = 1e-4f;
  r.tmax = tmax;
  return trace(s, r).hit;
}

/// Radiance leaving a hit towards the ray origin: Lambertian under sun (with shadows) and sky,
/// plus a Fresnel sky reflection on water and glass (the view-dependent part).
inline Spectrum shade(const SynthScene& s, const Ray& ray, const RayHit& h) {
  if (!h.hit) return sky_radiance(s, ray.d);
  Vec3f n = h.n;
  if (h.surface == Surface::Crown) {
    // Leafy crowns scatter light in many directions: a noisy shading normal breaks the spheres up.
    const Tree& t = s.trees[static_cast<std::size_t>(h.object)];
    const Vec3f q = h.p * 3.f;
    const Vec3f jitter(value_noise(q.x(), q.y(), q.z(), hash_mix(t.seed, 11)) - 0.5f,
                       value_noise(q.x(), q.y(), q.z(), hash_mix(t.seed, 12)) - 0.5f,
                       value_noise(q.x(), q.y(), q.z(), hash_mix(t.seed, 13)) - 0.5f);
    n = (n + 1.2f * jitter).normalized();
  }
  const Spectrum a = albedo(s, h);
  const float cos_sun = std::max(0.f, n.dot(s.sun_dir));
  const float lit = cos_sun > 0.f && h.n.dot(s.sun_dir) > -0.2f &&
                            !occluded(s, h.p + 2e-3f * h.n, s.sun_dir)
                        ? cos_sun
                        : 0.f;
  const float sky_view = 0.5f + 0.5f * n.z();
  Spectrum out;
  for (std::size_t i = 0; i < 7; ++i) out[i] = a[i] * (s.sun[i] * lit + s.sky[i] * sky_view);
  const bool glossy = h.surface == Surface::Pond || (h.surface == Surface::Panel && h.face == 5);
  if (glossy) {
    const float c = std::clamp(-ray.d.dot(h.n), 0.f, 1.f);
    const float f0 = h.surface == Surface::Pond ? 0.02f : 0.04f;
    const float fres = f0 + (1.f - f0) * std::pow(1.f - c, 5.f);
    const Vec3f refl = ray.d - 2.f * ray.d.dot(h.n) * h.n;
    out = out * (1.f - fres) + sky_radiance(s, refl) * fres;
  }
  return out;
}

}  // namespace msgs::synth
