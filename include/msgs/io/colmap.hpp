// include/msgs/io/colmap.hpp
// COLMAP sparse models (cameras, images, points3D; text or binary) as msgs cameras and a point
// cloud, and a loader for ordinary RGB datasets laid out as <root>/images + <root>/sparse/0.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "msgs/camera.hpp"
#include "msgs/io/dataset.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"
#include "msgs/io/ply.hpp"
#include "msgs/io/undistort.hpp"

namespace msgs::io {

/// One COLMAP camera (intrinsics shared by several images).
struct ColmapCamera {
  int id = 0;
  std::string model;           ///< COLMAP model name, e.g. "PINHOLE", "OPENCV"
  int width = 0, height = 0;
  std::vector<double> params;  ///< as COLMAP stores them for `model`
};

/// One registered image: its name and its camera with pose.
struct ColmapImage {
  int id = 0;
  int camera_id = 0;
  std::string name;        ///< path relative to the image folder
  Camera<float> camera;    ///< intrinsics + world-to-camera pose (COLMAP uses OpenCV axes, like msgs)
  Distortion dist;         ///< lens model of the camera
};

/// A COLMAP sparse reconstruction.
struct ColmapModel {
  std::vector<ColmapCamera> cameras;
  std::vector<ColmapImage> images;  ///< sorted by name
  PointCloud points;                ///< xyz + rgb of points3D
};

namespace detail {

struct ColmapModelSpec {
  int id;
  const char* name;
  int params;
};
inline constexpr ColmapModelSpec colmap_models[] = {
    {0, "SIMPLE_PINHOLE", 3}, {1, "PINHOLE", 4},  {2, "SIMPLE_RADIAL", 4},          {3, "RADIAL", 5},
    {4, "OPENCV", 8},         {5, "OPENCV_FISHEYE", 8}, {6, "FULL_OPENCV", 12},    {7, "FOV", 5},
    {8, "SIMPLE_RADIAL_FISHEYE", 4}, {9, "RADIAL_FISHEYE", 5}, {10, "THIN_PRISM_FISHEYE", 12}};

inline const ColmapModelSpec* colmap_model_by_name(const std::string& n) {
  for (const auto& m : colmap_models)
    if (n == m.name) return &m;
  return nullptr;
}
inline const ColmapModelSpec* colmap_model_by_id(int id) {
  for (const auto& m : colmap_models)
    if (id == m.id) return &m;
  return nullptr;
}

/// Intrinsics and lens model of a COLMAP camera; IoError for models msgs cannot represent.
inline void colmap_intrinsics(const ColmapCamera& c, const std::filesystem::path& p, Camera<float>& cam,
                              Distortion& dist) {
  const auto& q = c.params;
  const std::string field = cat("camera ", c.id);
  double fx, fy, cx, cy;
  dist = Distortion{};
  if (c.model == "SIMPLE_PINHOLE" || c.model == "SIMPLE_RADIAL" || c.model == "RADIAL") {
    fx = fy = q[0]; cx = q[1]; cy = q[2];
    if (c.model != "SIMPLE_PINHOLE") {
      dist.model = Distortion::Model::opencv;
      dist.k1 = q[3];
      if (c.model == "RADIAL") dist.k2 = q[4];
    }
  } else if (c.model == "PINHOLE" || c.model == "OPENCV" || c.model == "OPENCV_FISHEYE" || c.model == "FULL_OPENCV") {
    fx = q[0]; fy = q[1]; cx = q[2]; cy = q[3];
    if (c.model == "OPENCV") {
      dist.model = Distortion::Model::opencv;
      dist.k1 = q[4]; dist.k2 = q[5]; dist.p1 = q[6]; dist.p2 = q[7];
    } else if (c.model == "OPENCV_FISHEYE") {
      dist.model = Distortion::Model::fisheye;
      dist.k1 = q[4]; dist.k2 = q[5]; dist.k3 = q[6]; dist.k4 = q[7];
    } else if (c.model == "FULL_OPENCV") {
      // k1 k2 p1 p2 k3 k4 k5 k6: OpenCV's rational model (k4..k6 in the denominator).
      dist.model = (q[9] != 0 || q[10] != 0 || q[11] != 0) ? Distortion::Model::rational : Distortion::Model::opencv;
      dist.k1 = q[4]; dist.k2 = q[5]; dist.p1 = q[6]; dist.p2 = q[7]; dist.k3 = q[8];
      if (dist.model == Distortion::Model::rational) { dist.k4 = q[9]; dist.k5 = q[10]; dist.k6 = q[11]; }
    }
  } else {
    fail(p, field, cat("unsupported camera model ", c.model,
                       " (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, FULL_OPENCV)"));
  }
  for (double v : q)
    if (!std::isfinite(v)) fail(p, field, "parameters must be finite");
  if (!(fx > 0 && fy > 0)) fail(p, field, "focal length must be > 0");
  if (c.width < 1 || c.height < 1) fail(p, field, "width and height must be >= 1");
  cam.fx = float(fx); cam.fy = float(fy); cam.cx = float(cx); cam.cy = float(cy);
  cam.width = c.width; cam.height = c.height;
}

inline void colmap_pose(double qw, double qx, double qy, double qz, double tx, double ty, double tz,
                        const std::filesystem::path& p, const std::string& field, Camera<float>& cam) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  const double n = q.norm();
  if (!std::isfinite(n) || n < 1e-8 || !std::isfinite(tx) || !std::isfinite(ty) || !std::isfinite(tz))
    fail(p, field, "pose must be finite with a non-zero quaternion");
  q.coeffs() /= n;
  cam.R = q.toRotationMatrix().cast<float>();
  cam.t = Eigen::Vector3f(float(tx), float(ty), float(tz));
}

/// Little-endian binary reader over a whole file, with truncation checks naming the file.
class BinReader {
 public:
  explicit BinReader(const std::filesystem::path& p) : p_(p), b_(read_bytes(p)) {}
  template <class T>
  T get(const char* what) {
    if (b_.size() - pos_ < sizeof(T)) fail(p_, cat("truncated while reading ", what, " at byte ", pos_));
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));  // COLMAP writes little-endian; so does every host we target
    pos_ += sizeof(T);
    return v;
  }
  std::string get_cstring(const char* what) {
    std::string s;
    for (;;) {
      const char ch = get<char>(what);
      if (ch == '\0') return s;
      s.push_back(ch);
    }
  }
  void skip(std::uint64_t n, const char* what) {
    if (b_.size() - pos_ < n) fail(p_, cat("truncated while reading ", what, " at byte ", pos_));
    pos_ += static_cast<std::size_t>(n);
  }
  bool at_end() const { return pos_ == b_.size(); }
  std::size_t pos() const { return pos_; }

 private:
  std::filesystem::path p_;
  std::vector<unsigned char> b_;
  std::size_t pos_ = 0;
};

/// Non-comment, non-empty lines of a COLMAP text file, with their 1-based line numbers. Empty lines
/// matter in images.txt (an image with no 2D points has an empty second line), so `keep_empty`.
inline std::vector<std::pair<int, std::string>> colmap_lines(const std::filesystem::path& p, bool keep_empty) {
  std::istringstream in(read_text(p));
  std::vector<std::pair<int, std::string>> out;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first != std::string::npos && line[first] == '#') continue;
    if (first == std::string::npos && !keep_empty) continue;
    out.emplace_back(n, line);
  }
  return out;
}

inline std::vector<ColmapCamera> read_colmap_cameras_text(const std::filesystem::path& p) {
  std::vector<ColmapCamera> cams;
  for (const auto& [n, line] : colmap_lines(p, false)) {
    std::istringstream ss(line);
    ColmapCamera c;
    if (!(ss >> c.id >> c.model >> c.width >> c.height)) fail(p, cat("line ", n), "need CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    const ColmapModelSpec* spec = colmap_model_by_name(c.model);
    if (!spec) fail(p, cat("line ", n), cat("unknown camera model '", c.model, "'"));
    for (double v; ss >> v;) c.params.push_back(v);
    if (!ss.eof()) fail(p, cat("line ", n), "parameters must be numbers");
    if (static_cast<int>(c.params.size()) != spec->params)
      fail(p, cat("line ", n), cat(c.model, " needs ", spec->params, " parameters, got ", c.params.size()));
    cams.push_back(std::move(c));
  }
  return cams;
}

inline std::vector<ColmapCamera> read_colmap_cameras_binary(const std::filesystem::path& p) {
  BinReader r(p);
  const auto n = r.get<std::uint64_t>("number of cameras");
  std::vector<ColmapCamera> cams;
  for (std::uint64_t i = 0; i < n; ++i) {
    ColmapCamera c;
    c.id = r.get<std::int32_t>("camera_id");
    const int model = r.get<std::int32_t>("model_id");
    const ColmapModelSpec* spec = colmap_model_by_id(model);
    if (!spec) fail(p, cat("camera ", c.id), cat("unknown model id ", model));
    c.model = spec->name;
    const auto w = r.get<std::uint64_t>("width"), h = r.get<std::uint64_t>("height");
    if (w > 1000000 || h > 1000000) fail(p, cat("camera ", c.id), "implausible image size");
    c.width = int(w);
    c.height = int(h);
    for (int k = 0; k < spec->params; ++k) c.params.push_back(r.get<double>("camera params"));
    cams.push_back(std::move(c));
  }
  if (!r.at_end()) fail(p, "data continues after the declared cameras (wrong count?)");
  return cams;
}

struct RawImage {
  int id, camera_id;
  std::string name;
  double q[4], t[3];
};

inline std::vector<RawImage> read_colmap_images_text(const std::filesystem::path& p) {
  const auto lines = colmap_lines(p, true);
  std::vector<RawImage> out;
  std::size_t i = 0;
  // Skip leading blank lines; after that each image is a pose line followed by a (possibly empty) points line.
  while (i < lines.size() && lines[i].second.find_first_not_of(" \t") == std::string::npos) ++i;
  while (i < lines.size()) {
    const auto& [n, line] = lines[i];
    if (line.find_first_not_of(" \t") == std::string::npos) { ++i; continue; }
    std::istringstream ss(line);
    RawImage im;
    if (!(ss >> im.id >> im.q[0] >> im.q[1] >> im.q[2] >> im.q[3] >> im.t[0] >> im.t[1] >> im.t[2] >> im.camera_id))
      fail(p, cat("line ", n), "need IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    ss >> std::ws;
    std::getline(ss, im.name);  // names may contain spaces
    while (!im.name.empty() && (im.name.back() == ' ' || im.name.back() == '\t')) im.name.pop_back();
    if (im.name.empty()) fail(p, cat("line ", n), "image has no NAME");
    out.push_back(std::move(im));
    i += 2;  // the POINTS2D line (validated by nobody: msgs does not use 2D observations)
  }
  return out;
}

inline std::vector<RawImage> read_colmap_images_binary(const std::filesystem::path& p) {
  BinReader r(p);
  const auto n = r.get<std::uint64_t>("number of images");
  std::vector<RawImage> out;
  for (std::uint64_t i = 0; i < n; ++i) {
    RawImage im;
    im.id = r.get<std::int32_t>("image_id");
    for (double& v : im.q) v = r.get<double>("qvec");
    for (double& v : im.t) v = r.get<double>("tvec");
    im.camera_id = r.get<std::int32_t>("camera_id");
    im.name = r.get_cstring("image name");
    const auto np = r.get<std::uint64_t>("num_points2D");
    if (np > (std::uint64_t(1) << 40)) fail(p, cat("image ", im.id), "implausible num_points2D (corrupt file?)");
    r.skip(np * 24, "points2D");
    out.push_back(std::move(im));
  }
  if (!r.at_end()) fail(p, "data continues after the declared images (wrong count?)");
  return out;
}

inline PointCloud read_colmap_points_text(const std::filesystem::path& p) {
  PointCloud pc;
  for (const auto& [n, line] : colmap_lines(p, false)) {
    std::istringstream ss(line);
    long long id;
    double x, y, z;
    int rgb[3];
    if (!(ss >> id >> x >> y >> z >> rgb[0] >> rgb[1] >> rgb[2]))
      fail(p, cat("line ", n), "need POINT3D_ID X Y Z R G B ERROR TRACK[]");
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) fail(p, cat("line ", n), "position is not finite");
    for (int c : rgb)
      if (c < 0 || c > 255) fail(p, cat("line ", n), "colour must be 0..255");
    for (double v : {x, y, z}) pc.xyz.push_back(float(v));
    for (int c : rgb) pc.rgb.push_back(float(c) / 255.0f);
  }
  return pc;
}

inline PointCloud read_colmap_points_binary(const std::filesystem::path& p) {
  BinReader r(p);
  const auto n = r.get<std::uint64_t>("number of points");
  PointCloud pc;
  for (std::uint64_t i = 0; i < n; ++i) {
    (void)r.get<std::uint64_t>("point3D_id");
    double xyz[3];
    for (double& v : xyz) v = r.get<double>("xyz");
    for (double v : xyz)
      if (!std::isfinite(v)) fail(p, cat("point ", i), "position is not finite");
    for (double v : xyz) pc.xyz.push_back(float(v));
    for (int c = 0; c < 3; ++c) pc.rgb.push_back(float(r.get<std::uint8_t>("rgb")) / 255.0f);
    (void)r.get<double>("error");
    const auto track = r.get<std::uint64_t>("track_length");
    if (track > (std::uint64_t(1) << 40)) fail(p, cat("point ", i), "implausible track length (corrupt file?)");
    r.skip(track * 8, "track");
  }
  if (!r.at_end()) fail(p, "data continues after the declared points (wrong count?)");
  return pc;
}

}  // namespace detail

/// Read a COLMAP sparse model from `dir`: cameras/images/points3D as .bin when present, else .txt.
/// Images come back sorted by name with their cameras; points3D may be absent (empty cloud).
/// Throws IoError naming the file and the line/camera for anything malformed.
inline ColmapModel read_colmap(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  auto pick = [&](const char* stem, bool required) -> fs::path {
    const fs::path b = dir / cat(stem, ".bin"), t = dir / cat(stem, ".txt");
    if (fs::is_regular_file(b, ec)) return b;
    if (fs::is_regular_file(t, ec)) return t;
    if (required) fail(dir / cat(stem, ".bin|.txt"), "COLMAP file does not exist");
    return {};
  };
  const fs::path cam_path = pick("cameras", true), img_path = pick("images", true), pts_path = pick("points3D", false);
  ColmapModel m;
  m.cameras = cam_path.extension() == ".bin" ? detail::read_colmap_cameras_binary(cam_path)
                                             : detail::read_colmap_cameras_text(cam_path);
  std::map<int, std::size_t> cam_index;
  for (std::size_t i = 0; i < m.cameras.size(); ++i) {
    if (!cam_index.emplace(m.cameras[i].id, i).second) fail(cam_path, cat("camera ", m.cameras[i].id), "duplicate id");
  }
  const auto raw = img_path.extension() == ".bin" ? detail::read_colmap_images_binary(img_path)
                                                  : detail::read_colmap_images_text(img_path);
  for (const auto& r : raw) {
    const auto it = cam_index.find(r.camera_id);
    const std::string field = cat("image ", r.id, " (", r.name, ")");
    if (it == cam_index.end()) fail(img_path, field, cat("refers to camera ", r.camera_id, " which cameras file lacks"));
    ColmapImage im;
    im.id = r.id;
    im.camera_id = r.camera_id;
    im.name = r.name;
    detail::colmap_intrinsics(m.cameras[it->second], cam_path, im.camera, im.dist);
    detail::colmap_pose(r.q[0], r.q[1], r.q[2], r.q[3], r.t[0], r.t[1], r.t[2], img_path, field, im.camera);
    m.images.push_back(std::move(im));
  }
  std::sort(m.images.begin(), m.images.end(), [](const ColmapImage& a, const ColmapImage& b) { return a.name < b.name; });
  if (!pts_path.empty())
    m.points = pts_path.extension() == ".bin" ? detail::read_colmap_points_binary(pts_path)
                                              : detail::read_colmap_points_text(pts_path);
  return m;
}

/// Load an ordinary RGB dataset in COLMAP layout: images in <root>/<image_dir>, the model in
/// <root>/sparse/0 (or <root>/sparse). Every frame is band "D"; the split is every
/// `opt.eval_every`-th image by name (3DGS uses 8 for its benchmarks); poses and points are
/// re-oriented like load_dataset when `opt.orient_and_center`. Images are read lazily by
/// load_frame_image as for the multi-spectral layout.
///
/// An `image_dir` other than "images" may hold resized copies (3DGS's images_4): the first image of
/// each COLMAP camera is read and the camera's intrinsics are scaled to its size; every other image
/// of that camera must then have the same size (checked when it is loaded).
inline Dataset load_colmap_dataset(const std::filesystem::path& root, const LoadOptions& opt = {},
                                   const std::string& image_dir = "images") {
  namespace fs = std::filesystem;
  std::error_code ec;
  auto has_model = [&](const fs::path& d) {
    return fs::is_regular_file(d / "cameras.bin", ec) || fs::is_regular_file(d / "cameras.txt", ec);
  };
  fs::path sparse = root / "sparse" / "0";
  if (!has_model(sparse)) sparse = root / "sparse";
  if (!fs::is_directory(sparse, ec)) fail(root / "sparse", "COLMAP model folder does not exist (need sparse/0 or sparse)");
  const ColmapModel m = read_colmap(sparse);
  if (m.images.empty()) fail(sparse, "model has no registered images");
  Dataset ds;
  ds.root = root;
  ds.downscale = std::max(1, opt.downscale);
  std::vector<Eigen::Matrix4d> c2w;
  for (std::size_t i = 0; i < m.images.size(); ++i) {
    const ColmapImage& im = m.images[i];
    Frame f;
    f.file_path = (fs::path(image_dir) / im.name).generic_string();
    f.band = "D";
    f.band_index = 0;
    f.raw_camera = im.camera;
    f.dist = im.dist;
    f.split = (opt.eval_every > 0 && i % static_cast<std::size_t>(opt.eval_every) == 0) ? Split::eval : Split::train;
    if (!fs::is_regular_file(root / f.file_path, ec))
      fail(sparse, cat("image ", im.id), cat("image '", (root / f.file_path).string(), "' does not exist"));
    c2w.push_back(im.camera.opengl_c2w().cast<double>());
    ds.frames.push_back(std::move(f));
  }
  if (fs::path(image_dir).lexically_normal() != fs::path("images")) {
    std::map<int, std::pair<double, double>> scale_of;  // camera id -> (sx, sy)
    for (std::size_t i = 0; i < ds.frames.size(); ++i) {
      Frame& f = ds.frames[i];
      const int cam = m.images[i].camera_id;
      auto it = scale_of.find(cam);
      if (it == scale_of.end()) {
        const Image<float> first = read_image(root / f.file_path);
        const double sx = double(first.width) / f.raw_camera.width, sy = double(first.height) / f.raw_camera.height;
        if (std::abs(sx - sy) > 0.02 * std::max(sx, sy))
          fail(root / f.file_path, cat("image is ", first.width, "x", first.height, " but COLMAP camera ", cam, " is ",
                                       f.raw_camera.width, "x", f.raw_camera.height,
                                       ": not a uniformly resized copy (aspect ratio differs)"));
        it = scale_of.emplace(cam, std::make_pair(sx, sy)).first;
      }
      const auto [sx, sy] = it->second;
      Camera<float>& c = f.raw_camera;
      const int w = int(std::lround(c.width * sx)), h = int(std::lround(c.height * sy));
      c.fx = float(c.fx * (double(w) / c.width)); c.cx = float(c.cx * (double(w) / c.width));
      c.fy = float(c.fy * (double(h) / c.height)); c.cy = float(c.cy * (double(h) / c.height));
      c.width = w; c.height = h;
    }
  }
  const Eigen::Matrix4d T = opt.orient_and_center ? detail::orient_and_center_transform(c2w) : Eigen::Matrix4d::Identity();
  ds.transform = T.cast<float>();
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    Frame& f = ds.frames[i];
    const Camera<float> pose = Camera<float>::from_opengl_c2w((T * c2w[i]).cast<float>());
    f.raw_camera.R = pose.R;
    f.raw_camera.t = pose.t;
    f.camera = undistorted_camera(f.raw_camera, f.dist, opt.undistort_zoom);
    f.camera.validate();
  }
  if (opt.load_points) {
    ds.points = m.points;
    detail::to_dataset_frame(ds);
  }
  return ds;
}

}  // namespace msgs::io
