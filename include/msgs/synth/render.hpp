// include/msgs/synth/render.hpp
// Rendering of one band's image by CPU ray tracing (OpenMP over rows, jittered antialiasing that is
// deterministic per pixel) and the sparse point cloud sampled on the traced geometry.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "../camera.hpp"
#include "../image.hpp"
#include "noise.hpp"
#include "scene.hpp"

namespace msgs::synth {

/// World-space ray through the continuous pixel position (u, v) of a camera (pixel centres at
/// i + 0.5), following camera.hpp: a camera point (x, y, z) lands at (fx x/z + cx, fy y/z + cy).
inline Ray camera_ray(const Camera<float>& cam, float u, float v) {
  const Vec3f dc((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.f);
  Ray r;
  r.o = cam.position();
  r.d = (cam.R.transpose() * dc).normalized();
  r.tmin = 1e-4f;
  return r;
}

/// Options of render_band.
struct RenderSettings {
  int aa = 2;                  ///< jittered samples per pixel along each axis (aa^2 rays)
  std::uint64_t jitter_seed = 0;  ///< varies the sub-pixel pattern between images
};

/// Jitter seed of the image of band `b` in capture `capture` of a dataset generated with `seed`.
inline std::uint64_t frame_jitter_seed(std::uint64_t seed, int capture, Band b) {
  return hash_tuple(seed, 0x1A6EULL, capture, static_cast<int>(b));
}

/// Pixel value a band's camera records for a radiance: the RGB camera writes sRGB-encoded values
/// (as a JPEG would), the multispectral cameras linear values; both clamped to [0, 1].
inline float band_value(const Spectrum& radiance, Band b, int channel) {
  const float v = radiance[static_cast<std::size_t>(band_offset(b) + channel)];
  if (b == Band::D) return srgb_encode(v);
  return std::clamp(v, 0.f, 1.f);
}

/// Radiance of pixel (x, y): the mean over rs.aa x rs.aa jittered rays, the jitter a hash of
/// (rs.jitter_seed, x, y, sample), accumulated per spectrum channel in float in sample order.
inline Spectrum pixel_spectrum(const SynthScene& s, const Camera<float>& cam, int x, int y, const RenderSettings& rs) {
  const int aa = std::max(1, rs.aa);
  Spectrum acc{};
  for (int sy = 0; sy < aa; ++sy)
    for (int sx = 0; sx < aa; ++sx) {
      const std::uint64_t h = hash_tuple(rs.jitter_seed, x, y, sx, sy);
      const float jx = (float(sx) + hash_to_unit(h)) / float(aa);
      const float jy = (float(sy) + hash_to_unit(splitmix64(h))) / float(aa);
      const Ray ray = camera_ray(cam, float(x) + jx, float(y) + jy);
      const Spectrum L = shade(s, ray, trace(s, ray));
      for (std::size_t c = 0; c < acc.size(); ++c) acc[c] += L[c];
    }
  const float inv = 1.f / float(aa * aa);
  for (float& v : acc) v *= inv;
  return acc;
}

/// Ray-trace one band's image with `cam` ([H, W, C], C = band_channels(b)). Averaging happens in
/// linear radiance before the sRGB encoding, like a real sensor. Every pixel seeds its own
/// jitter from (seed, x, y), so the result does not depend on the thread count.
inline Image<float> render_band(const SynthScene& s, const Camera<float>& cam, Band b,
                                const RenderSettings& rs = {}) {
  cam.validate();
  const int C = band_channels(b);
  Image<float> img(cam.width, cam.height, C);
#pragma omp parallel for schedule(dynamic, 1)
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Spectrum mean = pixel_spectrum(s, cam, x, y, rs);
      for (int c = 0; c < C; ++c) img.at(x, y, c) = band_value(mean, b, c);
    }
  }
  return img;
}

/// Sparse point cloud in the style of the published data: points on visible surfaces (as SfM
/// would find them), perturbed by noise, plus uniform outliers; colours are a mix of RGB and
/// grey (a multispectral band's value), which is why they make a poor colour initialisation.
struct SparsePoints {
  std::vector<float> clean;             ///< [N, 3] exact surface points (outliers: same as positions)
  std::vector<float> positions;         ///< [N, 3] what is written: clean + noise, or an outlier
  std::vector<std::uint8_t> colors;     ///< [N, 3] 8-bit colours
  std::vector<std::uint8_t> outlier;    ///< [N]    1 for an outlier
  std::vector<std::int32_t> capture;    ///< [N]    capture whose RGB camera found the point (-1 outliers)
  std::size_t size() const { return outlier.size(); }
};

/// Sample `count` points: ~95 % as hits of rays through random pixels of the RGB cameras of the
/// listed captures (noise sigma 0.5 % of the viewing distance), ~5 % uniform outliers in the
/// scene's box. Deterministic in `seed`.
inline SparsePoints sample_sparse_points(const SynthScene& s, const std::vector<int>& capture_ids, int count,
                                         std::uint64_t seed) {
  SparsePoints pts;
  if (count <= 0 || capture_ids.empty()) return pts;
  Rng rng(hash_mix(seed, 0x5BA75EULL));
  auto to8 = [](float v) { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.f, 1.f) * 255.f)); };
  const int n_out = count / 20;
  int guard = 0;
  while (int(pts.size()) < count - n_out && guard++ < 50 * count) {
    const int ci = capture_ids[rng.below(capture_ids.size())];
    const Camera<float>& cam = s.captures[static_cast<std::size_t>(ci)].cameras[0];
    const float u = float(rng.uniform(0.0, cam.width)), v = float(rng.uniform(0.0, cam.height));
    const Ray ray = camera_ray(cam, u, v);
    const RayHit h = trace(s, ray);
    if (!h.hit || h.t > 60.f) continue;  // SfM finds nothing on the sky or the far distance
    const Spectrum L = shade(s, ray, h);
    const float sigma = 0.005f * h.t;
    const Vec3f noisy = h.p + sigma * Vec3f(float(rng.normal()), float(rng.normal()), float(rng.normal()));
    std::uint8_t c3[3];
    if (rng.uniform() < 0.5) {
      for (int c = 0; c < 3; ++c) c3[c] = to8(band_value(L, Band::D, c));
    } else {
      const Band gb = all_bands[1 + rng.below(4)];
      c3[0] = c3[1] = c3[2] = to8(band_value(L, gb, 0));
    }
    for (int k = 0; k < 3; ++k) {
      pts.clean.push_back(h.p[k]);
      pts.positions.push_back(noisy[k]);
      pts.colors.push_back(c3[k]);
    }
    pts.outlier.push_back(0);
    pts.capture.push_back(ci);
  }
  for (int i = 0; i < n_out; ++i) {
    const Vec3f p(float(rng.uniform(-12.0, 12.0)), float(rng.uniform(-12.0, 12.0)), float(rng.uniform(-1.0, 8.0)));
    const bool grey = rng.uniform() < 0.5;
    const std::uint8_t g = static_cast<std::uint8_t>(rng.below(256));
    for (int k = 0; k < 3; ++k) {
      pts.clean.push_back(p[k]);
      pts.positions.push_back(p[k]);
      pts.colors.push_back(grey ? g : static_cast<std::uint8_t>(rng.below(256)));
    }
    pts.outlier.push_back(1);
    pts.capture.push_back(-1);
  }
  // Interleave outliers among inliers (a reader should not find them all at the end).
  for (std::size_t i = pts.size(); i > 1; --i) {
    const std::size_t j = rng.below(i);
    const std::size_t a = i - 1;
    if (a == j) continue;
    for (int k = 0; k < 3; ++k) {
      std::swap(pts.clean[3 * a + k], pts.clean[3 * j + k]);
      std::swap(pts.positions[3 * a + k], pts.positions[3 * j + k]);
      std::swap(pts.colors[3 * a + k], pts.colors[3 * j + k]);
    }
    std::swap(pts.outlier[a], pts.outlier[j]);
    std::swap(pts.capture[a], pts.capture[j]);
  }
  return pts;
}

}  // namespace msgs::synth
