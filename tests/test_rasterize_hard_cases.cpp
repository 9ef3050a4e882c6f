// tests/test_rasterize_hard_cases.cpp
// Numerically hard inputs (REFERENCE §7): degenerate quaternions, extreme scales and opacities, the
// near plane, far off-screen splats, needles, NaN/Inf parameters, empty scenes, tiny images, crowded tiles.
// Built twice: as test_rasterize_hard_cases with the double-precision projection, and with
// MSGS_TEST_SINGLE_PRECISION as test_rasterize_hard_cases_single with the single-precision one (whose
// hard Gaussians go to double precision); the finite-difference checks always differentiate the
// double-precision rasteriser.
#include <doctest/doctest.h>

#include <msgs/rasterize.hpp>

#include "reference_renderer.hpp"

#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>

namespace test_rasterize_hard_cases {
using namespace msgs;
using namespace msgs::testing;

namespace {

#ifdef MSGS_TEST_SINGLE_PRECISION
constexpr bool kSingle = true;
#else
constexpr bool kSingle = false;
#endif
constexpr RasterOptions kDepth{.depth = true, .antialiased = false, .absgrad = true, .single_precision = kSingle};
constexpr RasterOptions kDepthDouble{.depth = true, .antialiased = false, .absgrad = true};

/// Tolerance against the reference: `f` for float models or a single-precision projection, else `d`.
template <class S>
constexpr double ref_tol(double f, double d) {
  return std::is_same_v<S, float> || kSingle ? f : d;
}

template <class S>
Image<S> weights(int w, int h, int c, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Image<S> img(w, h, c);
  for (S& v : img.data) v = S(u(rng));
  return img;
}

/// Camera at the origin looking down +z (R = I, t = 0): world coordinates are camera coordinates.
template <class S>
Camera<S> axis_camera(int w, int h, double f, double cx, double cy) {
  Camera<S> cam;
  cam.width = w;
  cam.height = h;
  cam.fx = S(f);
  cam.fy = S(f);
  cam.cx = S(cx);
  cam.cy = S(cy);
  return cam;
}

/// One Gaussian at camera-space `p` with isotropic log-scale, identity rotation, grey-ish colour.
template <class G, class S>
void set_gaussian(GaussianModel<G, S>& m, std::size_t i, double x, double y, double z, double log_scale,
                  double opacity_logit, double colour) {
  m.means[3 * i] = S(x);
  m.means[3 * i + 1] = S(y);
  m.means[3 * i + 2] = S(z);
  for (int k = 0; k < 3; ++k) m.log_scales[3 * i + static_cast<std::size_t>(k)] = S(log_scale);
  m.quats[4 * i] = S(1);
  m.quats[4 * i + 1] = m.quats[4 * i + 2] = m.quats[4 * i + 3] = S(0);
  m.opacity_logits[i] = S(opacity_logit);
  for (int c = 0; c < G::bands; ++c) {
    m.sh_at(i, 0, c) = S((colour + 0.1 * c - 0.5) / kShC0);
    for (int k = 1; k < G::sh_coeffs; ++k) m.sh_at(i, k, c) = S(0.02 * k);
  }
}

/// The model without the Gaussians in `drop`.
template <class G, class S>
GaussianModel<G, S> without(const GaussianModel<G, S>& m, const std::vector<std::size_t>& drop) {
  GaussianModel<G, S> r;
  for (std::size_t i = 0; i < m.size(); ++i) {
    if (std::find(drop.begin(), drop.end(), i) != drop.end()) continue;
    r.means.insert(r.means.end(), m.means.begin() + 3 * i, m.means.begin() + 3 * i + 3);
    r.log_scales.insert(r.log_scales.end(), m.log_scales.begin() + 3 * i, m.log_scales.begin() + 3 * i + 3);
    r.quats.insert(r.quats.end(), m.quats.begin() + 4 * i, m.quats.begin() + 4 * i + 4);
    r.opacity_logits.push_back(m.opacity_logits[i]);
  }
  // SH band planes: each plane keeps the same rows.
  r.sh.assign(r.size() * static_cast<std::size_t>(G::sh_floats), S(0));
  for (int c = 0; c < G::bands; ++c)
    for (std::size_t i = 0, j = 0; i < m.size(); ++i) {
      if (std::find(drop.begin(), drop.end(), i) != drop.end()) continue;
      std::copy_n(m.sh_row(i, c), G::sh_coeffs, r.sh_row(j++, c));
    }
  return r;
}

/// Forward + backward; every output and every gradient must be finite, alpha in [0, 1].
template <class G, class S, RasterOptions Opt = kDepth>
Gradients<G, S> render_finite(Rasterizer<G, S, Opt>& r, const GaussianModel<G, S>& m, const Camera<S>& cam,
                              const RenderSettings<S>& rs = {}) {
  r.forward(m, cam, rs);
  CHECK(all_finite(r.image().data));
  CHECK(all_finite(r.alpha().data));
  for (S a : r.alpha().data) REQUIRE((a >= S(0) && a <= S(1)));
  if constexpr (Opt.depth) CHECK(all_finite(r.depth().data));
  const Image<S> wi = weights<S>(cam.width, cam.height, r.image().channels, 1);
  const Image<S> wa = weights<S>(cam.width, cam.height, 1, 2);
  const Image<S> wd = weights<S>(cam.width, cam.height, 1, 3);
  Gradients<G, S> g;
  r.backward(wi, &wa, Opt.depth ? &wd : nullptr, g);
  CHECK(all_finite(g.model.means));
  CHECK(all_finite(g.model.log_scales));
  CHECK(all_finite(g.model.quats));
  CHECK(all_finite(g.model.opacity_logits));
  CHECK(all_finite(g.model.sh));
  CHECK(all_finite(g.mean2d));
  CHECK(all_finite(g.absgrad));
  CHECK(all_finite(g.background));
  return g;
}

/// Gaussians in `culled` are culled: zero radii, zero geometry gradients, and the render equals
/// (bit for bit) the render of the model without them.
template <class G, class S, RasterOptions Opt = kDepth>
void check_culled(const GaussianModel<G, S>& m, const Camera<S>& cam, const std::vector<std::size_t>& culled) {
  Rasterizer<G, S, Opt> r;
  const Gradients<G, S> g = render_finite(r, m, cam);
  for (std::size_t i : culled) {
    INFO("gaussian ", i);
    CHECK(r.radii()[2 * i] == 0);
    CHECK(r.radii()[2 * i + 1] == 0);
    for (int k = 0; k < 3; ++k) CHECK(g.model.means[3 * i + static_cast<std::size_t>(k)] == S(0));
    CHECK(g.model.opacity_logits[i] == S(0));
    CHECK(g.mean2d[2 * i] == S(0));
  }
  Rasterizer<G, S, Opt> r2;
  r2.forward(without(m, culled), cam, {});
  CHECK(max_abs_diff(r.image().data, r2.image().data) == 0.0);
  CHECK(max_abs_diff(r.alpha().data, r2.alpha().data) == 0.0);
  if constexpr (Opt.depth) CHECK(max_abs_diff(r.depth().data, r2.depth().data) == 0.0);
}

/// Fast path against the reference (image, alpha, depth), tolerance `tol`.
template <class G, class S, RasterOptions Opt = kDepth>
void check_reference(const GaussianModel<G, S>& m, const Camera<S>& cam, double tol) {
  Rasterizer<G, S, Opt> r;
  render_finite(r, m, cam);
  ReferenceSettings rs;
  rs.depth = Opt.depth;
  rs.antialiased = Opt.antialiased;
  const ReferenceResult<double> ref = reference_render<double>(m, cam, rs);
  CHECK(max_abs_diff(r.image().data, ref.image.data) <= tol);
  CHECK(max_abs_diff(r.alpha().data, ref.alpha.data) <= tol);
  if constexpr (Opt.depth) CHECK(max_abs_diff(r.depth().data, ref.depth.data) <= tol * 10);
}

/// Central differences (double) for every parameter of Gaussian `i`, except those `skip` names
/// (parameter index in [0, G::params): mean 0-2, log-scale 3-5, quat 6-9, opacity 10, SH 11..).
template <class G, RasterOptions Opt = kDepthDouble>
void fd_check_gaussian(GaussianModel<G, double> m, const Camera<double>& cam, std::size_t i,
                       const std::vector<int>& skip = {}, double h = 1e-6) {
  Rasterizer<G, double, Opt> r;
  const Image<double> wi = weights<double>(cam.width, cam.height, G::bands, 1);
  const Image<double> wa = weights<double>(cam.width, cam.height, 1, 2);
  const Image<double> wd = weights<double>(cam.width, cam.height, 1, 3);
  auto loss = [&] {
    r.forward(m, cam, {});
    double l = 0;
    for (std::size_t k = 0; k < wi.data.size(); ++k) l += wi.data[k] * r.image().data[k];
    for (std::size_t k = 0; k < wa.data.size(); ++k) l += wa.data[k] * r.alpha().data[k];
    if constexpr (Opt.depth)
      for (std::size_t k = 0; k < wd.data.size(); ++k) l += wd.data[k] * r.depth().data[k];
    return l;
  };
  loss();
  Gradients<G, double> g;
  r.backward(wi, &wa, Opt.depth ? &wd : nullptr, g);
  std::vector<std::pair<double*, double>> entries;  // (parameter, analytic gradient)
  for (int k = 0; k < 3; ++k) entries.emplace_back(&m.means[3 * i + k], g.model.means[3 * i + k]);
  for (int k = 0; k < 3; ++k) entries.emplace_back(&m.log_scales[3 * i + k], g.model.log_scales[3 * i + k]);
  for (int k = 0; k < 4; ++k) entries.emplace_back(&m.quats[4 * i + k], g.model.quats[4 * i + k]);
  entries.emplace_back(&m.opacity_logits[i], g.model.opacity_logits[i]);
  for (int c = 0; c < G::bands; ++c)
    for (int k = 0; k < G::sh_coeffs; ++k) entries.emplace_back(&m.sh_at(i, k, c), g.model.sh_at(i, k, c));
  double scale = 1e-12;
  for (auto& e : entries) scale = std::max(scale, std::abs(e.second));
  std::string msg;
  int bad = 0;
  for (std::size_t k = 0; k < entries.size(); ++k) {
    if (std::find(skip.begin(), skip.end(), static_cast<int>(k)) != skip.end()) continue;
    double* p = entries[k].first;
    const double v = *p;
    *p = v + h;
    const double lp = loss();
    *p = v - h;
    const double lm = loss();
    *p = v;
    const double fd = (lp - lm) / (2 * h), an = entries[k].second;
    if (!(std::abs(fd - an) <= 1e-5 * std::max(std::abs(fd), std::abs(an)) + 1e-7 * scale)) {
      ++bad;
      char buf[160];
      std::snprintf(buf, sizeof buf, "param %zu: analytic %.12g fd %.12g\n", k, an, fd);
      msg += buf;
    }
  }
  INFO("gaussian ", i, "\n", msg);
  CHECK(bad == 0);
}

/// A small seeded background scene in front of `cam` to embed hard Gaussians in.
template <class G, class S>
GaussianModel<G, S> background_scene(const Camera<S>& cam, std::size_t n, std::uint64_t seed) {
  SceneParams sp;
  sp.n = n;
  sp.opacity_max = 0.7;
  sp.colour_min = 0.3;
  sp.colour_max = 0.7;
  sp.sh_rest = 0.03;
  sp.log_scale_min = std::log(0.1);
  sp.log_scale_max = std::log(0.3);
  return random_scene<G, S>(cam, sp, seed);
}

using G31 = Gaussian<3, 1>;

}  // namespace

TEST_CASE_TEMPLATE("zero and near-zero quaternions", S, float, double) {
  const Camera<S> cam = axis_camera<S>(32, 24, 30, 16, 12);
  GaussianModel<G31, S> m = background_scene<G31, S>(cam, 12, 1);
  for (int k = 0; k < 4; ++k) m.quats[4 * 2 + k] = S(0);                        // exactly zero: culled
  for (int k = 0; k < 4; ++k) m.quats[4 * 5 + k] = S(k == 0 ? 1e-20 : 0);       // below 1e-8: culled
  for (int k = 0; k < 4; ++k) m.quats[4 * 7 + k] = S(k == 0 ? -1e-30 : 1e-31);  // subnormal-ish: culled
  check_culled(m, cam, {2, 5, 7});
  // Small but valid: rendered as its direction.
  for (int k = 0; k < 4; ++k) m.quats[4 * 9 + k] = S(1e-5 * (k + 1));
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) {
    for (int k = 0; k < 4; ++k) m.quats[4 * 9 + k] = 1e-3 * (k + 1);
    fd_check_gaussian(m, cam, 9, {}, 1e-9);
  }
}

TEST_CASE_TEMPLATE("extreme log-scales", S, float, double) {
  const Camera<S> cam = axis_camera<S>(32, 24, 30, 16, 12);
  GaussianModel<G31, S> m = background_scene<G31, S>(cam, 10, 2);
  set_gaussian(m, 1, 0.1, 0.05, 3.0, -30.0, 0.5, 0.6);  // a point: the 0.3 px^2 filter alone
  set_gaussian(m, 4, -0.2, 0.1, 4.0, 30.0, -2.0, 0.4);  // covers everything, almost flat
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) {
    fd_check_gaussian(m, cam, 1);
    fd_check_gaussian(m, cam, 4);
  }
  // Beyond exp's range in float (the projection clamps): still finite.
  set_gaussian(m, 6, 0.0, 0.0, 3.0, 90.0, 0.0, 0.5);
  set_gaussian(m, 7, 0.3, 0.0, 3.0, -120.0, 0.0, 0.5);
  Rasterizer<G31, S, kDepth> r;
  render_finite(r, m, cam);
}

TEST_CASE_TEMPLATE("extreme opacity logits", S, float, double) {
  const Camera<S> cam = axis_camera<S>(32, 24, 30, 16, 12);
  GaussianModel<G31, S> m = background_scene<G31, S>(cam, 10, 3);
  set_gaussian(m, 3, 0.0, 0.0, 2.5, std::log(0.2), 30.0, 0.7);  // alpha clamped at 0.99 in the middle
  set_gaussian(m, 6, 0.2, 0.0, 2.0, std::log(0.2), -30.0, 0.7); // opacity 1e-13: culled
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  check_culled(m, cam, {6});
  if constexpr (std::is_same_v<S, double>) fd_check_gaussian(m, cam, 3);
}

TEST_CASE_TEMPLATE("16 coincident opaque Gaussians (ties broken by index)", S, float, double) {
  const Camera<S> cam = axis_camera<S>(24, 20, 30, 12, 10);
  GaussianModel<G31, S> m(16);
  for (std::size_t i = 0; i < 16; ++i)
    set_gaussian(m, i, 0.02, -0.01, 3.0, std::log(0.3), std::log(0.85 / 0.15), 0.05 * double(i) + 0.1);
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) {
    // Moving a mean along z breaks the tie (a discontinuity): skip parameter 2.
    fd_check_gaussian(m, cam, 0, {2});
    fd_check_gaussian(m, cam, 2, {2});
    fd_check_gaussian(m, cam, 15, {2});
  }
}

TEST_CASE_TEMPLATE("on and around the near plane", S, float, double) {
  Camera<S> cam = axis_camera<S>(32, 24, 30, 16, 12);
  GaussianModel<G31, S> m = background_scene<G31, S>(cam, 8, 4);
  const double near = double(cam.near_plane);
  set_gaussian(m, 0, 0.0, 0.0, near, std::log(0.01), 1.0, 0.5);           // exactly on: culled
  set_gaussian(m, 1, 0.0, 0.0, near * (1 - 1e-6), std::log(0.01), 1.0, 0.5);  // just behind: culled
  set_gaussian(m, 2, 0.0, 0.0, 0.0, std::log(0.01), 1.0, 0.5);            // at the camera centre
  set_gaussian(m, 3, 0.1, 0.0, -1.0, std::log(0.01), 1.0, 0.5);           // behind the camera
  check_culled(m, cam, {0, 1, 2, 3});
  set_gaussian(m, 0, 0.0, 0.0, near * 1.05, std::log(0.001), 0.0, 0.5);   // just in front: huge splat
  set_gaussian(m, 1, 0.015, -0.003, near * 1.5, std::log(0.005), 0.0, 0.5);  // off axis, clamp active
  Rasterizer<G31, S, kDepth> r;
  render_finite(r, m, cam);
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) {
    fd_check_gaussian(m, cam, 0, {}, 1e-8);
    fd_check_gaussian(m, cam, 1, {}, 1e-8);
  }
}

TEST_CASE_TEMPLATE("straddling the border with a principal point far outside the image", S, float, double) {
  // cx < 0 and cy > height: the image sees only one quadrant of the optical axis.
  Camera<S> cam = test_camera<S>(40, 28, -25.0, 45.0, 35.0);
  SceneParams sp;
  sp.n = 120;
  sp.margin_px = 20;
  const GaussianModel<G31, S> m = random_scene<G31, S>(cam, sp, 5);
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) {
    // Find a Gaussian whose centre is just outside the left border and FD-check it.
    const ReferenceResult<double> ref = reference_render<double>(m, cam, ReferenceSettings{});
    for (std::size_t i = 0; i < m.size(); ++i) {
      const auto& s = ref.splats[i];
      if (!s.culled && s.mean2d.x() < 0 && s.mean2d.x() > -4 && s.mean2d.y() > 2 && s.mean2d.y() < 26) {
        fd_check_gaussian(m, cam, i);
        break;
      }
    }
  }
}

TEST_CASE_TEMPLATE("far outside the frustum", S, float, double) {
  const Camera<S> cam = axis_camera<S>(32, 24, 30, 16, 12);
  GaussianModel<G31, S> m = background_scene<G31, S>(cam, 10, 6);
  set_gaussian(m, 0, 1e6, 0.0, 1.0, std::log(0.1), 2.0, 0.5);
  set_gaussian(m, 1, 0.0, -1e8, 2.0, std::log(0.1), 2.0, 0.5);
  set_gaussian(m, 2, 0.0, 0.0, 2e10, std::log(0.1), 2.0, 0.5);  // beyond the far plane
  set_gaussian(m, 3, 1e30, 1e30, 1e30, std::log(0.1), 2.0, 0.5);
  set_gaussian(m, 4, -50.0, 0.0, 1.0, std::log(0.1), 2.0, 0.5);
  check_culled(m, cam, {0, 1, 2, 3, 4});
}

TEST_CASE_TEMPLATE("needles with a scale ratio of 1e6", S, float, double) {
  const Camera<S> cam = test_camera<S>(48, 36, 20.0, 18.0, 40.0);
  SceneParams sp;
  sp.n = 40;
  GaussianModel<G31, S> m = random_scene<G31, S>(cam, sp, 7);
  std::mt19937_64 rng(8);
  for (std::size_t i = 0; i < m.size(); i += 2) {
    const int axis = static_cast<int>(i / 2 % 3);
    for (int k = 0; k < 3; ++k)
      m.log_scales[3 * i + static_cast<std::size_t>(k)] = S(k == axis ? std::log(0.5) : std::log(5e-7));
  }
  Rasterizer<G31, S, kDepth> r;
  render_finite(r, m, cam);
  // Float blends with float conics: along a long needle sigma loses a few digits to cancellation.
  check_reference(m, cam, ref_tol<S>(1e-3, 1e-9));
  if constexpr (std::is_same_v<S, double>) fd_check_gaussian(m, cam, 2, {}, 1e-7);
}

TEST_CASE("NaN and Inf in each parameter are culled, never painted") {
  const Camera<float> cam = axis_camera<float>(32, 24, 30, 16, 12);
  const GaussianModel<G31, float> base = background_scene<G31, float>(cam, 12, 9);
  const float bad_values[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                              -std::numeric_limits<float>::infinity()};
  const std::size_t i = 4;
  for (float bad : bad_values) {
    for (int p = 0; p < G31::params; ++p) {
      GaussianModel<G31, float> m = base;
      if (p < 3) m.means[3 * i + static_cast<std::size_t>(p)] = bad;
      else if (p < 6) m.log_scales[3 * i + static_cast<std::size_t>(p - 3)] = bad;
      else if (p < 10) m.quats[4 * i + static_cast<std::size_t>(p - 6)] = bad;
      else if (p == 10) m.opacity_logits[i] = bad;
      else m.sh_at(i, (p - 11) / G31::bands, (p - 11) % G31::bands) = bad;
      INFO("parameter ", p, " = ", bad);
      check_culled(m, cam, {i});
    }
  }
}

TEST_CASE_TEMPLATE("no Gaussians", S, float, double) {
  const Camera<S> cam = axis_camera<S>(20, 10, 20, 10, 5);
  GaussianModel<G31, S> m;
  Rasterizer<G31, S, kDepth> r;
  RenderSettings<S> rs;
  rs.background = {S(0.25), S(0.5), S(0.75)};
  const Gradients<G31, S> g = render_finite(r, m, cam, rs);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 20; ++x) {
      for (int c = 0; c < 3; ++c) CHECK(r.image().at(x, y, c) == rs.background[static_cast<std::size_t>(c)]);
      CHECK(r.alpha().at(x, y, 0) == S(0));
      CHECK(r.depth().at(x, y, 0) == S(0));
    }
  CHECK(r.fragments() == 0);
  CHECK(g.model.size() == 0);
  CHECK(g.mean2d.empty());
  // dL/d(background) = sum of the image weights per channel (T = 1 everywhere).
  const Image<S> wi = weights<S>(20, 10, 3, 1);
  REQUIRE(g.background.size() == 3);
  for (int c = 0; c < 3; ++c) {
    double s = 0;
    for (std::size_t k = static_cast<std::size_t>(c); k < wi.data.size(); k += 3) s += double(wi.data[k]);
    CHECK(double(g.background[static_cast<std::size_t>(c)]) == doctest::Approx(s).epsilon(1e-5));
  }
}

TEST_CASE_TEMPLATE("a 1x1 image", S, float, double) {
  const Camera<S> cam = axis_camera<S>(1, 1, 2.0, 0.3, 0.8);
  GaussianModel<G31, S> m(6);
  for (std::size_t i = 0; i < 6; ++i)
    set_gaussian(m, i, -0.2 + 0.07 * double(i), 0.1 - 0.05 * double(i), 1.0 + 0.3 * double(i), std::log(0.1 + 0.05 * double(i)),
                 0.3 * double(i) - 0.8, 0.2 + 0.1 * double(i));
  check_reference(m, cam, ref_tol<S>(1e-5, 1e-9));
  if constexpr (std::is_same_v<S, double>) fd_check_gaussian(m, cam, 2);
}

TEST_CASE("one tile holding 100k Gaussians") {
  using G = Gaussian<1, 0>;
  const Camera<float> cam = axis_camera<float>(16, 16, 20, 8, 8);
  SceneParams sp;
  sp.n = 100000;
  sp.margin_px = 0;
  sp.opacity_min = 0.005;
  sp.opacity_max = 0.03;
  sp.z_min = 1;
  sp.z_max = 50;
  const GaussianModel<G, float> m = random_scene<G, float>(cam, sp, 10);
  Rasterizer<G, float, kDepth> r;
  render_finite(r, m, cam);
  ReferenceSettings rs;
  rs.depth = true;
  const ReferenceResult<double> ref = reference_render<double>(m, cam, rs);
  CHECK(max_abs_diff(r.image().data, ref.image.data) <= 1e-4);
  CHECK(max_abs_diff(r.alpha().data, ref.alpha.data) <= 1e-4);
  CHECK(r.fragments() > 256u * 100u);
}

namespace {

/// Geometries for the lane test: random visible ones interleaved with every hard case.
std::vector<GaussianGeometry> lane_test_geometries() {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  auto random_one = [&] {
    GaussianGeometry g;
    g.mean = Eigen::Vector3d(u(rng), u(rng), 3.0 + u(rng));
    g.log_scale = Eigen::Vector3d(-3 + u(rng), -3 + u(rng), -3 + u(rng));
    g.quat = Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
    g.opacity_logit = 3 * u(rng);
    return g;
  };
  std::vector<GaussianGeometry> gs;
  for (int k = 0; k < 64; ++k) {  // every other one a hard case
    GaussianGeometry g = random_one();
    switch (k % 2 == 0 ? 0 : (k / 2) % 9 + 1) {
      case 1: g.quat = Eigen::Vector4d(0, 0, 0, 0); break;            // degenerate quaternion
      case 2: g.log_scale = Eigen::Vector3d(-30, 30, 0.5); break;     // needle / extreme scales
      case 3: g.log_scale = Eigen::Vector3d(60, -60, 0); break;       // beyond the clamp
      case 4: g.opacity_logit = ((k / 2) % 2 == 0) ? 30 : -30; break;      // extreme opacity
      case 5: g.mean[2] = ((k / 2) % 2 == 0) ? 0.01 : -1.0; break;         // on / behind the near plane
      case 6: g.mean = Eigen::Vector3d(1e4, -1e4, 5); break;          // far outside the frustum
      case 7: g.mean[k % 3] = ((k / 2) % 2 == 0) ? nan : inf; break;       // non-finite
      case 8: g.quat[k % 4] = nan; break;
      case 9: g.mean = Eigen::Vector3d(4.0, 2.5, 3.0); break;         // near the tan-fov clamp
      default: break;
    }
    gs.push_back(g);
  }
  return gs;
}

template <class T>
bool same_bits(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

template <bool AA>
void check_lanes_match_scalar() {
  using D = detail::ProjVec;
  constexpr int L = detail::kProjLanes;
  const Camera<double> c = axis_camera<double>(64, 48, 50, 20, 30);
  const ProjectCamera cam = ProjectCamera::from(c);
  const std::vector<GaussianGeometry> gs = lane_test_geometries();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int visible = 0;
  for (std::size_t i0 = 0; i0 + L <= gs.size(); i0 += L) {
    detail::GeometryLanes<D> gl;
    detail::ProjectedGradLanes<D> vl;
    detail::GeometryGradLanes<D> gradl{};
    ProjectedGrad v[L];
    for (int l = 0; l < L; ++l) {
      const GaussianGeometry& g = gs[i0 + std::size_t(l)];
      for (int k = 0; k < 3; ++k) gl.mean[k][l] = g.mean[k], gl.log_scale[k][l] = g.log_scale[k];
      for (int k = 0; k < 4; ++k) gl.quat[k][l] = g.quat[k];
      gl.opacity_logit[l] = g.opacity_logit;
      v[l] = ProjectedGrad{{u(rng), u(rng)}, {u(rng), u(rng), u(rng)}, u(rng), u(rng)};
      for (int k = 0; k < 2; ++k) vl.mean2d[k][l] = v[l].mean2d[k];
      for (int k = 0; k < 3; ++k) vl.conic[k][l] = v[l].conic[k];
      vl.opacity[l] = v[l].opacity;
      vl.depth[l] = v[l].depth;
    }
    detail::ProjectedLanes<D> pl;
    const auto vis = detail::project_lanes<AA>(gl, cam, pl, nullptr, false);
    detail::project_bwd_lanes<AA>(gl, cam, vl, gradl, false);
    for (int l = 0; l < L; ++l) {
      const GaussianGeometry& g = gs[i0 + std::size_t(l)];
      ProjectedGaussian p;
      const bool ok = project_fwd<AA>(g, cam, p);
      INFO("geometry ", i0 + std::size_t(l));
      REQUIRE(ok == (vis[l] != 0));
      GeometryGrad gg;
      project_bwd<AA>(g, cam, v[l], gg);
      for (int k = 0; k < 3; ++k) {
        CHECK(same_bits(gg.mean[k], gradl.mean[k][l]));
        CHECK(same_bits(gg.log_scale[k], gradl.log_scale[k][l]));
      }
      for (int k = 0; k < 4; ++k) CHECK(same_bits(gg.quat[k], gradl.quat[k][l]));
      CHECK(same_bits(gg.opacity_logit, gradl.opacity_logit[l]));
      if (!ok) continue;
      ++visible;
      for (int k = 0; k < 2; ++k) {
        CHECK(same_bits(p.mean2d[k], pl.mean2d[k][l]));
        CHECK(same_bits(p.extent[k], pl.extent[k][l]));
      }
      for (int k = 0; k < 3; ++k) CHECK(same_bits(p.conic[k], pl.conic[k][l]));
      CHECK(same_bits(p.depth, pl.depth[l]));
      CHECK(same_bits(p.opacity, pl.opacity[l]));
      CHECK(same_bits(p.support, pl.support[l]));
    }
  }
  CHECK(visible >= 32);  // the random lanes project; the lanes culled beside them do not disturb them
}

}  // namespace

TEST_CASE("vector projection lanes match the scalar projection bit for bit, hard cases mixed in") {
  check_lanes_match_scalar<false>();
  check_lanes_match_scalar<true>();
}

}  // namespace test_rasterize_hard_cases
