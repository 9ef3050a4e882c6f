// tests/reference_renderer.hpp
// A slow, obviously correct Gaussian splatting renderer (per pixel, every Gaussian, no tiles) written
// straight from REFERENCE.md §6, plus seeded random scenes; the fast rasterizer is checked against it.
#pragma once

#include <msgs/camera.hpp>
#include <msgs/gaussian.hpp>
#include <msgs/image.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

namespace msgs::testing {

/// Real spherical-harmonics constants of 3DGS (degree 0..3), with their signs.
inline constexpr double kShC0 = 0.28209479177387814;
inline constexpr double kShC1 = 0.4886025119029199;
inline constexpr std::array<double, 5> kShC2 = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                                -1.0925484305920792, 0.5462742152960396};
inline constexpr std::array<double, 7> kShC3 = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                                                0.3731763325901154,  -0.4570457994644658, 1.445305721320277,
                                                -0.5900435899266435};

/// The (deg + 1)^2 SH basis values for unit direction d, in the coefficient order of 3DGS.
template <class T>
std::vector<T> reference_sh_basis(int deg, const Eigen::Matrix<T, 3, 1>& d) {
  const T x = d.x(), y = d.y(), z = d.z();
  std::vector<T> b;
  b.push_back(T(kShC0));
  if (deg >= 1) {
    b.push_back(-T(kShC1) * y);
    b.push_back(T(kShC1) * z);
    b.push_back(-T(kShC1) * x);
  }
  if (deg >= 2) {
    const T xx = x * x, yy = y * y, zz = z * z;
    b.push_back(T(kShC2[0]) * x * y);
    b.push_back(T(kShC2[1]) * y * z);
    b.push_back(T(kShC2[2]) * (T(2) * zz - xx - yy));
    b.push_back(T(kShC2[3]) * x * z);
    b.push_back(T(kShC2[4]) * (xx - yy));
  }
  if (deg >= 3) {
    const T xx = x * x, yy = y * y, zz = z * z;
    b.push_back(T(kShC3[0]) * y * (T(3) * xx - yy));
    b.push_back(T(kShC3[1]) * x * y * z);
    b.push_back(T(kShC3[2]) * y * (T(4) * zz - xx - yy));
    b.push_back(T(kShC3[3]) * z * (T(2) * zz - T(3) * xx - T(3) * yy));
    b.push_back(T(kShC3[4]) * x * (T(4) * zz - xx - yy));
    b.push_back(T(kShC3[5]) * z * (xx - yy));
    b.push_back(T(kShC3[6]) * x * (xx - T(3) * yy));
  }
  return b;
}

/// What to render; mirrors msgs::RenderSettings and RasterOptions but is defined here so the
/// reference does not depend on the code it checks.
struct ReferenceSettings {
  int band_first = 0;              ///< first model channel rendered
  int band_count = -1;             ///< -1: all channels from band_first
  int sh_degree = -1;              ///< active SH degree, -1: the model's
  std::vector<double> background;  ///< empty: 0; one value: broadcast; else band_count values
  bool depth = false;              ///< also accumulate sum_i w_i z_i
  bool antialiased = false;        ///< opacity x sqrt(det cov2d / det(cov2d + 0.3 I))
  double quat_eps = 1e-16;         ///< squared quaternion norm below which a Gaussian is culled (REFERENCE §7)
  double compensation_floor = 0.005;  ///< lower bound of the antialiasing compensation factor (§6)
};

/// Per-Gaussian intermediate values of the reference, exposed so tests can probe single terms.
template <class T>
struct ReferenceSplat {
  bool culled = true;
  T z = 0;                              ///< camera-space depth
  Eigen::Matrix<T, 2, 1> mean2d;        ///< projected mean, pixels
  Eigen::Matrix<T, 2, 2> cov2d;         ///< screen covariance including + 0.3 I
  T conic_a = 0, conic_b = 0, conic_c = 0;
  T opacity = 0;                        ///< sigmoid(logit), times the compensation when antialiased
  std::vector<T> colour;                ///< [band_count], SH . basis + 0.5 clamped at 0
};

/// Outputs of the reference renderer, all in scalar T.
template <class T>
struct ReferenceResult {
  Image<T> image;                        ///< [H, W, band_count]
  Image<T> alpha;                        ///< [H, W, 1]
  Image<T> depth;                        ///< [H, W, 1] (zeros unless settings.depth)
  std::vector<ReferenceSplat<T>> splats; ///< [N]
  std::size_t fragments = 0;             ///< blended pixel-Gaussian pairs
};

template <class S>
bool reference_all_finite(const S* p, int n) {
  for (int k = 0; k < n; ++k)
    if (!std::isfinite(static_cast<double>(p[k]))) return false;
  return true;
}

/// Every SH coefficient of Gaussian i, all bands, finite.
template <class G, class S>
bool sh_finite(const GaussianModel<G, S>& model, std::size_t i) {
  for (int c = 0; c < G::bands; ++c)
    if (!reference_all_finite(model.sh_row(i, c), G::sh_coeffs)) return false;
  return true;
}

/// Project Gaussian i of `model` for `cam` in scalar T, applying the culling rules of §6:
/// non-finite parameters, quaternion norm ~ 0, z <= near or z > far, opacity < 1/255.
template <class T, class G, class S>
ReferenceSplat<T> reference_project(const GaussianModel<G, S>& model, const Camera<S>& cam_s, std::size_t i,
                                    int band_first, int band_count, int sh_degree, const ReferenceSettings& rs) {
  using Vec3 = Eigen::Matrix<T, 3, 1>;
  using Mat3 = Eigen::Matrix<T, 3, 3>;
  using Mat2 = Eigen::Matrix<T, 2, 2>;
  ReferenceSplat<T> s;
  const Camera<T> cam = cam_s.template cast<T>();
  if (!reference_all_finite(&model.means[3 * i], 3) || !reference_all_finite(&model.log_scales[3 * i], 3) ||
      !reference_all_finite(&model.quats[4 * i], 4) || !reference_all_finite(&model.opacity_logits[i], 1) ||
      !sh_finite(model, i))
    return s;

  const Vec3 mean(T(model.means[3 * i]), T(model.means[3 * i + 1]), T(model.means[3 * i + 2]));
  const T qw = T(model.quats[4 * i]), qx = T(model.quats[4 * i + 1]), qy = T(model.quats[4 * i + 2]),
          qz = T(model.quats[4 * i + 3]);
  if (qw * qw + qx * qx + qy * qy + qz * qz < T(rs.quat_eps)) return s;
  const T opacity_raw = T(1) / (T(1) + std::exp(-T(model.opacity_logits[i])));
  if (opacity_raw < T(1) / T(255)) return s;

  const Vec3 pc = cam.R * mean + cam.t;
  if (pc.z() <= cam.near_plane || pc.z() > cam.far_plane) return s;

  // Sigma = R S S^T R^T with R from the normalised quaternion.
  const Mat3 rot = Eigen::Quaternion<T>(qw, qx, qy, qz).normalized().toRotationMatrix();
  const Vec3 scale(std::exp(T(model.log_scales[3 * i])), std::exp(T(model.log_scales[3 * i + 1])),
                   std::exp(T(model.log_scales[3 * i + 2])));
  const Mat3 m = rot * scale.asDiagonal();
  const Mat3 sigma_world = m * m.transpose();
  const Mat3 sigma_cam = cam.R * sigma_world * cam.R.transpose();

  // EWA Jacobian of the perspective projection, evaluated at a point whose x/z, y/z are clamped
  // to a little beyond the field of view (3DGS) so far off-screen Gaussians do not explode.
  const T z = pc.z();
  const T tan_fovx = T(0.5) * T(cam.width) / cam.fx, tan_fovy = T(0.5) * T(cam.height) / cam.fy;
  const T lim_x_pos = (T(cam.width) - cam.cx) / cam.fx + T(0.3) * tan_fovx;
  const T lim_x_neg = cam.cx / cam.fx + T(0.3) * tan_fovx;
  const T lim_y_pos = (T(cam.height) - cam.cy) / cam.fy + T(0.3) * tan_fovy;
  const T lim_y_neg = cam.cy / cam.fy + T(0.3) * tan_fovy;
  const T tx = z * std::min(lim_x_pos, std::max(-lim_x_neg, pc.x() / z));
  const T ty = z * std::min(lim_y_pos, std::max(-lim_y_neg, pc.y() / z));
  Eigen::Matrix<T, 2, 3> jac;
  jac << cam.fx / z, T(0), -cam.fx * tx / (z * z), T(0), cam.fy / z, -cam.fy * ty / (z * z);
  Mat2 cov = jac * sigma_cam * jac.transpose();
  const T det_raw = cov.determinant();
  cov += T(0.3) * Mat2::Identity();
  const T det = cov.determinant();

  T opacity = opacity_raw;
  if (rs.antialiased)
    opacity *= std::max(T(rs.compensation_floor), std::sqrt(std::max(T(0), det_raw / det)));

  const Mat2 conic = cov.inverse();
  s.z = z;
  s.mean2d = Eigen::Matrix<T, 2, 1>(cam.fx * pc.x() / z + cam.cx, cam.fy * pc.y() / z + cam.cy);
  s.cov2d = cov;
  s.conic_a = conic(0, 0);
  s.conic_b = conic(0, 1);
  s.conic_c = conic(1, 1);
  s.opacity = opacity;

  // View-dependent colour: direction from the camera centre to the mean.
  const Vec3 dir = (mean - cam.position()).normalized();
  const std::vector<T> basis = reference_sh_basis<T>(sh_degree, dir);
  s.colour.assign(static_cast<std::size_t>(band_count), T(0));
  for (int c = 0; c < band_count; ++c) {
    T v = T(0.5);
    for (std::size_t k = 0; k < basis.size(); ++k)
      v += basis[k] * T(model.sh_at(i, static_cast<int>(k), band_first + c));
    s.colour[static_cast<std::size_t>(c)] = std::max(T(0), v);
  }
  s.culled = false;
  return s;
}

/// Render `model` through `cam` the slow way: for every pixel, blend every unculled Gaussian in
/// front-to-back order of camera z (ties by index).
template <class T, class G, class S>
ReferenceResult<T> reference_render(const GaussianModel<G, S>& model, const Camera<S>& cam,
                                    const ReferenceSettings& rs = {}) {
  const int band_first = rs.band_first;
  const int band_count = rs.band_count < 0 ? G::bands - band_first : rs.band_count;
  const int sh_degree = rs.sh_degree < 0 ? G::sh_degree : rs.sh_degree;
  const std::size_t n = model.size();

  ReferenceResult<T> out;
  out.splats.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    out.splats.push_back(reference_project<T>(model, cam, i, band_first, band_count, sh_degree, rs));

  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < n; ++i)
    if (!out.splats[i].culled) order.push_back(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return out.splats[a].z < out.splats[b].z; });

  std::vector<T> bg(static_cast<std::size_t>(band_count), T(0));
  for (int c = 0; c < band_count; ++c) {
    if (rs.background.size() == 1) bg[static_cast<std::size_t>(c)] = T(rs.background[0]);
    else if (!rs.background.empty()) bg[static_cast<std::size_t>(c)] = T(rs.background[static_cast<std::size_t>(c)]);
  }

  out.image.reset(cam.width, cam.height, band_count);
  out.alpha.reset(cam.width, cam.height, 1);
  out.depth.reset(cam.width, cam.height, 1);
  for (int py = 0; py < cam.height; ++py) {
    for (int px = 0; px < cam.width; ++px) {
      const T u = T(px) + T(0.5), v = T(py) + T(0.5);
      T trans = 1, depth = 0;
      std::vector<T> colour(static_cast<std::size_t>(band_count), T(0));
      for (std::size_t i : order) {
        const ReferenceSplat<T>& s = out.splats[i];
        const T dx = u - s.mean2d.x(), dy = v - s.mean2d.y();
        const T sigma = T(0.5) * (s.conic_a * dx * dx + s.conic_c * dy * dy) + s.conic_b * dx * dy;
        if (sigma < T(0)) continue;
        const T alpha = std::min(T(0.99), s.opacity * std::exp(-sigma));
        if (alpha < T(1) / T(255)) continue;
        const T next = trans * (T(1) - alpha);
        if (next <= T(1e-4)) break;
        const T w = alpha * trans;
        for (int c = 0; c < band_count; ++c) colour[static_cast<std::size_t>(c)] += w * s.colour[static_cast<std::size_t>(c)];
        depth += w * s.z;
        trans = next;
        ++out.fragments;
      }
      for (int c = 0; c < band_count; ++c)
        out.image.at(px, py, c) = colour[static_cast<std::size_t>(c)] + trans * bg[static_cast<std::size_t>(c)];
      out.alpha.at(px, py, 0) = T(1) - trans;
      if (rs.depth) out.depth.at(px, py, 0) = depth;
    }
  }
  return out;
}

// ---- seeded random scenes ----

/// Knobs for random_scene: Gaussians whose centres project into (a margin around) the image.
struct SceneParams {
  std::size_t n = 100;
  double z_min = 2, z_max = 6;             ///< camera-space depth range
  double margin_px = 8;                    ///< centres may project this far outside the image
  double log_scale_min = std::log(0.03), log_scale_max = std::log(0.25);
  double opacity_min = 0.05, opacity_max = 0.95;
  double colour_min = 0.0, colour_max = 1.0;  ///< DC colour range (before higher orders)
  double sh_rest = 0.1;                    ///< higher-order SH coefficients uniform in +-sh_rest
};

/// A camera with an off-centre principal point and a generic (non-identity) pose.
template <class S>
Camera<S> test_camera(int width, int height, double cx, double cy, double f = 45.0) {
  Camera<S> cam;
  cam.width = width;
  cam.height = height;
  cam.fx = S(f);
  cam.fy = S(f * 1.1);
  cam.cx = S(cx);
  cam.cy = S(cy);
  const Eigen::Matrix<double, 3, 3> rot =
      (Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1.0, -0.4).normalized())).toRotationMatrix();
  cam.R = rot.cast<S>();
  cam.t = Eigen::Matrix<S, 3, 1>(S(0.4), S(-0.2), S(0.7));
  return cam;
}

/// Uniform random unit quaternion (Shoemake), stored w, x, y, z.
inline std::array<double, 4> random_unit_quat(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double u1 = u(rng), u2 = u(rng), u3 = u(rng);
  const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
  const double pi2 = 2 * 3.14159265358979323846;
  return {a * std::sin(pi2 * u2), a * std::cos(pi2 * u2), b * std::sin(pi2 * u3), b * std::cos(pi2 * u3)};
}

/// N random Gaussians in front of `cam` (seeded, identical for float and double).
template <class G, class S>
GaussianModel<G, S> random_scene(const Camera<S>& cam, const SceneParams& p, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto uni = [&](double lo, double hi) { return lo + (hi - lo) * u(rng); };
  const Camera<double> c = cam.template cast<double>();
  GaussianModel<G, S> m(p.n);
  for (std::size_t i = 0; i < p.n; ++i) {
    const double px = uni(-p.margin_px, c.width + p.margin_px), py = uni(-p.margin_px, c.height + p.margin_px);
    const double z = uni(p.z_min, p.z_max);
    const Eigen::Vector3d pc((px - c.cx) / c.fx * z, (py - c.cy) / c.fy * z, z);
    const Eigen::Vector3d w = c.R.transpose() * (pc - c.t);
    for (int k = 0; k < 3; ++k) m.means[3 * i + k] = S(w[k]);
    for (int k = 0; k < 3; ++k) m.log_scales[3 * i + k] = S(uni(p.log_scale_min, p.log_scale_max));
    const auto q = random_unit_quat(rng);
    // Not normalised on purpose: the renderer must normalise.
    const double qs = uni(0.5, 2.0);
    for (int k = 0; k < 4; ++k) m.quats[4 * i + k] = S(q[static_cast<std::size_t>(k)] * qs);
    const double o = uni(p.opacity_min, p.opacity_max);
    m.opacity_logits[i] = S(std::log(o / (1 - o)));
    for (int ch = 0; ch < G::bands; ++ch) {
      m.sh_at(i, 0, ch) = S((uni(p.colour_min, p.colour_max) - 0.5) / kShC0);
      for (int k = 1; k < G::sh_coeffs; ++k) m.sh_at(i, k, ch) = S(uni(-p.sh_rest, p.sh_rest));
    }
  }
  return m;
}

/// Row i of `to` := row j of `from`.
template <class G, class S>
void copy_row(const GaussianModel<G, S>& from, std::size_t j, GaussianModel<G, S>& to, std::size_t i) {
  for (int a = 0; a < 3; ++a) {
    to.means[3 * i + a] = from.means[3 * j + a];
    to.log_scales[3 * i + a] = from.log_scales[3 * j + a];
  }
  for (int a = 0; a < 4; ++a) to.quats[4 * i + a] = from.quats[4 * j + a];
  to.opacity_logits[i] = from.opacity_logits[j];
  for (int c = 0; c < G::bands; ++c)
    for (int k = 0; k < G::sh_coeffs; ++k) to.sh_at(i, k, c) = from.sh_at(j, k, c);
}

/// `m` with its rows moved: row i of the result is row row_of(i) of m (row_of a permutation).
template <class G, class S, class RowOf>
GaussianModel<G, S> rows_moved(const GaussianModel<G, S>& m, RowOf&& row_of) {
  GaussianModel<G, S> r(m.size());
  for (std::size_t i = 0; i < m.size(); ++i) copy_row(m, row_of(i), r, i);
  return r;
}

/// Convert a model to another scalar type.
template <class T, class G, class S>
GaussianModel<G, T> cast_model(const GaussianModel<G, S>& m) {
  GaussianModel<G, T> r(m.size());
  auto cp = [](const std::vector<S>& a, std::vector<T>& b) {
    for (std::size_t k = 0; k < a.size(); ++k) b[k] = T(a[k]);
  };
  cp(m.means, r.means);
  cp(m.log_scales, r.log_scales);
  cp(m.quats, r.quats);
  cp(m.opacity_logits, r.opacity_logits);
  cp(m.sh, r.sh);
  return r;
}

/// Largest |a - b| over two equally sized buffers (infinity when sizes differ or a value is NaN).
template <class A, class B>
double max_abs_diff(const std::vector<A>& a, const std::vector<B>& b) {
  if (a.size() != b.size()) return INFINITY;
  double m = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    const double d = std::abs(static_cast<double>(a[k]) - static_cast<double>(b[k]));
    if (!(d <= m)) m = std::isnan(d) ? INFINITY : d;
  }
  return m;
}

/// True when every value is finite.
template <class S>
bool all_finite(const std::vector<S>& v) {
  return std::all_of(v.begin(), v.end(), [](S x) { return std::isfinite(static_cast<double>(x)); });
}

}  // namespace msgs::testing
