// include/msgs/synth/raw.hpp
// The synthetic scene as a folder of raw multi-band captures, the way a real multispectral camera
// writes them (offline test data for `msgs import`): the camera's file names, 16-bit TIFFs whose
// digital numbers carry per-capture exposure differences, vignetting and a black level,
//
//   DN = black_level + radiance * exposure_s * gain * falloff(r) * sensitivity * light, clamped to 0..65535,
//
// and the metadata that real camera writes, as an XMP packet in TIFF tag 700 (readable by exiv2).
//
//   micasense  IMG_0001_1.tif .. IMG_0001_5.tif (1 Blue, 2 Green, 3 Red, 4 NIR, 5 RedEdge); no RGB
//              camera. XMP: Camera:BandName, Camera:CentralWavelength, Camera:WavelengthFWHM,
//              Camera:VignettingCenter, Camera:VignettingPolynomial (fall-off 1 + k0 r + ... in
//              pixels), Camera:BlackLevel, MicaSense:RadiometricCalibration (a1, a2, a3: the sensor
//              records row y brighter by 1 + a2 y / exposure - a3 y; a real RedEdge's values,
//              scaled to the image height; a1 such that pi x radiance / irradiance gives back the
//              scene's values), Camera:HorizontalIrradiance + Camera:IrradianceScaleToSIUnits (a
//              DLS 2's reading of the capture's sunlight, see RawOptions::light_variation,
//              dls_bias and heading_bias) and the sensor's attitude (DLS:Yaw/Pitch/Roll, radians,
//              raw_attitude); with RawOptions::dls1 a DLS 1's tilted reading and attitude instead,
//              DLS:SpectralIrradiance, with Camera:Irradiance and
//              Camera:IrradianceYaw/Pitch/Roll in degrees as the real camera repeats them),
//              exif:ExposureTime, exif:ISOSpeedRatings, exif:FocalLength, exif:DateTimeOriginal,
//              exif:FocalPlaneXResolution/YResolution/ResolutionUnit (4 = mm), and the band
//              camera's calibration: Camera:PerspectiveFocalLength (pixels) and Camera:PrincipalPoint
//              (mm on the focal plane), its true focal length and principal point. Real MicaSense files
//              keep exposure, ISO, focal length and black level in EXIF IFDs instead; the importer
//              reads both places.
//   dji        DJI_<datetime>_0001_MS_G.TIF, _MS_R, _MS_RE, _MS_NIR, and _D.JPG (8-bit sRGB), as a
//              Mavic 3M names them. XMP: Camera:BandName, Camera:CentralWavelength,
//              Camera:BlackCurrent (the Mavic 3M's black level), drone-dji:ExposureTime
//              (microseconds), drone-dji:SensorGain,
//              drone-dji:VignettingData (a correction polynomial that multiplies the image),
//              drone-dji:CalibratedOpticalCenterX/Y, the same correction again as
//              Camera:VignettingPolynomial + Camera:VignettingCenter, exif:ExposureTime,
//              exif:FocalLength, exif:FocalPlane*, and the sunlight sensor as DJI's guides use it:
//              drone-dji:SensorGainAdjustment (dji_gain_adjustment) and drone-dji:Irradiance, such
//              that (DN - black) / 2^16 / (exposure gain) x vignetting correction x
//              SensorGainAdjustment / Irradiance is kDjiReflectanceFactor x the scene's values in
//              every band; drone-dji:FlightYawDegree/PitchDegree/RollDegree the drone's attitude.
//   p4m        DJI_0010.JPG (RGB), DJI_0011.TIF (blue) .. DJI_0015.TIF (NIR), DJI_0020.JPG .., as a
//              P4 Multispectral numbers them; its tags as the Mavic 3M's, but the black level as
//              drone-dji:BlackLevel (4096).
//   sequoia    IMG_<yymmdd>_<hhmmss>_0001_GRE.TIF, _RED, _REG, _NIR, and _RGB.JPG. Like the real
//              camera: no black level tag, and the vignetting as a 2-D fall-off
//              polynomial in x / width and y / height (Camera:VignettingPolynomial2D, its exponents
//              in Camera:VignettingPolynomial2DName); exposure, ISO, wavelengths and focal data as
//              for MicaSense; the sunshine sensor's readings of the band since the previous capture
//              and its gains' calibration, Camera:IrradianceList and
//              Camera:IrradianceCalibrationMeasurement (sequoia_sunshine_list), and the sensor's
//              model Camera:SensorModel, which the DN follow (sequoia_sensor_model).
//   All three carry the capture's position (the RGB mount's centre as metres east, north and up
//   of 51.98 N, 5.66 E, 20 m): DJI as drone-dji:GpsLatitude/GpsLongitude/AbsoluteAltitude, the
//   others as exif:GPSLatitude/GPSLongitude ("DD,MM.mmmmmmK") and exif:GPSAltitude.
//
// Exposure time and ISO vary per capture and band (an auto-exposing camera), seeded: the same
// seed gives the same bytes.
//
// A set can end with captures of a calibration panel (RawOptions::panel_captures), and begin with
// one (RawOptions::panel_before), as a camera
// takes them on the ground: a grey panel of reflectance raw_panel_albedo() on a darker background,
// seen a little off-centre and turned. MicaSense files mark them as the camera does
// (Camera:CalibrationPicture 2, Camera:Albedo, Camera:ReflectArea: the corners of the panel's inner
// area, whole pixels, and Camera:PanelSerial); for the other cameras, which do not, the set holds
// panels.json, the list `msgs import --panels` reads (msgs/io/panel_list.hpp) with the same areas.
// With RawOptions::dark_panel every second panel capture after the flight shows a dark panel
// (raw_dark_panel_albedo()), and RawOptions::path_reflectance adds haze: light in proportion to
// the sunlight, as if every surface reflected that much more (the offset of an empirical line).
#pragma once

#include <nlohmann/json.hpp>
#include <stb/stb_image_write.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "../io/calibration_panel.hpp"
#include "../io/capture_meta.hpp"
#include "../io/error.hpp"
#include "../io/file.hpp"
#include "../io/image_io.hpp"
#include "../io/light_sensor_tilt.hpp"
#include "../io/match_pairs.hpp"
#include "../io/radiometry.hpp"
#include "../io/sun_position.hpp"
#include "dataset.hpp"
#include "render.hpp"
#include "scene.hpp"

namespace msgs::synth {

/// What to generate.
struct RawOptions {
  std::string camera = "micasense";  ///< micasense | dji | p4m | sequoia
  std::string preset = "tiny";       ///< scene, flight and image sizes (see synth_presets)
  std::uint64_t seed = 1;
  int captures = 0;   ///< number of captures (0: the preset's)
  int width = 0;      ///< multispectral image width (0: the preset's); height 3/4 of it, RGB 1.5x
  /// The sunlight of each capture is 1 +- this (uniform, the same for every band of a capture),
  /// as under passing clouds; 0 keeps it steady. The light sensors of MicaSense, DJI and the
  /// Sequoia record it.
  double light_variation = 0.0;
  /// The light sensor reads (1 + this) x the sunlight (a calibration or mounting error, which a
  /// calibration panel takes out); -0.5 .. 1.
  double dls_bias = 0.0;
  /// Captures of a calibration panel after the flight's.
  int panel_captures = 0;
  /// One more capture of the panel before the flight (numbered 0, 2 s before the first).
  bool panel_before = false;
  /// The sunlight grows linearly in time by this fraction from the first capture written to the
  /// last (the sun climbing); -0.5 .. 1, 0 keeps it level.
  double light_drift = 0.0;
  /// MicaSense only: a RedEdge-M's first light sensor, which records its tilted reading and its
  /// attitude instead of HorizontalIrradiance (see dls1_reading).
  bool dls1 = false;
  /// In flight the light sensor (MicaSense, DJI) reads (1 + this cos(heading - 20 degrees)) x what it
  /// would read level: a sensor whose tilt its firmware leaves partly in, so that readings on the
  /// flight lines of raw_attitude differ by (1 + this) / (1 - this); -0.5 .. 0.5.
  double heading_bias = 0.0;
  /// Every second panel capture after the flight shows a dark panel (raw_dark_panel_albedo).
  bool dark_panel = false;
  /// Haze between the camera and the ground: every band sees this much more reflectance, in
  /// every capture (the panels' too); 0 .. 0.2.
  double path_reflectance = 0.0;
  bool overwrite = false;
};

/// What was generated.
struct RawSummary {
  std::filesystem::path out;
  std::string camera;
  int captures = 0;
  int panel_captures = 0;
  int files = 0;
  int ms_width = 0, ms_height = 0, rgb_width = 0, rgb_height = 0;
  double min_exposure_s = 0, max_exposure_s = 0;
  int min_iso = 0, max_iso = 0;
  double seconds = 0;
};

/// One band of a raw camera.
struct RawBand {
  const char* name_part;   ///< file-name part ("1", "MS_G", "GRE")
  const char* band_name;   ///< Camera:BandName
  double wavelength_nm, fwhm_nm;
  int spectrum_channel;    ///< Spectrum index rendered (0..2 linear RGB, 3..6 the narrow bands)
  Band mount;              ///< whose rig position and boresight the lens takes
  bool rgb;                ///< the 8-bit RGB JPEG camera
  double sensitivity;      ///< DN per unit radiance x second x gain
};

/// The bands of a raw camera, in file order.
inline std::vector<RawBand> raw_bands(std::string_view camera) {
  if (camera == "micasense")
    return {{"1", "Blue", 475, 32, 2, Band::D, false, 1.10e7},
            {"2", "Green", 560, 27, 3, Band::MS_G, false, 1.00e7},
            {"3", "Red", 668, 14, 4, Band::MS_R, false, 1.20e7},
            {"4", "NIR", 840, 57, 6, Band::MS_NIR, false, 0.80e7},
            {"5", "RedEdge", 717, 12, 5, Band::MS_RE, false, 0.95e7}};
  if (camera == "dji")
    return {{"D", "RGB", 0, 0, 0, Band::D, true, 0},
            {"MS_G", "Green", 560, 16, 3, Band::MS_G, false, 1.00e7},
            {"MS_R", "Red", 650, 16, 4, Band::MS_R, false, 1.15e7},
            {"MS_RE", "RedEdge", 730, 16, 5, Band::MS_RE, false, 0.90e7},
            {"MS_NIR", "NIR", 860, 26, 6, Band::MS_NIR, false, 0.80e7}};
  if (camera == "p4m")
    return {{"0", "RGB", 0, 0, 0, Band::D, true, 0},
            {"1", "Blue", 450, 16, 2, Band::D, false, 1.10e7},
            {"2", "Green", 560, 16, 3, Band::MS_G, false, 1.00e7},
            {"3", "Red", 650, 16, 4, Band::MS_R, false, 1.15e7},
            {"4", "RedEdge", 730, 16, 5, Band::MS_RE, false, 0.90e7},
            {"5", "NIR", 840, 26, 6, Band::MS_NIR, false, 0.80e7}};
  if (camera == "sequoia")
    return {{"GRE", "Green", 550, 40, 3, Band::MS_G, false, 1.00e7},
            {"RED", "Red", 660, 40, 4, Band::MS_R, false, 1.10e7},
            {"REG", "Red edge", 735, 10, 5, Band::MS_RE, false, 0.90e7},
            {"NIR", "NIR", 790, 40, 6, Band::MS_NIR, false, 0.85e7},
            {"RGB", "RGB", 0, 0, 0, Band::D, true, 0}};
  throw std::invalid_argument("unknown raw camera '" + std::string(camera) + "' (expected micasense, dji, p4m or sequoia)");
}

/// When capture `capture` (0-based; -1 the panel capture before the flight, `flight_captures` and
/// later the panel captures after it) was taken, in seconds after midnight: the flight from
/// 10:00:00, one capture every 2 s; the panel on the ground 5 minutes before take-off and a
/// minute after landing.
inline int raw_capture_seconds(int capture, int flight_captures) {
  const int flight = 10 * 3600 + 2 * capture;
  return capture < 0 ? flight - 300 : capture >= flight_captures ? flight + 60 : flight;
}

/// The drone's attitude, which its light sensor shares (radians, north-east-down;
/// msgs/io/light_sensor_tilt.hpp).
struct RawAttitude {
  double yaw = 0, pitch = 0, roll = 0;
};

/// The attitude at capture `capture`: on flight lines that turn back at every capture (headings
/// 20 and 200 degrees), pitched 8 degrees forward, rolled a little; level on the ground for a
/// panel capture.
inline RawAttitude raw_attitude(int capture, bool panel) {
  constexpr double deg = std::numbers::pi / 180.0;
  if (panel) return {60.0 * deg, 0.0, 0.0};
  return {(capture % 2 == 0 ? 20.0 : 200.0) * deg, -8.0 * deg, (capture % 3 - 1) * 2.0 * deg};
}

/// What a DLS 1 with attitude `a` reads under a clear sky that gives `level` irradiance on level
/// ground, at `seconds` after midnight UTC of 2024-06-01 above `position` (metres east, north, up
/// of the scene's origin, as add_gps places it): the direct part D and the scattered D / 6 that
/// make `level` with the sun's elevation, through the diffuser at the sun's angle to the sensor.
inline double dls1_reading(double level, const RawAttitude& a, int seconds, const Vec3f& position) {
  const auto [lat, lon, alt] = io::local_to_gps({double(position.x()), double(position.y()), 20.0}, 51.98, 5.66);
  (void)alt;
  const double t = *io::parse_date_time("2024:06:01 00:00:00") + seconds;
  const io::SunPosition sun = io::sun_position(t, lat, lon);
  const double scattered = 1.0 / io::kDirectToScattered;
  const double direct = level / (std::sin(sun.elevation) + scattered);
  const double theta = io::sun_sensor_angle(sun, a.yaw, a.pitch, a.roll);
  return io::diffuser_transmission(theta) * direct * (std::cos(theta) + scattered);
}

/// File name of band `b` of capture `capture` (0-based; -1 the panel capture before the flight,
/// numbered 0) of a set of `flight_captures` flight captures, as `camera` names it.
inline std::string raw_file_name(std::string_view camera, const RawBand& b, int capture, int flight_captures = 1 << 20) {
  char buf[96];
  const int n = capture + 1;
  const int secs = raw_capture_seconds(capture, flight_captures);
  const int hh = secs / 3600, mm = secs / 60 % 60, ss = secs % 60;
  if (camera == "micasense") std::snprintf(buf, sizeof buf, "IMG_%04d_%s.tif", n, b.name_part);
  else if (camera == "dji")
    std::snprintf(buf, sizeof buf, "DJI_20240601%02d%02d%02d_%04d_%s.%s", hh, mm, ss, n, b.name_part, b.rgb ? "JPG" : "TIF");
  else if (camera == "p4m") std::snprintf(buf, sizeof buf, "DJI_%03d%s.%s", n % 1000, b.name_part, b.rgb ? "JPG" : "TIF");
  else std::snprintf(buf, sizeof buf, "IMG_240601_%02d%02d%02d_%04d_%s.%s", hh, mm, ss, n, b.name_part, b.rgb ? "JPG" : "TIF");
  return buf;
}

/// Exposure of one image.
struct RawExposure {
  double exposure_s;
  int iso;
  double gain() const { return iso / 100.0; }
};

/// Auto-exposure of band `band` in capture `capture`: 1/2000 .. 1/500 s, ISO 100 / 200 / 400 (400 rare).
inline RawExposure raw_exposure(std::uint64_t seed, int capture, int band) {
  Rng rng(hash_tuple(seed, 0xE7905EULL, capture, band));
  RawExposure e;
  e.exposure_s = 0.0005 * std::pow(4.0, rng.uniform());
  const double u = rng.uniform();
  e.iso = u < 0.55 ? 100 : u < 0.9 ? 200 : 400;
  e.exposure_s = std::round(1.0 / e.exposure_s) > 0 ? 1.0 / std::round(1.0 / e.exposure_s) : e.exposure_s;  // 1/N s
  return e;
}

/// Sunlight on a level surface at wavelength `nm` under the steady sky of the raw sets (W/m^2/nm,
/// roughly the solar spectrum at the ground from green to near infra-red).
inline double raw_irradiance(double nm) { return 1.45 - 0.0006 * (nm - 475.0); }

/// The reflectance of the synthetic calibration panel at wavelength `nm` (MicaSense's panels are
/// about 0.49 to 0.53 from blue to near infra-red).
inline double raw_panel_albedo(double nm) { return 0.49 + 0.04 * (nm - 475.0) / 400.0; }

/// The reflectance of the dark panel of RawOptions::dark_panel at wavelength `nm` (a dark grey
/// tarp, about 0.09 to 0.11).
inline double raw_dark_panel_albedo(double nm) { return 0.09 + 0.02 * (nm - 475.0) / 400.0; }

/// Does `camera` write DJI's tags (drone-dji namespace, a vignetting correction)?
inline bool dji_camera(std::string_view camera) { return camera == "dji" || camera == "p4m"; }

/// DJI's SensorGainAdjustment of a synthetic band: a few percent apart, as real files carry them.
inline double dji_gain_adjustment(const RawBand& b) {
  const std::string_view n = b.band_name;
  return n == "Blue" ? 0.991 : n == "Red" ? 0.985 : n == "RedEdge" ? 1.033 : n == "NIR" ? 1.005 : 1.0;
}

/// What DJI's reflectance formula gives for a surface of reflectance 1 in the synthetic DJI sets
/// (the unknown factor common to all bands in DJI's guides).
inline constexpr double kDjiReflectanceFactor = 0.01;

/// The SensorModel A, B, C of band `b` of the raw sets' Parrot Sequoia: DN / fall-off - B =
/// (A exposure ISO + C) x radiance, with A exposure ISO = exposure x ISO / 100 x the band's
/// sensitivity (as the other cameras' DN), a dark level B of 200 and C = 2e-5 x the sensitivity:
/// 0.25-4% of the response at the flight's exposures, more at the panel's.
inline std::array<double, 3> sequoia_sensor_model(const RawBand& b) {
  return {b.sensitivity / 100.0, 200.0, 2e-5 * b.sensitivity};
}

/// The gains of the raw sets' Parrot Sequoia sunshine sensor at gain index 0 .. 3 (a real unit's
/// ratios, rounded), and its counts per millisecond at gain 1 under the factory calibration's light.
inline constexpr double kSequoiaSunshineGain[4] = {1.0, 24.8, 410.0, 6600.0};
inline constexpr double kSequoiaSunshineCalibrationRate = 0.055;

/// Xmp.Camera.IrradianceCalibrationMeasurement of the raw sets' Sequoia: every gain index for
/// 600 ms under the calibration's light, the highest saturated, as a real unit's.
inline std::string sequoia_sunshine_calibration() {
  std::string s;
  for (int g = 0; g < 4; ++g) {
    const double ch0 = std::min(65535.0, std::round(kSequoiaSunshineCalibrationRate * kSequoiaSunshineGain[g] * 600.0));
    const double ch1 = std::min(65535.0, std::round(0.5 * kSequoiaSunshineCalibrationRate * kSequoiaSunshineGain[g] * 600.0));
    s += io::cat(g ? "," : "", g, ",600,", ch0, ",", ch1);
  }
  return s;
}

/// The raw sets' Sequoia sunshine sensor's reading of band `b` (file order `band_index`) under the
/// sunlight `light` (relative to the steady sky, the sensor's own error included) relative to the
/// calibration's light: (CH0 / t) / (CH0_cal / t_cal) of msgs/io/sunshine_sensor.hpp.
inline double sequoia_sunshine_reading(const RawBand& b, double light) {
  return 0.5 * b.sensitivity / 1e7 * light / kSequoiaSunshineCalibrationRate;
}

/// Xmp.Camera.IrradianceList of band `b` of a capture at `seconds` after midnight: ten readings at
/// 5 Hz up to the capture, alternately at gain index 1 for 100 ms and gain index 2 for 20 ms. The
/// first four (more than a second before the capture) read the previous capture's light
/// `previous`, the last six this capture's `light`, so that a reader that averages the whole list
/// is off where one that takes the last second is not. The last band's next-to-last reading is
/// saturated (65535), as a glint would leave it.
inline std::string sequoia_sunshine_list(const RawBand& b, int band_index, int seconds, double light, double previous,
                                         const RawAttitude& att) {
  std::vector<io::SunshineReading> list;
  for (int j = 0; j < 10; ++j) {
    io::SunshineReading r;
    r.time_us = std::uint64_t(seconds - 9 * 3600) * 1000000u - std::uint64_t(9 - j) * 200000u;
    r.gain_index = std::uint16_t(j % 2 ? 2 : 1);
    r.integration_ms = std::uint16_t(j % 2 ? 20 : 100);
    const double rate = 0.5 * b.sensitivity / 1e7 * (j < 4 ? previous : light);  // counts per ms at gain 1
    const double ch0 = std::round(rate * kSequoiaSunshineGain[r.gain_index] * r.integration_ms);
    r.ch0 = std::uint16_t(std::clamp(ch0, 1.0, 65534.0));
    r.ch1 = std::uint16_t(std::clamp(std::round(0.5 * ch0), 1.0, 65534.0));
    if (band_index == 3 && j == 8) r.ch0 = 65535;
    constexpr double deg = 180.0 / std::numbers::pi;
    r.yaw = float(att.yaw * deg);
    r.pitch = float(att.pitch * deg);
    r.roll = float(att.roll * deg);
    list.push_back(r);
  }
  return io::sunshine_list_base64(list);
}

/// The sunlight of capture `capture` relative to the steady sky: 1 + variation x U(-1, 1).
inline double raw_light(std::uint64_t seed, int capture, double variation) {
  if (variation == 0.0) return 1.0;
  Rng rng(hash_tuple(seed, 0x5A71C7ULL, capture));
  return 1.0 + variation * (2.0 * rng.uniform() - 1.0);
}

namespace detail {

/// Linear radiance of one Spectrum channel, traced like render_band (same jitter), not clamped.
inline Image<float> render_radiance(const SynthScene& s, const Camera<float>& cam, int channel, const RenderSettings& rs) {
  cam.validate();
  Image<float> img(cam.width, cam.height, 1);
#pragma omp parallel for schedule(dynamic, 1)
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) img.at(x, y, 0) = pixel_spectrum(s, cam, x, y, rs)[static_cast<std::size_t>(channel)];
  return img;
}

/// A panel picture's corners: a square of side `side` x height centred `dx`, `dy` off the image
/// centre (in units of the height), turned by 12 degrees; corners in the camera's order.
inline io::PanelArea panel_square(int width, int height, double side, double dx, double dy) {
  const double c = std::cos(0.2094395102393195), sn = std::sin(0.2094395102393195), h = 0.5 * side * height;
  const double cx = 0.5 * width + dx * height, cy = 0.5 * height + dy * height;
  io::PanelArea q{};
  const double u[4] = {1, -1, -1, 1}, v[4] = {-1, -1, 1, 1};  // upper right, upper left, lower left, lower right
  for (int i = 0; i < 4; ++i) q[i] = {cx + h * (u[i] * c - v[i] * sn), cy + h * (u[i] * sn + v[i] * c)};
  return q;
}

/// The reflecting area a camera (or a user) marks in a panel picture: the inner square of side 0.22
/// x height of the panel of side 0.36 x height, corners at whole pixels.
inline std::array<std::array<long, 2>, 4> panel_area(int width, int height, double dx, double dy) {
  std::array<std::array<long, 2>, 4> a{};
  const io::PanelArea q = panel_square(width, height, 0.22, dx, dy);
  for (std::size_t i = 0; i < 4; ++i) a[i] = {std::lround(q[i][0]), std::lround(q[i][1])};
  return a;
}

/// The scene's values of a panel picture: `albedo` inside the panel square `q`, a darker
/// background outside (0.08 at the top to 0.12 at the bottom).
inline Image<float> panel_radiance(int width, int height, const io::PanelArea& q, double albedo) {
  Image<float> img(width, height, 1);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      img.at(x, y, 0) = float(io::inside_quad(q, x, y) ? albedo : 0.08 + 0.04 * y / std::max(1, height - 1));
  return img;
}

inline std::string g10(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

inline std::string rdf_seq(const std::vector<double>& v) {
  std::string s = "<rdf:Seq>";
  for (double x : v) s += "<rdf:li>" + g10(x) + "</rdf:li>";
  return s + "</rdf:Seq>";
}

/// The camera position `p` (metres east, north, up of the scene's origin) as GPS tags in the
/// camera's style: DJI's decimal degrees and absolute altitude, otherwise XMP exif "DD,MM.mmmmmmK"
/// with the altitude as a rational. The origin is placed at 51.98 N, 5.66 E, 20 m above sea level.
inline void add_gps(const std::string& camera, const Vec3f& p, std::vector<std::pair<std::string, std::string>>& attrs) {
  const auto [lat, lon, alt] = io::local_to_gps({double(p.x()), double(p.y()), 20.0 + double(p.z())}, 51.98, 5.66);
  if (dji_camera(camera)) {
    attrs.emplace_back("drone-dji:GpsLatitude", g10(lat));
    attrs.emplace_back("drone-dji:GpsLongitude", g10(lon));
    attrs.emplace_back("drone-dji:AbsoluteAltitude", g10(alt));
    return;
  }
  const auto dm = [](double deg, char pos, char neg) {
    const double a = std::abs(deg), d = std::floor(a);
    char buf[48];
    std::snprintf(buf, sizeof buf, "%d,%.6f%c", int(d), (a - d) * 60.0, deg < 0 ? neg : pos);
    return std::string(buf);
  };
  attrs.emplace_back("exif:GPSLatitude", dm(lat, 'N', 'S'));
  attrs.emplace_back("exif:GPSLongitude", dm(lon, 'E', 'W'));
  attrs.emplace_back("exif:GPSAltitude", io::cat(std::lround(std::abs(alt) * 1000.0), "/1000"));
  attrs.emplace_back("exif:GPSAltitudeRef", alt < 0 ? "1" : "0");
}

/// XMP packet: simple properties as attributes, sequences as elements.
inline std::string xmp_packet(const std::vector<std::pair<std::string, std::string>>& attrs,
                              const std::vector<std::pair<std::string, std::string>>& elems) {
  std::string s =
      "<?xpacket begin=\"\xEF\xBB\xBF\" id=\"W5M0MpCehiHzreSzNTczkc9d\"?>\n"
      "<x:xmpmeta xmlns:x=\"adobe:ns:meta/\">\n"
      " <rdf:RDF xmlns:rdf=\"http://www.w3.org/1999/02/22-rdf-syntax-ns#\">\n"
      "  <rdf:Description rdf:about=\"\"\n"
      "    xmlns:Camera=\"http://pix4d.com/camera/1.0/\"\n"
      "    xmlns:exif=\"http://ns.adobe.com/exif/1.0/\"\n"
      "    xmlns:tiff=\"http://ns.adobe.com/tiff/1.0/\"\n"
      "    xmlns:drone-dji=\"http://www.dji.com/drone-dji/1.0/\"\n"
      "    xmlns:MicaSense=\"http://micasense.com/MicaSense/1.0/\"\n"
      "    xmlns:DLS=\"http://micasense.com/DLS/1.0/\"";
  for (const auto& [k, v] : attrs) s += "\n    " + k + "=\"" + v + "\"";
  s += ">\n";
  for (const auto& [k, v] : elems) s += "   <" + k + ">" + v + "</" + k + ">\n";
  s += "  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>\n<?xpacket end=\"w\"?>";
  return s;
}

/// 16-bit greyscale TIFF of digital numbers with an XMP packet (tag 700). Atomic.
inline void write_raw_tiff(const std::filesystem::path& p, int w, int h, const std::vector<std::uint16_t>& dn,
                           const std::string& xmp) {
  io::AtomicFile out(p);
  {
    io::detail::TiffFile tf(out.temp(), "w");
    TIFF* tif = tf.get();
    if (!tif) io::fail(p, io::cat("cannot open for writing: ", tf.error()));
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, std::uint32_t(w));
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, std::uint32_t(h));
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, std::uint16_t(16));
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, std::uint16_t(1));
    TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, std::uint16_t(SAMPLEFORMAT_UINT));
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, std::uint16_t(PLANARCONFIG_CONTIG));
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, std::uint16_t(PHOTOMETRIC_MINISBLACK));
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, std::uint32_t(h));
    TIFFSetField(tif, TIFFTAG_XMLPACKET, std::uint32_t(xmp.size()), xmp.data());
    std::vector<std::uint16_t> line(static_cast<std::size_t>(w));
    for (int y = 0; y < h; ++y) {
      std::copy(dn.begin() + std::ptrdiff_t(y) * w, dn.begin() + std::ptrdiff_t(y + 1) * w, line.begin());
      if (TIFFWriteScanline(tif, line.data(), std::uint32_t(y), 0) < 0) io::fail(p, io::cat("cannot write TIFF row: ", tf.error()));
    }
    if (!tf.close()) io::fail(p, io::cat("cannot finish TIFF: ", tf.error()));
  }
  out.commit();
}

/// 8-bit sRGB JPEG (quality 95) with the XMP packet in an APP1 segment right after SOI. Atomic.
inline void write_rgb_jpeg(const std::filesystem::path& p, const Image<float>& srgb, const std::string& xmp) {
  std::vector<unsigned char> px(srgb.data.size());
  for (std::size_t i = 0; i < px.size(); ++i)
    px[i] = static_cast<unsigned char>(std::lround(std::clamp(srgb.data[i], 0.f, 1.f) * 255.f));
  std::vector<unsigned char> jpg;
  if (!stbi_write_jpg_to_func(io::detail::append_jpeg_bytes, &jpg, srgb.width, srgb.height, 3, px.data(), 95) || jpg.size() < 4)
    io::fail(p, "JPEG encoding failed");
  static constexpr char ns[] = "http://ns.adobe.com/xap/1.0/";  // with its terminating NUL
  const std::size_t len = 2 + sizeof ns + xmp.size();
  if (len > 65535) io::fail(p, "XMP packet too large for one APP1 segment");
  std::vector<unsigned char> app1 = {0xFF, 0xE1, static_cast<unsigned char>(len >> 8), static_cast<unsigned char>(len & 0xFF)};
  app1.insert(app1.end(), ns, ns + sizeof ns);
  app1.insert(app1.end(), xmp.begin(), xmp.end());
  jpg.insert(jpg.begin() + 2, app1.begin(), app1.end());
  io::write_bytes_atomic(p, jpg.data(), jpg.size());
}

}  // namespace detail

/// Render the scene of `opt.preset` / `opt.seed` as raw captures of `opt.camera` into `out`
/// (written into a hidden sibling first, renamed into place at the end; an existing `out` is an
/// error unless `opt.overwrite`). Throws std::invalid_argument for a bad camera, preset or size,
/// io::IoError for I/O errors.
inline RawSummary write_synthetic_raw(const std::filesystem::path& out_arg, const RawOptions& opt) {
  namespace fs = std::filesystem;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<RawBand> bands = raw_bands(opt.camera);
  SynthPreset preset = synth_preset(opt.preset);
  if (opt.captures < 0 || opt.captures > 100000) throw std::invalid_argument("captures must be 0 (preset) .. 100000");
  if (opt.width != 0 && (opt.width < 16 || opt.width > 8192)) throw std::invalid_argument("width must be 0 (preset) or 16 .. 8192");
  if (!(opt.light_variation >= 0.0 && opt.light_variation <= 0.9))
    throw std::invalid_argument("the light variation must be 0 .. 0.9");
  if (!(opt.dls_bias >= -0.5 && opt.dls_bias <= 1.0)) throw std::invalid_argument("the light sensor's bias must be -0.5 .. 1");
  if (opt.panel_captures < 0 || opt.panel_captures > 100) throw std::invalid_argument("panel captures must be 0 .. 100");
  if (!(opt.light_drift >= -0.5 && opt.light_drift <= 1.0)) throw std::invalid_argument("the light drift must be -0.5 .. 1");
  if (opt.dls1 && opt.camera != "micasense") throw std::invalid_argument("a DLS 1 comes with MicaSense cameras only");
  if (!(opt.heading_bias >= -0.5 && opt.heading_bias <= 0.5))
    throw std::invalid_argument("the light sensor's heading bias must be -0.5 .. 0.5");
  if (opt.heading_bias != 0.0 && opt.camera != "micasense" && !dji_camera(opt.camera))
    throw std::invalid_argument("a heading bias needs a camera with a light sensor (micasense, dji, p4m)");
  if (opt.dark_panel && opt.panel_captures < 2)
    throw std::invalid_argument("a dark panel needs 2 panel captures or more (every second one shows it)");
  if (!(opt.path_reflectance >= 0.0 && opt.path_reflectance <= 0.2))
    throw std::invalid_argument("the path reflectance must be 0 .. 0.2");
  if (opt.captures > 0) preset.captures = opt.captures;
  if (opt.width > 0) {
    preset.ms_width = opt.width;
    preset.ms_height = opt.width * 3 / 4;
    preset.rgb_width = opt.width * 3 / 2;
    preset.rgb_height = preset.ms_height * 3 / 2;
  }
  fs::path out = fs::absolute(out_arg).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();
  std::error_code ec;
  if (fs::exists(out, ec) && !opt.overwrite)
    io::fail(out, "output directory already exists (choose another one, or overwrite: --force)");
  io::StagedDirectory stage(out, ".raw-tmp-");
  const fs::path& tmp = stage.dir();

  const SynthScene scene = make_scene(preset, opt.seed);
  RawSummary sum;
  sum.out = out;
  sum.camera = opt.camera;
  sum.captures = int(scene.captures.size());
  sum.ms_width = preset.ms_width;
  sum.ms_height = preset.ms_height;
  sum.rgb_width = preset.rgb_width;
  sum.rgb_height = preset.rgb_height;
  sum.min_exposure_s = 1e9;
  sum.min_iso = 1 << 30;
  sum.panel_captures = opt.panel_captures + (opt.panel_before ? 1 : 0);
  const bool black = opt.camera != "sequoia", sequoia = opt.camera == "sequoia", micasense = opt.camera == "micasense";
  // MicaSense's row gradient: a RedEdge's a2 and a3 (for its 960 rows), scaled to this height so
  // that the last row gains what the camera's does (6-26% at these exposures).
  const double row_a2 = 1.39479e-07 * 960.0 / preset.ms_height, row_a3 = 1.17145e-05 * 960.0 / preset.ms_height;
  // Sequoia's 2-D fall-off 1 - 0.6 ((u - 1/2)^2 + (v - 1/2)^2) in u = x / width, v = y / height
  // (0.7 in the corners), written out as the camera writes it: coefficients and exponent pairs.
  const std::vector<double> c2d = {0.7, 0.6, 0.6, -0.6, -0.6};
  const std::vector<std::array<int, 2>> e2d = {{0, 0}, {1, 0}, {0, 1}, {2, 0}, {0, 2}};
  const bool dji = dji_camera(opt.camera);
  const double black_level = opt.camera == "dji" ? 3200.0 : opt.camera == "p4m" ? 4096.0 : 4800.0;
  nlohmann::ordered_json panel_list = nlohmann::ordered_json::array();  // panels.json's pictures
  const int first = opt.panel_before ? -1 : 0, last = sum.captures + opt.panel_captures - 1;
  for (int ci = first; ci <= last; ++ci) {
    const bool panel = ci < 0 || ci >= sum.captures;  // a calibration panel's capture, on the ground by the first
    const Capture& cap = scene.captures[static_cast<std::size_t>(panel ? 0 : ci)];
    for (std::size_t bi = 0; bi < bands.size(); ++bi) {
      const RawBand& b = bands[bi];
      Camera<float> cam = cap.cameras[static_cast<std::size_t>(b.mount)];
      if (!b.rgb && b.mount == Band::D) {  // MicaSense blue: an MS lens where the RGB lens would be
        const Camera<float> ms = rig_intrinsics(Band::MS_G, preset);
        cam.fx = ms.fx; cam.fy = ms.fy; cam.cx = ms.cx; cam.cy = ms.cy; cam.width = ms.width; cam.height = ms.height;
      }
      // Nominal lens data as the camera reports it (the real focal length differs by ~1 %).
      const double hfov = rig_mount(b.mount == Band::D && !b.rgb ? Band::MS_G : b.mount).hfov_deg;
      const double nominal_fx = 0.5 * cam.width / std::tan(0.5 * hfov * 3.14159265358979323846 / 180.0);
      const double focal_mm = b.rgb ? 12.29 : 5.5;
      const double px_per_mm = nominal_fx / focal_mm;
      RenderSettings rs;
      rs.aa = preset.aa;
      rs.jitter_seed = frame_jitter_seed(opt.seed, ci, b.mount) ^ (bi * 0x9E3779B97F4A7C15ULL);
      const fs::path file = tmp / raw_file_name(opt.camera, b, ci, sum.captures);
      std::vector<std::pair<std::string, std::string>> attrs = {
          {"Camera:BandName", b.band_name},
          {"exif:FocalLength", detail::g10(focal_mm)},
          {"exif:FocalPlaneXResolution", detail::g10(px_per_mm)},
          {"exif:FocalPlaneYResolution", detail::g10(px_per_mm)},
          {"exif:FocalPlaneResolutionUnit", "4"}};
      {
        const int t = raw_capture_seconds(ci, sum.captures);
        char when[32];
        std::snprintf(when, sizeof when, "2024-06-01T%02d:%02d:%02d", t / 3600, t / 60 % 60, t % 60);
        attrs.emplace_back("exif:DateTimeOriginal", when);
      }
      detail::add_gps(opt.camera, cap.cameras[static_cast<std::size_t>(Band::D)].position(), attrs);
      std::vector<std::pair<std::string, std::string>> elems;
      if (b.rgb) {
        const Image<float> img = render_band(scene, cam, Band::D, rs);
        detail::write_rgb_jpeg(file, img, detail::xmp_packet(attrs, elems));
        ++sum.files;
        continue;
      }
      RawExposure e = raw_exposure(opt.seed, ci, int(bi));
      if (panel) {  // auto-exposed for the bright panel: 4 times shorter, ISO 100
        e.exposure_s = 1.0 / std::round(4.0 / e.exposure_s);
        e.iso = 100;
      }
      const double t_first = raw_capture_seconds(first, sum.captures), t_last = raw_capture_seconds(last, sum.captures);
      const auto light_of = [&](int c) {
        return raw_light(opt.seed, c, opt.light_variation) *
               (1.0 + opt.light_drift *
                          (t_last > t_first ? (raw_capture_seconds(c, sum.captures) - t_first) / (t_last - t_first) : 0.0));
      };
      const double light = light_of(ci);
      const RawAttitude att = raw_attitude(ci, panel);
      // What the light sensor adds to the light: a calibration error, and in flight the heading's part.
      const double sensor = (1.0 + opt.dls_bias) *
                            (panel ? 1.0 : 1.0 + opt.heading_bias * std::cos(att.yaw - 20.0 * std::numbers::pi / 180.0));
      sum.min_exposure_s = std::min(sum.min_exposure_s, e.exposure_s);
      sum.max_exposure_s = std::max(sum.max_exposure_s, e.exposure_s);
      sum.min_iso = std::min(sum.min_iso, e.iso);
      sum.max_iso = std::max(sum.max_iso, e.iso);
      // Vignetting: fall-off to ~0.72 in the corners, centre a few pixels off the image centre.
      const double vcx = 0.5 * cam.width - 0.5 + 0.02 * cam.width, vcy = 0.5 * cam.height - 0.5 - 0.015 * cam.height;
      const double rmax = std::hypot(0.5 * cam.width, 0.5 * cam.height);
      // falloff(r) = 1 - 0.30 rho^2 + 0.02 rho^4 (rho = r / rmax); DJI's correction is 1 + 0.3 rho^2 + 0.07 rho^4,
      // whose inverse is the fall-off the sensor sees.
      const std::vector<double> k = dji
                                        ? std::vector<double>{0, 0.30 / (rmax * rmax), 0, 0.07 / std::pow(rmax, 4), 0, 0}
                                        : std::vector<double>{0, -0.30 / (rmax * rmax), 0, 0.02 / std::pow(rmax, 4), 0, 0};
      // The panel as this lens sees it: a little off-centre, differently per band.
      const double pdx = 0.03 * (double(bi) - 2.0), pdy = 0.02 * (double(bi % 2) - 0.5);
      const double albedo = opt.dark_panel && ci >= sum.captures && (ci - sum.captures) % 2 == 1
                                ? raw_dark_panel_albedo(b.wavelength_nm)
                                : raw_panel_albedo(b.wavelength_nm);
      if (panel && !micasense) {  // listed for --panels, as a user would from the pictures
        nlohmann::ordered_json pic;
        pic["file"] = raw_file_name(opt.camera, b, ci, sum.captures);
        pic["area"] = detail::panel_area(cam.width, cam.height, pdx, pdy);
        pic["albedo"] = albedo;
        panel_list.push_back(pic);
      }
      const Image<float> L =
          panel ? detail::panel_radiance(cam.width, cam.height, detail::panel_square(cam.width, cam.height, 0.36, pdx, pdy),
                                         albedo)
                : detail::render_radiance(scene, cam, b.spectrum_channel, rs);
      std::vector<std::uint16_t> dn(L.data.size());
      const std::array<double, 3> model = sequoia_sensor_model(b);
      const double bl = black ? black_level : 0.0;
      for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
          double fall = 1.0;
          if (sequoia) {
            fall = io::vignetting_polynomial_2d(c2d, e2d, double(x) / cam.width, double(y) / cam.height);
          } else {
            double p = 0.0;
            const double r = std::hypot(x - vcx, y - vcy);
            for (std::size_t i = k.size(); i-- > 0;) p = (p + k[i]) * r;
            fall = dji ? 1.0 / (1.0 + p) : 1.0 + p;
          }
          const double row = micasense ? 1.0 + row_a2 * y / e.exposure_s - row_a3 * y : 1.0;
          // The Sequoia as its SensorModel says: DN / fall-off - B = (A exposure ISO + C) x light.
          const double dark = sequoia ? fall * model[1] : bl;
          const double camera = sequoia ? model[0] * e.exposure_s * e.iso + model[2] : e.exposure_s * e.gain() * b.sensitivity;
          const double v = dark + (double(L.at(x, y, 0)) + opt.path_reflectance) * camera * fall * row * light;
          dn[std::size_t(y) * std::size_t(cam.width) + std::size_t(x)] =
              static_cast<std::uint16_t>(std::lround(std::clamp(v, 0.0, 65535.0)));
        }
      attrs.emplace_back("Camera:CentralWavelength", detail::g10(b.wavelength_nm));
      attrs.emplace_back("Camera:WavelengthFWHM", detail::g10(b.fwhm_nm));
      attrs.emplace_back("exif:ExposureTime", io::cat("1/", std::lround(1.0 / e.exposure_s)));
      if (dji) {
        attrs.emplace_back("drone-dji:ExposureTime", detail::g10(e.exposure_s * 1e6));  // microseconds
        attrs.emplace_back(opt.camera == "p4m" ? "drone-dji:BlackLevel" : "Camera:BlackCurrent", detail::g10(black_level));
        attrs.emplace_back("drone-dji:SensorGain", detail::g10(e.gain()));
        std::string kv;
        for (std::size_t i = 0; i < k.size(); ++i) {
          if (i) kv += ',';
          kv += detail::g10(k[i]);  // (not `"," + str`: GCC 12's -Wrestrict false positive)
        }
        attrs.emplace_back("drone-dji:VignettingData", kv);
        attrs.emplace_back("drone-dji:CalibratedOpticalCenterX", detail::g10(vcx));
        attrs.emplace_back("drone-dji:CalibratedOpticalCenterY", detail::g10(vcy));
        // (DN - black) / 2^16 / (exposure gain fall-off) = value x sensitivity x light / 2^16, so
        // this reading makes DJI's ratio kDjiReflectanceFactor x value in every band.
        const double adjustment = dji_gain_adjustment(b);
        attrs.emplace_back("drone-dji:SensorGainAdjustment", detail::g10(adjustment));
        attrs.emplace_back("drone-dji:Irradiance",
                           detail::g10(b.sensitivity * adjustment * light * sensor / (65536.0 * kDjiReflectanceFactor)));
        // The drone's attitude in degrees, yaw in -180 .. 180 as DJI writes it.
        constexpr double deg = 180.0 / std::numbers::pi;
        const double yaw = att.yaw * deg;
        attrs.emplace_back("drone-dji:FlightYawDegree", detail::g10(yaw > 180.0 ? yaw - 360.0 : yaw));
        attrs.emplace_back("drone-dji:FlightPitchDegree", detail::g10(att.pitch * deg));
        attrs.emplace_back("drone-dji:FlightRollDegree", detail::g10(att.roll * deg));
      } else {
        elems.emplace_back("exif:ISOSpeedRatings", detail::rdf_seq({double(e.iso)}));
        if (black) attrs.emplace_back("Camera:BlackLevel", detail::g10(black_level));
        if (micasense) {
          // The scene's values are reflectances under the band's sunlight E_ref: a1 makes
          // pi a1 (DN - black) / 2^16 / (exposure gain fall-off row E) give them back.
          const double e_ref = raw_irradiance(b.wavelength_nm);
          const double a1 = 65536.0 * e_ref / (std::numbers::pi * b.sensitivity);
          elems.emplace_back("MicaSense:RadiometricCalibration", detail::rdf_seq({a1, row_a2, row_a3}));
          const double level = e_ref * light * sensor;
          // The sensor's attitude, which a DLS 2 records too.
          attrs.emplace_back("DLS:Yaw", detail::g10(att.yaw));
          attrs.emplace_back("DLS:Pitch", detail::g10(att.pitch));
          attrs.emplace_back("DLS:Roll", detail::g10(att.roll));
          if (opt.dls1) {
            const double reading = dls1_reading(level, att, raw_capture_seconds(ci, sum.captures),
                                                cap.cameras[static_cast<std::size_t>(Band::D)].position());
            constexpr double deg = 180.0 / std::numbers::pi;
            attrs.emplace_back("DLS:SpectralIrradiance", detail::g10(reading));
            attrs.emplace_back("Camera:Irradiance", detail::g10(reading));
            attrs.emplace_back("Camera:IrradianceYaw", detail::g10(att.yaw * deg));
            attrs.emplace_back("Camera:IrradiancePitch", detail::g10(att.pitch * deg));
            attrs.emplace_back("Camera:IrradianceRoll", detail::g10(att.roll * deg));
          } else {
            attrs.emplace_back("Camera:HorizontalIrradiance", detail::g10(level / 0.01));
            attrs.emplace_back("Camera:IrradianceScaleToSIUnits", "0.01");
          }
          if (panel) {  // the inner area of the panel, as the camera marks it: whole pixels
            std::string area;
            for (const auto& c : detail::panel_area(cam.width, cam.height, pdx, pdy))
              area += io::cat(area.empty() ? "" : ",", c[0], ",", c[1]);
            attrs.emplace_back("Camera:CalibrationPicture", "2");
            attrs.emplace_back("Camera:Albedo", detail::g10(albedo));
            attrs.emplace_back("Camera:ReflectArea", area);
            attrs.emplace_back("Camera:PanelSerial", "RP04-1234567-OB");
          }
        }
      }
      if (sequoia) {
        std::vector<double> exps;
        for (const auto& ab : e2d) exps.insert(exps.end(), {double(ab[0]), double(ab[1])});
        elems.emplace_back("Camera:VignettingPolynomial2D", detail::rdf_seq(c2d));
        elems.emplace_back("Camera:VignettingPolynomial2DName", detail::rdf_seq(exps));
        const double previous = ci > first ? light_of(ci - 1) : light;
        attrs.emplace_back("Camera:IrradianceList",
                           sequoia_sunshine_list(b, int(bi), raw_capture_seconds(ci, sum.captures), light * sensor,
                                                 previous * sensor, att));
        attrs.emplace_back("Camera:IrradianceCalibrationMeasurement", sequoia_sunshine_calibration());
        attrs.emplace_back("Camera:SensorModel", io::cat(detail::g10(model[0]), ",", detail::g10(model[1]), ",",
                                                         detail::g10(model[2])));
      } else {  // Pix4D's keys (for DJI the same correction again, as the real camera writes it)
        elems.emplace_back("Camera:VignettingCenter", detail::rdf_seq({vcx, vcy}));
        elems.emplace_back("Camera:VignettingPolynomial", detail::rdf_seq(k));
      }
      if (micasense) {  // the band camera's own calibration, where the nominal lens data is ~1% off
        attrs.emplace_back("Camera:PerspectiveFocalLength", detail::g10(cam.fx));
        attrs.emplace_back("Camera:PrincipalPoint",
                           io::cat(detail::g10(cam.cx / px_per_mm), ",", detail::g10(cam.cy / px_per_mm)));
      }
      detail::write_raw_tiff(file, cam.width, cam.height, dn, detail::xmp_packet(attrs, elems));
      ++sum.files;
    }
  }
  if (!panel_list.empty()) {
    nlohmann::ordered_json list;
    list["pictures"] = panel_list;
    io::write_text_atomic(tmp / "panels.json", list.dump(2) + "\n");
  }
  stage.commit();
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

}  // namespace msgs::synth
