// examples/cmd_import.cpp
// `msgs import`: a folder of raw multi-band captures (MicaSense, DJI Mavic 3M, Parrot Sequoia, or
// explicit file-name patterns) -> the multi-spectral dataset layout: radiometric normalisation from
// the metadata (read with the exiv2 tool), poses and a sparse point cloud from COLMAP (CPU), from
// every pair of images or from the pairs of nearby captures (msgs/io/match_pairs.hpp).
// File-name recognition, metadata parsing and the normalisation maths live in the library
// (msgs/io/capture_names.hpp, capture_meta.hpp, radiometry.hpp); this file runs the tools.
#include <tiffio.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <msgs/io/calibration_panel.hpp>
#include <msgs/io/capture_meta.hpp>
#include <msgs/io/capture_names.hpp>
#include <msgs/io/colmap.hpp>
#include <msgs/io/dataset.hpp>
#include <msgs/io/file.hpp>
#include <msgs/io/frame_json.hpp>
#include <msgs/io/image_io.hpp>
#include <msgs/io/light_sensor_heading.hpp>
#include <msgs/io/match_pairs.hpp>
#include <msgs/io/model_alignment.hpp>
#include <msgs/io/panel_list.hpp>
#include <msgs/io/ply.hpp>
#include <msgs/io/radiometry.hpp>
#include <msgs/io/rig_poses.hpp>

#include "colmap_progress.hpp"
#include "commands.hpp"
#include "subprocess.hpp"

namespace cmd_import {  // this file's own names: the tool's files compile in unity groups
namespace {

namespace fs = std::filesystem;
using msgs::io::cat;
using msgs::io::fail;

constexpr const char* kUsage =
    "usage: msgs import --images DIR --out DIR [--camera auto|micasense|dji|p4m|sequoia]\n"
    "                   [--bands PATTERN=ID,...] [--eval-every N] [--camera-model M]\n"
    "                   [--radiometry auto|none|reflectance|sun-sensor|panel|panel+dls]\n"
    "                   [--panel-albedo A]\n"
    "                   [--panels FILE] [--panel-offset fit|zero]\n"
    "                   [--matching exhaustive|window|gps]\n"
    "                   [--window N] [--neighbours K] [--sift-threshold T] [--ba-tolerance X]\n"
    "                   [--merge-models on|off] [--rig on|off] [--poses-from DATASET]\n"
    "                   [--allow-partial] [--downscales N]\n"
    "                   [--light-sensor-heading report|correct]\n"
    "                   [--force]\n"
    "                   [--colmap BIN] [--exiv2 BIN] [--keep-work]\n"
    "\n"
    "Turn a folder of raw multi-band captures into the multi-spectral dataset layout (transforms.json,\n"
    "train_split.json, images/, sparse_pc.ply) that `msgs train` reads.\n"
    "\n"
    "  1. Captures and bands from the file names: MicaSense RedEdge/Altum IMG_0001_1.tif.._5.tif\n"
    "     (1 Blue, 2 Green, 3 Red, 4 NIR, 5 RedEdge), DJI Mavic 3M DJI_<datetime>_0001_MS_G.TIF,\n"
    "     _MS_R, _MS_RE, _MS_NIR, _D.JPG, DJI P4 Multispectral DJI_0010.JPG (RGB), DJI_0011.TIF (Blue)\n"
    "     .. DJI_0015.TIF (NIR), Parrot Sequoia IMG_<date>_<time>_0001_GRE.TIF, _RED, _REG,\n"
    "     _NIR, _RGB.JPG. Bands msgs has no slot for (blue, thermal) are skipped with a warning.\n"
    "     A central wavelength in the metadata that does not fit the slot (green 490-600 nm, red\n"
    "     600-700, red edge 690-760, NIR 760-1000) stops the import, naming the file.\n"
    "  2. Radiometry from the metadata (exiv2): (DN - black level) / (exposure time x gain x\n"
    "     vignetting x MicaSense's row gradient), then one common factor per band so the band's\n"
    "     brightest value is 1; written as 16-bit PNG and recorded per frame under \"radiometry\"\n"
    "     in transforms.json. Steps whose tags are missing are left out for that band, with a\n"
    "     warning naming the files. A vignetting polynomial is the correction the image is\n"
    "     multiplied by in DJI files and the fall-off it is divided by in all others (keys:\n"
    "     msgs/io/capture_meta.hpp). These values are relative radiance, not reflectance: indices\n"
    "     such as NDVI computed from them are shifted from reflectance-based ones. With\n"
    "     --radiometry reflectance, MicaSense files give reflectance instead: pi x radiance (a1\n"
    "     of RadiometricCalibration) / the horizontal irradiance of the DLS 2 light sensor (a\n"
    "     DLS 1's tilted reading levelled for the sun's place, as MicaSense's library does); with\n"
    "     panel or panel+dls, reflectance from the calibration-panel captures the camera marked;\n"
    "     with sun-sensor, reflectance up to one factor common to all bands from DJI's sunlight\n"
    "     sensor (or MicaSense's DLS 2), so that indices such as NDVI are those of reflectance.\n"
    "     Captures marked as pictures of a calibration panel (Camera:CalibrationPicture) are set\n"
    "     aside in every mode: they are not part of the scene.\n"
    "  3. Poses with COLMAP on the CPU (feature_extractor with one camera per band and the focal\n"
    "     length, and the principal point where the camera writes its calibration, from the\n"
    "     metadata as priors; matching of every pair, of nearby captures by GPS or\n"
    "     of a window of captures; mapper) on contrast-stretched 8-bit copies; the largest model\n"
    "     is the main one. Every image must register or be posed by steps 4 and 5 (else an error\n"
    "     names the ones that did not).\n"
    "  4. Models of the rest: a band that matches its own images but not the other bands makes no\n"
    "     part of the main model. The mapper's other models, then a second run of it on the images\n"
    "     still without a pose, are each carried into the main model's frame by the similarity that\n"
    "     maps their capture centres onto the main model's (at least 3 shared captures, within 0.15\n"
    "     of the capture spacing, not all along one line; captures that disagree are left out).\n"
    "  5. The rig: the lenses of a multi-band camera fire together from fixed mounts, so an image\n"
    "     COLMAP did not register (matching across bands is hard) is placed through a band of its\n"
    "     own capture that registered, with the bands' offset measured on the captures where both\n"
    "     did; captures that disagree with the offset are left out of it, and a band without 3\n"
    "     agreeing captures is not placed. transforms.json says which frames were (\"pose\").\n"
    "Everything is built in a temporary folder beside --out and renamed into place at the end.\n"
    "\n"
    "  --images DIR        folder of captures (searched recursively)\n"
    "  --out DIR           output dataset folder (must not exist unless --force)\n"
    "  --camera C          file-name scheme: auto (default: the one that matches most files),\n"
    "                      micasense, dji (Mavic 3M), p4m (P4 Multispectral), sequoia\n"
    "  --bands LIST        explicit patterns instead: PATTERN=ID,... with * and ? wildcards matching\n"
    "                      the capture number, ID one of D, MS_G, MS_R, MS_RE, MS_NIR or skip,\n"
    "                      e.g. --bands 'IMG_*_2.tif=MS_G,IMG_*_3.tif=MS_R,IMG_*_5.tif=MS_RE,IMG_*_4.tif=MS_NIR'\n"
    "  --eval-every N      every N-th capture (all its bands) goes to eval (default 10; 0: none)\n"
    "  --camera-model M    COLMAP camera model: OPENCV (default), PINHOLE, SIMPLE_RADIAL, RADIAL\n"
    "  --radiometry R      auto (default: use the metadata), none (keep the stored values; the\n"
    "                      focal lengths in the metadata are still COLMAP's priors) or reflectance\n"
    "                      (pi x radiance / irradiance from MicaSense's a1 and its DLS light\n"
    "                      sensor, no band scale: every band image must carry them, else an error;\n"
    "                      values above 1 are clipped, with a warning), panel (reflectance from\n"
    "                      the captures of a calibration panel the camera marked and read:\n"
    "                      CalibrationPicture 2 with the panel's Albedo and ReflectArea; one\n"
    "                      irradiance per band, the mean over the panel's area of the corrected\n"
    "                      DN / albedo), panel+dls (the light sensor, MicaSense's DLS 2, DJI's\n"
    "                      sunlight sensor or the Parrot Sequoia's sunshine sensor, follows the\n"
    "                      light through the flight, the panel sets its level in each band) or\n"
    "                      sun-sensor (each image divided by its light sensor's\n"
    "                      reading and multiplied by the band camera's calibration, DJI's\n"
    "                      SensorGainAdjustment or MicaSense's a1, as DJI's guides compute NDVI;\n"
    "                      then one scale for all bands, the brightest value of any band 1:\n"
    "                      band ratios and indices as from reflectance, the level unknown)\n"
    "  --panel-albedo A    the panel's reflectance, for every band (0.49) or per band\n"
    "                      (MS_G=0.49,MS_R=0.5,...): where Camera:Albedo is missing, or to\n"
    "                      override it with the panel's calibration sheet; not where --panels\n"
    "                      gives a picture its reflectance\n"
    "  --panels FILE       the panel pictures of a camera that does not mark them (DJI, Parrot,\n"
    "                      or a MicaSense that could not read the panel), as JSON:\n"
    "                        {\"albedo\": 0.49, \"pictures\": [{\"file\": \"DJI_0021_MS_G.TIF\",\n"
    "                          \"area\": [[412, 300], [380, 301], [381, 333], [413, 332]]}, ...]}\n"
    "                      file relative to --images; area the corners of the panel's reflecting\n"
    "                      part in that image, x and y in pixels, in order around it; albedo per\n"
    "                      picture or for all (else --panel-albedo or Camera:Albedo). Their\n"
    "                      captures are set aside in every mode; with panel and panel+dls each\n"
    "                      listed picture calibrates its band. List a picture once for each panel\n"
    "                      it shows (a further panel's reflectance comes from the list or\n"
    "                      --panel-albedo, never from Camera:Albedo, the camera's own panel's):\n"
    "                      panels of reflectances 2 times apart or more in one session\n"
    "                      give an empirical line, response = E (albedo + offset), whose offset\n"
    "                      (haze, a black level a little off) every image then loses\n"
    "  --panel-offset O    fit (default): the empirical line's offset where the panels give one;\n"
    "                      zero: the line through zero all the same (a black level and an air\n"
    "                      you trust over the panels); the offset they would give is logged\n"
    "  --matching M        image pairs COLMAP matches: exhaustive (default: every pair; the time\n"
    "                      grows with the square of the image count), window (the bands of a\n"
    "                      capture with each other, and each band with the same band of the next\n"
    "                      --window captures in file-name order: for long flights whose captures\n"
    "                      are numbered along the path; views that come back later are not matched)\n"
    "                      or gps (the bands of a capture with each other, and each band with the\n"
    "                      same band of the --neighbours captures nearest by the GPS positions in\n"
    "                      the metadata: for long flights, whatever their order)\n"
    "  --window N          captures ahead that window matching reaches (default 6: a point on the\n"
    "                      ground is in about 4 to 6 consecutive captures at 75-80% forward overlap)\n"
    "  --neighbours K      nearest captures that gps matching pairs each capture with (default 12:\n"
    "                      about 5 along a survey line times 3 across at 75% / 65% overlap)\n"
    "  --sift-threshold T  SIFT's peak threshold on the 8-bit copies COLMAP matches (default\n"
    "                      0.0067, COLMAP's own; lower finds more features in low-contrast bands:\n"
    "                      try 0.003 when a band's images do not register)\n"
    "  --ba-tolerance X    relative change of the cost at which COLMAP's mapper ends a global\n"
    "                      bundle adjustment (default 1e-6, as 3DGS's convert.py: on a 240-image\n"
    "                      flight 2.3-4.6x faster than 0, COLMAP's own default, which runs each\n"
    "                      one to its iteration limit, with the same poses)\n"
    "  --merge-models M    on (default: step 4) or off (the main model only)\n"
    "  --rig R             on (default: place images COLMAP did not register by the rig, step 5)\n"
    "                      or off (only COLMAP's poses)\n"
    "  --poses-from DATASET  the poses, lenses and sparse points of an earlier import of these\n"
    "                      captures (its folder) in place of steps 3-5: COLMAP does not run, only\n"
    "                      the radiometry is done anew, e.g. to try another --radiometry on a\n"
    "                      flight whose COLMAP run took hours. Each image takes the pose of the\n"
    "                      frame whose \"source\" is its file (relative to --images), which must\n"
    "                      have its band and its size; msgs_import's COLMAP figures are copied.\n"
    "                      Not with the options of steps 3-5 (--camera-model to --rig, --colmap)\n"
    "  --allow-partial     drop images that have no pose (with a warning) instead of failing\n"
    "  --downscales N      also write copies downscaled by 2, 4, .. 2^N (box filter) into images_2/,\n"
    "                      images_4/, .. (0 to 4; default 0), for `msgs train --images images_4`\n"
    "  --light-sensor-heading H  report (default) or correct: with reflectance, sun-sensor and\n"
    "                      panel+dls, each band's light-sensor readings are fitted as a slow change\n"
    "                      in time plus a term in the drone's heading (a sensor that tilts with\n"
    "                      the drone reads more facing the sun); the log gives the heading's effect\n"
    "                      and warns where it stands above the noise, and correct divides it out\n"
    "                      of the readings (6 flight lines and headings 90 degrees apart at least)\n"
    "  --force             replace an existing --out once the new dataset is complete\n"
    "  --colmap BIN        COLMAP executable (default: colmap on PATH)\n"
    "  --exiv2 BIN         exiv2 executable (default: exiv2 on PATH)\n"
    "  --keep-work         keep the temporary folder (COLMAP database, logs) for inspection\n";

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// One image of the import.
struct Item {
  std::size_t capture = 0;  ///< index into the sorted captures
  std::string band;
  fs::path source;          ///< relative to --images
  std::string out_name;     ///< images/<out_name> in the layout
  std::string colmap_name;  ///< <band>/<name>.png under the COLMAP image folder
  msgs::io::CaptureMeta meta;
  msgs::io::FrameRadiometry rad;
  bool radiometry_applied = false;
  int width = 0, height = 0;
  /// What the light sensor's reading was divided by for the drone's heading (--light-sensor-heading
  /// correct); the file's own reading is meta.irradiance times this
  std::optional<double> heading_factor;
};

/// The images of `scan`'s captures in msgs' band order, with their names in the layout and in
/// COLMAP's folder (numbered by capture).
std::vector<Item> scan_items(const msgs::io::CaptureScan& scan) {
  std::vector<Item> items;
  for (std::size_t ci = 0; ci < scan.captures.size(); ++ci)
    for (const auto& b : msgs::io::standard_bands()) {
      const auto it = scan.captures[ci].bands.find(b.id);
      if (it == scan.captures[ci].bands.end()) continue;
      Item item;
      item.capture = ci;
      item.band = b.id;
      item.source = it->second;
      char num[32];
      std::snprintf(num, sizeof num, "_%05zu", ci + 1);
      const bool rgb = b.channels == 3;
      std::string ext = rgb ? it->second.extension().string() : ".png";
      for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
      item.out_name = cat(b.id, num, ext);
      item.colmap_name = cat(b.id, "/", b.id, num, ".png");
      items.push_back(std::move(item));
    }
  return items;
}

/// --panel-albedo: one reflectance for every band ("0.49", key "") or one per band
/// ("MS_G=0.49,MS_R=0.5,..."), each in (0, 1].
std::map<std::string, double> parse_panel_albedo(const std::string& text) {
  std::map<std::string, double> out;
  if (text.empty()) return out;
  const auto value = [&](const std::string& v) {
    const auto x = msgs::io::detail::parse_number(v);
    if (!x || !(*x > 0 && *x <= 1))
      throw msgs::cli::UsageError("--panel-albedo expects reflectances in (0, 1], as 0.49 or MS_G=0.49,MS_R=0.5,...; got '" +
                                  v + "'");
    return *x;
  };
  if (text.find('=') == std::string::npos) {
    out[""] = value(text);
    return out;
  }
  std::size_t i = 0;
  while (i <= text.size()) {
    const std::size_t j = std::min(text.find(',', i), text.size());
    const std::string part = text.substr(i, j - i);
    const std::size_t eq = part.find('=');
    const std::string band = eq == std::string::npos ? part : part.substr(0, eq);
    if (eq == std::string::npos || band == "D" || !msgs::io::find_band(band))
      throw msgs::cli::UsageError(
          "--panel-albedo expects BAND=REFLECTANCE pairs with BAND one of MS_G, MS_R, MS_RE, MS_NIR; got '" + part + "'");
    out[band] = value(part.substr(eq + 1));
    i = j + 1;
  }
  return out;
}

/// The normalisation of an image `r` in words, for transforms.json.
std::string radiometry_formula(const msgs::io::FrameRadiometry& r, bool applied, msgs::io::Calibration calibration) {
  if (!applied) return "value = DN / dn_max (stored values kept: no radiometric metadata)";
  const auto& s = r.steps;
  const std::string response =
      cat(s.sensor_model ? " * (A * exposure_s * ISO + C)" : cat(s.exposure ? " * exposure_s" : "", s.gain ? " * gain" : ""),
          s.vignetting ? " * vignetting(r)" : "", s.row_gradient ? " * (1 + a2 y / exposure_s - a3 y)" : "",
          s.irradiance ? " * light_sensor" : "");
  const std::string dark = s.sensor_model ? (s.vignetting ? " - B * vignetting(r)" : " - B")
                           : s.black_level ? " - black_level"
                                           : "";
  const std::string v = cat("(DN", dark, ")",
                            response.empty() ? "" : " / (" + response.substr(3) + ")", " * scale",
                            r.offset != 0.0 ? " - offset" : "");
  switch (calibration) {
    case msgs::io::Calibration::relative: return "value = " + v;
    case msgs::io::Calibration::sun_sensor: return "reflectance = " + v + ", scale = pi * a1 / (dn_max + 1)";
    case msgs::io::Calibration::sun_sensor_relative:
      return "reflectance up to a factor common to all bands = " + v + ", scale = " +
             (r.radiance_a1 > 0 ? "pi * a1" : "SensorGainAdjustment") +
             " / (dn_max + 1) * one factor for all bands (the brightest value of any band 1)";
    default:
      return "reflectance = " + v + ", scale = 1 / the mean over the band's calibration-panel pictures of the same" +
             " without scale, averaged over the panel's area and divided by its albedo (interpolated linearly in" +
             " time between sessions of panel pictures taken more than 2 minutes apart)" +
             (r.offset != 0.0 ? ", offset = that of the line through the panels of several reflectances (albedo +"
                                " offset in place of the albedo)"
                              : "");
  }
}

/// Bits per sample of a TIFF (0 when it is not a readable TIFF).
int tiff_bits(const fs::path& p) {
  msgs::io::detail::TiffFile tf(p, "r");
  if (!tf.get()) return 0;
  std::uint16_t bits = 0;
  TIFFGetFieldDefaulted(tf.get(), TIFFTAG_BITSPERSAMPLE, &bits);
  return bits;
}

std::string list_some(const std::vector<std::string>& v, std::size_t n = 6) {
  std::string s;
  for (std::size_t i = 0; i < v.size() && i < n; ++i) s += cat(i ? ", " : "", v[i]);
  if (v.size() > n) s += cat(", ... (", v.size(), " in all)");
  return s;
}

/// The values a band's images were written with: a histogram over [0, 1] in steps of 0.001 (values
/// above 1 are clipped to it and counted apart), for the percentiles the log reports.
struct ValueHistogram {
  std::array<std::uint64_t, 1001> bins{};
  std::uint64_t above = 0, pixels = 0;
  void add(float v) {
    ++pixels;
    above += v > 1.0f;
    bins[std::size_t(std::lround(std::clamp(double(v), 0.0, 1.0) * 1000.0))] += 1;
  }
  /// The value below which a share `q` of the pixels lies (to 0.001).
  double quantile(double q) const {
    const double target = q * double(pixels);
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < bins.size(); ++i)
      if (double(seen += bins[i]) >= target && seen > 0) return double(i) / 1000.0;
    return 1.0;
  }
};

/// A multispectral band image as stored (values in [0, 1]) and the digital number of a stored 1.
struct BandImage {
  msgs::Image<float> raw;
  double dn_max = 65535.0;
};

/// Read an image of multispectral band `band`: single channel, 8 or 16 bits (IoError otherwise).
BandImage read_band_image(const fs::path& src, const std::string& band) {
  const int bits = tiff_bits(src);
  if (bits != 8 && bits != 16 && bits != 0)
    fail(src, cat("unsupported ", bits, "-bit samples for a multispectral band (need 8 or 16)"));
  BandImage b{msgs::io::read_image(src), bits == 16 ? 65535.0 : 255.0};
  if (b.raw.channels != 1) fail(src, cat("band ", band, " needs a single-channel image, this one has ", b.raw.channels));
  return b;
}

/// The heading check of `band`'s light-sensor readings (items `idx`, flight captures only;
/// msgs/io/light_sensor_heading.hpp), logged; with `correct`, a significant heading effect is
/// divided out of the readings. What was found as JSON for transforms.json (null where the band's
/// images carry no reading to check).
nlohmann::ordered_json check_light_sensor_heading(const std::string& band, const std::vector<std::size_t>& idx,
                                                  std::vector<Item>& items, bool correct) {
  std::vector<double> reading, time_s, heading;
  std::size_t without = 0;
  for (std::size_t i : idx) {
    const msgs::io::CaptureMeta& m = items[i].meta;
    if (!m.irradiance) return nullptr;  // (the radiometry plan says what is missing)
    if (!m.time_s || !m.heading_deg) {
      ++without;
      continue;
    }
    reading.push_back(*m.irradiance);
    time_s.push_back(*m.time_s);
    heading.push_back(*m.heading_deg);
  }
  nlohmann::ordered_json j;
  if (without > 0) {
    std::printf("  %s: the light sensor's readings not checked against the heading: %zu of %zu images have no"
                " heading or time (Xmp.drone-dji.FlightYawDegree, Xmp.DLS.Yaw; Exif.Photo.DateTimeOriginal)\n",
                band.c_str(), without, idx.size());
    j["problem"] = cat(without, " images without a heading or time");
    return j;
  }
  const msgs::io::HeadingFit fit = msgs::io::fit_heading_bias(reading, time_s, heading);
  j["captures"] = fit.captures;
  j["flight_lines"] = fit.lines;
  if (!fit.problem.empty()) {
    std::printf("  %s: the light sensor's readings not checked against the heading: %s\n", band.c_str(),
                fit.problem.c_str());
    j["problem"] = fit.problem;
    return j;
  }
  const bool significant = fit.significant();
  const bool divided = correct && significant;
  if (divided)
    for (std::size_t k = 0; k < idx.size(); ++k) {
      *items[idx[k]].meta.irradiance /= fit.heading_factor[k];
      items[idx[k]].heading_factor = fit.heading_factor[k];
    }
  std::printf("  %s: the light sensor reads %.1f%% (+- %.1f%%) higher flying %.0f degrees than flying %.0f degrees,"
              " the change in time taken out (%zu captures on %zu flight lines, %.1f%% scatter between lines)%s\n",
              band.c_str(), 100.0 * (fit.ratio - 1.0), 100.0 * fit.ratio * fit.ratio_log_se, fit.high_heading_deg,
              fit.low_heading_deg, fit.captures, fit.lines, 100.0 * fit.scatter,
              divided        ? ": divided out"
              : significant ? ""
                            : ": within the noise, kept");
  if (significant && !correct)
    std::printf("  warning: %s: images taken on one heading come out %.1f%% darker than on the other;"
                " --light-sensor-heading correct divides the heading's part out of the readings\n",
                band.c_str(), 100.0 * (fit.ratio - 1.0));
  j["ratio"] = fit.ratio;
  j["ratio_log_standard_error"] = fit.ratio_log_se;
  j["high_heading_deg"] = fit.high_heading_deg;
  j["low_heading_deg"] = fit.low_heading_deg;
  j["scatter"] = fit.scatter;
  j["degrees_of_freedom"] = fit.degrees_of_freedom;
  j["significant"] = significant;
  j["divided_out"] = divided;
  return j;
}

/// The panel pictures (indices into `panels`) that can calibrate `band`: those the camera read
/// (Xmp.Camera.CalibrationPicture 2) with the panel's area (Xmp.Camera.ReflectArea). IoError when
/// there is none, saying why.
std::vector<std::size_t> usable_panels(const std::vector<Item>& panels, const std::string& band, const fs::path& images,
                                       const std::string& radiometry) {
  std::vector<std::size_t> use;
  std::vector<std::string> why;
  for (std::size_t k = 0; k < panels.size(); ++k) {
    const Item& p = panels[k];
    if (p.band != band) continue;
    if (p.meta.calibration_picture == 2 && p.meta.panel_area) use.push_back(k);
    else
      why.push_back(cat(p.source.generic_string(), p.meta.calibration_picture != 2
                                                       ? " (CalibrationPicture 1: the camera could not read the panel)"
                                                       : " (no Xmp.Camera.ReflectArea)"));
  }
  if (use.empty())
    fail(images, cat("--radiometry ", radiometry, " needs a picture of the calibration panel in band ", band,
                     " that the camera read (Xmp.Camera.CalibrationPicture 2, the panel's area in Xmp.Camera.ReflectArea)",
                     " or that --panels lists; ",
                     !why.empty()      ? "these are not: " + list_some(why, 3)
                     : panels.empty() ? std::string("no capture in --images is marked as one")
                                      : std::string("no panel capture holds this band"),
                     "\n  msgs does not search images for a panel: list the panel pictures and their areas with",
                     " --panels FILE (see msgs import --help), or use --radiometry reflectance (MicaSense's DLS 2 alone),",
                     " sun-sensor (the light sensor alone, band ratios only) or auto (relative radiance)"));
  return use;
}

/// The irradiance of `band` through the flight from its panel pictures `use`
/// (msgs/io/calibration_panel.hpp), in the sensor's units: an image's scale is 1 / its value at
/// the image's time, less the empirical line's offset where panels of several reflectances give
/// one and `fit_offset` (--panel-offset fit) lets it. Each picture is logged and appended to
/// `report`, the line to `line_report`.
msgs::io::PanelSchedule calibrate_with_panels(std::vector<Item>& panels, const std::vector<std::size_t>& use,
                                              const std::string& band, const msgs::io::RadiometrySteps& steps,
                                              const std::map<std::string, double>& albedo_arg, bool fit_offset,
                                              const fs::path& images, nlohmann::ordered_json& report,
                                              nlohmann::ordered_json& line_report) {
  struct Picture {
    double albedo = 0.0;
    std::string albedo_from;
    msgs::io::PanelReading reading;
  };
  std::vector<Picture> pictures;
  std::vector<msgs::io::PanelResponse> responses;
  std::set<double> replaced;  // the pictures' own Camera:Albedo that --panel-albedo replaced
  for (std::size_t k : use) {
    Item& p = panels[k];
    const fs::path src = images / p.source;
    Picture pic;
    // A reflectance --panels gives this picture, else --panel-albedo's for the band, else the camera's.
    const bool listed = p.meta.panel_albedo && p.meta.source.at("panel_albedo") == "--panels";
    if (const auto a = albedo_arg.count(band) ? albedo_arg.find(band) : albedo_arg.find("");
        !listed && a != albedo_arg.end()) {
      pic.albedo = a->second;
      pic.albedo_from = "--panel-albedo";
      if (p.meta.panel_albedo) replaced.insert(*p.meta.panel_albedo);
    } else if (p.meta.panel_albedo) {
      pic.albedo = *p.meta.panel_albedo;
      pic.albedo_from = p.meta.source.at("panel_albedo");
    } else {
      fail(src, "Xmp.Camera.Albedo",
           "missing: the panel's reflectance in this band is not known (give it from the panel's calibration sheet"
           " with --panel-albedo 0.49, or per band --panel-albedo MS_G=0.49,MS_R=0.49,...)");
    }
    const BandImage img = read_band_image(src, band);
    p.rad = msgs::io::frame_radiometry(p.meta, steps, img.dn_max, img.raw.width, img.raw.height);
    pic.reading = msgs::io::read_panel(img.raw, p.rad, *p.meta.panel_area, src);
    responses.push_back({pic.reading.mean, pic.albedo, p.meta.time_s});
    pictures.push_back(pic);
  }
  if (replaced.size() > 1) {
    std::string own;
    for (double a : replaced) own += cat(own.empty() ? "" : ", ", msgs::io::short_number(a, 4));
    std::printf("  warning: %s: --panel-albedo gives one reflectance to panels the camera marks as of several"
                " (%s, Xmp.Camera.Albedo): give each panel its own in --panels, or leave --panel-albedo out\n",
                band.c_str(), own.c_str());
  }
  // Panels of several reflectances: the empirical line's offset (0 where they do not give one, or
  // where --panel-offset zero keeps the line through zero).
  msgs::io::PanelLine line = msgs::io::panel_line(responses);
  const bool forced_through_zero = line.fitted() && !fit_offset;
  if (line.fitted()) {
    const char* const sessions = line.sessions == 1 ? "" : "s";
    if (forced_through_zero)
      std::printf("  %s: panels of reflectance %.3g to %.3g in %zu session%s would give an offset of %.4g;"
                  " --panel-offset zero keeps the line through zero\n",
                  band.c_str(), line.low_albedo, line.high_albedo, line.sessions, sessions, line.offset);
    else
      std::printf("  %s: panels of reflectance %.3g to %.3g in %zu session%s lie on a line with an offset of %.4g:"
                  " each image's reflectance is response / E %s %.4g\n",
                  band.c_str(), line.low_albedo, line.high_albedo, line.sessions, sessions, line.offset,
                  line.offset < 0 ? "+" : "-", std::abs(line.offset));
    line_report["offset"] = forced_through_zero ? 0.0 : line.offset;
    if (forced_through_zero) line_report["fitted_offset_not_used"] = line.offset;
    line_report["sessions"] = line.sessions;
    line_report["albedo_range"] = {line.low_albedo, line.high_albedo};
    if (forced_through_zero) line.offset = 0.0;
  } else if (!line.problem.empty()) {  // panels of several reflectances that give no line: say why
    std::printf("  warning: %s: no empirical line from the panels: %s; the line through zero is used\n", band.c_str(),
                line.problem.c_str());
    line_report["problem"] = line.problem;
  }
  std::vector<msgs::io::PanelIrradiance> readings;
  for (std::size_t u = 0; u < use.size(); ++u) {
    Item& p = panels[use[u]];
    const Picture& pic = pictures[u];
    const double e = pic.reading.mean / (pic.albedo + line.offset);
    p.rad.scale = 1.0 / e;
    readings.push_back({e, p.meta.time_s});
    const double watts = msgs::io::reflectance_irradiance(p.rad);  // 0 without MicaSense's a1
    std::printf("  %s: panel %s, albedo %.4g (%s), %zu px: %s%s\n", band.c_str(), p.source.generic_string().c_str(),
                pic.albedo, pic.albedo_from.c_str(), pic.reading.pixels,
                watts > 0 ? cat("irradiance ", msgs::io::short_number(watts, 4), " W/m^2/nm").c_str()
                          : cat("irradiance ", msgs::io::short_number(e, 4), " in the sensor's units").c_str(),
                steps.irradiance ? cat(", the light sensor read ", msgs::io::short_number(p.rad.irradiance, 4),
                                       p.meta.irradiance_si ? " W/m^2/nm" : " (its own units)")
                                       .c_str()
                                 : "");
    nlohmann::ordered_json j;
    j["band"] = band;
    j["source"] = p.source.generic_string();
    j["albedo"] = pic.albedo;
    j["albedo_from"] = pic.albedo_from;
    j["area"] = *p.meta.panel_area;
    j["pixels"] = pic.reading.pixels;
    j["saturated_pixels"] = pic.reading.saturated;
    j["mean_response"] = pic.reading.mean;
    if (p.meta.time_s) j["time_s"] = *p.meta.time_s;
    if (watts > 0) j["irradiance_w_m2_nm"] = watts;
    if (steps.irradiance) j[p.meta.irradiance_si ? "light_sensor_w_m2_nm" : "light_sensor"] = p.rad.irradiance;
    if (!p.meta.panel_serial.empty()) j["panel_serial"] = p.meta.panel_serial;
    report.push_back(j);
  }
  msgs::io::PanelSchedule schedule = msgs::io::panel_schedule(readings);
  schedule.offset = line.offset;
  // Pictures that should agree (one session, or all of them when there are no sessions in time).
  std::vector<double> lo(schedule.nodes.size(), 1e300), hi(schedule.nodes.size(), 0.0);
  for (const auto& r : readings) {
    std::size_t k = 0;
    if (schedule.timed())
      while (k + 1 < schedule.nodes.size() && *r.time_s > 0.5 * (schedule.nodes[k][0] + schedule.nodes[k + 1][0])) ++k;
    lo[k] = std::min(lo[k], r.e);
    hi[k] = std::max(hi[k], r.e);
  }
  for (std::size_t k = 0; k < lo.size(); ++k)
    if (hi[k] > 1.05 * lo[k])
      std::printf("  warning: %s: %s panel pictures disagree by %.3g%% (%s); their mean is used\n", band.c_str(),
                  schedule.timed() ? "one session's" : cat("the ", use.size()).c_str(), 100.0 * (hi[k] / lo[k] - 1.0),
                  forced_through_zero ? "the offset of their line, which --panel-offset zero leaves in?"
                  : steps.irradiance  ? "after the light sensor's readings: a shaded or tilted panel?"
                  : schedule.timed()
                      ? "the light changed between them? --radiometry panel+dls follows it with the light sensor"
                      : "the light changed between them? Pictures before and after the flight (more than 2 minutes"
                        " apart, with capture times) are interpolated in time; --radiometry panel+dls follows the"
                        " light with the light sensor");
  if (schedule.timed()) {
    // In W/m^2/nm where MicaSense's a1 gives them, as the pictures above (with the light sensor,
    // the nodes are the panel's irradiance per unit of its reading: no unit).
    const double watts_per_unit =
        steps.irradiance ? 0.0 : msgs::io::reflectance_irradiance(panels[use[0]].rad) * panels[use[0]].rad.scale;
    std::string nodes;
    for (const auto& n : schedule.nodes) {
      const long t = std::lround(n[0]) % 86400;
      char clock[16];
      std::snprintf(clock, sizeof clock, "%02ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
      nodes += cat(nodes.empty() ? "" : ", ",
                   watts_per_unit > 0 ? cat(msgs::io::short_number(n[1] * watts_per_unit, 4), " W/m^2/nm")
                                      : msgs::io::short_number(n[1], 4),
                   " at ", clock);
    }
    std::printf("  %s: the panel's irradiance interpolated in time between %zu sessions (%s)\n", band.c_str(),
                schedule.nodes.size(), nodes.c_str());
  }
  return schedule;
}

/// Copies of `img` (images/`name` of the layout) downscaled by 2, 4, .. 2^`levels` into images_2/,
/// images_4/, ..: 16-bit PNG for a band's normalised values (`sixteen_bit`), else by the name's
/// extension (a JPEG for the RGB camera's JPEG, an 8-bit PNG otherwise). load_frame_image reads them.
void write_downscaled(const fs::path& layout, const std::string& name, const msgs::Image<float>& img, long levels,
                      bool sixteen_bit) {
  const std::string ext = msgs::io::detail::lower_extension(name);
  for (long k = 1; k <= levels; ++k) {
    const int f = 1 << k;
    const fs::path p = layout / cat("images_", f) / name;
    std::error_code ec;
    fs::create_directories(p.parent_path(), ec);
    const msgs::Image<float> small = msgs::io::downscale(img, f);
    if (sixteen_bit) msgs::io::write_png16(p, small);
    else if (ext == ".jpg" || ext == ".jpeg") msgs::io::write_jpeg(p, small, 95);
    else msgs::io::write_png8(p, small);
  }
}

/// A colmap stage with progress, timing, log and the log's tail on failure.
double run_colmap(const std::string& colmap, const std::string& stage, std::vector<std::string> args,
                  const fs::path& log, std::size_t images) {
  std::printf("  colmap %-18s ...", stage.c_str());
  std::fflush(stdout);
  const auto t = Clock::now();
  std::error_code size_ec;
  const std::uintmax_t log_start = fs::exists(log, size_ec) ? fs::file_size(log, size_ec) : 0;  // this stage's lines follow
  // A stage that runs long says how far it has come, every kReportEvery seconds.
  constexpr double kReportEvery = 30;
  double next_report = kReportEvery;
  bool reported = false;
  const auto report = [&] {
    const double elapsed = since(t);
    if (elapsed < next_report) return;
    next_report = elapsed + kReportEvery;
    if (const auto p = msgs::cli::colmap_progress(msgs::cli::file_tail(log, 16384, size_ec ? 0 : log_start), images)) {
      std::printf("\n    %4.0f s: %s", elapsed, p->c_str());
      std::fflush(stdout);
      reported = true;
    }
  };
  args.insert(args.begin(), {colmap, stage});
  {
    std::FILE* f = std::fopen(log.c_str(), "a");
    if (f) {
      std::string line;
      for (const auto& a : args) line += a + " ";
      std::fprintf(f, "\n==== %s\n", line.c_str());
      std::fclose(f);
    }
  }
  // A COLMAP run that uses no CPU for a minute is deadlocked (COLMAP 3.8's feature extractor
  // sometimes is, at random): kill it and run the stage again, once.
  constexpr double kIdleLimit = 60;
  int rc = msgs::cli::run_process(args, log, log, kIdleLimit, report);
  if (rc == msgs::cli::kProcessHung) {
    std::printf(" no progress for %.0f s, killed; again ...", kIdleLimit);
    std::fflush(stdout);
    rc = msgs::cli::run_process(args, log, log, kIdleLimit, report);
  }
  const double s = since(t);
  if (rc == msgs::cli::kProcessHung) {
    std::printf(" no progress again\n");
    std::fflush(stdout);
    throw msgs::io::IoError(cat("colmap ", stage, " used no CPU time for ", kIdleLimit,
                                " s, twice, and was stopped (a deadlocked COLMAP; run msgs import again, or "
                                "update COLMAP); last lines of its log:\n",
                                msgs::cli::tail_lines(log, 25)));
  }
  if (rc != 0) {
    std::printf(" failed (exit %d) after %.1f s\n", rc, s);
    std::fflush(stdout);
    const std::string hint =
        stage == "mapper" ? "\n  (no initial pair or too few matches: images too small (COLMAP needed >= 160 px wide "
                            "for the synthetic captures), too little texture or overlap, or too few captures?)"
                          : "";
    throw msgs::io::IoError(cat("colmap ", stage, " failed with exit status ", rc, "; last lines of its log",
                                " (--keep-work keeps the whole log):\n", msgs::cli::tail_lines(log, 25), hint));
  }
  if (reported) std::printf("\n    done in %.1f s\n", s);
  else std::printf(" %6.1f s\n", s);
  std::fflush(stdout);
  return s;
}

/// 8-bit copy for SIFT: each image stretched from its 0.5th to 99.5th percentile to [0, 1] (the
/// normalised bands can be dark; SIFT's contrast threshold is absolute).
msgs::Image<float> sift_copy(const msgs::Image<float>& img) {
  std::vector<float> v = img.data;
  if (v.empty()) return img;
  const std::size_t lo = v.size() / 200, hi = v.size() - 1 - v.size() / 200;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(lo), v.end());
  const float a = v[lo];
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(hi), v.end());
  const float b = v[hi];
  msgs::Image<float> out = img;
  const float k = b > a ? 1.0f / (b - a) : 1.0f;
  for (float& x : out.data) x = std::clamp((x - a) * k, 0.0f, 1.0f);
  return out;
}

nlohmann::ordered_json opt_number(const std::optional<double>& v) {
  return v ? nlohmann::ordered_json(*v) : nlohmann::ordered_json(nullptr);
}

/// Each capture's position in metres (east, north, up of the first capture), the mean of the GPS
/// positions of its images. A capture without one is an error naming its files and what was wrong.
std::vector<std::array<double, 3>> capture_positions(const std::vector<Item>& items, std::size_t captures,
                                                     const fs::path& images) {
  std::vector<std::array<double, 3>> sum(captures, {0.0, 0.0, 0.0});
  std::vector<int> n(captures, 0);
  std::vector<std::string> missing;
  for (const Item& it : items) {
    if (!it.meta.gps) {
      missing.push_back(cat(it.source.generic_string(), " (",
                            it.meta.gps_problem.empty() ? "no GPS tags" : it.meta.gps_problem, ")"));
      continue;
    }
    for (int a = 0; a < 3; ++a) sum[it.capture][std::size_t(a)] += (*it.meta.gps)[std::size_t(a)];
    ++n[it.capture];
  }
  std::vector<std::string> lacking;
  for (std::size_t c = 0; c < captures; ++c)
    if (n[c] == 0) lacking.push_back(cat("capture ", c + 1));
  if (!lacking.empty())
    fail(images, cat("--matching gps needs a GPS position for every capture; ", lacking.size(), " have none: ",
             list_some(lacking), "; files without one: ", list_some(missing, 4),
             "\n  (--matching window pairs captures by their order instead)"));
  std::vector<std::array<double, 3>> pos(captures);
  for (std::size_t c = 0; c < captures; ++c)
    for (int a = 0; a < 3; ++a) pos[c][std::size_t(a)] = sum[c][std::size_t(a)] / n[c];
  const double lat0 = pos[0][0], lon0 = pos[0][1];
  for (auto& p : pos) p = msgs::io::local_metres(p, lat0, lon0);
  return pos;
}

/// A COLMAP image's pose as a RigPose.
msgs::io::RigPose pose_of(const msgs::io::ColmapImage& im) {
  return msgs::io::RigPose{im.camera.R.cast<double>(), im.camera.t.cast<double>()};
}

/// Images the rig placed (step 5 of the usage): COLMAP records with their band's intrinsics and
/// the rig's pose, the band of its capture each was placed from, and the rig for transforms.json.
struct RigResult {
  msgs::io::Rig rig;
  std::vector<msgs::io::ColmapImage> images;
  std::map<std::string, std::string> from;  ///< COLMAP image name -> the band it was placed from
  nlohmann::ordered_json report;
};

/// Places the images of `items` missing from `registered` by the rig of the registered ones.
RigResult place_unregistered(const std::vector<Item>& items, std::size_t captures,
                             const std::map<std::string, std::vector<std::size_t>>& by_band,
                             const std::map<std::string, const msgs::io::ColmapImage*>& registered) {
  RigResult r;
  std::vector<std::string> bands;
  std::map<std::string, std::size_t> band_index;
  for (const auto& entry : by_band) {
    band_index[entry.first] = bands.size();
    bands.push_back(entry.first);
  }
  const std::size_t B = bands.size();
  std::vector<std::vector<std::optional<msgs::io::RigPose>>> poses(captures, std::vector<std::optional<msgs::io::RigPose>>(B));
  std::vector<std::vector<const Item*>> item_at(captures, std::vector<const Item*>(B, nullptr));
  std::vector<const msgs::io::ColmapImage*> of_band(B, nullptr);  // a registered image of each band: its intrinsics
  for (const Item& it : items) {
    const std::size_t b = band_index.at(it.band);
    item_at[it.capture][b] = &it;
    const auto reg = registered.find(it.colmap_name);
    if (reg == registered.end()) continue;
    poses[it.capture][b] = pose_of(*reg->second);
    if (!of_band[b]) of_band[b] = reg->second;
  }
  r.rig = msgs::io::estimate_rig(poses, B, bands);
  std::vector<std::size_t> placed_per_band(B, 0);
  for (const auto& p : msgs::io::place_by_rig(poses, r.rig)) {
    const Item* it = item_at[p.capture][p.band];
    if (!it) continue;  // the capture has no image of that band
    msgs::io::ColmapImage im = *of_band[p.band];  // the band has an offset, so an image of it registered
    im.id = 0;
    im.name = it->colmap_name;
    im.camera.R = poses[p.capture][p.band]->R.cast<float>();
    im.camera.t = poses[p.capture][p.band]->t.cast<float>();
    r.images.push_back(im);
    r.from[it->colmap_name] = bands[p.from];
    ++placed_per_band[p.band];
  }
  if (r.rig.reference < 0) return r;
  r.report["reference"] = bands[std::size_t(r.rig.reference)];
  r.report["capture_spacing"] = r.rig.capture_spacing;
  std::string line;
  for (std::size_t b = 0; b < B; ++b) {
    if (!r.rig.bands[b] || int(b) == r.rig.reference) continue;
    const msgs::io::RigOffset& o = *r.rig.bands[b];
    nlohmann::ordered_json j;
    j["captures"] = o.samples;
    j["agreeing"] = o.inliers;
    j["rotation_spread_deg"] = o.rotation_spread_deg;
    j["translation_spread_of_spacing"] = o.translation_spread;
    j["placed"] = placed_per_band[b];
    r.report["bands"][bands[b]] = j;
    if (placed_per_band[b] > 0) {
      char agree[96];
      std::snprintf(agree, sizeof agree, "%.3f degrees and %.2f%%", o.rotation_spread_deg, 100.0 * o.translation_spread);
      line += cat("\n    ", bands[b], ": ", placed_per_band[b], " placed; offset from ", o.inliers, " of ", o.samples,
                  " captures, which agree within ", agree, " of the capture spacing");
    }
  }
  r.report["problems"] = r.rig.problems;
  if (!r.images.empty())
    std::printf("  rig (reference %s): placed %zu image%s COLMAP did not register, through %s capture's other bands:%s\n",
                bands[std::size_t(r.rig.reference)].c_str(), r.images.size(), r.images.size() == 1 ? "" : "s",
                r.images.size() == 1 ? "its" : "their", line.c_str());
  return r;
}

/// Models of the images the main model lacks (step 4 of the usage): first the other models COLMAP's
/// first mapper run made, then the mapper once more on the images still without a pose; each model
/// carried into the main model's frame through the captures both hold
/// (msgs/io/model_alignment.hpp).
struct MergeResult {
  std::vector<msgs::io::ColmapImage> images;  ///< carried over, posed in the main frame
  msgs::io::PointCloud points;                ///< the carried models' points, in the main frame
  std::map<std::string, std::string> from;    ///< COLMAP image name -> its "pose" in transforms.json
  nlohmann::ordered_json report;
  std::vector<std::string> problems;
  double seconds = 0;
};

/// A model COLMAP's mapper wrote, and its folder.
struct MapperModel {
  fs::path dir;
  msgs::io::ColmapModel model;
};

/// Models in COLMAP's numbered folders under `dir`, largest first (ties in folder order).
std::vector<MapperModel> read_models(const fs::path& dir) {
  std::error_code ec;
  std::vector<fs::path> dirs;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_directory()) dirs.push_back(e.path());
  std::sort(dirs.begin(), dirs.end());
  std::vector<MapperModel> models;
  for (const fs::path& d : dirs) models.push_back({d, msgs::io::read_colmap(d)});
  std::stable_sort(models.begin(), models.end(),
                   [](const auto& a, const auto& b) { return a.model.images.size() > b.model.images.size(); });
  return models;
}

MergeResult merge_rest_models(const std::vector<Item>& items, std::size_t captures,
                              const std::map<std::string, const msgs::io::ColmapImage*>& registered,
                              const std::vector<MapperModel>& first_run_others, const std::string& colmap,
                              const fs::path& work, const fs::path& log, const std::string& ba_tolerance) {
  MergeResult r;  // r.report stays null until a model is tried
  const msgs::io::AlignTolerance tol;
  std::map<std::string, const Item*> item_of;
  std::set<std::size_t> main_captures;
  for (const Item& it : items) {
    item_of[it.colmap_name] = &it;
    if (registered.count(it.colmap_name)) main_captures.insert(it.capture);
  }
  std::set<std::string> taken;  // a model tried later never overrides an earlier one
  // The import's item of a model's image that still needs a pose; nullptr otherwise.
  const auto needing_pose = [&](const std::string& name) -> const Item* {
    const auto it = item_of.find(name);
    return it == item_of.end() || registered.count(name) || taken.count(name) ? nullptr : it->second;
  };
  std::vector<std::pair<std::size_t, msgs::io::RigPose>> main_cameras;
  for (const auto& [name, im] : registered)
    if (const auto it = item_of.find(name); it != item_of.end()) main_cameras.emplace_back(it->second->capture, pose_of(*im));
  const msgs::io::CaptureCentres main_centres = msgs::io::capture_centres(main_cameras, captures);

  const auto carry = [&](const msgs::io::ColmapModel& m) {
    std::vector<std::pair<std::size_t, msgs::io::RigPose>> cameras;
    std::map<std::string, int> bands;
    for (const auto& im : m.images)
      if (const Item* item = needing_pose(im.name)) {
        cameras.emplace_back(item->capture, pose_of(im));
        ++bands[item->band];
      }
    if (cameras.empty()) return;
    std::string band_list;
    for (const auto& [b, n] : bands) band_list += cat(band_list.empty() ? "" : ", ", b, " ", n);
    const msgs::io::ModelAlignment a =
        msgs::io::align_by_captures(main_centres, msgs::io::capture_centres(cameras, captures), tol);
    nlohmann::ordered_json j;
    j["images"] = cameras.size();
    j["bands"] = bands;
    j["shared_captures"] = a.shared;
    j["agreeing"] = a.agreeing;
    const std::string what = cat("a model of ", cameras.size(), " images (", band_list, ")");
    if (!a.to_main) {
      j["problem"] = a.problem;
      r.report.push_back(j);
      r.problems.push_back(cat(what, " ", a.problem));
      return;
    }
    j["median_residual_of_spacing"] = a.median_residual;
    j["max_residual_of_spacing"] = a.max_residual;
    j["scale"] = a.to_main->scale;
    const std::set<std::size_t> disagreeing(a.disagreeing.begin(), a.disagreeing.end());
    std::size_t carried = 0, left = 0;
    for (const auto& im : m.images) {
      const Item* item = needing_pose(im.name);
      if (!item) continue;
      if (disagreeing.count(item->capture)) {
        ++left;  // registered elsewhere in this model than in the main one
        continue;
      }
      msgs::io::ColmapImage c = im;
      const msgs::io::RigPose p = msgs::io::pose_in_main_frame(pose_of(im), *a.to_main);
      c.id = 0;
      c.camera.R = p.R.cast<float>();
      c.camera.t = p.t.cast<float>();
      r.images.push_back(c);
      r.from[im.name] = cat("colmap, model of the rest aligned by ", a.agreeing, " captures");
      taken.insert(im.name);
      ++carried;
    }
    j["carried"] = carried;
    j["left_disagreeing"] = left;
    r.report.push_back(j);
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      const Eigen::Vector3d x = (*a.to_main)(Eigen::Vector3d(m.points.xyz[3 * i], m.points.xyz[3 * i + 1], m.points.xyz[3 * i + 2]));
      for (int d = 0; d < 3; ++d) r.points.xyz.push_back(float(x[d]));
      for (int d = 0; d < 3 && m.points.has_colour(); ++d) r.points.rgb.push_back(m.points.rgb[3 * i + std::size_t(d)]);
    }
    char fit[128];
    std::snprintf(fit, sizeof fit, "within %.3f of the capture spacing (median %.3f)", a.max_residual, a.median_residual);
    std::printf("  carried %zu images of %s into the main model, aligned by %zu of %zu shared captures %s%s\n", carried,
                what.c_str(), a.agreeing, a.shared, fit,
                left ? cat("; ", left, " left out (their captures disagree)").c_str() : "");
  };
  // 1. The first run's other models: the mapper often already made the model of the bands the
  // main one lacks, and a second run on them alone can fail to start one.
  for (const auto& m : first_run_others) carry(m.model);

  // 2. The mapper on the images still without a pose.
  std::vector<const Item*> rest;
  std::set<std::size_t> rest_captures;
  for (const Item& it : items)
    if (needing_pose(it.colmap_name)) {
      rest.push_back(&it);
      rest_captures.insert(it.capture);
    }
  // A model of fewer captures could not be aligned: those images are the rig's.
  if (rest_captures.size() < tol.min_captures) return r;
  // Only a capture with images on both sides can be in the main model and in a model of the rest:
  // with fewer such captures than an alignment needs, the mapper would run for nothing.
  std::size_t split = 0;
  for (std::size_t c : rest_captures) split += main_captures.count(c);
  if (split < tol.min_captures) {
    r.problems.push_back(cat("the ", rest.size(), " images the main model lacks are in ", rest_captures.size(),
                             " captures, of which ", split, " have images in the main model; ", tol.min_captures,
                             " needed to align a model of them (whole captures are missing: too little overlap, or ",
                             "their pairs were not matched)"));
    return r;
  }
  std::string list;
  for (const Item* it : rest) list += it->colmap_name + "\n";
  const fs::path list_path = work / "rest_images.txt", out = work / "sparse_rest";
  msgs::io::write_text_atomic(list_path, list);
  std::error_code ec;
  fs::create_directories(out, ec);
  std::printf("  %zu images in %zu captures are not in the main model: the mapper on them alone\n", rest.size(),
              rest_captures.size());
  try {
    r.seconds = run_colmap(colmap, "mapper",
                           {"--database_path", (work / "database.db").string(), "--image_path", (work / "images").string(),
                            "--output_path", out.string(), "--image_list_path", list_path.string(),
                            "--Mapper.ba_global_function_tolerance", ba_tolerance},
                           log, rest.size());
  } catch (const msgs::io::IoError&) {  // no model among them: say so, and leave them to the rig
    r.problems.push_back(cat("the mapper made no model of the ", rest.size(), " images the main model lacks"));
    return r;
  }
  const std::vector<MapperModel> models = read_models(out);
  if (models.empty()) r.problems.push_back(cat("the mapper made no model of the ", rest.size(), " images the main model lacks"));
  for (const auto& m : models) carry(m.model);
  return r;
}

/// --poses-from: an earlier import of the same captures, whose poses stand in for COLMAP's.
struct GivenPoses {
  fs::path root, transforms;
  nlohmann::ordered_json frames;                 ///< its transforms.json's frames
  std::map<std::string, std::size_t> by_source;  ///< a frame's "source" -> its index in frames
  nlohmann::ordered_json report;                 ///< its msgs_import entries on how the poses were found
  std::vector<unsigned char> points;             ///< its sparse point cloud, the file's bytes
};

/// The keys of a frame that make its camera and pose, in the order msgs import writes them.
constexpr const char* kPoseKeys[] = {"fl_x", "fl_y", "cx", "cy", "w",  "h",  "camera_model",     "k1",
                                     "k2",   "k3",   "k4", "p1", "p2", "transform_matrix", "pose"};
/// The entries of transforms.json's msgs_import that say how the poses were found.
constexpr const char* kPoseReportKeys[] = {"registered",           "from_models_of_the_rest", "models_of_the_rest",
                                           "placed_by_rig",        "rig",
                                           "mean_reprojection_error_px", "colmap_camera_model",
                                           "colmap_sift_peak_threshold", "colmap_ba_global_function_tolerance",
                                           "colmap_matching"};

/// The dataset folder `root` as --poses-from, checked as `msgs train` checks a dataset (errors
/// name its transforms.json and the field), with a sparse point cloud and every frame's source
/// file, once each. Read whole before the import starts, so --out may be `root` (with --force).
GivenPoses read_given_poses(const fs::path& root) {
  GivenPoses g;
  g.root = root;
  g.transforms = root / "transforms.json";
  const std::string what = "the --poses-from dataset";
  std::error_code ec;
  if (!fs::is_directory(root, ec)) fail(root, cat(what, " does not exist or is not a folder"));
  const msgs::io::Dataset ds = msgs::io::load_dataset(root);
  if (ds.points.size() == 0)
    fail(g.transforms, "ply_file_path",
         cat("no sparse point cloud in ", what, ": --poses-from takes the points training starts from with the poses"));
  const auto tf = nlohmann::ordered_json::parse(msgs::io::detail::strip_trailing_commas(msgs::io::read_text(g.transforms)));
  g.frames = tf["frames"];
  for (std::size_t i = 0; i < g.frames.size(); ++i) {
    auto& f = g.frames[i];
    for (const char* key : kPoseKeys)  // intrinsics given once for all frames, as load_dataset takes them
      if (!f.contains(key) && tf.contains(key)) f[key] = tf[key];
    const std::string field = cat("frames[", i, "].source");
    if (!f.contains("source") || !f["source"].is_string())
      fail(g.transforms, field,
           "missing: --poses-from finds an image's pose by the file it came from, which msgs import writes as "
           "\"source\" (relative to its --images); give every frame one");
    const std::string src = fs::path(f["source"].get<std::string>()).lexically_normal().generic_string();
    if (const auto [at, added] = g.by_source.emplace(src, i); !added)
      fail(g.transforms, field, cat("'", src, "' is the source of frames[", at->second, "] too"));
  }
  if (tf.contains("msgs_import") && tf["msgs_import"].is_object())
    for (const char* k : kPoseReportKeys)
      if (tf["msgs_import"].contains(k)) g.report[k] = tf["msgs_import"][k];
  g.points = msgs::io::read_bytes(root / tf.value("ply_file_path", std::string("sparse_pc.ply")));
  return g;
}

int run_import(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(argv,
                             {"images", "out", "camera", "bands", "eval-every", "camera-model", "radiometry", "panel-albedo", "panels", "matching",
                              "window", "neighbours", "sift-threshold", "ba-tolerance", "merge-models", "rig", "colmap", "exiv2",
                              "downscales", "light-sensor-heading", "panel-offset", "poses-from"},
                             {"force", "allow-partial", "keep-work", "help"});
  if (args.flag("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  const auto t_start = Clock::now();
  const fs::path images = fs::absolute(args.require("images")).lexically_normal();
  fs::path out = fs::absolute(args.require("out")).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();
  const std::string camera = args.get("camera", "auto");
  if (camera != "auto" && camera != "micasense" && camera != "dji" && camera != "p4m" && camera != "sequoia")
    throw msgs::cli::UsageError("--camera expects auto, micasense, dji, p4m or sequoia, got '" + camera + "'");
  std::vector<msgs::io::BandPattern> patterns;
  if (args.has("bands")) {
    try {
      patterns = msgs::io::parse_band_patterns(args.get("bands"));
    } catch (const std::invalid_argument& e) {
      throw msgs::cli::UsageError(e.what());
    }
  }
  const long eval_every = args.integer("eval-every", 10);
  if (eval_every < 0) throw msgs::cli::UsageError("--eval-every expects a non-negative integer");
  const std::string model = args.get("camera-model", "OPENCV");
  const std::map<std::string, int> model_params = {{"OPENCV", 8}, {"PINHOLE", 4}, {"SIMPLE_RADIAL", 4}, {"RADIAL", 5}};
  if (!model_params.count(model))
    throw msgs::cli::UsageError("--camera-model expects OPENCV, PINHOLE, SIMPLE_RADIAL or RADIAL, got '" + model + "'");
  const std::string radiometry = args.get("radiometry", "auto");
  const std::map<std::string, msgs::io::Calibration> calibrations = {
      {"auto", msgs::io::Calibration::relative},
      {"none", msgs::io::Calibration::relative},
      {"reflectance", msgs::io::Calibration::sun_sensor},
      {"panel", msgs::io::Calibration::panel},
      {"panel+dls", msgs::io::Calibration::panel_and_sun_sensor},
      {"sun-sensor", msgs::io::Calibration::sun_sensor_relative}};
  if (!calibrations.count(radiometry))
    throw msgs::cli::UsageError("--radiometry expects auto, none, reflectance, sun-sensor, panel or panel+dls, got '" +
                                radiometry + "'");
  const msgs::io::Calibration calibration = calibrations.at(radiometry);
  const bool reflectance = calibration != msgs::io::Calibration::relative;
  const bool by_panel =
      calibration == msgs::io::Calibration::panel || calibration == msgs::io::Calibration::panel_and_sun_sensor;
  const bool band_ratios = calibration == msgs::io::Calibration::sun_sensor_relative;  // one scale for all bands
  const std::map<std::string, double> panel_albedo = parse_panel_albedo(args.get("panel-albedo", ""));
  if (!panel_albedo.empty() && !by_panel)
    throw msgs::cli::UsageError("--panel-albedo goes with --radiometry panel or panel+dls");
  const std::string panel_offset = args.get("panel-offset", "fit");
  if (panel_offset != "fit" && panel_offset != "zero")
    throw msgs::cli::UsageError("--panel-offset expects fit or zero, got '" + panel_offset + "'");
  if (args.has("panel-offset") && !by_panel)
    throw msgs::cli::UsageError("--panel-offset goes with --radiometry panel or panel+dls");
  const bool fit_panel_offset = panel_offset == "fit";
  const long downscales = args.integer("downscales", 0);
  if (downscales < 0 || downscales > 4) throw msgs::cli::UsageError("--downscales expects 0 to 4");
  const std::string heading_mode = args.get("light-sensor-heading", "report");
  if (heading_mode != "report" && heading_mode != "correct")
    throw msgs::cli::UsageError("--light-sensor-heading expects report or correct, got '" + heading_mode + "'");
  // The modes that divide the images by the light sensor's readings.
  const bool uses_light_sensor = calibration == msgs::io::Calibration::sun_sensor ||
                                 calibration == msgs::io::Calibration::panel_and_sun_sensor || band_ratios;
  if (heading_mode == "correct" && !uses_light_sensor)
    throw msgs::cli::UsageError("--light-sensor-heading correct goes with --radiometry reflectance, sun-sensor or panel+dls");
  const std::string matching = args.get("matching", "exhaustive");
  if (matching != "exhaustive" && matching != "window" && matching != "gps")
    throw msgs::cli::UsageError("--matching expects exhaustive, window or gps, got '" + matching + "'");
  const long window = args.integer("window", 6);
  if (window < 1) throw msgs::cli::UsageError("--window expects a positive number of captures");
  const long neighbours = args.integer("neighbours", 12);
  if (neighbours < 1) throw msgs::cli::UsageError("--neighbours expects a positive number of captures");
  const double sift_threshold = args.number("sift-threshold", 0.02 / 3);
  if (!(sift_threshold > 0 && sift_threshold < 1))
    throw msgs::cli::UsageError("--sift-threshold expects a contrast in (0, 1), e.g. 0.004");
  const double ba_tolerance = args.number("ba-tolerance", 1e-6);
  if (!(ba_tolerance >= 0 && ba_tolerance < 1))
    throw msgs::cli::UsageError("--ba-tolerance expects a relative change in [0, 1), e.g. 1e-6 or 0");
  const std::string merge_mode = args.get("merge-models", "on");
  if (merge_mode != "on" && merge_mode != "off")
    throw msgs::cli::UsageError("--merge-models expects on or off, got '" + merge_mode + "'");
  const std::string rig_mode = args.get("rig", "on");
  if (rig_mode != "on" && rig_mode != "off") throw msgs::cli::UsageError("--rig expects on or off, got '" + rig_mode + "'");
  const fs::path poses_from = args.has("poses-from") ? fs::absolute(args.get("poses-from")).lexically_normal() : fs::path();
  if (!poses_from.empty())
    for (const char* o : {"camera-model", "matching", "window", "neighbours", "sift-threshold", "ba-tolerance",
                          "merge-models", "rig", "colmap"})
      if (args.has(o))
        throw msgs::cli::UsageError(cat("--", o, " says how COLMAP finds the poses; with --poses-from they come from ",
                                        poses_from.string(), " and COLMAP does not run"));

  std::error_code ec;
  if (!fs::is_directory(images, ec)) fail(images, "--images folder does not exist or is not a folder");
  const fs::path panels_file = args.has("panels") ? fs::absolute(args.get("panels")) : fs::path();
  const std::vector<msgs::io::PanelPicture> panel_list =
      args.has("panels") ? msgs::io::read_panel_list(panels_file) : std::vector<msgs::io::PanelPicture>{};
  if (fs::exists(out, ec) && !args.flag("force"))
    fail(out, "output folder already exists (choose another --out, or replace it with --force)");
  if (out == images || images.lexically_relative(out).string().rfind("..", 0) != 0)
    fail(out, "--out must not be the --images folder or contain it");
  // The earlier import's poses, read (and checked) before any work.
  const std::optional<GivenPoses> given =
      poses_from.empty() ? std::nullopt : std::optional<GivenPoses>(read_given_poses(poses_from));
  const std::string colmap_arg = args.get("colmap", "colmap");
  const auto colmap = given ? std::nullopt : msgs::cli::find_program(colmap_arg);  // (not run with --poses-from)
  if (!given && !colmap)
    fail(colmap_arg, "COLMAP executable not found (install it: apt-get install --no-install-recommends colmap, "
                     "or point --colmap at it)");
  // Headless COLMAP: its Qt must not look for a display.
  ::setenv("QT_QPA_PLATFORM", "offscreen", 0);

  // ---- 1. captures from the file names
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(images, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    const fs::path rel = it->path().lexically_relative(images);
    if (rel.filename().string().rfind('.', 0) == 0) {  // hidden files and folders
      if (it->is_directory(ec)) it.disable_recursion_pending();
      continue;
    }
    if (it->is_regular_file(ec)) files.push_back(rel);
  }
  if (ec) fail(images, cat("cannot list the folder: ", ec.message()));
  std::sort(files.begin(), files.end());
  msgs::io::CaptureScan scan = msgs::io::scan_capture_names(images, files, camera, patterns);
  const auto counts = scan.band_counts();
  std::string band_list;
  for (const auto& b : msgs::io::standard_bands())
    if (counts.count(b.id)) band_list += cat(band_list.empty() ? "" : ", ", b.id, " ", counts.at(b.id));
  std::printf("import: %s, %zu captures x %zu bands (%s) from %s\n", scan.camera.c_str(), scan.captures.size(),
              counts.size(), band_list.c_str(), images.string().c_str());
  for (const auto& [name, fl] : scan.skipped) {
    std::vector<std::string> names;
    for (const auto& f : fl) names.push_back(f.generic_string());
    std::printf("  warning: skipping band %s (no msgs band slot): %s\n", name.c_str(), list_some(names, 3).c_str());
  }
  {
    std::vector<std::string> names;  // (the --panels list may sit among the images)
    for (const auto& f : scan.unmatched)
      if ((images / f).lexically_normal() != panels_file.lexically_normal()) names.push_back(f.generic_string());
    if (!names.empty())
      std::printf("  warning: %zu files match no pattern and are ignored: %s\n", names.size(), list_some(names, 4).c_str());
  }
  {
    std::vector<std::string> incomplete;
    for (const auto& c : scan.captures)
      if (c.bands.size() != counts.size()) incomplete.push_back(c.key);
    if (!incomplete.empty())
      std::printf("  warning: %zu captures lack some band: %s\n", incomplete.size(), list_some(incomplete).c_str());
  }

  std::vector<Item> items = scan_items(scan);

  // ---- temporary folders: layout (renamed to --out at the end) and COLMAP work
  msgs::io::StagedDirectory stage(out, ".import-tmp-");
  const fs::path& tmp = stage.dir();
  const fs::path layout = tmp / "layout", work = tmp / "work";
  fs::create_directories(layout / "images", ec);
  if (!ec) fs::create_directories(work / "images", ec);
  if (ec) fail(tmp, cat("cannot create the temporary folder: ", ec.message()));
  if (args.flag("keep-work")) stage.keep();
  const fs::path log = work / "colmap.log";

  // ---- 2. metadata (exiv2): radiometry, GPS positions and the focal lengths COLMAP starts from
  const auto t_meta = Clock::now();
  bool have_meta = false;
  {
    const std::string exiv2_arg = args.get("exiv2", "exiv2");
    // Without exiv2 the import still runs (stored values, guessed focal lengths) unless it needs
    // the positions.
    if (!msgs::cli::find_program(exiv2_arg)) {
      if (matching == "gps" || reflectance)
        fail(exiv2_arg, cat(matching == "gps" ? "--matching gps reads the positions"
                                              : "--radiometry " + radiometry + " reads the metadata",
                            " with exiv2, which was not found (install it: apt-get install exiv2, or point --exiv2 at it)"));
      std::printf("  warning: exiv2 not found (install it: apt-get install exiv2); keeping the stored values%s "
                  "and letting COLMAP guess the focal lengths\n",
                  radiometry != "none" ? " (no radiometric normalisation)" : "");
    } else {
      have_meta = true;
      const std::size_t batch = 64;
      for (std::size_t i0 = 0; i0 < items.size(); i0 += batch) {
        const std::size_t i1 = std::min(items.size(), i0 + batch);
        std::vector<std::string> cmd = {exiv2_arg, "-q", "-P", "kv"};
        for (const auto& k : msgs::io::exiv2_metadata_keys()) {
          cmd.push_back("-K");
          cmd.push_back(k);
        }
        std::vector<std::string> names;
        for (std::size_t i = i0; i < i1; ++i) names.push_back((images / items[i].source).string());
        // exiv2 prefixes every line with the file name only when given several files.
        if (names.size() == 1) names.push_back(names[0]);
        cmd.insert(cmd.end(), names.begin(), names.end());
        const fs::path txt = work / cat("exiv2_", i0, ".txt");
        const int rc = msgs::cli::run_process(cmd, txt, work / "exiv2.log");
        // exiv2 exits non-zero when a file has none of the keys; only a missing output is an error.
        const std::string text = fs::exists(txt, ec) ? msgs::io::read_text(txt) : std::string();
        if (rc != 0 && text.empty() && rc != 1 && rc != 253)
          throw msgs::io::IoError(cat(exiv2_arg, " failed with exit status ", rc,
                                      " (a broken install? point --exiv2 at a working one):\n",
                                      msgs::cli::tail_lines(work / "exiv2.log", 10)));
        const auto per_file = msgs::io::split_exiv2_output(text, names);
        for (std::size_t i = i0; i < i1; ++i) items[i].meta = msgs::io::parse_capture_meta(per_file[i - i0], images / items[i].source);
      }
      // The file name put each image in a band slot; a wavelength in its metadata that does not
      // fit that slot means the camera orders its bands otherwise (a model or firmware the naming
      // scheme does not know, or a --bands mapping that swaps two): training on it would fill a
      // band with another band's light.
      for (const Item& it : items) {
        if (!it.meta.wavelength_nm || msgs::io::wavelength_fits_band(it.band, *it.meta.wavelength_nm)) continue;
        const msgs::io::BandWindow w = msgs::io::band_window(it.band);
        const auto g = [](double v) { return msgs::io::short_number(v); };
        fail(images / it.source, it.meta.source.at("wavelength_nm"),
             cat("the camera says ", g(*it.meta.wavelength_nm), " nm", it.meta.band_name ? " (" + *it.meta.band_name + ")" : "",
                 ", but ", scan.camera == "patterns" ? std::string("--bands") : "the " + scan.camera + " file name",
                 " puts the image in ", it.band, " (", g(w.lo_nm), "-", g(w.hi_nm),
                 " nm): this camera orders its bands otherwise; say which files hold which band with --bands",
                 " 'PATTERN=ID,...' (see msgs import --help)"));
      }
    }
  }

  // ---- calibration-panel pictures are not part of the scene: set aside, for --radiometry panel
  std::vector<Item> panels;
  std::vector<std::string> panel_keys;
  {
    // The pictures listed in --panels count as marked by the camera, with the list's area and albedo;
    // a picture listed again for another panel in it is calibrated from that one too (`more_panels`).
    std::map<fs::path, std::vector<std::size_t>> more_panels;  // source -> its further entries in the list
    for (std::size_t i = 0; i < panel_list.size(); ++i) {
      const msgs::io::PanelPicture& p = panel_list[i];
      const auto it = std::find_if(items.begin(), items.end(), [&](const Item& x) { return x.source == p.file; });
      if (it == items.end() || it->band == "D")
        fail(panels_file, cat("pictures[", i, "].file"),
             cat("'", p.file.generic_string(), "' is not ",
                 it == items.end() ? "one of the band images found in --images (a typo, or a file the names scheme skipped)"
                                   : "a multispectral band's image (the RGB camera's are not calibrated)"));
      if (it->meta.source.count("panel_area") && it->meta.source.at("panel_area") == "--panels") {
        more_panels[p.file].push_back(i);
        continue;
      }
      it->meta.calibration_picture = 2;
      it->meta.panel_area = p.area;
      it->meta.source["panel_area"] = "--panels";
      if (p.albedo) {
        it->meta.panel_albedo = *p.albedo;
        it->meta.source["panel_albedo"] = "--panels";
      }
    }
    std::set<std::size_t> marked;
    for (const Item& it : items)
      if (it.meta.calibration_picture != 0) marked.insert(it.capture);
    if (!marked.empty()) {
      for (std::size_t ci : marked) panel_keys.push_back(scan.captures[ci].key);
      if (marked.size() == scan.captures.size())
        fail(images, cat("every capture is a picture of a calibration panel (Xmp.Camera.CalibrationPicture",
                         panel_list.empty() ? "" : " or --panels", "): ", list_some(panel_keys),
                         "; add the flight's captures to --images"));
      std::map<fs::path, msgs::io::CaptureMeta> meta_of;
      for (Item& it : items) {
        if (!marked.count(it.capture)) {
          meta_of[it.source] = std::move(it.meta);
          continue;
        }
        panels.push_back(std::move(it));
      }
      for (std::size_t k = 0, n = panels.size(); k < n; ++k)
        if (const auto more = more_panels.find(panels[k].source); more != more_panels.end())
          for (std::size_t i : more->second) {
            Item other = panels[k];
            // A further panel in a picture: the camera's Camera:Albedo is its own panel's, not this one's.
            if (by_panel && !panel_list[i].albedo && !panel_albedo.count(other.band) && !panel_albedo.count(""))
              fail(panels_file, cat("pictures[", i, "].albedo"),
                   cat("missing: '", panel_list[i].file.generic_string(), "' is listed again, for a further panel,"
                       " whose reflectance Xmp.Camera.Albedo cannot give (where the camera writes one, it is its own"
                       " panel's): give it here, or for band ", other.band, " with --panel-albedo ", other.band, "=0.49"));
            other.meta.panel_area = panel_list[i].area;
            other.meta.panel_albedo = panel_list[i].albedo;
            if (panel_list[i].albedo) other.meta.source["panel_albedo"] = "--panels";
            else other.meta.source.erase("panel_albedo");
            panels.push_back(std::move(other));
          }
      std::vector<msgs::io::CaptureFiles> flight;
      for (std::size_t ci = 0; ci < scan.captures.size(); ++ci)
        if (!marked.count(ci)) flight.push_back(std::move(scan.captures[ci]));
      scan.captures = std::move(flight);
      items = scan_items(scan);
      for (Item& it : items) it.meta = std::move(meta_of.at(it.source));
      std::printf("  %zu capture%s of a calibration panel set aside (Xmp.Camera.CalibrationPicture%s): %s%s\n",
                  panel_keys.size(), panel_keys.size() == 1 ? "" : "s", panel_list.empty() ? "" : ", --panels",
                  list_some(panel_keys).c_str(),
                  by_panel ? "" : " (--radiometry panel calibrates with them)");
    }
  }

  // An image whose source file the earlier import put in another band: the two imports told the
  // bands apart otherwise, and the poses would go to the wrong cameras.
  if (given)
    for (const Item& it : items) {
      const auto k = given->by_source.find(it.source.generic_string());
      if (k == given->by_source.end()) continue;  // no pose for it: stopped below, with the others
      const std::string band = given->frames[k->second].value("mm_channel", std::string("D"));
      if (band != it.band)
        fail(given->transforms, cat("frames[", k->second, "].mm_channel"),
             cat("'", band, "', but this import puts '", it.source.generic_string(), "' in band ", it.band, " (",
                 scan.camera == "patterns" ? std::string("--bands") : "the " + scan.camera + " file name",
                 "): give --camera or --bands as the import of the poses had them"));
    }

  // ---- 3. radiometry: plan per band, pass 1 for the band maxima (relative radiance), pass 2 writes
  std::map<std::string, std::vector<std::size_t>> by_band;
  for (std::size_t i = 0; i < items.size(); ++i) by_band[items[i].band].push_back(i);
  nlohmann::ordered_json panel_report = nlohmann::ordered_json::array();  // what each panel picture gave
  nlohmann::ordered_json panel_lines = nlohmann::ordered_json::object();  // band -> the empirical line
  nlohmann::ordered_json heading_report = nlohmann::ordered_json::object();  // band -> the heading check
  double all_bands_max = 0.0;  // sun-sensor: the brightest value of any band, and its band
  std::string brightest_band;
  for (const auto& [band, idx] : by_band) {
    if (band == "D") continue;
    msgs::io::RadiometrySteps steps;
    std::vector<std::size_t> band_panels;  // the panel pictures of this band that calibrate it
    if (have_meta && uses_light_sensor)
      if (auto j = check_light_sensor_heading(band, idx, items, heading_mode == "correct"); !j.is_null())
        heading_report[band] = j;
    if (have_meta && radiometry != "none") {
      std::vector<msgs::io::CaptureMeta> metas;
      std::vector<fs::path> srcs;
      for (std::size_t i : idx) {
        metas.push_back(items[i].meta);
        srcs.push_back(items[i].source);
      }
      if (by_panel) {
        band_panels = usable_panels(panels, band, images, radiometry);
        for (std::size_t k : band_panels) {
          metas.push_back(panels[k].meta);
          srcs.push_back(panels[k].source);
        }
      }
      const auto plan = msgs::io::plan_band(metas, srcs, calibration);
      steps = plan.steps;
      if (!plan.missing.empty()) {
        std::string what;
        for (const auto& [tag, lacking] : plan.missing) {
          std::vector<std::string> names;
          for (const auto& f : lacking) names.push_back(f.generic_string());
          what += cat("\n    ", tag, " missing in ", lacking.size(), " of ", idx.size(), " files: ", list_some(names, 3));
        }
        if (reflectance) {
          // Why a light-sensor reading was not taken (a firmware known to write it wrongly).
          for (std::size_t i : idx)
            if (!items[i].meta.irradiance_problem.empty()) {
              what += cat("\n    (", items[i].source.generic_string(), ": ", items[i].meta.irradiance_problem, ")");
              break;
            }
          fail(images / srcs[0],
               cat("--radiometry ", radiometry, " needs every step",
                   calibration == msgs::io::Calibration::sun_sensor ? ", MicaSense's radiance calibration and the DLS 2 irradiance"
                   : band_ratios ? ", the band camera's calibration and the light sensor's reading"
                   : by_panel && calibration != msgs::io::Calibration::panel ? " and the light sensor's reading"
                                                                               : "",
                   " in every image of band ", band, by_panel ? " and in its panel pictures" : "", ":", what,
                   "\n  msgs computes reflectance from MicaSense's DLS 2 (reflectance), from a light sensor up to",
                   " one factor for all bands (sun-sensor: MicaSense, DJI) and from calibration panels (panel;",
                   " panel+dls, where the light sensor follows the light: MicaSense, DJI and the Parrot Sequoia's",
                   " sunshine sensor); use --radiometry auto for relative radiance"));
        }
        std::printf("  warning: %s: corrections left out for the whole band (%s):%s\n", band.c_str(),
                    steps.any() ? "the others are applied" : "stored values kept", what.c_str());
      }
    }
    double mx = 0.0;
    for (std::size_t i : idx) {
      Item& it = items[i];
      const fs::path src = images / it.source;
      const BandImage img = read_band_image(src, band);
      const msgs::Image<float>& raw = img.raw;
      it.width = raw.width;
      it.height = raw.height;
      it.rad = msgs::io::frame_radiometry(it.meta, steps, img.dn_max, raw.width, raw.height);
      it.radiometry_applied = steps.any();
      if (band_ratios) it.rad.scale = msgs::io::light_sensor_scale(it.rad);
      if (it.radiometry_applied && (!reflectance || band_ratios))
        mx = std::max(mx, double(msgs::io::max_value(msgs::io::normalise_image(raw, it.rad, src))));
    }
    if (band_ratios) {  // the common scale is set once every band's maximum is known
      if (mx > all_bands_max) {
        all_bands_max = mx;
        brightest_band = band;
      }
      continue;
    }
    nlohmann::ordered_json line_report = nlohmann::ordered_json::object();
    const msgs::io::PanelSchedule schedule =
        by_panel ? calibrate_with_panels(panels, band_panels, band, steps, panel_albedo, fit_panel_offset, images,
                                         panel_report, line_report)
                 : msgs::io::PanelSchedule{};
    if (!line_report.empty()) panel_lines[band] = line_report;
    if (schedule.timed()) {
      std::vector<std::string> untimed;
      for (std::size_t i : idx)
        if (!items[i].meta.time_s) untimed.push_back(items[i].source.generic_string());
      if (!untimed.empty())
        std::printf("  warning: %s: %zu images have no capture time (%s): the panel's mean irradiance is used for them\n",
                    band.c_str(), untimed.size(), list_some(untimed, 3).c_str());
    }
    for (std::size_t i : idx) {
      if (by_panel) items[i].rad.offset = schedule.offset;
      items[i].rad.scale = by_panel                    ? 1.0 / schedule.at(items[i].meta.time_s)
                           : reflectance                 ? msgs::io::reflectance_scale(items[i].rad)
                           : items[i].radiometry_applied ? msgs::io::band_scale(mx)
                                                         : 1.0 / items[i].rad.dn_max;
    }
  }
  double common = 1.0;
  if (band_ratios) {
    common = msgs::io::band_scale(all_bands_max);
    for (Item& it : items)
      if (it.band != "D") it.rad.scale *= common;
    std::printf("  sun-sensor: one scale for all bands, %.6g, from the brightest value (in %s)\n", common,
                brightest_band.c_str());
  }
  std::map<std::string, ValueHistogram> written;  // band -> its values, before clipping at 1
  nlohmann::ordered_json reflectance_percentiles = nlohmann::ordered_json::object();
  for (Item& it : items) {
    const fs::path src = images / it.source;
    const msgs::Image<float> raw = msgs::io::read_image(src);
    if (!given) fs::create_directories((work / "images" / it.colmap_name).parent_path(), ec);
    if (it.band == "D") {
      if (raw.channels < 3) fail(src, "band D (RGB) needs a colour image");
      it.width = raw.width;
      it.height = raw.height;
      fs::copy_file(src, layout / "images" / it.out_name, ec);
      if (ec) fail(layout / "images" / it.out_name, cat("cannot copy ", src.string(), ": ", ec.message()));
      if (!given) msgs::io::write_png8(work / "images" / it.colmap_name, raw);
      write_downscaled(layout, it.out_name, raw, downscales, false);
      continue;
    }
    msgs::Image<float> norm = msgs::io::normalise_image(raw, it.rad, src);
    ValueHistogram& h = written[it.band];
    for (float& v : norm.data) {
      h.add(v);
      v = std::min(v, 1.0f);
    }
    msgs::io::write_png16(layout / "images" / it.out_name, norm);
    if (!given) msgs::io::write_png8(work / "images" / it.colmap_name, sift_copy(norm));
    write_downscaled(layout, it.out_name, norm, downscales, true);
  }
  if (reflectance) {
    // The sunlight each band's reflectance was computed under (from MicaSense's a1): how much
    // the light sensor saw it change over the flight, or the panel's single value.
    for (const auto& [band, idx] : by_band) {
      if (band == "D") continue;
      double lo = 1e300, hi = 0, dls_lo = 1e300, dls_hi = 0;
      for (std::size_t i : idx) {
        const double e = msgs::io::reflectance_irradiance(items[i].rad);
        lo = std::min(lo, e);
        hi = std::max(hi, e);
        if (items[i].meta.irradiance) {
          dls_lo = std::min(dls_lo, *items[i].meta.irradiance);
          dls_hi = std::max(dls_hi, *items[i].meta.irradiance);
        }
      }
      const std::string how = calibration == msgs::io::Calibration::sun_sensor ? "the light sensor's readings"
                              : calibration == msgs::io::Calibration::panel    ? "the panel's"
                                                                               : "the light sensor's readings, levelled by the panel";
      if (band_ratios) {
        if (dls_hi > 0)
          std::printf("  %s: the light sensor read %s to %s%s\n", band.c_str(), msgs::io::short_number(dls_lo, 4).c_str(),
                      msgs::io::short_number(dls_hi, 4).c_str(),
                      items[idx[0]].meta.irradiance_si ? " W/m^2/nm" : " (its own units)");
      } else if (lo > 0)
        std::printf("  %s: reflectance under %s W/m^2/nm of sunlight (%s)\n", band.c_str(),
                    (calibration == msgs::io::Calibration::panel && hi <= lo * (1 + 1e-9) ? msgs::io::short_number(lo, 4)
                                                                 : cat(msgs::io::short_number(lo, 4), " to ", msgs::io::short_number(hi, 4)))
                        .c_str(),
                    how.c_str());
      // One panel irradiance for a flight under changing light: the light sensor saw the change.
      if (calibration == msgs::io::Calibration::panel && dls_hi > 1.05 * dls_lo)
        std::printf("  warning: %s: the light sensor's readings change by %.3g%% over the flight, which one panel"
                    " irradiance does not follow; --radiometry panel+dls does\n",
                    band.c_str(), 100.0 * (dls_hi / dls_lo - 1.0));
      // Readings msgs levelled for the sun's place (a DLS 1, or a DLS 2's faulty firmware).
      std::size_t levelled = 0;
      double el_lo = 90, el_hi = -90, th_lo = 180, th_hi = 0;
      for (std::size_t i : idx)
        if (const auto& m = items[i].meta; m.sun_elevation_deg && items[i].rad.steps.irradiance) {
          ++levelled;
          el_lo = std::min(el_lo, *m.sun_elevation_deg);
          el_hi = std::max(el_hi, *m.sun_elevation_deg);
          if (m.sun_sensor_angle_deg) {
            th_lo = std::min(th_lo, *m.sun_sensor_angle_deg);
            th_hi = std::max(th_hi, *m.sun_sensor_angle_deg);
          }
        }
      const auto one_decimal = [](double v) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.1f", v);
        return std::string(buf);
      };
      if (levelled > 0)
        std::printf("  %s: %zu of %zu light-sensor readings levelled for the sun, %s degrees high%s\n", band.c_str(),
                    levelled, idx.size(),
                    (el_hi - el_lo < 0.05 ? one_decimal(el_lo) : cat(one_decimal(el_lo), " to ", one_decimal(el_hi))).c_str(),
                    th_hi >= th_lo ? cat(", ", msgs::io::short_number(th_lo, 3), " to ", msgs::io::short_number(th_hi, 3),
                                         " degrees from the tilted sensor's normal")
                                         .c_str()
                                   : "");
    }
    // What the bands hold, to hold against what the surfaces should reflect (vegetation: a few
    // percent in red, 30-50% in the near infra-red).
    for (const auto& [band, h] : written) {
      const double p5 = h.quantile(0.05), p50 = h.quantile(0.5), p95 = h.quantile(0.95);
      std::printf("  %s: %sreflectance %.3f / %.3f / %.3f (5th percentile / median / 95th, %llu pixels)\n", band.c_str(),
                  band_ratios ? "relative " : "", p5, p50, p95, static_cast<unsigned long long>(h.pixels));
      reflectance_percentiles[band] = {{"p5", p5}, {"p50", p50}, {"p95", p95}};
      if (h.above > 0)  // (relative radiance peaks at 1 by construction)
        std::printf("  warning: %s: %.3g%% of the pixels have a reflectance above 1, clipped to 1 (specular highlights,"
                    " or an irradiance that does not fit the light the camera saw)\n",
                    band.c_str(), 100.0 * double(h.above) / double(h.pixels));
    }
  }
  std::printf("  radiometry and copies: %zu images in %.1f s\n", items.size(), since(t_meta));
  std::fflush(stdout);

  // ---- 4. COLMAP (or the poses of --poses-from)
  std::map<std::string, double> timings;
  std::map<std::string, const msgs::io::ColmapImage*> registered;  // colmap_name -> its pose from COLMAP
  std::map<std::string, const nlohmann::ordered_json*> given_frame;  // colmap_name -> its frame in --poses-from
  fs::path best_dir;
  msgs::io::ColmapModel best;
  int n_models = 0;
  MergeResult merged;
  RigResult rig;
  if (given) {
    for (const Item& it : items) {
      const auto k = given->by_source.find(it.source.generic_string());
      if (k == given->by_source.end()) continue;
      const auto& f = given->frames[k->second];
      const auto w = long(f["w"].get<double>()), h = long(f["h"].get<double>());  // (whole: load_dataset checked them)
      if (w != it.width || h != it.height)
        fail(given->transforms, cat("frames[", k->second, "].w"),
             cat(w, " x ", h, " pixels, but '", it.source.generic_string(), "' is ", it.width, " x ", it.height,
                 ": the poses are of other pictures, or of copies at another size"));
      given_frame[it.colmap_name] = &f;
    }
    std::printf("  poses of %zu images from %s\n", given_frame.size(), given->transforms.string().c_str());
  } else {
    const std::string db = (work / "database.db").string();
    double t_features = 0.0;
    char peak[32];
    std::snprintf(peak, sizeof peak, "%.17g", sift_threshold);
    for (const auto& [band, idx] : by_band) {
      const fs::path list = work / cat("list_", band, ".txt");
      std::string text;
      for (std::size_t i : idx) text += items[i].colmap_name + "\n";
      msgs::io::write_text_atomic(list, text);
      std::vector<std::string> a = {"--database_path", db, "--image_path", (work / "images").string(), "--image_list_path",
                                    list.string(), "--ImageReader.single_camera", "1", "--ImageReader.camera_model", model,
                                    "--SiftExtraction.use_gpu", "0", "--SiftExtraction.peak_threshold", peak};
      // Focal length prior from the metadata: median over the band's images of the camera's
      // calibration, or else of mm x pixels/mm. The principal point from the calibration where every
      // image has one (COLMAP keeps it as given), else the image's centre.
      std::vector<double> f, px, py;
      for (std::size_t i : idx) {
        if (auto fp = items[i].meta.focal_px()) f.push_back(*fp);
        if (const auto& pp = items[i].meta.principal_point_px) {
          px.push_back((*pp)[0]);
          py.push_back((*pp)[1]);
        }
      }
      const auto median = [](std::vector<double> v) {
        std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
        return v[v.size() / 2];
      };
      const Item& first = items[idx.front()];
      if (f.size() == idx.size()) {
        const double fpx = median(f);
        double cx = first.width / 2.0, cy = first.height / 2.0;
        bool calibrated = px.size() == idx.size();
        if (calibrated) {
          const double mx = median(px), my = median(py);
          // A principal point outside the image is not a calibration of this image size.
          calibrated = mx > 0 && mx < first.width && my > 0 && my < first.height;
          if (calibrated) {
            cx = mx;
            cy = my;
          } else {
            std::printf("  %s: note: the principal point the camera writes, (%s, %s), lies outside the %dx%d image; "
                        "COLMAP starts from its centre\n",
                        band.c_str(), msgs::io::short_number(mx, 5).c_str(), msgs::io::short_number(my, 5).c_str(),
                        first.width, first.height);
          }
        }
        std::string p = model == "PINHOLE" ? cat(fpx, ",", fpx, ",", cx, ",", cy)
                        : model == "OPENCV" ? cat(fpx, ",", fpx, ",", cx, ",", cy, ",0,0,0,0")
                        : model == "SIMPLE_RADIAL" ? cat(fpx, ",", cx, ",", cy, ",0")
                                                   : cat(fpx, ",", cx, ",", cy, ",0,0");
        a.push_back("--ImageReader.camera_params");
        a.push_back(p);
        std::printf("  %s: focal length prior %.1f px from the metadata%s\n", band.c_str(), fpx,
                    calibrated ? cat(", principal point (", msgs::io::short_number(cx, 5), ", ", msgs::io::short_number(cy, 5),
                                     ") from the camera's calibration").c_str()
                               : "");
      } else {
        std::printf("  %s: no focal length + focal-plane resolution in the metadata; COLMAP guesses the focal length\n",
                    band.c_str());
      }
      t_features += run_colmap(colmap->string(), "feature_extractor", a, log, idx.size());
    }
    timings["features"] = t_features;
    // Every pair by default: it needs no positions, and a window (msgs/io/match_pairs.hpp) misses
    // the views a path comes back to, as a walk around a building or the next line of a survey grid
    // does.
    if (matching == "exhaustive") {
      const std::size_t n_pairs = msgs::io::exhaustive_pair_count(items.size());
      std::printf("  matching every pair: %zu\n", n_pairs);
      // About 0.03 s (320x240) to 0.4 s (1024x768) a pair on two cores: beyond 20k pairs, hours.
      if (n_pairs > 20000)
        std::printf("  note: that many pairs take hours; --matching gps (by the positions in the metadata) or window "
                    "(by the order of the files) matches only nearby captures\n");
      timings["matching"] = run_colmap(colmap->string(), "exhaustive_matcher",
                                       {"--database_path", db, "--SiftMatching.use_gpu", "0"}, log, 0);
    } else {
      std::vector<msgs::io::PairImage> pi;
      for (const Item& it : items) pi.push_back({it.capture, it.band});
      std::vector<std::pair<std::size_t, std::size_t>> pairs;
      if (matching == "window") {
        pairs = msgs::io::window_pairs(pi, std::size_t(window));
        std::printf("  matching a window of %ld captures: %zu of the %zu pairs\n", window, pairs.size(),
                    msgs::io::exhaustive_pair_count(items.size()));
      } else {
        const auto positions = capture_positions(items, scan.captures.size(), images);
        pairs = msgs::io::neighbour_pairs(pi, positions, std::size_t(neighbours));
        std::printf("  matching the %ld nearest captures by GPS: %zu of the %zu pairs\n", neighbours, pairs.size(),
                    msgs::io::exhaustive_pair_count(items.size()));
      }
      std::string text;
      for (const auto& [i, j] : pairs) text += items[i].colmap_name + " " + items[j].colmap_name + "\n";
      const fs::path list = work / "match_pairs.txt";
      msgs::io::write_text_atomic(list, text);
      timings["matching"] = run_colmap(colmap->string(), "matches_importer",
                                       {"--database_path", db, "--match_list_path", list.string(), "--match_type", "pairs",
                                        "--SiftMatching.use_gpu", "0"},
                                       log, 0);
    }
    fs::create_directories(work / "sparse", ec);
    char tolerance[32];
    std::snprintf(tolerance, sizeof tolerance, "%.17g", ba_tolerance);
    timings["mapping"] = run_colmap(colmap->string(), "mapper",
                                    {"--database_path", db, "--image_path", (work / "images").string(), "--output_path",
                                     (work / "sparse").string(), "--Mapper.ba_global_function_tolerance", tolerance},
                                    log, items.size());

    // ---- 5. the largest model, registration check
    std::vector<MapperModel> models = read_models(work / "sparse");
    n_models = int(models.size());
    if (models.empty())
      throw msgs::io::IoError(cat("COLMAP's mapper reconstructed nothing (too few matches between the images?); ",
                                  "last lines of its log:\n", msgs::cli::tail_lines(log, 15)));
    best_dir = models.front().dir;
    best = std::move(models.front().model);
    models.erase(models.begin());
    for (const auto& im : best.images) registered[im.name] = &im;
    if (n_models > 1)
      std::printf("  warning: COLMAP made %d separate models; keeping the largest (%zu images)\n", n_models, best.images.size());
    if (merge_mode == "on" && registered.size() < items.size()) {
      merged = merge_rest_models(items, scan.captures.size(), registered, models, colmap->string(), work, log, tolerance);
      timings["mapping"] += merged.seconds;
      for (const auto& im : merged.images) registered[im.name] = &im;
    }
    if (rig_mode == "on" && registered.size() < items.size()) {
      rig = place_unregistered(items, scan.captures.size(), by_band, registered);
      for (const auto& im : rig.images) registered[im.name] = &im;
    }
  }
  std::vector<std::string> missing;
  for (const auto& it : items)
    if (!registered.count(it.colmap_name) && !given_frame.count(it.colmap_name))
      missing.push_back(cat(it.source.generic_string(), " (", it.band, ")"));
  if (!missing.empty()) {
    std::string why;
    for (const auto& p : merged.problems) why += "\n  models of the rest: " + p;
    for (const auto& p : rig.rig.problems) why += "\n  rig: " + p;
    if (given && !args.flag("allow-partial"))
      fail(given->transforms, "frames",
           cat(missing.size(), " of ", items.size(), " images have no frame here: ", list_some(missing, 12),
               "\n  (not in the import of the poses, or other captures? --allow-partial drops them and goes on)"));
    if (!args.flag("allow-partial"))
      fail(images, cat(missing.size(), " of ", items.size(), " images have no pose: COLMAP did not register them",
                       rig_mode == "on" ? " and the rig could not place them" : "", ": ", list_some(missing, 12), why,
                       "\n  (too little texture or overlap, or bands too different to match across? "
                       "--allow-partial drops them and goes on)"));
    std::printf("  warning: dropping %zu images without a pose: %s%s\n", missing.size(), list_some(missing, 8).c_str(),
                why.c_str());
  }
  // Mean reprojection error from model_analyzer.
  std::optional<double> reproj;
  if (!given) {
    const fs::path alog = work / "model_analyzer.log";
    const int rc = msgs::cli::run_process({colmap->string(), "model_analyzer", "--path", best_dir.string()}, alog, alog);
    if (rc == 0) {
      const std::string text = msgs::io::read_text(alog);
      const auto p = text.find("Mean reprojection error:");
      if (p != std::string::npos) {
        double v = 0;
        if (std::sscanf(text.c_str() + p, "Mean reprojection error: %lfpx", &v) == 1 && std::isfinite(v)) reproj = v;
      }
    }
  }

  // ---- 6. the layout
  nlohmann::ordered_json tf;
  tf["ply_file_path"] = "sparse_pc.ply";
  nlohmann::ordered_json meta_json;
  meta_json["camera"] = scan.camera;
  meta_json["source"] = images.string();
  meta_json["captures"] = scan.captures.size();
  const std::size_t n_main = items.size() - missing.size() - merged.images.size() - rig.images.size();
  if (given) {  // how the poses were found, as the import of them says
    meta_json["poses_from"] = given->root.string();
    for (const auto& [key, value] : given->report.items()) meta_json[key] = value;
  } else {
    meta_json["registered"] = n_main;
    meta_json["from_models_of_the_rest"] = merged.images.size();
    if (!merged.report.is_null() || !merged.problems.empty()) {  // the second mapper ran, or why it did not
      nlohmann::ordered_json mj;
      mj["models"] = merged.report.is_null() ? nlohmann::ordered_json::array() : merged.report;
      mj["problems"] = merged.problems;
      meta_json["models_of_the_rest"] = mj;
    }
    meta_json["placed_by_rig"] = rig.images.size();
    if (!rig.images.empty()) meta_json["rig"] = rig.report;
  }
  meta_json["images"] = items.size();
  if (!panel_keys.empty()) meta_json["calibration_captures_set_aside"] = panel_keys;
  if (!panel_report.empty()) meta_json["calibration_panels"] = panel_report;
  if (!panel_lines.empty()) meta_json["calibration_panel_lines"] = panel_lines;
  if (reflectance) meta_json["reflectance_percentiles"] = reflectance_percentiles;
  if (band_ratios) meta_json["sun_sensor_common_scale"] = {{"scale", common}, {"brightest_band", brightest_band}};
  if (!heading_report.empty()) meta_json["light_sensor_heading"] = heading_report;
  if (!given) {
    meta_json["mean_reprojection_error_px"] = opt_number(reproj);
    meta_json["colmap_camera_model"] = model;
    meta_json["colmap_sift_peak_threshold"] = sift_threshold;
    meta_json["colmap_ba_global_function_tolerance"] = ba_tolerance;
    meta_json["colmap_matching"] = matching == "window" ? cat("window ", window)
                                    : matching == "gps"  ? cat("gps ", neighbours, " nearest")
                                                         : matching;
  }
  tf["msgs_import"] = meta_json;
  nlohmann::ordered_json frames = nlohmann::ordered_json::array();
  std::vector<std::string> train, eval;
  std::map<std::string, std::size_t> train_frames;  // per band: msgs train needs at least one
  std::size_t n_frames = 0;
  for (const Item& it : items) {
    const auto reg = registered.find(it.colmap_name);
    const auto gf = given_frame.find(it.colmap_name);
    if (reg == registered.end() && gf == given_frame.end()) {
      fs::remove(layout / "images" / it.out_name, ec);
      for (long k = 1; k <= downscales; ++k) fs::remove(layout / cat("images_", 1 << k) / it.out_name, ec);
      continue;
    }
    nlohmann::ordered_json f;
    f["file_path"] = "images/" + it.out_name;
    f["mm_channel"] = it.band;
    if (gf != given_frame.end()) {  // camera and pose as the import of them wrote them
      for (const char* key : kPoseKeys)
        if (gf->second->contains(key)) f[key] = (*gf->second)[key];
    } else {
      const msgs::io::ColmapImage& im = *reg->second;
      msgs::io::write_intrinsics_json(f, im.camera);
      using M = msgs::io::Distortion::Model;
      f["camera_model"] = im.dist.model == M::none ? "PINHOLE" : im.dist.model == M::fisheye ? "OPENCV_FISHEYE" : "OPENCV";
      f["k1"] = im.dist.k1;
      f["k2"] = im.dist.k2;
      f["k3"] = im.dist.k3;
      f["k4"] = im.dist.k4;
      f["p1"] = im.dist.p1;
      f["p2"] = im.dist.p2;
      f["transform_matrix"] = msgs::io::transform_matrix_json(im.camera);
      const auto from = rig.from.find(it.colmap_name);
      const auto carried = merged.from.find(it.colmap_name);
      f["pose"] = from != rig.from.end()        ? "rig from " + from->second
                  : carried != merged.from.end() ? carried->second
                                                 : "colmap";
    }
    f["source"] = it.source.generic_string();
    f["capture"] = scan.captures[it.capture].key;
    nlohmann::ordered_json rad;
    if (it.band == "D") {
      rad["applied"] = false;
      rad["note"] = "RGB camera: the camera's sRGB values are kept";
    } else {
      rad["applied"] = it.radiometry_applied;
      const auto& s = it.rad.steps;
      rad["black_level"] = s.black_level ? nlohmann::ordered_json(it.rad.black_level) : nlohmann::ordered_json(nullptr);
      if (s.sensor_model) rad["sensor_model_a_b_c"] = {it.rad.model_a, it.rad.model_b, it.rad.model_c};
      rad["exposure_s"] = s.exposure ? nlohmann::ordered_json(it.rad.exposure_s) : nlohmann::ordered_json(nullptr);
      rad["gain"] = s.gain ? nlohmann::ordered_json(it.rad.gain) : nlohmann::ordered_json(nullptr);
      rad["vignetting"] = s.vignetting;
      if (s.vignetting)
        rad["vignetting_model"] = !it.rad.vignetting_poly2d.empty()
                                      ? "fall-off: the image is divided by sum_i c_i (x / width)^a_i (y / height)^b_i"
                                  : it.rad.vignetting_kind == msgs::io::VignettingKind::falloff
                                      ? "fall-off: the image is divided by 1 + k0 r + k1 r^2 + ..."
                                      : "correction: the image is multiplied by 1 + k0 r + k1 r^2 + ...";
      if (s.row_gradient) rad["row_gradient_a2_a3"] = {it.rad.row_a2, it.rad.row_a3};
      if (reflectance && !band_ratios && it.rad.radiance_a1 > 0) {
        rad["radiance_a1"] = it.rad.radiance_a1;
        rad["irradiance_w_m2_nm"] = msgs::io::reflectance_irradiance(it.rad);
      }
      if (s.irradiance) rad[it.meta.irradiance_si ? "light_sensor_w_m2_nm" : "light_sensor"] = it.rad.irradiance;
      if (s.irradiance && it.meta.light_sensor_readings > 0) rad["light_sensor_readings"] = it.meta.light_sensor_readings;
      if (s.irradiance && it.heading_factor) rad["light_sensor_heading_factor"] = *it.heading_factor;
      if (s.irradiance && it.meta.sun_elevation_deg) rad["sun_elevation_deg"] = *it.meta.sun_elevation_deg;
      if (s.irradiance && it.meta.sun_sensor_angle_deg) rad["sun_sensor_angle_deg"] = *it.meta.sun_sensor_angle_deg;
      if (band_ratios) rad[it.rad.radiance_a1 > 0 ? "radiance_a1" : "gain_adjustment"] =
          it.rad.radiance_a1 > 0 ? it.rad.radiance_a1 : it.rad.gain_adjustment;
      rad["scale"] = it.rad.scale;
      if (it.rad.offset != 0.0) rad["offset"] = it.rad.offset;
      rad["dn_max"] = it.rad.dn_max;
      rad["formula"] = radiometry_formula(it.rad, it.radiometry_applied, calibration);
      if (it.meta.band_name) rad["band_name"] = *it.meta.band_name;
      if (it.meta.wavelength_nm) rad["wavelength_nm"] = *it.meta.wavelength_nm;
      // Which exiv2 key each quantity came from, to check against the camera's documentation.
      if (!it.meta.source.empty()) rad["metadata_keys"] = it.meta.source;
    }
    f["radiometry"] = rad;
    frames.push_back(f);
    const bool ev = eval_every > 0 && it.capture % static_cast<std::size_t>(eval_every) == 0;
    (ev ? eval : train).push_back("images/" + it.out_name);
    train_frames[it.band] += ev ? 0 : 1;
    ++n_frames;
  }
  tf["frames"] = frames;
  msgs::io::write_text_atomic(layout / "transforms.json", tf.dump(2) + "\n");
  nlohmann::ordered_json split;
  split["train"] = train;
  split["eval"] = eval;
  msgs::io::write_text_atomic(layout / "train_split.json", split.dump(2) + "\n");
  msgs::io::PointCloud cloud = best.points;  // with the points of the models carried over
  cloud.xyz.insert(cloud.xyz.end(), merged.points.xyz.begin(), merged.points.xyz.end());
  if (cloud.has_colour() && merged.points.rgb.size() == merged.points.xyz.size())
    cloud.rgb.insert(cloud.rgb.end(), merged.points.rgb.begin(), merged.points.rgb.end());
  else
    cloud.rgb.clear();
  if (given)  // the file as it was
    msgs::io::write_bytes_atomic(layout / "sparse_pc.ply", given->points.data(), given->points.size());
  else
    msgs::io::write_point_cloud(layout / "sparse_pc.ply", cloud);
  // Self-check: the layout loads.
  const msgs::io::Dataset check = msgs::io::load_dataset(layout);
  if (check.frames.size() != n_frames) fail(layout / "transforms.json", "self-check: frame count differs after loading");

  // ---- 7. into place
  stage.commit("layout");
  if (args.flag("keep-work")) std::printf("  work folder kept: %s\n", work.string().c_str());

  std::printf("wrote %s\n", out.string().c_str());
  // A band whose every frame went to eval cannot be trained: say so now, not at `msgs train`.
  std::string untrained;
  for (const auto& [band, n] : train_frames)
    if (n == 0) untrained += cat(untrained.empty() ? "" : ", ", band);
  if (!untrained.empty())
    std::printf("  warning: no training frame of %s: --eval-every %ld put all of its captures in eval, and msgs train "
                "needs training frames (--eval-every 0 keeps every capture for training)\n",
                untrained.c_str(), eval_every);
  if (given) {
    std::printf("  frames: %zu (%zu train, %zu eval), posed as in %s; sparse_pc.ply copied from there\n", n_frames,
                train.size(), eval.size(), given->root.string().c_str());
    std::printf("  time: %.1f s\n", since(t_start));
    return 0;
  }
  std::printf("  frames: %zu (%zu train, %zu eval), registered %zu of %zu images in the largest of %d model(s)%s%s\n",
              n_frames, train.size(), eval.size(), n_main, items.size(), n_models,
              merged.images.empty() ? "" : cat(", ", merged.images.size(), " carried over from models of the rest").c_str(),
              rig.images.empty() ? "" : cat(", ", rig.images.size(), " placed by the rig").c_str());
  std::printf("  sparse_pc.ply: %zu points, mean reprojection error %s\n", cloud.size(),
              reproj ? cat(*reproj, " px").c_str() : "n/a");
  std::printf("  time: %.1f s (features %.1f s, matching %.1f s, mapping %.1f s)\n", since(t_start), timings["features"],
              timings["matching"], timings["mapping"]);
  return 0;
}

}  // namespace
}  // namespace cmd_import

MSGS_COMMAND("import", "Turn a folder of raw multi-band captures into the dataset layout (COLMAP + exiv2)", cmd_import::run_import);
