// include/msgs/spectral_index.hpp
// Spectral indices computed per pixel from rendered (or captured) bands: the normalised difference
// (NDVI, NDRE) with its colour-scale range, and the colour-infrared composite.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "detail/image_checks.hpp"
#include "image.hpp"

namespace msgs {

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
/// Lower and upper end of the NDVI / NDRE colour scale.
inline constexpr float index_scale_lo = -1.0f, index_scale_hi = 1.0f;

}  // namespace msgs
