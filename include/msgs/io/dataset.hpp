// include/msgs/io/dataset.hpp
// Loader for the nerfstudio-style multi-spectral dataset layout (REFERENCE.md §2): transforms.json,
// train_split.json, images/ and images_<f>/, sparse_pc.ply; poses re-oriented and centred.
//
// Loading is split in two: load_dataset() parses and validates the metadata (cameras, bands,
// split, point cloud) and checks that every image exists; load_frame_image() reads one image
// lazily at the requested resolution, checks its size against the camera and undistorts it.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "msgs/camera.hpp"
#include "msgs/image.hpp"
#include "msgs/io/bands.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"
#include "msgs/io/image_io.hpp"
#include "msgs/io/ply.hpp"
#include "msgs/io/undistort.hpp"

namespace msgs::io {

/// Which split a frame belongs to.
enum class Split { train, eval, unused };

/// One image of one band with its camera.
struct Frame {
  std::string file_path;   ///< as written in transforms.json, relative to the dataset root ("images/D_00001.JPG")
  std::string band;        ///< mm_channel ("D", "MS_G", ...); "D" when the file has none
  int band_index = 0;      ///< index into standard_bands()
  Camera<float> camera;    ///< full-resolution pinhole camera of the undistorted image, in dataset coordinates
  Camera<float> raw_camera;///< intrinsics of the stored (distorted) image; same pose as `camera`
  Distortion dist;         ///< lens model of the stored image (identity: nothing to undistort)
  Split split = Split::train;
  bool train() const { return split == Split::train; }
};

/// How to load.
struct LoadOptions {
  /// Re-orient and centre poses like the reference loader: the mean camera up becomes +z, the
  /// mean camera position the origin, scale 1. False keeps the file's coordinates.
  bool orient_and_center = true;
  /// Default resolution divisor for load_frame_image (1, 2, 4, 8 ...).
  int downscale = 1;
  /// Undistort into a zoomed pinhole camera so no output pixel samples outside the image
  /// (see undistorted_camera); false keeps the file's intrinsics.
  bool undistort_zoom = false;
  /// Load only these bands (empty: all bands present).
  std::vector<std::string> bands;
  /// Read the sparse point cloud (ply_file_path, else sparse_pc.ply when present).
  bool load_points = true;
  /// Without train_split.json: every `eval_every`-th frame of each band (0-based index % n == 0)
  /// goes to eval; 0 puts everything in train.
  int eval_every = 10;
  /// Use train_split.json when the dataset has one; false splits by `eval_every` instead.
  bool use_split_file = true;
};

/// A loaded dataset (metadata only; images come from load_frame_image).
struct Dataset {
  std::filesystem::path root;
  std::vector<Frame> frames;
  PointCloud points;  ///< in dataset coordinates (after `transform`)
  /// World transform applied to the file's coordinates: x_dataset = transform * x_file
  /// (homogeneous). Identity when orient_and_center is off.
  Eigen::Matrix4f transform = Eigen::Matrix4f::Identity();
  int downscale = 1;  ///< default divisor for load_frame_image / frame_camera
  bool has_split_file = false;

  /// Indices of the frames of `band` in `split`, in file order.
  std::vector<std::size_t> frames_of(std::string_view band, Split split) const {
    std::vector<std::size_t> out;
    for (std::size_t i = 0; i < frames.size(); ++i)
      if (frames[i].band == band && frames[i].split == split) out.push_back(i);
    return out;
  }
  /// Band ids present, in the order of standard_bands().
  std::vector<std::string> bands() const {
    std::vector<std::string> out;
    for (const auto& b : standard_bands())
      for (const auto& f : frames)
        if (f.band == b.id) { out.push_back(b.id); break; }
    return out;
  }
};

namespace detail {

/// Remove commas that directly precede a closing ']' or '}' (whitespace between allowed), outside
/// string literals. The published train_split.json files have them and nlohmann's parser (3.11)
/// has no option to accept them. Not a parser: only string boundaries and escapes are tracked.
inline std::string strip_trailing_commas(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char ch = text[i];
    if (in_string) {
      out.push_back(ch);
      if (ch == '\\' && i + 1 < text.size()) out.push_back(text[++i]);
      else if (ch == '"') in_string = false;
      continue;
    }
    if (ch == '"') { in_string = true; out.push_back(ch); continue; }
    if (ch == ',') {
      std::size_t j = i + 1;
      while (j < text.size() && (text[j] == ' ' || text[j] == '\t' || text[j] == '\n' || text[j] == '\r')) ++j;
      if (j < text.size() && (text[j] == ']' || text[j] == '}')) continue;
    }
    out.push_back(ch);
  }
  return out;
}

inline nlohmann::json parse_json_file(const std::filesystem::path& p) {
  const std::string text = strip_trailing_commas(read_text(p));
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // syntax errors, and numbers out of range (1e999)
    fail(p, cat("invalid JSON: ", e.what()));
  }
}

/// A number from the frame, else from the top level; nullopt when neither has it.
inline std::optional<double> json_number(const nlohmann::json& frame, const nlohmann::json& top, const char* key,
                                         const std::filesystem::path& p, const std::string& field) {
  const nlohmann::json* v = nullptr;
  if (frame.contains(key)) v = &frame[key];
  else if (top.contains(key)) v = &top[key];
  if (!v || v->is_null()) return std::nullopt;
  if (!v->is_number()) fail(p, field, "must be a number");
  const double d = v->get<double>();
  if (!std::isfinite(d)) fail(p, field, "must be finite");
  return d;
}

inline std::optional<std::string> json_string(const nlohmann::json& frame, const nlohmann::json& top, const char* key,
                                              const std::filesystem::path& p, const std::string& field) {
  const nlohmann::json* v = nullptr;
  if (frame.contains(key)) v = &frame[key];
  else if (top.contains(key)) v = &top[key];
  if (!v || v->is_null()) return std::nullopt;
  if (!v->is_string()) fail(p, field, "must be a string");
  return v->get<std::string>();
}

inline Eigen::Matrix4d json_matrix(const nlohmann::json& v, const std::filesystem::path& p, const std::string& field) {
  if (!v.is_array() || (v.size() != 4 && v.size() != 3)) fail(p, field, "must be a 4x4 (or 3x4) array of numbers");
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (std::size_t r = 0; r < v.size(); ++r) {
    if (!v[r].is_array() || v[r].size() != 4) fail(p, field, "every row must have 4 numbers");
    for (std::size_t c = 0; c < 4; ++c) {
      if (!v[r][c].is_number()) fail(p, field, "entries must be numbers");
      m(int(r), int(c)) = v[r][c].get<double>();
    }
  }
  if (!m.allFinite()) fail(p, field, "entries must be finite");
  const Eigen::Matrix3d R = m.block<3, 3>(0, 0);
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 || R.determinant() < 0)
    fail(p, field, "rotation part is not a rotation (scaled or mirrored poses are not supported)");
  if (v.size() == 4 && (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6)
    fail(p, field, "last row must be 0 0 0 1");
  return m;
}

/// The rotation taking unit vector `a` onto unit vector `b` about their common normal (Rodrigues);
/// for opposite vectors, a half turn about an axis perpendicular to `a`.
inline Eigen::Matrix3d rotation_between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d v = a.cross(b);
  const double c = a.dot(b);
  if (c > -1.0 + 1e-12) {
    Eigen::Matrix3d K;
    K << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
    return Eigen::Matrix3d::Identity() + K + K * K / (1.0 + c);
  }
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  int least = 0;
  for (int i = 1; i < 3; ++i)
    if (std::abs(a[i]) < std::abs(a[least])) least = i;
  e[least] = 1.0;
  const Eigen::Vector3d axis = a.cross(e).normalized();
  return 2.0 * axis * axis.transpose() - Eigen::Matrix3d::Identity();
}

/// The re-orienting transform of the reference loader: up = normalised mean of the camera up
/// vectors (OpenGL +y), rotated onto +z; origin at the mean camera position; scale 1.
inline Eigen::Matrix4d orient_and_center_transform(const std::vector<Eigen::Matrix4d>& c2w) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero(), up = Eigen::Vector3d::Zero();
  for (const auto& m : c2w) {
    centre += m.block<3, 1>(0, 3);
    up += m.block<3, 1>(0, 1);
  }
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  if (c2w.empty()) return t;
  centre /= double(c2w.size());
  // Cameras whose up vectors cancel out (e.g. a ring looking inwards with rolled cameras) give no
  // up direction; keep the file's orientation then rather than dividing by ~0.
  const Eigen::Matrix3d R = up.norm() > 1e-9 ? rotation_between(up.normalized(), Eigen::Vector3d::UnitZ())
                                             : Eigen::Matrix3d::Identity();
  t.block<3, 3>(0, 0) = R;
  t.block<3, 1>(0, 3) = -R * centre;
  return t;
}

/// Normalise a split entry or frame path for comparison ("./images/a.png" == "images/a.png").
inline std::string normal_path(const std::string& s) {
  return std::filesystem::path(s).lexically_normal().generic_string();
}

inline void apply_split(Dataset& ds, const std::filesystem::path& split_path) {
  const nlohmann::json js = parse_json_file(split_path);
  if (!js.is_object()) fail(split_path, "top level must be an object with 'train' and 'eval' lists");
  std::map<std::string, std::vector<std::size_t>> by_path, by_name;
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    by_path[normal_path(ds.frames[i].file_path)].push_back(i);
    by_name[std::filesystem::path(ds.frames[i].file_path).filename().string()].push_back(i);
  }
  std::vector<int> seen(ds.frames.size(), 0);  // 1 train, 2 eval
  for (auto& f : ds.frames) f.split = Split::unused;
  bool any_list = false;
  for (const char* key : {"train", "eval", "val", "test"}) {
    if (!js.contains(key)) continue;
    const std::string k = key;
    // One eval list: "eval", else "val", else "test".
    if ((k == "val" && js.contains("eval")) || (k == "test" && (js.contains("eval") || js.contains("val")))) continue;
    any_list = true;
    const auto& list = js[key];
    if (!list.is_array()) fail(split_path, k, "must be a list of image paths");
    const Split s = k == "train" ? Split::train : Split::eval;
    for (std::size_t j = 0; j < list.size(); ++j) {
      const std::string field = cat(k, "[", j, "]");
      if (!list[j].is_string()) fail(split_path, field, "must be a string");
      const std::string entry = list[j].get<std::string>();
      const std::vector<std::size_t>* hits = nullptr;
      if (auto it = by_path.find(normal_path(entry)); it != by_path.end()) hits = &it->second;
      else if (auto it2 = by_name.find(std::filesystem::path(entry).filename().string());
               it2 != by_name.end() && it2->second.size() == 1)
        hits = &it2->second;  // entries given without (or with another) folder
      if (!hits) fail(split_path, field, cat("entry '", entry, "' matches no frame of transforms.json"));
      for (std::size_t i : *hits) {
        const int want = s == Split::train ? 1 : 2;
        if (seen[i] != 0 && seen[i] != want)
          fail(split_path, field, cat("'", entry, "' is listed in both train and eval"));
        seen[i] = want;
        ds.frames[i].split = s;
      }
    }
  }
  if (!any_list) fail(split_path, "train", "missing (need 'train' and 'eval' lists)");
}

/// Moves ds.points from the file's coordinates into the dataset's: x = transform * x_file.
inline void to_dataset_frame(Dataset& ds) {
  const Eigen::Matrix3f R = ds.transform.block<3, 3>(0, 0);
  const Eigen::Vector3f t = ds.transform.block<3, 1>(0, 3);
  for (std::size_t i = 0; i < ds.points.size(); ++i) {
    Eigen::Map<Eigen::Vector3f> p(ds.points.xyz.data() + 3 * i);
    p = R * p + t;
  }
}

}  // namespace detail

/// Parse transforms.json (and train_split.json when present) under `root` into cameras, bands and
/// splits, read the sparse point cloud, and optionally re-orient and centre the scene. Checks that
/// every image file exists; images themselves are read by load_frame_image. Throws IoError naming
/// the file and field for anything malformed: missing files, unknown mm_channel, missing
/// intrinsics, bad matrices, split entries that match no frame.
inline Dataset load_dataset(const std::filesystem::path& root, const LoadOptions& opt = {}) {
  namespace fs = std::filesystem;
  Dataset ds;
  ds.root = root;
  ds.downscale = std::max(1, opt.downscale);
  const fs::path tf_path = root / "transforms.json";
  const nlohmann::json tf = detail::parse_json_file(tf_path);
  if (!tf.is_object()) fail(tf_path, "top level must be an object");
  if (!tf.contains("frames") || !tf["frames"].is_array()) fail(tf_path, "frames", "missing or not a list");
  const nlohmann::json empty = nlohmann::json::object();
  for (const auto& want : opt.bands)
    if (!find_band(want)) fail(tf_path, "mm_channel", cat("requested band '", want, "' is not a known band"));

  std::vector<Eigen::Matrix4d> c2w_all;
  const auto& frames = tf["frames"];
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto& fj = frames[i];
    const std::string pre = cat("frames[", i, "].");
    if (!fj.is_object()) fail(tf_path, cat("frames[", i, "]"), "must be an object");
    Frame f;
    if (!fj.contains("file_path") || !fj["file_path"].is_string()) fail(tf_path, pre + "file_path", "missing or not a string");
    f.file_path = fj["file_path"].get<std::string>();
    f.band = detail::json_string(fj, empty, "mm_channel", tf_path, pre + "mm_channel").value_or("D");
    const BandInfo* band = find_band(f.band);
    if (!band) {
      std::string known;
      for (const auto& b : standard_bands()) known += cat(known.empty() ? "" : ", ", b.id);
      fail(tf_path, pre + "mm_channel", cat("unknown band '", f.band, "' (expected one of ", known, ")"));
    }
    if (!opt.bands.empty() && std::find(opt.bands.begin(), opt.bands.end(), f.band) == opt.bands.end()) continue;
    f.band_index = static_cast<int>(band - standard_bands().data());

    auto need = [&](const char* key) {
      const auto v = detail::json_number(fj, tf, key, tf_path, pre + key);
      if (!v) fail(tf_path, pre + key, cat("missing intrinsics for '", f.file_path, "' (no per-frame or top-level value)"));
      return *v;
    };
    const double fx = need("fl_x"), fy = need("fl_y"), cx = need("cx"), cy = need("cy"), w = need("w"), h = need("h");
    if (!(fx > 0 && fy > 0)) fail(tf_path, pre + "fl_x", "focal lengths must be > 0");
    if (!(w >= 1 && h >= 1) || w != std::floor(w) || h != std::floor(h) || w > 1e6 || h > 1e6)
      fail(tf_path, pre + "w", "w and h must be positive integers");

    const std::string model = detail::json_string(fj, tf, "camera_model", tf_path, pre + "camera_model").value_or("OPENCV");
    if (model == "OPENCV" || model == "FULL_OPENCV" || model == "RADIAL" || model == "SIMPLE_RADIAL")
      f.dist.model = Distortion::Model::opencv;
    else if (model == "OPENCV_FISHEYE")
      f.dist.model = Distortion::Model::fisheye;
    else if (model == "PINHOLE" || model == "SIMPLE_PINHOLE")
      f.dist.model = Distortion::Model::none;
    else
      fail(tf_path, pre + "camera_model", cat("unsupported camera model '", model, "' (OPENCV, OPENCV_FISHEYE, PINHOLE)"));
    double* coeff[] = {&f.dist.k1, &f.dist.k2, &f.dist.k3, &f.dist.k4, &f.dist.p1, &f.dist.p2};
    const char* names[] = {"k1", "k2", "k3", "k4", "p1", "p2"};
    for (int k = 0; k < 6; ++k) *coeff[k] = detail::json_number(fj, tf, names[k], tf_path, pre + names[k]).value_or(0.0);
    if (f.dist.model == Distortion::Model::none && !f.dist.is_identity())
      fail(tf_path, pre + "camera_model", "PINHOLE camera with non-zero distortion coefficients");

    if (!fj.contains("transform_matrix")) fail(tf_path, pre + "transform_matrix", "missing");
    c2w_all.push_back(detail::json_matrix(fj["transform_matrix"], tf_path, pre + "transform_matrix"));

    f.raw_camera.fx = float(fx); f.raw_camera.fy = float(fy);
    f.raw_camera.cx = float(cx); f.raw_camera.cy = float(cy);
    f.raw_camera.width = int(w); f.raw_camera.height = int(h);

    const fs::path img = root / f.file_path;
    std::error_code ec;
    if (!fs::is_regular_file(img, ec)) fail(tf_path, pre + "file_path", cat("image '", img.string(), "' does not exist"));
    ds.frames.push_back(std::move(f));
  }
  if (ds.frames.empty()) fail(tf_path, "frames", "no frames (of the requested bands)");

  const Eigen::Matrix4d T = opt.orient_and_center ? detail::orient_and_center_transform(c2w_all) : Eigen::Matrix4d::Identity();
  ds.transform = T.cast<float>();
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    Frame& f = ds.frames[i];
    const Eigen::Matrix4d m = T * c2w_all[i];
    // Cameras are single precision: a finite double pose can still overflow float (1e55).
    bool fits = true;  // (a plain loop: Eigen's AVX-512 maxCoeff trips GCC 12's -Wmaybe-uninitialized)
    for (int k = 0; k < 16; ++k) fits = fits && std::abs(m(k / 4, k % 4)) <= double(std::numeric_limits<float>::max());
    if (!fits)
      fail(tf_path, "transform_matrix of " + f.file_path, "entries must fit in single precision (|x| <= 3.4e38)");
    const Camera<float> pose = Camera<float>::from_opengl_c2w(m.cast<float>());
    f.raw_camera.R = pose.R;
    f.raw_camera.t = pose.t;
    f.camera = undistorted_camera(f.raw_camera, f.dist, opt.undistort_zoom);
    try {
      f.camera.validate();
    } catch (const std::invalid_argument& e) {  // anything else the checks above did not catch
      fail(tf_path, "camera of " + f.file_path, e.what());
    }
  }

  // Split: the file when present, else every eval_every-th frame per band.
  const fs::path split_path = root / "train_split.json";
  std::error_code ec;
  if (opt.use_split_file && fs::exists(split_path, ec)) {
    ds.has_split_file = true;
    if (opt.bands.empty()) {
      detail::apply_split(ds, split_path);
    } else {
      // Entries of filtered-out bands legitimately match nothing: check against all frames, then
      // keep ours. Re-run the split on a dataset holding every frame's path.
      Dataset all;
      for (const auto& fj : frames) {
        Frame f;
        f.file_path = fj.value("file_path", std::string());
        all.frames.push_back(std::move(f));
      }
      detail::apply_split(all, split_path);
      std::map<std::string, Split> split_of;
      for (const auto& f : all.frames) split_of[detail::normal_path(f.file_path)] = f.split;
      for (auto& f : ds.frames) f.split = split_of[detail::normal_path(f.file_path)];
    }
  } else {
    std::map<std::string, int> counter;
    for (auto& f : ds.frames) {
      const int k = counter[f.band]++;
      f.split = (opt.eval_every > 0 && k % opt.eval_every == 0) ? Split::eval : Split::train;
    }
  }

  if (opt.load_points) {
    fs::path ply;
    if (tf.contains("ply_file_path")) {
      if (!tf["ply_file_path"].is_string()) fail(tf_path, "ply_file_path", "must be a string");
      ply = root / tf["ply_file_path"].get<std::string>();
      if (!fs::is_regular_file(ply, ec)) fail(tf_path, "ply_file_path", cat("point cloud '", ply.string(), "' does not exist"));
    } else if (fs::is_regular_file(root / "sparse_pc.ply", ec)) {
      ply = root / "sparse_pc.ply";
    }
    if (!ply.empty()) {
      ds.points = read_point_cloud(ply);
      detail::to_dataset_frame(ds);
    }
  }
  return ds;
}

/// The camera of `f` at resolution divisor `factor` (0: the dataset's default).
inline Camera<float> frame_camera(const Dataset& ds, const Frame& f, int factor = 0) {
  return f.camera.downscaled(factor > 0 ? factor : ds.downscale);
}

/// Read the image of `f` at resolution divisor `factor_arg` (0: the dataset's default), as floats
/// in [0, 1] with the band's channel count (a grey image of an RGB band is repeated in R, G, B), undistorted into frame_camera(ds, f, factor_arg).
/// A downscaled copy in images_<f>/ is used when present and of the expected size
/// (ceil(w / f) x ceil(h / f)); a copy one pixel off (rounded down) is ignored and the full image
/// is box-filtered in memory instead, so image and camera always agree. Throws IoError naming the
/// file for a missing, unreadable or truncated image and for a size contradicting w/h.
inline Image<float> load_frame_image(const Dataset& ds, const Frame& f, int factor_arg = 0) {
  namespace fs = std::filesystem;
  const int factor = factor_arg > 0 ? factor_arg : ds.downscale;
  const fs::path full = ds.root / f.file_path;
  const Camera<float> raw = f.raw_camera.downscaled(factor);
  Image<float> img;
  bool have = false;
  if (factor > 1) {
    // images/<name> -> images_<f>/<name>; paths in other folders keep their folder with the suffix.
    fs::path rel = fs::path(f.file_path).lexically_normal();
    fs::path folder = rel.parent_path(), name = rel.filename();
    const fs::path small = ds.root / folder.parent_path() / cat(folder.filename().string(), "_", factor) / name;
    std::error_code ec;
    if (!folder.empty() && fs::is_regular_file(small, ec)) {
      Image<float> s = read_image(small);
      if (s.width == raw.width && s.height == raw.height) {
        img = std::move(s);
        have = true;
      } else if (std::abs(s.width - raw.width) > 1 || std::abs(s.height - raw.height) > 1) {
        fail(small, cat("image is ", s.width, "x", s.height, " but w/h of '", f.file_path, "' downscaled by ", factor,
                        " give ", raw.width, "x", raw.height));
      }
    }
  }
  if (!have) {
    Image<float> big = read_image(full);
    if (big.width != f.raw_camera.width || big.height != f.raw_camera.height)
      fail(full, cat("image is ", big.width, "x", big.height, " but transforms.json says w x h = ", f.raw_camera.width,
                     "x", f.raw_camera.height));
    img = downscale(big, factor);
  }

  // Channel count of the band: RGBA loses alpha; a grey band stored as RGB(A) takes the mean of R, G, B.
  const int want = standard_bands()[static_cast<std::size_t>(f.band_index)].channels;
  if (img.channels != want) {
    if (img.channels < want && img.channels != 1)
      fail(full, cat("band ", f.band, " needs ", want, " channels but the image has ", img.channels));
    Image<float> o(img.width, img.height, want);
    for (std::size_t p = 0; p < img.pixels(); ++p) {
      const float* src = img.data.data() + p * std::size_t(img.channels);
      if (want == 1 && img.channels >= 3) o.data[p] = (src[0] + src[1] + src[2]) / 3.0f;
      else if (img.channels == 1)  // a grey photo of an RGB band: the same value in every channel
        for (int c = 0; c < want; ++c) o.data[p * std::size_t(want) + std::size_t(c)] = src[0];
      else
        for (int c = 0; c < want; ++c) o.data[p * std::size_t(want) + std::size_t(c)] = src[c];
    }
    img = std::move(o);
  }
  if (!f.dist.is_identity()) img = undistort_image(img, raw, f.dist, f.camera.downscaled(factor));
  return img;
}

}  // namespace msgs::io
