// tests/test_render_util.cpp
// Tests of what render_util.hpp includes: spectral indices, colour scales, CIR order, error maps,
// contact-sheet layout (the labelled one: test_contact_sheet.cpp), PLY model dispatch and band
// resolution, output staging, and the dataset render and evaluation paths end to end on the
// synthetic tiny dataset.
#include <doctest/doctest.h>

#include <msgs/init.hpp>
#include <msgs/render_util.hpp>
#include <msgs/synth.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

namespace test_render_util {
namespace fs = std::filesystem;
using msgs::Image;

namespace {

fs::path scratch_dir(const std::string& sub) {
  const char* env = std::getenv("MSGS_TEST_TMP");
  fs::path d = env ? fs::path(env) : fs::temp_directory_path() / "msgs_test";
  d /= "render_util";
  d /= sub;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

Image<float> grey(int w, int h, std::vector<float> v) {
  Image<float> img(w, h, 1);
  REQUIRE(v.size() == img.data.size());
  img.data = std::move(v);
  return img;
}

/// PNG bit depth and colour type from the IHDR chunk (bytes 24 and 25).
std::pair<int, int> png_depth_and_type(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  unsigned char b[26] = {};
  in.read(reinterpret_cast<char*>(b), 26);
  REQUIRE(in.gcount() == 26);
  return {b[24], b[25]};
}

/// A small model with distinct, known parameters.
template <class G>
msgs::GaussianModel<G, float> toy_model(std::size_t n, float base) {
  msgs::GaussianModel<G, float> m(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      m.means[3 * i + std::size_t(a)] = base + float(i) + 0.1f * float(a);
      m.log_scales[3 * i + std::size_t(a)] = -2.0f - 0.1f * float(a);
    }
    m.quats[4 * i] = 1.0f;
    m.quats[4 * i + 1] = 0.1f * float(i);
    m.opacity_logits[i] = 0.5f - float(i);
    for (int k = 0; k < G::sh_coeffs; ++k)
      for (int c = 0; c < G::bands; ++c) m.sh_at(i, k, c) = base + 0.01f * float(k) + 0.001f * float(c);
  }
  return m;
}

/// A factory whose renderers need no rasterizer: channel c of the output is 100 * (model index + 1)
/// + first channel + c, so band resolution and pass merging can be read off the pixels.
struct FakeFactory {
  std::shared_ptr<int> calls = std::make_shared<int>(0);
  std::shared_ptr<int> next_index = std::make_shared<int>(0);
  msgs::ChannelRenderer operator()(std::shared_ptr<const msgs::LoadedModel> m) const {
    const int index = (*next_index)++;
    auto c = calls;
    return [index, c, m](const msgs::Camera<float>& cam, const msgs::RenderSettings<float>& rs) {
      ++*c;
      const int count = rs.band_count < 0 ? m->channels() - rs.band_first : rs.band_count;
      Image<float> img(cam.width, cam.height, count);
      for (std::size_t p = 0; p < img.pixels(); ++p)
        for (int ch = 0; ch < count; ++ch)
          img.data[p * std::size_t(count) + std::size_t(ch)] = float(100 * (index + 1) + rs.band_first + ch);
      return img;
    };
  }
};

msgs::Camera<float> small_camera(int w = 4, int h = 3) {
  msgs::Camera<float> c;
  c.width = w;
  c.height = h;
  c.fx = c.fy = 4;
  c.cx = float(w) / 2;
  c.cy = float(h) / 2;
  return c;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Indices, composites, colour scales
// ---------------------------------------------------------------------------------------------

TEST_CASE("normalized_difference: known values, dark pixels, clamping and bad input") {
  const std::vector<float> nir = {0.8f, 0.3f, 0.0f, 0.5f, 0.0f, 1e-8f, 0.9f, 0.25f};
  const std::vector<float> red = {0.2f, 0.3f, 0.0f, 0.0f, 0.5f, 0.0f, 0.1f, 0.75f};
  const Image<float> v = msgs::ndvi(grey(4, 2, nir), grey(4, 2, red));
  REQUIRE(v.channels == 1);
  REQUIRE(v.width == 4);
  REQUIRE(v.height == 2);
  for (std::size_t i = 0; i < nir.size(); ++i) {
    const double s = double(nir[i]) + double(red[i]);
    const double want = s < 1e-6 ? 0.0 : (double(nir[i]) - double(red[i])) / s;
    CHECK(std::isfinite(v.data[i]));
    CHECK(v.data[i] == doctest::Approx(want).epsilon(1e-6));
  }
  CHECK(v.data[0] == doctest::Approx(0.6));
  CHECK(v.data[1] == 0.0f);   // equal bands
  CHECK(v.data[2] == 0.0f);   // NIR + R = 0: defined as the neutral 0
  CHECK(v.data[3] == 1.0f);
  CHECK(v.data[4] == -1.0f);
  CHECK(v.data[5] == 0.0f);   // below eps
  CHECK(v.data[6] == doctest::Approx(0.8));
  CHECK(v.data[7] == doctest::Approx(-0.5));

  // NDRE is the same formula with the red edge.
  const Image<float> e = msgs::ndre(grey(2, 1, {0.6f, 0.1f}), grey(2, 1, {0.2f, 0.3f}));
  CHECK(e.data[0] == doctest::Approx(0.5));
  CHECK(e.data[1] == doctest::Approx(-0.5));

  // Negative inputs (unclamped renders) stay within [-1, 1] and finite.
  const Image<float> n = msgs::normalized_difference(grey(2, 1, {-0.5f, 0.5f}), grey(2, 1, {0.4f, -0.49f}));
  for (float x : n.data) {
    CHECK(std::isfinite(x));
    CHECK(x >= -1.0f);
    CHECK(x <= 1.0f);
  }

  CHECK_THROWS_AS(msgs::ndvi(grey(1, 1, {std::nanf("")}), grey(1, 1, {0.5f})), std::invalid_argument);
  CHECK_THROWS_AS(msgs::ndvi(grey(1, 1, {INFINITY}), grey(1, 1, {0.5f})), std::invalid_argument);
  CHECK_THROWS_AS(msgs::ndvi(grey(2, 1, {0, 0}), grey(1, 1, {0})), std::invalid_argument);
  CHECK_THROWS_AS(msgs::ndvi(Image<float>(1, 1, 3), grey(1, 1, {0})), std::invalid_argument);
}

TEST_CASE("cir_composite puts NIR, R, G into red, green, blue") {
  const Image<float> nir = grey(2, 1, {0.9f, 0.8f}), red = grey(2, 1, {0.5f, 0.4f}), green = grey(2, 1, {0.1f, 0.2f});
  const Image<float> c = msgs::cir_composite(nir, red, green);
  REQUIRE(c.channels == 3);
  for (int x = 0; x < 2; ++x) {
    CHECK(c.at(x, 0, 0) == nir.at(x, 0, 0));
    CHECK(c.at(x, 0, 1) == red.at(x, 0, 0));
    CHECK(c.at(x, 0, 2) == green.at(x, 0, 0));
  }
  CHECK_THROWS_AS(msgs::cir_composite(nir, red, grey(1, 1, {0})), std::invalid_argument);
}

TEST_CASE("colour scales: endpoints, middle, clamping, colourize and legends") {
  using msgs::Colormap;
  auto near = [](std::array<float, 3> c, float r, float g, float b) {
    CHECK(c[0] == doctest::Approx(r / 255.0f).epsilon(1e-6));
    CHECK(c[1] == doctest::Approx(g / 255.0f).epsilon(1e-6));
    CHECK(c[2] == doctest::Approx(b / 255.0f).epsilon(1e-6));
  };
  // ColorBrewer RdYlGn ends and centre.
  near(msgs::colour_at(Colormap::diverging, 0.0f), 165, 0, 38);
  near(msgs::colour_at(Colormap::diverging, 1.0f), 0, 104, 55);
  near(msgs::colour_at(Colormap::diverging, 0.5f), 255, 255, 191);
  near(msgs::colour_at(Colormap::diverging, -3.0f), 165, 0, 38);
  near(msgs::colour_at(Colormap::diverging, 7.0f), 0, 104, 55);
  near(msgs::colour_at(Colormap::sequential, 0.0f), 0, 0, 0);
  near(msgs::colour_at(Colormap::sequential, 1.0f), 255, 255, 255);
  // Halfway between the first two stops of RdYlGn (0.1 apart).
  near(msgs::colour_at(Colormap::diverging, 0.05f), 190, 24, 38.5f);
  // Sequential scale brightens monotonically.
  float prev = -1;
  for (int i = 0; i <= 20; ++i) {
    const auto c = msgs::colour_at(Colormap::sequential, float(i) / 20);
    const float s = c[0] + c[1] + c[2];
    CHECK(s >= prev);
    prev = s;
  }

  const Image<float> ci = msgs::colourize(grey(3, 1, {-1.0f, 0.0f, 1.0f}), Colormap::diverging, -1.0f, 1.0f);
  near({ci.at(0, 0, 0), ci.at(0, 0, 1), ci.at(0, 0, 2)}, 165, 0, 38);
  near({ci.at(1, 0, 0), ci.at(1, 0, 1), ci.at(1, 0, 2)}, 255, 255, 191);
  near({ci.at(2, 0, 0), ci.at(2, 0, 1), ci.at(2, 0, 2)}, 0, 104, 55);
  CHECK_THROWS_AS(msgs::colourize(grey(1, 1, {0}), Colormap::diverging, 1.0f, 1.0f), std::invalid_argument);

  const Image<float> bar = msgs::legend_bar(50, 4, Colormap::diverging);
  CHECK(bar.width == 50);
  CHECK(bar.height == 4);
  near({bar.at(0, 3, 0), bar.at(0, 3, 1), bar.at(0, 3, 2)}, 165, 0, 38);
  near({bar.at(49, 0, 0), bar.at(49, 0, 1), bar.at(49, 0, 2)}, 0, 104, 55);

  Image<float> rgb(120, 90, 3, 0.25f);
  const Image<float> lg = msgs::with_legend(rgb, Colormap::diverging, -1.0f, 1.0f);
  CHECK(lg.width == 120);
  CHECK(lg.height > 90);
  CHECK(lg.at(60, 45, 1) == 0.25f);  // the picture itself is untouched
  // Somewhere in the strip is the red end of the bar, somewhere the label ink (black).
  bool red_end = false, ink = false;
  for (int y = 90; y < lg.height; ++y)
    for (int x = 0; x < lg.width; ++x) {
      if (std::abs(lg.at(x, y, 0) - 165 / 255.f) < 1e-5f && lg.at(x, y, 1) == 0.0f) red_end = true;
      if (lg.at(x, y, 0) == 0.0f && lg.at(x, y, 1) == 0.0f && lg.at(x, y, 2) == 0.0f) ink = true;
    }
  CHECK(red_end);
  CHECK(ink);
}

TEST_CASE("error_map: zero error is black, full scale white, channels averaged") {
  Image<float> a(2, 1, 3, 0.5f), b(2, 1, 3, 0.5f);
  for (int c = 0; c < 3; ++c) b.at(1, 0, c) = 0.5f + (c == 0 ? 0.75f : 0.0f);  // mean |diff| = 0.25
  const Image<float> e = msgs::error_map(a, b, 0.25f);
  REQUIRE(e.channels == 3);
  for (int c = 0; c < 3; ++c) {
    CHECK(e.at(0, 0, c) == 0.0f);
    CHECK(e.at(1, 0, c) == doctest::Approx(1.0f));
  }
  CHECK_THROWS_AS(msgs::error_map(a, Image<float>(2, 1, 1), 0.25f), std::invalid_argument);
  CHECK_THROWS_AS(msgs::error_map(a, b, 0.0f), std::invalid_argument);
}

TEST_CASE("contact sheet layout: column widths, row heights, gaps and placement") {
  const Image<float> a = grey(5, 4, std::vector<float>(20, 0.1f));
  Image<float> b(7, 3, 3, 0.2f);
  const Image<float> c = grey(2, 6, std::vector<float>(12, 0.3f));
  const msgs::SheetCells rows = {{&a, &b, nullptr}, {&c}, {nullptr, nullptr, &a}};
  const int gap = 3;
  const msgs::SheetLayout L = msgs::contact_sheet_layout(rows, gap);
  REQUIRE(L.col_w == std::vector<int>{5, 7, 5});
  REQUIRE(L.row_h == std::vector<int>{4, 6, 4});
  CHECK(L.col_x == std::vector<int>{3, 11, 21});
  CHECK(L.row_y == std::vector<int>{3, 10, 19});
  CHECK(L.width == gap * 4 + 5 + 7 + 5);
  CHECK(L.height == gap * 4 + 4 + 6 + 4);

  const Image<float> s = msgs::contact_sheet(rows, gap, 1.0f);
  CHECK(s.width == L.width);
  CHECK(s.height == L.height);
  CHECK(s.channels == 3);
  CHECK(s.at(3, 3, 2) == 0.1f);               // a, grey replicated
  CHECK(s.at(11 + 6, 3 + 2, 0) == 0.2f);      // b's last column
  CHECK(s.at(11 + 6, 3 + 3, 0) == 1.0f);      // below b (shorter than the row): fill
  CHECK(s.at(3 + 1, 10 + 5, 1) == 0.3f);      // c
  CHECK(s.at(21 + 4, 19 + 3, 0) == 0.1f);     // a again, bottom right
  CHECK(s.at(0, 0, 0) == 1.0f);               // gap
  CHECK_THROWS_AS(msgs::contact_sheet_layout({}, 2), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Models
// ---------------------------------------------------------------------------------------------

TEST_CASE("load_model dispatches on channel count and SH degree") {
  const fs::path dir = scratch_dir("dispatch");
  using namespace msgs;
  const auto m1 = toy_model<Gaussian<1, 0>>(3, 0.5f);
  const auto m3 = toy_model<Gaussian<3, 2>>(4, 1.5f);
  const auto m7 = toy_model<Gaussian<7, 3>>(2, 2.5f);
  const auto m7b = toy_model<Gaussian<7, 1>>(5, 3.5f);
  io::write_ply(dir / "one.ply", m1);
  io::write_ply(dir / "rgb.ply", m3, {"D_R", "D_G", "D_B"});
  io::write_ply(dir / "joint.ply", m7, io::joint_channel_names());
  io::write_ply(dir / "joint_unnamed.ply", m7b);

  const LoadedModel l1 = load_model(dir / "one.ply");
  CHECK(l1.channels() == 1);
  CHECK(l1.sh_degree() == 0);
  REQUIRE(std::holds_alternative<ModelOf<1, 0>>(l1.model));
  CHECK(std::get<ModelOf<1, 0>>(l1.model).sh == m1.sh);
  CHECK(l1.size() == 3);

  const LoadedModel l3 = load_model(dir / "rgb.ply");
  REQUIRE(std::holds_alternative<ModelOf<3, 2>>(l3.model));
  CHECK(std::get<ModelOf<3, 2>>(l3.model).means == m3.means);
  CHECK(std::get<ModelOf<3, 2>>(l3.model).sh == m3.sh);
  CHECK(l3.info.band_names == std::vector<std::string>{"D_R", "D_G", "D_B"});

  const LoadedModel l7 = load_model(dir / "joint.ply");
  REQUIRE(std::holds_alternative<ModelOf<7, 3>>(l7.model));
  CHECK(std::get<ModelOf<7, 3>>(l7.model).sh == m7.sh);
  CHECK(std::get<ModelOf<7, 3>>(l7.model).quats == m7.quats);
  REQUIRE(std::holds_alternative<ModelOf<7, 1>>(load_model(dir / "joint_unnamed.ply").model));

  // Refused: other channel counts (naming the field), point clouds, missing files.
  io::write_ply(dir / "five.ply", toy_model<Gaussian<5, 0>>(1, 0.0f));
  try {
    (void)load_model(dir / "five.ply");
    FAIL("five channels accepted");
  } catch (const io::IoError& e) {
    CHECK(std::string(e.what()).find("five.ply") != std::string::npos);
    CHECK(std::string(e.what()).find("f_dc_") != std::string::npos);
  }
  io::PointCloud pc;
  pc.xyz = {0, 0, 0, 1, 1, 1};
  io::write_point_cloud(dir / "points.ply", pc);
  CHECK_THROWS_AS((void)load_model(dir / "points.ply"), io::IoError);
  CHECK_THROWS_AS((void)load_model(dir / "missing.ply"), io::IoError);
}

TEST_CASE("ModelSet resolves bands from names, files and the Joint layout") {
  const fs::path dir = scratch_dir("modelset");
  using namespace msgs;
  const auto cam = small_camera();

  SUBCASE("Joint model with names: every band, adjacent bands in one pass") {
    io::write_ply(dir / "joint.ply", toy_model<Gaussian<7, 0>>(2, 0.5f), io::joint_channel_names());
    FakeFactory f;
    const ModelSet s = ModelSet::load(dir / "joint.ply", f);
    for (const auto& b : io::standard_bands()) {
      const BandSource* src = s.source(b.id);
      REQUIRE(src);
      CHECK(src->first_channel == b.first_channel_in_joint);
      CHECK(src->channels == b.channels);
    }
    const Image<float> d = s.render("D", cam);
    CHECK(d.channels == 3);
    CHECK(d.at(0, 0, 2) == 102.0f);
    *f.calls = 0;
    const auto views = s.render_bands({"MS_NIR", "MS_R", "MS_G", "MS_RE"}, cam);
    CHECK(*f.calls == 1);  // channels 3..6 in one forward
    CHECK(views[0].at(1, 1, 0) == 106.0f);
    CHECK(views[1].at(1, 1, 0) == 104.0f);
    CHECK(views[2].at(1, 1, 0) == 103.0f);
    CHECK(views[3].at(1, 1, 0) == 105.0f);
    CHECK_THROWS_AS(s.render("MS_R", cam, {0.1f, 0.2f}), std::invalid_argument);
  }

  SUBCASE("directory of per-band models, as msgs train writes for Separate") {
    io::write_ply(dir / "model_D.ply", toy_model<Gaussian<3, 1>>(2, 0.5f), {"D_R", "D_G", "D_B"});
    io::write_ply(dir / "model_MS_NIR.ply", toy_model<Gaussian<1, 0>>(2, 0.5f), {"MS_NIR"});
    io::write_ply(dir / "model_MS_R.ply", toy_model<Gaussian<1, 2>>(2, 0.5f), {"MS_R"});
    io::write_text_atomic(dir / "notes.txt", "not a model\n");
    FakeFactory f;
    const ModelSet s = ModelSet::load(dir, f);
    REQUIRE(s.models().size() == 3);  // sorted: model_D, model_MS_NIR, model_MS_R
    CHECK(s.source("D")->model == 0);
    CHECK(s.source("MS_NIR")->model == 1);
    CHECK(s.source("MS_R")->model == 2);
    CHECK_FALSE(s.renders("MS_G"));
    CHECK_FALSE(s.renders("MS_RE"));
    *f.calls = 0;
    const auto views = s.render_bands({"MS_R", "MS_NIR"}, cam);
    CHECK(*f.calls == 2);  // different models: one pass each
    CHECK(views[0].at(0, 0, 0) == 300.0f);
    CHECK(views[1].at(0, 0, 0) == 200.0f);
  }

  SUBCASE("files without band names") {
    io::write_ply(dir / "model_a.ply", toy_model<Gaussian<3, 0>>(1, 0.5f));
    io::write_ply(dir / "model_b.ply", toy_model<Gaussian<1, 0>>(1, 0.5f));
    const ModelSet s = ModelSet::load(dir, FakeFactory{});
    CHECK(s.source("D")->model == 0);
    for (const char* b : {"MS_G", "MS_R", "MS_RE", "MS_NIR"}) {
      REQUIRE(s.source(b));
      CHECK(s.source(b)->model == 1);
      CHECK_FALSE(s.named_source(b));  // not usable for composites
    }
    const ModelSet j = ModelSet::load([&] {
      io::write_ply(dir / "unnamed_joint.ply", toy_model<Gaussian<7, 0>>(1, 0.5f));
      return dir / "unnamed_joint.ply";
    }(), FakeFactory{});
    CHECK(j.named_source("MS_RE")->first_channel == 5);
  }

  SUBCASE("conflicts and unknown names are errors naming the file") {
    io::write_ply(dir / "model_x.ply", toy_model<Gaussian<3, 0>>(1, 0.5f), {"D_R", "D_G", "D_B"});
    io::write_ply(dir / "model_y.ply", toy_model<Gaussian<7, 0>>(1, 0.5f), io::joint_channel_names());
    try {
      (void)ModelSet::load(dir, FakeFactory{});
      FAIL("two models for D accepted");
    } catch (const io::IoError& e) {
      CHECK(std::string(e.what()).find("model_x.ply") != std::string::npos);
      CHECK(std::string(e.what()).find("band D") != std::string::npos);
    }
    io::write_ply(dir / "odd.ply", toy_model<Gaussian<1, 0>>(1, 0.5f), {"THERMAL"});
    CHECK_THROWS_WITH_AS((void)ModelSet::load(dir / "odd.ply", FakeFactory{}), doctest::Contains("msgs_bands"),
                         io::IoError);
    const fs::path empty = dir / "empty";
    fs::create_directories(empty);
    CHECK_THROWS_AS((void)ModelSet::load(empty, FakeFactory{}), io::IoError);
    CHECK_THROWS_AS((void)ModelSet::load(dir / "nothing_here", FakeFactory{}), io::IoError);
  }
}

// ---------------------------------------------------------------------------------------------
// Dataset helpers
// ---------------------------------------------------------------------------------------------

TEST_CASE("capture keys, band backgrounds and output staging") {
  CHECK(msgs::capture_key("images/MS_NIR_00007.TIF") == "00007");
  CHECK(msgs::capture_key("D_00001.JPG") == "00001");
  CHECK(msgs::capture_key("images/frame.png") == "");

  CHECK(msgs::band_background({}, "D").empty());
  CHECK(msgs::band_background({0.5f}, "MS_R") == std::vector<float>{0.5f});
  CHECK(msgs::band_background({0.1f, 0.2f, 0.3f}, "D") == std::vector<float>{0.1f, 0.2f, 0.3f});
  const std::vector<float> seven = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f};
  CHECK(msgs::band_background(seven, "D") == std::vector<float>{0.1f, 0.2f, 0.3f});
  CHECK(msgs::band_background(seven, "MS_RE") == std::vector<float>{0.6f});
  CHECK_THROWS_AS(msgs::band_background({0.1f, 0.2f, 0.3f}, "MS_G"), std::invalid_argument);
  CHECK_THROWS_AS(msgs::band_background({0.1f, 0.2f}, "D"), std::invalid_argument);
  CHECK_THROWS_AS(msgs::band_background({NAN}, "D"), std::invalid_argument);

  const fs::path dir = scratch_dir("stage");
  {
    msgs::OutputStage st(dir / "out_fail");
    msgs::io::write_text_atomic(st.dir() / "a.txt", "x");
  }  // no commit: nothing remains, not even the directory it created
  CHECK_FALSE(fs::exists(dir / "out_fail"));
  fs::create_directories(dir / "out_ok");
  msgs::io::write_text_atomic(dir / "out_ok" / "keep.txt", "old");
  {
    msgs::OutputStage st(dir / "out_ok");
    fs::create_directories(st.dir() / "sub");
    msgs::io::write_text_atomic(st.dir() / "sub" / "b.txt", "y");
    msgs::io::write_text_atomic(st.dir() / "a.txt", "x");
    CHECK_FALSE(fs::exists(dir / "out_ok" / "a.txt"));
    CHECK(st.commit().size() == 2);
  }
  CHECK(msgs::io::read_text(dir / "out_ok" / "a.txt") == "x");
  CHECK(msgs::io::read_text(dir / "out_ok" / "sub" / "b.txt") == "y");
  CHECK(msgs::io::read_text(dir / "out_ok" / "keep.txt") == "old");
  std::size_t entries = 0;
  for (const auto& e : fs::directory_iterator(dir / "out_ok")) entries += e.path().filename().string().rfind(".msgs", 0) == 0;
  CHECK(entries == 0);  // the staging directory is gone
}

// ---------------------------------------------------------------------------------------------
// End to end on the synthetic tiny dataset
// ---------------------------------------------------------------------------------------------

namespace {

using G7 = msgs::Gaussian<7, 0>;

/// The synthetic tiny dataset and a Joint model initialised from its points, made once.
struct TinyScene {
  fs::path root;
  msgs::SynthSummary synth;
  msgs::io::Dataset ds;
  msgs::GaussianModel<G7, float> joint;
  msgs::ModelSet models;

  static msgs::ChannelRenderer factory(std::shared_ptr<const msgs::LoadedModel> m) {
    if (m->channels() == 7) return msgs::make_typed_renderer<G7>(m);
    if (m->channels() == 3) return msgs::make_typed_renderer<msgs::Gaussian<3, 0>>(m);
    return msgs::make_typed_renderer<msgs::Gaussian<1, 0>>(m);
  }

  static const TinyScene& get() {
    static const TinyScene scene = make();
    return scene;
  }

 private:
  static TinyScene make() {
    using namespace msgs;
    TinyScene t;
    t.root = scratch_dir("e2e");
    SynthOptions so;
    so.preset = "tiny";
    so.seed = 3;
    t.synth = write_synthetic_dataset(t.root / "data", so);
    t.ds = io::load_dataset(t.root / "data");
    InitConfig ic;
    ic.initial_opacity = 0.6;
    ic.seed = 7;
    t.joint = init_from_points<G7>(t.ds.points.xyz, ic);
    io::write_ply(t.root / "joint.ply", t.joint, io::joint_channel_names());
    t.models = ModelSet::load(t.root / "joint.ply", factory);
    return t;
  }
};

}  // namespace

TEST_CASE("render_dataset: every frame from its own camera, composites from the NIR camera") {
  using namespace msgs;
  const TinyScene& t = TinyScene::get();
  const io::Dataset& ds = t.ds;
  const auto& joint = t.joint;
  REQUIRE(ds.frames.size() == 5u * std::size_t(t.synth.captures));

  DatasetRenderOptions opt;
  opt.write_float = true;
  const fs::path out = t.root / "render";
  DatasetRenderSummary sum;
  {
    OutputStage stage(out);
    sum = render_dataset(ds, t.models, stage.dir(), opt);
    stage.commit();
  }
  CHECK(sum.frames == ds.frames.size());
  CHECK(sum.skipped.empty());
  CHECK(sum.composite_captures == std::size_t(t.synth.captures));
  // Per frame a PNG and an npy; per capture CIR (png + npy), NDVI and NDRE (png + npy each).
  CHECK(sum.files.size() == 2 * ds.frames.size() + 6 * std::size_t(t.synth.captures));
  for (const auto& f : sum.files) CHECK(fs::is_regular_file(out / f));
  Rasterizer<G7, float> raster;
  for (const io::Frame& f : ds.frames) {
    const std::string stem = fs::path(f.file_path).stem().string();
    const io::BandInfo& b = *io::find_band(f.band);
    const Image<float> png = io::read_image(out / (stem + ".png"));
    CHECK(png.width == f.camera.width);
    CHECK(png.height == f.camera.height);
    CHECK(png.channels == b.channels);
    const auto [depth, type] = png_depth_and_type(out / (stem + ".png"));
    CHECK(depth == (b.channels == 1 ? 16 : 8));
    CHECK(type == (b.channels == 1 ? 0 : 2));  // grey / RGB
    const Image<float> npy = io::read_npy(out / (stem + ".npy"));
    REQUIRE(npy.channels == b.channels);
    REQUIRE(npy.width == f.camera.width);
    // The float output is exactly the rasterizer's render from the frame's own camera.
    RenderSettings<float> rs;
    rs.band_first = b.first_channel_in_joint;
    rs.band_count = b.channels;
    const Image<float>& ref = raster.forward(joint, f.camera, rs);
    CHECK(npy.data == ref.data);
  }

  // Composites are rendered from the NIR camera of each capture.
  std::set<std::string> keys;
  for (const io::Frame& f : ds.frames)
    if (f.band == "MS_NIR") {
      const std::string key = capture_key(f.file_path);
      keys.insert(key);
      RenderSettings<float> rs;
      rs.band_first = io::find_band("MS_R")->first_channel_in_joint;
      rs.band_count = 1;
      const Image<float> red = raster.forward(joint, f.camera, rs);
      rs.band_first = io::find_band("MS_NIR")->first_channel_in_joint;
      const Image<float> nir = raster.forward(joint, f.camera, rs);
      const Image<float> got = io::read_npy(out / ("NDVI_" + key + ".npy"));
      REQUIRE(got.width == nir.width);
      REQUIRE(got.height == nir.height);
      double max_diff = 0;
      bool all_finite = true;
      for (std::size_t p = 0; p < got.data.size(); ++p) {
        const double s = double(nir.data[p]) + double(red.data[p]);
        const double want = s < 1e-6 ? 0.0 : (double(nir.data[p]) - double(red.data[p])) / s;
        max_diff = std::max(max_diff, std::abs(want - double(got.data[p])));
        all_finite = all_finite && std::isfinite(got.data[p]);
      }
      CHECK(all_finite);
      CHECK(max_diff < 1e-5);
      const Image<float> cir = io::read_npy(out / ("CIR_" + key + ".npy"));
      CHECK(cir.channels == 3);
      CHECK(cir.at(5, 7, 0) == nir.at(5, 7, 0));
      CHECK(cir.at(5, 7, 1) == red.at(5, 7, 0));
      const Image<float> ndvi_png = io::read_image(out / ("NDVI_" + key + ".png"));
      CHECK(ndvi_png.width == nir.width);
      CHECK(ndvi_png.height > nir.height);  // legend strip
      CHECK(ndvi_png.channels == 3);
    }
  CHECK(keys.size() == std::size_t(t.synth.captures));

}

TEST_CASE("evaluation: metrics as an independent render, contact sheet layout") {
  using namespace msgs;
  const TinyScene& t = TinyScene::get();
  const io::Dataset& ds = t.ds;
  const auto& joint = t.joint;
  Rasterizer<G7, float> raster;
  const fs::path sheets = t.root / "sheets";
  fs::create_directories(sheets);
  const EvalResult res = evaluate_models(ds, t.models, sheets);
  REQUIRE(res.metrics.size() == io::standard_bands().size());
  CHECK(res.skipped_bands.empty());
  for (std::size_t b = 0; b < res.metrics.size(); ++b) {
    const BandMetrics& m = res.metrics[b];
    CHECK(m.band == io::standard_bands()[b].id);
    const auto eval = ds.frames_of(m.band, io::Split::eval);
    REQUIRE(m.psnr.size() == eval.size());
    REQUIRE(res.frames[b].size() == eval.size());
    for (std::size_t i = 0; i < eval.size(); ++i) {
      const io::Frame& f = ds.frames[eval[i]];
      CHECK(res.frames[b][i] == f.file_path);
      const io::BandInfo& bi = *io::find_band(f.band);
      RenderSettings<float> rs;
      rs.band_first = bi.first_channel_in_joint;
      rs.band_count = bi.channels;
      rs.background = eval_background<float>(bi.channels);
      Image<float> r = raster.forward(joint, f.camera, rs);
      for (float& v : r.data) v = std::clamp(v, 0.0f, 1.0f);
      const Image<float> gt = io::load_frame_image(ds, f, 1);
      CHECK(m.psnr[i] == doctest::Approx(psnr(r, gt)).epsilon(1e-12));
      CHECK(m.ssim[i] == doctest::Approx(ssim(r, gt, msgs::SsimBorder::valid)).epsilon(1e-12));  // EvalOptions::ssim_border
      CHECK(std::isfinite(m.psnr[i]));
    }
  }
  // One sheet per eval capture: five band rows, then CIR, NDVI, NDRE; three columns. With a text
  // renderer: row labels in a column on the left, a line of column titles above the first row
  // and above NDVI, legend strips below CIR and below NDRE.
  const std::size_t eval_captures = std::size_t(t.synth.eval_captures);
  REQUIRE(res.files.size() == eval_captures);
  const Image<float> sheet = io::read_image(sheets / res.files.front());
  const int gap = EvalOptions{}.gap;
  const int rgb_w = t.synth.width[0], rgb_h = t.synth.height[0], ms_h = t.synth.height[1];
  int label_w = 0, lines_h = 0;
  if (const TextRenderer* text = default_text()) {
    const int px = label_px(rgb_w);
    for (const char* l : {"RGB (D)", "green (MS_G)", "red (MS_R)", "red edge (MS_RE)", "NIR (MS_NIR)", "CIR", "NDVI", "NDRE"})
      label_w = std::max(label_w, text_width(*text, l, px));
    label_w += gap;
    lines_h = 2 * (text->line_height(px) + gap) + 2 * (legend_metrics(px, text).height() + gap);
  }
  CHECK(sheet.width == 4 * gap + 3 * rgb_w + label_w);
  CHECK(sheet.height == 9 * gap + rgb_h + 7 * ms_h + lines_h);
  // Without labels: the grid alone.
  EvalOptions plain;
  plain.labels = false;
  plain.max_sheets = 1;
  const fs::path plain_dir = t.root / "sheets_plain";
  fs::create_directories(plain_dir);
  const EvalResult pr = evaluate_models(ds, t.models, plain_dir, plain);
  const Image<float> ps = io::read_image(plain_dir / pr.files.front());
  CHECK(ps.width == 4 * gap + 3 * rgb_w);
  CHECK(ps.height == 9 * gap + rgb_h + 7 * ms_h);
}

TEST_CASE("band_label: colour name and id") {
  CHECK(msgs::band_label("D") == "RGB (D)");
  CHECK(msgs::band_label("MS_G") == "green (MS_G)");
  CHECK(msgs::band_label("MS_RE") == "red edge (MS_RE)");
  CHECK(msgs::band_label("MS_NIR") == "NIR (MS_NIR)");
  CHECK(msgs::band_label("X") == "X");
}

TEST_CASE("Separate models in a directory render the same images; composites where bands exist") {
  using namespace msgs;
  const TinyScene& t = TinyScene::get();
  const io::Dataset& ds = t.ds;
  const auto& joint = t.joint;
  Rasterizer<G7, float> raster;
  const fs::path dir = t.root / "separate";
  fs::create_directories(dir);
  io::write_ply(dir / "model_D.ply", io::slice_channels<0, 3>(joint), {"D_R", "D_G", "D_B"});
  io::write_ply(dir / "model_MS_R.ply", io::slice_channels<4, 1>(joint), {"MS_R"});
  io::write_ply(dir / "model_MS_NIR.ply", io::slice_channels<6, 1>(joint), {"MS_NIR"});
  const ModelSet sep = ModelSet::load(dir, TinyScene::factory);
  DatasetRenderOptions so2;
  so2.split = io::Split::eval;
  so2.write_float = true;
  so2.background = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f};
  const fs::path out2 = t.root / "render_sep";
  fs::create_directories(out2);
  const DatasetRenderSummary s2 = render_dataset(ds, sep, out2, so2);
  const std::size_t eval_frames_per_band = ds.frames_of("D", io::Split::eval).size();
  CHECK(s2.frames == 3 * eval_frames_per_band);
  CHECK(s2.skipped.size() == 2 * eval_frames_per_band);  // MS_G, MS_RE
  for (std::size_t f : ds.frames_of("MS_NIR", io::Split::eval)) {
    const std::string key = capture_key(ds.frames[f].file_path);
    CHECK(fs::exists(out2 / ("NDVI_" + key + ".png")));
    CHECK_FALSE(fs::exists(out2 / ("CIR_" + key + ".png")));   // no green model
    CHECK_FALSE(fs::exists(out2 / ("NDRE_" + key + ".png")));  // no red-edge model
  }
  for (std::size_t f : ds.frames_of("MS_R", io::Split::eval)) {
    const io::Frame& fr = ds.frames[f];
    const Image<float> got = io::read_npy(out2 / (fs::path(fr.file_path).stem().string() + ".npy"));
    RenderSettings<float> rs;
    rs.band_first = 4;
    rs.band_count = 1;
    rs.background = {0.5f};  // MS_R's slot of the seven values
    const Image<float>& ref = raster.forward(joint, fr.camera, rs);
    REQUIRE(got.data.size() == ref.data.size());
    double max_diff = 0;
    for (std::size_t i = 0; i < ref.data.size(); ++i)
      max_diff = std::max(max_diff, std::abs(double(got.data[i]) - double(ref.data[i])));
    CHECK(max_diff < 1e-6);
  }
}

TEST_CASE("bad background and empty selections are refused before anything is written") {
  using namespace msgs;
  const TinyScene& t = TinyScene::get();
  const io::Dataset& ds = t.ds;
  const fs::path out3 = t.root / "render_bad";
  fs::create_directories(out3);
  DatasetRenderOptions bad;
  bad.background = {0.1f, 0.2f};
  CHECK_THROWS_AS(render_dataset(ds, t.models, out3, bad), std::invalid_argument);
  CHECK(fs::is_empty(out3));
  DatasetRenderOptions none;
  none.split = io::Split::unused;
  CHECK_THROWS_AS(render_dataset(ds, t.models, out3, none), io::IoError);
  CHECK(fs::is_empty(out3));
}

}  // namespace test_render_util
