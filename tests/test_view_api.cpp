// tests/test_view_api.cpp
// The request side of `msgs view` without a socket: strict query parsing, cameras, modes and
// their availability, the five spectral indices (0/0, negatives, non-finite inputs), mode
// composition over a fake renderer, encoding, ground truth at dataset cameras, /api/info.
#include <doctest/doctest.h>

#include "fixtures.hpp"

#include "../examples/view_api.hpp"

#include <msgs/io/image_io.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace test_view_api {
using namespace msgs;
using view::Params;
using view::Query;
using view::ViewError;

namespace {

/// Status of the ViewError `fn` throws, or 0 when it throws none.
template <class F>
int status_of(F&& fn) {
  try {
    fn();
  } catch (const ViewError& e) {
    return e.status;
  }
  return 0;
}

Params params(std::initializer_list<std::pair<const char*, const char*>> kv) {
  Params p;
  for (const auto& [k, v] : kv) p.emplace(k, v);
  return p;
}

/// Joint channel values the fake renderer paints everywhere: D = (.2, .3, .4), G .3, R .1, RE .4, NIR .6.
constexpr float kJoint[7] = {0.2f, 0.3f, 0.4f, 0.3f, 0.1f, 0.4f, 0.6f};

/// A ModelSet of fake models that paint constant channels (no rasteriser involved): `channels`
/// with `names` (Joint names of the channels the model holds).
ModelSet fake_models(const std::vector<std::vector<std::string>>& models_names, int* calls = nullptr) {
  std::vector<LoadedModel> ms;
  for (const auto& names : models_names) {
    LoadedModel m;
    m.path = "fake.ply";
    m.info.gaussian = true;
    m.info.channels = int(names.size());
    m.info.sh_degree = 0;
    m.info.band_names = names;
    ms.push_back(std::move(m));
  }
  return ModelSet::from_models(std::move(ms), [calls](std::shared_ptr<const LoadedModel> m) -> ChannelRenderer {
    std::vector<float> vals;
    const auto joint = io::joint_channel_names();
    for (const auto& n : m->info.band_names)
      for (std::size_t k = 0; k < joint.size(); ++k)
        if (joint[k] == n) vals.push_back(kJoint[k]);
    return [vals, calls](const Camera<float>& cam, const RenderSettings<float>& rs) {
      if (calls) ++*calls;
      const int n = rs.band_count < 0 ? int(vals.size()) - rs.band_first : rs.band_count;
      Image<float> img(cam.width, cam.height, n);
      for (std::size_t p = 0; p < img.pixels(); ++p)
        for (int c = 0; c < n; ++c)
          img.data[p * std::size_t(n) + std::size_t(c)] = vals[std::size_t(rs.band_first + c)];
      return img;
    };
  });
}

Camera<float> test_camera(int w = 8, int h = 6) {
  Camera<float> c;
  c.width = w;
  c.height = h;
  c.fx = c.fy = 10;
  c.cx = w / 2.0f;
  c.cy = h / 2.0f;
  return c;
}

const char* kR = "1,0,0,0,1,0,0,0,1";

}  // namespace

TEST_CASE("index_value: the five formulas") {
  using view::Index;
  const float nir = 0.6f, r = 0.1f, g = 0.3f, re = 0.4f;
  CHECK(view::index_value(Index::ndvi, nir, r) == doctest::Approx(0.5 / 0.7));
  CHECK(view::index_value(Index::ndre, nir, re) == doctest::Approx(0.2 / 1.0));
  CHECK(view::index_value(Index::gndvi, nir, g) == doctest::Approx(0.3 / 0.9));
  CHECK(view::index_value(Index::ndwi, g, nir) == doctest::Approx(-0.3 / 0.9));
  CHECK(view::index_value(Index::savi, nir, r) == doctest::Approx(1.5 * 0.5 / 1.2));
  // The formulas' bands, as the modes render them.
  CHECK(std::string(view::index_info(Index::ndwi).a) == "MS_G");
  CHECK(std::string(view::index_info(Index::ndwi).b) == "MS_NIR");
  CHECK(std::string(view::index_info(Index::gndvi).b) == "MS_G");
  CHECK(std::string(view::index_info(Index::ndre).b) == "MS_RE");
  CHECK(std::string(view::index_info(Index::savi).b) == "MS_R");
}

TEST_CASE("index_value: 0/0, negatives and non-finite inputs give finite values in [-1, 1]") {
  using view::Index;
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const auto& info : view::indices()) {
    const Index i = info.index;
    CAPTURE(info.id);
    CHECK(view::index_value(i, nan, 0.5f) == 0.0f);
    CHECK(view::index_value(i, 0.5f, nan) == 0.0f);
    CHECK(view::index_value(i, inf, 0.5f) == 0.0f);
    CHECK(view::index_value(i, 0.5f, -inf) == 0.0f);
    for (float a : {-2.0f, -1.0f, -0.25f, -1e-8f, 0.0f, 1e-8f, 0.3f, 1.0f, 5.0f, 1e30f, -1e30f})
      for (float b : {-2.0f, -0.75f, -0.25f, 0.0f, 1e-8f, 0.1f, 1.0f, 3.0f, 1e30f}) {
        const float v = view::index_value(i, a, b);
        CHECK(std::isfinite(v));
        CHECK(v >= -1.0f);
        CHECK(v <= 1.0f);
      }
  }
  CHECK(view::index_value(Index::ndvi, 0.0f, 0.0f) == 0.0f);                // 0/0 on black
  CHECK(view::index_value(Index::ndvi, 1e-8f, 1e-8f) == 0.0f);              // below eps
  CHECK(view::index_value(Index::ndvi, 0.3f, -0.3f) == 0.0f);               // cancelling negatives
  CHECK(view::index_value(Index::savi, -0.25f, -0.25f) == 0.0f);            // SAVI's denominator 0
  CHECK(view::index_value(Index::ndvi, 0.5f, -0.2f) == 1.0f);               // 0.7 / 0.3 clamped
  CHECK(view::index_value(Index::ndvi, -0.5f, 0.2f) == 1.0f);               // -0.7 / -0.3 clamped
  CHECK(view::index_value(Index::ndvi, 0.0f, 0.5f) == -1.0f);
}

TEST_CASE("index_image of NDVI / NDRE equals msgs::ndvi / msgs::ndre bit for bit") {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  Image<float> a(13, 7, 1), b(13, 7, 1);
  for (auto& v : a.data) v = u(rng);
  for (auto& v : b.data) v = u(rng);
  a.data[0] = b.data[0] = 0.0f;
  a.data[1] = 1e-7f;
  b.data[1] = -1e-7f;
  const Image<float> mine = view::index_image(view::Index::ndvi, a, b), lib = ndvi(a, b);
  CHECK(mine.data == lib.data);
  CHECK(view::index_image(view::Index::ndre, a, b).data == ndre(a, b).data);
  CHECK_THROWS_AS(view::index_image(view::Index::ndvi, a, Image<float>(13, 6, 1)), std::invalid_argument);
}

TEST_CASE("Query: unknown, repeated and malformed parameters are 400") {
  CHECK(status_of([] { Query q(params({{"width", "1"}, {"bogus", "2"}}), {"width"}); }) == 400);
  CHECK(status_of([] { Query q(params({{"width", "1"}, {"width", "2"}}), {"width"}); }) == 400);
  for (const char* bad : {"", "nan", "NaN", "inf", "-inf", "1e999", "-1e999", "0x10", " 1", "1 ", "1,", "1.2.3", "--1",
                          "1e", "+", "e5", "12abc", "\x01"}) {
    CAPTURE(bad);
    const Query q(params({{"x", bad}}), {"x"});
    CHECK(status_of([&] { (void)q.number("x", 0, -1e9, 1e9); }) == 400);
  }
  const Query q(params({{"x", "1e-3"}, {"n", "42"}, {"v", "1,-2.5,3e2"}, {"big", "99999999999999999999"}}),
                {"x", "n", "v", "big", "absent"});
  CHECK(q.number("x", 0, -1, 1) == doctest::Approx(1e-3));
  CHECK(q.number("absent", 7, 0, 1) == 7);  // the default is not range-checked
  CHECK(status_of([&] { (void)q.number("x", 0, 0.5, 1); }) == 400);
  CHECK(q.integer("n", 0, 0, 100) == 42);
  CHECK(status_of([&] { (void)q.integer("n", 0, 0, 10); }) == 400);
  CHECK(status_of([&] { (void)q.integer("x", 0, 0, 10); }) == 400);
  CHECK(status_of([&] { (void)q.integer("big", 0, 0, 10); }) == 400);
  CHECK(q.numbers("v", 3) == std::vector<double>{1, -2.5, 300});
  CHECK(status_of([&] { (void)q.numbers("v", 2); }) == 400);
  CHECK(status_of([&] { (void)q.numbers("v", 4); }) == 400);
  CHECK(Query::printable(std::string("a\nb\x80") + std::string(100, 'x')).size() == 63);
}

TEST_CASE("parse_camera: intrinsics and both pose forms") {
  const Camera<float> c = view::parse_camera(
      Query(params({{"width", "64"}, {"height", "48"}, {"fx", "50"}, {"R", kR}, {"t", "1,2,3"}}),
            {"width", "height", "fx", "fy", "cx", "cy", "fovy", "R", "t", "eye", "target", "up"}));
  CHECK(c.width == 64);
  CHECK(c.height == 48);
  CHECK(c.fx == 50);
  CHECK(c.fy == 50);
  CHECK(c.cx == 32);
  CHECK(c.cy == 24);
  CHECK(c.t.x() == 1);
  CHECK(c.t.z() == 3);

  // Look-at: the target projects to the principal point, up points up the image (-y).
  const Camera<float> l = view::parse_camera(
      Query(params({{"width", "64"}, {"height", "48"}, {"fovy", "90"}, {"eye", "1,2,3"}, {"target", "1,7,3"},
                    {"up", "0,0,1"}}),
            {"width", "height", "fovy", "eye", "target", "up"}));
  CHECK(l.fy == doctest::Approx(24.0f));
  const Eigen::Vector3f tc = l.R * Eigen::Vector3f(1, 7, 3) + l.t;
  CHECK(tc.z() == doctest::Approx(5.0f));
  CHECK(std::abs(tc.x()) < 1e-5f);
  CHECK(std::abs(tc.y()) < 1e-5f);
  const Eigen::Vector3f above = l.R * Eigen::Vector3f(1, 7, 4) + l.t;
  CHECK(above.y() < 0);  // OpenCV: y down, so a point above the target is at negative y
  CHECK((l.R * l.R.transpose() - Eigen::Matrix3f::Identity()).cwiseAbs().maxCoeff() < 1e-6f);
  CHECK(l.R.determinant() == doctest::Approx(1.0f));
}

TEST_CASE("parse_camera: every malformed camera is a 400") {
  const std::initializer_list<std::string_view> all = {"width", "height", "fx", "fy",  "cx",     "cy",
                                                        "fovy",  "R",      "t",  "eye", "target", "up"};
  auto status = [&](std::initializer_list<std::pair<const char*, const char*>> kv) {
    return status_of([&] { (void)view::parse_camera(Query(params(kv), all)); });
  };
  const std::pair<const char*, const char*> w{"width", "64"}, h{"height", "48"}, R{"R", kR}, t{"t", "0,0,0"};
  CHECK(status({w, h, R, t}) == 0);
  CHECK(status({h, R, t}) == 400);                                          // no width
  CHECK(status({{"width", "0"}, h, R, t}) == 400);
  CHECK(status({{"width", "4097"}, h, R, t}) == 400);
  CHECK(status({{"width", "4096"}, {"height", "4096"}, R, t}) == 400);      // over max_pixels
  CHECK(status({{"width", "-5"}, h, R, t}) == 400);
  CHECK(status({{"width", "64.5"}, h, R, t}) == 400);
  CHECK(status({w, h}) == 400);                                             // no pose
  CHECK(status({w, h, R}) == 400);                                          // R without t
  CHECK(status({w, h, R, {"t", "0,0"}}) == 400);
  CHECK(status({w, h, R, {"t", "0,0,nan"}}) == 400);
  CHECK(status({w, h, R, {"t", "0,0,1e300"}}) == 400);                      // beyond max_abs_number
  CHECK(status({w, h, {"R", "1,0,0,0,1,0,0,0,2"}, t}) == 400);               // not orthonormal
  CHECK(status({w, h, {"R", "1,0,0,0,1,0,0,0,-1"}, t}) == 400);              // a reflection
  CHECK(status({w, h, {"R", "1,0,0,0,1,0,0,0"}, t}) == 400);
  CHECK(status({w, h, {"fx", "0"}, R, t}) == 400);
  CHECK(status({w, h, {"fx", "-3"}, R, t}) == 400);
  CHECK(status({w, h, {"fx", "inf"}, R, t}) == 400);
  CHECK(status({w, h, {"fy", "3"}, R, t}) == 400);                          // fy without fx
  CHECK(status({w, h, {"fx", "3"}, {"fovy", "40"}, R, t}) == 400);
  CHECK(status({w, h, {"fovy", "180"}, R, t}) == 400);
  CHECK(status({w, h, {"cx", "nan"}, R, t}) == 400);
  CHECK(status({w, h, {"eye", "0,0,0"}, {"target", "0,0,0"}}) == 400);
  CHECK(status({w, h, {"eye", "0,0,0"}, {"target", "0,0,1"}}) == 400);      // parallel to the default up
  CHECK(status({w, h, {"eye", "0,0,0"}, {"target", "1,0,0"}, {"up", "0,0,0"}}) == 400);
  CHECK(status({w, h, {"eye", "0,0,0"}}) == 400);
  CHECK(status({w, h, R, t, {"eye", "0,0,0"}, {"target", "1,0,0"}}) == 400);
}

TEST_CASE("modes: names, bands and availability") {
  for (const auto& id : view::all_mode_ids()) CHECK(view::parse_mode(id).id() == id);
  CHECK(status_of([] { (void)view::parse_mode("NDVI"); }) == 400);
  CHECK(status_of([] { (void)view::parse_mode("../etc"); }) == 400);
  CHECK(status_of([] { (void)view::parse_mode(""); }) == 400);
  CHECK(view::parse_mode("cir").bands() == std::vector<std::string>{"MS_NIR", "MS_R", "MS_G"});
  CHECK(view::parse_mode("ndwi").bands() == std::vector<std::string>{"MS_G", "MS_NIR"});

  const ModelSet joint = fake_models({io::joint_channel_names()});
  for (const auto& id : view::all_mode_ids()) CHECK(view::mode_unavailable(joint, view::parse_mode(id)).empty());

  const ModelSet rgb = fake_models({{"D_R", "D_G", "D_B"}});
  CHECK(view::mode_unavailable(rgb, view::parse_mode("rgb")).empty());
  CHECK(view::mode_unavailable(rgb, view::parse_mode("D")).empty());
  const std::string why = view::mode_unavailable(rgb, view::parse_mode("ndre"));
  CHECK(why.find("MS_NIR, MS_RE") != std::string::npos);
  CHECK(status_of([&] { view::require_mode(rgb, view::parse_mode("ndvi")); }) == 422);
  CHECK(status_of([&] { view::require_mode(rgb, view::parse_mode("MS_NIR")); }) == 422);

  // Separate per-band models: indices work across models (one pass per model).
  const ModelSet sep = fake_models({{"MS_NIR"}, {"MS_R"}});
  CHECK(view::mode_unavailable(sep, view::parse_mode("ndvi")).empty());
  CHECK(!view::mode_unavailable(sep, view::parse_mode("ndre")).empty());
}

TEST_CASE("render_values: bands, RGB, CIR and indices from one pass over adjacent channels") {
  int calls = 0;
  const ModelSet joint = fake_models({io::joint_channel_names()}, &calls);
  const Camera<float> cam = test_camera();
  const view::Background black{false, {0.0f}};

  const Image<float> nir = view::render_values(joint, view::parse_mode("MS_NIR"), cam, black);
  CHECK(nir.channels == 1);
  CHECK(nir.data[5] == 0.6f);
  const Image<float> rgb = view::render_values(joint, view::parse_mode("rgb"), cam, black);
  CHECK(rgb.channels == 3);
  CHECK(rgb.width == 8);
  CHECK(rgb.data[4] == 0.3f);
  calls = 0;
  const Image<float> cir = view::render_values(joint, view::parse_mode("cir"), cam, black);
  CHECK(calls == 1);  // G, R, (RE,) NIR: one forward pass of channels 3..6
  CHECK(cir.data[0] == 0.6f);
  CHECK(cir.data[1] == 0.1f);
  CHECK(cir.data[2] == 0.3f);
  calls = 0;
  const Image<float> nd = view::render_values(joint, view::parse_mode("ndvi"), cam, black);
  CHECK(calls == 1);  // NIR and R with RE between them: one pass
  CHECK(nd.channels == 1);
  CHECK(nd.data[3] == view::index_value(view::Index::ndvi, 0.6f, 0.1f));
  const Image<float> ndwi = view::render_values(joint, view::parse_mode("ndwi"), cam, black);
  CHECK(ndwi.data[3] == doctest::Approx(-0.3 / 0.9));

  // Display: indices through the diverging scale, bands times the gain.
  const Image<float> shown = view::display(view::parse_mode("ndvi"), nd, 1.0f);
  CHECK(shown.channels == 3);
  const auto col = colour_at(Colormap::diverging, (nd.data[0] + 1.0f) / 2.0f);
  CHECK(shown.data[0] == col[0]);
  CHECK(view::display(view::parse_mode("MS_NIR"), nir, 2.0f).data[0] == doctest::Approx(1.2f));

  const ModelSet rgb_only = fake_models({{"D_R", "D_G", "D_B"}});
  CHECK(status_of([&] { (void)view::render_values(rgb_only, view::parse_mode("savi"), cam, black); }) == 422);
}

TEST_CASE("backgrounds: eval grey, names and numbers") {
  auto parse = [](const char* v) { return view::parse_background(Query(params({{"bg", v}}), {"bg"})); };
  CHECK(view::parse_background(Query({}, {"bg"})).eval);
  CHECK(parse("eval").for_band("D") == eval_background<float>(3));
  CHECK(parse("eval").for_band("MS_R") == eval_background<float>(1));
  CHECK(parse("black").for_band("D") == std::vector<float>{0.0f});
  CHECK(parse("white").for_band("MS_G") == std::vector<float>{1.0f});
  CHECK(parse("0.5").for_band("MS_G") == std::vector<float>{0.5f});
  CHECK(parse("0.1,0.2,0.3").for_band("D").size() == 3);
  CHECK(parse("0,0.1,0.2,0.3,0.4,0.5,0.6").for_band("MS_RE") == std::vector<float>{0.5f});
  CHECK(status_of([&] { (void)parse("0.1,0.2,0.3").for_band("MS_G"); }) == 400);
  for (const char* bad : {"grey", "2", "-0.1", "nan", "0.1,0.2", "1,1,1,1,1"}) {
    CAPTURE(bad);
    CHECK(status_of([&] { (void)parse(bad); }) == 400);
  }
}

TEST_CASE("encode: PNG and JPEG decode to the image's size; PNG values exactly as write_png8") {
  Image<float> img(17, 9, 3);
  for (std::size_t i = 0; i < img.data.size(); ++i) img.data[i] = float(i % 29) / 28.0f * 1.2f - 0.1f;
  img.data[5] = std::numeric_limits<float>::quiet_NaN();
  const auto dir = testing::scratch_dir("view_api");
  auto decode = [&](const view::Encoded& e, const char* name) {
    const auto p = dir / name;
    std::ofstream(p, std::ios::binary).write(e.bytes.data(), std::streamsize(e.bytes.size()));
    return io::read_image(p);
  };
  const view::Encoded png = view::encode(img, view::Format::png);
  CHECK(std::string(png.content_type) == "image/png");
  const Image<float> back = decode(png, "e.png");
  REQUIRE(back.width == 17);
  REQUIRE(back.height == 9);
  REQUIRE(back.channels == 3);
  for (std::size_t i = 0; i < img.data.size(); ++i) {
    const float v = std::isnan(img.data[i]) ? 0.0f : std::clamp(img.data[i], 0.0f, 1.0f);
    CHECK(back.data[i] == float(std::lround(v * 255.0f)) / 255.0f);
  }
  const Image<float> jpg = decode(view::encode(img, view::Format::jpeg, 90), "e.jpg");
  CHECK(jpg.width == 17);
  CHECK(jpg.height == 9);
  const Image<float> grey = decode(view::encode(Image<float>(5, 4, 1, 0.5f), view::Format::png), "g.png");
  CHECK(grey.channels == 1);
  CHECK(grey.data[0] == 128.0f / 255.0f);
  CHECK_THROWS_AS(view::encode(Image<float>(5, 4, 2), view::Format::png), std::invalid_argument);
  CHECK(status_of([] { (void)view::parse_format(Query(params({{"format", "gif"}}), {"format", "quality"})); }) == 400);
  CHECK(status_of([] { (void)view::parse_format(Query(params({{"quality", "0"}}), {"format", "quality"})); }) == 400);
  CHECK(status_of([] { (void)view::parse_gain(Query(params({{"gain", "0"}}), {"gain"})); }) == 400);
}

TEST_CASE("dataset frames: ground truth per mode, capture lookups and size checks") {
  const io::Dataset& ds = testing::tiny_scene("view_api", 3);
  const view::FrameIndex fx(ds);
  std::size_t nir = ds.frames.size(), d = ds.frames.size();
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    if (nir == ds.frames.size() && ds.frames[i].band == "MS_NIR") nir = i;
    if (d == ds.frames.size() && ds.frames[i].band == "D") d = i;
  }
  REQUIRE(nir < ds.frames.size());
  REQUIRE(d < ds.frames.size());
  const Capture& cap = fx.capture(nir);
  REQUIRE(cap.frames.count("MS_R"));

  const Image<float> own = view::ground_truth(ds, fx, nir, view::parse_mode("MS_NIR"), 1);
  CHECK(own.data == io::load_frame_image(ds, ds.frames[nir], 1).data);
  const Image<float> cir = view::ground_truth(ds, fx, nir, view::parse_mode("cir"), 1);
  const Image<float> red = io::load_frame_image(ds, ds.frames[cap.frames.at("MS_R")], 1);
  CHECK(cir.channels == 3);
  CHECK(cir.data[1] == red.data[0]);
  const Image<float> nd = view::ground_truth(ds, fx, nir, view::parse_mode("ndvi"), 1);
  CHECK(nd.data == view::index_image(view::Index::ndvi, own, red).data);
  // The D image is larger than the multispectral cameras: no CIR ground truth from its camera.
  CHECK(status_of([&] { (void)view::ground_truth(ds, fx, d, view::parse_mode("cir"), 1); }) == 422);

  // frame_factor: the default fits the limits; explicit scales are range-checked.
  const view::Query none({}, {"scale"});
  CHECK(view::frame_factor(none, ds, ds.frames[d]) == std::max(1, ds.downscale));
  CHECK(view::frame_factor(view::Query(params({{"scale", "2"}}), {"scale"}), ds, ds.frames[d]) == 2);
  const view::Query too_far(params({{"scale", "65"}}), {"scale"});
  CHECK(status_of([&] { (void)view::frame_factor(too_far, ds, ds.frames[d]); }) == 400);

  // compare_frame against a fake model painting constants: PSNR of a constant against the image.
  const ModelSet joint = fake_models({io::joint_channel_names()});
  const view::FrameComparison c =
      view::compare_frame(joint, ds, fx, nir, view::parse_mode("MS_NIR"), view::Background{false, {0.0f}}, 1);
  CHECK(c.gt_error.empty());
  CHECK(c.psnr == doctest::Approx(psnr(Image<float>(own.width, own.height, 1, 0.6f), own)));
  const view::FrameComparison ci =
      view::compare_frame(joint, ds, fx, nir, view::parse_mode("ndvi"), view::Background{false, {0.0f}}, 1);
  CHECK(ci.mae > 0);
  CHECK(view::error_image(view::parse_mode("ndvi"), ci).channels == 3);
  const view::FrameComparison cd =
      view::compare_frame(joint, ds, fx, d, view::parse_mode("cir"), view::Background{false, {0.0f}}, 1);
  CHECK(!cd.gt_error.empty());
  CHECK(status_of([&] { (void)view::error_image(view::parse_mode("cir"), cd); }) == 422);

  // /api/info lists every camera with its intrinsics and pose.
  const nlohmann::json j = view::info_json(joint, &ds, &fx);
  REQUIRE(j["cameras"].size() == ds.frames.size());
  const auto& c0 = j["cameras"][nir];
  CHECK(c0["band"] == "MS_NIR");
  CHECK(c0["fx"].get<float>() == ds.frames[nir].camera.fx);
  CHECK(c0["R"].size() == 9);
  CHECK(c0["capture"] == cap.key);
  CHECK(j["modes"].size() == view::all_mode_ids().size());
  CHECK(j["scene"]["up"][2].get<double>() > 0.9);  // oriented datasets: +z up
  const nlohmann::json k = view::info_json(fake_models({{"D_R", "D_G", "D_B"}}), nullptr, nullptr);
  CHECK(k["cameras"].empty());
  CHECK(k["bands"].size() == 1);
  for (const auto& m : k["modes"])
    if (m["id"] == "ndvi") CHECK(m["available"] == false);
}

}  // namespace test_view_api
