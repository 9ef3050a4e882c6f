// tests/test_light_sensor_tilt.cpp
// The sun's position (msgs/io/sun_position.hpp) against a published reference, the geometry and
// diffuser of a tilted light sensor (msgs/io/light_sensor_tilt.hpp) against hand-worked cases,
// and the level-ground irradiance that parse_capture_meta computes where a MicaSense file lacks a
// usable HorizontalIrradiance: a real RedEdge's DLS 1 record, a DLS 2 with faulty firmware, and
// the files whose readings cannot be levelled.
#include <doctest/doctest.h>

#include <cmath>
#include <numbers>
#include <string>

#include <msgs/io/capture_meta.hpp>
#include <msgs/io/light_sensor_tilt.hpp>
#include <msgs/io/sun_position.hpp>

namespace test_light_sensor_tilt {
using namespace msgs::io;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double unix_utc(const char* exif_date_time) { return *parse_date_time(exif_date_time); }

}  // namespace

TEST_CASE("sun_position: the example of NREL's Solar Position Algorithm, and noon on the equator") {
  // Reda and Andreas, "Solar Position Algorithm for Solar Radiation Applications" (NREL, 2004),
  // table A5.1: 2003-10-17 12:30:30 at UTC-7, 39.742476 N, 105.1786 W: topocentric zenith
  // 50.11162 degrees (refraction included), azimuth 194.34024 degrees. NOAA's algorithm, with a
  // standard atmosphere rather than the example's 820 mbar, is within 0.02 degrees of it.
  const SunPosition s = sun_position(unix_utc("2003:10:17 19:30:30"), 39.742476, -105.1786);
  CHECK(std::abs(90.0 - s.elevation / kDeg - 50.11162) < 0.02);
  CHECK(std::abs(s.azimuth / kDeg - 194.34024) < 0.02);
  // At an equinox's solar noon the sun stands near the zenith of the equator (declination within
  // half a degree of 0 on 2024-03-20; noon at 0 E about 12:07 UTC, the equation of time).
  const SunPosition eq = sun_position(unix_utc("2024:03:20 12:07:30"), 0.0, 0.0);
  CHECK(eq.elevation / kDeg > 89.0);
  // Sunrise in the east, afternoon in the south-west, night below the horizon (Wageningen, June).
  const SunPosition morning = sun_position(unix_utc("2024:06:01 04:00:00"), 51.98, 5.66);
  CHECK(morning.azimuth / kDeg > 45.0);
  CHECK(morning.azimuth / kDeg < 70.0);
  CHECK(std::abs(morning.elevation / kDeg) < 5.0);
  const SunPosition afternoon = sun_position(unix_utc("2024:06:01 14:00:00"), 51.98, 5.66);
  CHECK(afternoon.azimuth / kDeg > 200.0);
  CHECK(afternoon.azimuth / kDeg < 260.0);
  CHECK(sun_position(unix_utc("2024:06:01 23:30:00"), 51.98, 5.66).elevation < 0.0);
  // Southern hemisphere: the noon sun stands in the north.
  const SunPosition south = sun_position(unix_utc("2024:06:01 02:00:00"), -33.87, 151.21);  // Sydney, noon
  CHECK((south.azimuth / kDeg < 20.0 || south.azimuth / kDeg > 340.0));
}

TEST_CASE("light sensor geometry: the normal of a tilted body, the angle to the sun, the diffuser") {
  const auto near = [](std::array<double, 3> a, std::array<double, 3> b) {
    return std::abs(a[0] - b[0]) < 1e-12 && std::abs(a[1] - b[1]) < 1e-12 && std::abs(a[2] - b[2]) < 1e-12;
  };
  // Level: the sensor faces up (minus down). Nose down 90 degrees heading north: its top faces
  // north. Right wing down 90 degrees: its top faces east. Heading east, nose 10 degrees down:
  // tilted 10 degrees towards the east.
  CHECK(near(light_sensor_normal_ned(0.7, 0, 0), {0, 0, -1}));
  CHECK(near(light_sensor_normal_ned(0, -90 * kDeg, 0), {1, 0, 0}));
  CHECK(near(light_sensor_normal_ned(0, 0, 90 * kDeg), {0, 1, 0}));
  CHECK(near(light_sensor_normal_ned(90 * kDeg, -10 * kDeg, 0), {0, std::sin(10 * kDeg), -std::cos(10 * kDeg)}));
  // The angle to a sun 40 degrees high in the east: 50 degrees for a level sensor, 40 tilted
  // 10 degrees towards it, 60 tilted away.
  const SunPosition east{40 * kDeg, 90 * kDeg};
  CHECK(sun_sensor_angle(east, 0, 0, 0) / kDeg == doctest::Approx(50.0));
  CHECK(sun_sensor_angle(east, 90 * kDeg, -10 * kDeg, 0) / kDeg == doctest::Approx(40.0));
  CHECK(sun_sensor_angle(east, -90 * kDeg, -10 * kDeg, 0) / kDeg == doctest::Approx(60.0));
  // The diffuser at normal incidence: (1 - R01)(1 - R12), R = ((n1 - n2) / (n1 + n2))^2.
  const double r01 = std::pow((1.000277 - 1.6) / (1.000277 + 1.6), 2), r12 = std::pow((1.6 - 1.38) / (1.6 + 1.38), 2);
  CHECK(diffuser_transmission(0.0) == doctest::Approx((1 - r01) * (1 - r12)).epsilon(1e-12));
  // It passes less light the more slanted the light is: under half as much at 85 degrees.
  double last = diffuser_transmission(0.0);
  for (int a = 5; a <= 85; a += 5) {
    const double t = diffuser_transmission(a * kDeg);
    CHECK(t < last);
    CHECK(t > 0.0);
    last = t;
  }
  CHECK(diffuser_transmission(85 * kDeg) < 0.5 * diffuser_transmission(0.0));
}

TEST_CASE("level_tilted_reading: the clear-sky model's reading of a tilted sensor levels back") {
  // Direct light D on a surface facing the sun, scattered D / 6: a sensor at theta reads
  // T(theta) (D cos(theta) + D / 6); level ground gets D sin(elevation) + D / 6.
  for (const double elevation : {20.0, 45.0, 70.0})
    for (const double theta : {0.0, 15.0, 40.0, 75.0}) {
      const double D = 1.3, e = elevation * kDeg, t = theta * kDeg;
      const double reading = diffuser_transmission(t) * (D * std::cos(t) + D / 6);
      CHECK(level_tilted_reading(reading, t, e) == doctest::Approx(D * std::sin(e) + D / 6).epsilon(1e-12));
    }
  CHECK(level_direct_scattered(1.2, 0.2, 30 * kDeg) == doctest::Approx(0.8));
  // What cannot be levelled says why.
  CHECK(levelling_problem(-2 * kDeg, 0).find("above the horizon") != std::string::npos);
  CHECK(levelling_problem(30 * kDeg, 85 * kDeg).find("from the light sensor's normal") != std::string::npos);
  CHECK(levelling_problem(30 * kDeg, 60 * kDeg).empty());
}

// A RedEdge with a DLS 1 (firmware v2.0.5), 2017-07-26 over Rochester, NY: the keys of one band
// file as exiv2 printed them in a public project's notes. No HorizontalIrradiance: the reading of
// the tilted sensor and its attitude only.
constexpr const char* kRedEdgeDls1 =
    "Exif.GPSInfo.GPSAltitude 272152000/1000000\n"
    "Exif.GPSInfo.GPSAltitudeRef 0\n"
    "Exif.GPSInfo.GPSLatitude 42000000/1000000 52000000/1000000 26928120/1000000\n"
    "Exif.GPSInfo.GPSLatitudeRef N\n"
    "Exif.GPSInfo.GPSLongitude 77000000/1000000 1000000/1000000 39963000/1000000\n"
    "Exif.GPSInfo.GPSLongitudeRef W\n"
    "Exif.Image.Make MicaSense\n"
    "Exif.Image.Model RedEdge\n"
    "Exif.Image.Software v2.0.5\n"
    "Exif.Photo.DateTimeOriginal 2017:07:26 16:12:57\n"
    "Exif.Photo.SubSecTime -279654\n"
    "Xmp.Camera.BandName Blue\n"
    "Xmp.Camera.Irradiance 0.71537387371063232\n"
    "Xmp.Camera.IrradiancePitch -2.0375641618928038\n"
    "Xmp.Camera.IrradianceRoll -0.30438037845010268\n"
    "Xmp.Camera.IrradianceYaw -157.14660934524608\n"
    "Xmp.DLS.Pitch -0.035562203345668203\n"
    "Xmp.DLS.Roll -0.0053124397824206868\n"
    "Xmp.DLS.SpectralIrradiance 0.71537387371063232\n"
    "Xmp.DLS.Yaw -2.7427257414198345\n";

TEST_CASE("parse_capture_meta: a real DLS 1 record is levelled for the sun; what cannot be levelled says why") {
  const CaptureMeta m = parse_capture_meta(kRedEdgeDls1, "IMG_0000_1.tif");
  // MicaSense's negative sub-second: 0.279654 s before 16:12:57.
  REQUIRE(m.time_s.has_value());
  CHECK(*m.time_s == doctest::Approx(unix_utc("2017:07:26 16:12:57") - 0.279654).epsilon(1e-15));
  REQUIRE(m.gps.has_value());
  // The sun over Rochester at 12:13 EDT in late July: about 63 degrees high (declination 19.5,
  // an hour angle of -15 degrees, worked by hand).
  REQUIRE(m.irradiance.has_value());
  REQUIRE(m.sun_elevation_deg.has_value());
  REQUIRE(m.sun_sensor_angle_deg.has_value());
  CHECK(*m.sun_elevation_deg > 62.0);
  CHECK(*m.sun_elevation_deg < 64.5);
  CHECK(m.irradiance_si);
  CHECK(m.irradiance_problem.empty());
  CHECK(m.source.at("irradiance") == "Xmp.DLS.SpectralIrradiance levelled with Xmp.DLS.Yaw/Pitch/Roll");
  // The parse applies the model to the file's own numbers (scale 1: a DLS 1 without a scale key).
  const SunPosition sun = sun_position(*m.time_s, (*m.gps)[0], (*m.gps)[1]);
  const double theta = sun_sensor_angle(sun, -2.7427257414198345, -0.035562203345668203, -0.0053124397824206868);
  CHECK(*m.sun_sensor_angle_deg == doctest::Approx(theta / kDeg));
  CHECK(*m.irradiance == doctest::Approx(level_tilted_reading(0.71537387371063232, theta, sun.elevation)));
  // A sensor within a few degrees of level under a high sun: level ground gets a little less
  // than the sensor facing nearer the sun, over the diffuser's losses.
  CHECK(*m.irradiance > 0.71537387371063232);
  CHECK(*m.irradiance < 0.71537387371063232 / diffuser_transmission(0.0));

  // Without a position, a time, or an attitude the reading stays unlevelled, and the reason is kept.
  const auto without = [](std::string text, const std::string& key) {
    for (std::size_t at; (at = text.find(key)) != std::string::npos;) text.erase(at, text.find('\n', at) - at + 1);
    return parse_capture_meta(text, "a.tif");
  };
  const CaptureMeta no_gps = without(kRedEdgeDls1, "Exif.GPSInfo.GPSLatitude");
  CHECK(!no_gps.irradiance);
  CHECK(no_gps.irradiance_problem == "its DLS 1's tilted reading could not be levelled: the file has no position");
  CHECK(without(kRedEdgeDls1, "Exif.Photo.DateTimeOriginal").irradiance_problem.find("no capture time") !=
        std::string::npos);
  CHECK(without(kRedEdgeDls1, "Xmp.DLS.Roll").irradiance_problem.find("no attitude of the sensor") != std::string::npos);
  // At night (the same place at 04:00 UTC) the sun is below the horizon: a clock that is not UTC.
  std::string night(kRedEdgeDls1);
  night.replace(night.find("16:12:57"), 8, "04:12:57");
  CHECK(parse_capture_meta(night, "a.tif").irradiance_problem.find("above the horizon (expected > 0: is the capture time UTC?)") !=
        std::string::npos);
  // A drone banked 70 degrees away from the sun: its sensor cannot see it.
  std::string banked(kRedEdgeDls1);
  banked.replace(banked.find("Xmp.DLS.Roll -0.0053124397824206868"), 35, "Xmp.DLS.Roll 1.3");
  CHECK(parse_capture_meta(banked, "a.tif").irradiance_problem.find("from the light sensor's normal") != std::string::npos);
  // A malformed attitude is an error naming the file and the key.
  std::string bad(kRedEdgeDls1);
  bad.replace(bad.find("Xmp.DLS.Yaw -2.7427257414198345"), 31, "Xmp.DLS.Yaw north");
  CHECK_THROWS_WITH_AS(parse_capture_meta(bad, "a.tif"), doctest::Contains("a.tif: field 'Xmp.DLS.Yaw'"), IoError);
  // DJI files are not levelled: DJI compensates its sensor's reading itself.
  CHECK(!parse_capture_meta(std::string(kRedEdgeDls1) + "Xmp.drone-dji.ExposureTime 1000\n", "a.tif").sun_elevation_deg);
}

TEST_CASE("parse_capture_meta: a DLS 2 whose firmware wrote HorizontalIrradiance wrongly is recomputed") {
  // An Altum before v1.2.3: the direct and scattered parts are right, the level-ground value is not
  // (MicaSense's library recomputes it from them with its own sun position).
  const std::string text =
      "Exif.Image.Make MicaSense\nExif.Image.Model Altum\nExif.Image.Software v1.1.0\n"
      "Exif.Photo.DateTimeOriginal 2019:06:12 19:02:11\n"
      "Exif.GPSInfo.GPSLatitude 38/1 31/1 1234/100\nExif.GPSInfo.GPSLatitudeRef N\n"
      "Exif.GPSInfo.GPSLongitude 121/1 45/1 5678/100\nExif.GPSInfo.GPSLongitudeRef W\n"
      "Xmp.DLS.HorizontalIrradiance 131.2\nXmp.DLS.DirectIrradiance 118.4\nXmp.DLS.ScatteredIrradiance 26.1\n"
      "Xmp.DLS.SpectralIrradiance 139.0\nXmp.DLS.Yaw 1.2\nXmp.DLS.Pitch -0.1\nXmp.DLS.Roll 0.02\n";
  const CaptureMeta m = parse_capture_meta(text, "IMG_0010_3.tif");
  REQUIRE(m.irradiance.has_value());
  REQUIRE(m.gps.has_value());
  const SunPosition sun = sun_position(*m.time_s, (*m.gps)[0], (*m.gps)[1]);
  // 0.01: MicaSense's unit of a DLS 2 that writes no IrradianceScaleToSIUnits.
  CHECK(*m.irradiance == doctest::Approx(0.01 * (118.4 * std::sin(sun.elevation) + 26.1)));
  CHECK(m.source.at("irradiance") == "Xmp.DLS.DirectIrradiance x sin(sun elevation) + Xmp.DLS.ScatteredIrradiance");
  CHECK(m.irradiance_problem.empty());
  CHECK(!m.sun_sensor_angle_deg);  // the DLS 2 measured its own angles
  // Firmware that wrote it rightly keeps the camera's value.
  std::string good = text;
  good.replace(good.find("v1.1.0"), 6, "v1.3.0");
  const CaptureMeta g = parse_capture_meta(good, "a.tif");
  CHECK(*g.irradiance == doctest::Approx(1.312));
  CHECK(g.source.at("irradiance") == "Xmp.DLS.HorizontalIrradiance");
  // Faulty firmware and nothing to recompute from: both reasons are kept.
  std::string bare = text;
  bare.erase(bare.find("Exif.GPSInfo"), bare.find("Xmp.DLS.Horizontal") - bare.find("Exif.GPSInfo"));
  const CaptureMeta b = parse_capture_meta(bare, "a.tif");
  CHECK(!b.irradiance);
  CHECK(b.irradiance_problem.find("before v1.2.3) wrote HorizontalIrradiance wrongly; its DLS 2's direct and scattered"
                                  " light could not be levelled: the file has no position") != std::string::npos);
}

}  // namespace test_light_sensor_tilt
