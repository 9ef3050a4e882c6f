// include/msgs/render_util.hpp
// Rendering trained models over a dataset and looking at the result: spectral indices (NDVI, NDRE)
// with colour scales, colour-infrared composites, error maps, contact sheets, loading PLY models
// of any channel count / SH degree by run-time dispatch, and per-band evaluation.
//
// Layers, bottom up:
//   images      normalized_difference / ndvi / ndre, cir_composite, colourize, legend_bar,
//               with_legend, error_map, contact_sheet
//   models      load_model (inspect_ply -> Gaussian<C, D>, C in {1, 3, 7}, D in {0..3}),
//               make_typed_renderer / make_channel_renderer, ModelSet (which model renders which band)
//   datasets    render_dataset (every frame with its own camera, plus per-capture composites),
//               evaluate_models (PSNR / SSIM per band, contact sheets), OutputStage (all-or-nothing output)
//
// Rendering a model type instantiates a Rasterizer; a RendererFactory decides which types are
// compiled where, so a tool can spread the twelve instantiations over several translation units.
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <variant>
#include <vector>

#include "camera.hpp"
#include "gaussian.hpp"
#include "image.hpp"
#include "io/bands.hpp"
#include "io/dataset.hpp"
#include "io/error.hpp"
#include "io/image_io.hpp"
#include "io/ply.hpp"
#include "loss.hpp"
#include "rasterize.hpp"
#include "schedule.hpp"
#include "train.hpp"

namespace msgs {

// =============================================================================================
// Images: spectral indices, composites, colour scales, error maps, contact sheets
// =============================================================================================

namespace detail {

inline void check_single_channel(const Image<float>& img, const char* who, const char* name) {
  if (img.channels != 1 || img.data.size() != img.pixels())
    throw std::invalid_argument(std::string(who) + ": " + name + " must be a single-channel image, got " +
                                std::to_string(img.channels) + " channels");
}

inline void check_same_size(const Image<float>& a, const Image<float>& b, const char* who, const char* na,
                            const char* nb) {
  if (a.width != b.width || a.height != b.height)
    throw std::invalid_argument(std::string(who) + ": " + na + " is " + std::to_string(a.width) + "x" +
                                std::to_string(a.height) + " but " + nb + " is " + std::to_string(b.width) + "x" +
                                std::to_string(b.height));
}

inline void check_finite_image(const Image<float>& img, const char* who, const char* name) {
  for (std::size_t i = 0; i < img.data.size(); ++i)
    if (!std::isfinite(img.data[i]))
      throw std::invalid_argument(std::string(who) + ": " + name + " has a non-finite value at element " +
                                  std::to_string(i));
}

}  // namespace detail

/// Smallest |a + b| for which normalized_difference divides; below it the index is 0.
inline constexpr float normalized_difference_eps = 1e-6f;

/// Per-pixel normalised difference (a - b) / (a + b) of two single-channel images, [H, W, 1].
/// Where |a + b| < eps both bands are (nearly) dark, the ratio is undefined and the result is 0,
/// the index's neutral value, so black backgrounds stay finite. Results are clamped to [-1, 1],
/// which only matters for negative inputs. Non-finite inputs throw std::invalid_argument.
inline Image<float> normalized_difference(const Image<float>& a, const Image<float>& b,
                                          float eps = normalized_difference_eps) {
  detail::check_single_channel(a, "normalized_difference", "a");
  detail::check_single_channel(b, "normalized_difference", "b");
  detail::check_same_size(a, b, "normalized_difference", "a", "b");
  detail::check_finite_image(a, "normalized_difference", "a");
  detail::check_finite_image(b, "normalized_difference", "b");
  Image<float> out(a.width, a.height, 1);
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    // Double: a + b may cancel, and (a - b) / (a + b) of two floats near eps loses digits.
    const double x = a.data[i], y = b.data[i], s = x + y;
    out.data[i] = std::abs(s) < double(eps) ? 0.0f : float(std::clamp((x - y) / s, -1.0, 1.0));
  }
  return out;
}

/// Normalised difference vegetation index (NIR - R) / (NIR + R), [H, W, 1] in [-1, 1].
inline Image<float> ndvi(const Image<float>& nir, const Image<float>& red) { return normalized_difference(nir, red); }

/// Normalised difference red-edge index (NIR - RE) / (NIR + RE), [H, W, 1] in [-1, 1].
inline Image<float> ndre(const Image<float>& nir, const Image<float>& red_edge) {
  return normalized_difference(nir, red_edge);
}

/// Colour-infrared composite, [H, W, 3]: NIR shown as red, red as green, green as blue (the
/// false-colour convention of CIR film, in which vegetation appears red).
inline Image<float> cir_composite(const Image<float>& nir, const Image<float>& red, const Image<float>& green) {
  detail::check_single_channel(nir, "cir_composite", "nir");
  detail::check_single_channel(red, "cir_composite", "red");
  detail::check_single_channel(green, "cir_composite", "green");
  detail::check_same_size(nir, red, "cir_composite", "nir", "red");
  detail::check_same_size(nir, green, "cir_composite", "nir", "green");
  Image<float> out(nir.width, nir.height, 3);
  const Image<float>* src[3] = {&nir, &red, &green};
  for (std::size_t p = 0; p < nir.pixels(); ++p)
    for (int c = 0; c < 3; ++c) out.data[p * 3 + std::size_t(c)] = src[c]->data[p];
  return out;
}

/// Colour scales for single-channel data.
enum class Colormap {
  diverging,   ///< ColorBrewer RdYlGn: red (low) - pale yellow (middle) - green (high); for NDVI/NDRE
  sequential,  ///< black - red - yellow - white ("hot"); for errors
};

namespace detail {
struct ColourStop {
  float r, g, b;
};
/// ColorBrewer RdYlGn, 11 classes, as sRGB in [0, 1].
inline constexpr ColourStop rdylgn_stops[] = {
    {165 / 255.f, 0 / 255.f, 38 / 255.f},    {215 / 255.f, 48 / 255.f, 39 / 255.f},
    {244 / 255.f, 109 / 255.f, 67 / 255.f},  {253 / 255.f, 174 / 255.f, 97 / 255.f},
    {254 / 255.f, 224 / 255.f, 139 / 255.f}, {255 / 255.f, 255 / 255.f, 191 / 255.f},
    {217 / 255.f, 239 / 255.f, 139 / 255.f}, {166 / 255.f, 217 / 255.f, 106 / 255.f},
    {102 / 255.f, 189 / 255.f, 99 / 255.f},  {26 / 255.f, 152 / 255.f, 80 / 255.f},
    {0 / 255.f, 104 / 255.f, 55 / 255.f}};
inline constexpr ColourStop hot_stops[] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {1, 1, 1}};

template <std::size_t N>
std::array<float, 3> interpolate_stops(const ColourStop (&stops)[N], float t) {
  const float x = t * float(N - 1);
  const std::size_t i = std::min<std::size_t>(N - 2, std::size_t(std::max(0.0f, std::floor(x))));
  const float f = std::clamp(x - float(i), 0.0f, 1.0f);
  const ColourStop &a = stops[i], &b = stops[i + 1];
  return {a.r + f * (b.r - a.r), a.g + f * (b.g - a.g), a.b + f * (b.b - a.b)};
}
}  // namespace detail

/// Colour of `cm` at position t in [0, 1] (clamped; NaN is treated as the middle), as RGB in [0, 1].
inline std::array<float, 3> colour_at(Colormap cm, float t) {
  t = std::isnan(t) ? 0.5f : std::clamp(t, 0.0f, 1.0f);
  return cm == Colormap::diverging ? detail::interpolate_stops(detail::rdylgn_stops, t)
                                   : detail::interpolate_stops(detail::hot_stops, t);
}

/// Map a single-channel image [H, W, 1] through `cm`, lo -> 0 and hi -> 1 (clamped), to RGB [H, W, 3].
inline Image<float> colourize(const Image<float>& values, Colormap cm, float lo, float hi) {
  detail::check_single_channel(values, "colourize", "values");
  if (!(std::isfinite(lo) && std::isfinite(hi) && hi > lo))
    throw std::invalid_argument("colourize: need finite lo < hi, got [" + std::to_string(lo) + ", " +
                                std::to_string(hi) + "]");
  detail::check_finite_image(values, "colourize", "values");
  Image<float> out(values.width, values.height, 3);
  for (std::size_t p = 0; p < values.pixels(); ++p) {
    const auto c = colour_at(cm, (values.data[p] - lo) / (hi - lo));
    for (int k = 0; k < 3; ++k) out.data[p * 3 + std::size_t(k)] = c[std::size_t(k)];
  }
  return out;
}

/// A horizontal colour bar [height, width, 3]: column x shows colour_at(cm, x / (width - 1)), so
/// the first and last columns are exactly the scale's end colours.
inline Image<float> legend_bar(int width, int height, Colormap cm) {
  if (width < 1 || height < 1) throw std::invalid_argument("legend_bar: width and height must be >= 1");
  Image<float> out(width, height, 3);
  for (int x = 0; x < width; ++x) {
    const auto c = colour_at(cm, width > 1 ? float(x) / float(width - 1) : 0.5f);
    for (int y = 0; y < height; ++y)
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = c[std::size_t(k)];
  }
  return out;
}

namespace detail {
/// 3x5 pixel glyphs, one row per 3-bit number (bit 2 = left column), for legend labels.
inline const std::uint8_t* glyph(char ch) {
  static constexpr std::uint8_t digits[10][5] = {{7, 5, 5, 5, 7}, {2, 6, 2, 2, 7}, {7, 1, 7, 4, 7}, {7, 1, 7, 1, 7},
                                                 {5, 5, 7, 1, 1}, {7, 4, 7, 1, 7}, {7, 4, 7, 5, 7}, {7, 1, 1, 1, 1},
                                                 {7, 5, 7, 5, 7}, {7, 5, 7, 1, 7}};
  static constexpr std::uint8_t minus[5] = {0, 0, 7, 0, 0}, plus[5] = {0, 2, 7, 2, 0}, dot[5] = {0, 0, 0, 0, 2};
  if (ch >= '0' && ch <= '9') return digits[ch - '0'];
  if (ch == '-') return minus;
  if (ch == '+') return plus;
  if (ch == '.') return dot;
  return nullptr;
}
inline constexpr int glyph_w = 3, glyph_h = 5;

inline int text_width(std::string_view s, int scale) { return s.empty() ? 0 : int(s.size()) * (glyph_w + 1) * scale - scale; }

/// Draw `s` (digits, sign, point) with its top-left corner at (x0, y0), clipped to the image.
inline void draw_text(Image<float>& img, int x0, int y0, std::string_view s, int scale, float value) {
  for (std::size_t i = 0; i < s.size(); ++i) {
    const std::uint8_t* g = glyph(s[i]);
    if (!g) continue;
    const int gx = x0 + int(i) * (glyph_w + 1) * scale;
    for (int r = 0; r < glyph_h; ++r)
      for (int c = 0; c < glyph_w; ++c) {
        if (!((g[r] >> (glyph_w - 1 - c)) & 1)) continue;
        for (int dy = 0; dy < scale; ++dy)
          for (int dx = 0; dx < scale; ++dx) {
            const int x = gx + c * scale + dx, y = y0 + r * scale + dy;
            if (x < 0 || y < 0 || x >= img.width || y >= img.height) continue;
            for (int k = 0; k < img.channels; ++k) img.at(x, y, k) = value;
          }
      }
  }
}

inline std::string format_label(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", double(v));
  return buf;
}
}  // namespace detail

/// Grey [H, W, 1] -> RGB [H, W, 3] by replication; an RGB image is returned as it is.
inline Image<float> to_rgb(const Image<float>& img) {
  if (img.channels == 3) return img;
  if (img.channels != 1)
    throw std::invalid_argument("to_rgb: need 1 or 3 channels, got " + std::to_string(img.channels));
  Image<float> out(img.width, img.height, 3);
  for (std::size_t p = 0; p < img.pixels(); ++p)
    for (int k = 0; k < 3; ++k) out.data[p * 3 + std::size_t(k)] = img.data[p];
  return out;
}

/// `rgb` [H, W, 3] with a white strip below it holding a colour bar of `cm` from `lo` (left) to
/// `hi` (right), tick marks at both ends and the middle, and their values as pixel-font labels
/// (left out when the image is too narrow for them). The result keeps the width.
inline Image<float> with_legend(const Image<float>& rgb, Colormap cm, float lo, float hi) {
  if (rgb.channels != 3) throw std::invalid_argument("with_legend: need an RGB image");
  const int W = rgb.width, H = rgb.height;
  const int pad = std::max(2, H / 50), bar_h = std::max(4, H / 16), scale = std::max(1, H / 160);
  const int text_h = detail::glyph_h * scale;
  const int strip = pad + bar_h + pad + text_h + pad;
  Image<float> out(W, H + strip, 3, 1.0f);
  std::copy(rgb.data.begin(), rgb.data.end(), out.data.begin());
  const int x0 = W > 2 * pad + 2 ? pad : 0, x1 = W > 2 * pad + 2 ? W - pad - 1 : W - 1;  // bar columns [x0, x1]
  const Image<float> bar = legend_bar(x1 - x0 + 1, bar_h, cm);
  const int bar_y = H + pad;
  for (int y = 0; y < bar_h; ++y)
    for (int x = 0; x < bar.width; ++x)
      for (int k = 0; k < 3; ++k) out.at(x0 + x, bar_y + y, k) = bar.at(x, y, k);
  const int xm = (x0 + x1) / 2, tick_y = bar_y + bar_h;
  for (int x : {x0, xm, x1})
    for (int y = tick_y; y < tick_y + pad; ++y)
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = 0.0f;
  const std::string l0 = detail::format_label(lo), lm = detail::format_label(0.5f * (lo + hi)),
                    l1 = detail::format_label(hi);
  const int w0 = detail::text_width(l0, scale), wm = detail::text_width(lm, scale), w1 = detail::text_width(l1, scale);
  if (w0 + wm + w1 + 4 * scale <= x1 - x0 + 1) {
    const int ty = tick_y + pad;
    detail::draw_text(out, x0, ty, l0, scale, 0.0f);
    detail::draw_text(out, xm - wm / 2, ty, lm, scale, 0.0f);
    detail::draw_text(out, x1 + 1 - w1, ty, l1, scale, 0.0f);
  }
  return out;
}

/// Default full-scale value of error maps: a mean absolute error of 0.25 shows as white.
inline constexpr float default_error_scale = 0.25f;

/// Per-pixel mean over channels of |render - reference|, shown on the sequential scale from 0
/// (black) to `scale` (white), [H, W, 3]. The images must have the same shape.
inline Image<float> error_map(const Image<float>& render, const Image<float>& reference,
                              float scale = default_error_scale) {
  detail::check_same_size(render, reference, "error_map", "render", "reference");
  if (render.channels != reference.channels || render.channels < 1)
    throw std::invalid_argument("error_map: render has " + std::to_string(render.channels) + " channels, reference " +
                                std::to_string(reference.channels));
  if (!(scale > 0) || !std::isfinite(scale)) throw std::invalid_argument("error_map: scale must be finite and > 0");
  Image<float> err(render.width, render.height, 1);
  const std::size_t C = std::size_t(render.channels);
  for (std::size_t p = 0; p < render.pixels(); ++p) {
    double s = 0;
    for (std::size_t c = 0; c < C; ++c) s += std::abs(double(render.data[p * C + c]) - double(reference.data[p * C + c]));
    err.data[p] = float(s / double(C));
  }
  return colourize(err, Colormap::sequential, 0.0f, scale);
}

/// Where the cells of a contact sheet go. Column c spans [col_x[c], col_x[c] + col_w[c]), row r
/// spans [row_y[r], row_y[r] + row_h[r]); `gap` pixels around and between cells.
struct SheetLayout {
  int width = 0, height = 0;
  std::vector<int> col_x, col_w;  // [columns]
  std::vector<int> row_y, row_h;  // [rows]
};

/// Rows of cells, each an image (1 or 3 channels) or nullptr for an empty cell.
using SheetCells = std::vector<std::vector<const Image<float>*>>;

/// Layout of a contact sheet: a column is as wide as its widest image, a row as tall as its
/// tallest, so bands of different resolutions line up in a grid.
inline SheetLayout contact_sheet_layout(const SheetCells& rows, int gap) {
  if (rows.empty()) throw std::invalid_argument("contact_sheet: no rows");
  if (gap < 0) throw std::invalid_argument("contact_sheet: gap must be >= 0");
  std::size_t cols = 0;
  for (const auto& r : rows) cols = std::max(cols, r.size());
  SheetLayout L;
  L.col_w.assign(cols, 0);
  L.row_h.assign(rows.size(), 0);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (std::size_t c = 0; c < rows[r].size(); ++c)
      if (const Image<float>* im = rows[r][c]) {
        L.col_w[c] = std::max(L.col_w[c], im->width);
        L.row_h[r] = std::max(L.row_h[r], im->height);
      }
  int x = gap, y = gap;
  for (int w : L.col_w) { L.col_x.push_back(x); x += w + gap; }
  for (int h : L.row_h) { L.row_y.push_back(y); y += h + gap; }
  L.width = std::max(1, x);
  L.height = std::max(1, y);
  return L;
}

/// Compose `rows` into one RGB image [height, width, 3] (see contact_sheet_layout); each image
/// sits at the top-left of its cell, grey images are replicated to RGB, the rest is `fill`.
inline Image<float> contact_sheet(const SheetCells& rows, int gap = 4, float fill = 1.0f) {
  const SheetLayout L = contact_sheet_layout(rows, gap);
  Image<float> out(L.width, L.height, 3, fill);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      const Image<float>* im = rows[r][c];
      if (!im) continue;
      const Image<float> rgb = to_rgb(*im);
      for (int y = 0; y < rgb.height; ++y)
        for (int x = 0; x < rgb.width; ++x)
          for (int k = 0; k < 3; ++k) out.at(L.col_x[c] + x, L.row_y[r] + y, k) = rgb.at(x, y, k);
    }
  return out;
}

/// Channels [first, first + count) of `img` as an image of their own.
inline Image<float> channel_slice(const Image<float>& img, int first, int count) {
  if (first < 0 || count < 1 || first + count > img.channels)
    throw std::invalid_argument("channel_slice: channels [" + std::to_string(first) + ", " +
                                std::to_string(first + count) + ") outside an image of " +
                                std::to_string(img.channels));
  Image<float> out(img.width, img.height, count);
  const std::size_t C = std::size_t(img.channels), n = std::size_t(count);
  for (std::size_t p = 0; p < img.pixels(); ++p)
    for (std::size_t c = 0; c < n; ++c) out.data[p * n + c] = img.data[p * C + std::size_t(first) + c];
  return out;
}

// =============================================================================================
// Models: run-time dispatch on channel count and SH degree
// =============================================================================================

/// The model type msgs reads for `C` channels and SH degree `D`.
template <int C, int D>
using ModelOf = GaussianModel<Gaussian<C, D>, float>;

/// Any model a PLY can hold: C in {1, 3, 7} (a narrow band, RGB, Joint), degree 0..3.
using AnyModel = std::variant<ModelOf<1, 0>, ModelOf<1, 1>, ModelOf<1, 2>, ModelOf<1, 3>,  //
                              ModelOf<3, 0>, ModelOf<3, 1>, ModelOf<3, 2>, ModelOf<3, 3>,  //
                              ModelOf<7, 0>, ModelOf<7, 1>, ModelOf<7, 2>, ModelOf<7, 3>>;

/// A model read from a PLY file together with what its header says.
struct LoadedModel {
  std::filesystem::path path;
  io::PlyInfo info;  ///< channels, SH degree, band names (empty for files from other tools)
  AnyModel model;
  int channels() const { return info.channels; }
  int sh_degree() const { return info.sh_degree; }
  std::size_t size() const {
    return std::visit([](const auto& m) { return m.size(); }, model);
  }
};

namespace detail {
template <int C>
AnyModel read_model_with_channels(const std::filesystem::path& p, int degree) {
  switch (degree) {
    case 0: return io::read_ply<Gaussian<C, 0>>(p);
    case 1: return io::read_ply<Gaussian<C, 1>>(p);
    case 2: return io::read_ply<Gaussian<C, 2>>(p);
    case 3: return io::read_ply<Gaussian<C, 3>>(p);
    default: io::fail(p, "f_rest_*", io::cat("SH degree ", degree, " is not 0..3"));
  }
}
}  // namespace detail

/// Read a Gaussian model PLY as the Gaussian<C, D> its header describes (io::inspect_ply). Throws
/// io::IoError naming the file and field for anything else: point clouds, other channel counts,
/// malformed or truncated files.
inline LoadedModel load_model(const std::filesystem::path& p) {
  LoadedModel m;
  m.path = p;
  m.info = io::inspect_ply(p);
  if (!m.info.gaussian) io::fail(p, "not a Gaussian model (needs f_dc_* and opacity properties)");
  switch (m.info.channels) {
    case 1: m.model = detail::read_model_with_channels<1>(p, m.info.sh_degree); break;
    case 3: m.model = detail::read_model_with_channels<3>(p, m.info.sh_degree); break;
    case 7: m.model = detail::read_model_with_channels<7>(p, m.info.sh_degree); break;
    default:
      io::fail(p, "f_dc_*", io::cat(m.info.channels, " colour channels; msgs renders models with 1 (one band), ",
                                    "3 (RGB) or 7 (Joint) channels"));
  }
  return m;
}

/// Renders channels of one loaded model: (camera, settings) -> image [H, W, band_count].
using ChannelRenderer = std::function<Image<float>(const Camera<float>&, const RenderSettings<float>&)>;
/// Makes the renderer of a loaded model; decides which Rasterizer types are compiled.
using RendererFactory = std::function<ChannelRenderer(std::shared_ptr<const LoadedModel>)>;

/// Renderer for a model held as exactly GaussianModel<G>; std::invalid_argument for another type.
/// The renderer keeps the model and one Rasterizer (its buffers are reused between frames).
template <class G>
ChannelRenderer make_typed_renderer(std::shared_ptr<const LoadedModel> m) {
  using Model = GaussianModel<G, float>;
  const Model* model = std::get_if<Model>(&m->model);
  if (!model)
    throw std::invalid_argument("make_typed_renderer: " + m->path.string() + " holds " +
                                std::to_string(m->channels()) + " channels of SH degree " +
                                std::to_string(m->sh_degree()) + ", not Gaussian<" + std::to_string(G::bands) + ", " +
                                std::to_string(G::sh_degree) + ">");
  auto raster = std::make_shared<Rasterizer<G, float>>();
  return [m, model, raster](const Camera<float>& cam, const RenderSettings<float>& rs) {
    return raster->forward(*model, cam, rs);
  };
}

/// Renderer for a model with `C` channels and any SH degree (instantiates four Rasterizers).
template <int C>
ChannelRenderer make_channel_renderer(std::shared_ptr<const LoadedModel> m) {
  if (m->channels() != C)
    throw std::invalid_argument("make_channel_renderer<" + std::to_string(C) + ">: " + m->path.string() + " has " +
                                std::to_string(m->channels()) + " channels");
  switch (m->sh_degree()) {
    case 0: return make_typed_renderer<Gaussian<C, 0>>(std::move(m));
    case 1: return make_typed_renderer<Gaussian<C, 1>>(std::move(m));
    case 2: return make_typed_renderer<Gaussian<C, 2>>(std::move(m));
    default: return make_typed_renderer<Gaussian<C, 3>>(std::move(m));
  }
}

/// Where a band's channels live: which model of a ModelSet, which of its channels.
struct BandSource {
  std::size_t model = 0;  ///< index into ModelSet::models()
  int first_channel = 0;
  int channels = 1;
};

/// The models that render a dataset's bands: one Joint PLY, one RGB or single-band PLY, or a
/// directory of per-band PLYs (model_D.ply, model_MS_NIR.ply ... as `msgs train` writes them).
/// Bands come from the `msgs_bands` header comment; a file without names is read as the RGB band
/// D (3 channels), the standard Joint layout (7), or a single band that renders any 1-channel
/// band it is asked for (1).
class ModelSet {
 public:
  /// Load `ply_or_dir` (a PLY file, or a directory whose model_*.ply files are all loaded) and
  /// make a renderer for each model with `factory`. Throws io::IoError naming the file for
  /// unreadable models, unknown band names and two models claiming the same band.
  static ModelSet load(const std::filesystem::path& ply_or_dir, const RendererFactory& factory) {
    namespace fs = std::filesystem;
    std::vector<fs::path> files;
    std::error_code ec;
    if (fs::is_directory(ply_or_dir, ec)) {
      for (const auto& e : fs::directory_iterator(ply_or_dir, ec)) {
        const std::string name = e.path().filename().string();
        if (e.is_regular_file() && name.rfind("model_", 0) == 0 && io::detail::lower_extension(e.path()) == ".ply")
          files.push_back(e.path());
      }
      if (ec) io::fail(ply_or_dir, io::cat("cannot list directory: ", ec.message()));
      if (files.empty()) io::fail(ply_or_dir, "directory holds no model_*.ply files");
      std::sort(files.begin(), files.end());
    } else if (fs::exists(ply_or_dir, ec)) {
      files.push_back(ply_or_dir);
    } else {
      io::fail(ply_or_dir, "model file or directory does not exist");
    }
    std::vector<LoadedModel> models;
    for (const auto& f : files) models.push_back(load_model(f));
    return from_models(std::move(models), factory);
  }

  /// A set from models already in memory (their `path` is used in messages only).
  static ModelSet from_models(std::vector<LoadedModel> models, const RendererFactory& factory) {
    if (models.empty()) throw std::invalid_argument("ModelSet: no models");
    ModelSet s;
    for (auto& m : models) {
      auto shared = std::make_shared<const LoadedModel>(std::move(m));
      s.add_bands(*shared, s.models_.size());
      s.renderers_.push_back(factory(shared));
      s.models_.push_back(std::move(shared));
    }
    return s;
  }

  const std::vector<std::shared_ptr<const LoadedModel>>& models() const { return models_; }

  /// The source of `band`: a named one, else the unnamed single-band model for a 1-channel band;
  /// nullptr when no model renders it.
  const BandSource* source(std::string_view band) const {
    if (auto it = named_.find(std::string(band)); it != named_.end()) return &it->second;
    const io::BandInfo* b = io::find_band(band);
    if (wildcard_ && b && b->channels == 1) return &*wildcard_;
    return nullptr;
  }
  /// Like source() but only a model that names the band: composites need distinct bands.
  const BandSource* named_source(std::string_view band) const {
    auto it = named_.find(std::string(band));
    return it == named_.end() ? nullptr : &it->second;
  }
  /// True when some model renders `band`.
  bool renders(std::string_view band) const { return source(band) != nullptr; }

  /// Render `band` from `cam`. `background`: empty (0), one value or one per band channel;
  /// `sh_degree` < 0 renders the model's full degree, otherwise at most that degree.
  Image<float> render(std::string_view band, const Camera<float>& cam, const std::vector<float>& background = {},
                      int sh_degree = -1) const {
    return render_bands({std::string(band)}, cam, {background}, sh_degree).front();
  }

  /// Render several bands from one camera (the same viewpoint), one image per band in the order
  /// given. Bands held in adjacent channels of one model (G, R, RE, NIR of a Joint model) share
  /// one forward pass. `backgrounds[i]` as in render() for bands[i] (or empty vector: all 0).
  std::vector<Image<float>> render_bands(const std::vector<std::string>& bands, const Camera<float>& cam,
                                         const std::vector<std::vector<float>>& backgrounds = {},
                                         int sh_degree = -1) const {
    if (!backgrounds.empty() && backgrounds.size() != bands.size())
      throw std::invalid_argument("ModelSet::render_bands: " + std::to_string(backgrounds.size()) +
                                  " backgrounds for " + std::to_string(bands.size()) + " bands");
    struct Item { std::size_t index; BandSource src; std::vector<float> bg; };
    std::vector<Item> items;
    for (std::size_t i = 0; i < bands.size(); ++i) {
      const BandSource* s = source(bands[i]);
      if (!s) throw std::invalid_argument("ModelSet: no model renders band '" + bands[i] + "'");
      std::vector<float> bg = backgrounds.empty() ? std::vector<float>{} : backgrounds[i];
      if (bg.empty()) bg.assign(std::size_t(s->channels), 0.0f);
      else if (bg.size() == 1) bg.assign(std::size_t(s->channels), bg[0]);
      else if (bg.size() != std::size_t(s->channels))
        throw std::invalid_argument("ModelSet: band '" + bands[i] + "' has " + std::to_string(s->channels) +
                                    " channel(s) but " + std::to_string(bg.size()) + " background values");
      items.push_back({i, *s, std::move(bg)});
    }
    std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
      return a.src.model != b.src.model ? a.src.model < b.src.model : a.src.first_channel < b.src.first_channel;
    });
    std::vector<Image<float>> out(bands.size());
    for (std::size_t i = 0; i < items.size();) {
      // A run of bands in adjacent channels of one model renders in one pass.
      std::size_t j = i + 1;
      int end = items[i].src.first_channel + items[i].src.channels;
      while (j < items.size() && items[j].src.model == items[i].src.model && items[j].src.first_channel == end) {
        end += items[j].src.channels;
        ++j;
      }
      const LoadedModel& m = *models_[items[i].src.model];
      RenderSettings<float> rs;
      rs.band_first = items[i].src.first_channel;
      rs.band_count = end - rs.band_first;
      rs.sh_degree = sh_degree < 0 ? -1 : std::min(sh_degree, m.sh_degree());
      for (std::size_t k = i; k < j; ++k) rs.background.insert(rs.background.end(), items[k].bg.begin(), items[k].bg.end());
      const Image<float> img = renderers_[items[i].src.model](cam, rs);
      for (std::size_t k = i; k < j; ++k)
        out[items[k].index] = j - i == 1 ? img
                                         : channel_slice(img, items[k].src.first_channel - rs.band_first,
                                                         items[k].src.channels);
      i = j;
    }
    return out;
  }

 private:
  void claim(const std::string& band, BandSource src, const LoadedModel& m) {
    auto [it, inserted] = named_.emplace(band, src);
    if (!inserted)
      io::fail(m.path, "comment msgs_bands",
               io::cat("band ", band, " is also rendered by ", models_[it->second.model]->path.string(),
                       " (one model per band)"));
  }

  void add_bands(const LoadedModel& m, std::size_t index) {
    const auto& names = m.info.band_names;
    const std::vector<std::string> joint = io::joint_channel_names();
    const io::BandInfo& rgb = *io::find_band("D");
    if (names.empty()) {
      if (m.channels() == 1) {
        if (wildcard_)
          io::fail(m.path, "comment msgs_bands",
                   io::cat("two single-band models without band names (also ", models_[wildcard_->model]->path.string(),
                           "): cannot tell which band each renders"));
        wildcard_ = BandSource{index, 0, 1};
      } else if (m.channels() == rgb.channels) {
        claim(rgb.id, BandSource{index, 0, rgb.channels}, m);
      } else {  // the standard Joint layout
        for (const auto& b : io::standard_bands()) claim(b.id, BandSource{index, b.first_channel_in_joint, b.channels}, m);
      }
      return;
    }
    bool any = false;
    for (const auto& b : io::standard_bands()) {
      // A band's channel names are its slice of the Joint names: D_R D_G D_B, or MS_NIR.
      const auto first = joint.begin() + b.first_channel_in_joint;
      const std::vector<std::string> want(first, first + b.channels);
      for (std::size_t c = 0; c + want.size() <= names.size(); ++c)
        if (std::equal(want.begin(), want.end(), names.begin() + std::ptrdiff_t(c))) {
          claim(b.id, BandSource{index, int(c), b.channels}, m);
          any = true;
          break;
        }
    }
    if (!any) {
      std::string got, known;
      for (const auto& n : names) got += (got.empty() ? "" : " ") + n;
      for (const auto& n : joint) known += (known.empty() ? "" : " ") + n;
      io::fail(m.path, "comment msgs_bands", io::cat("channel names '", got, "' match no known band (expected ", known, ")"));
    }
  }

  std::vector<std::shared_ptr<const LoadedModel>> models_;
  std::vector<ChannelRenderer> renderers_;
  std::map<std::string, BandSource> named_;
  std::optional<BandSource> wildcard_;
};

// =============================================================================================
// Datasets: frame naming, captures, rendering, evaluation
// =============================================================================================

/// The capture a frame belongs to: the trailing digits of its file name's stem, which the frames
/// of one exposure share ("images/MS_NIR_00007.TIF" -> "00007"); empty when the stem ends in none.
inline std::string capture_key(std::string_view file_path) {
  const std::string stem = std::filesystem::path(file_path).stem().string();
  std::size_t i = stem.size();
  while (i > 0 && std::isdigit(static_cast<unsigned char>(stem[i - 1]))) --i;
  return stem.substr(i);
}

/// Frames of one exposure of the rig: band id -> index into Dataset::frames.
struct Capture {
  std::string key;  ///< capture_key of its frames, or a frame's stem when it has no numeric suffix
  std::map<std::string, std::size_t> frames;
};

/// Group `frames` (indices into ds.frames) by capture, in order of first appearance. A second
/// frame of the same band and key (another folder) starts a capture of its own.
inline std::vector<Capture> group_captures(const io::Dataset& ds, const std::vector<std::size_t>& frames) {
  std::vector<Capture> out;
  std::map<std::string, std::vector<std::size_t>> by_key;  // key -> captures with that key
  for (std::size_t f : frames) {
    const io::Frame& fr = ds.frames[f];
    std::string key = capture_key(fr.file_path);
    if (key.empty()) key = std::filesystem::path(fr.file_path).stem().string();
    Capture* cap = nullptr;
    for (std::size_t c : by_key[key])
      if (!out[c].frames.count(fr.band)) { cap = &out[c]; break; }
    if (!cap) {
      by_key[key].push_back(out.size());
      out.push_back(Capture{key, {}});
      cap = &out.back();
    }
    cap->frames[fr.band] = f;
  }
  return out;
}

/// Resolve a background given on the command line for one band: no values (0), one value (every
/// channel), one per channel of the band, or one per Joint channel (D_R D_G D_B MS_G MS_R MS_RE
/// MS_NIR) from which the band's slice is taken. std::invalid_argument otherwise.
inline std::vector<float> band_background(const std::vector<float>& values, std::string_view band) {
  const io::BandInfo* b = io::find_band(band);
  if (!b) throw std::invalid_argument("band_background: unknown band '" + std::string(band) + "'");
  for (float v : values)
    if (!std::isfinite(v)) throw std::invalid_argument("background values must be finite");
  if (values.size() <= 1) return values;
  if (int(values.size()) == io::joint_channels())
    return {values.begin() + b->first_channel_in_joint, values.begin() + b->first_channel_in_joint + b->channels};
  if (int(values.size()) == b->channels) return values;
  throw std::invalid_argument("background: " + std::to_string(values.size()) + " values do not fit band " + b->id +
                              " (" + std::to_string(b->channels) + " channel(s)); give 1 value, " +
                              std::to_string(b->channels) + ", or " + std::to_string(io::joint_channels()) +
                              " in Joint channel order");
}

/// A hidden staging directory inside `out`: write everything there, then commit() moves the
/// files into `out` (keeping subfolders, replacing files of the same name). Without commit (an
/// error), the staging directory is removed, and so is `out` if this created it; earlier
/// contents of `out` are never touched.
class OutputStage {
 public:
  explicit OutputStage(std::filesystem::path out) : out_(std::move(out)) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(out_, ec) && !fs::is_directory(out_, ec)) io::fail(out_, "output path exists and is not a directory");
    created_ = !fs::exists(out_, ec);
    fs::create_directories(out_, ec);
    if (ec) io::fail(out_, io::cat("cannot create output directory: ", ec.message()));
    std::random_device rd;
    char buf[32];
    std::snprintf(buf, sizeof buf, ".msgs-stage-%08x", unsigned(rd()));
    stage_ = out_ / buf;
    fs::create_directory(stage_, ec);
    if (ec) io::fail(stage_, io::cat("cannot create staging directory: ", ec.message()));
  }
  OutputStage(const OutputStage&) = delete;
  OutputStage& operator=(const OutputStage&) = delete;
  ~OutputStage() {
    std::error_code ec;
    std::filesystem::remove_all(stage_, ec);
    if (!committed_ && created_) std::filesystem::remove(out_, ec);  // only succeeds when empty
  }

  /// Where to write.
  const std::filesystem::path& dir() const { return stage_; }
  /// The final directory.
  const std::filesystem::path& out() const { return out_; }

  /// Move every staged file into place. Each file appears whole (rename); returns their final paths.
  std::vector<std::filesystem::path> commit() {
    namespace fs = std::filesystem;
    std::vector<fs::path> moved;
    std::vector<fs::path> files;
    for (auto it = fs::recursive_directory_iterator(stage_); it != fs::recursive_directory_iterator(); ++it)
      if (it->is_regular_file()) files.push_back(it->path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      const fs::path target = out_ / f.lexically_relative(stage_);
      std::error_code ec;
      fs::create_directories(target.parent_path(), ec);
      if (ec) io::fail(target.parent_path(), io::cat("cannot create directory: ", ec.message()));
      fs::rename(f, target, ec);
      if (ec) io::fail(target, io::cat("cannot move the finished file into place: ", ec.message()));
      moved.push_back(target);
    }
    committed_ = true;
    return moved;
  }

 private:
  std::filesystem::path out_, stage_;
  bool created_ = false, committed_ = false;
};

/// What render_dataset does.
struct DatasetRenderOptions {
  std::optional<io::Split> split;  ///< frames of this split only; nullopt = every frame
  bool write_float = false;        ///< also write float32 .npy [H, W, C], unclamped, for exact comparisons
  std::vector<float> background;   ///< see band_background; empty = black
  int sh_degree = -1;              ///< render at most this SH degree; -1 = each model's own
  bool composites = true;          ///< CIR / NDVI / NDRE per capture where the bands exist
  bool legend = true;              ///< colour bar under NDVI / NDRE maps
  /// Called after each rendered frame with (frames done, frames selected); may be empty.
  std::function<void(std::size_t, std::size_t)> on_progress;
};

/// What render_dataset wrote.
struct DatasetRenderSummary {
  std::size_t frames = 0;              ///< frames rendered
  std::vector<std::string> skipped;    ///< frames whose band no model renders (file_path)
  std::size_t composite_captures = 0;  ///< captures with at least one composite
  std::vector<std::string> files;      ///< names written, relative to the output directory
};

/// Lower and upper end of the NDVI / NDRE colour scale.
inline constexpr float index_scale_lo = -1.0f, index_scale_hi = 1.0f;

/// Render every selected frame of `ds` with its own full-resolution camera into `dir`:
/// `<stem>.png` (8-bit for RGB, 16-bit for single bands; + `<stem>.npy` with write_float).
/// Per capture whose MS_NIR frame is selected and whose bands the models name, everything is
/// rendered from the NIR camera (the cameras of one capture differ slightly, and per-pixel ratios
/// need one viewpoint): `CIR_<key>.png` (NIR, R, G as RGB), `NDVI_<key>.png`, `NDRE_<key>.png`
/// on the diverging scale over [-1, 1] (+ raw `.npy` with write_float). Everything is checked
/// before the first file is written; writes go straight into `dir` (stage it with OutputStage).
inline DatasetRenderSummary render_dataset(const io::Dataset& ds, const ModelSet& models,
                                           const std::filesystem::path& dir, const DatasetRenderOptions& opt = {}) {
  namespace fs = std::filesystem;
  DatasetRenderSummary sum;
  std::vector<std::size_t> selected;
  std::map<std::string, std::size_t> stems;  // output stem -> frame, to refuse collisions
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    const io::Frame& f = ds.frames[i];
    if (opt.split && f.split != *opt.split) continue;
    if (!models.renders(f.band)) { sum.skipped.push_back(f.file_path); continue; }
    (void)band_background(opt.background, f.band);  // throws on a background that does not fit
    const std::string stem = fs::path(f.file_path).stem().string();
    if (auto [it, ok] = stems.emplace(stem, i); !ok)
      io::fail(ds.root / "transforms.json", "file_path",
               io::cat("frames '", ds.frames[it->second].file_path, "' and '", f.file_path,
                       "' would both be rendered to ", stem, ".png"));
    selected.push_back(i);
  }
  if (selected.empty())
    io::fail(ds.root / "transforms.json", "frames",
             "no selected frame shows a band the model renders (check --split, --bands and the model's bands)");
  if (opt.sh_degree > 3) throw std::invalid_argument("render_dataset: sh_degree must be <= 3");

  for (std::size_t i : selected) {
    const io::Frame& f = ds.frames[i];
    const Image<float> img = models.render(f.band, io::frame_camera(ds, f, 1), band_background(opt.background, f.band),
                                           opt.sh_degree);
    const std::string stem = fs::path(f.file_path).stem().string();
    if (img.channels == 1) io::write_png16(dir / (stem + ".png"), img);
    else io::write_png8(dir / (stem + ".png"), img);
    sum.files.push_back(stem + ".png");
    if (opt.write_float) {
      io::write_npy(dir / (stem + ".npy"), img);
      sum.files.push_back(stem + ".npy");
    }
    ++sum.frames;
    if (opt.on_progress) opt.on_progress(sum.frames, selected.size());
  }

  if (!opt.composites) return sum;
  for (const Capture& cap : group_captures(ds, selected)) {
    auto nir_it = cap.frames.find("MS_NIR");
    if (nir_it == cap.frames.end() || !models.named_source("MS_NIR")) continue;
    std::vector<std::string> bands = {"MS_NIR"};
    for (const char* b : {"MS_R", "MS_G", "MS_RE"})
      if (models.named_source(b)) bands.push_back(b);
    if (bands.size() == 1) continue;
    std::vector<std::vector<float>> bgs;
    for (const auto& b : bands) bgs.push_back(band_background(opt.background, b));
    const io::Frame& nir_frame = ds.frames[nir_it->second];
    const std::vector<Image<float>> views =
        models.render_bands(bands, io::frame_camera(ds, nir_frame, 1), bgs, opt.sh_degree);
    auto view = [&](const char* b) -> const Image<float>* {
      for (std::size_t k = 0; k < bands.size(); ++k)
        if (bands[k] == b) return &views[k];
      return nullptr;
    };
    auto write_index = [&](const std::string& name, const Image<float>& index) {
      Image<float> rgb = colourize(index, Colormap::diverging, index_scale_lo, index_scale_hi);
      if (opt.legend) rgb = with_legend(rgb, Colormap::diverging, index_scale_lo, index_scale_hi);
      io::write_png8(dir / (name + ".png"), rgb);
      sum.files.push_back(name + ".png");
      if (opt.write_float) {
        io::write_npy(dir / (name + ".npy"), index);
        sum.files.push_back(name + ".npy");
      }
    };
    const Image<float>* nir = view("MS_NIR");
    if (view("MS_R") && view("MS_G")) {
      const Image<float> cir = cir_composite(*nir, *view("MS_R"), *view("MS_G"));
      io::write_png8(dir / ("CIR_" + cap.key + ".png"), cir);
      sum.files.push_back("CIR_" + cap.key + ".png");
      if (opt.write_float) {
        io::write_npy(dir / ("CIR_" + cap.key + ".npy"), cir);
        sum.files.push_back("CIR_" + cap.key + ".npy");
      }
    }
    if (view("MS_R")) write_index("NDVI_" + cap.key, ndvi(*nir, *view("MS_R")));
    if (view("MS_RE")) write_index("NDRE_" + cap.key, ndre(*nir, *view("MS_RE")));
    ++sum.composite_captures;
  }
  return sum;
}

/// What evaluate_models does.
struct EvalOptions {
  bool sheets = true;                     ///< write a contact sheet per eval capture
  /// Sheets for at most this many eval captures, the first ones in capture order (group_captures
  /// of the eval frames, i.e. file order); -1 = every eval capture, 0 = none. Metrics always
  /// cover every eval frame.
  int max_sheets = -1;
  float error_scale = default_error_scale; ///< mean absolute error shown as white in error maps
  float index_error_scale = 0.5f;         ///< NDVI / NDRE difference shown as white
  int gap = 4;                            ///< pixels between contact-sheet cells
  float fill = 0.35f;                     ///< grey between cells: error maps run from black to white
  /// Called after each eval capture with (captures done, eval captures); may be empty.
  std::function<void(std::size_t, std::size_t)> on_progress;
};

/// Per-band results of evaluate_models.
struct EvalResult {
  std::vector<BandMetrics> metrics;              ///< standard band order; bands with eval frames and a model
  std::vector<std::vector<std::string>> frames;  ///< per metrics entry: file_path of each value
  std::vector<std::string> skipped_bands;        ///< bands with eval frames that no model renders
  std::vector<std::string> files;                ///< sheets written, relative to the sheet directory
};

/// PSNR and SSIM of every eval frame whose band a model renders, at full resolution with the
/// reference evaluation background (eval_background) and renders clamped to [0, 1], exactly as
/// Trainer::evaluate. With `sheet_dir` non-empty and opt.sheets, one `sheet_<capture>.png` per
/// eval capture (the first opt.max_sheets captures when that is >= 0): a row per band of ground
/// truth | render | error map, then rows for CIR, NDVI and NDRE of ground truth | render (all from
/// the NIR camera) | difference, where the bands exist. Sheets are written straight into
/// `sheet_dir`, each file atomically (stage the directory with OutputStage for all-or-nothing).
/// Ground-truth composites combine the bands' own images (one size required; they come from
/// slightly different viewpoints, as the cameras do).
inline EvalResult evaluate_models(const io::Dataset& ds, const ModelSet& models,
                                  const std::filesystem::path& sheet_dir = {}, const EvalOptions& opt = {}) {
  if (opt.max_sheets < -1)
    throw std::invalid_argument("evaluate_models: max_sheets must be -1 (every capture) or >= 0, got " +
                                std::to_string(opt.max_sheets));
  EvalResult res;
  std::vector<std::size_t> eval_frames;
  std::set<std::string> skipped;
  for (std::size_t i = 0; i < ds.frames.size(); ++i) {
    const io::Frame& f = ds.frames[i];
    if (f.split != io::Split::eval) continue;
    if (models.renders(f.band)) eval_frames.push_back(i);
    else skipped.insert(f.band);
  }
  for (const auto& b : io::standard_bands())
    if (skipped.count(b.id)) res.skipped_bands.push_back(b.id);
  if (eval_frames.empty())
    io::fail(ds.root / (ds.has_split_file ? "train_split.json" : "transforms.json"), "eval",
             "no eval frame shows a band the model renders");

  std::map<std::string, std::size_t> slot;  // band -> index into res.metrics
  for (const auto& b : io::standard_bands())
    for (std::size_t f : eval_frames)
      if (ds.frames[f].band == b.id) {
        slot[b.id] = res.metrics.size();
        res.metrics.push_back(BandMetrics{b.id, {}, {}});
        res.frames.emplace_back();
        break;
      }

  const bool sheets = opt.sheets && !sheet_dir.empty();
  const std::vector<Capture> captures = group_captures(ds, eval_frames);
  std::size_t done = 0;
  for (const Capture& cap : captures) {
    if (opt.on_progress && done > 0) opt.on_progress(done, captures.size());
    // Captures come in a fixed order, so "the first max_sheets" is the same set on every run.
    const bool sheet = sheets && (opt.max_sheets < 0 || done < std::size_t(opt.max_sheets));
    ++done;
    struct View { std::string band; Image<float> gt, render, error; };
    std::vector<View> views;
    for (const auto& b : io::standard_bands()) {
      auto it = cap.frames.find(b.id);
      if (it == cap.frames.end()) continue;
      const io::Frame& f = ds.frames[it->second];
      View v;
      v.band = b.id;
      v.render = models.render(b.id, io::frame_camera(ds, f, 1), eval_background<float>(b.channels));
      clamp01(v.render);
      v.gt = io::load_frame_image(ds, f, 1);
      BandMetrics& m = res.metrics[slot.at(b.id)];
      m.psnr.push_back(psnr(v.render, v.gt));
      m.ssim.push_back(ssim(v.render, v.gt));
      res.frames[slot.at(b.id)].push_back(f.file_path);
      if (sheet) {
        v.error = error_map(v.render, v.gt, opt.error_scale);
        views.push_back(std::move(v));
      }
    }
    if (!sheet) continue;

    SheetCells rows;
    for (const View& v : views) rows.push_back({&v.gt, &v.render, &v.error});
    // Composites: ground truth from each band's own image, renders from the NIR camera.
    std::deque<Image<float>> extra;  // keeps the composite images alive for `rows` (stable addresses)
    auto find_view = [&](const char* b) -> const View* {
      for (const View& v : views)
        if (v.band == b) return &v;
      return nullptr;
    };
    const View* nir = find_view("MS_NIR");
    if (nir && models.named_source("MS_NIR")) {
      std::vector<std::string> bands = {"MS_NIR"};
      for (const char* b : {"MS_R", "MS_G", "MS_RE"})
        if (find_view(b) && models.named_source(b) && find_view(b)->gt.width == nir->gt.width &&
            find_view(b)->gt.height == nir->gt.height)
          bands.push_back(b);
      const std::vector<std::vector<float>> bgs(bands.size(), eval_background<float>(1));
      std::vector<Image<float>> rendered =
          models.render_bands(bands, io::frame_camera(ds, ds.frames[cap.frames.at("MS_NIR")], 1), bgs);
      for (auto& r : rendered) clamp01(r);
      auto pick = [&](const char* b) -> std::pair<const Image<float>*, const Image<float>*> {
        for (std::size_t k = 0; k < bands.size(); ++k)
          if (bands[k] == b) return {&find_view(b)->gt, &rendered[k]};
        return {nullptr, nullptr};
      };
      const auto [gn, rn] = pick("MS_NIR");
      const auto [gr, rr] = pick("MS_R");
      const auto [gg, rg] = pick("MS_G");
      const auto [ge, re] = pick("MS_RE");
      auto add_row = [&](Image<float> g, Image<float> r, Image<float> e) {
        extra.push_back(std::move(g));
        extra.push_back(std::move(r));
        extra.push_back(std::move(e));
        const std::size_t n = extra.size();
        rows.push_back({&extra[n - 3], &extra[n - 2], &extra[n - 1]});
      };
      if (gr && gg) {
        Image<float> cg = cir_composite(*gn, *gr, *gg), cr = cir_composite(*rn, *rr, *rg);
        Image<float> ce = error_map(cr, cg, opt.error_scale);
        add_row(std::move(cg), std::move(cr), std::move(ce));
      }
      for (auto [gb, rb] : {std::pair{gr, rr}, std::pair{ge, re}}) {
        if (!gb) continue;
        const Image<float> ig = normalized_difference(*gn, *gb), ir = normalized_difference(*rn, *rb);
        add_row(colourize(ig, Colormap::diverging, index_scale_lo, index_scale_hi),
                colourize(ir, Colormap::diverging, index_scale_lo, index_scale_hi),
                error_map(ir, ig, opt.index_error_scale));
      }
    }
    const std::string name = "sheet_" + cap.key + ".png";
    io::write_png8(sheet_dir / name, contact_sheet(rows, opt.gap, opt.fill));
    res.files.push_back(name);
  }
  if (opt.on_progress) opt.on_progress(captures.size(), captures.size());
  return res;
}

}  // namespace msgs
