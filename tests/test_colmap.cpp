// tests/test_colmap.cpp
// Tests for include/msgs/io/colmap.hpp: small COLMAP models written by the test in text and binary
// form read back to the same cameras and points, conventions, the RGB dataset loader, bad files.
#include <doctest/doctest.h>

#include <cstdlib>
#include <fstream>

#include "msgs/io/colmap.hpp"
#include "msgs/io/load_scene.hpp"
#include "scratch.hpp"

namespace test_colmap {
namespace fs = std::filesystem;
using msgs::testing::io_error_of;
using namespace msgs;
using namespace msgs::io;

namespace {

fs::path scratch(const std::string& sub) { return msgs::testing::fresh_scratch_dir("test_colmap/" + sub); }

struct Cam { int id; std::string model; int model_id; int w, h; std::vector<double> params; };
struct Img { int id; double q[4]; double t[3]; int cam; std::string name; };
struct Pt { std::uint64_t id; double xyz[3]; unsigned char rgb[3]; };

const std::vector<Cam> cams = {
    {1, "PINHOLE", 1, 40, 30, {35, 36, 20, 15}},
    {2, "SIMPLE_RADIAL", 2, 40, 30, {33, 19.5, 15.5, -0.05}},
    {3, "OPENCV", 4, 40, 30, {30, 31, 20, 15, -0.1, 0.01, 0.001, -0.002}},
    {4, "SIMPLE_PINHOLE", 0, 20, 10, {12, 10, 5}},
};
// Quaternion of a 90 degree turn about z: (cos 45, 0, 0, sin 45).
const double c45 = std::sqrt(0.5);
const std::vector<Img> imgs = {
    {7, {c45, 0, 0, c45}, {0.5, -1, 2}, 1, "b.png"},
    {3, {1, 0, 0, 0}, {0, 0, 4}, 2, "a.png"},
    {9, {0.9, 0.1, -0.3, 0.2}, {1, 2, 3}, 3, "c d.png"},  // name with a space; quaternion not normalised
};
const std::vector<Pt> pts = {{1, {0.1, 0.2, 0.3}, {255, 0, 10}}, {5, {-1, 2, -3}, {1, 2, 3}}};

void write_text_model(const fs::path& dir, const std::vector<Cam>& cs = cams) {
  std::ofstream c(dir / "cameras.txt");
  c << "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  c.precision(17);
  for (const auto& k : cs) {
    c << k.id << " " << k.model << " " << k.w << " " << k.h;
    for (double p : k.params) c << " " << p;
    c << "\n";
  }
  std::ofstream i(dir / "images.txt");
  i.precision(17);
  i << "# Image list with two lines of data per image:\n";
  bool first = true;
  for (const auto& m : imgs) {
    i << m.id << " " << m.q[0] << " " << m.q[1] << " " << m.q[2] << " " << m.q[3] << " " << m.t[0] << " " << m.t[1]
      << " " << m.t[2] << " " << m.cam << " " << m.name << "\n";
    i << (first ? "" : "12.5 3.5 1 4.0 5.0 -1") << "\n";
    first = false;
  }
  std::ofstream p(dir / "points3D.txt");
  p << "# 3D point list\n";
  for (const auto& q : pts)
    p << q.id << " " << q.xyz[0] << " " << q.xyz[1] << " " << q.xyz[2] << " " << int(q.rgb[0]) << " " << int(q.rgb[1])
      << " " << int(q.rgb[2]) << " 0.5 7 0 9 1\n";
}

template <class T>
void put(std::ofstream& f, T v) { f.write(reinterpret_cast<const char*>(&v), sizeof v); }

void write_binary_model(const fs::path& dir) {
  std::ofstream c(dir / "cameras.bin", std::ios::binary);
  put<std::uint64_t>(c, cams.size());
  for (const auto& k : cams) {
    put<std::int32_t>(c, k.id);
    put<std::int32_t>(c, k.model_id);
    put<std::uint64_t>(c, std::uint64_t(k.w));
    put<std::uint64_t>(c, std::uint64_t(k.h));
    for (double p : k.params) put<double>(c, p);
  }
  std::ofstream i(dir / "images.bin", std::ios::binary);
  put<std::uint64_t>(i, imgs.size());
  for (const auto& m : imgs) {
    put<std::int32_t>(i, m.id);
    for (double v : m.q) put<double>(i, v);
    for (double v : m.t) put<double>(i, v);
    put<std::int32_t>(i, m.cam);
    i.write(m.name.c_str(), std::streamsize(m.name.size() + 1));
    put<std::uint64_t>(i, 2);
    for (int k = 0; k < 2; ++k) { put<double>(i, 1.5 * k); put<double>(i, 2.5); put<std::int64_t>(i, -1); }
  }
  std::ofstream p(dir / "points3D.bin", std::ios::binary);
  put<std::uint64_t>(p, pts.size());
  for (const auto& q : pts) {
    put<std::uint64_t>(p, q.id);
    for (double v : q.xyz) put<double>(p, v);
    for (unsigned char v : q.rgb) put<std::uint8_t>(p, v);
    put<double>(p, 0.25);
    put<std::uint64_t>(p, 3);
    for (int k = 0; k < 3; ++k) { put<std::int32_t>(p, 7); put<std::int32_t>(p, k); }
  }
}

void check_model(const ColmapModel& m) {
  REQUIRE(m.cameras.size() == 4);
  REQUIRE(m.images.size() == 3);
  // Sorted by name.
  CHECK(m.images[0].name == "a.png");
  CHECK(m.images[1].name == "b.png");
  CHECK(m.images[2].name == "c d.png");
  const ColmapImage& b = m.images[1];
  CHECK(b.camera.fx == 35.0f);
  CHECK(b.camera.fy == 36.0f);
  CHECK(b.camera.cx == 20.0f);
  CHECK(b.camera.width == 40);
  CHECK(b.dist.is_identity());
  // 90 degrees about z: world x lands on camera y; t as given.
  const Eigen::Vector3f x = b.camera.R * Eigen::Vector3f::UnitX();
  CHECK((x - Eigen::Vector3f::UnitY()).norm() < 1e-6f);
  CHECK(b.camera.t.z() == 2.0f);
  const ColmapImage& a = m.images[0];
  CHECK(a.camera.fx == 33.0f);
  CHECK(a.camera.fy == 33.0f);
  CHECK(a.dist.model == Distortion::Model::opencv);
  CHECK(a.dist.k1 == -0.05);
  const ColmapImage& c = m.images[2];
  CHECK(c.dist.p2 == -0.002);
  CHECK(c.dist.k2 == 0.01);
  CHECK((c.camera.R.transpose() * c.camera.R - Eigen::Matrix3f::Identity()).norm() < 1e-5f);  // normalised
  Eigen::Quaterniond q(0.9, 0.1, -0.3, 0.2);
  q.normalize();
  CHECK((c.camera.R.cast<double>() - q.toRotationMatrix()).norm() < 1e-6);
  REQUIRE(m.points.size() == 2);
  CHECK(m.points.xyz[3] == -1.0f);
  CHECK(m.points.xyz[5] == -3.0f);
  CHECK(m.points.rgb[0] == 1.0f);
  CHECK(m.points.rgb[5] == doctest::Approx(3.0f / 255.0f));
}

}  // namespace

TEST_CASE("COLMAP text model") {
  const auto dir = scratch("text");
  write_text_model(dir);
  check_model(read_colmap(dir));
}

TEST_CASE("COLMAP binary model matches the text model") {
  const auto dir = scratch("bin");
  write_binary_model(dir);
  const auto m = read_colmap(dir);
  check_model(m);
  const auto tdir = scratch("text2");
  write_text_model(tdir);
  const auto t = read_colmap(tdir);
  for (std::size_t i = 0; i < 3; ++i) {
    CHECK(m.images[i].camera.R == t.images[i].camera.R);
    CHECK(m.images[i].camera.t == t.images[i].camera.t);
    CHECK(m.images[i].camera.fx == t.images[i].camera.fx);
  }
  CHECK(m.points.xyz == t.points.xyz);
}

TEST_CASE("COLMAP RGB dataset: images/ + sparse/0, lazy loading, split every n-th") {
  const auto root = scratch("dataset");
  fs::create_directories(root / "sparse" / "0");
  fs::create_directories(root / "images");
  write_binary_model(root / "sparse" / "0");
  for (const auto& m : imgs) {
    Image<float> im(40, 30, 3, 0.5f);
    im.at(1, 2, 0) = 1.0f;
    write_png8(root / "images" / m.name, im);
  }
  LoadOptions opt;
  opt.orient_and_center = false;
  opt.eval_every = 2;
  const Dataset ds = load_colmap_dataset(root, opt);
  REQUIRE(ds.frames.size() == 3);
  CHECK(ds.frames[0].file_path == "images/a.png");
  CHECK(ds.frames[0].split == Split::eval);
  CHECK(ds.frames[1].split == Split::train);
  CHECK(ds.frames[2].split == Split::eval);
  CHECK(ds.frames[1].camera.t.z() == doctest::Approx(2.0f));
  const auto img = load_frame_image(ds, ds.frames[1]);
  CHECK(img.at(1, 2, 0) == 1.0f);
  // Re-orientation keeps projections: compare a point in camera space.
  const Dataset oriented = load_colmap_dataset(root);
  for (std::size_t f = 0; f < 3; ++f) {
    const Eigen::Vector3f a = ds.frames[f].camera.R * Eigen::Vector3f(ds.points.xyz.data()) + ds.frames[f].camera.t;
    const Eigen::Vector3f b =
        oriented.frames[f].camera.R * Eigen::Vector3f(oriented.points.xyz.data()) + oriented.frames[f].camera.t;
    CHECK((a - b).norm() < 1e-4f);
  }
  fs::remove(root / "images" / "b.png");
  CHECK(io_error_of([&] { (void)load_colmap_dataset(root); }).find("b.png") != std::string::npos);
}

TEST_CASE("bad COLMAP: unsupported model, wrong parameter count, missing camera, truncated binary") {
  auto dir = scratch("bad_model");
  auto cs = cams;
  cs[3] = {4, "FOV", 7, 20, 10, {12, 12, 10, 5, 0.1}};
  write_text_model(dir, cs);
  // A FOV camera parses, but an image that uses it cannot be represented.
  {
    std::ofstream i(dir / "images.txt");
    i << "1 1 0 0 0 0 0 0 4 x.png\n\n";
  }
  auto msg = io_error_of([&] { (void)read_colmap(dir); });
  CHECK(msg.find("cameras.txt") != std::string::npos);
  CHECK(msg.find("FOV") != std::string::npos);

  dir = scratch("bad_count");
  cs = cams;
  cs[0].params.pop_back();
  write_text_model(dir, cs);
  msg = io_error_of([&] { (void)read_colmap(dir); });
  CHECK(msg.find("line 3") != std::string::npos);
  CHECK(msg.find("needs 4 parameters") != std::string::npos);

  dir = scratch("bad_ref");
  write_text_model(dir);
  {
    std::ofstream i(dir / "images.txt");
    i << "1 1 0 0 0 0 0 0 42 x.png\n\n";
  }
  msg = io_error_of([&] { (void)read_colmap(dir); });
  CHECK(msg.find("camera 42") != std::string::npos);

  dir = scratch("bad_trunc");
  write_binary_model(dir);
  fs::resize_file(dir / "images.bin", fs::file_size(dir / "images.bin") - 5);
  msg = io_error_of([&] { (void)read_colmap(dir); });
  CHECK(msg.find("images.bin") != std::string::npos);
  CHECK(msg.find("truncated") != std::string::npos);

  dir = scratch("missing");
  msg = io_error_of([&] { (void)read_colmap(dir); });
  CHECK(msg.find("cameras") != std::string::npos);
}

TEST_CASE("load_scene: detects the layout, image folders of resized copies, grey photos") {
  const auto root = scratch("scene");
  fs::create_directories(root / "sparse" / "0");
  fs::create_directories(root / "images");
  write_binary_model(root / "sparse" / "0");
  for (const auto& m : imgs) {
    Image<float> im(40, 30, 3, 0.25f);
    im.at(3, 4, 1) = 1.0f;
    write_png8(root / "images" / m.name, im);
  }
  LoadOptions opt;
  opt.orient_and_center = false;
  SceneInfo info;
  const Dataset full = load_scene(root, opt, "images", &info);
  CHECK(info.layout == SceneLayout::colmap);
  CHECK(info.binary);
  CHECK(info.describe(root) == "COLMAP scene (sparse/0, binary)");
  REQUIRE(full.frames.size() == 3);

  // images_2 next to images/: the prepared half-size copies, as the dataset's default divisor.
  fs::create_directories(root / "images_2");
  for (const auto& m : imgs) write_png8(root / "images_2" / m.name, Image<float>(20, 15, 3, 0.5f));
  const Dataset half = load_scene(root, opt, "images_2");
  CHECK(half.downscale == 2);
  CHECK(frame_camera(half, half.frames[1]).width == 20);
  CHECK(load_frame_image(half, half.frames[1]).at(0, 0, 0) == doctest::Approx(0.5).epsilon(0.01));  // the copy, not 0.25

  // Any other folder of resized copies: the intrinsics follow the size of its images.
  fs::create_directories(root / "small");
  for (const auto& m : imgs) write_png8(root / "small" / m.name, Image<float>(20, 15, 1, 0.75f));  // grey
  const Dataset small = load_scene(root, opt, "small");
  CHECK(small.downscale == 1);
  for (std::size_t i = 0; i < 3; ++i) {
    CHECK(small.frames[i].raw_camera.width == 20);
    CHECK(small.frames[i].raw_camera.fx == doctest::Approx(full.frames[i].raw_camera.fx * 0.5f));
    CHECK(small.frames[i].raw_camera.cy == doctest::Approx(full.frames[i].raw_camera.cy * 0.5f));
  }
  const Image<float> grey = load_frame_image(small, small.frames[1]);  // a grey photo of band D: R = G = B
  REQUIRE(grey.channels == 3);
  CHECK(grey.at(5, 5, 0) == doctest::Approx(0.75).epsilon(0.01));
  CHECK(grey.at(5, 5, 2) == grey.at(5, 5, 0));
  write_png8(root / "small" / "a.png", Image<float>(20, 20, 3, 0.5f));  // not a uniform resize
  CHECK(io_error_of([&] { (void)load_scene(root, opt, "small"); }).find("aspect ratio") != std::string::npos);
  CHECK(io_error_of([&] { (void)load_scene(root, opt, "images_8"); }).find("images_8") != std::string::npos);
  CHECK(io_error_of([&] { (void)load_scene(root, opt, "nowhere"); }).find("nowhere") != std::string::npos);

  // A text model directly in sparse/.
  const auto flat = scratch("scene_flat");
  fs::create_directories(flat / "sparse");
  write_text_model(flat / "sparse");
  CHECK(detect_scene(flat).describe(flat) == "COLMAP scene (sparse, text)");

  // Neither layout: one message naming both and the import command.
  const auto empty = scratch("scene_none");
  const std::string msg = io_error_of([&] { (void)detect_scene(empty); });
  CHECK(msg.find("transforms.json") != std::string::npos);
  CHECK(msg.find("sparse/0") != std::string::npos);
  CHECK(msg.find("msgs import") != std::string::npos);
  CHECK(io_error_of([&] { (void)detect_scene(empty / "missing"); }).find("does not exist") != std::string::npos);
  CHECK(downscale_folder_factor("images_4") == 4);
  CHECK(!downscale_folder_factor("images_").has_value());
  CHECK(!downscale_folder_factor("images_x").has_value());
  CHECK(!downscale_folder_factor("images_0").has_value());
}

}  // namespace test_colmap
