// include/msgs/io/capture_meta.hpp
// Radiometric and lens metadata of one multi-band image, parsed from the text the exiv2 command-line
// tool prints (`exiv2 -q -P kv -K KEY ... FILE...`): band name, centre wavelength, black level,
// exposure time, gain / ISO, vignetting model, focal length and focal-plane resolution.
//
// Keys read (first one present wins), as MicaSense, DJI and Parrot write them:
//   band name     Xmp.Camera.BandName
//   wavelength    Xmp.Camera.CentralWavelength (nm)
//   black level   Exif.Image.BlackLevel (MicaSense, IFD0; several values are averaged),
//                 Xmp.drone-dji.BlackLevel (DJI P4 Multispectral), Xmp.Camera.BlackLevel,
//                 Xmp.Camera.BlackCurrent (DJI Mavic 3M: "BlackCurrent, black level: 3200")
//   exposure      Xmp.drone-dji.ExposureTime (DJI, microseconds), Exif.Photo.ExposureTime,
//                 Xmp.exif.ExposureTime (seconds, "1/1250" or decimal)
//   gain          Xmp.drone-dji.SensorGain (a factor), else ISO / 100 from Exif.Photo.ISOSpeed,
//                 Exif.Photo.ISOSpeedRatings, Xmp.exifEX.ISOSpeed, Xmp.exif.ISOSpeedRatings
//   vignetting    Xmp.Camera.VignettingPolynomial + Xmp.Camera.VignettingCenter (MicaSense and
//                 Pix4D's convention: the fall-off 1 + k0 r + ... + k5 r^6, r in pixels; the image
//                 is divided by it). DJI files (Exif.Image.Make "DJI", or any drone-dji key) hold
//                 the correction 1 + k0 r + ..., which multiplies the image, in
//                 Xmp.drone-dji.VignettingData + Xmp.drone-dji.CalibratedOpticalCenterX/Y (read
//                 first, as DJI's processing guides use it) and in the Camera polynomial as well
//                 (OpenDroneMap multiplies DJI files by it, divides all others). Without a radial
//                 model: Xmp.Camera.VignettingPolynomial2D + Xmp.Camera.VignettingPolynomial2DName
//                 (Parrot Sequoia, MicaSense RedEdge-P and Altum-PT: the fall-off
//                 sum_i c_i (x / width)^a_i (y / height)^b_i, the exponents a_0, b_0, a_1, b_1, ...
//                 in the Name key; the image is divided by it)
//   sensor model  Xmp.Camera.SensorModel (Parrot Sequoia, firmware 1.2.1 and later: A, B, C of
//                 irradiance = f^2 (DN / fall-off - B) / (A exposure ISO + C), Parrot's application
//                 note SEQ-AN-01 as its users quote it; B takes the black level's place)
//   row gradient  Xmp.MicaSense.RadiometricCalibration (a1, a2, a3: MicaSense's sensor records row y
//                 brighter by 1 + a2 y / exposure - a3 y; a1 turns the corrected DN / 2^bits into
//                 radiance in W/m^2/sr/nm, used by --radiometry reflectance only)
//   irradiance    Xmp.Camera.HorizontalIrradiance or Xmp.DLS.HorizontalIrradiance (MicaSense DLS 2:
//                 the sunlight on a level surface, W/m^2/nm after x Xmp.Camera.IrradianceScaleToSIUnits,
//                 0.01 where that key is missing, as MicaSense's library assumes). Left out, with the
//                 reason in `irradiance_problem`, for a RedEdge / RedEdge-M before firmware 5.1.7 and
//                 an Altum before 1.2.3 (Exif.Image.Model, Exif.Image.Software), whose firmware
//                 wrote it wrongly; in DJI files (Mavic 3M, P4 Multispectral) the sunlight sensor's
//                 reading of this band, in its own units: Xmp.drone-dji.Irradiance, else
//                 Xmp.Camera.Irradiance (DJI's guides: "solar irradiance value after compensation");
//                 a Parrot Sequoia's sunshine sensor, in its own units: Xmp.Camera.IrradianceList
//                 with the gains of Xmp.Camera.IrradianceCalibrationMeasurement
//                 (msgs/io/sunshine_sensor.hpp)
//   levelled      where a MicaSense file has no HorizontalIrradiance, or one its firmware wrote
//                 wrongly, the level-ground irradiance is computed as MicaSense's library does
//                 (msgs/io/light_sensor_tilt.hpp), with the sun's place from the position and the
//                 capture time (UTC, as MicaSense cameras write it): a DLS 2's
//                 Xmp.DLS.DirectIrradiance x sin(sun elevation) + Xmp.DLS.ScatteredIrradiance, else
//                 a DLS 1's tilted Xmp.DLS.SpectralIrradiance levelled with its attitude
//                 Xmp.DLS.Yaw/Pitch/Roll (radians); x IrradianceScaleToSIUnits, else 0.01 where
//                 the file has HorizontalIrradiance (DLS 2) and 1 where it has not (DLS 1)
//   band factor   Xmp.drone-dji.SensorGainAdjustment (DJI: the band camera's sensitivity relative
//                 to DJI's reference module, which the image is multiplied by before it is divided
//                 by the sunlight sensor's reading)
//   panel         Xmp.Camera.CalibrationPicture (Pix4D's tag, which MicaSense writes: 0 a flight
//                 image, 1 a picture of a calibration panel the camera could not read, 2 one it read;
//                 a Sequoia writes 1 and 2 for any panel picture), Xmp.Camera.Albedo (the panel's
//                 reflectance in this band), Xmp.Camera.ReflectArea (the four corners of the panel's
//                 reflecting area, x and y in pixels), Xmp.MicaSense.PanelSerial (a RedEdge-P's
//                 panel capture has all four) or Xmp.Camera.PanelSerial
//   focal length  Exif.Photo.FocalLength, Xmp.exif.FocalLength (mm)
//   focal plane   Exif.Photo.FocalPlaneXResolution / YResolution / ResolutionUnit and the same in
//                 Xmp.exif (unit 2 inch, the EXIF default, 3 cm, 4 mm, 5 micrometre)
//   bit depth     Exif.Image.BitsPerSample
//   heading       Xmp.drone-dji.FlightYawDegree (DJI, degrees), else Xmp.DLS.Yaw (MicaSense's light
//                 sensor, radians): which way the drone flew, for msgs/io/light_sensor_heading.hpp
//   time          Exif.Photo.DateTimeOriginal ("2024:07:30 10:15:32") + Exif.Photo.SubSecTimeOriginal
//                 or Exif.Photo.SubSecTime (MicaSense's, which may be negative: "-279654"),
//                 else Xmp.exif.DateTimeOriginal ("2024-07-30T10:15:32.25", a time zone ignored):
//                 seconds since 1970-01-01 in the camera's clock, to order captures in time
// Parsing never crashes on odd text: lines that are not "KEY VALUE" are ignored, and a recognised
// key whose value is not what it should be is an IoError naming the file, the key and the value.
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "msgs/io/error.hpp"
#include "msgs/io/light_sensor_tilt.hpp"
#include "msgs/io/sun_position.hpp"
#include "msgs/io/sunshine_sensor.hpp"

namespace msgs::io {

/// How a vignetting polynomial p(r) = 1 + k0 r + k1 r^2 + ... relates to the image.
enum class VignettingKind {
  falloff,     ///< MicaSense: DN is proportional to p(r); divide by it
  correction,  ///< DJI: p(r) is the correction; multiply by it
};

/// Metadata of one image. Absent tags stay empty; `source` says which key gave each quantity.
struct CaptureMeta {
  std::optional<std::string> band_name;
  std::optional<double> wavelength_nm;
  std::optional<double> black_level;   ///< in the file's digital numbers
  std::optional<double> exposure_s;
  std::optional<double> gain;          ///< linear factor (ISO / 100 when only ISO is given)
  std::vector<double> vignetting_poly; ///< k0, k1, ... (empty: no radial vignetting model)
  std::optional<std::array<double, 2>> vignetting_centre;  ///< pixels
  VignettingKind vignetting_kind = VignettingKind::falloff;
  /// The 2-D fall-off sum_i c_i (x / width)^a_i (y / height)^b_i (empty: none), used where there
  /// is no radial model.
  std::vector<double> vignetting_poly2d;                ///< c_i
  std::vector<std::array<int, 2>> vignetting_exp2d;     ///< (a_i, b_i)
  /// The Parrot Sequoia's model of its sensor (Xmp.Camera.SensorModel, firmware 1.2.1 and later):
  /// A, B, C of irradiance = f^2 (DN / fall-off - B) / (A x exposure_s x ISO + C).
  std::optional<std::array<double, 3>> sensor_model;
  /// MicaSense's a2, a3: DN grows along the row index y by 1 + a2 y / exposure_s - a3 y.
  std::optional<std::array<double, 2>> row_gradient;
  /// MicaSense's a1: radiance (W/m^2/sr/nm) = a1 x (DN - black level) / 2^bits / (exposure x gain
  /// x fall-off x row gradient).
  std::optional<double> radiance_a1;
  /// The light sensor's reading of the sunlight at the capture, in this band: MicaSense's DLS 2
  /// spectral irradiance on a level surface in W/m^2/nm (`irradiance_si`), or DJI's sunlight
  /// sensor in its own units.
  std::optional<double> irradiance;
  bool irradiance_si = false;
  /// DJI's SensorGainAdjustment: (DN - black) / 2^bits / (exposure x gain) x this / the sunlight
  /// sensor's reading is reflectance up to one factor common to every band (DJI's guides).
  std::optional<double> gain_adjustment;
  /// How many readings `irradiance` is the mean of (a Parrot Sequoia's sunshine sensor; 0 otherwise).
  int light_sensor_readings = 0;
  /// Why an irradiance the file holds was not taken (a firmware known to write it wrongly, a
  /// reading that could not be levelled).
  std::string irradiance_problem;
  /// Where `irradiance` was levelled for the sun's place (a DLS 1's tilted reading, a DLS 2 whose
  /// firmware wrote HorizontalIrradiance wrongly): the sun's elevation, and for a DLS 1 its angle
  /// from the sensor's normal, in degrees.
  std::optional<double> sun_elevation_deg, sun_sensor_angle_deg;
  /// Which way the drone flew: degrees clockwise from north, [0, 360).
  std::optional<double> heading_deg;
  /// Xmp.Camera.CalibrationPicture: 0 a flight image, 1 a panel picture the camera could not
  /// read, 2 one it read (a Sequoia writes 1 or 2 for either).
  int calibration_picture = 0;
  std::optional<double> panel_albedo;  ///< the panel's reflectance in this band (0..1]
  /// The corners of the panel's reflecting area in the image, (x, y) in pixels, in the camera's order.
  std::optional<std::array<std::array<double, 2>, 4>> panel_area;
  std::string panel_serial;
  std::optional<double> focal_length_mm;
  std::optional<double> focal_plane_px_per_mm;  ///< x resolution, converted to pixels per mm
  /// The band camera's own calibration, where it writes one (MicaSense: Pix4D's
  /// `Camera:PerspectiveFocalLength`, in pixels or in `PerspectiveFocalLengthUnits`, and
  /// `Camera:PrincipalPoint` in mm on the focal plane), in pixels of the image as stored.
  std::optional<double> calibrated_focal_px;
  std::optional<std::array<double, 2>> principal_point_px;
  std::optional<int> bits_per_sample;
  /// Where the camera was: latitude and longitude in degrees (north and east positive) and
  /// altitude in metres (0 when the file gives none). Unset when the file has no position or an
  /// unreadable one (`gps_problem` then says which key and value).
  std::optional<std::array<double, 3>> gps;
  std::string gps_problem;
  /// When the image was taken: seconds since 1970-01-01 in the camera's clock (its time zone, if
  /// any, ignored). Unset when the file gives none or an unreadable one (`time_problem` says which).
  std::optional<double> time_s;
  std::string time_problem;
  std::map<std::string, std::string> source;    ///< quantity -> exiv2 key it was read from

  /// Focal length in pixels: the camera's calibration where it writes one, else the nominal focal
  /// length x focal-plane resolution, when both are known.
  std::optional<double> focal_px() const {
    if (calibrated_focal_px) return calibrated_focal_px;
    if (focal_length_mm && focal_plane_px_per_mm) return *focal_length_mm * *focal_plane_px_per_mm;
    return std::nullopt;
  }
  bool has_radial_vignetting() const { return !vignetting_poly.empty() && vignetting_centre.has_value(); }
  bool has_vignetting() const { return has_radial_vignetting() || !vignetting_poly2d.empty(); }
};

/// Every key capture_meta_from_exiv2 looks at, for `exiv2 -K`.
inline const std::vector<std::string>& exiv2_metadata_keys() {
  static const std::vector<std::string> keys = {
      "Xmp.Camera.BandName", "Xmp.Camera.CentralWavelength", "Exif.Image.BlackLevel", "Xmp.drone-dji.BlackLevel",
      "Xmp.Camera.BlackLevel", "Exif.Photo.ExposureTime", "Xmp.exif.ExposureTime", "Xmp.drone-dji.SensorGain",
      "Exif.Photo.ISOSpeed", "Exif.Photo.ISOSpeedRatings", "Xmp.exifEX.ISOSpeed", "Xmp.exif.ISOSpeedRatings",
      "Xmp.Camera.VignettingPolynomial", "Xmp.Camera.VignettingCenter", "Xmp.drone-dji.VignettingData",
      "Xmp.drone-dji.CalibratedOpticalCenterX", "Xmp.drone-dji.CalibratedOpticalCenterY", "Exif.Photo.FocalLength",
      "Xmp.exif.FocalLength", "Exif.Photo.FocalPlaneXResolution", "Exif.Photo.FocalPlaneResolutionUnit",
      "Xmp.exif.FocalPlaneXResolution", "Xmp.exif.FocalPlaneResolutionUnit", "Exif.Image.BitsPerSample",
      "Exif.GPSInfo.GPSLatitude", "Exif.GPSInfo.GPSLatitudeRef", "Exif.GPSInfo.GPSLongitude",
      "Exif.GPSInfo.GPSLongitudeRef", "Exif.GPSInfo.GPSAltitude", "Exif.GPSInfo.GPSAltitudeRef",
      "Xmp.drone-dji.GpsLatitude", "Xmp.drone-dji.GpsLongitude", "Xmp.drone-dji.GpsLongtitude",
      "Xmp.drone-dji.AbsoluteAltitude", "Xmp.exif.GPSLatitude", "Xmp.exif.GPSLongitude", "Xmp.exif.GPSAltitude",
      "Xmp.exif.GPSAltitudeRef", "Xmp.Camera.BlackCurrent", "Xmp.drone-dji.ExposureTime", "Exif.Image.Make",
      "Xmp.Camera.VignettingPolynomial2D", "Xmp.Camera.VignettingPolynomial2DName",
      "Xmp.MicaSense.RadiometricCalibration", "Xmp.Camera.HorizontalIrradiance", "Xmp.DLS.HorizontalIrradiance",
      "Xmp.Camera.IrradianceScaleToSIUnits", "Exif.Image.Model", "Exif.Image.Software", "Xmp.Camera.CalibrationPicture",
      "Xmp.Camera.Albedo", "Xmp.Camera.ReflectArea", "Xmp.MicaSense.PanelSerial", "Xmp.Camera.PanelSerial",
      "Xmp.drone-dji.Irradiance", "Xmp.Camera.Irradiance", "Xmp.drone-dji.SensorGainAdjustment",
      "Exif.Photo.DateTimeOriginal", "Exif.Photo.SubSecTimeOriginal", "Xmp.exif.DateTimeOriginal",
      "Exif.Photo.SubSecTime", "Xmp.DLS.DirectIrradiance", "Xmp.DLS.ScatteredIrradiance",
      "Xmp.DLS.SpectralIrradiance", "Xmp.DLS.Yaw", "Xmp.DLS.Pitch", "Xmp.DLS.Roll", "Xmp.drone-dji.FlightYawDegree",
      "Xmp.Camera.IrradianceList", "Xmp.Camera.IrradianceCalibrationMeasurement", "Xmp.Camera.SensorModel",
      "Xmp.Camera.PerspectiveFocalLength", "Xmp.Camera.PerspectiveFocalLengthUnits", "Xmp.Camera.PrincipalPoint"};
  return keys;
}

namespace detail {

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

inline std::string_view trim(std::string_view s) {
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

/// A metadata key as exiv2 prints it: Family.Group.Name, letters, digits, '-' and '_'.
inline bool looks_like_key(std::string_view k) {
  if (k.size() < 5 || k.size() > 200) return false;
  int dots = 0;
  for (char c : k) {
    if (c == '.') ++dots;
    else if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) return false;
  }
  return dots >= 2 && (k.rfind("Exif.", 0) == 0 || k.rfind("Xmp.", 0) == 0 || k.rfind("Iptc.", 0) == 0);
}

/// A finite number: decimal, or a rational "a/b" with b != 0. nullopt for anything else.
inline std::optional<double> parse_number(std::string_view s) {
  s = trim(s);
  if (s.empty() || s.size() > 64) return std::nullopt;
  const std::string str(s);
  const std::size_t slash = str.find('/');
  auto whole = [](const std::string& t) -> std::optional<double> {
    if (t.empty()) return std::nullopt;
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (end != t.c_str() + t.size() || !std::isfinite(v)) return std::nullopt;
    return v;
  };
  if (slash == std::string::npos) return whole(str);
  const auto a = whole(str.substr(0, slash)), b = whole(str.substr(slash + 1));
  if (!a || !b || *b == 0.0) return std::nullopt;
  const double v = *a / *b;
  if (!std::isfinite(v)) return std::nullopt;
  return v;
}

/// Numbers separated by commas and/or spaces ("1, 2, 3", "4800 4800 4800 4800"); nullopt when any
/// piece is not a number or there is none.
inline std::optional<std::vector<double>> parse_number_list(std::string_view s, std::size_t max_count = 64) {
  std::vector<double> out;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (is_space(s[i]) || s[i] == ',')) ++i;
    std::size_t j = i;
    while (j < s.size() && !is_space(s[j]) && s[j] != ',') ++j;
    if (j > i) {
      const auto v = parse_number(s.substr(i, j - i));
      if (!v || out.size() >= max_count) return std::nullopt;
      out.push_back(*v);
    }
    i = j;
  }
  if (out.empty()) return std::nullopt;
  return out;
}

/// An EXIF GPS coordinate, "d/1 m/1 s/100" (degrees, minutes, seconds as rationals), with its
/// reference letter ("N", "S", "E", "W"): signed degrees, or nullopt when malformed.
inline std::optional<double> parse_exif_coordinate(std::string_view dms, std::string_view ref, char positive,
                                                   char negative) {
  const auto v = parse_number_list(dms, 3);
  ref = trim(ref);
  if (!v || v->size() != 3 || ref.size() != 1 || (ref[0] != positive && ref[0] != negative)) return std::nullopt;
  if ((*v)[0] < 0 || (*v)[1] < 0 || (*v)[1] >= 60 || (*v)[2] < 0 || (*v)[2] >= 60) return std::nullopt;
  const double deg = (*v)[0] + (*v)[1] / 60.0 + (*v)[2] / 3600.0;
  return ref[0] == negative ? -deg : deg;
}

/// An XMP GPS coordinate, "DDD,MM.mmmK" or "DDD,MM,SSK" with K one of the two reference letters:
/// signed degrees, or nullopt when malformed.
inline std::optional<double> parse_xmp_coordinate(std::string_view s, char positive, char negative) {
  s = trim(s);
  if (s.size() < 4) return std::nullopt;
  const char ref = s.back();
  if (ref != positive && ref != negative) return std::nullopt;
  std::string body(s.substr(0, s.size() - 1));
  for (char& c : body)
    if (c == ',') c = ' ';
  const auto v = parse_number_list(body, 3);
  if (!v || v->size() < 2 || (*v)[0] < 0 || (*v)[1] < 0 || (*v)[1] >= 60) return std::nullopt;
  double deg = (*v)[0] + (*v)[1] / 60.0;
  if (v->size() == 3) {
    if ((*v)[1] != std::floor((*v)[1]) || (*v)[2] < 0 || (*v)[2] >= 60) return std::nullopt;
    deg += (*v)[2] / 3600.0;
  }
  return ref == negative ? -deg : deg;
}

/// The leading numbers of a firmware version ("v5.1.7", "v2.1.2-34-g05e37eb" -> {5, 1, 7},
/// {2, 1, 2}); empty when it does not start with one.
inline std::vector<int> firmware_version(std::string_view s) {
  s = trim(s);
  if (!s.empty() && (s[0] == 'v' || s[0] == 'V')) s.remove_prefix(1);
  std::vector<int> out;
  std::size_t i = 0;
  while (i < s.size() && out.size() < 4 && std::isdigit(static_cast<unsigned char>(s[i]))) {
    long v = 0;
    while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i])) && v < 100000) v = v * 10 + (s[i++] - '0');
    out.push_back(int(v));
    if (i < s.size() && s[i] == '.') ++i;
    else break;
  }
  return out;
}

}  // namespace detail

/// Parse exiv2's `-P kv` output for ONE file ("KEY<spaces>VALUE" per line) into key -> value.
/// Lines that do not start with a metadata key are skipped (exiv2 warnings, continuation lines of
/// multi-line values); for a repeated key the first value is kept.
inline std::map<std::string, std::string> parse_exiv2_kv(std::string_view text) {
  std::map<std::string, std::string> kv;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view line = detail::trim(text.substr(pos, eol - pos));
    pos = eol + 1;
    std::size_t k = 0;
    while (k < line.size() && !detail::is_space(line[k])) ++k;
    const std::string_view key = line.substr(0, k);
    if (!detail::looks_like_key(key)) continue;
    kv.emplace(std::string(key), std::string(detail::trim(line.substr(k))));
  }
  return kv;
}

/// Split exiv2 output for several files (each line prefixed by the file name as it was passed)
/// into per-file text, keyed by the index into `files`. Each line goes to the longest file name it
/// starts with (followed by white space); other lines are dropped.
inline std::vector<std::string> split_exiv2_output(std::string_view text, const std::vector<std::string>& files) {
  std::vector<std::string> out(files.size());
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    const std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    std::size_t best = files.size(), best_len = 0;
    for (std::size_t i = 0; i < files.size(); ++i) {
      const std::string& f = files[i];
      if (f.empty() || f.size() < best_len || line.size() <= f.size() || line.compare(0, f.size(), f) != 0 ||
          !detail::is_space(line[f.size()]))
        continue;
      best = i;
      best_len = f.size();
    }
    if (best == files.size()) continue;
    out[best].append(line.substr(best_len));
    out[best].push_back('\n');
  }
  return out;
}

/// The camera position of one file's key -> value map into m.gps, from the EXIF GPS tags, else
/// DJI's XMP (decimal degrees; some firmware spells GpsLongtitude), else XMP exif (DDD,MM.mmmK).
/// A position is optional, so a malformed one is no error here: m.gps stays unset and
/// m.gps_problem names the key and value (an import that needs positions reports it).
/// Seconds since 1970-01-01 of a date and time "YYYY:MM:DD HH:MM:SS" (EXIF) or
/// "YYYY-MM-DDTHH:MM:SS[.fff][zone]" (XMP; the zone is ignored); nullopt for anything else.
inline std::optional<double> parse_date_time(std::string_view v) {
  v = detail::trim(v);
  if (v.size() < 19) return std::nullopt;
  auto digits = [&](std::size_t at, std::size_t n) -> int {
    int x = 0;
    for (std::size_t i = at; i < at + n; ++i) {
      if (v[i] < '0' || v[i] > '9') return -1;
      x = 10 * x + (v[i] - '0');
    }
    return x;
  };
  const bool exif = v[4] == ':' && v[7] == ':' && v[10] == ' ';
  const bool xmp = v[4] == '-' && v[7] == '-' && v[10] == 'T';
  if ((!exif && !xmp) || v[13] != ':' || v[16] != ':') return std::nullopt;
  const int y = digits(0, 4), mo = digits(5, 2), d = digits(8, 2), h = digits(11, 2), mi = digits(14, 2), s = digits(17, 2);
  if (y < 1900 || mo < 1 || mo > 12 || d < 1 || d > 31 || h < 0 || h > 23 || mi < 0 || mi > 59 || s < 0 || s > 60)
    return std::nullopt;
  double frac = 0.0;
  if (xmp && v.size() > 20 && v[19] == '.') {
    double scale = 0.1;
    for (std::size_t i = 20; i < v.size() && v[i] >= '0' && v[i] <= '9'; ++i, scale *= 0.1) frac += (v[i] - '0') * scale;
  }
  // Days from 1970-01-01 of the civil date (Howard Hinnant's days_from_civil).
  const int yy = y - (mo <= 2 ? 1 : 0);
  const int era = yy / 400, yoe = yy - era * 400;
  const int doy = (153 * (mo + (mo > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const long days = long(era) * 146097 + long(yoe) * 365 + yoe / 4 - yoe / 100 + doy - 719468;
  return double(days) * 86400.0 + h * 3600.0 + mi * 60.0 + s + frac;
}

/// The capture time of `kv` into m.time_s (or the reason it is unreadable into m.time_problem).
inline void read_time(const std::map<std::string, std::string>& kv, CaptureMeta& m) {
  for (const char* key : {"Exif.Photo.DateTimeOriginal", "Xmp.exif.DateTimeOriginal"}) {
    const auto it = kv.find(key);
    if (it == kv.end()) continue;
    const auto t = parse_date_time(it->second);
    if (!t) {
      m.time_problem = cat(key, " '", it->second.substr(0, 40), "' is not a date and time");
      return;
    }
    m.time_s = *t;
    m.source["time"] = key;
    if (std::string_view(key) != "Exif.Photo.DateTimeOriginal") return;
    auto sub = kv.find("Exif.Photo.SubSecTimeOriginal");
    if (sub == kv.end()) sub = kv.find("Exif.Photo.SubSecTime");
    if (sub == kv.end()) return;
    // "25" is a quarter second: the digits are a decimal fraction. MicaSense writes a sign where
    // the second was rounded up ("-279654": 0.279654 s before the stated second).
    std::string_view d = detail::trim(sub->second);
    const bool negative = !d.empty() && d[0] == '-';
    if (negative) d.remove_prefix(1);
    double frac = 0.0, scale = 0.1;
    bool ok = !d.empty() && d.size() <= 9;
    for (char c : d) {
      if (c < '0' || c > '9') ok = false;
      frac += (c - '0') * scale;
      scale *= 0.1;
    }
    if (ok) *m.time_s += negative ? -frac : frac;
    return;
  }
}

inline void read_gps(const std::map<std::string, std::string>& kv, CaptureMeta& m) {
  const auto get = [&](const char* k) -> const std::string* {
    const auto it = kv.find(k);
    return it == kv.end() ? nullptr : &it->second;
  };
  const auto problem = [&](const char* key) {
    m.gps_problem = cat(key, " '", get(key) ? get(key)->substr(0, 60) : std::string(), "' is not a position");
  };
  std::optional<double> lat, lon, alt;
  const char *lat_key = nullptr, *lon_key = nullptr, *alt_key = nullptr, *alt_ref_key = nullptr;
  const std::string none;
  const auto value = [&](const char* k) -> const std::string& { return get(k) ? *get(k) : none; };
  if (get("Exif.GPSInfo.GPSLatitude") && get("Exif.GPSInfo.GPSLongitude")) {
    lat_key = "Exif.GPSInfo.GPSLatitude";
    lon_key = "Exif.GPSInfo.GPSLongitude";
    alt_key = "Exif.GPSInfo.GPSAltitude";
    alt_ref_key = "Exif.GPSInfo.GPSAltitudeRef";
    lat = detail::parse_exif_coordinate(value(lat_key), value("Exif.GPSInfo.GPSLatitudeRef"), 'N', 'S');
    lon = detail::parse_exif_coordinate(value(lon_key), value("Exif.GPSInfo.GPSLongitudeRef"), 'E', 'W');
  } else if (get("Xmp.drone-dji.GpsLatitude") && (get("Xmp.drone-dji.GpsLongitude") || get("Xmp.drone-dji.GpsLongtitude"))) {
    lat_key = "Xmp.drone-dji.GpsLatitude";
    lon_key = get("Xmp.drone-dji.GpsLongitude") ? "Xmp.drone-dji.GpsLongitude" : "Xmp.drone-dji.GpsLongtitude";
    alt_key = "Xmp.drone-dji.AbsoluteAltitude";
    lat = detail::parse_number(value(lat_key));
    lon = detail::parse_number(value(lon_key));
  } else if (get("Xmp.exif.GPSLatitude") && get("Xmp.exif.GPSLongitude")) {
    lat_key = "Xmp.exif.GPSLatitude";
    lon_key = "Xmp.exif.GPSLongitude";
    alt_key = "Xmp.exif.GPSAltitude";
    alt_ref_key = "Xmp.exif.GPSAltitudeRef";
    lat = detail::parse_xmp_coordinate(value(lat_key), 'N', 'S');
    lon = detail::parse_xmp_coordinate(value(lon_key), 'E', 'W');
  } else {
    return;  // no position
  }
  if (!lat || !(std::abs(*lat) <= 90.0)) return problem(lat_key);
  if (!lon || !(std::abs(*lon) <= 180.0)) return problem(lon_key);
  if (get(alt_key)) {  // the altitude, optional; a reference of 1 means below sea level
    alt = detail::parse_number(value(alt_key));
    if (!alt) return problem(alt_key);
    if (alt_ref_key && detail::trim(value(alt_ref_key)) == "1") alt = -*alt;
  }
  m.gps = std::array<double, 3>{*lat, *lon, alt.value_or(0.0)};
  m.source["gps"] = lat_key;
}

/// Where a MicaSense file `kv` gave no level-ground irradiance (m.irradiance unset: no
/// HorizontalIrradiance, or one from firmware that wrote it wrongly), compute it from what the
/// light sensor recorded and the sun's place at m.gps and m.time_s (taken as UTC): a DLS 2's direct
/// and scattered parts, else a DLS 1's tilted reading and attitude (msgs/io/light_sensor_tilt.hpp).
/// Sets m.irradiance (W/m^2/nm), or says in m.irradiance_problem why it could not. A malformed
/// value is an IoError naming `file` and the key.
inline void level_light_sensor(const std::map<std::string, std::string>& kv, const std::filesystem::path& file,
                               CaptureMeta& m) {
  if (m.irradiance) return;
  const auto value = [&](const char* key, bool angle) -> std::optional<double> {
    const auto it = kv.find(key);
    if (it == kv.end()) return std::nullopt;
    const auto v = detail::parse_number_list(it->second, 1);
    if (!v || (!angle && (*v)[0] < 0))
      fail(file, key, cat("value '", it->second.substr(0, 80), "' is not ", angle ? "an angle in radians" : "an irradiance (>= 0)",
                          " (skip the metadata with --radiometry none)"));
    return (*v)[0];
  };
  const auto direct = value("Xmp.DLS.DirectIrradiance", false), scattered = value("Xmp.DLS.ScatteredIrradiance", false);
  const auto tilted = value("Xmp.DLS.SpectralIrradiance", false);
  const bool dls2 = direct && scattered && *direct > 0 && *scattered > 0;
  if (!dls2 && !(tilted && *tilted > 0)) return;  // no reading to level
  const bool horizontal = kv.count("Xmp.Camera.HorizontalIrradiance") || kv.count("Xmp.DLS.HorizontalIrradiance");
  double scale = horizontal ? 0.01 : 1.0;  // MicaSense's units of a DLS 2 and a DLS 1
  if (const auto sc = kv.find("Xmp.Camera.IrradianceScaleToSIUnits"); sc != kv.end()) {
    const auto v = detail::parse_number(sc->second);
    if (!v || !(*v > 0))
      fail(file, sc->first, cat("value '", sc->second.substr(0, 80), "' is not a scale factor (> 0)",
                                " (skip the metadata with --radiometry none)"));
    scale = *v;
  }
  const std::string before = m.irradiance_problem.empty() ? "" : m.irradiance_problem + "; ";
  const std::string what = dls2 ? "its DLS 2's direct and scattered light" : "its DLS 1's tilted reading";
  const auto give_up = [&](const std::string& why) {
    m.irradiance_problem = cat(before, what, " could not be levelled: ", why);
  };
  if (!m.gps) return give_up(m.gps_problem.empty() ? "the file has no position" : m.gps_problem);
  if (!m.time_s) return give_up(m.time_problem.empty() ? "the file has no capture time" : m.time_problem);
  const SunPosition sun = sun_position(*m.time_s, (*m.gps)[0], (*m.gps)[1]);
  double theta = 0.0;
  if (!dls2) {
    const auto yaw = value("Xmp.DLS.Yaw", true), pitch = value("Xmp.DLS.Pitch", true), roll = value("Xmp.DLS.Roll", true);
    if (!yaw || !pitch || !roll) return give_up("the file has no attitude of the sensor (Xmp.DLS.Yaw, Pitch, Roll)");
    theta = sun_sensor_angle(sun, *yaw, *pitch, *roll);
  }
  if (const std::string why = levelling_problem(sun.elevation, theta); !why.empty()) return give_up(why);
  const double level = dls2 ? level_direct_scattered(*direct * scale, *scattered * scale, sun.elevation)
                            : level_tilted_reading(*tilted * scale, theta, sun.elevation);
  if (!(level > 0) || !std::isfinite(level)) return give_up(cat("it gives ", level, " W/m^2/nm"));
  constexpr double deg = 180.0 / std::numbers::pi;
  m.irradiance = level;
  m.irradiance_si = true;
  m.sun_elevation_deg = sun.elevation * deg;
  if (dls2) {
    m.source["irradiance"] = "Xmp.DLS.DirectIrradiance x sin(sun elevation) + Xmp.DLS.ScatteredIrradiance";
  } else {
    m.sun_sensor_angle_deg = theta * deg;
    m.source["irradiance"] = "Xmp.DLS.SpectralIrradiance levelled with Xmp.DLS.Yaw/Pitch/Roll";
  }
  m.irradiance_problem.clear();
}

/// A Parrot Sequoia's sunshine sensor (msgs/io/sunshine_sensor.hpp): sets m.irradiance, in the
/// sensor's own units, from the IrradianceList `list` and the gains of `calibration`, or says in
/// m.irradiance_problem why not. Never an error: a list msgs cannot read leaves the modes that need
/// the reading to refuse the band, and the others unaffected.
inline void read_sunshine_sensor(const std::pair<const std::string, std::string>& list,
                                 const std::pair<const std::string, std::string>* calibration, CaptureMeta& m) {
  const SunshineList readings = parse_sunshine_list(list.second);
  if (!readings.problem.empty()) {
    m.irradiance_problem = cat(list.first, ": ", readings.problem);
    return;
  }
  const auto values = calibration ? detail::parse_number_list(calibration->second) : std::nullopt;
  const auto rows = values ? sunshine_calibration(*values) : std::nullopt;
  if (!rows) {
    m.irradiance_problem =
        calibration ? cat(calibration->first, ": value '", calibration->second.substr(0, 80),
                          "' is not rows of gain index, integration time, CH0 and CH1")
                    : "no Xmp.Camera.IrradianceCalibrationMeasurement, which gives the sunshine sensor's gains";
    return;
  }
  const SunshineIrradiance e = sunshine_irradiance(readings.readings, *rows);
  if (!e.problem.empty()) {
    m.irradiance_problem = cat(list.first, ": ", e.problem);
    return;
  }
  m.irradiance = e.irradiance;
  m.light_sensor_readings = e.readings;
  m.source["irradiance"] = list.first;
}

/// The exposure time legacy MicaSense RedEdge firmware writes for some frames, and what they were
/// exposed (MicaSense's imageprocessing library, micasense/metadata.py).
inline constexpr double kRedEdgeWrongExposureS = 1.0 / 6329.0;
inline constexpr double kRedEdgeTrueExposureS = 0.000274;

/// Turn the key -> value map of one file into metadata. `file` names the image in errors.
/// Throws IoError for a recognised key whose value is malformed (not a number where one is
/// expected, a vignetting centre without two numbers, a non-positive exposure ...).
inline CaptureMeta capture_meta_from_exiv2(const std::map<std::string, std::string>& kv,
                                           const std::filesystem::path& file) {
  CaptureMeta m;
  auto first = [&](std::initializer_list<const char*> keys) -> const std::pair<const std::string, std::string>* {
    for (const char* k : keys)
      if (auto it = kv.find(k); it != kv.end()) return &*it;
    return nullptr;
  };
  auto bad = [&](const std::pair<const std::string, std::string>& e, const char* expected) {
    fail(file, e.first, cat("value '", e.second.substr(0, 80), "' is not ", expected,
                            " (skip the metadata with --radiometry none)"));
  };
  auto number = [&](const std::pair<const std::string, std::string>& e, const char* expected, bool positive) {
    // An exiv2 "interpreted" value may carry a unit ("5.5 mm"); -P kv gives plain values, but
    // accept the first token either way.
    auto list = detail::parse_number_list(e.second);
    if (!list) {
      const std::string_view v = detail::trim(e.second);
      const std::size_t sp = v.find(' ');
      if (sp != std::string_view::npos) list = detail::parse_number_list(v.substr(0, sp));
    }
    if (!list || (positive && !((*list)[0] > 0))) bad(e, expected);
    return (*list)[0];
  };
  if (auto e = first({"Xmp.Camera.BandName"})) {
    m.band_name = std::string(detail::trim(e->second));
    m.source["band_name"] = e->first;
  }
  if (auto e = first({"Xmp.Camera.CentralWavelength"})) {
    m.wavelength_nm = number(*e, "a wavelength in nm (> 0)", true);
    m.source["wavelength_nm"] = e->first;
  }
  if (auto e = first({"Exif.Image.BlackLevel", "Xmp.drone-dji.BlackLevel", "Xmp.Camera.BlackLevel",
                      "Xmp.Camera.BlackCurrent"})) {
    const auto list = detail::parse_number_list(e->second);
    if (!list) bad(*e, "a black level (one number, or one per CFA position)");
    double s = 0;
    for (double v : *list) s += v;
    m.black_level = s / double(list->size());
    if (*m.black_level < 0) bad(*e, "a non-negative black level");
    m.source["black_level"] = e->first;
  }
  // DJI's microseconds first: whole microseconds, where EXIF may round to a shutter-speed step
  // (OpenDroneMap prefers them too).
  if (auto us = first({"Xmp.drone-dji.ExposureTime"})) {
    m.exposure_s = number(*us, "an exposure time in microseconds (> 0)", true) * 1e-6;
    m.source["exposure_s"] = us->first;
  } else if (auto e = first({"Exif.Photo.ExposureTime", "Xmp.exif.ExposureTime"})) {
    m.exposure_s = number(*e, "an exposure time in seconds (> 0, e.g. 1/1250)", true);
    m.source["exposure_s"] = e->first;
  }
  if (auto e = first({"Xmp.drone-dji.SensorGain"})) {
    m.gain = number(*e, "a gain factor (> 0)", true);
    m.source["gain"] = e->first;
  } else if (auto iso = first({"Exif.Photo.ISOSpeed", "Exif.Photo.ISOSpeedRatings", "Xmp.exifEX.ISOSpeed",
                               "Xmp.exif.ISOSpeedRatings"})) {
    m.gain = number(*iso, "an ISO value (> 0)", true) / 100.0;
    m.source["gain"] = iso->first + " / 100";
  }
  // Which convention a vignetting polynomial follows depends on the maker, not on the key: DJI
  // writes its correction under Pix4D's Camera key too.
  const auto make = first({"Exif.Image.Make"});
  const bool dji = (make && detail::trim(make->second).substr(0, 3) == "DJI") ||
                   std::any_of(kv.begin(), kv.end(), [](const auto& e) { return e.first.rfind("Xmp.drone-dji.", 0) == 0; });
  // Legacy RedEdge firmware (v2.1.2 among them) writes 1/6329 s for frames it exposed 0.274 ms;
  // MicaSense's library reads that value so for every camera of theirs but the Altum.
  const auto model = first({"Exif.Image.Model"});
  if (m.exposure_s && make && detail::trim(make->second) == "MicaSense" &&
      !(model && detail::trim(model->second) == "Altum") && std::abs(*m.exposure_s - kRedEdgeWrongExposureS) < 1e-6) {
    m.exposure_s = kRedEdgeTrueExposureS;
    m.source["exposure_s"] += " (1/6329 s: legacy RedEdge firmware's value for 0.274 ms, as MicaSense's library reads it)";
  }
  auto read_vignetting = [&](const char* poly_key, std::initializer_list<const char*> centre_keys, VignettingKind kind) {
    const auto p = first({poly_key});
    if (!p) return false;
    const auto list = detail::parse_number_list(p->second, 16);
    if (!list) bad(*p, "a list of up to 16 polynomial coefficients");
    m.vignetting_poly = *list;
    m.vignetting_kind = kind;
    m.source["vignetting"] = p->first;
    if (centre_keys.size() == 1) {  // one key holding "x, y"
      if (auto c = first({*centre_keys.begin()})) {
        const auto cl = detail::parse_number_list(c->second, 2);
        if (!cl || cl->size() != 2) bad(*c, "two numbers (x, y in pixels)");
        m.vignetting_centre = std::array<double, 2>{(*cl)[0], (*cl)[1]};
      }
    } else {  // one key each for x and y
      const auto cx = first({*centre_keys.begin()});
      const auto cy = first({*(centre_keys.begin() + 1)});
      if (cx && cy) m.vignetting_centre = std::array<double, 2>{number(*cx, "a pixel position", false),
                                                                number(*cy, "a pixel position", false)};
    }
    return true;
  };
  const auto dji_data = [&] {
    return read_vignetting("Xmp.drone-dji.VignettingData",
                           {"Xmp.drone-dji.CalibratedOpticalCenterX", "Xmp.drone-dji.CalibratedOpticalCenterY"},
                           VignettingKind::correction);
  };
  const auto camera_poly = [&](VignettingKind kind) {
    return read_vignetting("Xmp.Camera.VignettingPolynomial", {"Xmp.Camera.VignettingCenter"}, kind);
  };
  if (dji) {
    if (!dji_data() || !m.vignetting_centre) camera_poly(VignettingKind::correction);
  } else if (!camera_poly(VignettingKind::falloff)) {
    dji_data();
  }
  if (!m.has_radial_vignetting()) {
    if (auto c = first({"Xmp.Camera.VignettingPolynomial2D"})) {
      const auto names = first({"Xmp.Camera.VignettingPolynomial2DName"});
      if (!names) bad(*c, "usable without Xmp.Camera.VignettingPolynomial2DName, which gives its exponents");
      const auto coeffs = detail::parse_number_list(c->second, 64);
      if (!coeffs) bad(*c, "a list of up to 64 polynomial coefficients");
      const auto exps = detail::parse_number_list(names->second, 128);
      if (!exps || exps->size() != 2 * coeffs->size())
        bad(*names, cat("two exponents (of x and y) for each of the ", coeffs->size(), " coefficients").c_str());
      for (double e : *exps)
        if (!(e >= 0 && e <= 16) || e != std::floor(e)) bad(*names, "whole exponents from 0 to 16");
      m.vignetting_poly.clear();
      m.vignetting_centre.reset();
      m.vignetting_kind = VignettingKind::falloff;
      m.vignetting_poly2d = *coeffs;
      for (std::size_t i = 0; i < coeffs->size(); ++i)
        m.vignetting_exp2d.push_back({int((*exps)[2 * i]), int((*exps)[2 * i + 1])});
      m.source["vignetting"] = c->first;
    }
  }
  if (auto e = first({"Xmp.Camera.SensorModel"})) {
    const auto list = detail::parse_number_list(e->second, 3);
    if (!list || list->size() != 3 || !((*list)[0] > 0)) bad(*e, "three numbers A, B, C with A > 0");
    m.sensor_model = std::array<double, 3>{(*list)[0], (*list)[1], (*list)[2]};
    m.source["sensor_model"] = e->first;
  }
  if (auto e = first({"Xmp.MicaSense.RadiometricCalibration"})) {
    const auto list = detail::parse_number_list(e->second, 3);
    if (!list || list->size() != 3) bad(*e, "three numbers (a1, a2, a3)");
    m.row_gradient = std::array<double, 2>{(*list)[1], (*list)[2]};
    m.source["row_gradient"] = e->first;
    if ((*list)[0] > 0) {
      m.radiance_a1 = (*list)[0];
      m.source["radiance_a1"] = e->first;
    }
  }
  if (auto e = first({"Xmp.Camera.HorizontalIrradiance", "Xmp.DLS.HorizontalIrradiance"})) {
    // A zero is what a capture without a light-sensor reading carries: no irradiance, no error.
    const double h = number(*e, "an irradiance (>= 0)", false);
    if (h < 0) bad(*e, "an irradiance (>= 0)");
    double scale = 0.01;
    if (auto sc = first({"Xmp.Camera.IrradianceScaleToSIUnits"})) scale = number(*sc, "a scale factor (> 0)", true);
    // MicaSense's library distrusts HorizontalIrradiance from these firmware versions.
    const std::string_view name = model ? detail::trim(model->second) : std::string_view();
    const std::vector<int> fixed = name == "RedEdge" || name == "RedEdge-M" ? std::vector<int>{5, 1, 7}
                                   : name == "Altum"                          ? std::vector<int>{1, 2, 3}
                                                                              : std::vector<int>{};
    const auto software = first({"Exif.Image.Software"});
    const std::vector<int> version = software ? detail::firmware_version(software->second) : std::vector<int>{};
    if (!fixed.empty() && (version.empty() || version < fixed)) {
      m.irradiance_problem = cat("a ", name, " with firmware '", software ? software->second.substr(0, 40) : std::string("?"),
                                 "' (before v", fixed[0], ".", fixed[1], ".", fixed[2],
                                 ") wrote HorizontalIrradiance wrongly");
    } else if (h > 0) {
      m.irradiance = h * scale;
      m.irradiance_si = true;
      m.source["irradiance"] = e->first;
    }
  } else if (dji) {
    // (MicaSense's Camera:Irradiance is the reading facing the sky, not the level-surface value.)
    if (auto d = first({"Xmp.drone-dji.Irradiance", "Xmp.Camera.Irradiance"})) {
      // A zero: no sunlight sensor on the drone, or no reading; no error.
      const double h = number(*d, "a sunlight-sensor reading (>= 0)", false);
      if (h < 0) bad(*d, "a sunlight-sensor reading (>= 0)");
      if (h > 0) {
        m.irradiance = h;
        m.source["irradiance"] = d->first;
      }
    }
  }
  if (!m.irradiance && m.irradiance_problem.empty())
    if (auto e = first({"Xmp.Camera.IrradianceList"})) read_sunshine_sensor(*e, first({"Xmp.Camera.IrradianceCalibrationMeasurement"}), m);
  if (auto e = first({"Xmp.drone-dji.SensorGainAdjustment"})) {
    m.gain_adjustment = number(*e, "a gain adjustment factor (> 0)", true);
    m.source["gain_adjustment"] = e->first;
  }
  if (auto e = first({"Xmp.Camera.CalibrationPicture"})) {
    const double c = number(*e, "0, 1 or 2 (not a panel, an unread panel, a read one)", false);
    if (c != 0 && c != 1 && c != 2) bad(*e, "0, 1 or 2 (not a panel, an unread panel, a read one)");
    m.calibration_picture = int(c);
    m.source["calibration_picture"] = e->first;
  }
  if (auto e = first({"Xmp.Camera.Albedo"})) {
    // A list (one value per band of a multi-page file) gives this page's first value.
    const double a = number(*e, "a panel reflectance in (0, 1]", true);
    if (!(a <= 1)) bad(*e, "a panel reflectance in (0, 1]");
    m.panel_albedo = a;
    m.source["panel_albedo"] = e->first;
  }
  if (auto e = first({"Xmp.Camera.ReflectArea"})) {
    const auto list = detail::parse_number_list(e->second, 8);
    if (!list || list->size() != 8) bad(*e, "eight numbers (x, y of the panel area's four corners, in pixels)");
    std::array<std::array<double, 2>, 4> q{};
    for (std::size_t i = 0; i < 4; ++i) q[i] = {(*list)[2 * i], (*list)[2 * i + 1]};
    m.panel_area = q;
    m.source["panel_area"] = e->first;
  }
  if (auto e = first({"Xmp.MicaSense.PanelSerial", "Xmp.Camera.PanelSerial"}))
    m.panel_serial = std::string(detail::trim(e->second)).substr(0, 64);
  if (auto e = first({"Exif.Photo.FocalLength", "Xmp.exif.FocalLength"})) {
    m.focal_length_mm = number(*e, "a focal length in mm (> 0)", true);
    m.source["focal_length_mm"] = e->first;
  }
  const bool exif_plane = kv.count("Exif.Photo.FocalPlaneXResolution") > 0;
  if (auto e = first({"Exif.Photo.FocalPlaneXResolution", "Xmp.exif.FocalPlaneXResolution"})) {
    const double res = number(*e, "a focal-plane resolution (> 0)", true);
    double unit = 2;  // EXIF default: inch
    if (auto u = first({exif_plane ? "Exif.Photo.FocalPlaneResolutionUnit" : "Xmp.exif.FocalPlaneResolutionUnit"})) {
      unit = number(*u, "a resolution unit (2 inch, 3 cm, 4 mm, 5 micrometre)", true);
      if (unit != 2 && unit != 3 && unit != 4 && unit != 5) bad(*u, "a resolution unit (2 inch, 3 cm, 4 mm, 5 micrometre)");
    }
    const double mm_per_unit = unit == 2 ? 25.4 : unit == 3 ? 10.0 : unit == 4 ? 1.0 : 0.001;
    m.focal_plane_px_per_mm = res / mm_per_unit;
    m.source["focal_plane_px_per_mm"] = e->first;
  }
  if (auto e = first({"Xmp.Camera.PerspectiveFocalLength"})) {
    const double f = number(*e, "a focal length (> 0)", true);
    const auto units = first({"Xmp.Camera.PerspectiveFocalLengthUnits"});
    const std::string_view u = units ? detail::trim(units->second) : std::string_view("px");
    if (u != "mm" && u != "px") bad(*units, "'mm' or 'px'");
    // In mm it needs the focal plane's resolution; without one it is not used.
    if (u == "px" || m.focal_plane_px_per_mm) {
      m.calibrated_focal_px = u == "px" ? f : f * *m.focal_plane_px_per_mm;
      if (!std::isfinite(*m.calibrated_focal_px)) bad(*e, "a focal length of a finite number of pixels");
      m.source["calibrated_focal_px"] = e->first;
    }
  }
  if (auto e = first({"Xmp.Camera.PrincipalPoint"})) {
    const auto list = detail::parse_number_list(e->second, 2);
    if (!list || list->size() != 2 || !((*list)[0] > 0) || !((*list)[1] > 0))
      bad(*e, "x,y of the principal point in mm on the focal plane (two numbers > 0)");
    if (m.focal_plane_px_per_mm) {
      m.principal_point_px = {(*list)[0] * *m.focal_plane_px_per_mm, (*list)[1] * *m.focal_plane_px_per_mm};
      if (!std::isfinite((*m.principal_point_px)[0]) || !std::isfinite((*m.principal_point_px)[1]))
        bad(*e, "a principal point a finite number of pixels from the corner");
      m.source["principal_point_px"] = e->first;
    }
  }
  if (auto e = first({"Exif.Image.BitsPerSample"})) {
    const double b = number(*e, "a bit depth (1..32)", true);
    if (b != std::floor(b) || b > 32) bad(*e, "a bit depth (1..32)");
    m.bits_per_sample = int(b);
    m.source["bits_per_sample"] = e->first;
  }
  if (auto e = first({"Xmp.drone-dji.FlightYawDegree", "Xmp.DLS.Yaw"})) {
    const bool radians = e->first == "Xmp.DLS.Yaw";
    const double v = number(*e, radians ? "a heading in radians" : "a heading in degrees", false);
    const double degrees = radians ? v * 180.0 / std::numbers::pi : v;
    if (std::isfinite(degrees)) {  // (else so large that it overflowed: no heading)
      double d = std::fmod(degrees, 360.0);  // (-360, 360)
      if (d < 0) d += 360.0;
      m.heading_deg = d < 360.0 ? d : 0.0;  // -1e-17 + 360 rounds to 360
      m.source["heading"] = e->first;
    }
  }
  read_gps(kv, m);
  read_time(kv, m);
  if (!dji) level_light_sensor(kv, file, m);
  return m;
}

/// parse_exiv2_kv + capture_meta_from_exiv2.
inline CaptureMeta parse_capture_meta(std::string_view exiv2_text, const std::filesystem::path& file) {
  return capture_meta_from_exiv2(parse_exiv2_kv(exiv2_text), file);
}

}  // namespace msgs::io
