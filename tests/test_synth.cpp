// tests/test_synth.cpp
// Tests of the synthetic dataset generator: layout, split, determinism, reflectance ordering in the
// rendered images, cross-band detail, and agreement of the written cameras with the ray tracer.
#include <doctest/doctest.h>

#include <msgs/io/bands.hpp>
#include <msgs/io/dataset.hpp>
#include <msgs/synth.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace test_synth {
namespace fs = std::filesystem;
using namespace msgs::synth;
using Json = nlohmann::json;

namespace {

fs::path scratch_dir() {
  const char* env = std::getenv("MSGS_TEST_TMP");
  fs::path d = env ? fs::path(env) : fs::temp_directory_path() / "msgs_test";
  d /= "synth";
  fs::create_directories(d);
  return d;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The tiny dataset with seed 1, generated once per test run.
const fs::path& tiny_dataset() {
  static const fs::path dir = [] {
    const fs::path d = scratch_dir() / "tiny_seed1";
    fs::remove_all(d);
    SynthOptions opt;
    opt.preset = "tiny";
    opt.seed = 1;
    write_synthetic_dataset(d, opt);
    return d;
  }();
  return dir;
}

/// A camera parsed straight from a transforms.json frame.
struct JsonCam {
  Eigen::Matrix4d c2w;  // OpenGL axes
  double fx, fy, cx, cy;
  int w, h;
  std::string path, band;
};

std::vector<JsonCam> read_cameras(const fs::path& dir) {
  const Json tf = Json::parse(slurp(dir / "transforms.json"));
  std::vector<JsonCam> cams;
  for (const auto& f : tf.at("frames")) {
    JsonCam c;
    for (int r = 0; r < 4; ++r)
      for (int k = 0; k < 4; ++k) c.c2w(r, k) = f.at("transform_matrix").at(r).at(k).get<double>();
    c.fx = f.at("fl_x"); c.fy = f.at("fl_y"); c.cx = f.at("cx"); c.cy = f.at("cy");
    c.w = f.at("w"); c.h = f.at("h");
    c.path = f.at("file_path"); c.band = f.at("mm_channel");
    cams.push_back(c);
  }
  return cams;
}

/// Pinhole projection written out from the OpenGL camera-to-world matrix (independent of
/// Camera::from_opengl_c2w): camera looks down -z, y up, so image v grows with -y.
bool project_gl(const JsonCam& c, const Eigen::Vector3d& p, double& u, double& v) {
  const Eigen::Matrix3d rot = c.c2w.block<3, 3>(0, 0);
  const Eigen::Vector3d q = rot.transpose() * (p - c.c2w.block<3, 1>(0, 3));
  if (q.z() > -1e-3) return false;
  u = c.cx + c.fx * (q.x() / -q.z());
  v = c.cy + c.fy * (-q.y() / -q.z());
  return u >= 0 && v >= 0 && u < c.w && v < c.h;
}

/// World ray through continuous pixel (u, v), again from the OpenGL matrix.
Ray ray_gl(const JsonCam& c, double u, double v) {
  const Eigen::Vector3d dir_cam((u - c.cx) / c.fx, -(v - c.cy) / c.fy, -1.0);
  Ray r;
  r.o = c.c2w.block<3, 1>(0, 3).cast<float>();
  r.d = (c.c2w.block<3, 3>(0, 0) * dir_cam).normalized().cast<float>();
  return r;
}

/// Classify a pixel by tracing its centre and four inner corners: the surface if all agree.
Surface pixel_surface(const SynthScene& s, const JsonCam& c, int x, int y, RayHit* centre = nullptr) {
  const double offs[5][2] = {{0.5, 0.5}, {0.1, 0.1}, {0.9, 0.1}, {0.1, 0.9}, {0.9, 0.9}};
  Surface first = Surface::None;
  for (int k = 0; k < 5; ++k) {
    const RayHit h = trace(s, ray_gl(c, x + offs[k][0], y + offs[k][1]));
    if (k == 0) {
      first = h.surface;
      if (centre) *centre = h;
    } else if (h.surface != first) {
      return Surface::None;
    }
  }
  return first;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

double cv(const std::vector<double>& v) {  // coefficient of variation
  const double m = mean(v);
  double s = 0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / double(std::max<std::size_t>(1, v.size()))) / std::max(1e-12, std::abs(m));
}

/// PNG bit depth from the IHDR chunk (byte 24).
int png_bit_depth(const fs::path& p) {
  const std::string b = slurp(p);
  REQUIRE(b.size() > 25);
  return static_cast<unsigned char>(b[24]);
}

}  // namespace

TEST_CASE("synth: presets, unknown preset and bands") {
  CHECK(synth_preset("tiny").captures >= 8);
  CHECK(synth_preset("small").rgb_width > synth_preset("tiny").rgb_width);
  CHECK(synth_preset("medium").ms_width > synth_preset("small").ms_width);
  try {
    (void)synth_preset("huge");
    FAIL("unknown preset accepted");
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    CHECK(msg.find("huge") != std::string::npos);
    CHECK(msg.find("tiny") != std::string::npos);
    CHECK(msg.find("medium") != std::string::npos);
  }
  CHECK(band_from_name("MS_NIR") == Band::MS_NIR);
  CHECK_THROWS_AS(band_from_name("NIR"), std::invalid_argument);
  // Band channel offsets agree with the io band table (Joint model channel order).
  for (Band b : all_bands) {
    const auto* info = msgs::io::find_band(band_name(b));
    REQUIRE(info != nullptr);
    CHECK(info->first_channel_in_joint == band_offset(b));
    CHECK(info->channels == band_channels(b));
  }
}

TEST_CASE("synth: rig looks at the scene from nadir to oblique") {
  const SynthScene s = make_scene("tiny", 3);
  REQUIRE(s.captures.size() == std::size_t(synth_preset("tiny").captures));
  float max_tilt = 0.f;
  for (const Capture& cap : s.captures) {
    max_tilt = std::max(max_tilt, cap.tilt_deg);
    const auto& d = cap.cameras[0];
    for (Band b : all_bands) {
      const auto& c = cap.cameras[static_cast<std::size_t>(b)];
      CHECK_NOTHROW(c.validate());
      // Rotations are orthonormal; lenses sit within 10 cm of the RGB lens.
      CHECK((c.R * c.R.transpose() - Mat3f::Identity()).norm() < 1e-5f);
      CHECK((c.position() - d.position()).norm() < 0.1f);
      if (b != Band::D) CHECK((c.position() - d.position()).norm() > 0.01f);
      CHECK(c.width == (b == Band::D ? s.preset.rgb_width : s.preset.ms_width));
      // Principal points slightly off-centre.
      CHECK(std::abs(c.cx - 0.5f * c.width) > 0.001f * c.width);
      CHECK(std::abs(c.cx - 0.5f * c.width) < 0.05f * c.width);
    }
    // Everyone sees the scene centre.
    for (const auto& c : cap.cameras) {
      const Vec3f q = c.R * Vec3f::Zero() + c.t;
      REQUIRE(q.z() > 0.f);
      const float u = c.fx * q.x() / q.z() + c.cx, v = c.fy * q.y() / q.z() + c.cy;
      CHECK(u > 0.f);
      CHECK(u < float(c.width));
      CHECK(v > 0.f);
      CHECK(v < float(c.height));
    }
  }
  // Capture 0 is nadir: the forward axis (third row of R) points straight down.
  CHECK(s.captures[0].cameras[0].R.row(2).z() < -0.9999f);
  CHECK(max_tilt > 25.f);
  // Different MS lenses have different focal lengths.
  CHECK(s.captures[0].cameras[1].fx != s.captures[0].cameras[2].fx);
}

TEST_CASE("synth: ray tracer ground truth on simple rays") {
  const SynthScene s = make_scene("tiny", 1);
  // Straight down onto the pond centre: hits water at its height.
  Ray r;
  r.o = Vec3f(s.pond.c.x(), s.pond.c.y(), 20.f);
  r.d = Vec3f(0, 0, -1);
  RayHit h = trace(s, r);
  REQUIRE(h.hit);
  CHECK(h.surface == Surface::Pond);
  CHECK(h.p.z() == doctest::Approx(s.pond.c.z()).epsilon(1e-4));
  // Straight down onto a tree: crown above the trunk height, normal facing up-ish.
  const Tree& t = s.trees[0];
  r.o = Vec3f(t.trunk.base.x(), t.trunk.base.y(), 20.f);
  h = trace(s, r);
  REQUIRE(h.hit);
  CHECK(h.surface == Surface::Crown);
  CHECK(h.p.z() > t.trunk.h * 0.5f);
  CHECK(h.n.z() > 0.f);
  // Upward ray escapes to the sky.
  r.o = Vec3f(0, 0, 1);
  r.d = Vec3f(0, 0, 1);
  CHECK_FALSE(trace(s, r).hit);
  // Under the panels the ground lies in shadow when the sun is behind them: a point below a panel
  // centre, lit only if nothing is on the way to the sun.
  const PanelRow& row = s.panels[0];
  const Vec3f below(row.panel.c.x(), row.panel.c.y(), 0.f);
  CHECK(occluded(s, below + Vec3f(0, 0, 1e-3f), Vec3f(0, 0, 1)));
}

TEST_CASE("synth: dataset layout, split and PLY") {
  const fs::path& dir = tiny_dataset();
  const SynthPreset& p = synth_preset("tiny");
  REQUIRE(fs::is_regular_file(dir / "transforms.json"));
  REQUIRE(fs::is_regular_file(dir / "train_split.json"));
  REQUIRE(fs::is_regular_file(dir / "sparse_pc.ply"));
  // No temporary leftovers next to the output.
  for (const auto& e : fs::directory_iterator(dir.parent_path()))
    CHECK(e.path().filename().string().find(".synth-") == std::string::npos);

  const Json tf = Json::parse(slurp(dir / "transforms.json"));
  CHECK(tf.at("ply_file_path") == "sparse_pc.ply");
  CHECK(tf.at("camera_model") == "OPENCV");
  const auto& frames = tf.at("frames");
  REQUIRE(frames.size() == std::size_t(num_bands * p.captures));
  std::set<std::string> paths;
  int per_band[num_bands] = {};
  for (const auto& f : frames) {
    const std::string fp = f.at("file_path");
    const Band b = band_from_name(f.at("mm_channel").get<std::string>());
    per_band[static_cast<int>(b)]++;
    paths.insert(fp);
    CHECK(fp.rfind("images/" + std::string(band_name(b)) + "_", 0) == 0);
    for (const char* k : {"k1", "k2", "k3", "k4", "p1", "p2"}) CHECK(f.at(k).get<double>() == 0.0);
    CHECK(f.at("camera_model") == "OPENCV");
    const auto& m = f.at("transform_matrix");
    REQUIRE(m.size() == 4);
    CHECK(m.at(3) == Json::array({0.0, 0.0, 0.0, 1.0}));
    const int w = f.at("w"), h = f.at("h");
    CHECK(w == (b == Band::D ? p.rgb_width : p.ms_width));
    CHECK(h == (b == Band::D ? p.rgb_height : p.ms_height));
    // Full resolution and every downscaled copy exist with the right size, channels and depth.
    const msgs::Image<float> img = msgs::io::read_image(dir / fp);
    CHECK(img.width == w);
    CHECK(img.height == h);
    CHECK(img.channels == band_channels(b));
    CHECK(png_bit_depth(dir / fp) == (b == Band::D ? 8 : 16));
    for (int fct : p.downscales) {
      const fs::path dp = dir / ("images_" + std::to_string(fct)) / fs::path(fp).filename();
      REQUIRE(fs::is_regular_file(dp));
      const msgs::Image<float> small = msgs::io::read_image(dp);
      CHECK(small.width == (w + fct - 1) / fct);
      CHECK(small.height == (h + fct - 1) / fct);
    }
  }
  CHECK(paths.size() == frames.size());
  for (int b = 0; b < num_bands; ++b) CHECK(per_band[b] == p.captures);

  // train_split.json carries trailing commas like the published files; with them removed it is
  // plain JSON. Every 10th capture (0, 10, ...) is eval, everything else train.
  const std::string split_text = slurp(dir / "train_split.json");
  CHECK(std::regex_search(split_text, std::regex(",\\s*\\]")));
  const Json split = Json::parse(std::regex_replace(split_text, std::regex(",(\\s*[\\]}])"), "$1"));
  std::set<std::string> train, eval;
  for (const auto& x : split.at("train")) train.insert(x.get<std::string>());
  for (const auto& x : split.at("eval")) eval.insert(x.get<std::string>());
  CHECK(train.size() + eval.size() == paths.size());
  for (const auto& fp : paths) {
    const int idx = std::stoi(fp.substr(fp.size() - 9, 5)) - 1;  // "..._00011.png" -> 10
    CHECK(eval.count(fp) == (idx % 10 == 0 ? 1u : 0u));
    CHECK(train.count(fp) == (idx % 10 == 0 ? 0u : 1u));
  }
  CHECK(eval.size() == std::size_t(num_bands * ((p.captures + 9) / 10)));

  // PLY: header as nerfstudio writes it, ~5 % outliers, both RGB and grey colours.
  std::ifstream ply(dir / "sparse_pc.ply");
  std::string line;
  std::size_t n = 0;
  std::vector<std::string> props;
  while (std::getline(ply, line) && line != "end_header") {
    if (line.rfind("element vertex ", 0) == 0) n = std::stoul(line.substr(15));
    if (line.rfind("property ", 0) == 0) props.push_back(line.substr(9));
  }
  CHECK(props == std::vector<std::string>{"float x", "float y", "float z", "uint8 red", "uint8 green", "uint8 blue"});
  CHECK(n == std::size_t(p.points));
  std::size_t rows = 0, grey = 0;
  double x, y, z;
  int r, g, b;
  while (ply >> x >> y >> z >> r >> g >> b) {
    ++rows;
    grey += (r == g && g == b);
    CHECK((std::isfinite(x) && std::isfinite(y) && std::isfinite(z)));
  }
  CHECK(rows == n);
  CHECK(grey > n / 4);
  CHECK(grey < 3 * n / 4);
}

TEST_CASE("synth: same seed gives identical files, another seed does not; no partial output") {
  const fs::path& a = tiny_dataset();
  const fs::path b = scratch_dir() / "tiny_seed1_again";
  fs::remove_all(b);
  SynthOptions opt;
  opt.seed = 1;
  const SynthSummary sum = write_synthetic_dataset(b, opt);
  CHECK(sum.captures == synth_preset("tiny").captures);
  CHECK(sum.outliers > 0);
  for (const char* f : {"transforms.json", "train_split.json", "sparse_pc.ply", "images/D_00003.png",
                        "images/MS_NIR_00007.png", "images/MS_RE_00001.png", "images_2/MS_G_00004.png"}) {
    INFO(f);
    const std::string x = slurp(a / f), y = slurp(b / f);
    CHECK(!x.empty());
    CHECK(x == y);
  }
  // Seed 2 moves things around: the first RGB frame differs.
  const SynthScene s1 = make_scene("tiny", 1), s2 = make_scene("tiny", 2);
  const auto i1 = render_band(s1, s1.captures[0].cameras[0], Band::D);
  const auto i2 = render_band(s2, s2.captures[0].cameras[0], Band::D);
  CHECK(i1.data != i2.data);

  // Existing output without overwrite: refused, old data untouched, nothing left behind.
  const std::string before = slurp(b / "transforms.json");
  CHECK_THROWS_AS(write_synthetic_dataset(b, opt), msgs::io::IoError);
  CHECK(slurp(b / "transforms.json") == before);
  // Unknown preset: refused before anything is written.
  SynthOptions bad;
  bad.preset = "enormous";
  CHECK_THROWS_AS(write_synthetic_dataset(scratch_dir() / "never", bad), std::invalid_argument);
  CHECK_FALSE(fs::exists(scratch_dir() / "never"));
  for (const auto& e : fs::directory_iterator(scratch_dir()))
    CHECK(e.path().filename().string().find(".synth-") == std::string::npos);
  fs::remove_all(b);
}

TEST_CASE("synth: reflectance ordering in the written images") {
  const fs::path& dir = tiny_dataset();
  const SynthScene s = make_scene("tiny", 1);
  const auto cams = read_cameras(dir);
  // Per band: mean pixel value over pixels that are entirely vegetation (tree crowns) or water.
  std::vector<double> veg[num_bands], water[num_bands];
  for (const JsonCam& c : cams) {
    const int b = static_cast<int>(band_from_name(c.band));
    const msgs::Image<float> img = msgs::io::read_image(dir / c.path);
    for (int y = 0; y < c.h; ++y)
      for (int x = 0; x < c.w; ++x) {
        const Surface sf = pixel_surface(s, c, x, y);
        // For RGB take linear green, so the numbers compare with the narrow bands.
        const double v = b == 0 ? srgb_decode(img.at(x, y, 1)) : img.at(x, y, 0);
        if (sf == Surface::Crown) veg[b].push_back(v);
        if (sf == Surface::Pond) water[b].push_back(v);
      }
  }
  const int G = 1, R = 2, RE = 3, NIR = 4;
  for (int b = 0; b < num_bands; ++b) {
    REQUIRE(veg[b].size() > 20);
    REQUIRE(water[b].size() > 20);
  }
  MESSAGE("vegetation G/R/RE/NIR: ", mean(veg[G]), " ", mean(veg[R]), " ", mean(veg[RE]), " ", mean(veg[NIR]));
  MESSAGE("water      G/R/RE/NIR: ", mean(water[G]), " ", mean(water[R]), " ", mean(water[RE]), " ", mean(water[NIR]));
  // Red edge: vegetation NIR far above red; red below green (chlorophyll absorption).
  CHECK(mean(veg[NIR]) > 5.0 * mean(veg[R]));
  CHECK(mean(veg[RE]) > 3.0 * mean(veg[R]));
  CHECK(mean(veg[G]) > mean(veg[R]));
  // Water is dark in NIR, darker than in green, and far darker than vegetation.
  CHECK(mean(water[NIR]) < 0.03);
  CHECK(mean(water[NIR]) < mean(water[G]));
  CHECK(mean(water[NIR]) < 0.1 * mean(veg[NIR]));
}

TEST_CASE("synth: detail that lives in one part of the spectrum") {
  const SynthScene s = make_scene("tiny", 1);
  // Leaf vigour: over crown hits, the NIR/G albedo ratio varies strongly while the RGB hue
  // (R/G and B/G of the RGB camera) barely moves.
  std::vector<double> nir_g, rgb_rg, rgb_bg;
  // Painted pad: the albedo varies strongly in RGB and not at all in red edge / NIR.
  std::vector<double> pad_rgb, pad_nir, pad_re;
  Rng rng(7);
  for (int i = 0; i < 6000; ++i) {
    const std::size_t ti = rng.below(s.trees.size());
    const Tree& t = s.trees[ti];
    Ray r;
    r.o = t.bound.c + Vec3f(float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), 0.f) * (0.7f * t.bound.r);
    r.o.z() = 30.f;
    const RayHit h = trace(s, r);
    if (h.surface == Surface::Crown) {
      const Spectrum a = albedo(s, h);
      nir_g.push_back(a[6] / a[3]);
      rgb_rg.push_back(a[0] / a[1]);
      rgb_bg.push_back(a[2] / a[1]);
    }
    const Vec2f q = s.pad.c + Vec2f(float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))).cwiseProduct(s.pad.half) * 0.95f;
    // Inside the (rotated) pad: rotate the offset.
    const float ca = std::cos(s.pad.angle), sa = std::sin(s.pad.angle);
    const Vec2f d = q - s.pad.c;
    const Vec2f w = s.pad.c + Vec2f(ca * d.x() - sa * d.y(), sa * d.x() + ca * d.y());
    const Spectrum g = ground_albedo(s, w.x(), w.y());
    pad_rgb.push_back(0.2126 * g[0] + 0.7152 * g[1] + 0.0722 * g[2]);
    pad_re.push_back(g[5]);
    pad_nir.push_back(g[6]);
  }
  REQUIRE(nir_g.size() > 1000);
  MESSAGE("crown cv NIR/G ", cv(nir_g), "  R/G ", cv(rgb_rg), "  B/G ", cv(rgb_bg));
  MESSAGE("pad cv luma ", cv(pad_rgb), "  RE ", cv(pad_re), "  NIR ", cv(pad_nir));
  CHECK(cv(nir_g) > 0.15);
  CHECK(cv(rgb_rg) < 0.01);
  CHECK(cv(rgb_bg) < 0.01);
  CHECK(cv(pad_rgb) > 0.3);
  CHECK(cv(pad_nir) < 0.06);
  CHECK(cv(pad_re) < 0.06);
}

TEST_CASE("synth: written cameras agree with the ray tracer (pose consistency)") {
  const fs::path& dir = tiny_dataset();
  const SynthScene s = make_scene("tiny", 1);
  const auto cams = read_cameras(dir);
  std::vector<int> all;
  for (int i = 0; i < s.preset.captures; ++i) all.push_back(i);
  const SparsePoints pts = sample_sparse_points(s, all, s.preset.points, 1);

  // The PLY holds exactly these points (written with 6 decimals).
  {
    std::ifstream ply(dir / "sparse_pc.ply");
    std::string line;
    while (std::getline(ply, line) && line != "end_header") {}
    double x, y, z;
    int r, g, b;
    std::size_t i = 0;
    double worst = 0;
    while (ply >> x >> y >> z >> r >> g >> b && i < pts.size()) {
      worst = std::max({worst, std::abs(x - pts.positions[3 * i]), std::abs(y - pts.positions[3 * i + 1]),
                        std::abs(z - pts.positions[3 * i + 2])});
      ++i;
    }
    CHECK(i == pts.size());
    CHECK(worst < 1e-5);
    // Inliers sit near their clean surface points (noise 0.5 % of the range), outliers do not count.
    std::vector<double> dev;
    for (std::size_t k = 0; k < pts.size(); ++k)
      if (!pts.outlier[k])
        dev.push_back((Eigen::Vector3f(pts.positions[3 * k], pts.positions[3 * k + 1], pts.positions[3 * k + 2]) -
                       Eigen::Vector3f(pts.clean[3 * k], pts.clean[3 * k + 1], pts.clean[3 * k + 2])).norm());
    std::sort(dev.begin(), dev.end());
    CHECK(dev[dev.size() / 2] > 0.02);
    CHECK(dev[dev.size() / 2] < 0.3);
    CHECK(std::count(pts.outlier.begin(), pts.outlier.end(), 1) == s.preset.points / 20);
  }

  // Project every clean inlier with every camera as written to transforms.json (OpenGL matrix,
  // fl_x, fl_y, cx, cy); the ray that the renderer shot through that pixel position (the scene's
  // own camera for that frame) must meet the point itself, unless something closer is in the way
  // (occlusion). A ray that passes where the point is means the written pose disagrees.
  auto check = [&](bool flip_y, int& agree, int& behind, int& total) {
    agree = behind = total = 0;
    for (const JsonCam& c : cams) {
      const int ci = std::stoi(c.path.substr(c.path.size() - 9, 5)) - 1;
      const auto& rcam = s.captures.at(std::size_t(ci)).cameras[static_cast<std::size_t>(band_from_name(c.band))];
      for (std::size_t k = 0; k < pts.size(); k += 4) {
        if (pts.outlier[k]) continue;
        const Eigen::Vector3d p(pts.clean[3 * k], pts.clean[3 * k + 1], pts.clean[3 * k + 2]);
        double u, v;
        if (!project_gl(c, p, u, v)) continue;
        if (flip_y) v = c.h - v;
        const Ray r = camera_ray(rcam, float(u), float(v));
        const RayHit h = trace(s, r);
        const double dist = (p - r.o.cast<double>()).norm();
        ++total;
        if (h.hit && (h.p.cast<double>() - p).norm() < 5e-3) ++agree;
        else if (!h.hit || h.t > dist + 5e-3) ++behind;  // the ray passed where the point is: wrong pose
      }
    }
  };
  int agree, behind, total;
  check(false, agree, behind, total);
  MESSAGE("pose consistency: ", agree, " agree, ", behind, " pass through, of ", total);
  REQUIRE(total > 2000);
  CHECK(agree > 0.75 * total);
  CHECK(behind < 0.005 * total);
  // Negative control: the same check with the image upside down must fail badly.
  check(true, agree, behind, total);
  CHECK(agree < 0.2 * total);
  CHECK(behind > 0.1 * total);

  // The rendered pixels agree too: cameras read back through Camera::from_opengl_c2w render, with
  // the library's render_band, exactly the images on disk (to 16-bit / 8-bit quantisation).
  for (const JsonCam& c : cams) {
    if (c.path != "images/MS_NIR_00002.png" && c.path != "images/D_00005.png") continue;
    msgs::Camera<float> cam = msgs::Camera<float>::from_opengl_c2w(c.c2w.cast<float>());
    cam.fx = float(c.fx); cam.fy = float(c.fy); cam.cx = float(c.cx); cam.cy = float(c.cy);
    cam.width = c.w; cam.height = c.h;
    const Band b = band_from_name(c.band);
    const int ci = std::stoi(c.path.substr(c.path.size() - 9, 5)) - 1;
    RenderSettings rs;
    rs.aa = s.preset.aa;
    rs.jitter_seed = frame_jitter_seed(1, ci, b);
    const msgs::Image<float> mine = render_band(s, cam, b, rs);
    const msgs::Image<float> disk = msgs::io::read_image(dir / c.path);
    REQUIRE(mine.size() == disk.size());
    // Re-deriving R, t from the matrix moves rays by float rounding, which may flip a sub-pixel
    // sample across an edge here and there: allow a few such pixels, not more.
    const double tol = (b == Band::D ? 0.6 / 255.0 : 0.6 / 65535.0) + 1e-4;
    std::size_t off = 0;
    double sum = 0;
    for (std::size_t i = 0; i < mine.size(); ++i) {
      const double e = std::abs(double(mine.data[i]) - double(disk.data[i]));
      off += e > tol;
      sum += e;
    }
    INFO(c.path);
    CHECK(off <= mine.size() / 100);
    CHECK(sum / double(mine.size()) < 1e-3);
  }
}

TEST_CASE("synth: the dataset loader reads the generated dataset back") {
  const fs::path& dir = tiny_dataset();
  const SynthScene s = make_scene("tiny", 1);
  const int n = s.preset.captures;
  for (bool orient : {false, true}) {
    msgs::io::LoadOptions lo;
    lo.orient_and_center = orient;
    const msgs::io::Dataset ds = msgs::io::load_dataset(dir, lo);
    REQUIRE(ds.frames.size() == std::size_t(num_bands * n));
    CHECK(ds.has_split_file);
    CHECK(ds.points.size() == std::size_t(s.preset.points));
    for (Band b : all_bands) {
      CHECK(ds.frames_of(band_name(b), msgs::io::Split::eval).size() == std::size_t((n + 9) / 10));
      CHECK(ds.frames_of(band_name(b), msgs::io::Split::train).size() == std::size_t(n - (n + 9) / 10));
    }
    // Every loaded camera maps scene points to the same pixels as the generator's camera, after
    // the loader's world transform.
    const Eigen::Matrix4f T = ds.transform;
    for (const auto& f : ds.frames) {
      const int ci = std::stoi(f.file_path.substr(f.file_path.size() - 9, 5)) - 1;
      const auto& gen = s.captures.at(std::size_t(ci)).cameras[static_cast<std::size_t>(band_from_name(f.band))];
      CHECK(f.camera.width == gen.width);
      CHECK(f.camera.fx == doctest::Approx(gen.fx).epsilon(1e-6));
      CHECK(f.camera.cy == doctest::Approx(gen.cy).epsilon(1e-6));
      for (const Vec3f& p : {Vec3f(0.f, 0.f, 0.f), Vec3f(3.f, -2.f, 1.f), Vec3f(-4.f, 5.f, 0.5f)}) {
        const Vec3f qg = gen.R * p + gen.t;
        const Vec3f pd = (T * p.homogeneous()).head<3>();
        const Vec3f ql = f.camera.R * pd + f.camera.t;
        CHECK(std::abs(qg.x() / qg.z() - ql.x() / ql.z()) * gen.fx < 1e-2f);
        CHECK(std::abs(qg.y() / qg.z() - ql.y() / ql.z()) * gen.fy < 1e-2f);
      }
    }
    const auto img = msgs::io::load_frame_image(ds, ds.frames[3], 2);
    CHECK(img.width == (s.preset.ms_width + 1) / 2);
  }
}

}  // namespace test_synth
