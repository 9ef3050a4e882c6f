// tests/test_rasterize_single.cpp
// The single-precision projection (RasterOptions::single_precision): its exp and log, its lanes
// against the double-precision projection, the Gaussians it hands to double precision, and the
// whole rasteriser against the reference renderer and the double-precision gradients.
#include <doctest/doctest.h>

#include <msgs/rasterize.hpp>

#include "reference_renderer.hpp"

#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace test_rasterize_single {
using namespace msgs;
using namespace msgs::testing;

namespace {

/// |a - ref| in units of float's ulp at ref (ref exact, in double).
double ulps_f(float a, double ref) {
  const float rf = float(ref);
  const double ulp = double(std::nextafter(std::abs(rf), INFINITY)) - double(std::abs(rf));
  return std::abs(double(a) - ref) / ulp;
}

/// Channels 1 and 2 of a three-channel model at SH degree `deg`.
RenderSettings<float> middle_channels(int deg) {
  RenderSettings<float> rs;
  rs.band_first = 1;
  rs.band_count = 2;
  rs.sh_degree = deg;
  return rs;
}

/// Random Gaussians in front of `c` (some off screen), none of them hard.
std::vector<GaussianGeometry> tame_geometries(std::uint64_t seed, int n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0), uz(1.0, 12.0), uls(-6.0, 0.5), uo(-4.0, 6.0);
  std::vector<GaussianGeometry> gs;
  for (int i = 0; i < n; ++i) {
    GaussianGeometry g;
    const double z = uz(rng);
    g.mean = Eigen::Vector3d(1.2 * u(rng) * z, 0.9 * u(rng) * z, z);
    g.log_scale = Eigen::Vector3d(uls(rng), uls(rng), uls(rng));
    g.quat = Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng));
    g.opacity_logit = uo(rng);
    gs.push_back(g);
  }
  return gs;
}

/// Lane l of a single-precision geometry vector set from one Gaussian.
void set_geometry_lane(detail::GeometryLanes<detail::ProjVecF>& gl, int l, const GaussianGeometry& g) {
  for (int k = 0; k < 3; ++k) gl.mean[k][l] = float(g.mean[k]), gl.log_scale[k][l] = float(g.log_scale[k]);
  for (int k = 0; k < 4; ++k) gl.quat[k][l] = float(g.quat[k]);
  gl.opacity_logit[l] = float(g.opacity_logit);
}

/// The geometry as float values, back in double (what the single-precision path sees).
GaussianGeometry rounded(const GaussianGeometry& g) {
  GaussianGeometry r = g;
  for (int k = 0; k < 3; ++k) r.mean[k] = double(float(g.mean[k])), r.log_scale[k] = double(float(g.log_scale[k]));
  for (int k = 0; k < 4; ++k) r.quat[k] = double(float(g.quat[k]));
  r.opacity_logit = double(float(g.opacity_logit));
  return r;
}

template <bool AA>
void check_single_lanes() {
  using D = detail::ProjVecF;
  constexpr int L = detail::kProjLanesF;
  const Camera<double> c = test_camera<double>(320, 240, 150.0, 130.0, 300.0);
  const ProjectCamera cam = ProjectCamera::from(c);
  // 1024 whatever the lane count (64 vectors with AVX-512, 256 with SSE2), so that every build
  // compares some 500 visible Gaussians.
  const std::vector<GaussianGeometry> gs = tame_geometries(7, 1024);
  static_assert(1024 % L == 0);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int visible = 0;
  double worst_px = 0, worst_conic = 0, worst_opacity = 0, worst_depth = 0, worst_grad = 0;
  bool same_as_scalar = true;
  for (std::size_t i0 = 0; i0 < gs.size(); i0 += L) {
    detail::GeometryLanes<D> gl;
    detail::ProjectedGradLanes<D> vl;
    detail::GeometryGradLanes<D> gradl{};
    ProjectedGrad v[L];
    for (int l = 0; l < L; ++l) {
      set_geometry_lane(gl, l, gs[i0 + std::size_t(l)]);
      v[l] = ProjectedGrad{{u(rng), u(rng)}, {u(rng), u(rng), u(rng)}, u(rng), u(rng)};
      for (int k = 0; k < 2; ++k) vl.mean2d[k][l] = float(v[l].mean2d[k]);
      for (int k = 0; k < 3; ++k) vl.conic[k][l] = float(v[l].conic[k]);
      vl.opacity[l] = float(v[l].opacity);
      vl.depth[l] = float(v[l].depth);
    }
    detail::ProjectedLanes<D> pl;
    const auto vis = detail::project_lanes<AA>(gl, cam, pl, nullptr, false);
    CHECK(detail::lane_bits(pl.hard) == 0u);
    const auto hard_bwd = detail::project_bwd_lanes<AA>(gl, cam, vl, gradl, false);
    CHECK(detail::lane_bits(hard_bwd) == 0u);
    for (int l = 0; l < L; ++l) {
      const GaussianGeometry g = rounded(gs[i0 + std::size_t(l)]);
      ProjectedGaussian p;
      const bool ok = project_fwd<AA>(g, cam, p);
      INFO("geometry ", i0 + std::size_t(l));
      REQUIRE(ok == (vis[l] != 0));
      // One lane of float projects to the same bits as a lane of the vector.
      {
        detail::GeometryLanes<float> g1;
        for (int k = 0; k < 3; ++k) g1.mean[k] = gl.mean[k][l], g1.log_scale[k] = gl.log_scale[k][l];
        for (int k = 0; k < 4; ++k) g1.quat[k] = gl.quat[k][l];
        g1.opacity_logit = gl.opacity_logit[l];
        detail::ProjectedLanes<float> p1;
        const bool ok1 = detail::project_lanes<AA>(g1, cam, p1, nullptr, false);
        same_as_scalar = same_as_scalar && ok1 == ok;
        if (ok1 && ok)
          same_as_scalar = same_as_scalar && p1.mean2d[0] == pl.mean2d[0][l] && p1.conic[1] == pl.conic[1][l] &&
                           p1.opacity == pl.opacity[l] && p1.extent[0] == pl.extent[0][l];
      }
      if (!ok) continue;
      ++visible;
      for (int k = 0; k < 2; ++k) worst_px = std::max(worst_px, std::abs(p.mean2d[k] - double(pl.mean2d[k][l])));
      const double cs = std::max({std::abs(p.conic[0]), std::abs(p.conic[2])});
      for (int k = 0; k < 3; ++k) worst_conic = std::max(worst_conic, std::abs(p.conic[k] - double(pl.conic[k][l])) / cs);
      worst_opacity = std::max(worst_opacity, std::abs(p.opacity - double(pl.opacity[l])));
      worst_depth = std::max(worst_depth, std::abs(p.depth - double(pl.depth[l])) / p.depth);
      // Gradients relative to the Gaussian's largest one.
      GeometryGrad gd;
      project_bwd<AA>(g, cam, v[l], gd);
      double scale = 1e-30;
      for (int k = 0; k < 3; ++k) scale = std::max({scale, std::abs(gd.mean[k]), std::abs(gd.log_scale[k])});
      for (int k = 0; k < 4; ++k) scale = std::max(scale, std::abs(gd.quat[k]));
      scale = std::max(scale, std::abs(gd.opacity_logit));
      double err = std::abs(gd.opacity_logit - double(gradl.opacity_logit[l]));
      for (int k = 0; k < 3; ++k)
        err = std::max({err, std::abs(gd.mean[k] - double(gradl.mean[k][l])), std::abs(gd.log_scale[k] - double(gradl.log_scale[k][l]))});
      for (int k = 0; k < 4; ++k) err = std::max(err, std::abs(gd.quat[k] - double(gradl.quat[k][l])));
      worst_grad = std::max(worst_grad, err / scale);
    }
  }
  INFO("visible ", visible, ": worst mean2d ", worst_px, " px, conic ", worst_conic, ", opacity ", worst_opacity,
       ", depth ", worst_depth, ", gradient ", worst_grad);
  CHECK(visible >= 200);
  CHECK(same_as_scalar);
  CHECK(worst_px <= 1e-3);
  CHECK(worst_conic <= 1e-5);
  CHECK(worst_opacity <= 1e-6);
  CHECK(worst_depth <= 1e-6);
  CHECK(worst_grad <= 5e-4);  // a chain of some 50 float operations
}

constexpr RasterOptions kSingleAA{.depth = true, .antialiased = true, .single_precision = true};
constexpr RasterOptions kDoubleAA{.depth = true, .antialiased = true};

}  // namespace

TEST_CASE("single-precision exp and log: within 1.5 ulp of libm, the same bits per lane and one at a time") {
  using D = detail::ProjVecF;
  constexpr int L = detail::kProjLanesF;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> ue(-87.0, 88.5), ul(-80.0, 80.0), u1(0.5, 300.0);
  double worst_exp = 0, worst_log = 0;
  bool same = true;
  for (int it = 0; it < 50000; ++it) {
    D x, y;
    for (int l = 0; l < L; ++l) {
      x[l] = float(ue(rng));
      y[l] = (it & 1) ? float(std::exp(ul(rng))) : float(u1(rng));
    }
    const D e = detail::lexp(x), g = detail::llog(y);
    for (int l = 0; l < L; ++l) {
      worst_exp = std::max(worst_exp, ulps_f(e[l], std::exp(double(x[l]))));
      if (y[l] != 1.0f) worst_log = std::max(worst_log, ulps_f(g[l], std::log(double(y[l]))));
      same = same && detail::lexp(x[l]) == e[l] && detail::llog(y[l]) == g[l];
    }
  }
  INFO("worst exp ", worst_exp, " ulp, worst log ", worst_log, " ulp");
  CHECK(worst_exp <= 1.5);
  CHECK(worst_log <= 1.0);
  CHECK(same);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  CHECK(detail::lexp(89.0f) == inf);
  CHECK(detail::lexp(1e30f) == inf);
  CHECK(detail::lexp(inf) == inf);
  CHECK(detail::lexp(-inf) == 0.0f);
  CHECK(detail::lexp(-1e30f) == 0.0f);
  CHECK(std::abs(double(detail::lexp(-100.0f)) - std::exp(-100.0)) <= 0x1p-149);  // subnormal
  CHECK(std::isnan(detail::lexp(nan)));
  CHECK(detail::lexp(0.0f) == 1.0f);
  CHECK(detail::llog(1.0f) == 0.0f);
  for (float bad : {0.0f, -1.0f, 1e-40f, inf, -inf, nan}) CHECK(std::isnan(detail::llog(bad)));
}

TEST_CASE("single-precision projection lanes: within float rounding of the double projection") {
  check_single_lanes<false>();
  check_single_lanes<true>();
}

TEST_CASE("single-precision projection hands the hard Gaussians to double precision and leaves them alone") {
  using D = detail::ProjVecF;
  constexpr int L = detail::kProjLanesF;
  const Camera<double> c = test_camera<double>(320, 240, 150.0, 130.0, 300.0);
  const ProjectCamera cam = ProjectCamera::from(c);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // Each case: a tame Gaussian made hard in one way; even entries are hard, odd ones tame. The
  // 16 entries (eight hard cases) go through the lanes in batches of L (one batch with AVX-512,
  // two with AVX2, four with SSE2), so every build meets every case.
  constexpr int kCases = 16;
  static_assert(kCases % L == 0);
  std::vector<GaussianGeometry> gs = tame_geometries(11, kCases);
  auto in_front = [&](double x, double y, double z) {  // camera-space point -> world
    const Eigen::Vector3d p(x, y, z);
    return Eigen::Vector3d(c.R.transpose() * (p - c.t));
  };
  for (int i = 0; i < kCases; i += 2) {
    GaussianGeometry& g = gs[std::size_t(i)];
    g.mean = in_front(0.1, 0.1, 4.0);
    g.log_scale = Eigen::Vector3d(-3, -3, -3);
    g.opacity_logit = 2;
    switch (i / 2) {
      case 0: g.log_scale[1] = 25.0; break;                     // scale e^25
      case 1: g.log_scale[2] = -21.0; break;                    // scale e^-21
      case 2: g.mean = in_front(0.0, 0.0, 3e7); break;          // beyond kMean
      case 3: g.mean = in_front(5.0, 0.0, 0.01); break;         // depth small against |mean|
      case 4: g.quat[2] = 1e16; break;                          // huge quaternion
      case 5: g.mean[0] = nan; break;                           // non-finite
      case 6: g.log_scale = Eigen::Vector3d(3, 3, 3);           // a footprint above 1e8 px^2
              g.mean = in_front(0.0, 0.0, 0.4); break;
      default: g.opacity_logit = nan; break;
    }
  }
  for (int i0 = 0; i0 < kCases; i0 += L) {
    detail::GeometryLanes<D> gl;
    for (int l = 0; l < L; ++l) set_geometry_lane(gl, l, gs[std::size_t(i0 + l)]);
    detail::ProjectedLanes<D> pl;
    const auto vis = detail::project_lanes<false>(gl, cam, pl, nullptr, false);
    detail::ProjectedGradLanes<D> vl{};
    for (int l = 0; l < L; ++l) vl.mean2d[0][l] = 1.0f, vl.conic[0][l] = 1.0f, vl.opacity[l] = 1.0f;
    detail::GeometryGradLanes<D> gradl{};
    const auto hard_bwd = detail::project_bwd_lanes<false>(gl, cam, vl, gradl, false);
    for (int l = 0; l < L; ++l) {
      INFO("case ", i0 + l);
      const bool hard = ((i0 + l) % 2 == 0);
      CHECK((pl.hard[l] != 0) == hard);
      CHECK((hard_bwd[l] != 0) == hard);
      if (hard) {
        CHECK(vis[l] == 0);
        // Untouched: the double-precision pass writes these. (Copied out: a reference, as CHECK
        // takes its operands, cannot bind to a vector lane under Clang.)
        const float mean0 = gradl.mean[0][l], opacity = gradl.opacity_logit[l];
        CHECK(mean0 == 0.0f);
        CHECK(opacity == 0.0f);
      }
    }
  }
  // The footprint case is on screen in double precision (what it is handed to).
  ProjectedGaussian p;
  CHECK(project_fwd<false>(rounded(gs[12]), cam, p));
  CHECK(std::max(p.conic[0], p.conic[2]) < 1e-8);
}

TEST_CASE_TEMPLATE("single-precision rasteriser against the reference renderer", G, Gaussian<1, 3>, Gaussian<3, 3>,
                   Gaussian<7, 3>) {
  SceneParams sp;
  sp.n = 400;
  const Camera<float> cam = test_camera<float>(70, 45, 41.0, 12.0, 55.0);
  const GaussianModel<G, float> model = random_scene<G, float>(cam, sp, 21);
  Rasterizer<G, float, kSingleAA> fast;
  RenderSettings<float> rs;
  rs.background = {0.2f};
  fast.forward(model, cam, rs);
  ReferenceSettings ref_rs;
  ref_rs.background = {0.2};
  ref_rs.depth = true;
  ref_rs.antialiased = true;
  const ReferenceResult<double> ref = reference_render<double>(model, cam, ref_rs);
  CHECK(max_abs_diff(fast.image().data, ref.image.data) <= 1e-5);
  CHECK(max_abs_diff(fast.alpha().data, ref.alpha.data) <= 1e-5);
  CHECK(max_abs_diff(fast.depth().data, ref.depth.data) <= 1e-5 * sp.z_max);
  CHECK(fast.fragments() == ref.fragments);
}

TEST_CASE("single-precision backward agrees with the double-precision one on a crowded scene") {
  using G = Gaussian<7, 3>;
  const Camera<float> cam = test_camera<float>(96, 64, 30.0, 40.0, 80.0);
  SceneParams sp;
  sp.n = 2000;
  sp.log_scale_max = std::log(0.3);
  sp.opacity_max = 0.99;
  const GaussianModel<G, float> m = random_scene<G, float>(cam, sp, 5);
  RenderSettings<float> rs;
  rs.band_first = 4;
  rs.band_count = 1;
  Rasterizer<G, float, kSingleAA> rs_single;
  Rasterizer<G, float, kDoubleAA> rs_double;
  rs_single.forward(m, cam, rs);
  rs_double.forward(m, cam, rs);
  CHECK(max_abs_diff(rs_single.image().data, rs_double.image().data) <= 1e-5);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Image<float> wi(cam.width, cam.height, 1), wa(cam.width, cam.height, 1), wd(cam.width, cam.height, 1);
  for (auto* img : {&wi, &wa, &wd})
    for (float& v : img->data) v = u(rng);
  Gradients<G, float> gs, gd;
  rs_single.backward(wi, &wa, &wd, gs);
  rs_double.backward(wi, &wa, &wd, gd);
  auto rel = [](const std::vector<float>& a, const std::vector<float>& b) {
    double scale = 0, diff = 0;
    for (std::size_t k = 0; k < a.size(); ++k) {
      scale = std::max(scale, std::abs(double(b[k])));
      diff = std::max(diff, std::abs(double(a[k]) - double(b[k])));
    }
    return scale > 0 ? diff / scale : diff;
  };
  CHECK(rel(gs.model.means, gd.model.means) < 1e-4);
  CHECK(rel(gs.model.log_scales, gd.model.log_scales) < 1e-4);
  CHECK(rel(gs.model.quats, gd.model.quats) < 1e-4);
  CHECK(rel(gs.model.opacity_logits, gd.model.opacity_logits) < 1e-4);
  CHECK(rel(gs.model.sh, gd.model.sh) < 1e-4);
  CHECK(rel(gs.mean2d, gd.mean2d) < 1e-4);
}

TEST_CASE_TEMPLATE("transpose_square turns an L x L block of vector lanes around", D, detail::ProjVecF, detail::ProjVec) {
  constexpr int L = detail::Lanes<D>::kCount;
  D r[L];
  for (int i = 0; i < L; ++i)
    for (int j = 0; j < L; ++j) r[i][j] = typename detail::Lanes<D>::T(100 * i + j);
  detail::transpose_square(r);
  for (int i = 0; i < L; ++i)
    for (int j = 0; j < L; ++j) {
      const auto got = r[i][j];  // a copy: CHECK's reference cannot bind to a vector lane under Clang
      CHECK(got == typename detail::Lanes<D>::T(100 * j + i));
    }
}

TEST_CASE("single-precision colour rows move as transposed blocks at every SH degree") {
  // The single-precision path gathers and scatters SH rows as whole vectors (an L x L transpose)
  // and writes zeros above the active degree; the double-precision path copies value by value.
  using G = Gaussian<3, 3>;
  const Camera<float> cam = test_camera<float>(80, 56, 36.0, 30.0, 60.0);
  SceneParams sp;
  sp.n = 700;  // not a multiple of 16: the last batch has padded lanes
  const GaussianModel<G, float> m = random_scene<G, float>(cam, sp, 9);
  for (int deg = 0; deg <= 3; ++deg) {
    CAPTURE(deg);
    const RenderSettings<float> rs = middle_channels(deg);
    Rasterizer<G, float, kSingleAA> rs_single;
    Rasterizer<G, float, kDoubleAA> rs_double;
    rs_single.forward(m, cam, rs);
    rs_double.forward(m, cam, rs);
    CHECK(max_abs_diff(rs_single.image().data, rs_double.image().data) <= 1e-5);
    Image<float> wi(cam.width, cam.height, 2);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (float& v : wi.data) v = u(rng);
    Gradients<G, float> gs, gd;
    rs_single.backward(wi, nullptr, nullptr, gs);
    rs_double.backward(wi, nullptr, nullptr, gd);
    const int K = sh_coeffs_for_degree(deg);
    double scale = 0, diff = 0;
    bool zero_above = true, untouched = true;
    for (std::size_t i = 0; i < m.size(); ++i)
      for (int ch = 0; ch < G::bands; ++ch)
        for (int k = 0; k < G::sh_coeffs; ++k) {
          const float a = gs.model.sh_row(i, ch)[k], b = gd.model.sh_row(i, ch)[k];
          if (ch < 1 || ch > 2) untouched = untouched && a == 0.0f && !std::signbit(a);
          else if (k >= K) zero_above = zero_above && a == 0.0f && !std::signbit(a);
          else {
            scale = std::max(scale, std::abs(double(b)));
            diff = std::max(diff, std::abs(double(a) - double(b)));
          }
        }
    CHECK(zero_above);
    CHECK(untouched);
    CHECK(scale > 0);
    CHECK(diff <= 1e-4 * scale);
  }
}

namespace {
/// Keeps what Rasterizer::backward hands a ColourGradientSink, and how often each row came.
template <class G>
struct RecordingSink final : ColourGradientSink<float> {
  GaussianModel<G, float> got;
  std::vector<std::atomic<int>> calls;
  explicit RecordingSink(std::size_t n) : got(n), calls(n * std::size_t(G::bands)) {}
  // Not inlined: inlined into the backward, GCC 12 (-march=x86-64-v3) cannot see that n is at
  // most the batch's lane count and warns of a copy past its row array (-Warray-bounds).
  [[gnu::noinline]] void consume(const std::uint32_t* ids, int n, std::uint32_t skip, int channel, const float* rows,
               std::size_t stride) override {
    for (int l = 0; l < n; ++l) {
      if (skip >> l & 1u) continue;
      std::memcpy(got.sh_row(ids[l], channel), rows + std::size_t(l) * stride, sizeof(float) * G::sh_coeffs);
      ++calls[std::size_t(channel) * got.size() + ids[l]];
    }
  }
};
}  // namespace

TEST_CASE("a colour sink gets the colour gradients the backward would store, once per visible Gaussian and channel") {
  // Degree 3 moves rows as transposed blocks, degree 1 value by value; a few Gaussians are handed
  // to double precision (a huge scale), whose rows come one lane at a time.
  using G = Gaussian<3, 3>;
  const Camera<float> cam = test_camera<float>(80, 56, 36.0, 30.0, 60.0);
  SceneParams sp;
  sp.n = 700;
  GaussianModel<G, float> m = random_scene<G, float>(cam, sp, 13);
  for (std::size_t i = 5; i < m.size(); i += 97) m.log_scales[3 * i + 1] = 21.0f;
  for (const int deg : {1, 3})
    for (const GradientFill fill : {GradientFill::dense, GradientFill::visible}) {
      CAPTURE(deg);
      Rasterizer<G, float, kSingleAA> r;
      r.forward(m, cam, middle_channels(deg));
      Image<float> wi(cam.width, cam.height, 2);
      std::mt19937_64 rng(7);
      std::uniform_real_distribution<float> u(-1.0f, 1.0f);
      for (float& v : wi.data) v = u(rng);
      Gradients<G, float> stored, fused;
      r.backward(wi, nullptr, nullptr, stored, fill);
      RecordingSink<G> sink(m.size());
      r.backward(wi, nullptr, nullptr, fused, fill, &sink);
      std::vector<bool> seen(m.size(), false);
      for (std::uint32_t i : r.visible()) seen[i] = true;
      REQUIRE(r.visible_count() > 100);
      int hard_seen = 0;
      for (std::size_t i = 5; i < m.size(); i += 97) hard_seen += seen[i];
      CHECK(hard_seen > 0);
      bool same = true, once = true, geometry = true;
      for (std::size_t i = 0; i < m.size(); ++i) {
        for (int ch = 0; ch < G::bands; ++ch) {
          const bool rendered = ch == 1 || ch == 2;
          once = once && sink.calls[std::size_t(ch) * m.size() + i] == (rendered && seen[i] ? 1 : 0);
          if (rendered && seen[i])
            same = same && std::memcmp(sink.got.sh_row(i, ch), stored.model.sh_row(i, ch), sizeof(float) * G::sh_coeffs) == 0;
        }
        if (seen[i])
          geometry = geometry && std::memcmp(&fused.model.means[3 * i], &stored.model.means[3 * i], 3 * sizeof(float)) == 0 &&
                     fused.model.opacity_logits[i] == stored.model.opacity_logits[i];
      }
      CHECK(same);
      CHECK(once);
      CHECK(geometry);
    }
}

namespace {

/// A scene whose back half is hidden: `per_side` random Gaussians in front of a wall of four
/// nearly opaque discs facing the camera and covering the whole image, which stops every pixel,
/// and `per_side` random Gaussians behind it, in the view but blending nowhere. Rows alternate
/// front and back, the wall's four rows last; `hidden[i]` marks the rows behind the wall.
template <class G>
GaussianModel<G, float> walled_scene(const Camera<float>& cam, std::size_t per_side, std::vector<bool>& hidden) {
  SceneParams fp;
  fp.n = per_side;
  fp.z_min = 1.5;
  fp.z_max = 2.5;
  SceneParams bp = fp;
  bp.z_min = 5;
  bp.z_max = 8;
  const GaussianModel<G, float> front = random_scene<G, float>(cam, fp, 21), back = random_scene<G, float>(cam, bp, 22);
  constexpr std::size_t kWall = 4;
  GaussianModel<G, float> m(2 * per_side + kWall);
  hidden.assign(m.size(), false);
  for (std::size_t j = 0; j < per_side; ++j) {
    copy_row(front, j, m, 2 * j);
    copy_row(back, j, m, 2 * j + 1);
    hidden[2 * j + 1] = true;
  }
  // The discs: the camera's axes as their rotation, 10 x 10 x 0.01 (about 170 px across at depth 3),
  // on the optical axis at depths 3.0 to 3.3, opacity 0.999.
  const Camera<double> c = cam.cast<double>();
  const Eigen::Quaterniond q(c.R.transpose());
  for (std::size_t w = 0; w < kWall; ++w) {
    const std::size_t i = 2 * per_side + w;
    const Eigen::Vector3d x = c.R.transpose() * (Eigen::Vector3d(0, 0, 3.0 + 0.1 * double(w)) - c.t);
    for (int a = 0; a < 3; ++a) m.means[3 * i + a] = float(x[a]);
    m.log_scales[3 * i] = m.log_scales[3 * i + 1] = std::log(10.0f);
    m.log_scales[3 * i + 2] = std::log(0.01f);
    const double wxyz[4] = {q.w(), q.x(), q.y(), q.z()};
    for (int a = 0; a < 4; ++a) m.quats[4 * i + a] = float(wxyz[a]);
    m.opacity_logits[i] = std::log(0.999f / 0.001f);
    for (int ch = 0; ch < G::bands; ++ch) m.sh_at(i, 0, ch) = 0.3f;
  }
  return m;
}

}  // namespace

TEST_CASE("Gaussians behind an opaque wall get a +0 gradient, and the others the same bits whatever their rows") {
  // The backward gives a visible Gaussian none of whose pairs blended +0 in every row it writes,
  // without its projection backward, and packs the others into full vectors: here every vector of
  // the interleaved rows holds both kinds. Moving the hidden rows first (whole vectors of them) must
  // change no bit of anyone's gradient, and a colour sink gets zero rows for the hidden ones.
  using G = Gaussian<3, 3>;
  const Camera<float> cam = test_camera<float>(64, 48, 30.0, 26.0, 50.0);
  std::vector<bool> hidden;
  const GaussianModel<G, float> m = walled_scene<G>(cam, 300, hidden);
  const std::size_t n = m.size();
  std::vector<std::size_t> row_of;  // the moved model's row i holds row row_of[i] of m: hidden ones first
  for (std::size_t i = 0; i < n; ++i)
    if (hidden[i]) row_of.push_back(i);
  for (std::size_t i = 0; i < n; ++i)
    if (!hidden[i]) row_of.push_back(i);
  const GaussianModel<G, float> moved = rows_moved(m, [&](std::size_t i) { return row_of[i]; });
  Image<float> wi(cam.width, cam.height, G::bands), wa(cam.width, cam.height, 1);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (float& v : wi.data) v = u(rng);
  for (float& v : wa.data) v = u(rng);

  constexpr float kSentinel = 12345.0f;
  const auto backward = [&](Rasterizer<G, float, kSingleAA>& r, const GaussianModel<G, float>& model) {
    r.forward(model, cam);
    Gradients<G, float> g;
    g.model.resize(n);
    for (auto* v : {&g.model.means, &g.model.log_scales, &g.model.quats, &g.model.opacity_logits, &g.model.sh})
      v->assign(v->size(), kSentinel);
    g.mean2d.assign(2 * n, kSentinel);
    r.backward(wi, &wa, nullptr, g, GradientFill::visible);
    return g;
  };
  Rasterizer<G, float, kSingleAA> ra, rb;
  const Gradients<G, float> ga = backward(ra, m), gb = backward(rb, moved);
  CHECK(std::memcmp(ra.image().data.data(), rb.image().data.data(), ra.image().data.size() * sizeof(float)) == 0);

  std::vector<bool> seen(n, false);
  for (std::uint32_t i : ra.visible()) seen[i] = true;
  std::size_t hidden_seen = 0, front_seen = 0;
  for (std::size_t i = 0; i < n; ++i) (hidden[i] ? hidden_seen : front_seen) += seen[i];
  REQUIRE(hidden_seen > 200);
  REQUIRE(front_seen > 200);

  std::vector<std::size_t> moved_row(n);
  for (std::size_t i = 0; i < n; ++i) moved_row[row_of[i]] = i;
  const float zero = 0.0f;
  std::size_t not_plus_zero = 0, moved_differs = 0, nonzero_front = 0;
  const auto row = [&](const float* a, const float* b, std::size_t i, std::size_t w) {  // row i of m, row moved_row[i]
    for (std::size_t k = 0; k < w; ++k) {
      if (std::memcmp(&a[k], &b[k], sizeof(float)) != 0) ++moved_differs;
      if (hidden[i] && std::memcmp(&a[k], &zero, sizeof(float)) != 0) ++not_plus_zero;
      if (!hidden[i] && a[k] != 0.0f) ++nonzero_front;
    }
  };
  for (std::size_t i = 0; i < n; ++i) {
    if (!seen[i]) continue;
    const std::size_t j = moved_row[i];
    row(&ga.model.means[3 * i], &gb.model.means[3 * j], i, 3);
    row(&ga.model.log_scales[3 * i], &gb.model.log_scales[3 * j], i, 3);
    row(&ga.model.quats[4 * i], &gb.model.quats[4 * j], i, 4);
    row(&ga.model.opacity_logits[i], &gb.model.opacity_logits[j], i, 1);
    row(&ga.mean2d[2 * i], &gb.mean2d[2 * j], i, 2);
    for (int ch = 0; ch < G::bands; ++ch) row(ga.model.sh_row(i, ch), gb.model.sh_row(j, ch), i, G::sh_coeffs);
  }
  CHECK(not_plus_zero == 0);
  CHECK(moved_differs == 0);
  CHECK(nonzero_front > 1000);  // the front Gaussians do get gradients

  // Through a colour sink: each visible Gaussian once per channel, zero rows for the hidden ones,
  // the stored rows for the others.
  RecordingSink<G> sink(n);
  Gradients<G, float> fused;
  ra.backward(wi, &wa, nullptr, fused, GradientFill::visible, &sink);
  bool once = true, same = true;
  for (std::size_t i = 0; i < n; ++i)
    for (int ch = 0; ch < G::bands; ++ch) {
      once = once && sink.calls[std::size_t(ch) * n + i] == (seen[i] ? 1 : 0);
      if (seen[i])
        same = same && std::memcmp(sink.got.sh_row(i, ch), ga.model.sh_row(i, ch), sizeof(float) * G::sh_coeffs) == 0;
    }
  CHECK(once);
  CHECK(same);
}

namespace {

/// `m` with its rows rotated by r: row i holds the Gaussian of row (i + r) mod n.
template <class G>
GaussianModel<G, float> rotated(const GaussianModel<G, float>& m, std::size_t r) {
  return rows_moved(m, [r, n = m.size()](std::size_t i) { return (i + r) % n; });
}

}  // namespace

TEST_CASE_TEMPLATE("the projection writes a whole batch of Gaussians as it writes them one at a time", G, Gaussian<1, 3>,
                   Gaussian<3, 3>) {
  // project_all stores a full batch of L consecutive rows as whole vectors and the last, partial
  // batch lane by lane. Rotating the rows moves every Gaussian through both and through every
  // lane: the radii, the visible rows, the image and the mean gradients must keep their bits.
  // Among the Gaussians: hard ones (handed to double precision), a non-finite colour, one behind
  // the camera and some off screen.
  constexpr int L = detail::kProjLanesF;
  const Camera<float> cam = test_camera<float>(70, 45, 41.0, 12.0, 55.0);
  SceneParams sp;
  // Full batches and a partial one, and more rows than the 24 set below: 43 with SSE2 (L = 4) as
  // with AVX2 (5 L + 3 rows there).
  sp.n = std::size_t(std::max(5 * L + 3, 43));
  sp.margin_px = 4;
  GaussianModel<G, float> m = random_scene<G, float>(cam, sp, 31);
  m.log_scales[3 * 2 + 1] = 25.0f;                                   // hard: scale e^25
  m.opacity_logits[7] = std::numeric_limits<float>::quiet_NaN();     // hard: non-finite
  m.sh_at(11, 0, 0) = std::numeric_limits<float>::infinity();        // culled: colour not finite
  m.quats[4 * 19 + 2] = 1e16f;                                       // hard: huge quaternion
  for (int k = 0; k < 3; ++k) m.means[3 * 23 + k] = -m.means[3 * 23 + k];  // behind the camera
  constexpr RasterOptions kOpt{.single_precision = true, .ties_by_mean = true};
  RenderSettings<float> rs;
  rs.band_count = G::bands;
  const std::size_t n = m.size();
  Rasterizer<G, float, kOpt> first;
  first.forward(m, cam, rs);
  Image<float> w(cam.width, cam.height, G::bands);  // dL/dimage
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (float& v : w.data) v = u(rng);
  Gradients<G, float> g0;
  first.backward(w, nullptr, nullptr, g0);
  REQUIRE(first.visible_count() > n / 2);
  REQUIRE(first.visible_count() < n - 4);
  for (std::size_t r = 1; r <= std::size_t(L); ++r) {
    INFO("rows rotated by ", r);
    const GaussianModel<G, float> mr = rotated(m, r);
    Rasterizer<G, float, kOpt> rast;
    rast.forward(mr, cam, rs);
    Gradients<G, float> gr;
    rast.backward(w, nullptr, nullptr, gr);
    CHECK(std::memcmp(rast.image().data.data(), first.image().data.data(), first.image().data.size() * sizeof(float)) == 0);
    CHECK(rast.fragments() == first.fragments());
    bool same_radii = true, same_visible = rast.visible_count() == first.visible_count(), same_grad = true;
    std::vector<std::uint8_t> seen(n, 0);
    for (std::uint32_t v : rast.visible()) seen[(v + r) % n] = 1;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t s = (i + r) % n;  // row i of the rotated model is row s of m
      same_radii = same_radii && rast.radii()[2 * i] == first.radii()[2 * s] && rast.radii()[2 * i + 1] == first.radii()[2 * s + 1];
      for (int k = 0; k < 3; ++k) same_grad = same_grad && gr.model.means[3 * i + k] == g0.model.means[3 * s + k];
    }
    for (std::uint32_t v : first.visible()) same_visible = same_visible && seen[v] == 1;
    CHECK(same_radii);
    CHECK(same_visible);
    CHECK(same_grad);
  }
}

}  // namespace test_rasterize_single
