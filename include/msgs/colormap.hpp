// include/msgs/colormap.hpp
// Colour scales for single-channel data (diverging RdYlGn for indices, sequential "hot" for
// errors), colour bars, and legends with their values under a picture.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>

#include "detail/image_checks.hpp"
#include "image.hpp"

namespace msgs {

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

}  // namespace msgs
