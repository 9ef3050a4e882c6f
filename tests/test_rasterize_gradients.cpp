// tests/test_rasterize_gradients.cpp
// Central finite differences in double for every gradient of Rasterizer::backward: means,
// log-scales, quaternions, opacity logits, SH, background, mean2d, through image, alpha and depth.
#include <doctest/doctest.h>

#include <msgs/rasterize.hpp>

#include "reference_renderer.hpp"

#include <cstdio>
#include <functional>
#include <random>
#include <string>

namespace test_rasterize_gradients {
using namespace msgs;
using namespace msgs::testing;

namespace {

constexpr double kSentinel = 12345.0;  // pre-filled into gradient buffers that must stay untouched

/// A fixed random weight field in [-1, 1]: the loss is sum(W * output).
Image<double> random_weights(int w, int h, int c, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Image<double> img(w, h, c);
  for (double& v : img.data) v = u(rng);
  return img;
}

double dot(const Image<double>& a, const Image<double>& b) {
  double s = 0;
  for (std::size_t k = 0; k < a.data.size(); ++k) s += a.data[k] * b.data[k];
  return s;
}

/// L = sum(W_img image) + sum(W_a alpha) [+ sum(W_d depth)] for one rasterizer configuration.
template <class G, RasterOptions Opt>
struct LinearLoss {
  Camera<double> cam;
  RenderSettings<double> rs;
  Image<double> w_img, w_alpha, w_depth;
  bool use_alpha = true;
  Rasterizer<G, double, Opt> r;

  LinearLoss(const Camera<double>& c, const RenderSettings<double>& s, int channels, std::uint64_t seed)
      : cam(c), rs(s) {
    w_img = random_weights(c.width, c.height, channels, seed);
    w_alpha = random_weights(c.width, c.height, 1, seed + 1);
    w_depth = random_weights(c.width, c.height, 1, seed + 2);
  }

  double operator()(const GaussianModel<G, double>& m) {
    r.forward(m, cam, rs);
    double l = dot(r.image(), w_img);
    if (use_alpha) l += dot(r.alpha(), w_alpha);
    if constexpr (Opt.depth) l += dot(r.depth(), w_depth);
    return l;
  }

  void gradients(const GaussianModel<G, double>& m, Gradients<G, double>& g) {
    r.forward(m, cam, rs);
    r.backward(w_img, use_alpha ? &w_alpha : nullptr, Opt.depth ? &w_depth : nullptr, g);
  }
};

/// Compares analytic[k] with the central difference of `loss` in param[k] for every k where
/// `want(k)` holds. Tolerance: rtol * max(|fd|, |analytic|) + atol.
struct FdReport {
  int checked = 0, failed = 0;
  std::string first_failures;
};

void fd_compare(const char* name, std::vector<double>& param, const std::vector<double>& analytic,
                const std::function<double()>& loss, double h, double rtol, double atol, FdReport& rep,
                int stride, const std::function<bool(std::size_t)>& want = {}) {
  REQUIRE(analytic.size() == param.size());
  for (std::size_t k = 0; k < param.size(); ++k) {
    if (want && !want(k)) continue;
    const double v = param[k];
    param[k] = v + h;
    const double lp = loss();
    param[k] = v - h;
    const double lm = loss();
    param[k] = v;
    const double fd = (lp - lm) / (2 * h);
    const double an = analytic[k];
    ++rep.checked;
    if (!(std::abs(fd - an) <= rtol * std::max(std::abs(fd), std::abs(an)) + atol)) {
      ++rep.failed;
      if (rep.failed <= 8) {
        char buf[240];
        std::snprintf(buf, sizeof buf, "  %s[%zu] (gaussian %zu, component %zu): analytic %.12g fd %.12g\n", name, k,
                      k / static_cast<std::size_t>(stride), k % static_cast<std::size_t>(stride), an, fd);
        rep.first_failures += buf;
      }
    }
  }
}

/// Every parameter gradient of `model` against finite differences. `band_first/band_count` and
/// `sh_degree` say which SH entries are rendered (others must be 0 in FD and untouched by backward).
template <class G, RasterOptions Opt>
void check_all_gradients(LinearLoss<G, Opt>& L, GaussianModel<G, double> model, double atol_scale = 1e-7) {
  const int first = L.rs.band_first;
  const int count = L.rs.band_count < 0 ? G::bands - first : L.rs.band_count;
  const int deg = L.rs.sh_degree < 0 ? G::sh_degree : L.rs.sh_degree;
  const int active_k = sh_coeffs_for_degree(deg);

  Gradients<G, double> g;
  g.model.resize(model.size());
  g.model.set_zero();
  g.model.sh.assign(g.model.sh.size(), kSentinel);
  L.gradients(model, g);
  REQUIRE(g.model.size() == model.size());
  REQUIRE(g.model.means.size() == model.means.size());
  REQUIRE(g.mean2d.size() == 2 * model.size());
  if constexpr (Opt.absgrad) REQUIRE(g.absgrad.size() == 2 * model.size());
  else REQUIRE(g.absgrad.empty());

  double scale = 0;
  for (auto* v : {&g.model.means, &g.model.log_scales, &g.model.quats, &g.model.opacity_logits})
    for (double x : *v) scale = std::max(scale, std::abs(x));
  REQUIRE(scale > 0);  // the scene must actually depend on its parameters
  const double atol = atol_scale * scale, rtol = 1e-5, h = 1e-6;

  auto loss = [&] { return L(model); };
  FdReport rep;
  fd_compare("means", model.means, g.model.means, loss, h, rtol, atol, rep, 3);
  fd_compare("log_scales", model.log_scales, g.model.log_scales, loss, h, rtol, atol, rep, 3);
  fd_compare("quats", model.quats, g.model.quats, loss, h, rtol, atol, rep, 4);
  fd_compare("opacity_logits", model.opacity_logits, g.model.opacity_logits, loss, h, rtol, atol, rep, 1);

  // SH: rendered channels of active coefficients against FD. Band planes [Bands, N, K]: the
  // reported "gaussian" of an SH entry is its row over all planes, channel x N + Gaussian.
  const std::size_t plane = model.sh_plane_stride();
  auto channel = [&](std::size_t k) { return static_cast<int>(k / plane); };
  auto coeff = [&](std::size_t k) { return static_cast<int>(k % G::sh_coeffs); };
  auto rendered = [&](std::size_t k) { return channel(k) >= first && channel(k) < first + count; };
  fd_compare("sh", model.sh, g.model.sh, loss, h, rtol, atol, rep, G::sh_coeffs,
             [&](std::size_t k) { return rendered(k) && coeff(k) < active_k; });
  std::size_t touched_outside = 0, nonzero_inactive = 0;
  for (std::size_t k = 0; k < model.sh.size(); ++k) {
    if (!rendered(k)) touched_outside += g.model.sh[k] != kSentinel;
    // Coefficients above the active degree do not influence the image: 0, or left untouched.
    else if (coeff(k) >= active_k) nonzero_inactive += g.model.sh[k] != 0 && g.model.sh[k] != kSentinel;
  }
  CHECK_MESSAGE(touched_outside == 0, "SH gradients of channels outside the rendered range were written");
  CHECK_MESSAGE(nonzero_inactive == 0, "SH gradients above the active degree are neither 0 nor untouched");

  // Background.
  if (L.rs.background.size() == static_cast<std::size_t>(count)) {
    REQUIRE(g.background.size() == static_cast<std::size_t>(count));
    fd_compare("background", L.rs.background, g.background, loss, h, rtol, atol, rep, 1);
  } else if (L.rs.background.size() == 1) {
    // Broadcast: dL/d(the one value) is the sum over channels. The rasterizer may report it either
    // per channel ([band_count]) or already summed (one value).
    REQUIRE((g.background.size() == 1 || g.background.size() == static_cast<std::size_t>(count)));
    double sum = 0;
    for (double x : g.background) sum += x;
    std::vector<double> an{sum};
    fd_compare("background(broadcast)", L.rs.background, an, loss, h, rtol, atol, rep, 1);
  }

  // absgrad sums |per-pixel gradient| and so bounds |mean2d|.
  if constexpr (Opt.absgrad) {
    std::size_t absgrad_bad = 0;
    for (std::size_t k = 0; k < g.mean2d.size(); ++k)
      absgrad_bad += !(g.absgrad[k] >= std::abs(g.mean2d[k]) * (1 - 1e-12) && std::isfinite(g.absgrad[k]));
    CHECK(absgrad_bad == 0);
  }

  INFO("failures:\n", rep.first_failures);
  CHECK(rep.checked > 0);
  CHECK(rep.failed == 0);
}

SceneParams gradient_scene(std::size_t n) {
  SceneParams sp;
  sp.n = n;
  sp.z_min = 2;
  sp.z_max = 6;
  sp.margin_px = 12;  // a few centres beyond the tan-fov clamp
  sp.log_scale_min = std::log(0.12);
  sp.log_scale_max = std::log(0.45);
  sp.opacity_min = 0.1;
  sp.opacity_max = 0.7;  // far from the 0.99 clamp and from early termination
  sp.colour_min = 0.3;
  sp.colour_max = 0.7;   // far from the clamp at 0
  sp.sh_rest = 0.03;
  return sp;
}

/// The precondition of a smooth loss: every colour stays away from the clamp at 0.
template <class G>
void require_smooth(const GaussianModel<G, double>& m, const Camera<double>& cam, const ReferenceSettings& rs) {
  const ReferenceResult<double> ref = reference_render<double>(m, cam, rs);
  std::size_t visible = 0;
  for (const auto& s : ref.splats) {
    if (s.culled) continue;
    ++visible;
    for (double c : s.colour) REQUIRE(c > 0.02);
  }
  REQUIRE(visible >= m.size() / 2);
  REQUIRE(ref.fragments > 100);
}

constexpr RasterOptions kPlain{};
constexpr RasterOptions kAbsGrad{.absgrad = true};
constexpr RasterOptions kDepth{.depth = true, .antialiased = false, .absgrad = true};
constexpr RasterOptions kDepthAA{.depth = true, .antialiased = true, .absgrad = true};

}  // namespace

TEST_CASE("gradients: <3,3> model, every channel, image + alpha + depth") {
  using G = Gaussian<3, 3>;
  const Camera<double> cam = test_camera<double>(40, 32, 11.0, 25.0, 40.0);
  const GaussianModel<G, double> model = random_scene<G, double>(cam, gradient_scene(12), 101);
  ReferenceSettings ref;
  require_smooth(model, cam, ref);
  RenderSettings<double> rs;
  rs.background = {0.2, 0.5, 0.9};
  LinearLoss<G, kDepth> L(cam, rs, 3, 7);
  check_all_gradients(L, model);
}

TEST_CASE("gradients: <7,2> model, band subset, active degree 1, antialiased, broadcast background") {
  using G = Gaussian<7, 2>;
  const Camera<double> cam = test_camera<double>(37, 29, 30.0, 6.0, 38.0);
  const GaussianModel<G, double> model = random_scene<G, double>(cam, gradient_scene(10), 202);
  ReferenceSettings ref;
  ref.band_first = 2;
  ref.band_count = 3;
  ref.sh_degree = 1;
  require_smooth(model, cam, ref);
  RenderSettings<double> rs;
  rs.band_first = 2;
  rs.band_count = 3;
  rs.sh_degree = 1;
  rs.background = {0.35};
  LinearLoss<G, kDepthAA> L(cam, rs, 3, 8);
  check_all_gradients(L, model);

  SUBCASE("one spectral band, full degree, per-band background") {
    RenderSettings<double> one;
    one.band_first = 6;
    one.band_count = 1;
    one.background = {0.6};
    LinearLoss<G, kDepthAA> L1(cam, one, 1, 9);
    check_all_gradients(L1, model);
  }
}

TEST_CASE("gradients: <1,0> model, image only (no alpha or depth gradient)") {
  using G = Gaussian<1, 0>;
  const Camera<double> cam = test_camera<double>(33, 35, 16.0, 17.0, 36.0);
  const GaussianModel<G, double> model = random_scene<G, double>(cam, gradient_scene(14), 303);
  RenderSettings<double> rs;
  LinearLoss<G, kPlain> L(cam, rs, 1, 10);
  L.use_alpha = false;
  check_all_gradients(L, model);
}

TEST_CASE("mean2d: sum over Gaussians equals dL/d(principal point)") {
  // Moving cx, cy shifts every projected mean by the same amount and changes nothing else as long
  // as no Gaussian sits beyond the tan-fov clamp (margin 0 keeps every centre on screen).
  using G = Gaussian<3, 2>;
  Camera<double> cam = test_camera<double>(41, 30, 14.0, 20.0, 40.0);
  SceneParams sp = gradient_scene(15);
  sp.margin_px = 0;
  const GaussianModel<G, double> model = random_scene<G, double>(cam, sp, 404);
  RenderSettings<double> rs;
  rs.background = {0.1, 0.2, 0.3};
  LinearLoss<G, kDepth> L(cam, rs, 3, 11);
  Gradients<G, double> g;
  L.gradients(model, g);
  REQUIRE(g.mean2d.size() == 2 * model.size());
  double sum_x = 0, sum_y = 0;
  for (std::size_t i = 0; i < model.size(); ++i) {
    sum_x += g.mean2d[2 * i];
    sum_y += g.mean2d[2 * i + 1];
  }
  const double h = 1e-6;
  auto at = [&](double dcx, double dcy) {
    L.cam = cam;
    L.cam.cx += dcx;
    L.cam.cy += dcy;
    return L(model);
  };
  const double fd_x = (at(h, 0) - at(-h, 0)) / (2 * h);
  const double fd_y = (at(0, h) - at(0, -h)) / (2 * h);
  CHECK(sum_x == doctest::Approx(fd_x).epsilon(1e-5));
  CHECK(sum_y == doctest::Approx(fd_y).epsilon(1e-5));
  CHECK(std::abs(fd_x) > 1e-3);  // the check must be able to fail
}

TEST_CASE("mean2d per Gaussian: point-like splats, whose footprint is the 0.3 px^2 filter alone") {
  // With log-scale -30 the screen covariance is exactly 0.3 I whatever the mean, and with SH degree 0
  // the colour does not depend on the mean either; so with R = I, dL/d(mean x) = fx / z dL/d(mean2d x).
  using G = Gaussian<1, 0>;
  Camera<double> cam;
  cam.width = 24;
  cam.height = 20;
  cam.fx = 30;
  cam.fy = 33;
  cam.cx = 7;
  cam.cy = 12;
  SceneParams sp = gradient_scene(20);
  sp.margin_px = 0;
  sp.opacity_min = 0.3;
  GaussianModel<G, double> model = random_scene<G, double>(cam, sp, 505);
  for (double& ls : model.log_scales) ls = -30;
  RenderSettings<double> rs;
  LinearLoss<G, kAbsGrad> L(cam, rs, 1, 12);
  Gradients<G, double> g;
  L.gradients(model, g);
  const double h = 1e-7;
  std::size_t bad = 0, nonzero = 0;
  std::string msg;
  for (std::size_t i = 0; i < model.size(); ++i) {
    const double z = model.means[3 * i + 2];
    for (int a = 0; a < 2; ++a) {
      const double v = model.means[3 * i + a];
      model.means[3 * i + a] = v + h;
      const double lp = L(model);
      model.means[3 * i + a] = v - h;
      const double lm = L(model);
      model.means[3 * i + a] = v;
      const double fd = (lp - lm) / (2 * h) * z / (a == 0 ? cam.fx : cam.fy);
      const double an = g.mean2d[2 * i + static_cast<std::size_t>(a)];
      nonzero += std::abs(an) > 1e-6;
      if (!(std::abs(fd - an) <= 1e-5 * std::max(std::abs(fd), std::abs(an)) + 1e-8)) {
        ++bad;
        msg += "gaussian " + std::to_string(i) + " axis " + std::to_string(a) + ": analytic " + std::to_string(an) +
               " fd " + std::to_string(fd) + "\n";
      }
      CHECK(g.absgrad[2 * i + static_cast<std::size_t>(a)] >= std::abs(an) * (1 - 1e-12));
    }
  }
  INFO(msg);
  CHECK(bad == 0);
  CHECK(nonzero > 10);
}

TEST_CASE("gradients of Gaussians beyond the image are exactly zero and finite") {
  using G = Gaussian<3, 1>;
  const Camera<double> cam = test_camera<double>(30, 30, 15.0, 15.0, 40.0);
  SceneParams sp = gradient_scene(10);
  GaussianModel<G, double> model = random_scene<G, double>(cam, sp, 606);
  // Move Gaussian 0 far to the side and Gaussian 1 behind the camera.
  const Eigen::Vector3d side = cam.R.transpose() * (Eigen::Vector3d(500, 0, 4) - cam.t);
  const Eigen::Vector3d behind = cam.R.transpose() * (Eigen::Vector3d(0, 0, -3) - cam.t);
  for (int k = 0; k < 3; ++k) {
    model.means[static_cast<std::size_t>(k)] = side[k];
    model.means[static_cast<std::size_t>(3 + k)] = behind[k];
  }
  RenderSettings<double> rs;
  LinearLoss<G, kDepth> L(cam, rs, 3, 13);
  Gradients<G, double> g;
  L.gradients(model, g);
  for (std::size_t i : {std::size_t(0), std::size_t(1)}) {
    for (int k = 0; k < 3; ++k) CHECK(g.model.means[3 * i + static_cast<std::size_t>(k)] == 0.0);
    for (int k = 0; k < 3; ++k) CHECK(g.model.log_scales[3 * i + static_cast<std::size_t>(k)] == 0.0);
    for (int k = 0; k < 4; ++k) CHECK(g.model.quats[4 * i + static_cast<std::size_t>(k)] == 0.0);
    CHECK(g.model.opacity_logits[i] == 0.0);
    CHECK(g.mean2d[2 * i] == 0.0);
    CHECK(g.mean2d[2 * i + 1] == 0.0);
  }
  CHECK(all_finite(g.model.means));
  CHECK(all_finite(g.model.sh));
}

TEST_CASE("background gradient when some tiles hold no Gaussian") {
  // Every Gaussian in the left half of a 64x32 image: the right-hand tiles are empty, and their
  // pixels show the background alone (T = 1), so dL/d(background) must count them too.
  using G = Gaussian<1, 0>;
  Camera<double> cam;
  cam.width = 64;
  cam.height = 32;
  cam.fx = cam.fy = 40;
  cam.cx = 32;
  cam.cy = 16;
  GaussianModel<G, double> model(3);
  for (std::size_t i = 0; i < 3; ++i) {
    const double xyz[3] = {-0.5 + 0.1 * double(i), -0.1 + 0.1 * double(i), 3.0 + double(i)};
    for (int k = 0; k < 3; ++k) model.means[3 * i + static_cast<std::size_t>(k)] = xyz[k];
    for (int k = 0; k < 3; ++k) model.log_scales[3 * i + static_cast<std::size_t>(k)] = std::log(0.05);
    model.quats[4 * i] = 1;
    model.opacity_logits[i] = 0.5;
  }
  RenderSettings<double> rs;
  rs.background = {0.4};
  LinearLoss<G, kPlain> L(cam, rs, 1, 14);
  Gradients<G, double> g;
  L.gradients(model, g);
  REQUIRE(g.background.size() == 1);
  const double h = 1e-6;
  L.rs.background = {0.4 + h};
  const double lp = L(model);
  L.rs.background = {0.4 - h};
  const double lm = L(model);
  CHECK(g.background[0] == doctest::Approx((lp - lm) / (2 * h)).epsilon(1e-6));
}

namespace {

/// Largest |a - b| relative to max |b| over one gradient array.
template <class A, class B>
double relative_to_scale(const std::vector<A>& a, const std::vector<B>& b) {
  REQUIRE(a.size() == b.size());
  double scale = 0, diff = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    scale = std::max(scale, std::abs(double(b[k])));
    diff = std::max(diff, std::abs(double(a[k]) - double(b[k])));
  }
  return scale > 0 ? diff / scale : diff;
}

}  // namespace

TEST_CASE("float backward agrees with double backward on a crowded scene") {
  // The float path rebuilds transmittance by division and accumulates per-intersection records in
  // float; on a scene with thousands of Gaussians (some nearly opaque) it must stay within 1e-4 of
  // the double gradients, relative to each array's largest entry.
  using G = Gaussian<3, 3>;
  constexpr RasterOptions kOpt{.depth = true, .antialiased = true, .absgrad = true};
  const Camera<float> cam = test_camera<float>(96, 64, 30.0, 40.0, 80.0);
  for (double max_opacity : {0.9, 0.999}) {
    SceneParams sp;
    sp.n = 2000;
    sp.log_scale_max = std::log(0.3);
    sp.opacity_max = max_opacity;
    const GaussianModel<G, float> mf = random_scene<G, float>(cam, sp, 5);
    const GaussianModel<G, double> md = cast_model<double>(mf);
    const Camera<double> camd = cam.cast<double>();
    const Image<double> wi = random_weights(cam.width, cam.height, 3, 1), wa = random_weights(cam.width, cam.height, 1, 2),
                        wd = random_weights(cam.width, cam.height, 1, 3);
    auto to_float = [](const Image<double>& d) {
      Image<float> f(d.width, d.height, d.channels);
      for (std::size_t k = 0; k < d.data.size(); ++k) f.data[k] = float(d.data[k]);
      return f;
    };
    Rasterizer<G, float, kOpt> rf;
    Rasterizer<G, double, kOpt> rd;
    rf.forward(mf, cam, {});
    rd.forward(md, camd, {});
    Gradients<G, float> gf;
    Gradients<G, double> gd;
    const Image<float> wif = to_float(wi), waf = to_float(wa), wdf = to_float(wd);
    rf.backward(wif, &waf, &wdf, gf);
    rd.backward(wi, &wa, &wd, gd);
    INFO("max opacity ", max_opacity);
    CHECK(relative_to_scale(gf.model.means, gd.model.means) < 1e-4);
    CHECK(relative_to_scale(gf.model.log_scales, gd.model.log_scales) < 1e-4);
    CHECK(relative_to_scale(gf.model.quats, gd.model.quats) < 1e-4);
    CHECK(relative_to_scale(gf.model.opacity_logits, gd.model.opacity_logits) < 1e-4);
    CHECK(relative_to_scale(gf.model.sh, gd.model.sh) < 1e-4);
    CHECK(relative_to_scale(gf.mean2d, gd.mean2d) < 1e-4);
    CHECK(relative_to_scale(gf.absgrad, gd.absgrad) < 1e-4);
    CHECK(relative_to_scale(gf.background, gd.background) < 1e-4);
  }
}

}  // namespace test_rasterize_gradients
