// include/msgs/synth/spectra.hpp
// Bands of the synthetic 5-camera rig and per-material reflectance spectra (linear RGB albedo plus
// the four narrow multispectral bands), from published field spectra of vegetation, soil and water.
#pragma once

#include <array>
#include <cmath>
#include <stdexcept>
#include <string>
#include <string_view>

namespace msgs::synth {

/// The five cameras of the rig, in the order the dataset lists them (REFERENCE.md §1).
enum class Band : int { D = 0, MS_G = 1, MS_R = 2, MS_RE = 3, MS_NIR = 4 };

/// Number of bands (cameras) in the rig.
inline constexpr int num_bands = 5;
/// All bands in rig order.
inline constexpr std::array<Band, num_bands> all_bands = {Band::D, Band::MS_G, Band::MS_R, Band::MS_RE,
                                                          Band::MS_NIR};

/// `mm_channel` name of a band as written in transforms.json and in the file names.
constexpr std::string_view band_name(Band b) {
  switch (b) {
    case Band::D: return "D";
    case Band::MS_G: return "MS_G";
    case Band::MS_R: return "MS_R";
    case Band::MS_RE: return "MS_RE";
    case Band::MS_NIR: return "MS_NIR";
  }
  return "?";
}

/// Image channels of a band: 3 for the RGB camera, 1 for each narrow band.
constexpr int band_channels(Band b) { return b == Band::D ? 3 : 1; }

/// Parse a band name ("D", "MS_G", ...); throws std::invalid_argument on anything else.
inline Band band_from_name(std::string_view s) {
  for (Band b : all_bands)
    if (band_name(b) == s) return b;
  throw std::invalid_argument("unknown band '" + std::string(s) + "' (expected D, MS_G, MS_R, MS_RE or MS_NIR)");
}

/// Reflectance (or radiance) in the 7 rendered channels: linear R, G, B of the RGB camera, then
/// 560, 650, 730 and 860 nm. A Joint model's 7 colour channels follow the same order.
using Spectrum = std::array<float, 7>;

/// Index of the first Spectrum channel a band reads (D reads 3 channels from 0).
constexpr int band_offset(Band b) { return b == Band::D ? 0 : 2 + static_cast<int>(b); }

/// sRGB transfer function (linear -> encoded), input clamped to [0, 1].
inline float srgb_encode(float v) {
  v = v < 0.f ? 0.f : (v > 1.f ? 1.f : v);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.f / 2.4f) - 0.055f;
}

/// Inverse sRGB transfer function (encoded -> linear).
inline float srgb_decode(float v) {
  v = v < 0.f ? 0.f : (v > 1.f ? 1.f : v);
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

/// Channel-wise a + (b - a) t.
inline Spectrum mix(const Spectrum& a, const Spectrum& b, float t) {
  Spectrum r;
  for (int i = 0; i < 7; ++i) r[i] = a[i] + (b[i] - a[i]) * t;
  return r;
}

/// Channel-wise product.
inline Spectrum operator*(const Spectrum& a, const Spectrum& b) {
  Spectrum r;
  for (int i = 0; i < 7; ++i) r[i] = a[i] * b[i];
  return r;
}

/// Scale all channels.
inline Spectrum operator*(const Spectrum& a, float s) {
  Spectrum r;
  for (int i = 0; i < 7; ++i) r[i] = a[i] * s;
  return r;
}

/// Channel-wise sum.
inline Spectrum operator+(const Spectrum& a, const Spectrum& b) {
  Spectrum r;
  for (int i = 0; i < 7; ++i) r[i] = a[i] + b[i];
  return r;
}

/// Material reflectances. RGB entries are linear albedos chosen so that the narrow green/red bands
/// and the broad RGB channels tell a consistent story; narrow-band values follow the brief
/// (vegetation, soils, water) or typical field spectra (panels, paint, concrete, bark).
namespace spectra {
//                                   R      G      B     560    650    730    860
inline constexpr Spectrum grass      {0.040f, 0.075f, 0.022f, 0.053f, 0.029f, 0.270f, 0.425f};
inline constexpr Spectrum leaves     {0.032f, 0.068f, 0.020f, 0.050f, 0.026f, 0.300f, 0.460f};
inline constexpr Spectrum dry_soil   {0.300f, 0.240f, 0.170f, 0.264f, 0.309f, 0.353f, 0.411f};
inline constexpr Spectrum wet_soil   {0.036f, 0.028f, 0.020f, 0.029f, 0.036f, 0.048f, 0.072f};
inline constexpr Spectrum water      {0.025f, 0.040f, 0.055f, 0.040f, 0.030f, 0.010f, 0.005f};
inline constexpr Spectrum bark       {0.090f, 0.065f, 0.045f, 0.070f, 0.095f, 0.150f, 0.220f};
inline constexpr Spectrum panel_glass{0.030f, 0.040f, 0.095f, 0.040f, 0.032f, 0.038f, 0.050f};
inline constexpr Spectrum aluminium  {0.550f, 0.560f, 0.580f, 0.555f, 0.560f, 0.565f, 0.575f};
inline constexpr Spectrum backsheet  {0.700f, 0.700f, 0.690f, 0.700f, 0.705f, 0.710f, 0.715f};
inline constexpr Spectrum concrete   {0.380f, 0.370f, 0.345f, 0.375f, 0.390f, 0.410f, 0.420f};
// Paints: strong visible differences, red edge and NIR held at the concrete's 0.41 / 0.42 so the
// markings vanish in those bands (the RGB-only detail the brief asks for).
inline constexpr Spectrum paint_red    {0.550f, 0.050f, 0.040f, 0.060f, 0.520f, 0.410f, 0.420f};
inline constexpr Spectrum paint_blue   {0.040f, 0.090f, 0.420f, 0.090f, 0.045f, 0.410f, 0.420f};
inline constexpr Spectrum paint_yellow {0.620f, 0.500f, 0.040f, 0.520f, 0.600f, 0.410f, 0.420f};
inline constexpr Spectrum paint_white  {0.800f, 0.800f, 0.780f, 0.800f, 0.800f, 0.410f, 0.420f};
inline constexpr Spectrum paint_black  {0.040f, 0.040f, 0.040f, 0.040f, 0.040f, 0.410f, 0.420f};
// Line paint on the lawn: red edge / NIR matched to grass, so the line shows in RGB, G and R only.
inline constexpr Spectrum line_paint   {0.520f, 0.160f, 0.050f, 0.140f, 0.480f, 0.270f, 0.425f};
}  // namespace spectra

}  // namespace msgs::synth
