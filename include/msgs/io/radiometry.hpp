// include/msgs/io/radiometry.hpp
// Radiometric normalisation of raw multi-band captures to relative radiance:
//
//   L(x, y) = (DN - black_level) / (exposure_s * gain * falloff(r) * row(y)) * scale
//
// with DN in the file's digital numbers, falloff(r) the vignetting polynomial 1 + k0 r + k1 r^2 + ...
// at the pixel's distance r from the vignetting centre (MicaSense convention; a DJI-style
// correction polynomial enters as 1 / p(r)) or the 2-D fall-off sum_i c_i (x/W)^a_i (y/H)^b_i of
// Parrot Sequoia and MicaSense RedEdge-P / Altum-PT, row(y) = 1 + a2 y / exposure_s - a3 y
// MicaSense's row gradient (1 for other cameras), and `scale` one common factor per band for the whole
// capture set, chosen so that the brightest normalised value of the band is 1. Where a Parrot
// Sequoia writes its own model of the sensor (SensorModel A, B, C, with its fall-off V), that model
// takes the place of the black level, exposure and gain:
//
//   L(x, y) = (DN - B V(x, y)) / (V(x, y) (A exposure_s ISO + C)) * scale
//
// (Parrot's irradiance f^2 (DN / V - B) / (A exposure ISO + C), its fixed f-number in the scale).
// Steps whose tags
// are missing for some image of a band are left out for the whole band (mixing corrected and
// uncorrected images would break the common scale); plan_band says which and why.
//
// Reflectance (`msgs import --radiometry reflectance`), as MicaSense's library and OpenDroneMap
// compute it from the camera's light sensor:
//
//   R(x, y) = pi * a1 * (DN - black_level) / 2^bits / (exposure_s * gain * falloff * row(y) * E)
//
// with a1 MicaSense's radiometric calibration (radiance in W/m^2/sr/nm) and E the horizontal
// irradiance (W/m^2/nm) that the DLS 2 recorded with the capture, or that msgs levelled from what
// the light sensor recorded (msgs/io/light_sensor_tilt.hpp: a DLS 1's tilted reading, a DLS 2
// whose firmware wrote HorizontalIrradiance wrongly). Every step is then required.
//
// Reflectance from a calibration panel (`--radiometry panel`, as MicaSense's batch processing
// does): a picture of a panel of known reflectance rho (its albedo) gives the band's irradiance in
// the sensor's own units, E = mean over the panel's area of (DN - black_level) / response / rho,
// and every image of the band becomes R = (DN - black_level) / (response * E). With several panel
// pictures, E is their mean. Panels of several reflectances in one session give an empirical
// line, response = E (rho + offset) (msgs/io/calibration_panel.hpp), and R loses the offset.
// `--radiometry panel+dls` (MicaSense's tutorial 3) keeps the light sensor for the changes of the
// sunlight during the flight and lets the panel set its level: the response then includes the
// DLS 2 irradiance of each picture, the panel's and the flight's.
// DJI's sunlight sensor takes the DLS 2's place there, in its own units.
//
// Reflectance up to one factor common to all bands (`--radiometry sun-sensor`, as DJI's image
// processing guides compute NDVI from the sunlight sensor): every image is divided by its light
// sensor's reading and multiplied by the band camera's calibration (DJI's SensorGainAdjustment,
// MicaSense's pi a1), and one scale for all bands then maps the brightest value of any band to 1.
// Band ratios and normalised differences are those of reflectance; the level is not.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "msgs/image.hpp"
#include "msgs/io/capture_meta.hpp"
#include "msgs/io/error.hpp"

namespace msgs::io {

/// Which corrections are applied to a band.
struct RadiometrySteps {
  bool black_level = false, exposure = false, gain = false, vignetting = false, row_gradient = false;
  bool irradiance = false;  ///< reflectance: divide by the light sensor's irradiance
  /// The Parrot Sequoia's SensorModel in place of the black level and exposure x gain (with both
  /// the exposure and gain steps, gain being ISO / 100).
  bool sensor_model = false;
  bool any() const { return black_level || exposure || gain || vignetting || row_gradient || irradiance || sensor_model; }
};

/// The normalisation of one image.
struct FrameRadiometry {
  RadiometrySteps steps;
  double dn_max = 65535.0;  ///< digital number of a stored 1.0 (65535 for 16-bit, 255 for 8-bit)
  double black_level = 0.0, exposure_s = 1.0, gain = 1.0;
  std::vector<double> vignetting_poly;
  double vignetting_cx = 0.0, vignetting_cy = 0.0;
  VignettingKind vignetting_kind = VignettingKind::falloff;
  std::vector<double> vignetting_poly2d;             ///< 2-D fall-off coefficients (used when non-empty)
  std::vector<std::array<int, 2>> vignetting_exp2d;  ///< their exponents of x / width and y / height
  int width = 0, height = 0;  ///< the image's size, which the 2-D model's coordinates are divided by
  double row_a2 = 0.0, row_a3 = 0.0;  ///< MicaSense's row gradient (used when steps.row_gradient)
  double model_a = 0.0, model_b = 0.0, model_c = 0.0;  ///< the Sequoia's SensorModel (steps.sensor_model)
  double irradiance = 1.0;            ///< the light sensor's reading (used when steps.irradiance)
  double radiance_a1 = 0.0;           ///< MicaSense's a1 (reflectance only)
  double gain_adjustment = 0.0;       ///< DJI's SensorGainAdjustment (sun-sensor only)
  double scale = 1.0;  ///< common factor of the band; for reflectance pi a1 / 2^bits
  /// Subtracted after the scale: the offset of the empirical line that calibration panels of
  /// several reflectances give (PanelLine; 0 otherwise)
  double offset = 0.0;
};

/// What a band's values are made to mean.
enum class Calibration {
  relative,              ///< relative radiance: one factor per band, its brightest value 1
  sun_sensor,            ///< reflectance from MicaSense's a1 and the DLS 2 irradiance
  panel,                 ///< reflectance from calibration-panel pictures: one irradiance per band
  panel_and_sun_sensor,  ///< the panel sets the light sensor's level, which follows the light
  /// reflectance up to one factor common to all bands: the light sensor's reading and the band
  /// camera's calibration (DJI's SensorGainAdjustment or MicaSense's a1), one scale for all bands
  sun_sensor_relative,
};

/// What plan_band decided for a band, with the reasons.
struct BandPlan {
  RadiometrySteps steps;
  /// Missing tag -> files lacking it (only for steps left out because of them).
  std::map<std::string, std::vector<std::filesystem::path>> missing;
};

/// Decide which steps a band gets: a step is applied when every image of the band has its tags
/// (black level; exposure time; gain or ISO; vignetting polynomial and centre). Reflectance needs
/// every step (MicaSense's row gradient wherever the camera writes it, always for the light
/// sensor's; a panel's calibration takes a camera that writes no black level at all), MicaSense's
/// a1 and the DLS 2's W/m^2/nm for the light sensor's (the band camera's calibration, a1 or DJI's
/// SensorGainAdjustment, and the reading in any unit for sun_sensor_relative), and the light
/// sensor's reading in every image where it takes part: `missing` then lists what the caller must
/// refuse.
inline BandPlan plan_band(const std::vector<CaptureMeta>& metas, const std::vector<std::filesystem::path>& files,
                          Calibration calibration = Calibration::relative) {
  BandPlan plan;
  auto check = [&](const char* tag, auto&& has) {
    std::vector<std::filesystem::path> lacking;
    for (std::size_t i = 0; i < metas.size(); ++i)
      if (!has(metas[i])) lacking.push_back(i < files.size() ? files[i] : std::filesystem::path());
    if (!lacking.empty()) plan.missing[tag] = std::move(lacking);
    return plan.missing.count(tag) == 0 && !metas.empty();
  };
  // The modes that take the light sensor's reading in any unit (sun_sensor has its own branch).
  const bool sun = calibration == Calibration::panel_and_sun_sensor || calibration == Calibration::sun_sensor_relative;
  const bool panel = calibration == Calibration::panel || calibration == Calibration::panel_and_sun_sensor;
  // The Parrot Sequoia's own model of its sensor, wherever the band's images carry it: every image
  // must then, with the exposure time and ISO it takes. Its B is the black level.
  const auto has_model = [](const CaptureMeta& m) { return m.sensor_model.has_value(); };
  const bool model = std::any_of(metas.begin(), metas.end(), has_model);
  // A camera that writes no black level anywhere (the Parrot Sequoia) has none to subtract, which
  // a panel calibration can live with.
  if (!model &&
      (!panel || std::any_of(metas.begin(), metas.end(), [](const CaptureMeta& m) { return m.black_level.has_value(); })))
    plan.steps.black_level = check("black level", [](const CaptureMeta& m) { return m.black_level.has_value(); });
  plan.steps.exposure = check("exposure time", [](const CaptureMeta& m) { return m.exposure_s.has_value(); });
  plan.steps.gain = check("gain/ISO", [](const CaptureMeta& m) { return m.gain.has_value(); });
  if (model) plan.steps.sensor_model = check("sensor model (Parrot SensorModel)", has_model) && plan.steps.exposure && plan.steps.gain;
  plan.steps.vignetting = check("vignetting polynomial+centre", [](const CaptureMeta& m) { return m.has_vignetting(); });
  // MicaSense's row gradient needs the exposure time. Only MicaSense writes it, so a band none of
  // whose images has it is not missing anything.
  if (calibration == Calibration::sun_sensor ||
      std::any_of(metas.begin(), metas.end(), [](const CaptureMeta& m) { return m.row_gradient.has_value(); }))
    plan.steps.row_gradient =
        check("row gradient (MicaSense RadiometricCalibration)", [](const CaptureMeta& m) { return m.row_gradient.has_value(); }) &&
        plan.steps.exposure;
  if (calibration == Calibration::sun_sensor) {
    check("radiance calibration a1 (MicaSense RadiometricCalibration)",
          [](const CaptureMeta& m) { return m.radiance_a1.has_value(); });
    plan.steps.irradiance = check("horizontal irradiance (MicaSense DLS 2)",
                                  [](const CaptureMeta& m) { return m.irradiance.has_value() && m.irradiance_si; });
    return plan;
  }
  if (calibration == Calibration::sun_sensor_relative) {
    // One kind of band calibration for the whole band: a1 everywhere, or SensorGainAdjustment.
    const bool a1 = !metas.empty() && metas[0].radiance_a1.has_value();
    if (a1)
      check("radiance calibration a1 (MicaSense RadiometricCalibration)",
            [](const CaptureMeta& m) { return m.radiance_a1.has_value(); });
    else
      check("band calibration (DJI SensorGainAdjustment, MicaSense RadiometricCalibration)",
            [](const CaptureMeta& m) { return m.gain_adjustment.has_value() && !m.radiance_a1.has_value(); });
  }
  if (sun)
    plan.steps.irradiance = check("light sensor reading (MicaSense DLS 2 HorizontalIrradiance, DJI Irradiance)",
                                  [](const CaptureMeta& m) { return m.irradiance.has_value(); });
  return plan;
}

/// The normalisation of one image of `width` x `height` pixels under `steps` (scale 1; set it once
/// the band's maximum is known). The size matters only to a 2-D vignetting model.
inline FrameRadiometry frame_radiometry(const CaptureMeta& m, const RadiometrySteps& steps, double dn_max,
                                        int width = 0, int height = 0) {
  FrameRadiometry r;
  r.steps = steps;
  r.dn_max = dn_max;
  r.width = width;
  r.height = height;
  if (steps.black_level) r.black_level = *m.black_level;
  if (steps.exposure) r.exposure_s = *m.exposure_s;
  if (steps.gain) r.gain = *m.gain;
  if (steps.vignetting && m.has_radial_vignetting()) {
    r.vignetting_poly = m.vignetting_poly;
    r.vignetting_cx = (*m.vignetting_centre)[0];
    r.vignetting_cy = (*m.vignetting_centre)[1];
    r.vignetting_kind = m.vignetting_kind;
  } else if (steps.vignetting) {
    r.vignetting_poly2d = m.vignetting_poly2d;
    r.vignetting_exp2d = m.vignetting_exp2d;
  }
  if (steps.row_gradient) {
    r.row_a2 = (*m.row_gradient)[0];
    r.row_a3 = (*m.row_gradient)[1];
  }
  if (steps.irradiance) r.irradiance = *m.irradiance;
  if (steps.sensor_model) {
    r.model_a = (*m.sensor_model)[0];
    r.model_b = (*m.sensor_model)[1];
    r.model_c = (*m.sensor_model)[2];
  }
  if (m.radiance_a1) r.radiance_a1 = *m.radiance_a1;
  if (m.gain_adjustment) r.gain_adjustment = *m.gain_adjustment;
  return r;
}

/// The factor that turns (DN - black level) / sensor_response into reflectance: pi a1 / 2^bits,
/// with 2^bits = dn_max + 1 (65536 for 16-bit files, as MicaSense's library divides).
inline double reflectance_scale(const FrameRadiometry& r) {
  return std::numbers::pi * r.radiance_a1 / (r.dn_max + 1.0);
}

/// The factor that turns (DN - black level) / sensor_response, the light sensor's reading included,
/// into reflectance up to a factor common to every band: pi a1 / 2^bits from MicaSense's a1,
/// SensorGainAdjustment / 2^bits from DJI's (0 without either).
inline double light_sensor_scale(const FrameRadiometry& r) {
  if (r.radiance_a1 > 0) return reflectance_scale(r);
  return r.gain_adjustment > 0 ? r.gain_adjustment / (r.dn_max + 1.0) : 0.0;
}

/// The irradiance (W/m^2/nm) under which a reflectance image `r` was computed, from MicaSense's a1:
/// R = pi a1 (DN - black) / 2^bits / (response x E) = (DN - black) / response x scale (response
/// including the light sensor's reading where that step is on). 0 without a1.
inline double reflectance_irradiance(const FrameRadiometry& r) {
  if (!(r.radiance_a1 > 0) || !(r.scale > 0)) return 0.0;
  return (r.steps.irradiance ? r.irradiance : 1.0) * reflectance_scale(r) / r.scale;
}

/// 1 + k0 r + k1 r^2 + ... (Horner).
inline double vignetting_polynomial(const std::vector<double>& k, double r) {
  double acc = 0.0;
  for (std::size_t i = k.size(); i-- > 0;) acc = (acc + k[i]) * r;
  return 1.0 + acc;
}

/// sum_i c_i u^a_i v^b_i.
inline double vignetting_polynomial_2d(const std::vector<double>& c, const std::vector<std::array<int, 2>>& e,
                                       double u, double v) {
  double acc = 0.0;
  for (std::size_t i = 0; i < c.size() && i < e.size(); ++i) {
    double t = c[i];
    for (int k = 0; k < e[i][0]; ++k) t *= u;
    for (int k = 0; k < e[i][1]; ++k) t *= v;
    acc += t;
  }
  return acc;
}

/// How much darker the sensor records pixel (x, y) (0-based pixel indices, as MicaSense, DJI and
/// Parrot define them) than the centre: DN is proportional to radiance x vignetting_falloff. 1
/// without vignetting. The 2-D model is not normalised to 1 at the centre (the band scale absorbs
/// its level) and needs r.width and r.height.
inline double vignetting_falloff(const FrameRadiometry& r, double x, double y) {
  if (!r.steps.vignetting) return 1.0;
  if (!r.vignetting_poly2d.empty())
    return vignetting_polynomial_2d(r.vignetting_poly2d, r.vignetting_exp2d, x / r.width, y / r.height);
  if (r.vignetting_poly.empty()) return 1.0;
  const double p = vignetting_polynomial(r.vignetting_poly, std::hypot(x - r.vignetting_cx, y - r.vignetting_cy));
  return r.vignetting_kind == VignettingKind::falloff ? p : 1.0 / p;
}

/// How much brighter MicaSense's sensor records row y than row 0: 1 + a2 y / exposure_s - a3 y
/// (1 without that step).
inline double row_gradient_factor(const FrameRadiometry& r, double y) {
  return r.steps.row_gradient ? 1.0 + r.row_a2 * y / r.exposure_s - r.row_a3 * y : 1.0;
}

/// What the camera's exposure settings make of a unit of light: exposure x gain, or with the
/// Sequoia's SensorModel A x exposure x ISO + C (ISO = 100 gain).
inline double exposure_response(const FrameRadiometry& r) {
  return r.steps.sensor_model ? r.model_a * r.exposure_s * (100.0 * r.gain) + r.model_c : r.exposure_s * r.gain;
}

/// What the sensor records at pixel (x, y) per unit of relative radiance (of reflectance, with the
/// irradiance step), above the black level: exposure x gain (exposure_response) x vignetting
/// fall-off x row gradient (x irradiance).
inline double sensor_response(const FrameRadiometry& r, double x, double y) {
  const double s = exposure_response(r) * vignetting_falloff(r, x, y) * row_gradient_factor(r, y);
  return r.steps.irradiance ? s * r.irradiance : s;
}

/// What the sensor records at pixel (x, y) without light: the black level, or the Sequoia's B x its
/// fall-off (Parrot's model subtracts B from DN / fall-off).
inline double dark_level(const FrameRadiometry& r, double x, double y) {
  return r.steps.sensor_model ? r.model_b * vignetting_falloff(r, x, y) : r.black_level;
}

/// Relative radiance of digital number `dn` at pixel (x, y), before the band scale.
inline double relative_radiance(double dn, double x, double y, const FrameRadiometry& r) {
  return (dn - dark_level(r, x, y)) / sensor_response(r, x, y);
}

/// The largest fall-off factor a vignetting model may give the image's farthest pixel (a lens
/// only darkens; 5% above 1 allows for a fitted polynomial's wobble near a weak vignette).
inline constexpr double kMaxEdgeFalloff = 1.05;

/// A lens darkens the image towards its edge. A model that says `where` is recorded brighter than
/// the centre (`edge` times, above kMaxEdgeFalloff) has its convention the wrong way round (a
/// correction read as a fall-off, or the reverse): applying it would double the vignetting
/// instead of removing it. IoError naming `file` then.
inline void check_edge_falloff(double edge, const std::string& model, const std::string& where,
                               const std::filesystem::path& file) {
  if (!(edge > kMaxEdgeFalloff)) return;
  fail(file, cat("the vignetting model (", model, ") makes ", where, " ", short_number(edge, 3),
                 " times as bright as the centre, where a lens darkens it: its convention does not fit this",
                 " camera (msgs reads DJI files' polynomials as corrections, all others as fall-offs);",
                 " skip the metadata with --radiometry none"));
}

/// Check the parameters (finite, positive exposure and gain, a vignetting model that stays
/// positive over the image and does not brighten its edge); IoError naming `file` otherwise.
inline void check_radiometry(const FrameRadiometry& r, int width, int height, const std::filesystem::path& file) {
  if (!(r.dn_max > 0) || !std::isfinite(r.black_level) || !(r.exposure_s > 0) || !(r.gain > 0) ||
      !std::isfinite(r.exposure_s * r.gain) || !(r.scale > 0) || !std::isfinite(r.scale) || !std::isfinite(r.offset))
    fail(file, cat("radiometric parameters out of range (black level ", r.black_level, ", exposure ", r.exposure_s,
                   " s, gain ", r.gain, ", scale ", r.scale, ", offset ", r.offset, ")"));
  if (r.steps.sensor_model && (!(exposure_response(r) > 0) || !std::isfinite(exposure_response(r)) || !std::isfinite(r.model_b)))
    fail(file, cat("the sensor model's A x exposure x ISO + C is ", exposure_response(r), " (A ", r.model_a, ", B ",
                   r.model_b, ", C ", r.model_c, ", exposure ", r.exposure_s, " s, ISO ", 100.0 * r.gain,
                   "; expected > 0; skip the metadata with --radiometry none)"));
  if (r.steps.irradiance && (!(r.irradiance > 0) || !std::isfinite(r.irradiance * exposure_response(r))))
    fail(file, cat("light sensor reading ", r.irradiance, " out of range (expected > 0;",
                   " --radiometry auto gives relative radiance without it)"));
  // The row gradient is linear in y: positive at the first and last row means positive on all.
  for (const double y : {0.0, double(height - 1)}) {
    const double g = row_gradient_factor(r, y);
    if (!(g > 1e-3) || !std::isfinite(g))
      fail(file, cat("the row gradient 1 + a2 y / exposure - a3 y is ", g, " at row ", std::lround(y),
                     " (a2 ", r.row_a2, ", a3 ", r.row_a3, ", exposure ", r.exposure_s,
                     " s; expected > 0; skip the metadata with --radiometry none)"));
  }
  if (r.steps.vignetting && !r.vignetting_poly2d.empty()) {
    if (r.width != width || r.height != height)
      fail(file, cat("the 2-D vignetting model was set up for a ", r.width, "x", r.height, " image, this one is ", width,
                     "x", height));
    // Positive over the image (a 17 x 17 grid), and the corners no brighter than the centre.
    const double centre = vignetting_falloff(r, 0.5 * (width - 1), 0.5 * (height - 1));
    double corner = 0.0;
    for (int j = 0; j <= 16; ++j)
      for (int i = 0; i <= 16; ++i) {
        const double x = (width - 1) * i / 16.0, y = (height - 1) * j / 16.0;
        const double p = vignetting_falloff(r, x, y);
        if (!(p > 1e-3 * centre) || !std::isfinite(p) || !(centre > 0))
          fail(file, cat("the 2-D vignetting polynomial is ", p, " at pixel (", std::lround(x), ", ", std::lround(y),
                         ") and ", centre, " at the centre (expected > 0 over the image;",
                         " skip the metadata with --radiometry none)"));
        if ((i == 0 || i == 16) && (j == 0 || j == 16)) corner = std::max(corner, p / centre);
      }
    check_edge_falloff(corner, "the 2-D fall-off polynomial", "a corner", file);
  } else if (r.steps.vignetting) {
    // The polynomial in r is checked at the centre's nearest and farthest image points and in between.
    const double xs[] = {0.0, double(width - 1)}, ys[] = {0.0, double(height - 1)};
    double rmax = 0.0;
    for (double x : xs)
      for (double y : ys) rmax = std::max(rmax, std::hypot(x - r.vignetting_cx, y - r.vignetting_cy));
    for (int i = 0; i <= 64; ++i) {
      const double rr = rmax * i / 64.0;
      const double p = vignetting_polynomial(r.vignetting_poly, rr);
      if (!(p > 1e-3) || !std::isfinite(p))
        fail(file, cat("vignetting polynomial is ", p, " at ", rr, " px from its centre (expected > 0 over the image;",
                       " skip the metadata with --radiometry none)"));
    }
    check_edge_falloff(vignetting_falloff(r, r.vignetting_cx + rmax, r.vignetting_cy),
                       r.vignetting_kind == VignettingKind::falloff ? "a fall-off polynomial" : "a correction polynomial",
                       cat("the farthest pixel, ", std::lround(rmax), " px from its centre,"), file);
  }
}

/// Normalise an image read as [0, 1] (stored value x dn_max = DN), single channel or not: every
/// channel gets the same correction, the offset subtracted last. Negative results (noise below the
/// black level, a surface darker than the empirical line's offset) become 0;
/// values are not clamped above, so the caller can find the band's maximum with scale = 1.
inline Image<float> normalise_image(const Image<float>& raw, const FrameRadiometry& r, const std::filesystem::path& file) {
  check_radiometry(r, raw.width, raw.height, file);
  Image<float> out(raw.width, raw.height, raw.channels);
  for (int y = 0; y < raw.height; ++y)
    for (int x = 0; x < raw.width; ++x) {
      const double k = r.scale / sensor_response(r, x, y), dark = dark_level(r, x, y);
      for (int c = 0; c < raw.channels; ++c) {
        const double dn = double(raw.at(x, y, c)) * r.dn_max;
        out.at(x, y, c) = float(std::max(0.0, (dn - dark) * k - r.offset));
      }
    }
  return out;
}

/// Largest value of an image (0 for an empty one).
inline float max_value(const Image<float>& img) {
  float m = 0.0f;
  for (float v : img.data) m = std::max(m, v);
  return m;
}

/// The band scale: 1 / the largest relative radiance over all images of the band (1 when that is 0).
inline double band_scale(double max_relative_radiance) {
  return max_relative_radiance > 0 && std::isfinite(max_relative_radiance) ? 1.0 / max_relative_radiance : 1.0;
}

}  // namespace msgs::io
