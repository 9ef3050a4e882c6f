// bench/scene_family.hpp
// The seeded scene family every rasterizer benchmark uses, so numbers are comparable across runs,
// machines and band counts: one camera at the origin, Gaussians in a slab 3..5 units ahead.
#pragma once

#include <msgs/camera.hpp>
#include <msgs/gaussian.hpp>
#include <msgs/image.hpp>
#include <msgs/sh.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>

namespace msgs::bench {

/// One member of the family: N Gaussians rendered at width x height.
struct SceneSpec {
  std::size_t n = 10000;
  int width = 256, height = 256;
  std::uint64_t seed = 1;
  double sh_rest = 0.02;  ///< higher-order SH coefficients uniform in +-sh_rest
};

/// The family member of `n` Gaussians at width x height, default seed.
inline SceneSpec scene_spec(std::size_t n, int width, int height) {
  SceneSpec s;
  s.n = n;
  s.width = width;
  s.height = height;
  return s;
}

/// Camera at the origin looking down +z (R = I, t = 0), fx = fy = 0.8 W, principal point centred.
template <class S>
Camera<S> family_camera(const SceneSpec& spec) {
  Camera<S> cam;
  cam.width = spec.width;
  cam.height = spec.height;
  cam.fx = cam.fy = S(0.8 * spec.width);
  cam.cx = S(0.5 * spec.width);
  cam.cy = S(0.5 * spec.height);
  return cam;
}

/// The Gaussians: means uniform in x [-2, 2], y [-2H/W, 2H/W], z [3, 5]; log-scales uniform in
/// [log 0.005, log 0.05] per axis; uniform unit quaternions; opacity U(0.1, 0.9) stored as logits;
/// colours U(0, 1) as SH DC, higher orders small. Geometry and colour come from separate streams,
/// so models with different band counts share the same geometry for the same seed.
template <class G, class S>
GaussianModel<G, S> family_model(const SceneSpec& spec) {
  std::mt19937_64 geo(spec.seed), col(spec.seed ^ 0x9e3779b97f4a7c15ull);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto uni = [&](std::mt19937_64& rng, double lo, double hi) { return lo + (hi - lo) * u(rng); };
  const double aspect = double(spec.height) / double(spec.width);
  const double pi2 = 2 * 3.14159265358979323846;
  GaussianModel<G, S> m(spec.n);
  for (std::size_t i = 0; i < spec.n; ++i) {
    m.means[3 * i] = S(uni(geo, -2, 2));
    m.means[3 * i + 1] = S(uni(geo, -2 * aspect, 2 * aspect));
    m.means[3 * i + 2] = S(uni(geo, 3, 5));
    for (int k = 0; k < 3; ++k) m.log_scales[3 * i + std::size_t(k)] = S(uni(geo, std::log(0.005), std::log(0.05)));
    // Shoemake's uniform random rotation.
    const double u1 = u(geo), u2 = u(geo), u3 = u(geo);
    const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
    m.quats[4 * i] = S(a * std::sin(pi2 * u2));
    m.quats[4 * i + 1] = S(a * std::cos(pi2 * u2));
    m.quats[4 * i + 2] = S(b * std::sin(pi2 * u3));
    m.quats[4 * i + 3] = S(b * std::cos(pi2 * u3));
    const double o = uni(geo, 0.1, 0.9);
    m.opacity_logits[i] = S(std::log(o / (1 - o)));
    for (int c = 0; c < G::bands; ++c) {
      m.sh_at(i, 0, c) = S((u(col) - 0.5) / sh::C0);
      for (int k = 1; k < G::sh_coeffs; ++k) m.sh_at(i, k, c) = S(uni(col, -spec.sh_rest, spec.sh_rest));
    }
  }
  return m;
}

/// The fixed loss gradient dL/d(image): a seeded random field in [0, 1), [H, W, channels].
template <class S>
Image<S> family_image_grad(const SceneSpec& spec, int channels) {
  std::mt19937_64 rng(spec.seed + 17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Image<S> img(spec.width, spec.height, channels);
  for (S& v : img.data) v = S(u(rng));
  return img;
}

}  // namespace msgs::bench
