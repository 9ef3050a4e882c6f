// include/msgs/colormap.hpp
// Colour scales for single-channel data (diverging RdYlGn for indices, sequential "hot" for
// errors), colour bars, and legends with their values (drawn with text.hpp) under a picture.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>

#include "detail/image_checks.hpp"
#include "image.hpp"
#include "text.hpp"

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

/// Smallest size of the words in pictures (legend values, sheet labels), pixels per em: DejaVu
/// Sans stays legible down to about 12 px.
inline constexpr int min_label_px = 12;

/// Size of the words in a picture whose cells are `width` pixels wide: 1/40 of it (a 1800-pixel
/// image gets 45 px), at least min_label_px, at most 200.
inline int label_px(int width) { return std::clamp(int(std::lround(double(width) / 40.0)), min_label_px, 200); }

/// Sizes inside a legend strip for text at `px` (see legend_strip).
struct LegendMetrics {
  int pad = 0;    ///< margin above the bar, tick length, margin below the values
  int bar_h = 0;  ///< height of the colour bar
  int text_h = 0; ///< height of the value line (0 without text)
  int height() const { return pad + bar_h + pad + text_h + (text_h > 0 ? pad : 0); }
};

/// The sizes legend_strip uses for text at `px`, with or without text.
inline LegendMetrics legend_metrics(int px, const TextRenderer* text) {
  LegendMetrics m;
  m.pad = std::max(2, px / 5);
  m.bar_h = std::max(4, (px * 2) / 3);
  m.text_h = text ? text->line_height(px) : 0;
  return m;
}

/// A legend [legend_metrics(px, text).height(), width, 3] on `background`: a colour bar of `cm`
/// from `lo` (left) to `hi` (right) with `pad` pixels left and right (none when too narrow),
/// tick marks of `ink` at both ends and the middle, and below them their values at `px` (%g),
/// left-aligned, centred and right-aligned to the ticks. The values are left out when `text` is
/// nullptr or they do not fit side by side.
inline Image<float> legend_strip(int width, Colormap cm, float lo, float hi, const TextRenderer* text, int px,
                                 float background = 1.0f, float ink = 0.0f) {
  if (width < 1) throw std::invalid_argument("legend_strip: width must be >= 1");
  const LegendMetrics m = legend_metrics(px, text);
  Image<float> out(width, m.height(), 3, background);
  const int pad = m.pad;
  const int x0 = width > 2 * pad + 2 ? pad : 0, x1 = width > 2 * pad + 2 ? width - pad - 1 : width - 1;  // bar [x0, x1]
  const Image<float> bar = legend_bar(x1 - x0 + 1, m.bar_h, cm);
  for (int y = 0; y < m.bar_h; ++y)
    for (int x = 0; x < bar.width; ++x)
      for (int k = 0; k < 3; ++k) out.at(x0 + x, pad + y, k) = bar.at(x, y, k);
  const int xm = (x0 + x1) / 2, tick_y = pad + m.bar_h;
  for (int x : {x0, xm, x1})
    for (int y = tick_y; y < tick_y + pad; ++y)
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = ink;
  if (!text) return out;
  const std::string l0 = detail::format_label(lo), lm = detail::format_label(0.5f * (lo + hi)),
                    l1 = detail::format_label(hi);
  const int w0 = text_width(*text, l0, px), wm = text_width(*text, lm, px), w1 = text_width(*text, l1, px);
  if (w0 + wm + w1 + px > x1 - x0 + 1) return out;  // no room for three values and two spaces
  const int ty = tick_y + pad;
  const std::array<float, 3> c{ink, ink, ink};
  (void)draw_text(out, *text, l0, px, x0, ty, c);
  (void)draw_text(out, *text, lm, px, xm - wm / 2, ty, c);
  (void)draw_text(out, *text, l1, px, x1 + 1 - w1, ty, c);
  return out;
}

/// `rgb` [H, W, 3] with a white strip below it: legend_strip of `cm` from `lo` to `hi` with its
/// values in black at label_px(W). The result keeps the width. `text`: how the values are
/// drawn; nullptr leaves them out (the bar and ticks stay).
inline Image<float> with_legend(const Image<float>& rgb, Colormap cm, float lo, float hi,
                                const TextRenderer* text = default_text()) {
  if (rgb.channels != 3) throw std::invalid_argument("with_legend: need an RGB image");
  const Image<float> strip = legend_strip(rgb.width, cm, lo, hi, text, label_px(rgb.width));
  Image<float> out(rgb.width, rgb.height + strip.height, 3, 1.0f);
  std::copy(rgb.data.begin(), rgb.data.end(), out.data.begin());
  std::copy(strip.data.begin(), strip.data.end(), out.data.begin() + std::ptrdiff_t(rgb.data.size()));
  return out;
}

}  // namespace msgs
