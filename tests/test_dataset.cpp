// tests/test_dataset.cpp
// Tests for include/msgs/io/dataset.hpp: a small multi-spectral dataset written by the test,
// cameras, splits with trailing commas, re-orientation, lazy image loading, and bad input.
#include <doctest/doctest.h>

#include <cstdlib>
#include <fstream>
#include <functional>

#include "msgs/io/dataset.hpp"
#include "scratch.hpp"

namespace test_dataset {
namespace fs = std::filesystem;
using msgs::testing::io_error_of;
using namespace msgs;
using namespace msgs::io;
using nlohmann::json;

namespace {

fs::path scratch(const std::string& sub) { return msgs::testing::fresh_scratch_dir("test_dataset/" + sub); }

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

constexpr int W = 20, H = 14;

// Pixel value pattern that differs per frame, band and channel.
float pattern(int frame, int x, int y, int c) { return float((frame * 7 + x * 3 + y * 5 + c * 11) % 64) / 63.0f; }

// A camera-to-world (OpenGL) matrix: camera at `pos` looking at the origin, roughly level.
Eigen::Matrix4d look_at(const Eigen::Vector3d& pos) {
  const Eigen::Vector3d back = pos.normalized();  // OpenGL camera looks down -z
  const Eigen::Vector3d right = Eigen::Vector3d(0, 0, 1).cross(back).normalized();
  const Eigen::Vector3d up = back.cross(right);
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<3, 1>(0, 0) = right;
  m.block<3, 1>(0, 1) = up;
  m.block<3, 1>(0, 2) = back;
  m.block<3, 1>(0, 3) = pos;
  return m;
}

json matrix_json(const Eigen::Matrix4d& m) {
  json rows = json::array();
  for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
  return rows;
}

/// Four captures of D (8-bit PNG) and MS_NIR (16-bit TIFF); images_2 for D only; frame 0 of D
/// takes its intrinsics from the top level. `edit` may change the JSON before it is written.
fs::path make_dataset(const std::string& name, const std::function<void(json&)>& edit = {}, bool split = true) {
  const fs::path root = scratch(name);
  fs::create_directories(root / "images");
  fs::create_directories(root / "images_2");
  json tf;
  tf["camera_model"] = "OPENCV";
  tf["fl_x"] = 18.0; tf["fl_y"] = 18.5; tf["cx"] = 10.0; tf["cy"] = 7.0; tf["w"] = W; tf["h"] = H;
  tf["ply_file_path"] = "sparse_pc.ply";
  json frames = json::array();
  for (int i = 0; i < 4; ++i)
    for (const char* band : {"D", "MS_NIR"}) {
      const bool rgb = std::string(band) == "D";
      const std::string file = cat(band, "_0000", i + 1, rgb ? ".png" : ".tif");
      Image<float> img(W, H, rgb ? 3 : 1);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < img.channels; ++c) img.at(x, y, c) = pattern(i + (rgb ? 0 : 10), x, y, c);
      if (rgb) {
        write_png8(root / "images" / file, img);
        Image<float> small(W / 2, H / 2, 3, 0.25f);  // deliberately not a downscale: proves the folder is read
        write_png8(root / "images_2" / file, small);
      } else {
        write_tiff16(root / "images" / file, img);
      }
      json f;
      f["file_path"] = "images/" + file;
      f["mm_channel"] = band;
      const double a = 0.6 * i;
      f["transform_matrix"] = matrix_json(look_at(Eigen::Vector3d(3 * std::cos(a), 3 * std::sin(a), 1.0 + 0.1 * i)));
      if (!(rgb && i == 0)) {
        f["fl_x"] = rgb ? 20.0 : 16.0; f["fl_y"] = rgb ? 21.0 : 16.0;
        f["cx"] = 10.5; f["cy"] = 6.5; f["w"] = W; f["h"] = H;
      }
      for (const char* k : {"k1", "k2", "k3", "k4", "p1", "p2"}) f[k] = 0.0;
      frames.push_back(f);
    }
  tf["frames"] = frames;
  if (edit) edit(tf);
  write_text(root / "transforms.json", tf.dump(2));
  if (split)
    write_text(root / "train_split.json",
               "{\n  \"train\": [\n    \"images/D_00002.png\",\n    \"images/D_00003.png\",\n    \"images/D_00004.png\",\n"
               "    \"images/MS_NIR_00002.tif\",\n    \"images/MS_NIR_00003.tif\",\n    \"images/MS_NIR_00004.tif\",\n  ],\n"
               "  \"eval\": [\n    \"images/D_00001.png\",\n    \"images/MS_NIR_00001.tif\",\n  ],\n}\n");
  write_text(root / "sparse_pc.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "property uint8 red\nproperty uint8 green\nproperty uint8 blue\nend_header\n"
             "0 0 0 255 0 0\n0.5 -0.25 0.75 0 255 0\n-1 1 0.2 0 0 255\n");
  return root;
}

}  // namespace

TEST_CASE("band table") {
  const auto& b = standard_bands();
  REQUIRE(b.size() == 5);
  CHECK(b[0].id == "D");
  CHECK(b[0].channels == 3);
  CHECK(b[4].id == "MS_NIR");
  CHECK(b[4].first_channel_in_joint == 6);
  CHECK(b[4].centre_nm == 860.0);
  CHECK(joint_channels() == 7);
  CHECK(joint_channel_names() == std::vector<std::string>{"D_R", "D_G", "D_B", "MS_G", "MS_R", "MS_RE", "MS_NIR"});
  CHECK(find_band("MS_RE")->first_channel_in_joint == 5);
  CHECK(find_band("XX") == nullptr);
}

TEST_CASE("trailing commas are stripped outside strings only") {
  const std::string text = "{\"a\": \"x,]\", \"b\": [1, 2, ], \"c\": {\"d\": \"q\\\",}\",\n},\n}";
  const json j = json::parse(detail::strip_trailing_commas(text));
  CHECK(j["a"] == "x,]");
  CHECK(j["b"].size() == 2);
  CHECK(j["c"]["d"] == "q\",}");
}

TEST_CASE("load a dataset without re-orientation: cameras as in the file") {
  const auto root = make_dataset("raw");
  LoadOptions opt;
  opt.orient_and_center = false;
  const Dataset ds = load_dataset(root, opt);
  REQUIRE(ds.frames.size() == 8);
  CHECK(ds.bands() == std::vector<std::string>{"D", "MS_NIR"});
  CHECK(ds.has_split_file);
  const Frame& d0 = ds.frames[0];
  CHECK(d0.band == "D");
  CHECK(d0.band_index == 0);
  CHECK(ds.frames[1].band_index == 4);
  // Top-level fallback for frame 0, per-frame values elsewhere.
  CHECK(d0.camera.fx == 18.0f);
  CHECK(d0.camera.fy == 18.5f);
  CHECK(ds.frames[2].camera.fx == 20.0f);
  CHECK(ds.frames[2].camera.cx == 10.5f);
  CHECK(d0.camera.width == W);
  // Pose: camera centre is the matrix translation; the camera looks at the origin (+z in OpenCV).
  const Eigen::Vector3f pos = d0.camera.position();
  CHECK(pos.x() == doctest::Approx(3.0f));
  CHECK(pos.z() == doctest::Approx(1.0f));
  const Eigen::Vector3f origin_cam = d0.camera.R * Eigen::Vector3f::Zero() + d0.camera.t;
  CHECK(origin_cam.z() > 0);
  CHECK(origin_cam.x() == doctest::Approx(0.0f).epsilon(1e-5));
  CHECK(origin_cam.y() == doctest::Approx(0.0f).epsilon(1e-5));
  // Splits from train_split.json (with trailing commas).
  CHECK(ds.frames[0].split == Split::eval);
  CHECK(ds.frames[1].split == Split::eval);
  CHECK(ds.frames[2].split == Split::train);
  CHECK(ds.frames_of("D", Split::train) == std::vector<std::size_t>{2, 4, 6});
  CHECK(ds.frames_of("MS_NIR", Split::eval) == std::vector<std::size_t>{1});
  // Point cloud.
  REQUIRE(ds.points.size() == 3);
  CHECK(ds.points.xyz[3] == 0.5f);
  CHECK(ds.points.rgb[4] == 1.0f);
  CHECK(ds.transform.isIdentity());
}

TEST_CASE("re-orientation: mean position at the origin, mean up along +z, projections unchanged") {
  const auto root = make_dataset("orient", [](json& tf) {
    // Tilt the whole rig so the re-orientation has something to undo.
    const Eigen::Matrix3d tilt = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 0.3, 0).normalized()).toRotationMatrix();
    for (auto& f : tf["frames"]) {
      Eigen::Matrix4d m;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m(r, c) = f["transform_matrix"][r][c].get<double>();
      m.block<3, 3>(0, 0) = tilt * m.block<3, 3>(0, 0);
      m.block<3, 1>(0, 3) = tilt * m.block<3, 1>(0, 3) + Eigen::Vector3d(5, -2, 7);
      f["transform_matrix"] = matrix_json(m);
    }
  });
  LoadOptions raw_opt;
  raw_opt.orient_and_center = false;
  const Dataset raw = load_dataset(root, raw_opt);
  const Dataset ds = load_dataset(root);
  Eigen::Vector3d mean_pos = Eigen::Vector3d::Zero(), mean_up = Eigen::Vector3d::Zero();
  for (const auto& f : ds.frames) {
    mean_pos += f.camera.position().cast<double>();
    mean_up += -(f.camera.R.transpose().col(1)).cast<double>();  // OpenCV y is down; up = -y
  }
  mean_pos /= double(ds.frames.size());
  CHECK(mean_pos.norm() < 1e-5);
  CHECK(mean_up.normalized().z() == doctest::Approx(1.0).epsilon(1e-6));
  // The point cloud went through the same transform: it projects to the same pixels.
  for (std::size_t fi = 0; fi < ds.frames.size(); ++fi)
    for (std::size_t i = 0; i < ds.points.size(); ++i) {
      const Eigen::Vector3f a = raw.frames[fi].camera.R * Eigen::Vector3f(raw.points.xyz.data() + 3 * i) +
                                raw.frames[fi].camera.t;
      const Eigen::Vector3f b = ds.frames[fi].camera.R * Eigen::Vector3f(ds.points.xyz.data() + 3 * i) +
                                ds.frames[fi].camera.t;
      CHECK((a - b).norm() < 1e-4f);
    }
  // The transform is a rigid motion and maps the file's camera centres onto the loaded ones.
  const Eigen::Matrix3f R = ds.transform.block<3, 3>(0, 0);
  CHECK((R.transpose() * R - Eigen::Matrix3f::Identity()).norm() < 1e-5f);
  const Eigen::Vector4f p = ds.transform * raw.frames[3].camera.position().homogeneous();
  CHECK((p.head<3>() - ds.frames[3].camera.position()).norm() < 1e-4f);
}

TEST_CASE("load_frame_image: full resolution, images_2 folder, in-memory downscale, 16-bit TIFF") {
  const auto root = make_dataset("images");
  const Dataset ds = load_dataset(root);
  const auto d1 = load_frame_image(ds, ds.frames[2]);
  REQUIRE(d1.channels == 3);
  REQUIRE(d1.width == W);
  CHECK(d1.at(3, 4, 1) == doctest::Approx(std::round(pattern(1, 3, 4, 1) * 255) / 255));
  const auto nir = load_frame_image(ds, ds.frames[3]);
  REQUIRE(nir.channels == 1);
  CHECK(nir.at(5, 6, 0) == doctest::Approx(pattern(11, 5, 6, 0)).epsilon(1e-4));
  // images_2 exists for D: the folder's (constant) image is used.
  const auto d2 = load_frame_image(ds, ds.frames[2], 2);
  CHECK(d2.width == W / 2);
  CHECK(d2.at(1, 1, 0) == doctest::Approx(64.0 / 255.0));
  const Camera<float> c2 = frame_camera(ds, ds.frames[2], 2);
  CHECK(c2.width == d2.width);
  CHECK(c2.fx == doctest::Approx(10.0f));
  // No images_2 for MS_NIR and no images_4 at all: box filter of the full image.
  const auto n2 = load_frame_image(ds, ds.frames[3], 2);
  const auto ref = downscale(nir, 2);
  CHECK(n2.data == ref.data);
  const auto d4 = load_frame_image(ds, ds.frames[2], 4);
  CHECK(d4.width == 5);
  CHECK(d4.height == 4);  // ceil(14 / 4)
}

TEST_CASE("band filter and no split file") {
  const auto root = make_dataset("filter", {}, false);
  LoadOptions opt;
  opt.bands = {"MS_NIR"};
  opt.eval_every = 2;
  const Dataset ds = load_dataset(root, opt);
  REQUIRE(ds.frames.size() == 4);
  CHECK_FALSE(ds.has_split_file);
  CHECK(ds.frames_of("MS_NIR", Split::eval) == std::vector<std::size_t>{0, 2});
}

TEST_CASE("band filter with a split file: other bands' entries are fine") {
  const auto root = make_dataset("filter_split");
  LoadOptions opt;
  opt.bands = {"D"};
  const Dataset ds = load_dataset(root, opt);
  REQUIRE(ds.frames.size() == 4);
  CHECK(ds.frames_of("D", Split::eval) == std::vector<std::size_t>{0});
}

TEST_CASE("distorted frames are undistorted at load time") {
  const auto root = make_dataset("distorted", [](json& tf) { tf["frames"][2]["k1"] = 0.2; });
  const Dataset ds = load_dataset(root);
  const Frame& f = ds.frames[2];
  CHECK(f.dist.k1 == 0.2);
  CHECK_FALSE(f.dist.is_identity());
  const auto img = load_frame_image(ds, f);
  const auto raw = read_image(root / f.file_path);
  const auto ref = undistort_image(raw, f.raw_camera, f.dist, f.camera);
  CHECK(img.data == ref.data);
  CHECK(img.data != raw.data);
}

TEST_CASE("bad dataset: missing transforms.json") {
  const auto root = scratch("no_tf");
  const auto msg = io_error_of([&] { (void)load_dataset(root); });
  CHECK(msg.find("transforms.json") != std::string::npos);
  CHECK(msg.find("does not exist") != std::string::npos);
}

TEST_CASE("bad dataset: missing image") {
  const auto root = make_dataset("no_image");
  fs::remove(root / "images" / "MS_NIR_00003.tif");
  const auto msg = io_error_of([&] { (void)load_dataset(root); });
  CHECK(msg.find("frames[5].file_path") != std::string::npos);
  CHECK(msg.find("MS_NIR_00003.tif") != std::string::npos);
}

TEST_CASE("bad dataset: unknown mm_channel") {
  const auto root = make_dataset("bad_band", [](json& tf) { tf["frames"][3]["mm_channel"] = "MS_UV"; });
  const auto msg = io_error_of([&] { (void)load_dataset(root); });
  CHECK(msg.find("frames[3].mm_channel") != std::string::npos);
  CHECK(msg.find("MS_UV") != std::string::npos);
}

TEST_CASE("bad dataset: frame with no intrinsics") {
  const auto root = make_dataset("no_intr", [](json& tf) { tf.erase("fl_y"); });
  const auto msg = io_error_of([&] { (void)load_dataset(root); });
  CHECK(msg.find("frames[0].fl_y") != std::string::npos);
  CHECK(msg.find("missing intrinsics") != std::string::npos);
}

TEST_CASE("bad dataset: image size contradicting w/h") {
  const auto root = make_dataset("bad_size", [](json& tf) { tf["frames"][1]["w"] = W + 2; });
  const Dataset ds = load_dataset(root);
  const auto msg = io_error_of([&] { (void)load_frame_image(ds, ds.frames[1]); });
  CHECK(msg.find("MS_NIR_00001.tif") != std::string::npos);
  CHECK(msg.find(cat(W, "x", H)) != std::string::npos);
  CHECK(msg.find(cat(W + 2, "x", H)) != std::string::npos);
}

TEST_CASE("bad dataset: truncated image") {
  const auto root = make_dataset("trunc");
  const auto p = root / "images" / "D_00002.png";
  fs::resize_file(p, fs::file_size(p) / 2);
  const Dataset ds = load_dataset(root);
  const auto msg = io_error_of([&] { (void)load_frame_image(ds, ds.frames[2]); });
  CHECK(msg.find("D_00002.png") != std::string::npos);
  CHECK(msg.find("truncated") != std::string::npos);
}

TEST_CASE("bad dataset: split entry that matches no frame") {
  const auto root = make_dataset("bad_split");
  write_text(root / "train_split.json", "{\"train\": [\"images/D_00002.png\", \"images/D_00099.png\",], \"eval\": [],}");
  const auto msg = io_error_of([&] { (void)load_dataset(root); });
  CHECK(msg.find("train_split.json") != std::string::npos);
  CHECK(msg.find("train[1]") != std::string::npos);
  CHECK(msg.find("D_00099.png") != std::string::npos);
}

TEST_CASE("bad dataset: malformed JSON, bad matrix, missing point cloud") {
  auto root = make_dataset("bad_json");
  write_text(root / "transforms.json", "{\"frames\": [ {\"file_path\": ");
  CHECK(io_error_of([&] { (void)load_dataset(root); }).find("invalid JSON") != std::string::npos);
  // A number beyond double's range is out_of_range to the JSON parser, not a parse error (found by
  // fuzz_dataset): still an IoError naming the file.
  write_text(root / "transforms.json", "{\"frames\": [], \"fl_x\": 1E1111111111}");
  const std::string overflow = io_error_of([&] { (void)load_dataset(root); });
  CHECK(overflow.find("invalid JSON") != std::string::npos);
  CHECK(overflow.find("transforms.json") != std::string::npos);
  root = make_dataset("bad_matrix", [](json& tf) { tf["frames"][0]["transform_matrix"][0][0] = 2.0; });
  CHECK(io_error_of([&] { (void)load_dataset(root); }).find("frames[0].transform_matrix") != std::string::npos);
  // Finite in double, infinite in the single-precision camera (found by fuzz_dataset): an IoError
  // naming the file and the frame, with and without re-orientation.
  root = make_dataset("huge_translation", [](json& tf) { tf["frames"][0]["transform_matrix"][2][3] = 1e55; });
  for (bool orient : {true, false}) {
    LoadOptions opt;
    opt.orient_and_center = orient;
    const std::string err = io_error_of([&] { (void)load_dataset(root, opt); });
    CHECK(err.find("transforms.json") != std::string::npos);
    CHECK(err.find("single precision") != std::string::npos);
  }
  root = make_dataset("no_ply");
  fs::remove(root / "sparse_pc.ply");
  CHECK(io_error_of([&] { (void)load_dataset(root); }).find("ply_file_path") != std::string::npos);
}

TEST_CASE("rotation_between maps a onto b, including opposite vectors") {
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  for (const Eigen::Vector3d& a : {Eigen::Vector3d(0.3, -0.5, 0.8).normalized(), Eigen::Vector3d(0, 0, 1),
                                   Eigen::Vector3d(0, 0, -1), Eigen::Vector3d(1, 0, 0)}) {
    const Eigen::Matrix3d R = detail::rotation_between(a, z);
    CHECK((R * a - z).norm() < 1e-12);
    CHECK((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-12);
    CHECK(R.determinant() == doctest::Approx(1.0));
  }
}

}  // namespace test_dataset
