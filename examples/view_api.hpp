// examples/view_api.hpp
// The request side of `msgs view`, testable without a socket: strict query parsing, cameras from
// intrinsics + pose, display modes (a band, RGB, colour infrared, five spectral indices), the
// index maths, ground truth and error images at dataset cameras, image encoding and /api/info.
// cmd_view.cpp only wires these to HTTP routes.
//
// Every problem with a request is a ViewError carrying the HTTP status to answer with: 400 for a
// malformed or out-of-range parameter, 404 for an unknown frame, 422 for a well-formed request
// the model or dataset cannot serve (a band the model lacks, ground truth of another size).
#pragma once

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <stb/stb_image_write.h>

#include <msgs/camera.hpp>
#include <msgs/image.hpp>
#include <msgs/io/bands.hpp>
#include <msgs/io/dataset.hpp>
#include <msgs/loss.hpp>
#include <msgs/render_util.hpp>
#include <msgs/schedule.hpp>

namespace msgs::view {

/// Largest width or height of a served image, and largest pixel count (4096 x 2048).
inline constexpr int max_side = 4096;
inline constexpr std::size_t max_pixels = std::size_t(4096) * 2048;
/// Largest accepted |coordinate| of a pose or intrinsic: beyond it a float camera is meaningless.
inline constexpr double max_abs_number = 1e7;

/// A request the server answers with `status` and `what()` as the message.
struct ViewError : std::runtime_error {
  int status;
  ViewError(int s, const std::string& msg) : std::runtime_error(msg), status(s) {}
};
[[noreturn]] inline void bad_request(const std::string& msg) { throw ViewError(400, msg); }

/// Query parameters as HTTP libraries hand them over (httplib::Params is this type).
using Params = std::multimap<std::string, std::string>;

/// Strict, read-only view of a query: every parameter must be one of `allowed`, appear once, and
/// parse completely. Numbers must be finite decimals ("nan", "inf", "1e999", "0x1p3", "1," fail).
class Query {
 public:
  Query(const Params& p, std::initializer_list<std::string_view> allowed) {
    for (const auto& [k, v] : p) {
      if (std::find(allowed.begin(), allowed.end(), k) == allowed.end()) {
        std::string list;
        for (auto a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        bad_request("unknown parameter '" + printable(k) + "' (expected: " + list + ")");
      }
      if (!values_.emplace(k, v).second) bad_request("parameter '" + k + "' given more than once");
    }
  }
  bool has(const std::string& k) const { return values_.count(k) > 0; }
  std::string str(const std::string& k, const std::string& def = "") const {
    auto it = values_.find(k);
    return it == values_.end() ? def : it->second;
  }
  /// A finite number in [lo, hi]; `def` when absent.
  double number(const std::string& k, double def, double lo, double hi) const {
    if (!has(k)) return def;
    return checked(k, parse_number(k, str(k)), lo, hi);
  }
  /// Exactly `n` comma-separated finite numbers, each within +-max_abs_number.
  std::vector<double> numbers(const std::string& k, std::size_t n) const {
    const std::string s = str(k);
    std::vector<double> out;
    std::size_t start = 0;
    while (true) {
      const std::size_t comma = s.find(',', start);
      const std::string tok = s.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      out.push_back(checked(k, parse_number(k, tok), -max_abs_number, max_abs_number));
      if (out.size() > n) break;
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
    if (out.size() != n)
      bad_request("parameter '" + k + "' needs " + std::to_string(n) + " comma-separated numbers");
    return out;
  }
  /// An integer in [lo, hi]; `def` when absent.
  long long integer(const std::string& k, long long def, long long lo, long long hi) const {
    if (!has(k)) return def;
    const std::string s = str(k);
    long long v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || ec != std::errc() || end != s.data() + s.size())
      bad_request("parameter '" + k + "' expects an integer, got '" + printable(s) + "'");
    if (v < lo || v > hi)
      bad_request("parameter '" + k + "' must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                  std::to_string(v));
    return v;
  }

  /// At most 60 characters of `s` with control and non-ASCII bytes as '?', for messages.
  static std::string printable(std::string_view s) {
    std::string out;
    for (char c : s.substr(0, 60)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
    if (s.size() > 60) out += "...";
    return out;
  }

 private:
  static double parse_number(const std::string& k, const std::string& s) {
    // Plain decimals only: digits, sign, point, exponent. Rules out hex, inf/nan, spaces.
    const bool plain = !s.empty() && s.size() <= 64 && std::all_of(s.begin(), s.end(), [](char c) {
      return (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.' || c == 'e' || c == 'E';
    });
    double v = 0;
    if (plain) {
      const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
      if (ec == std::errc() && end == s.data() + s.size() && std::isfinite(v)) return v;
    }
    bad_request("parameter '" + k + "' expects a finite number, got '" + printable(s) + "'");
  }
  static double checked(const std::string& k, double v, double lo, double hi) {
    if (!(v >= lo && v <= hi)) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "parameter '%s' must be in [%g, %g], got %g", k.c_str(), lo, hi, v);
      bad_request(buf);
    }
    return v;
  }
  std::map<std::string, std::string> values_;
};

// ---------------------------------------------------------------------------------------------
// Spectral indices
// ---------------------------------------------------------------------------------------------

enum class Index { ndvi, ndre, gndvi, ndwi, savi };

/// An index of two bands a and b, on the diverging colour scale over [lo, hi].
struct IndexInfo {
  Index index;
  const char* id;       ///< mode name: "ndvi" ...
  const char* label;    ///< "NDVI"
  const char* formula;  ///< human-readable
  const char* a;        ///< first band of the formula
  const char* b;        ///< second band
};

inline const std::vector<IndexInfo>& indices() {
  static const std::vector<IndexInfo> v = {
      {Index::ndvi, "ndvi", "NDVI", "(NIR - R) / (NIR + R)", "MS_NIR", "MS_R"},
      {Index::ndre, "ndre", "NDRE", "(NIR - RE) / (NIR + RE)", "MS_NIR", "MS_RE"},
      {Index::gndvi, "gndvi", "GNDVI", "(NIR - G) / (NIR + G)", "MS_NIR", "MS_G"},
      {Index::ndwi, "ndwi", "NDWI", "(G - NIR) / (G + NIR)", "MS_G", "MS_NIR"},
      {Index::savi, "savi", "SAVI", "1.5 (NIR - R) / (NIR + R + 0.5)", "MS_NIR", "MS_R"},
  };
  return v;
}
inline const IndexInfo& index_info(Index i) { return indices()[std::size_t(i)]; }

/// Colour scale range of every index: NDVI-like indices of reflectances in [0, 1] lie in [-1, 1]
/// (SAVI with L = 0.5 too).
inline constexpr float index_lo = -1.0f, index_hi = 1.0f;

/// The index at one pixel from the two bands of its formula (a, b as in IndexInfo). Total: a
/// non-finite input gives 0 (the neutral value), so does a denominator below
/// normalized_difference_eps in magnitude (0/0 on a black background); results are clamped to
/// [-1, 1], which matters only for inputs outside [0, 1]. Normalised differences are computed in
/// double exactly as msgs::normalized_difference, so NDVI / NDRE match `msgs render`.
inline float index_value(Index idx, float a, float b) {
  if (!std::isfinite(a) || !std::isfinite(b)) return 0.0f;
  const double x = a, y = b;
  const double num = idx == Index::savi ? 1.5 * (x - y) : x - y;
  const double den = idx == Index::savi ? x + y + 0.5 : x + y;
  if (!(std::abs(den) >= double(normalized_difference_eps))) return 0.0f;
  return float(std::clamp(num / den, -1.0, 1.0));
}

/// index_value at every pixel of two single-channel images of one size, [H, W, 1].
inline Image<float> index_image(Index idx, const Image<float>& a, const Image<float>& b) {
  if (a.channels != 1 || b.channels != 1 || a.width != b.width || a.height != b.height ||
      a.data.size() != a.pixels() || b.data.size() != b.pixels())
    throw std::invalid_argument("index_image: need two single-channel images of one size");
  Image<float> out(a.width, a.height, 1);
  for (std::size_t i = 0; i < out.data.size(); ++i) out.data[i] = index_value(idx, a.data[i], b.data[i]);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Display modes
// ---------------------------------------------------------------------------------------------

/// What an image shows: one band, the RGB band D, colour infrared (NIR, R, G as red, green, blue),
/// or a spectral index on the diverging colour scale.
struct Mode {
  enum Kind { band, rgb, cir, index } kind = band;
  std::string band_id;         ///< kind == band
  Index idx = Index::ndvi;     ///< kind == index
  std::string id() const {
    switch (kind) {
      case band: return band_id;
      case rgb: return "rgb";
      case cir: return "cir";
      default: return index_info(idx).id;
    }
  }
  /// The bands rendered for this mode, in the order compose() expects them.
  std::vector<std::string> bands() const {
    switch (kind) {
      case band: return {band_id};
      case rgb: return {"D"};
      case cir: return {"MS_NIR", "MS_R", "MS_G"};
      default: return {index_info(idx).a, index_info(idx).b};
    }
  }
  bool is_index() const { return kind == index; }
};

/// Every mode name, for messages and /api/info.
inline std::vector<std::string> all_mode_ids() {
  std::vector<std::string> v;
  for (const auto& b : io::standard_bands()) v.push_back(b.id);
  v.push_back("rgb");
  v.push_back("cir");
  for (const auto& i : indices()) v.push_back(i.id);
  return v;
}

/// "MS_NIR", "rgb", "cir", "ndvi" ... -> Mode; 400 for anything else.
inline Mode parse_mode(const std::string& s) {
  Mode m;
  if (io::find_band(s)) { m.kind = Mode::band; m.band_id = s; return m; }
  if (s == "rgb") { m.kind = Mode::rgb; return m; }
  if (s == "cir") { m.kind = Mode::cir; return m; }
  for (const auto& i : indices())
    if (s == i.id) { m.kind = Mode::index; m.idx = i.index; return m; }
  std::string list;
  for (const auto& id : all_mode_ids()) list += (list.empty() ? "" : ", ") + id;
  bad_request("unknown mode '" + Query::printable(s) + "' (expected one of: " + list + ")");
}

/// Why `models` cannot render mode `m`, or "" when it can. A band needs a model that renders it;
/// composites and indices need models that name each band (an unnamed single-band model could be
/// any band, and a ratio of one band with itself would be meaningless).
inline std::string mode_unavailable(const ModelSet& models, const Mode& m) {
  const bool composite = m.kind == Mode::cir || m.kind == Mode::index;
  std::string missing;
  for (const auto& b : m.bands())
    if (composite ? !models.named_source(b) : !models.renders(b)) missing += (missing.empty() ? "" : ", ") + b;
  if (missing.empty()) return "";
  return "mode '" + m.id() + "' needs band(s) " + missing + ", which the model does not render";
}
inline void require_mode(const ModelSet& models, const Mode& m) {
  if (const std::string why = mode_unavailable(models, m); !why.empty()) throw ViewError(422, why);
}

/// The background behind the Gaussians: the evaluation grey (msgs eval / training's eval), or
/// explicit values in band_background's forms (1 value, one per channel, or 7 in Joint order).
struct Background {
  bool eval = true;
  std::vector<float> values;
  std::vector<float> for_band(const std::string& band) const {
    if (eval) return eval_background<float>(io::find_band(band)->channels);
    try {
      return band_background(values, band);
    } catch (const std::invalid_argument& e) {
      bad_request(std::string("bg: ") + e.what());
    }
  }
};

/// `bg`: "eval" (default), "black", "white", or 1, 3 or 7 comma-separated numbers in [0, 1].
inline Background parse_background(const Query& q) {
  Background bg;
  const std::string s = q.str("bg", "eval");
  if (s == "eval") return bg;
  bg.eval = false;
  if (s == "black") { bg.values = {0.0f}; return bg; }
  if (s == "white") { bg.values = {1.0f}; return bg; }
  const std::size_t n = std::size_t(std::count(s.begin(), s.end(), ',')) + 1;
  if (n != 1 && n != 3 && n != std::size_t(io::joint_channels()))
    bad_request("bg expects eval, black, white, or 1, 3 or 7 comma-separated numbers");
  for (double v : q.numbers("bg", n)) {
    if (!(v >= 0.0 && v <= 1.0)) bad_request("bg values must be in [0, 1]");
    bg.values.push_back(float(v));
  }
  return bg;
}

/// Render the bands of `m` from `cam` (one forward pass per model where the bands are adjacent
/// channels) and combine them into the mode's values: the band itself (1 or 3 channels), the
/// CIR composite (3 channels) or the index (1 channel, unclamped to the display range).
inline Image<float> render_values(const ModelSet& models, const Mode& m, const Camera<float>& cam,
                                  const Background& bg) {
  require_mode(models, m);
  const std::vector<std::string> bands = m.bands();
  // ModelSet renders bands in adjacent channels of one model in one forward pass. Fill the gaps
  // between wanted bands of one model (RE between R and NIR for NDVI and CIR): rendering an extra
  // channel is cheaper than a second projection and sort.
  std::vector<std::string> all = bands;
  for (const auto& sb : io::standard_bands()) {
    const BandSource* s = models.named_source(sb.id);
    if (!s || std::find(all.begin(), all.end(), sb.id) != all.end()) continue;
    bool below = false, above = false;
    for (const auto& b : bands) {
      const BandSource* w = models.named_source(b);
      if (!w || w->model != s->model) continue;
      below = below || w->first_channel < s->first_channel;
      above = above || w->first_channel > s->first_channel;
    }
    if (below && above) all.push_back(sb.id);
  }
  std::vector<std::vector<float>> bgs;
  for (const auto& b : all) bgs.push_back(bg.for_band(b));
  std::vector<Image<float>> imgs = models.render_bands(all, cam, bgs);
  imgs.resize(bands.size());  // the gap bands come last
  switch (m.kind) {
    case Mode::band:
    case Mode::rgb: return std::move(imgs[0]);
    case Mode::cir: return cir_composite(imgs[0], imgs[1], imgs[2]);
    default: return index_image(m.idx, imgs[0], imgs[1]);
  }
}

/// Values as shown: bands and composites multiplied by `gain` (clamping happens at encoding),
/// indices through the diverging colour scale over [index_lo, index_hi].
inline Image<float> display(const Mode& m, Image<float> values, float gain) {
  if (m.is_index()) return colourize(values, Colormap::diverging, index_lo, index_hi);
  if (gain != 1.0f)
    for (float& v : values.data) v *= gain;
  return values;
}

// ---------------------------------------------------------------------------------------------
// Cameras
// ---------------------------------------------------------------------------------------------

/// Image size from `width` and `height` (required), each in [1, max_side], at most max_pixels.
inline std::pair<int, int> parse_size(const Query& q) {
  if (!q.has("width") || !q.has("height")) bad_request("width and height are required");
  const int w = int(q.integer("width", 0, 1, max_side)), h = int(q.integer("height", 0, 1, max_side));
  if (std::size_t(w) * std::size_t(h) > max_pixels)
    bad_request("image of " + std::to_string(w) + "x" + std::to_string(h) + " pixels exceeds the limit of " +
                std::to_string(max_pixels) + " pixels");
  return {w, h};
}

/// Largest deviation of R R^T from the identity accepted for a rotation (float round trips).
inline constexpr double rotation_tolerance = 1e-3;

/// A camera from the query:
///   width, height        image size (see parse_size)
///   fx [, fy, cx, cy]    intrinsics in pixels (fy = fx, principal point at the centre by default)
///   or fovy              vertical field of view in degrees, (0, 179) (default 50 when fx is absent)
///   R, t                 world-to-camera pose, OpenCV axes (x right, y down, z forward): R as 9
///                        numbers row-major (a rotation: orthonormal, det +1), t as 3: x_cam = R x + t
///   or eye, target [, up]  look-at pose (up default 0,0,1)
/// Everything malformed, non-finite, out of range or degenerate is a 400.
inline Camera<float> parse_camera(const Query& q) {
  Camera<float> cam;
  std::tie(cam.width, cam.height) = parse_size(q);
  const double W = cam.width, H = cam.height;
  if (q.has("fx")) {
    if (q.has("fovy")) bad_request("give fx or fovy, not both");
    const double fx = q.number("fx", 0, 1e-3, max_abs_number);
    cam.fx = float(fx);
    cam.fy = float(q.number("fy", fx, 1e-3, max_abs_number));
  } else {
    if (q.has("fy")) bad_request("fy needs fx");
    const double fovy = q.number("fovy", 50.0, 0.1, 179.0);
    cam.fy = cam.fx = float(0.5 * H / std::tan(0.5 * fovy * 3.14159265358979323846 / 180.0));
  }
  cam.cx = float(q.number("cx", 0.5 * W, -max_abs_number, max_abs_number));
  cam.cy = float(q.number("cy", 0.5 * H, -max_abs_number, max_abs_number));

  const bool pose_rt = q.has("R") || q.has("t"), pose_look = q.has("eye") || q.has("target") || q.has("up");
  if (pose_rt && pose_look) bad_request("give the pose as R and t, or as eye, target and up, not both");
  if (pose_rt) {
    if (!q.has("R") || !q.has("t")) bad_request("R and t go together");
    const std::vector<double> r = q.numbers("R", 9), t = q.numbers("t", 3);
    Eigen::Matrix3d R;
    R << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
    const double err = (R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (!(err <= rotation_tolerance) || !(R.determinant() > 0))
      bad_request("R must be a rotation matrix (orthonormal rows, determinant +1)");
    cam.R = R.cast<float>();
    cam.t = Eigen::Vector3d(t[0], t[1], t[2]).cast<float>();
  } else if (pose_look) {
    if (!q.has("eye") || !q.has("target")) bad_request("eye and target go together");
    const std::vector<double> e = q.numbers("eye", 3), g = q.numbers("target", 3);
    const std::vector<double> u = q.has("up") ? q.numbers("up", 3) : std::vector<double>{0, 0, 1};
    const Eigen::Vector3d eye(e[0], e[1], e[2]), target(g[0], g[1], g[2]), up(u[0], u[1], u[2]);
    const Eigen::Vector3d fwd = target - eye;
    if (!(fwd.norm() > 1e-9)) bad_request("eye and target must differ");
    const Eigen::Vector3d z = fwd.normalized();
    const Eigen::Vector3d x = z.cross(up);  // right = forward x up (OpenCV: y points down)
    if (!(up.norm() > 1e-9) || !(x.norm() > 1e-6 * up.norm()))
      bad_request("up must not be parallel to the view direction");
    const Eigen::Vector3d xn = x.normalized(), y = z.cross(xn);
    Eigen::Matrix3d R;
    R.row(0) = xn.transpose();
    R.row(1) = y.transpose();
    R.row(2) = z.transpose();
    cam.R = R.cast<float>();
    cam.t = (-(R * eye)).cast<float>();
  } else {
    bad_request("a pose is required: R and t, or eye and target");
  }
  try {
    cam.validate();
  } catch (const std::invalid_argument& ex) {
    bad_request(ex.what());
  }
  return cam;
}

// ---------------------------------------------------------------------------------------------
// Encoding
// ---------------------------------------------------------------------------------------------

enum class Format { jpeg, png };

struct Encoded {
  std::string bytes;
  const char* content_type;
};

/// 8-bit JPEG (quality 1..100) or PNG of a 1- or 3-channel image: values clamped to [0, 1],
/// scaled by 255 and rounded like io::write_png8; NaN becomes 0.
inline Encoded encode(const Image<float>& img, Format fmt, int quality = 90) {
  if ((img.channels != 1 && img.channels != 3) || img.width < 1 || img.height < 1 ||
      img.data.size() != img.pixels() * std::size_t(img.channels))
    throw std::invalid_argument("encode: need a non-empty 1- or 3-channel image");
  std::vector<unsigned char> px(img.data.size());
  for (std::size_t i = 0; i < px.size(); ++i) {
    const float v = img.data[i];
    px[i] = std::isnan(v) ? 0 : static_cast<unsigned char>(std::lround(double(std::clamp(v, 0.0f, 1.0f)) * 255.0));
  }
  Encoded out{{}, fmt == Format::png ? "image/png" : "image/jpeg"};
  auto append = [](void* ctx, void* data, int size) {
    static_cast<std::string*>(ctx)->append(static_cast<const char*>(data), std::size_t(size));
  };
  const int ok = fmt == Format::png
                     ? stbi_write_png_to_func(append, &out.bytes, img.width, img.height, img.channels, px.data(),
                                              img.width * img.channels)
                     : stbi_write_jpg_to_func(append, &out.bytes, img.width, img.height, img.channels, px.data(),
                                              std::clamp(quality, 1, 100));
  if (!ok || out.bytes.empty()) throw std::runtime_error("encode: the image encoder failed");
  return out;
}

/// `format` (jpeg default, png) and `quality` (1..100, default 90, JPEG only).
inline std::pair<Format, int> parse_format(const Query& q, Format def = Format::jpeg) {
  const std::string f = q.str("format", def == Format::png ? "png" : "jpeg");
  Format fmt;
  if (f == "jpeg" || f == "jpg") fmt = Format::jpeg;
  else if (f == "png") fmt = Format::png;
  else bad_request("format expects jpeg or png, got '" + Query::printable(f) + "'");
  return {fmt, int(q.integer("quality", 90, 1, 100))};
}

/// `gain` in (0, 1000], default 1: brightness multiplier of band and composite displays.
inline float parse_gain(const Query& q) {
  const double g = q.number("gain", 1.0, 0.0, 1000.0);
  if (!(g > 0)) bad_request("gain must be > 0");
  return float(g);
}

// ---------------------------------------------------------------------------------------------
// Dataset frames: ground truth, error, PSNR
// ---------------------------------------------------------------------------------------------

/// Mean absolute error of an index (or composite) shown as white in error images; bands and
/// composites use default_error_scale (0.25) like `msgs eval`, indices 0.5 (EvalOptions).
inline float error_scale(const Mode& m) { return m.is_index() ? 0.5f : default_error_scale; }

/// Captures of a dataset: for each frame, the other frames of its exposure by band.
class FrameIndex {
 public:
  FrameIndex() = default;
  explicit FrameIndex(const io::Dataset& ds) {
    std::vector<std::size_t> all(ds.frames.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
    captures_ = group_captures(ds, all);
    capture_of_.assign(ds.frames.size(), 0);
    for (std::size_t c = 0; c < captures_.size(); ++c)
      for (const auto& [band, f] : captures_[c].frames) capture_of_[f] = c;
  }
  const Capture& capture(std::size_t frame) const { return captures_.at(capture_of_.at(frame)); }

 private:
  std::vector<Capture> captures_;
  std::vector<std::size_t> capture_of_;
};

/// Resolution divisor of a frame request: `scale` when given (1..64), else the dataset's default
/// divisor, raised until the image fits the size limits.
inline int frame_factor(const Query& q, const io::Dataset& ds, const io::Frame& f) {
  if (q.has("scale")) {
    const int s = int(q.integer("scale", 1, 1, 64));
    const Camera<float> c = io::frame_camera(ds, f, s);
    if (c.width > max_side || c.height > max_side || std::size_t(c.width) * std::size_t(c.height) > max_pixels)
      bad_request("frame at scale " + std::to_string(s) + " is " + std::to_string(c.width) + "x" +
                  std::to_string(c.height) + ", over the size limit; use a larger scale");
    return s;
  }
  for (int s = std::max(1, ds.downscale);; ++s) {
    const Camera<float> c = io::frame_camera(ds, f, s);
    if (c.width <= max_side && c.height <= max_side && std::size_t(c.width) * std::size_t(c.height) <= max_pixels)
      return s;
  }
}

/// Ground truth of mode `m` at frame `fi`, loaded at divisor `factor`: the frame's own image for
/// its band; for another band, RGB, CIR or an index, the images of the same capture (the rig's
/// other cameras, from slightly different viewpoints, as `msgs eval` contact sheets do). 422 when
/// the capture lacks a band or an image's size differs from this frame's camera.
inline Image<float> ground_truth(const io::Dataset& ds, const FrameIndex& fx, std::size_t fi, const Mode& m,
                                 int factor) {
  const io::Frame& f = ds.frames[fi];
  const Camera<float> cam = io::frame_camera(ds, f, factor);
  std::vector<Image<float>> imgs;
  for (const auto& b : m.bands()) {
    std::size_t src = fi;
    if (b != f.band) {
      const Capture& cap = fx.capture(fi);
      auto it = cap.frames.find(b);
      if (it == cap.frames.end())
        throw ViewError(422, "no ground truth for mode '" + m.id() + "' at frame " + std::to_string(fi) + ": capture " +
                                 cap.key + " has no " + b + " image");
      src = it->second;
    }
    Image<float> img = io::load_frame_image(ds, ds.frames[src], factor);
    if (img.width != cam.width || img.height != cam.height)
      throw ViewError(422, "no ground truth for mode '" + m.id() + "' at frame " + std::to_string(fi) + ": the " + b +
                               " image is " + std::to_string(img.width) + "x" + std::to_string(img.height) +
                               ", this camera " + std::to_string(cam.width) + "x" + std::to_string(cam.height));
    imgs.push_back(std::move(img));
  }
  switch (m.kind) {
    case Mode::band:
    case Mode::rgb: return std::move(imgs[0]);
    case Mode::cir: return cir_composite(imgs[0], imgs[1], imgs[2]);
    default: return index_image(m.idx, imgs[0], imgs[1]);
  }
}

/// Render, ground truth and their comparison at one dataset camera.
struct FrameComparison {
  Image<float> render;  ///< mode values; bands and composites clamped to [0, 1] as `msgs eval` does
  Image<float> gt;      ///< empty when `gt_error` is set
  std::string gt_error; ///< why there is no ground truth (422 message)
  double psnr = 0;      ///< dB, bands and composites with ground truth
  double mae = 0;       ///< mean absolute difference of index values, index modes with ground truth
};

/// The error image of a comparison: error_map of render against ground truth on the hot scale.
inline Image<float> error_image(const Mode& m, const FrameComparison& c) {
  if (!c.gt_error.empty()) throw ViewError(422, c.gt_error);
  return error_map(c.render, c.gt, error_scale(m));
}

/// Render frame `fi` in mode `m` with its own camera at divisor `factor` and compare it with its
/// ground truth where the dataset has one.
inline FrameComparison compare_frame(const ModelSet& models, const io::Dataset& ds, const FrameIndex& fx,
                                     std::size_t fi, const Mode& m, const Background& bg, int factor) {
  FrameComparison c;
  c.render = render_values(models, m, io::frame_camera(ds, ds.frames[fi], factor), bg);
  if (!m.is_index()) clamp01(c.render);
  try {
    c.gt = ground_truth(ds, fx, fi, m, factor);
  } catch (const ViewError& e) {
    c.gt_error = e.what();
    return c;
  }
  if (m.is_index()) {
    double s = 0;
    for (std::size_t i = 0; i < c.gt.data.size(); ++i) s += std::abs(double(c.render.data[i]) - double(c.gt.data[i]));
    c.mae = c.gt.data.empty() ? 0.0 : s / double(c.gt.data.size());
  } else {
    c.psnr = msgs::psnr(c.render, c.gt);
  }
  return c;
}

// ---------------------------------------------------------------------------------------------
// /api/info
// ---------------------------------------------------------------------------------------------

/// Centre (per-axis median of the means) and radius (80th percentile of the distances to it) of
/// the Gaussians of every model, for the initial view.
inline std::pair<std::array<double, 3>, double> scene_extent(const ModelSet& models) {
  std::array<std::vector<float>, 3> axis;
  for (const auto& m : models.models())
    std::visit(
        [&](const auto& g) {
          for (std::size_t i = 0; i < g.size(); ++i)
            for (std::size_t a = 0; a < 3; ++a) axis[a].push_back(g.means[3 * i + a]);
        },
        m->model);
  std::array<double, 3> c{0, 0, 0};
  if (axis[0].empty()) return {c, 1.0};
  for (std::size_t a = 0; a < 3; ++a) {
    auto mid = axis[a].begin() + std::ptrdiff_t(axis[a].size() / 2);
    std::nth_element(axis[a].begin(), mid, axis[a].end());
    c[a] = *mid;
  }
  std::vector<double> d;
  for (const auto& m : models.models())
    std::visit(
        [&](const auto& g) {
          for (std::size_t i = 0; i < g.size(); ++i) {
            double s = 0;
            for (std::size_t a = 0; a < 3; ++a) s += (g.means[3 * i + a] - c[a]) * (g.means[3 * i + a] - c[a]);
            d.push_back(std::sqrt(s));
          }
        },
        m->model);
  auto p80 = d.begin() + std::ptrdiff_t(d.size() * 8 / 10);
  std::nth_element(d.begin(), p80, d.end());
  const double r = *p80;
  return {c, std::isfinite(r) && r > 1e-6 ? r : 1.0};
}

inline nlohmann::json camera_json(const Camera<float>& c) {
  nlohmann::json j;
  j["width"] = c.width;
  j["height"] = c.height;
  j["fx"] = c.fx;
  j["fy"] = c.fy;
  j["cx"] = c.cx;
  j["cy"] = c.cy;
  std::vector<float> R, t;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) R.push_back(c.R(r, k));
  for (int r = 0; r < 3; ++r) t.push_back(c.t(r));
  j["R"] = R;
  j["t"] = t;
  return j;
}

/// Everything the page needs to start: model, bands, modes (with why one is unavailable),
/// indices, colour scales, limits, scene extent and up direction, and the dataset's cameras.
inline nlohmann::json info_json(const ModelSet& models, const io::Dataset* ds, const FrameIndex* fx) {
  using nlohmann::json;
  json j;
  std::size_t total = 0;
  json files = json::array();
  for (const auto& m : models.models()) {
    total += m->size();
    files.push_back({{"file", m->path.filename().string()},
                     {"channels", m->channels()},
                     {"sh_degree", m->sh_degree()},
                     {"gaussians", m->size()},
                     {"band_names", m->info.band_names}});
  }
  j["gaussians"] = total;
  j["models"] = files;
  json bands = json::array();
  for (const auto& b : io::standard_bands())
    if (models.renders(b.id))
      bands.push_back({{"id", b.id},
                       {"channels", b.channels},
                       {"centre_nm", b.centre_nm},
                       {"named", models.named_source(b.id) != nullptr}});
  j["bands"] = bands;
  json modes = json::array();
  for (const auto& id : all_mode_ids()) {
    const Mode m = parse_mode(id);
    const std::string why = mode_unavailable(models, m);
    json e = {{"id", id}, {"kind", m.kind == Mode::band ? "band" : m.kind == Mode::index ? "index" : "composite"},
              {"available", why.empty()}, {"bands", m.bands()}};
    if (!why.empty()) e["why"] = why;
    if (m.is_index()) {
      e["label"] = index_info(m.idx).label;
      e["formula"] = index_info(m.idx).formula;
      e["lo"] = index_lo;
      e["hi"] = index_hi;
    }
    e["error_scale"] = error_scale(m);
    modes.push_back(e);
  }
  j["modes"] = modes;
  auto stops = [](Colormap cm, int n) {
    json a = json::array();
    for (int i = 0; i < n; ++i) {
      const auto c = colour_at(cm, float(i) / float(n - 1));
      a.push_back({c[0], c[1], c[2]});
    }
    return a;
  };
  j["colormaps"] = {{"diverging", stops(Colormap::diverging, 11)}, {"sequential", stops(Colormap::sequential, 7)}};
  j["limits"] = {{"max_side", max_side}, {"max_pixels", max_pixels}};
  const auto [centre, radius] = scene_extent(models);
  Eigen::Vector3d up(0, 0, 1);
  json cams = json::array();
  if (ds) {
    // The scene's up: the mean of the cameras' up vectors (-y of OpenCV cameras), when it is defined.
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    for (const auto& f : ds->frames) s -= f.camera.R.row(1).transpose().cast<double>();
    if (s.norm() > 1e-6 * double(std::max<std::size_t>(1, ds->frames.size()))) up = s.normalized();
    for (std::size_t i = 0; i < ds->frames.size(); ++i) {
      const io::Frame& f = ds->frames[i];
      json c = camera_json(io::frame_camera(*ds, f, 1));
      c["id"] = i;
      c["name"] = f.file_path;
      c["band"] = f.band;
      c["split"] = f.split == io::Split::eval ? "eval" : "train";
      c["capture"] = fx ? fx->capture(i).key : "";
      c["rendered"] = models.renders(f.band);
      cams.push_back(c);
    }
    j["dataset"] = {{"root", ds->root.string()}, {"frames", ds->frames.size()}, {"downscale", ds->downscale}};
  }
  j["scene"] = {{"center", centre}, {"radius", radius}, {"up", {up.x(), up.y(), up.z()}}};
  j["cameras"] = cams;
  return j;
}

}  // namespace msgs::view
