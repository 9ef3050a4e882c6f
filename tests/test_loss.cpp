// tests/test_loss.cpp
// Checks loss.hpp against a slow, direct 11x11 SSIM reference and finite differences in double.
#include <doctest/doctest.h>

#include <omp.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "msgs/loss.hpp"

namespace test_loss {
using msgs::Image;

namespace {

// ---- slow reference: direct 2-D window over the zero-padded image, everything in double ----

double ref_window(int du, int dv) {
  static const std::vector<double> g = [] {
    std::vector<double> v(11);
    double sum = 0;
    for (int k = 0; k < 11; ++k) sum += v[k] = std::exp(-(k - 5.0) * (k - 5.0) / (2 * 1.5 * 1.5));
    for (double& e : v) e /= sum;
    return v;
  }();
  return g[du + 5] * g[dv + 5];
}

// `valid`: pytorch-msssim's mean over the pixels whose window fits (a dimension shorter than 11
// keeps every pixel, zero padded).
double ref_ssim(const Image<double>& x, const Image<double>& y, bool valid = false) {
  const double c1 = 1e-4, c2 = 9e-4;
  const int mx0 = valid && x.width >= 11 ? 5 : 0, mx1 = valid && x.width >= 11 ? x.width - 5 : x.width;
  const int my0 = valid && x.height >= 11 ? 5 : 0, my1 = valid && x.height >= 11 ? x.height - 5 : x.height;
  double total = 0;
  for (int c = 0; c < x.channels; ++c)
    for (int py = my0; py < my1; ++py)
      for (int px = mx0; px < mx1; ++px) {
        double mx = 0, my = 0, exx = 0, eyy = 0, exy = 0;
        for (int dv = -5; dv <= 5; ++dv)
          for (int du = -5; du <= 5; ++du) {
            const int qx = px + du, qy = py + dv;
            if (qx < 0 || qy < 0 || qx >= x.width || qy >= x.height) continue;  // zero padding
            const double w = ref_window(du, dv), a = x.at(qx, qy, c), b = y.at(qx, qy, c);
            mx += w * a; my += w * b; exx += w * a * a; eyy += w * b * b; exy += w * a * b;
          }
        const double sxx = exx - mx * mx, syy = eyy - my * my, sxy = exy - mx * my;
        total += ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2));
      }
  return total / (double(mx1 - mx0) * double(my1 - my0) * double(x.channels));
}

double ref_loss(const Image<double>& x, const Image<double>& y, bool valid = false) {
  double l1 = 0;
  for (std::size_t i = 0; i < x.size(); ++i) l1 += std::abs(x.data[i] - y.data[i]);
  l1 /= static_cast<double>(x.size());
  return 0.8 * l1 + 0.2 * (1.0 - ref_ssim(x, y, valid));
}

template <class S>
Image<S> random_image(int w, int h, int c, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Image<S> im(w, h, c);
  for (auto& v : im.data) v = static_cast<S>(u(rng));
  return im;
}

template <class T, class S>
Image<T> cast_image(const Image<S>& im) {
  Image<T> out(im.width, im.height, im.channels);
  for (std::size_t i = 0; i < im.size(); ++i) out.data[i] = static_cast<T>(im.data[i]);
  return out;
}

struct Size3 { int w, h, c; };

/// `grad` against central differences (h = 1e-6) of the double reference loss at x.
void check_gradient_fd(Image<double> x, const Image<double>& y, const Image<double>& grad, bool valid) {
  const double h = 1e-6;
  double max_err = 0, max_g = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double x0 = x.data[i];
    x.data[i] = x0 + h;
    const double lp = ref_loss(x, y, valid);
    x.data[i] = x0 - h;
    const double lm = ref_loss(x, y, valid);
    x.data[i] = x0;
    const double fd = (lp - lm) / (2 * h);
    max_err = std::max(max_err, std::abs(fd - grad.data[i]));
    max_g = std::max(max_g, std::abs(fd));
  }
  CAPTURE(max_g);
  CHECK(max_err < 1e-8 + 1e-5 * max_g);
}

}  // namespace

TEST_CASE("ssim window is a normalised Gaussian of sigma 1.5") {
  const auto w = msgs::ssim_window_1d<double>();
  double sum = 0;
  for (double v : w) sum += v;
  CHECK(sum == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(w[5] / w[4] == doctest::Approx(std::exp(1.0 / (2 * 2.25))).epsilon(1e-14));
  CHECK(w[0] == w[10]);
}

TEST_CASE("fast SSIM matches the direct 2-D reference, including images smaller than the window") {
  const Size3 sizes[] = {{1, 1, 1}, {1, 1, 3}, {2, 3, 7}, {4, 4, 3}, {11, 11, 1}, {12, 5, 3}, {17, 13, 7}, {33, 20, 3}};
  std::uint32_t seed = 1;
  for (const auto& s : sizes) {
    CAPTURE(s.w); CAPTURE(s.h); CAPTURE(s.c);
    const auto x = random_image<double>(s.w, s.h, s.c, seed++);
    auto y = random_image<double>(s.w, s.h, s.c, seed++);
    // Correlate y with x so the SSIM is far from 0 and the test sees the structure term.
    for (std::size_t i = 0; i < y.size(); ++i) y.data[i] = 0.7 * x.data[i] + 0.3 * y.data[i];
    const double ref = ref_ssim(x, y);
    CHECK(msgs::ssim(x, y) == doctest::Approx(ref).epsilon(1e-12));
    // Float pipeline against the double reference.
    CHECK(msgs::ssim(cast_image<float>(x), cast_image<float>(y)) == doctest::Approx(ref).epsilon(2e-5));
    // Per-channel means average to the whole.
    const auto pc = msgs::ssim_per_channel(x, y);
    REQUIRE(pc.size() == static_cast<std::size_t>(s.c));
    double m = 0;
    for (double v : pc) m += v;
    CHECK(m / s.c == doctest::Approx(ref).epsilon(1e-12));
  }
}

TEST_CASE("ssim of an image with itself is 1 and photometric loss is 0") {
  const auto x = random_image<float>(23, 19, 3, 7);
  CHECK(msgs::ssim(x, x) == doctest::Approx(1.0).epsilon(1e-6));
  CHECK(msgs::photometric_loss(x, x) == doctest::Approx(0.0).epsilon(1e-6));
}

TEST_CASE("photometric loss value matches the reference") {
  const auto x = random_image<double>(29, 17, 7, 11);
  const auto y = random_image<double>(29, 17, 7, 12);
  CHECK(msgs::photometric_loss(x, y) == doctest::Approx(ref_loss(x, y)).epsilon(1e-12));
}

TEST_CASE("photometric loss gradient matches central differences of the reference (double)") {
  const Size3 sizes[] = {{1, 1, 1}, {1, 1, 3}, {1, 1, 7}, {3, 2, 1}, {4, 3, 3}, {7, 9, 7}, {13, 16, 1}, {20, 14, 3}};
  std::uint32_t seed = 100;
  for (const auto& s : sizes) {
    CAPTURE(s.w); CAPTURE(s.h); CAPTURE(s.c);
    auto x = random_image<double>(s.w, s.h, s.c, seed++);
    auto y = random_image<double>(s.w, s.h, s.c, seed++);
    // Keep every |x - y| well away from the L1 kink so central differences are valid.
    for (std::size_t i = 0; i < x.size(); ++i)
      if (std::abs(x.data[i] - y.data[i]) < 1e-3) x.data[i] += 2e-3;
    Image<double> grad;
    msgs::SsimWorkspace<double> ws;
    const double value = msgs::photometric_loss(x, y, &grad, ws);
    CHECK(value == doctest::Approx(ref_loss(x, y)).epsilon(1e-12));
    REQUIRE(grad.size() == x.size());
    check_gradient_fd(x, y, grad, false);
  }
}

TEST_CASE("valid-window SSIM (pytorch-msssim) matches the direct reference, value and gradient") {
  const Size3 sizes[] = {{4, 4, 3}, {11, 11, 1}, {12, 5, 3}, {5, 14, 1}, {17, 13, 7}, {24, 16, 3}};
  std::uint32_t seed = 300;
  msgs::PhotometricLossConfig cfg;
  cfg.ssim_border = msgs::SsimBorder::valid;
  msgs::SsimWorkspace<double> ws;  // shared across sizes and modes: stale borders must not leak
  for (const auto& s : sizes) {
    CAPTURE(s.w); CAPTURE(s.h); CAPTURE(s.c);
    auto x = random_image<double>(s.w, s.h, s.c, seed++);
    auto y = random_image<double>(s.w, s.h, s.c, seed++);
    for (std::size_t i = 0; i < y.size(); ++i) y.data[i] = 0.7 * x.data[i] + 0.3 * y.data[i];
    for (std::size_t i = 0; i < x.size(); ++i)
      if (std::abs(x.data[i] - y.data[i]) < 1e-3) x.data[i] += 2e-3;
    const double ref = ref_ssim(x, y, true);
    CHECK(msgs::ssim(x, y, msgs::SsimBorder::valid) == doctest::Approx(ref).epsilon(1e-12));
    if (s.w >= 11 && s.h >= 11) CHECK(std::abs(ref - ref_ssim(x, y, false)) > 1e-6);  // the modes differ
    const auto pc = msgs::ssim_per_channel(x, y, msgs::SsimBorder::valid);
    double m = 0;
    for (double v : pc) m += v;
    CHECK(m / s.c == doctest::Approx(ref).epsilon(1e-12));
    Image<double> grad;
    (void)msgs::photometric_loss(x, y, &grad, ws);  // same mode first, to dirty the workspace
    const double value = msgs::photometric_loss(x, y, &grad, ws, cfg);
    CHECK(value == doctest::Approx(ref_loss(x, y, true)).epsilon(1e-12));
    check_gradient_fd(x, y, grad, true);
  }
}

TEST_CASE("float gradient agrees with the double gradient") {
  const auto xd = random_image<double>(37, 21, 3, 5);
  const auto yd = random_image<double>(37, 21, 3, 6);
  Image<double> gd;
  Image<float> gf;
  msgs::SsimWorkspace<double> wsd;
  msgs::SsimWorkspace<float> wsf;
  const double ld = msgs::photometric_loss(xd, yd, &gd, wsd);
  const double lf = msgs::photometric_loss(cast_image<float>(xd), cast_image<float>(yd), &gf, wsf);
  CHECK(lf == doctest::Approx(ld).epsilon(1e-5));
  double max_err = 0, max_g = 0;
  for (std::size_t i = 0; i < gd.size(); ++i) {
    max_err = std::max(max_err, std::abs(gd.data[i] - static_cast<double>(gf.data[i])));
    max_g = std::max(max_g, std::abs(gd.data[i]));
  }
  CHECK(max_err < 1e-4 * max_g);
}

TEST_CASE("loss and gradient are bit-identical whatever the thread count") {
  const int saved = omp_get_max_threads();
  // Tall enough for several row blocks, and shorter than the thread count.
  // Heights that leave partial row groups (of 4) at thread boundaries, and a thread per row.
  for (const Size3 s : {Size3{67, 45, 3}, Size3{5, 3, 1}, Size3{1, 1, 7}, Size3{9, 23, 7}, Size3{14, 11, 1}}) {
    CAPTURE(s.w); CAPTURE(s.h); CAPTURE(s.c);
    const auto x = random_image<float>(s.w, s.h, s.c, 21);
    const auto y = random_image<float>(s.w, s.h, s.c, 22);
    std::vector<float> first;
    double first_value = 0;
    for (int threads : {1, 2, 3, 5, 8}) {
      omp_set_num_threads(threads);
      Image<float> g;
      msgs::SsimWorkspace<float> ws;
      const double v = msgs::photometric_loss(x, y, &g, ws);
      if (first.empty()) {
        first = g.data;
        first_value = v;
      } else {
        CHECK(v == first_value);
        CHECK(g.data == first);
      }
    }
  }
  omp_set_num_threads(saved);
}

TEST_CASE("the fused loss pass equals ssim_fwd + L1 + ssim_bwd, bit for bit") {
  // photometric_loss runs SSIM's forward and backward and the L1 term as one pass over the images;
  // the separate functions keep the derivative maps in memory. Same operations per value, so the
  // same bits, for any height (partial row groups, thread halos) and thread count.
  const int saved = omp_get_max_threads();
  for (const auto border : {msgs::SsimBorder::same, msgs::SsimBorder::valid})
    for (const Size3 s : {Size3{1, 1, 1}, Size3{3, 2, 3}, Size3{12, 5, 7}, Size3{17, 13, 1}, Size3{40, 27, 3},
                          Size3{23, 64, 1}, Size3{6, 19, 9}})
      for (int threads : {1, 2, 3, 7}) {
        CAPTURE(s.w); CAPTURE(s.h); CAPTURE(s.c); CAPTURE(threads);
        omp_set_num_threads(threads);
        const auto x = random_image<float>(s.w, s.h, s.c, 41);
        const auto y = random_image<float>(s.w, s.h, s.c, 42);
        msgs::PhotometricLossConfig cfg;
        cfg.ssim_border = border;
        Image<float> fused;
        msgs::SsimWorkspace<float> ws;
        double mse = 0;
        const double value = msgs::photometric_loss(x, y, &fused, ws, cfg, &mse);
        // The same loss from the separate passes.
        msgs::SsimWorkspace<float> ws2;
        const double ssim_value = msgs::ssim_fwd(x, y, ws2, true, nullptr, border);
        const float l1_scale = static_cast<float>(0.8 / static_cast<double>(x.size()));
        Image<float> separate(s.w, s.h, s.c);
        double l1 = 0, se = 0;
        for (std::size_t i = 0; i < x.size(); ++i) {
          const float d = x.data[i] - y.data[i];
          separate.data[i] = d > 0 ? l1_scale : (d < 0 ? -l1_scale : 0.0f);
          l1 += std::abs(static_cast<double>(d));
          se += (static_cast<double>(x.data[i]) - y.data[i]) * (static_cast<double>(x.data[i]) - y.data[i]);
        }
        msgs::ssim_bwd(x, y, ws2, -0.2f, separate);
        CHECK(fused.data == separate.data);
        const double expect = 0.8 * (l1 / static_cast<double>(x.size())) + 0.2 * (1.0 - ssim_value);
        CHECK(value == doctest::Approx(expect).epsilon(1e-12));
        CHECK(mse == doctest::Approx(se / static_cast<double>(x.size())).epsilon(1e-12));
        // Without a gradient (the evaluation path) the value is the same.
        CHECK(msgs::photometric_loss(x, y, static_cast<Image<float>*>(nullptr), ws, cfg) == value);
      }
  omp_set_num_threads(saved);
}

TEST_CASE("per-channel sums of the SSIM map: exact order-independent cases and every channel count") {
  // channel_sums keeps 16 partial sums per channel; check it against a plain sum in double for
  // lengths around its block size, and exactly on values whose sums are exact in any order.
  for (int C : {1, 2, 3, 7, 8, 9, 12})
    for (std::ptrdiff_t n : {0, 1, 15, 16, 17, 33, 250}) {
      CAPTURE(C); CAPTURE(n);
      std::vector<float> p(static_cast<std::size_t>(n * C));
      std::mt19937 rng(static_cast<std::uint32_t>(C * 1000 + n));
      std::uniform_int_distribution<int> u(-64, 64);
      for (auto& v : p) v = static_cast<float>(u(rng)) * 0.125f;  // sums exact in double
      std::vector<double> got(static_cast<std::size_t>(C), -1.0);
      msgs::detail::channel_sums(p.data(), n, C, got.data());
      for (int c = 0; c < C; ++c) {
        double want = 0;
        for (std::ptrdiff_t i = 0; i < n; ++i) want += p[static_cast<std::size_t>(i * C + c)];
        CHECK(got[static_cast<std::size_t>(c)] == want);
      }
    }
}

TEST_CASE("workspace reuse across shapes gives the same result as a fresh one") {
  msgs::SsimWorkspace<float> ws;
  Image<float> g1, g2;
  const auto a = random_image<float>(40, 30, 3, 1), b = random_image<float>(40, 30, 3, 2);
  const auto c = random_image<float>(9, 31, 1, 3), d = random_image<float>(9, 31, 1, 4);
  msgs::photometric_loss(a, b, &g1, ws);
  const double v1 = msgs::photometric_loss(c, d, &g1, ws);
  msgs::SsimWorkspace<float> fresh;
  const double v2 = msgs::photometric_loss(c, d, &g2, fresh);
  CHECK(v1 == v2);
  CHECK(g1.data == g2.data);
}

TEST_CASE("shape mismatches and a stale workspace are reported") {
  const Image<float> a(4, 4, 3), b(4, 4, 1);
  CHECK_THROWS_AS(msgs::photometric_loss(a, b), std::invalid_argument);
  CHECK_THROWS_AS(msgs::psnr(a, b), std::invalid_argument);
  Image<float> bad(4, 4, 3);
  bad.data.pop_back();
  CHECK_THROWS_AS(msgs::ssim(a, bad), std::invalid_argument);
  msgs::SsimWorkspace<float> ws;
  Image<float> g(4, 4, 3);
  CHECK_THROWS_AS(msgs::ssim_bwd(a, a, ws, 1.0f, g), std::logic_error);
}

TEST_CASE("PSNR: known values, per channel, identical images finite") {
  Image<float> a(8, 4, 2, 0.0f), b(8, 4, 2, 0.0f);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) {
      b.at(x, y, 0) = 0.1f;   // MSE 0.01   -> 20 dB
      b.at(x, y, 1) = 0.01f;  // MSE 0.0001 -> 40 dB
    }
  const auto pc = msgs::psnr_per_channel(a, b);
  CHECK(pc[0] == doctest::Approx(20.0).epsilon(1e-6));
  CHECK(pc[1] == doctest::Approx(40.0).epsilon(1e-5));
  CHECK(msgs::psnr(a, b) == doctest::Approx(10.0 * std::log10(1.0 / ((0.01 + 0.0001) / 2))).epsilon(1e-6));
  CHECK(msgs::psnr(a, a) == doctest::Approx(100.0));
  CHECK(std::isfinite(msgs::psnr_per_channel(a, a)[1]));
}

TEST_CASE("photometric loss reports the MSE of psnr, and the same loss and gradient with it") {
  // 23 x 3 = 69 values a row: the 4-way partial sums end on a remainder.
  const auto x = random_image<float>(23, 19, 3, 41);
  const auto y = random_image<float>(23, 19, 3, 42);
  msgs::SsimWorkspace<float> ws;
  Image<float> g0, g1;
  const double l0 = msgs::photometric_loss(x, y, &g0, ws);
  double mse = -1;
  const double l1 = msgs::photometric_loss(x, y, &g1, ws, {}, &mse);
  CHECK(l1 == l0);
  CHECK(g1.data == g0.data);
  CHECK(msgs::psnr_from_mse(mse) == doctest::Approx(msgs::psnr(x, y)).epsilon(1e-12));
  CHECK(msgs::psnr_from_mse(0.0) == doctest::Approx(100.0));
  mse = -1;
  const Image<float> empty(0, 0, 3);
  CHECK(msgs::photometric_loss(empty, empty, static_cast<Image<float>*>(nullptr), ws, {}, &mse) == 0.0);
  CHECK(mse == 0.0);
}

TEST_CASE("scale regulariser: value, finite differences, ties, runaway scales") {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-4.0, 1.0);
  const int n = 200;
  std::vector<double> ls(3 * n);
  for (auto& v : ls) v = u(rng);
  // Hand-computed value.
  double expect = 0;
  for (int i = 0; i < n; ++i) {
    const double smax = std::exp(std::max({ls[3 * i], ls[3 * i + 1], ls[3 * i + 2]}));
    const double smin = std::exp(std::min({ls[3 * i], ls[3 * i + 1], ls[3 * i + 2]}));
    expect += std::max(smax / smin, 10.0) - 10.0;
  }
  expect = 0.1 * expect / n;
  std::vector<double> grad(3 * n, 0.0);
  const double v = msgs::scale_reg<double>(ls, grad);
  CHECK(v == doctest::Approx(expect).epsilon(1e-13));
  CHECK(v > 0);

  // Central differences (no ties with random values; skip entries sitting near the ratio-10 kink).
  const double h = 1e-6;
  std::vector<double> none;
  for (std::size_t i = 0; i < ls.size(); ++i) {
    const double l0 = ls[i];
    ls[i] = l0 + h;
    const double fp = msgs::scale_reg<double>(ls, none);
    ls[i] = l0 - h;
    const double fm = msgs::scale_reg<double>(ls, none);
    ls[i] = l0;
    const std::size_t g = i / 3;
    const double r = std::exp(std::max({ls[3 * g], ls[3 * g + 1], ls[3 * g + 2]}) -
                              std::min({ls[3 * g], ls[3 * g + 1], ls[3 * g + 2]}));
    if (std::abs(r - 10.0) < 1e-3) continue;
    CHECK(grad[i] == doctest::Approx((fp - fm) / (2 * h)).epsilon(1e-6).scale(1e-9));
  }

  // Gradient is added, not written.
  std::vector<double> ones(3 * n, 1.0);
  msgs::scale_reg<double>(ls, ones);
  for (std::size_t i = 0; i < ls.size(); ++i) CHECK(ones[i] == doctest::Approx(1.0 + grad[i]));

  // Tie on the maximum shares the gradient evenly.
  std::vector<float> tie = {std::log(20.0f), std::log(20.0f), 0.0f};
  std::vector<float> gt(3, 0.0f);
  const double vt = msgs::scale_reg<float>(tie, gt);
  CHECK(vt == doctest::Approx(0.1 * 10.0).epsilon(1e-5));
  CHECK(gt[0] == doctest::Approx(0.1 * 20.0 / 2).epsilon(1e-5));
  CHECK(gt[1] == gt[0]);
  CHECK(gt[2] == doctest::Approx(-0.1 * 20.0).epsilon(1e-5));

  // Runaway log-scales stay finite; a NaN log-scale contributes nothing.
  std::vector<float> wild = {200.0f, -200.0f, 0.0f, std::nanf(""), 0.0f, 1.0f};
  std::vector<float> gw(6, 0.0f);
  const double vw = msgs::scale_reg<float>(wild, gw);
  CHECK(std::isfinite(vw));
  for (float g : gw) CHECK(std::isfinite(g));
  CHECK(gw[3] == 0.0f);
}

TEST_CASE("scale regulariser on a model adds into grad.log_scales only") {
  using G = msgs::Gaussian<1, 0>;
  msgs::GaussianModel<G, float> m(2), g(2);
  m.log_scales = {0.0f, 0.0f, 3.0f, 0.0f, 0.0f, 0.0f};  // ratio e^3 ~ 20.1 and 1
  g.set_zero();
  const double v = msgs::scale_reg(m, &g);
  CHECK(v == doctest::Approx(0.1 * (std::exp(3.0) - 10.0) / 2).epsilon(1e-6));
  CHECK(g.log_scales[2] == doctest::Approx(0.1 * std::exp(3.0) / 2).epsilon(1e-6));
  CHECK(g.log_scales[0] == doctest::Approx(-0.1 * std::exp(3.0) / 4).epsilon(1e-6));  // min tie of two
  CHECK(g.log_scales[3] == 0.0f);
  CHECK(g.means[0] == 0.0f);
  CHECK(msgs::scale_reg(m, static_cast<msgs::GaussianModel<G, float>*>(nullptr)) == doctest::Approx(v));
}

TEST_CASE("scale regulariser over a row list: those rows only, normalised by N, others untouched") {
  const std::size_t n = 5000;
  std::vector<float> ls(3 * n), g_all(3 * n, 0.0f), g_rows(3 * n, 7.0f);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-4.0f, 4.0f);
  for (float& v : ls) v = u(rng);
  std::vector<std::uint32_t> rows;
  for (std::size_t i = 0; i < n; i += 2) rows.push_back(std::uint32_t(i));
  // The reference: every row, with the unlisted rows made isotropic (no penalty, no gradient).
  std::vector<float> ls_masked = ls;
  for (std::size_t i = 1; i < n; i += 2) ls_masked[3 * i] = ls_masked[3 * i + 1] = ls_masked[3 * i + 2] = 0.0f;
  const double want = msgs::scale_reg<float>(ls_masked, g_all);
  const double got = msgs::scale_reg<float>(ls, g_rows, {}, &rows);
  CHECK(got == doctest::Approx(want).epsilon(1e-12));
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      const float r = g_rows[3 * i + std::size_t(a)];
      if (i % 2 == 0) CHECK(r - 7.0f == doctest::Approx(g_all[3 * i + std::size_t(a)]).epsilon(1e-5));
      else CHECK(r == 7.0f);
    }
  const std::vector<std::uint32_t> outside = {std::uint32_t(n)};
  CHECK_THROWS_AS(msgs::scale_reg<float>(ls, g_rows, {}, &outside), std::invalid_argument);
}

}  // namespace test_loss
