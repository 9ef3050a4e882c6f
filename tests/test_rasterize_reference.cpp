// tests/test_rasterize_reference.cpp
// The fast tile rasterizer (float) against the slow per-pixel reference (double): every band count,
// SH degree, band subset, active degree, background, depth and antialiased option.
#include <doctest/doctest.h>

#include <msgs/rasterize.hpp>

#include "reference_renderer.hpp"

#include <bit>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <utility>

namespace test_rasterize_reference {
using namespace msgs;
using namespace msgs::testing;

namespace {

/// The worst pixel of a comparison, for a readable failure message.
template <class A, class B>
std::string worst_pixel(const Image<A>& fast, const Image<B>& ref) {
  double worst = -1;
  int wx = 0, wy = 0, wc = 0;
  for (int y = 0; y < ref.height; ++y)
    for (int x = 0; x < ref.width; ++x)
      for (int c = 0; c < ref.channels; ++c) {
        const double d = std::abs(double(fast.at(x, y, c)) - double(ref.at(x, y, c)));
        if (!(d <= worst)) { worst = std::isnan(d) ? INFINITY : d; wx = x; wy = y; wc = c; }
      }
  char buf[200];
  std::snprintf(buf, sizeof buf, "worst at pixel (x=%d, y=%d, c=%d): fast %.9g reference %.9g", wx, wy, wc,
                double(fast.at(wx, wy, wc)), double(ref.at(wx, wy, wc)));
  return buf;
}

ReferenceSettings to_reference(const RenderSettings<float>& rs, RasterOptions opt) {
  ReferenceSettings r;
  r.band_first = rs.band_first;
  r.band_count = rs.band_count;
  r.sh_degree = rs.sh_degree;
  r.background.assign(rs.background.begin(), rs.background.end());
  r.depth = opt.depth;
  r.antialiased = opt.antialiased;
  return r;
}

/// Render a seeded random scene with the fast path and the reference; compare image, alpha,
/// depth (when enabled), culling and the fragment count.
template <class G, RasterOptions Opt = RasterOptions{}>
void check_scene(const Camera<float>& cam, const SceneParams& sp, std::uint64_t seed,
                 const RenderSettings<float>& rs = {}, double tol = 1e-5) {
  const GaussianModel<G, float> model = random_scene<G, float>(cam, sp, seed);
  Rasterizer<G, float, Opt> fast;
  fast.forward(model, cam, rs);
  const ReferenceResult<double> ref = reference_render<double>(model, cam, to_reference(rs, Opt));

  INFO("bands=", G::bands, " sh=", G::sh_degree, " seed=", seed, " n=", sp.n, " image ", cam.width, "x",
       cam.height, " band_first=", rs.band_first, " band_count=", rs.band_count, " sh_degree=", rs.sh_degree);
  REQUIRE(fast.image().width == cam.width);
  REQUIRE(fast.image().height == cam.height);
  REQUIRE(fast.image().channels == ref.image.channels);
  REQUIRE(fast.alpha().channels == 1);
  {
    INFO("image: ", worst_pixel(fast.image(), ref.image));
    CHECK(max_abs_diff(fast.image().data, ref.image.data) <= tol);
  }
  {
    INFO("alpha: ", worst_pixel(fast.alpha(), ref.alpha));
    CHECK(max_abs_diff(fast.alpha().data, ref.alpha.data) <= tol);
  }
  if constexpr (Opt.depth) {
    // Depth is a sum of w_i z_i with z up to z_max: compare relative to the depth scale.
    INFO("depth: ", worst_pixel(fast.depth(), ref.depth));
    CHECK(max_abs_diff(fast.depth().data, ref.depth.data) <= tol * sp.z_max);
  }
  // Culled Gaussians have zero radii; every Gaussian that paints a pixel has a positive radius.
  REQUIRE(fast.radii().size() == 2 * model.size());
  std::size_t culled_with_radius = 0;
  for (std::size_t i = 0; i < model.size(); ++i)
    if (ref.splats[i].culled && (fast.radii()[2 * i] != 0 || fast.radii()[2 * i + 1] != 0)) ++culled_with_radius;
  CHECK(culled_with_radius == 0);
  CHECK(fast.fragments() == ref.fragments);
  // The blend evaluates whole vectors of lanes, and every blended fragment is one of them.
  CHECK(fast.blend_lanes() >= fast.fragments());
  CHECK(fast.blend_lanes() % std::uint64_t(detail::BlockVec<float>::kLanes) == 0);
}

constexpr RasterOptions kDepth{.depth = true, .antialiased = false};
constexpr RasterOptions kAA{.depth = false, .antialiased = true};
constexpr RasterOptions kDepthAA{.depth = true, .antialiased = true};

}  // namespace

TEST_CASE_TEMPLATE("fast forward matches the reference for every band count and SH degree", G,  //
                   Gaussian<1, 0>, Gaussian<1, 1>, Gaussian<1, 2>, Gaussian<1, 3>,              //
                   Gaussian<3, 0>, Gaussian<3, 1>, Gaussian<3, 2>, Gaussian<3, 3>,              //
                   Gaussian<7, 0>, Gaussian<7, 1>, Gaussian<7, 2>, Gaussian<7, 3>) {
  SceneParams sp;
  sp.n = 150;
  SUBCASE("non-square image, principal point far off centre, per-band background") {
    const Camera<float> cam = test_camera<float>(53, 37, 9.5, 30.25);
    RenderSettings<float> rs;
    for (int c = 0; c < G::bands; ++c) rs.background.push_back(0.1f + 0.11f * float(c));
    check_scene<G>(cam, sp, 11, rs);
  }
  SUBCASE("several tiles, broadcast background") {
    const Camera<float> cam = test_camera<float>(70, 45, 41.0, 12.0, 55.0);
    RenderSettings<float> rs;
    rs.background = {0.3f};
    sp.n = 250;
    check_scene<G>(cam, sp, 12, rs);
  }
  SUBCASE("default settings, square image") {
    const Camera<float> cam = test_camera<float>(32, 32, 16, 16, 30.0);
    check_scene<G>(cam, sp, 13);
  }
}

TEST_CASE("band subsets of a <7> model") {
  using G = Gaussian<7, 3>;
  const Camera<float> cam = test_camera<float>(53, 37, 40.0, 5.0);
  SceneParams sp;
  sp.n = 200;
  for (int first = 0; first < 7; ++first) {
    RenderSettings<float> rs;
    rs.band_first = first;
    rs.band_count = 1;
    rs.background = {0.25f};
    check_scene<G>(cam, sp, 21, rs);
  }
  RenderSettings<float> rgb;
  rgb.band_first = 0;
  rgb.band_count = 3;
  rgb.background = {0.149f, 0.165f, 0.216f};
  check_scene<G>(cam, sp, 22, rgb);
  RenderSettings<float> spectral;
  spectral.band_first = 3;  // band_count -1: all channels from band_first
  spectral.background = {0.1f, 0.2f, 0.3f, 0.4f};
  check_scene<G>(cam, sp, 23, spectral);
}

TEST_CASE("active SH degree below the model degree") {
  const Camera<float> cam = test_camera<float>(53, 37, 12.0, 20.0);
  SceneParams sp;
  sp.n = 150;
  sp.sh_rest = 0.3;  // large higher orders, so rendering them by mistake shows
  for (int deg = 0; deg <= 3; ++deg) {
    RenderSettings<float> rs;
    rs.sh_degree = deg;
    check_scene<Gaussian<7, 3>>(cam, sp, 31, rs);
    rs.band_first = 5;
    rs.band_count = 2;
    check_scene<Gaussian<7, 3>>(cam, sp, 32, rs);
  }
  RenderSettings<float> rs;
  rs.sh_degree = 1;
  check_scene<Gaussian<3, 2>>(cam, sp, 33, rs);
}

TEST_CASE("depth and antialiased options") {
  using G = Gaussian<3, 3>;
  const Camera<float> cam = test_camera<float>(53, 37, 45.0, 8.0);
  SceneParams sp;
  sp.n = 200;
  RenderSettings<float> rs;
  rs.background = {0.5f, 0.25f, 0.75f};
  check_scene<G, kDepth>(cam, sp, 41, rs);
  check_scene<G, kAA>(cam, sp, 42, rs);
  check_scene<G, kDepthAA>(cam, sp, 43, rs);
  // Small splats are where the compensation matters most.
  SceneParams tiny = sp;
  tiny.log_scale_min = std::log(0.002);
  tiny.log_scale_max = std::log(0.02);
  check_scene<G, kDepthAA>(cam, tiny, 44, rs);
  RenderSettings<float> one;
  one.band_first = 1;
  one.band_count = 1;
  check_scene<Gaussian<7, 3>, kDepthAA>(cam, sp, 45, one);
}

TEST_CASE("wide depth range: Gaussians behind the camera, near the near plane, off screen") {
  using G = Gaussian<3, 1>;
  const Camera<float> cam = test_camera<float>(53, 37, 50.0, 3.0);
  SceneParams sp;
  sp.n = 300;
  sp.z_min = -1.0;   // some behind the camera: culled
  sp.z_max = 8.0;
  sp.margin_px = 60;  // far enough outside that the tan-fov clamp of the EWA Jacobian is active
  check_scene<G, kDepth>(cam, sp, 51);
  sp.z_min = 0.02;
  sp.z_max = 0.6;    // close to the near plane: big splats
  sp.n = 60;
  check_scene<G, kDepth>(cam, sp, 52);
}

TEST_CASE("thousands of Gaussians: deep tile lists") {
  const Camera<float> cam = test_camera<float>(96, 64, 30.0, 40.0, 80.0);
  SceneParams sp;
  sp.n = 3000;
  sp.log_scale_max = std::log(0.4);
  RenderSettings<float> rs;
  rs.background = {0.2f, 0.4f, 0.6f};
  check_scene<Gaussian<3, 3>, kDepthAA>(cam, sp, 71, rs);
}

TEST_CASE("1x1 image and very opaque scenes (early termination)") {
  using G = Gaussian<3, 0>;
  SceneParams sp;
  sp.n = 200;
  sp.opacity_min = 0.9;
  sp.opacity_max = 0.999;  // above the 0.99 clamp
  check_scene<G>(test_camera<float>(1, 1, 0.5, 0.5, 1.0), sp, 61);
  check_scene<G>(test_camera<float>(40, 24, 20.0, 12.0), sp, 62);
}

// The vector helpers of the blend stage against scalar references (for the vector width this
// build targets).

TEST_CASE("exp_neg_into: within 2 ulp of exp on [0, 87]; negative -> 1, NaN -> exp(-87), huge -> exp(-87)") {
  using V = detail::BlockVec<float>::V;
  constexpr int L = detail::BlockVec<float>::kLanes;
  double worst = 0;
  for (int k = 0; k <= 870000; k += L) {
    V s, e;
    for (int i = 0; i < L; ++i) s[i] = float(k + i) * 1e-4f;
    detail::exp_neg_into(e, s);
    for (int i = 0; i < L; ++i) {
      const double ref = std::exp(-double(s[i]));
      if (s[i] <= 87.0f) worst = std::max(worst, std::abs(double(e[i]) - ref) / ref);
    }
  }
  CHECK(worst < 2 * 5.97e-8);
  V s, e;
  for (int i = 0; i < L; ++i) s[i] = (i % 4 == 0) ? -3.0f : (i % 4 == 1) ? NAN : (i % 4 == 2) ? 1e30f : INFINITY;
  detail::exp_neg_into(e, s);
  for (int i = 0; i < L; ++i) {
    CHECK(std::isfinite(e[i]));
    const float ei = e[i];  // (a vector element cannot bind to CHECK's reference under Clang)
    if (i % 4 == 0) CHECK(ei == 1.0f);
    else CHECK(ei == doctest::Approx(std::exp(-87.0)).epsilon(1e-6));
  }
}

TEST_CASE("sum_rows, lane_bits, any_le_and_gt, min_into and max_into match their scalar definitions") {
  using RV = detail::BlockVec<float>;
  using V = RV::V;
  using M = RV::M;
  constexpr int NH = RV::kChunks, L = RV::kLanes;
  // sum_rows: the documented tree (i + i+8, then i + i+4, then (0 + 2) + (1 + 3)), bit for bit.
  for (int n = 1; n <= 13; ++n) {
    std::vector<V> rows(std::size_t(n * NH));
    for (int l = 0; l < n; ++l)
      for (int x = 0; x < 16; ++x) rows[std::size_t(l * NH + x / L)][x % L] = std::ldexp(float(1 + 7 * l + 3 * x), -x) + 1e-3f * float(x);
    std::vector<float> sum(static_cast<std::size_t>(n));
    detail::sum_rows(rows.data(), n, sum.data());
    for (int l = 0; l < n; ++l) {
      float v[16];
      for (int x = 0; x < 16; ++x) v[x] = rows[std::size_t(l * NH + x / L)][x % L];
      float h8[8], h4[4];
      for (int i = 0; i < 8; ++i) h8[i] = v[i] + v[i + 8];
      for (int i = 0; i < 4; ++i) h4[i] = h8[i] + h8[i + 4];
      const float ref = (h4[0] + h4[2]) + (h4[1] + h4[3]);
      CHECK(std::memcmp(&ref, &sum[std::size_t(l)], sizeof ref) == 0);
    }
  }
  V a, b, lo, hi;
  M m;
  for (int i = 0; i < L; ++i) {
    a[i] = (i % 3 == 0) ? NAN : float(i) - 2.0f;
    b[i] = float(L - i) - 3.0f;
    m[i] = (i % 3 == 1) ? -1 : 0;
  }
  detail::min_into(lo, a, b);
  detail::max_into(hi, a, b);
  std::uint32_t bits_ref = 0;
  for (int i = 0; i < L; ++i) {
    const float lo_i = lo[i], hi_i = hi[i];
    CHECK(lo_i == (a[i] < b[i] ? a[i] : b[i]));  // NaN in a -> b
    CHECK(hi_i == (a[i] > b[i] ? a[i] : b[i]));
    bits_ref |= std::uint32_t(m[i] != 0) << i;
  }
  CHECK(detail::lane_bits(m) == bits_ref);
  // any_le_and_gt: true iff some lane has a <= b and c > d, NaN comparing false, whichever lane it is.
  for (int hit = -1; hit < L; ++hit)
    for (int nan_lane = -1; nan_lane < L; ++nan_lane) {
      V x, y, c, d;
      for (int i = 0; i < L; ++i) {
        x[i] = i == hit ? 1.0f : 2.0f;  // x <= y in the hit lane only
        y[i] = 1.0f;
        c[i] = (i == hit || i % 2 == 0) ? 0.5f : -0.5f;  // c > d in the hit lane and every even lane
        d[i] = 0.0f;
      }
      if (nan_lane >= 0) (nan_lane % 2 == 0 ? x : c)[nan_lane] = NAN;
      bool ref = false;
      for (int i = 0; i < L; ++i) ref = ref || (x[i] <= y[i] && c[i] > d[i]);
      CHECK(detail::any_le_and_gt(x, y, c, d) == ref);
      CHECK(ref == (hit >= 0 && hit != nan_lane));
    }
}

TEST_CASE("projection exp and log (lexp, llog): within 1 ulp of libm, the same bits per lane and one at a time") {
  using D = detail::ProjVec;
  constexpr int L = detail::kProjLanes;
  auto ulps = [](double a, double ref) {
    if (a == ref) return 0.0;
    return std::abs(a - ref) / (std::nextafter(std::abs(ref), INFINITY) - std::abs(ref));
  };
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> ue(-745.0, 709.78), ul(-700.0, 700.0), u1(0.5, 300.0);
  double worst_exp = 0, worst_log = 0;
  bool same = true;
  for (int it = 0; it < 50000; ++it) {
    D x, y;
    for (int l = 0; l < L; ++l) {
      x[l] = ue(rng);
      y[l] = (it & 1) ? std::exp(ul(rng)) : u1(rng);
    }
    const D e = detail::lexp(x), g = detail::llog(y);
    for (int l = 0; l < L; ++l) {
      const double re = std::exp(x[l]);
      if (re >= 0x1p-1022) worst_exp = std::max(worst_exp, ulps(e[l], re));  // normal results
      worst_log = std::max(worst_log, ulps(g[l], std::log(y[l])));
      same = same && detail::lexp(x[l]) == e[l] && detail::llog(y[l]) == g[l];
    }
  }
  CHECK(worst_exp <= 1.0);
  CHECK(worst_log <= 1.0);
  CHECK(same);
  // Special values: exp over- and underflows like IEEE, NaN stays NaN; log is NaN off its domain.
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  CHECK(detail::lexp(710.0) == inf);
  CHECK(detail::lexp(inf) == inf);
  CHECK(detail::lexp(-inf) == 0.0);
  CHECK(detail::lexp(-744.0) == std::exp(-744.0));  // subnormal
  CHECK(std::isnan(detail::lexp(nan)));
  CHECK(detail::lexp(0.0) == 1.0);
  CHECK(detail::llog(1.0) == 0.0);
  for (double bad : {0.0, -1.0, 1e-310, inf, -inf, nan}) CHECK(std::isnan(detail::llog(bad)));
}

TEST_CASE("pixel_rect: every pixel centre within the extent, clipped to the image; NaN gives nothing") {
  constexpr int W = 64, H = 48;
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> um(-20.0, 84.0), ue(0.0, 30.0);
  for (int i = 0; i < 2000; ++i) {
    const double mx = um(rng), my = um(rng), ex = ue(rng), ey = ue(rng);
    const PixelRect r = pixel_rect(mx, my, ex, ey, W, H);
    INFO("mean ", mx, " ", my, " extent ", ex, " ", ey);
    for (int x = 0; x < W; ++x)
      for (int y = 0; y < H; ++y)
        if (std::abs(x + 0.5 - mx) <= ex && std::abs(y + 0.5 - my) <= ey) {
          REQUIRE(!r.empty());
          CHECK((r.x0 <= x && x <= r.x1 && r.y0 <= y && y <= r.y1));
        }
    if (!r.empty()) CHECK((r.x0 >= 0 && r.x1 < W && r.y0 >= 0 && r.y1 < H));
  }
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  CHECK(pixel_rect(nan, 10, 2, 2, W, H).empty());
  CHECK(pixel_rect(10, nan, 2, 2, W, H).empty());
  CHECK(pixel_rect(10, 10, nan, 2, W, H).empty());
  CHECK(pixel_rect(10, 10, 2, nan, W, H).empty());
  CHECK(pixel_rect(inf, 10, 2, 2, W, H).empty());  // inf - inf would be NaN: the whole image
  CHECK(pixel_rect(10, -inf, 2, 2, W, H).empty());
  const PixelRect all = pixel_rect(10, 10, inf, inf, W, H);  // an infinite extent covers the image
  CHECK((all.x0 == 0 && all.y0 == 0 && all.x1 == W - 1 && all.y1 == H - 1));
}

TEST_CASE("pixel_rect_lanes: the rectangles of pixel_rect, lane by lane, for every kind of input") {
  constexpr int L = detail::kProjLanes;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const double specials[] = {nan, inf, -inf, 0.0, -0.0, 0.5, -0.5, 1.5, 63.5, 64.0, 64.5, -2.0, -1.5, 1e300, -1e300,
                             3e9, -3e9, 1e-310, 47.5, 48.0, 48.5, 0.49999999999999994, 2.0000000000000004};
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> um(-40.0, 110.0), ue(0.0, 40.0);
  // Exact halves and near-halves (where ceil and floor turn), random values and the specials.
  const auto draw = [&](bool extent) {
    switch (rng() % 4) {
      case 0: return specials[rng() % std::size(specials)];
      case 1: return double(std::int64_t(rng() % 300) - 100) * 0.5;
      case 2: return std::nextafter(double(std::int64_t(rng() % 200) - 50) * 0.5, rng() % 2 ? inf : -inf);
      default: return extent ? ue(rng) : um(rng);
    }
  };
  for (const auto& size : {std::pair{64, 48}, std::pair{1, 1}, std::pair{240, 180}}) {
    const int W = size.first, H = size.second;  // not a structured binding: INFO captures them
    for (int t = 0; t < 20000; ++t) {
      detail::ProjVec mx, my, ex, ey;
      for (int l = 0; l < L; ++l) {
        mx[l] = draw(false);
        my[l] = draw(false);
        ex[l] = draw(true);
        ey[l] = draw(true);
      }
      PixelRect got[L];
      detail::pixel_rect_lanes(mx, my, ex, ey, W, H, got);
      for (int l = 0; l < L; ++l) {
        const PixelRect want = pixel_rect(mx[l], my[l], ex[l], ey[l], W, H);
        INFO("mean ", mx[l], " ", my[l], " extent ", ex[l], " ", ey[l], " image ", W, "x", H);
        REQUIRE(got[l].empty() == want.empty());
        if (!want.empty()) CHECK((got[l].x0 == want.x0 && got[l].x1 == want.x1 && got[l].y0 == want.y0 && got[l].y1 == want.y1));
      }
    }
  }
}

TEST_CASE("BlockRange::blocks: the bit set of every block in the range, for every rectangle and clipped tile") {
  // Every pixel rectangle against a full tile and against clipped edge tiles: the bit set must
  // hold exactly the blocks of the block rows by0..by1 and columns bx0..bx1.
  constexpr int TS = TileGrid::kTileSize, P = detail::TileBlocks::kPerSide;
  const TileGrid grid(TS + 7, TS + 11);  // tile 3 is clipped to 7 x 11 pixels
  int checked = 0;
  for (const int tile : {0, 3}) {
    const detail::TileBounds<float> tb(grid, tile);
    for (int x0 = -2; x0 < 2 * TS; x0 += 1)
      for (int x1 = x0 - 1; x1 < 2 * TS; x1 += 3)
        for (int y0 = -1; y0 < 2 * TS; y0 += 2)
          for (int y1 = y0 - 1; y1 < 2 * TS; y1 += 5) {
            const detail::BlockRange r(PixelRect{x0, y0, x1, y1}, tb);
            std::uint32_t want = 0;
            for (int by = r.by0; by <= r.by1; ++by)
              for (int bx = r.bx0; bx <= r.bx1; ++bx) want |= 1u << (by * P + bx);
            REQUIRE(r.blocks() == want);
            ++checked;
          }
  }
  CHECK(checked > 10000);
}

TEST_CASE("append_set_bits: the set bits of every 16-bit mask, ascending, with their tag, after what is there") {
  // Both forms (the table one is the only one without AVX-512) against a loop over the bits, for
  // every mask, appended behind a prefix that must survive and ahead of the 16 entries of room.
  for (const bool by_table : {false, true}) {
    for (std::uint32_t bits = 0; bits < 65536u; ++bits) {
      std::uint8_t out[3 + 16 + 16], tags[3 + 16 + 16];
      std::memset(out, 0xee, sizeof out);
      std::memset(tags, 0xee, sizeof tags);
      const std::uint8_t tag = std::uint8_t(bits % 13);
      const int n = by_table ? detail::append_set_bits_by_table(bits, tag, out + 3, tags + 3)
                             : detail::append_set_bits(bits, tag, out + 3, tags + 3);
      int want = 0;
      bool ok = n == std::popcount(bits);
      for (int b = 0; b < 16; ++b)
        if (bits >> b & 1u) {
          ok = ok && out[3 + want] == b && tags[3 + want] == tag;
          ++want;
        }
      for (int i = 0; i < 3; ++i) ok = ok && out[i] == 0xee && tags[i] == 0xee;  // before: untouched
      for (int i = 3 + 16; i < int(sizeof out); ++i) ok = ok && out[i] == 0xee && tags[i] == 0xee;  // past the room
      INFO("mask ", bits, by_table ? " (table)" : "");
      REQUIRE(ok);
    }
  }
}

}  // namespace test_rasterize_reference
