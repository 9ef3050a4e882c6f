// tests/test_micasense_reference.cpp
// msgs' radiometry on a real MicaSense RedEdge capture against MicaSense's own library: the panel
// capture IMG_0000 of MicaSense's sample set (tests/data/micasense_rededge_2017, whose README says
// where it comes from), read by parse_capture_meta, plan_band, frame_radiometry and read_panel as
// `msgs import --radiometry panel` reads it, and its DLS 1 reading levelled as `--radiometry
// reflectance` levels it. The expected numbers are those MicaSense's tests of its library assert
// for these files (tests/test_capture.py and test_dls.py of micasense/imageprocessing, commit
// 133b04e): the panel's mean digital number, radiance and irradiance per band, the sun's
// elevation, its angle to the tilted sensor and the level-ground irradiance of band 1; and the
// exposure time of a file whose firmware wrote a wrong one.
#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>

#include <msgs/image.hpp>
#include <msgs/io/calibration_panel.hpp>
#include <msgs/io/capture_meta.hpp>
#include <msgs/io/file.hpp>
#include <msgs/io/image_io.hpp>
#include <msgs/io/radiometry.hpp>

namespace test_micasense_reference {
using namespace msgs::io;
namespace fs = std::filesystem;

namespace {

const fs::path kData = fs::path(MSGS_TEST_DATA) / "micasense_rededge_2017";
constexpr double kDeg = std::numbers::pi / 180.0;
constexpr int kWidth = 1280, kHeight = 960;

/// One band of the panel capture: its crop's place in the image and the panel area there.
struct Band {
  int index;  ///< MicaSense's band number, 1 (blue) .. 5 (red edge)
  int crop_x, crop_y;
  int dx, dy;  ///< the band camera's offset from band 1 (the data's README)
};
constexpr std::array<Band, 5> kBands = {{
    {1, 643, 449, 0, 0}, {2, 608, 460, -35, 11}, {3, 608, 487, -35, 38}, {4, 663, 492, 20, 43}, {5, 643, 469, 0, 20}}};

/// What MicaSense's library computes for band i of the capture (its tests' expected values): the
/// panel area's mean DN, its radiance (W/m^2/sr/nm), and the irradiance (W/m^2/nm) under the
/// panel's reflectance in that band.
constexpr std::array<double, 5> kPanelRaw = {45406.753893482026, 46924.919447148139, 53240.810340812051,
                                             56187.417482757308, 54479.170371812339};
constexpr std::array<double, 5> kPanelRadiance = {0.17028382320603955, 0.17940027272297152, 0.1622172746785481,
                                                  0.10647021248769974, 0.13081077851565506};
constexpr std::array<double, 5> kPanelAlbedo = {0.67, 0.69, 0.68, 0.61, 0.67};
constexpr std::array<double, 5> kPanelIrradiance = {0.79845135523772681, 0.81681533164998943, 0.74944205649335915,
                                                    0.54833776619262586, 0.61336444894797537};

std::string tags(int band) { return read_text(kData / ("IMG_0000_" + std::to_string(band) + ".tags.txt")); }

/// The band's 1280 x 960 picture: the stored crop in its place, black elsewhere.
msgs::Image<float> picture(const Band& b) {
  const fs::path crop_file =
      kData / ("IMG_0000_" + std::to_string(b.index) + ".panel_x" + std::to_string(b.crop_x) + "_y" +
               std::to_string(b.crop_y) + ".png");
  const msgs::Image<float> crop = read_image(crop_file);
  msgs::Image<float> img(kWidth, kHeight, 1);
  for (int y = 0; y < crop.height; ++y)
    for (int x = 0; x < crop.width; ++x) img.at(b.crop_x + x, b.crop_y + y, 0) = crop.at(x, y, 0);
  return img;
}

}  // namespace

TEST_CASE("a real RedEdge panel capture: msgs reads the panel's radiance and irradiance as MicaSense's library does") {
  for (const Band& b : kBands) {
    CAPTURE(b.index);
    const std::string file = "IMG_0000_" + std::to_string(b.index) + ".tif";
    const CaptureMeta m = parse_capture_meta(tags(b.index), file);
    const BandPlan plan = plan_band({m}, {file}, Calibration::panel);
    CHECK(plan.missing.empty());
    // Every step of MicaSense's model: black level, exposure, gain, vignetting and row gradient.
    CHECK(plan.steps.black_level);
    CHECK(plan.steps.exposure);
    CHECK(plan.steps.gain);
    CHECK(plan.steps.vignetting);
    CHECK(plan.steps.row_gradient);
    FrameRadiometry r = frame_radiometry(m, plan.steps, 65535, kWidth, kHeight);
    CHECK(r.black_level == 4800);
    const PanelArea area = {{{809.0 + b.dx, 613.0 + b.dy},
                             {648.0 + b.dx, 615.0 + b.dy},
                             {646.0 + b.dx, 454.0 + b.dy},
                             {808.0 + b.dx, 452.0 + b.dy}}};
    const msgs::Image<float> img = picture(b);
    const PanelReading reading = read_panel(img, r, area, file);
    const auto i = std::size_t(b.index - 1);
    // Band 1's area is the one MicaSense's library found; the others are moved by an offset found
    // here, and cover a pixel or two of the panel MicaSense's did not.
    const double tolerance = b.index == 1 ? 1e-4 : 1e-3;
    // MicaSense's library reads the area in the undistorted image, msgs in the image as stored;
    // near the image's centre the two differ by under a pixel.
    CHECK(double(reading.pixels) == doctest::Approx(26005).epsilon(0.001));
    CHECK(reading.saturated == 0);
    double dn = 0.0;
    for (int y = 0; y < kHeight; ++y)
      for (int x = 0; x < kWidth; ++x)
        if (inside_quad(area, x, y)) dn += double(img.at(x, y, 0)) * 65535.0;
    CHECK(dn / double(reading.pixels) == doctest::Approx(kPanelRaw[i]).epsilon(0.002));
    // Radiance a1 (DN - black) / 2^16 / (exposure x gain x vignetting x row gradient), averaged.
    CHECK(reading.mean * r.radiance_a1 / 65536.0 == doctest::Approx(kPanelRadiance[i]).epsilon(tolerance));
    // The band's scale as the import sets it, and the irradiance it stands for.
    r.scale = kPanelAlbedo[i] / reading.mean;
    CHECK(reflectance_irradiance(r) == doctest::Approx(kPanelIrradiance[i]).epsilon(tolerance));
  }
}

TEST_CASE("a real RedEdge DLS 1 reading: msgs levels it for the sun as MicaSense's library does") {
  const CaptureMeta m = parse_capture_meta(tags(1), "IMG_0000_1.tif");
  REQUIRE(m.time_s.has_value());
  // MicaSense: 2017-10-19T20:40:39.200174 UTC.
  CHECK(*m.time_s == doctest::Approx(*parse_date_time("2017:10:19 20:40:39") + 0.200173789).epsilon(1e-15));
  REQUIRE(m.gps.has_value());
  CHECK((*m.gps)[0] == doctest::Approx(36.576096).epsilon(1e-7));
  CHECK((*m.gps)[1] == doctest::Approx(-119.4352689).epsilon(1e-7));
  // MicaSense (pysolar): the sun 0.7193 rad high, 0.6754 rad from the tilted sensor's normal;
  // msgs (NOAA's algorithm) within 0.003 degrees of both.
  REQUIRE(m.sun_elevation_deg.has_value());
  REQUIRE(m.sun_sensor_angle_deg.has_value());
  CHECK(std::abs(*m.sun_elevation_deg - 0.7193 / kDeg) < 0.01);
  CHECK(std::abs(*m.sun_sensor_angle_deg - 0.6754 / kDeg) < 0.01);
  // Level-ground irradiance of band 1: MicaSense 1.0101948 W/m^2/nm from a reading of 1.0848248.
  REQUIRE(m.irradiance.has_value());
  CHECK(m.irradiance_si);
  CHECK(m.source.at("irradiance") == "Xmp.DLS.SpectralIrradiance levelled with Xmp.DLS.Yaw/Pitch/Roll");
  CHECK(*m.irradiance == doctest::Approx(1.0101948).epsilon(1e-4));
  // The other bands share the capture's angles: each reading scaled by the same factor.
  const double factor = 1.0101948 / 1.084824800491333;
  for (int band = 2; band <= 5; ++band) {
    CAPTURE(band);
    const std::string text = tags(band);
    const CaptureMeta mb = parse_capture_meta(text, "IMG_0000_" + std::to_string(band) + ".tif");
    REQUIRE(mb.irradiance.has_value());
    const double reading = std::stod(parse_exiv2_kv(text).at("Xmp.DLS.SpectralIrradiance"));
    CHECK(*mb.irradiance == doctest::Approx(reading * factor).epsilon(1e-4));
  }
}

TEST_CASE("real RedEdge files: the band camera's calibrated focal length and principal point, as MicaSense's library reads them") {
  // Firmware v2.1.2 writes the focal length in pixels; MicaSense's library makes the camera matrix
  // [[1449.4, 0, 627.6], [0, 1449.4, 479.9]] of IMG_0000_1 (its tests/test_image.py).
  const CaptureMeta v2 = parse_capture_meta(tags(1), "IMG_0000_1.tif");
  REQUIRE(v2.calibrated_focal_px.has_value());
  REQUIRE(v2.principal_point_px.has_value());
  CHECK(std::abs(*v2.focal_px() - 1449.4) < 0.1);
  CHECK(std::abs((*v2.principal_point_px)[0] - 627.6) < 0.1);
  CHECK(std::abs((*v2.principal_point_px)[1] - 479.9) < 0.1);
  // The nominal 5.5 mm would be 1466.7 pixels, 1.2% long.
  CHECK(*v2.focal_length_mm * *v2.focal_plane_px_per_mm == doctest::Approx(1466.67).epsilon(1e-4));
  // A RedEdge-M with firmware v3.3.0 (IMG_0002_4 of the set 0001SET) writes it in mm: MicaSense's
  // library reads 5.45221099 mm, 266.666667 pixels per mm.
  const CaptureMeta v3 = parse_capture_meta(read_text(kData / "IMG_0002_4.tags.txt"), "IMG_0002_4.tif");
  REQUIRE(v3.calibrated_focal_px.has_value());
  CHECK(*v3.calibrated_focal_px == doctest::Approx(5.45221099 * 266.666667).epsilon(1e-7));
  CHECK(*v3.exposure_s == doctest::Approx(0.00171).epsilon(1e-12));
  // Units other than mm or px are an error naming the key; without the focal plane's resolution a
  // length in mm, or a principal point, is left out.
  std::string cm = read_text(kData / "IMG_0002_4.tags.txt");
  cm.replace(cm.find("PerspectiveFocalLengthUnits        mm"), 37, "PerspectiveFocalLengthUnits        cm");
  CHECK_THROWS_WITH_AS(parse_capture_meta(cm, "a.tif"), doctest::Contains("a.tif: field 'Xmp.Camera.PerspectiveFocalLengthUnits'"),
                       IoError);
  std::string no_plane = read_text(kData / "IMG_0002_4.tags.txt");
  no_plane.erase(no_plane.find("Exif.Photo.FocalPlaneXResolution"),
                 no_plane.find('\n', no_plane.find("Exif.Photo.FocalPlaneXResolution")) -
                     no_plane.find("Exif.Photo.FocalPlaneXResolution") + 1);
  const CaptureMeta without = parse_capture_meta(no_plane, "a.tif");
  CHECK(!without.calibrated_focal_px);
  CHECK(!without.principal_point_px);
}

TEST_CASE("a real RedEdge file whose firmware wrote a wrong exposure time: msgs reads it as MicaSense's library does") {
  // IMG_0003_1 of MicaSense's set 0001SET (firmware v2.1.2) says 158/1000000 s, the 1/6329 s that
  // legacy RedEdge firmware writes for frames exposed 0.274 ms.
  const std::string text = read_text(kData / "IMG_0003_1.tags.txt");
  const CaptureMeta m = parse_capture_meta(text, "IMG_0003_1.tif");
  REQUIRE(m.exposure_s.has_value());
  CHECK(*m.exposure_s == 0.000274);
  CHECK(m.source.at("exposure_s").find("Exif.Photo.ExposureTime (1/6329 s: legacy RedEdge firmware") == 0);
  // Any other value, and any other camera, stay as written; so does an Altum's 1/6329 s.
  std::string other = text;
  other.replace(other.find("158/1000000"), 11, "170/1000000");
  CHECK(*parse_capture_meta(other, "a.tif").exposure_s == doctest::Approx(170e-6).epsilon(1e-12));
  std::string altum = text;
  altum.replace(altum.find("RedEdge"), 7, "Altum");
  CHECK(*parse_capture_meta(altum, "a.tif").exposure_s == doctest::Approx(158e-6).epsilon(1e-12));
  std::string other_make = text;
  other_make.replace(other_make.find("MicaSense"), 9, "Parrot");
  CHECK(*parse_capture_meta(other_make, "a.tif").exposure_s == doctest::Approx(158e-6).epsilon(1e-12));
}

}  // namespace test_micasense_reference
