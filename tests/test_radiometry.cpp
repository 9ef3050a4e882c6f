// tests/test_radiometry.cpp
// Tests for include/msgs/io/capture_meta.hpp (exiv2 output -> metadata),
// include/msgs/io/radiometry.hpp (DN -> relative radiance or reflectance) and
// include/msgs/io/calibration_panel.hpp (a panel picture -> the band's irradiance) and
// include/msgs/io/panel_list.hpp (the panel pictures a user lists): known values,
// vignetting conventions, band planning with missing tags, and clear errors for malformed text
// and unusable panel pictures instead of crashes.
#include <doctest/doctest.h>

#include <msgs/io/calibration_panel.hpp>
#include <msgs/io/capture_meta.hpp>
#include <msgs/io/panel_list.hpp>
#include <msgs/io/radiometry.hpp>

#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

namespace test_radiometry {
using namespace msgs::io;

namespace {

// What `exiv2 -q -P kv -K ...` prints for a synthetic MicaSense band (and real files' EXIF keys).
const char* kMicaSense =
    "Exif.Image.BitsPerSample                      16\n"
    "Xmp.Camera.BandName                           Green\n"
    "Xmp.Camera.CentralWavelength                  560\n"
    "Xmp.Camera.BlackLevel                         4800\n"
    "Xmp.Camera.VignettingCenter                   82.7, 57.7\n"
    "Xmp.Camera.VignettingPolynomial               0, -3e-05, 0, 2e-10, 0, 0\n"
    "Xmp.exif.FocalLength                          5.5\n"
    "Xmp.exif.FocalPlaneXResolution                24.2\n"
    "Xmp.exif.FocalPlaneResolutionUnit             4\n"
    "Xmp.exif.ExposureTime                         1/1246\n"
    "Xmp.exif.ISOSpeedRatings                      200\n";

}  // namespace

TEST_CASE("capture meta: MicaSense-style XMP as exiv2 prints it") {
  const CaptureMeta m = parse_capture_meta(kMicaSense, "IMG_0001_2.tif");
  CHECK(*m.band_name == "Green");
  CHECK(*m.wavelength_nm == 560);
  CHECK(*m.black_level == 4800);
  CHECK(*m.exposure_s == doctest::Approx(1.0 / 1246));
  CHECK(*m.gain == doctest::Approx(2.0));
  CHECK(m.source.at("gain") == "Xmp.exif.ISOSpeedRatings / 100");
  REQUIRE(m.has_vignetting());
  CHECK(m.vignetting_kind == VignettingKind::falloff);
  CHECK(m.vignetting_poly.size() == 6);
  CHECK((*m.vignetting_centre)[1] == doctest::Approx(57.7));
  CHECK(*m.focal_px() == doctest::Approx(5.5 * 24.2));
  CHECK(*m.bits_per_sample == 16);
}

TEST_CASE("capture meta: real EXIF keys, DJI keys, units and precedence") {
  const char* exif =
      "Exif.Image.BlackLevel                         4800 4800 4800 4802\n"
      "Exif.Photo.ExposureTime                       1/500\n"
      "Exif.Photo.ISOSpeed                           100\n"
      "Exif.Photo.FocalLength                        11/2\n"
      "Exif.Photo.FocalPlaneXResolution              6773.3\n"  // pixels per inch: unit defaults to 2
      "Xmp.exif.ExposureTime                         1/100\n";   // the EXIF value wins
  const CaptureMeta a = parse_capture_meta(exif, "a.tif");
  CHECK(*a.black_level == doctest::Approx(4800.5));
  CHECK(*a.exposure_s == doctest::Approx(0.002));
  CHECK(*a.gain == doctest::Approx(1.0));
  CHECK(*a.focal_plane_px_per_mm == doctest::Approx(6773.3 / 25.4));
  CHECK(!a.has_vignetting());

  const char* dji =
      "Xmp.drone-dji.BlackLevel                      3200\n"
      "Xmp.drone-dji.SensorGain                      1.5\n"
      "Xmp.exif.ISOSpeedRatings                      400\n"  // SensorGain wins over ISO
      "Xmp.drone-dji.VignettingData                  0,1.2e-05,0,3e-11,0,0\n"
      "Xmp.drone-dji.CalibratedOpticalCenterX        83.2\n"
      "Xmp.drone-dji.CalibratedOpticalCenterY        58.2\n";
  const CaptureMeta d = parse_capture_meta(dji, "DJI_x_MS_G.TIF");
  CHECK(*d.gain == 1.5);
  CHECK(d.vignetting_kind == VignettingKind::correction);
  CHECK(d.has_vignetting());
  CHECK(!d.exposure_s);
}

TEST_CASE("capture meta: a MicaSense RedEdge's XMP as exiv2 0.27 prints it") {
  // The Pix4D Camera namespace of a RedEdge file (http://pix4d.com/camera/1.0, no trailing slash;
  // the values are that file's) together with its EXIF black level: the polynomial is a fall-off.
  const char* rededge =
      "Exif.Image.Make                               MicaSense\n"
      "Exif.Image.BlackLevel                         4800 4800 4800 4800\n"
      "Xmp.Camera.BandName                           Blue\n"
      "Xmp.Camera.CentralWavelength                  475\n"
      "Xmp.Camera.VignettingCenter                   687.00738320456162, 476.97042888281499\n"
      "Xmp.Camera.VignettingPolynomial               -0.00010967439073279919, 1.3155710359786701e-06, "
      "-1.1121968712206205e-08, 3.1272962518162695e-11, -3.8345241237884648e-14, 1.6901727679290724e-17\n";
  const CaptureMeta m = parse_capture_meta(rededge, "IMG_0000_1.tif");
  CHECK(*m.band_name == "Blue");
  CHECK(*m.black_level == 4800);
  REQUIRE(m.has_vignetting());
  CHECK(m.vignetting_kind == VignettingKind::falloff);
  CHECK(m.source.at("vignetting") == "Xmp.Camera.VignettingPolynomial");
  RadiometrySteps steps;
  steps.vignetting = true;
  const FrameRadiometry r = frame_radiometry(m, steps, 65535);
  // The corner of the 1280x960 frame records about 0.72 of the centre's light.
  CHECK(vignetting_falloff(r, 0, 0) == doctest::Approx(0.72).epsilon(0.02));
  CHECK_NOTHROW(check_radiometry(r, 1280, 960, "IMG_0000_1.tif"));
}

TEST_CASE("capture meta: DJI files' vignetting polynomials are corrections, whichever key holds them") {
  // A P4 Multispectral writes the correction both as drone-dji:VignettingData and under Pix4D's
  // Camera key; DJI's own data (with its optical centre) is read.
  const CaptureMeta p4 = parse_capture_meta(
      "Exif.Image.Make                               DJI\n"
      "Xmp.Camera.VignettingPolynomial               0, 5e-07, 0, 1e-13\n"
      "Xmp.Camera.VignettingCenter                   800, 650\n"
      "Xmp.drone-dji.VignettingData                  0,1.2e-05,0,3e-11,0,0\n"
      "Xmp.drone-dji.CalibratedOpticalCenterX        812.5\n"
      "Xmp.drone-dji.CalibratedOpticalCenterY        640.25\n"
      "Xmp.drone-dji.BlackLevel                      4096\n",
      "DJI_0011.TIF");
  CHECK(p4.vignetting_kind == VignettingKind::correction);
  CHECK(p4.source.at("vignetting") == "Xmp.drone-dji.VignettingData");
  CHECK((*p4.vignetting_centre)[0] == 812.5);
  CHECK(*p4.black_level == 4096);

  // A Mavic 3M: the Camera key alone, the black level as Camera:BlackCurrent, the exposure in
  // microseconds in DJI's XMP.
  const char* m3m =
      "Exif.Image.Make                               DJI\n"
      "Xmp.Camera.BandName                           NIR\n"
      "Xmp.Camera.BlackCurrent                       3200\n"
      "Xmp.Camera.VignettingPolynomial               0, 5e-07, 0, 1e-13\n"
      "Xmp.Camera.VignettingCenter                   648, 486\n"
      "Xmp.drone-dji.ExposureTime                    1250\n"
      "Xmp.drone-dji.SensorGain                      1.044\n";
  const CaptureMeta d = parse_capture_meta(m3m, "DJI_20240101120000_0001_MS_NIR.TIF");
  CHECK(d.vignetting_kind == VignettingKind::correction);
  CHECK(d.source.at("vignetting") == "Xmp.Camera.VignettingPolynomial");
  CHECK(*d.black_level == 3200);
  CHECK(d.source.at("black_level") == "Xmp.Camera.BlackCurrent");
  CHECK(*d.exposure_s == doctest::Approx(0.00125));
  CHECK(d.source.at("exposure_s") == "Xmp.drone-dji.ExposureTime");
  RadiometrySteps steps;
  steps.vignetting = true;
  const FrameRadiometry r = frame_radiometry(d, steps, 65535);
  CHECK(vignetting_falloff(r, 0, 0) < 1.0);
  CHECK_NOTHROW(check_radiometry(r, 1296, 972, "x.tif"));
  // DJI's whole microseconds win over an EXIF exposure rounded to a shutter-speed step.
  const CaptureMeta both = parse_capture_meta(std::string(m3m) + "Exif.Photo.ExposureTime 1/800\n", "x.tif");
  CHECK(*both.exposure_s == doctest::Approx(0.00125));
  CHECK(both.source.at("exposure_s") == "Xmp.drone-dji.ExposureTime");
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.drone-dji.ExposureTime -3\n", "x.tif"),
                       doctest::Contains("microseconds"), IoError);

  // Any drone-dji key marks a DJI file when the make is missing; without a DJI optical centre the
  // Camera key's polynomial and centre are used.
  const CaptureMeta no_make = parse_capture_meta(
      "Xmp.drone-dji.VignettingData 0,1e-05\nXmp.Camera.VignettingPolynomial 0, 2e-05\n"
      "Xmp.Camera.VignettingCenter 10, 20\n",
      "x.tif");
  CHECK(no_make.vignetting_kind == VignettingKind::correction);
  CHECK(no_make.source.at("vignetting") == "Xmp.Camera.VignettingPolynomial");
  CHECK((*no_make.vignetting_centre)[1] == 20);
}

TEST_CASE("capture meta: the 2-D vignetting polynomial of Parrot Sequoia and MicaSense RedEdge-P") {
  // sum_i c_i (x/W)^a_i (y/H)^b_i, the exponent pairs in the Name key; read where no radial model is.
  const char* sequoia =
      "Xmp.Camera.BandName                           Green\n"
      "Xmp.Camera.VignettingPolynomial2D             0.7, 0.6, 0.6, -0.6, -0.6\n"
      "Xmp.Camera.VignettingPolynomial2DName         0, 0, 1, 0, 0, 1, 2, 0, 0, 2\n";
  const CaptureMeta m = parse_capture_meta(sequoia, "IMG_240601_100000_0001_GRE.TIF");
  REQUIRE(m.has_vignetting());
  CHECK(!m.has_radial_vignetting());
  CHECK(m.source.at("vignetting") == "Xmp.Camera.VignettingPolynomial2D");
  REQUIRE(m.vignetting_exp2d.size() == 5);
  CHECK(m.vignetting_exp2d[3] == std::array<int, 2>{2, 0});
  RadiometrySteps steps;
  steps.vignetting = true;
  const FrameRadiometry r = frame_radiometry(m, steps, 65535, 200, 100);
  CHECK(vignetting_falloff(r, 100, 50) == doctest::Approx(1.0));  // u = v = 1/2
  CHECK(vignetting_falloff(r, 0, 0) == doctest::Approx(0.7));
  CHECK(vignetting_falloff(r, 100, 0) == doctest::Approx(0.85));
  msgs::Image<float> img(200, 100, 1);
  img.at(0, 0, 0) = 0.7f * 0.5f;
  img.at(100, 50, 0) = 0.5f;
  const auto n = normalise_image(img, r, "x.tif");  // divided by the fall-off: one radiance
  CHECK(n.at(0, 0, 0) == doctest::Approx(n.at(100, 50, 0)).epsilon(1e-5));

  // A radial model, where there is one, wins; a 2-D model without its exponents, or with the
  // wrong number of them, is an error naming the key.
  const CaptureMeta both = parse_capture_meta(std::string(kMicaSense) + sequoia, "x.tif");
  CHECK(both.has_radial_vignetting());
  CHECK(both.vignetting_poly2d.empty());
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.Camera.VignettingPolynomial2D 1, 2\n", "x.tif"),
                       doctest::Contains("Xmp.Camera.VignettingPolynomial2D"), IoError);
  CHECK_THROWS_WITH_AS(
      parse_capture_meta("Xmp.Camera.VignettingPolynomial2D 1, 2\nXmp.Camera.VignettingPolynomial2DName 0, 0, 1\n", "x.tif"),
      doctest::Contains("two exponents (of x and y) for each of the 2 coefficients"), IoError);
  CHECK_THROWS_WITH_AS(
      parse_capture_meta("Xmp.Camera.VignettingPolynomial2D 1\nXmp.Camera.VignettingPolynomial2DName 0, 1.5\n", "x.tif"),
      doctest::Contains("whole exponents"), IoError);

  // The checks: the size it was set up for, positive over the image, no brighter corners.
  CHECK_THROWS_WITH_AS(normalise_image(msgs::Image<float>(20, 10, 1), r, "x.tif"), doctest::Contains("set up for a 200x100"),
                       IoError);
  FrameRadiometry bright = r;
  bright.vignetting_poly2d = {1.3, -0.6, -0.6, 0.6, 0.6};  // 1.3 - 0.6 (...): 1.0 at the centre, 1.3 in the corners
  CHECK_THROWS_WITH_AS(normalise_image(img, bright, "x.tif"),
                       doctest::Contains("(the 2-D fall-off polynomial) makes a corner 1.3 times as bright"), IoError);
  FrameRadiometry hole = r;
  hole.vignetting_poly2d = {-0.3, 0.6, 0.6, -0.6, -0.6};  // 0 at the centre
  CHECK_THROWS_WITH_AS(normalise_image(img, hole, "x.tif"), doctest::Contains("2-D vignetting polynomial is"), IoError);
}

TEST_CASE("radiometry: the Parrot Sequoia's SensorModel takes the place of the black level and exposure x gain") {
  // Parrot's irradiance f^2 (DN / V - B) / (A exposure ISO + C), V the 2-D fall-off.
  const std::string sequoia =
      "Xmp.Camera.BandName                           NIR\n"
      "Xmp.Camera.VignettingPolynomial2D             0.7, 0.6, 0.6, -0.6, -0.6\n"
      "Xmp.Camera.VignettingPolynomial2DName         0, 0, 1, 0, 0, 1, 2, 0, 0, 2\n"
      "Xmp.Camera.SensorModel                        85000,210.5,170\n"
      "Exif.Photo.ExposureTime                       1/1000\n"
      "Exif.Photo.ISOSpeedRatings                    200\n";
  const CaptureMeta m = parse_capture_meta(sequoia, "IMG_0001_NIR.TIF");
  REQUIRE(m.sensor_model);
  CHECK(*m.sensor_model == std::array<double, 3>{85000, 210.5, 170});
  CHECK(m.source.at("sensor_model") == "Xmp.Camera.SensorModel");

  // Every image with it: the model, and no black level wanted (in any mode).
  for (const Calibration c : {Calibration::relative, Calibration::panel}) {
    const BandPlan plan = plan_band({m, m}, {"a.TIF", "b.TIF"}, c);
    CHECK(plan.missing.empty());
    CHECK(plan.steps.sensor_model);
    CHECK(!plan.steps.black_level);
  }
  const BandPlan plan = plan_band({m}, {"a.TIF"});
  FrameRadiometry r = frame_radiometry(m, plan.steps, 65535, 200, 100);
  r.scale = 1.0;
  const double response = 85000 * 0.001 * 200 + 170;  // A exposure ISO + C
  CHECK(exposure_response(r) == doctest::Approx(response));
  for (const auto& [x, y] : {std::array<double, 2>{100, 50}, std::array<double, 2>{0, 0}, std::array<double, 2>{150, 10}}) {
    const double V = vignetting_falloff(r, x, y), dn = 12000.0;
    CHECK(dark_level(r, x, y) == doctest::Approx(210.5 * V));
    CHECK(relative_radiance(dn, x, y, r) == doctest::Approx((dn / V - 210.5) / response).epsilon(1e-12));
  }
  msgs::Image<float> img(200, 100, 1);
  img.at(0, 0, 0) = float(12000.0 / 65535.0);
  const auto n = normalise_image(img, r, "x.tif");
  CHECK(n.at(0, 0, 0) == doctest::Approx((12000.0 / 0.7 - 210.5) / response).epsilon(1e-6));
  CHECK(n.at(1, 0, 0) == 0.0f);  // DN 0, below the dark level: 0

  // The model in some images only: the others miss it. A model whose response is not positive, or
  // malformed text, is an error naming the file.
  CaptureMeta without = m;
  without.sensor_model.reset();
  const BandPlan some = plan_band({m, without}, {"a.TIF", "b.TIF"});
  CHECK(some.missing.at("sensor model (Parrot SensorModel)") == std::vector<std::filesystem::path>{"b.TIF"});
  CHECK(!some.steps.sensor_model);
  FrameRadiometry negative = r;
  negative.model_c = -1e6;
  CHECK_THROWS_WITH_AS(normalise_image(img, negative, "x.tif"),
                       doctest::Contains("x.tif: the sensor model's A x exposure x ISO + C is"), IoError);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.Camera.SensorModel 1,2\n", "x.tif"),
                       doctest::Contains("x.tif: field 'Xmp.Camera.SensorModel'"), IoError);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.Camera.SensorModel 0,2,3\n", "x.tif"),
                       doctest::Contains("three numbers A, B, C with A > 0"), IoError);
}

TEST_CASE("radiometry: MicaSense's row gradient, from RadiometricCalibration") {
  // A RedEdge's a1, a2, a3; row y is recorded 1 + a2 y / exposure - a3 y times as bright.
  const std::string text = std::string(kMicaSense) +
                           "Xmp.MicaSense.RadiometricCalibration          0.000145914, 1.39479e-07, 1.1714499999999999e-05\n";
  const CaptureMeta m = parse_capture_meta(text, "IMG_0001_2.tif");
  REQUIRE(m.row_gradient.has_value());
  CHECK((*m.row_gradient)[1] == doctest::Approx(1.17145e-05));
  const BandPlan p = plan_band({m, m}, {"a.tif", "b.tif"});
  CHECK(p.steps.row_gradient);
  FrameRadiometry r = frame_radiometry(m, p.steps, 65535, 1280, 960);
  r.exposure_s = 0.0005;
  const double row959 = 1 + 1.39479e-07 * 959 / 0.0005 - 1.17145e-05 * 959;  // 1.256
  CHECK(row_gradient_factor(r, 959) == doctest::Approx(row959));
  CHECK(row_gradient_factor(r, 0) == 1.0);
  // Divided out: the same radiance in the first and the last row.
  const double dn0 = r.black_level + 1000.0 * vignetting_falloff(r, 640, 0);
  const double dn1 = r.black_level + 1000.0 * vignetting_falloff(r, 640, 959) * row959;
  CHECK(relative_radiance(dn0, 640, 0, r) == doctest::Approx(relative_radiance(dn1, 640, 959, r)));

  // Only MicaSense writes it: a band without it anywhere is missing nothing; a band where some
  // images lack it leaves it out with a warning; without the exposure it cannot be applied.
  const CaptureMeta plain = parse_capture_meta(kMicaSense, "a.tif");
  CHECK(!plan_band({plain, plain}, {"a.tif", "b.tif"}).steps.row_gradient);
  CHECK(plan_band({plain, plain}, {"a.tif", "b.tif"}).missing.empty());
  const BandPlan some = plan_band({m, plain}, {"a.tif", "b.tif"});
  CHECK(!some.steps.row_gradient);
  CHECK(some.missing.count("row gradient (MicaSense RadiometricCalibration)") == 1);
  CaptureMeta no_exposure = m;
  no_exposure.exposure_s.reset();
  CHECK(!plan_band({no_exposure}, {"a.tif"}).steps.row_gradient);
  // Malformed, or a gradient that reaches zero within the image: errors naming the file.
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.MicaSense.RadiometricCalibration 1, 2\n", "x.tif"),
                       doctest::Contains("three numbers (a1, a2, a3)"), IoError);
  r.row_a3 = 0.01;  // 1 + ... - 0.01 y: below zero long before row 959
  CHECK_THROWS_WITH_AS(normalise_image(msgs::Image<float>(1280, 960, 1), r, "x.tif"),
                       doctest::Contains("x.tif: the row gradient"), IoError);
}

TEST_CASE("radiometry: reflectance from MicaSense's a1 and the DLS 2 irradiance") {
  const std::string cal = "Xmp.MicaSense.RadiometricCalibration          0.000145914, 1.39479e-07, 1.17145e-05\n";
  const std::string text = std::string(kMicaSense) + cal +
                           "Xmp.Camera.HorizontalIrradiance               120.5\n"
                           "Xmp.Camera.IrradianceScaleToSIUnits           0.01\n";
  const CaptureMeta m = parse_capture_meta(text, "IMG_0001_2.tif");
  REQUIRE(m.radiance_a1.has_value());
  CHECK(*m.radiance_a1 == doctest::Approx(0.000145914));
  REQUIRE(m.irradiance.has_value());
  CHECK(*m.irradiance == doctest::Approx(1.205));
  CHECK(m.source.at("irradiance") == "Xmp.Camera.HorizontalIrradiance");
  // Without the scale key, MicaSense's library takes 0.01; the DLS namespace is read too.
  const CaptureMeta dls = parse_capture_meta(std::string(kMicaSense) + "Xmp.DLS.HorizontalIrradiance 98\n", "a.tif");
  CHECK(*dls.irradiance == doctest::Approx(0.98));
  // No reading (0) is no irradiance, and no error; a negative one is an error naming the key.
  CHECK(!parse_capture_meta("Xmp.Camera.HorizontalIrradiance 0\n", "a.tif").irradiance);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.Camera.HorizontalIrradiance -3\n", "a.tif"),
                       doctest::Contains("a.tif: field 'Xmp.Camera.HorizontalIrradiance'"), IoError);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Xmp.Camera.HorizontalIrradiance 1\nXmp.Camera.IrradianceScaleToSIUnits 0\n", "a.tif"),
                       doctest::Contains("IrradianceScaleToSIUnits"), IoError);
  // Firmware that wrote HorizontalIrradiance wrongly (MicaSense's library recomputes it there).
  const auto with = [&](const char* model, const char* software) {
    return parse_capture_meta(text + "Exif.Image.Model " + model + "\nExif.Image.Software " + software + "\n", "a.tif");
  };
  CHECK(!with("RedEdge-M", "v5.1.6").irradiance);
  CHECK(with("RedEdge-M", "v5.1.6").irradiance_problem.find("before v5.1.7") != std::string::npos);
  CHECK(with("RedEdge-M", "v6.2.0").irradiance.has_value());
  CHECK(!with("Altum", "v1.2.2").irradiance);
  CHECK(with("Altum", "v1.10.0").irradiance.has_value());
  CHECK(!with("RedEdge", "unknown").irradiance);
  CHECK(with("RedEdge-P", "v1.0.0").irradiance.has_value());  // not affected

  // The plan for reflectance needs every step, a1 and the irradiance in every image.
  const BandPlan p = plan_band({m, m}, {"a.tif", "b.tif"}, Calibration::sun_sensor);
  CHECK(p.missing.empty());
  CHECK(p.steps.irradiance);
  CHECK(!plan_band({m, m}, {"a.tif", "b.tif"}).steps.irradiance);  // relative radiance ignores it
  CaptureMeta dark = m;
  dark.irradiance.reset();
  const BandPlan q = plan_band({m, dark}, {"a.tif", "b.tif"}, Calibration::sun_sensor);
  CHECK(!q.steps.irradiance);
  REQUIRE(q.missing.count("horizontal irradiance (MicaSense DLS 2)") == 1);
  CHECK(q.missing.at("horizontal irradiance (MicaSense DLS 2)") == std::vector<std::filesystem::path>{"b.tif"});
  const CaptureMeta plain = parse_capture_meta(kMicaSense, "c.tif");
  const BandPlan none = plan_band({plain}, {"c.tif"}, Calibration::sun_sensor);
  CHECK(none.missing.count("radiance calibration a1 (MicaSense RadiometricCalibration)") == 1);
  CHECK(none.missing.count("row gradient (MicaSense RadiometricCalibration)") == 1);

  // Known numbers: reflectance 0.1 under 1.205 W/m^2/nm is radiance 0.1 x 1.205 / pi; DN from
  // MicaSense's model, radiance = a1 (DN - black) / 2^16 / (exposure gain fall-off row).
  FrameRadiometry r = frame_radiometry(m, p.steps, 65535, 160, 120);
  r.scale = reflectance_scale(r);
  CHECK(r.scale == doctest::Approx(3.14159265358979 * 0.000145914 / 65536));
  const double x = 30, y = 90, rho = 0.1;
  const double radiance = rho * 1.205 / 3.14159265358979;
  const double response = r.exposure_s * r.gain * vignetting_falloff(r, x, y) * row_gradient_factor(r, y);
  const double dn = 4800 + radiance * 65536 / 0.000145914 * response;
  CHECK(relative_radiance(dn, x, y, r) * r.scale == doctest::Approx(rho));
  msgs::Image<float> img(160, 120, 1);
  img.at(int(x), int(y), 0) = float(dn / 65535);
  CHECK(normalise_image(img, r, "a.tif").at(int(x), int(y), 0) == doctest::Approx(rho).epsilon(1e-4));
  r.irradiance = 0;
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "a.tif"), doctest::Contains("a.tif: light sensor reading 0"), IoError);
}

TEST_CASE("radiometry: DJI's sunlight sensor and SensorGainAdjustment, reflectance up to one factor for all bands") {
  // A Mavic 3M band image's keys, as exiv2 prints them (values of the kind real files carry).
  const std::string dji =
      "Exif.Image.Make                               DJI\n"
      "Xmp.Camera.BlackCurrent                       3200\n"
      "Xmp.drone-dji.ExposureTime                    732\n"
      "Xmp.drone-dji.SensorGain                      1\n"
      "Xmp.drone-dji.SensorGainAdjustment            1.033\n"
      "Xmp.drone-dji.Irradiance                      16077.6\n"
      "Xmp.drone-dji.VignettingData                  0,1.2e-05,0,3e-11,0,0\n"
      "Xmp.drone-dji.CalibratedOpticalCenterX        83.2\n"
      "Xmp.drone-dji.CalibratedOpticalCenterY        58.2\n";
  const CaptureMeta m = parse_capture_meta(dji, "DJI_0001_MS_RE.TIF");
  REQUIRE(m.irradiance);
  CHECK(*m.irradiance == 16077.6);
  CHECK(!m.irradiance_si);  // the sensor's own units
  CHECK(m.source.at("irradiance") == "Xmp.drone-dji.Irradiance");
  CHECK(*m.gain_adjustment == 1.033);
  // Pix4D's Camera:Irradiance where a DJI file has no drone-dji key for it; a zero is no reading.
  CHECK(*parse_capture_meta("Exif.Image.Make DJI\nXmp.Camera.Irradiance 900.5\n", "d.tif").irradiance == 900.5);
  CHECK(!parse_capture_meta("Exif.Image.Make DJI\nXmp.drone-dji.Irradiance 0\n", "d.tif").irradiance);
  // MicaSense's Camera:Irradiance is the DLS facing the sky, not a level-surface value: not read.
  CHECK(!parse_capture_meta("Exif.Image.Make MicaSense\nXmp.Camera.Irradiance 0.98\n", "i.tif").irradiance);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Exif.Image.Make DJI\nXmp.drone-dji.SensorGainAdjustment -1\n", "d.tif"),
                       doctest::Contains("d.tif: field 'Xmp.drone-dji.SensorGainAdjustment'"), IoError);
  CHECK_THROWS_WITH_AS(parse_capture_meta("Exif.Image.Make DJI\nXmp.drone-dji.Irradiance x\n", "d.tif"),
                       doctest::Contains("is not a sunlight-sensor reading"), IoError);

  // The plans: sun-sensor takes DJI's reading and band factor; reflectance wants W/m^2/nm and a1;
  // panel+dls takes the reading alone.
  const BandPlan p = plan_band({m, m}, {"a.TIF", "b.TIF"}, Calibration::sun_sensor_relative);
  CHECK(p.missing.empty());
  CHECK(p.steps.irradiance);
  CHECK(p.steps.black_level);
  CHECK(p.steps.vignetting);
  const BandPlan refl = plan_band({m}, {"a.TIF"}, Calibration::sun_sensor);
  CHECK(refl.missing.count("horizontal irradiance (MicaSense DLS 2)") == 1);
  CHECK(refl.missing.count("radiance calibration a1 (MicaSense RadiometricCalibration)") == 1);
  CHECK(plan_band({m}, {"a.TIF"}, Calibration::panel_and_sun_sensor).missing.empty());
  CaptureMeta no_adjustment = m, no_reading = m;
  no_adjustment.gain_adjustment.reset();
  no_reading.irradiance.reset();
  const BandPlan q = plan_band({m, no_adjustment, no_reading}, {"a.TIF", "b.TIF", "c.TIF"}, Calibration::sun_sensor_relative);
  CHECK(q.missing.at("band calibration (DJI SensorGainAdjustment, MicaSense RadiometricCalibration)") ==
        std::vector<std::filesystem::path>{"b.TIF"});
  CHECK(q.missing.at("light sensor reading (MicaSense DLS 2 HorizontalIrradiance, DJI Irradiance)") ==
        std::vector<std::filesystem::path>{"c.TIF"});

  // DJI's formula: (DN - black) / 2^16 / (exposure x gain) x vignetting correction x
  // SensorGainAdjustment / Irradiance, here for a pixel at the vignetting centre.
  FrameRadiometry r = frame_radiometry(m, p.steps, 65535, 160, 120);
  r.scale = light_sensor_scale(r);
  const double dn = 20000, x = 83.2, y = 58.2;
  const double dji_ratio = (dn - 3200) / 65536 / (732e-6 * 1.0) * 1.033 / 16077.6;
  CHECK(relative_radiance(dn, x, y, r) * r.scale == doctest::Approx(dji_ratio).epsilon(1e-12));
  // Off the centre the correction polynomial multiplies.
  const double corr = 1 + 1.2e-05 * 1e2 + 3e-11 * 1e4;  // r = 10 px: 1 + k1 r^2 + k3 r^4
  CHECK(relative_radiance(dn, x + 10, y, r) * r.scale == doctest::Approx(dji_ratio * corr).epsilon(1e-12));
  // With MicaSense's a1 the same factor is pi a1 / 2^16.
  FrameRadiometry a = r;
  a.radiance_a1 = 1e-4;
  CHECK(light_sensor_scale(a) == doctest::Approx(std::numbers::pi * 1e-4 / 65536));
  a.radiance_a1 = 0;
  a.gain_adjustment = 0;
  CHECK(light_sensor_scale(a) == 0);
}

TEST_CASE("calibration panel: tags, the area's pixels, the band's irradiance, and unusable pictures") {
  const std::string cal = "Xmp.MicaSense.RadiometricCalibration          0.000145914, 1.39479e-07, 1.17145e-05\n";
  const std::string panel = std::string(kMicaSense) + cal +
                            "Xmp.Camera.CalibrationPicture                 2\n"
                            "Xmp.Camera.Albedo                             0.4985\n"
                            "Xmp.Camera.ReflectArea                        60,40,40,40,40,60,60,60\n"
                            "Xmp.Camera.PanelSerial                        RP04-1234567-OB\n";
  const CaptureMeta m = parse_capture_meta(panel, "IMG_0006_2.tif");
  CHECK(m.calibration_picture == 2);
  REQUIRE(m.panel_albedo.has_value());
  CHECK(*m.panel_albedo == doctest::Approx(0.4985));
  REQUIRE(m.panel_area.has_value());
  CHECK((*m.panel_area)[1] == std::array<double, 2>{40, 40});
  CHECK(m.panel_serial == "RP04-1234567-OB");
  CHECK(parse_capture_meta(kMicaSense, "a.tif").calibration_picture == 0);
  for (const char* bad : {"Xmp.Camera.CalibrationPicture 3\n", "Xmp.Camera.Albedo 1.5\n", "Xmp.Camera.Albedo 0\n",
                          "Xmp.Camera.ReflectArea 1,2,3,4,5,6\n", "Xmp.Camera.ReflectArea 1,2,3,4,5,6,7,x\n"}) {
    CAPTURE(bad);
    CHECK_THROWS_WITH_AS(parse_capture_meta(bad, "p.tif"), doctest::Contains("p.tif: field 'Xmp.Camera."), IoError);
  }

  // The quadrilateral: corners in either direction; a bow tie or a sliver is not an area.
  const PanelArea square = {{{60, 40}, {40, 40}, {40, 60}, {60, 60}}};
  const PanelArea reversed = {{{60, 60}, {40, 60}, {40, 40}, {60, 40}}};
  CHECK(convex_quad(square));
  CHECK(convex_quad(reversed));
  CHECK(!convex_quad({{{60, 40}, {40, 60}, {40, 40}, {60, 60}}}));
  CHECK(!convex_quad({{{0, 0}, {10, 0}, {20, 0}, {5, 5}}}));
  CHECK(inside_quad(square, 50, 50));
  CHECK(inside_quad(square, 40, 60));  // a corner
  CHECK(inside_quad(reversed, 60, 50));  // an edge
  CHECK(!inside_quad(square, 61, 50));
  const PanelArea diamond = {{{50, 30}, {30, 50}, {50, 70}, {70, 50}}};
  CHECK(inside_quad(diamond, 50, 50));
  CHECK(!inside_quad(diamond, 35, 35));

  // A picture whose panel area is reflectance 0.4985 under E = 0.1 W/m^2/nm (a dim sky), through
  // MicaSense's model (DN = black + radiance 2^16 / a1 x response), and a brighter background that
  // must not count.
  const BandPlan plan = plan_band({m}, {"IMG_0006_2.tif"}, Calibration::panel);
  CHECK(plan.missing.empty());
  CHECK(!plan.steps.irradiance);
  FrameRadiometry r = frame_radiometry(m, plan.steps, 65535, 160, 120);
  const double e = 0.1, a1 = 0.000145914;
  msgs::Image<float> img(160, 120, 1);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      const double rho = inside_quad(square, x, y) ? 0.4985 : 0.9;
      const double response = r.exposure_s * r.gain * vignetting_falloff(r, x, y) * row_gradient_factor(r, y);
      img.at(x, y, 0) = float((4800 + rho * e / 3.14159265358979 * 65536 / a1 * response) / 65535);
    }
  const PanelReading reading = read_panel(img, r, *m.panel_area, "IMG_0006_2.tif");
  CHECK(reading.pixels == 21 * 21);  // whole pixels on the edges count
  CHECK(reading.saturated == 0);
  // The band's scale 1 / E in the sensor's units; with a1, E in W/m^2/nm.
  r.scale = *m.panel_albedo / reading.mean;
  CHECK(reflectance_irradiance(r) == doctest::Approx(e).epsilon(1e-4));
  CHECK(relative_radiance(double(img.at(50, 50, 0)) * 65535, 50, 50, r) * r.scale == doctest::Approx(0.4985).epsilon(1e-4));

  // Unusable pictures: errors naming the file and what to do.
  const PanelArea outside = {{{500, 40}, {480, 40}, {480, 60}, {500, 60}}};
  CHECK_THROWS_WITH_AS(read_panel(img, r, outside, "p.tif"), doctest::Contains("holds 0 pixels of the 160x120 image"), IoError);
  CHECK_THROWS_WITH_AS(read_panel(img, r, {{{60, 40}, {40, 60}, {40, 40}, {60, 60}}}, "p.tif"),
                       doctest::Contains("p.tif: field 'Xmp.Camera.ReflectArea'"), IoError);
  msgs::Image<float> clipped = img;
  for (int x = 40; x <= 60; ++x) clipped.at(x, 45, 0) = 1.0f;  // 21 of 441 pixels: 4.8%
  CHECK_THROWS_WITH_AS(read_panel(clipped, r, square, "p.tif"),
                       doctest::Contains("21 of the 441 pixels of the panel area have clipped"), IoError);
  msgs::Image<float> dark(160, 120, 1);  // all at the black level: not a panel
  for (float& v : dark.data) v = float(4800.0 / 65535);
  CHECK_THROWS_WITH_AS(read_panel(dark, r, square, "p.tif"), doctest::Contains("no brighter than the black level"), IoError);

  // panel+dls needs the light sensor in every image; the panel alone needs neither it nor a1.
  CaptureMeta no_a1 = m;
  no_a1.radiance_a1.reset();
  CHECK(plan_band({no_a1}, {"a.tif"}, Calibration::panel).missing.empty());
  const BandPlan both = plan_band({no_a1}, {"a.tif"}, Calibration::panel_and_sun_sensor);
  CHECK(both.missing.count("light sensor reading (MicaSense DLS 2 HorizontalIrradiance, DJI Irradiance)") == 1);
  CHECK(both.missing.count("radiance calibration a1 (MicaSense RadiometricCalibration)") == 0);
  CaptureMeta no_black = m;
  no_black.black_level.reset();
  CHECK(plan_band({m, no_black}, {"a.tif", "b.tif"}, Calibration::panel).missing.count("black level") == 1);
}

TEST_CASE("capture time and the panel's irradiance interpolated in time between sessions") {
  // EXIF and XMP forms; sub-seconds are a decimal fraction; a time zone is ignored.
  CHECK(*parse_date_time("1970:01:02 00:00:01") == 86401.0);
  CHECK(*parse_date_time("2024:07:30 10:15:32") == doctest::Approx(1722334532.0));
  CHECK(*parse_date_time("2024-07-30T10:15:32.25+02:00") == doctest::Approx(1722334532.25));
  CHECK(*parse_date_time("2000-02-29T00:00:00Z") == 951782400.0);  // a leap day
  for (const char* junk : {"", "2024:07:30", "2024:13:30 10:15:32", "2024-07-30 10:15:32", "2024:07:30T10:15:32",
                           "abcd:07:30 10:15:32", "2024:07:30 25:15:32", "0000:00:00 00:00:00"})
    CHECK_MESSAGE(!parse_date_time(junk), junk);
  const CaptureMeta m = parse_capture_meta(
      "Exif.Photo.DateTimeOriginal 2024:07:30 10:15:32\nExif.Photo.SubSecTimeOriginal 25\n"
      "Xmp.exif.DateTimeOriginal 2024-07-30T11:00:00\n",
      "a.tif");
  CHECK(*m.time_s == doctest::Approx(1722334532.25));
  CHECK(m.source.at("time") == "Exif.Photo.DateTimeOriginal");
  CHECK(*parse_capture_meta("Xmp.exif.DateTimeOriginal 2024-07-30T10:15:33\n", "b.tif").time_s ==
        doctest::Approx(1722334533.0));
  // An unreadable time is no error (it only orders panel pictures), but says what was wrong.
  const CaptureMeta bad = parse_capture_meta("Exif.Photo.DateTimeOriginal yesterday\n", "c.tif");
  CHECK(!bad.time_s);
  CHECK(bad.time_problem.find("'yesterday' is not a date and time") != std::string::npos);

  // Three pictures before the flight within seconds, two after it: two sessions, their means.
  const PanelSchedule s = panel_schedule({{2.0, 1000.0}, {2.2, 1004.0}, {1.8, 998.0}, {3.0, 1700.0}, {3.2, 1702.0}});
  REQUIRE(s.timed());
  REQUIRE(s.nodes.size() == 2);
  CHECK(s.nodes[0][0] == doctest::Approx(1000.0 + 2.0 / 3.0));
  CHECK(s.nodes[0][1] == doctest::Approx(2.0));
  CHECK(s.nodes[1][1] == doctest::Approx(3.1));
  CHECK(s.mean == doctest::Approx(2.44));
  const double mid = 0.5 * (s.nodes[0][0] + s.nodes[1][0]);
  CHECK(s.at(mid) == doctest::Approx(2.55));
  CHECK(s.at(0.0) == doctest::Approx(2.0));     // before the first session: its irradiance
  CHECK(s.at(5000.0) == doctest::Approx(3.1));  // after the last
  CHECK(s.at(std::nullopt) == doctest::Approx(2.44));
  // Pictures within kPanelSessionGap of each other, or one without a time: one irradiance.
  CHECK(!panel_schedule({{2.0, 0.0}, {3.0, kPanelSessionGap}}).timed());
  const PanelSchedule untimed = panel_schedule({{2.0, 0.0}, {3.0, std::nullopt}});
  CHECK(!untimed.timed());
  CHECK(untimed.at(5.0) == doctest::Approx(2.5));
  // Three sessions: piecewise linear through them.
  const PanelSchedule three = panel_schedule({{1.0, 0.0}, {2.0, 1000.0}, {1.0, 2000.0}});
  CHECK(three.nodes.size() == 3);
  CHECK(three.at(500.0) == doctest::Approx(1.5));
  CHECK(three.at(1500.0) == doctest::Approx(1.5));
}

TEST_CASE("panel_line: panels of several reflectances give the empirical line's offset") {
  // response = E (rho + 0.04): a grey and a dark panel in each of two sessions, the light 20%
  // brighter in the second; panels of one reflectance elsewhere add nothing to the line.
  const auto response = [](double e, double rho) { return e * (rho + 0.04); };
  const std::vector<PanelResponse> two = {{response(2.0, 0.5), 0.5, 1000.0},
                                          {response(2.0, 0.1), 0.1, 1002.0},
                                          {response(2.4, 0.1), 0.1, 4000.0},
                                          {response(2.4, 0.5), 0.5, 4003.0},
                                          {response(2.4, 0.52), 0.52, 4005.0},
                                          {response(3.0, 0.5), 0.5, 9000.0}};
  CHECK(panel_sessions({1000.0, 1002.0, 4000.0, 4003.0, 4005.0, 9000.0}) ==
        std::vector<std::size_t>{0, 0, 1, 1, 1, 2});
  CHECK(panel_sessions({9000.0, 1000.0, std::nullopt}) == std::vector<std::size_t>{0, 0, 0});
  const PanelLine line = panel_line(two);
  CHECK_MESSAGE(line.fitted(), line.problem);
  CHECK(line.offset == doctest::Approx(0.04).epsilon(1e-12));
  CHECK(line.sessions == 2);
  CHECK(line.low_albedo == 0.1);
  CHECK(line.high_albedo == 0.52);
  // Each picture's irradiance from albedo + offset is its session's: the schedule sees no
  // disagreement between the grey and the dark panel.
  for (const PanelResponse& p : two) {
    const double e = p.response / (p.albedo + line.offset);
    CHECK(e == doctest::Approx(*p.time_s < 2000 ? 2.0 : *p.time_s < 5000 ? 2.4 : 3.0).epsilon(1e-12));
  }
  // A negative offset (a black level set too high) is fitted as well.
  const PanelLine below = panel_line({{2.0 * (0.5 - 0.02), 0.5, 0.0}, {2.0 * (0.2 - 0.02), 0.2, 1.0}});
  CHECK_MESSAGE(below.fitted(), below.problem);
  CHECK(below.offset == doctest::Approx(-0.02).epsilon(1e-12));
}

TEST_CASE("panel_line: what gives no line says why, and leaves the line through zero") {
  // One reflectance, or reflectances too close to tell an offset from the light: no line, and
  // nothing wrong.
  for (const std::vector<PanelResponse>& none :
       {std::vector<PanelResponse>{{1.0, 0.5, 0.0}, {1.1, 0.5, 5.0}}, {{1.0, 0.5, 0.0}, {0.8, 0.3, 5.0}}, {}}) {
    const PanelLine n = panel_line(none);
    CHECK(n.offset == 0.0);
    CHECK(n.sessions == 0);
    CHECK(!n.fitted());
    CHECK(n.problem.empty());
  }
  // A dark panel before the flight and a grey one after it: two sessions of one reflectance each.
  PanelLine l = panel_line({{0.2, 0.1, 0.0}, {1.0, 0.5, 1000.0}});
  CHECK(l.offset == 0.0);
  CHECK(!l.fitted());
  CHECK(l.problem.find("no session holds panels whose reflectances lie 2 times apart (panels photographed more than"
                       " 120 s apart do not make one line)") != std::string::npos);
  // The brighter panel reading darker: areas or reflectances swapped.
  l = panel_line({{0.2, 0.5, 0.0}, {1.0, 0.1, 1.0}});
  CHECK(l.offset == 0.0);
  CHECK(l.problem.find("read no brighter for the higher reflectance") != std::string::npos);
  // An offset of 5.9, far beyond what haze gives: a reflectance mistaken.
  l = panel_line({{0.3, 0.1, 0.0}, {0.32, 0.5, 1.0}});
  CHECK(l.offset == 0.0);
  CHECK(l.problem.find("the fitted offset, 5.9, is more than haze or a black level gives (at most 0.25") !=
        std::string::npos);
  // An offset of -0.109, below the darkest panel's reflectance: that panel's light would be negative.
  l = panel_line({{0.001, 0.1, 0.0}, {0.001, 0.12, 1.0}, {1.0, 0.5, 2.0}});
  CHECK(l.offset == 0.0);
  CHECK(l.problem.find("the fitted offset, -0.109, would leave the panel of reflectance 0.1 no light") !=
        std::string::npos);
}

TEST_CASE("calibration panel: the tags of a real RedEdge-P panel capture, as exiv2 prints them") {
  // IMG_0001_1.tif (blue) of a RedEdge-P flight of 2024-07-30, read with exiv2 -q -P kv and the
  // keys of exiv2_metadata_keys(). Measured on its pixels with read_panel: 8470 pixels in the
  // area, none clipped, an irradiance of 1.005 W/m^2/nm under the panel's albedo of 0.517; the DLS 2
  // recorded 0.980 facing the sky (Xmp.Camera.Irradiance) and estimated 0.700 on a level surface.
  const char* text =
    "Exif.Image.BitsPerSample                      16\n"
    "Exif.Image.Make                               MicaSense\n"
    "Exif.Image.Model                              RedEdge-P\n"
    "Exif.Image.Software                           v1.3.1\n"
    "Exif.Photo.ExposureTime                       557575/1000000000\n"
    "Exif.Photo.ISOSpeed                           100\n"
    "Exif.Photo.FocalLength                        550000000/100000000\n"
    "Exif.Photo.FocalPlaneXResolution              289855072/1000000\n"
    "Exif.Photo.FocalPlaneResolutionUnit           4\n"
    "Exif.GPSInfo.GPSLatitudeRef                   N\n"
    "Exif.GPSInfo.GPSLatitude                      500000000/10000000 510000000/10000000 463971600/10000000\n"
    "Exif.GPSInfo.GPSLongitudeRef                  E\n"
    "Exif.GPSInfo.GPSLongitude                     600000000/100000000 310000000/10000000 537823200/10000000\n"
    "Exif.GPSInfo.GPSAltitudeRef                   0\n"
    "Exif.GPSInfo.GPSAltitude                      131277000/1000000\n"
    "Exif.Image.BlackLevel                         3846 3846 3846 3846\n"
    "Xmp.Camera.BandName                           Blue\n"
    "Xmp.Camera.CentralWavelength                  475\n"
    "Xmp.Camera.VignettingPolynomial2DName         0,0,0,1,0,2,0,3,0,4,0,5,1,0,1,1,1,2,1,3,1,4,2,0,2,1,2,2,2,3,3,0,3,1,3,2,4,0,4,1,5,0\n"
    "Xmp.Camera.VignettingPolynomial2D             0.505123,0.440381,-0.485391,-0.101444,0.334918,-0.207206,1.438164,-0.699895,0.842299,0.042787,-0.147030,-0.769551,1.374026,-1.246214,0.122442,-1.806520,-0.839078,0.302632,1.974362,0.262407,-0.789175\n"
    "Xmp.Camera.Albedo                             0.51700000000000002\n"
    "Xmp.Camera.ReflectArea                        910,765,1003,763,1001,672,908,674\n"
    "Xmp.Camera.CalibrationPicture                 2\n"
    "Xmp.MicaSense.RadiometricCalibration          0.00018286520000000001, -2.1597300000000001e-08, 8.6948789999999996e-05\n"
    "Xmp.MicaSense.PanelSerial                     RP06-2304022-OB\n"
    "Xmp.DLS.HorizontalIrradiance                  69.95928235648455\n";
  const CaptureMeta m = parse_capture_meta(text, "IMG_0001_1.tif");
  CHECK(m.calibration_picture == 2);
  CHECK(*m.panel_albedo == doctest::Approx(0.517));
  REQUIRE(m.panel_area.has_value());
  CHECK(*m.panel_area == PanelArea{{{910, 765}, {1003, 763}, {1001, 672}, {908, 674}}});
  CHECK(convex_quad(*m.panel_area));
  CHECK(m.panel_serial == "RP06-2304022-OB");
  CHECK(*m.irradiance == doctest::Approx(0.6995928));
  CHECK(m.source.at("irradiance") == "Xmp.DLS.HorizontalIrradiance");
  CHECK(*m.exposure_s == doctest::Approx(557575e-9));
  CHECK(*m.radiance_a1 == doctest::Approx(0.0001828652));
  const BandPlan plan = plan_band({m}, {"IMG_0001_1.tif"}, Calibration::panel_and_sun_sensor);
  CHECK(plan.missing.empty());
  CHECK((plan.steps.black_level && plan.steps.exposure && plan.steps.gain && plan.steps.vignetting &&
         plan.steps.row_gradient && plan.steps.irradiance));
  const FrameRadiometry r = frame_radiometry(m, plan.steps, 65535, 1456, 1088);
  CHECK(r.vignetting_poly2d.size() == 21);
  CHECK_NOTHROW(check_radiometry(r, 1456, 1088, "IMG_0001_1.tif"));
}

TEST_CASE("panel list: pictures, areas and albedos as --panels reads them; malformed lists name the field") {
  const auto list = parse_panel_list(R"({"albedo": 0.49, "pictures": [
      {"file": "sub/./DJI_0007_MS_G.TIF", "area": [[60, 40], [40, 40], [40, 60], [60, 60]]},
      {"file": "DJI_0007_MS_R.TIF", "area": [[60.5, 40], [40, 40], [40, 60], [60, 60]], "albedo": 0.51}]})",
                                     "panels.json");
  REQUIRE(list.size() == 2);
  CHECK(list[0].file.generic_string() == "sub/DJI_0007_MS_G.TIF");
  CHECK(list[0].area[2] == std::array<double, 2>{40, 60});
  CHECK(*list[0].albedo == 0.49);
  CHECK(*list[1].albedo == 0.51);
  CHECK(list[1].area[0][0] == 60.5);
  CHECK(!parse_panel_list(R"({"pictures": [{"file": "a.tif", "area": [[0, 0], [9, 0], [9, 9], [0, 9]]}]})", "p.json")[0].albedo);

  const std::string good = R"("area": [[0, 0], [9, 0], [9, 9], [0, 9]])";
  // A picture of two panels (a grey one and a dark tarp): listed once for each.
  const auto two = parse_panel_list(R"({"pictures": [{"file": "a.tif", )" + good +
                                        R"(, "albedo": 0.5}, {"file": "a.tif", "area": [[20, 0], [29, 0], [29, 9], [20, 9]],)"
                                        R"( "albedo": 0.1}]})",
                                    "p.json");
  REQUIRE(two.size() == 2);
  CHECK(two[0].file == two[1].file);
  CHECK(two[1].area[0] == std::array<double, 2>{20, 0});
  CHECK(*two[1].albedo == 0.1);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"{", "p.json: invalid JSON"},
      {"[]", "field 'pictures'"},
      {R"({"pictures": []})", "field 'pictures'"},
      {R"({"pictures": [7]})", "field 'pictures[0]'"},
      {R"({"pictures": [{"area": [[0, 0], [9, 0], [9, 9], [0, 9]]}]})", "field 'pictures[0].file'"},
      {R"({"pictures": [{"file": "/abs/a.tif", )" + good + "}]}", "is not a path inside --images"},
      {R"({"pictures": [{"file": "../a.tif", )" + good + "}]}", "is not a path inside --images"},
      {R"({"pictures": [{"file": "a.tif", )" + good + R"(}, {"file": "./a.tif", "area": [[0, 0.0], [9, 0], [9, 9], [0, 9]]}]})",
       "'a.tif' is listed twice with the same area"},
      {R"({"pictures": [{"file": "a.tif", "area": [[0, 0], [9, 0], [9, 9]]}]})", "field 'pictures[0].area'"},
      {R"({"pictures": [{"file": "a.tif", "area": [[0, 0], [9, 0], [9, 9], [0, "9"]]}]})", "field 'pictures[0].area'"},
      {R"({"pictures": [{"file": "a.tif", "area": [[0, 0], [9, 9], [9, 0], [0, 9]]}]})", "convex"},
      {R"({"pictures": [{"file": "a.tif", )" + good + R"(, "albedo": 0}]})", "field 'pictures[0].albedo'"},
      {R"({"albedo": 1.2, "pictures": [{"file": "a.tif", )" + good + "}]}", "field 'albedo'"},
  };
  for (const auto& entry : bad) {  // (not a structured binding: Clang 14 refuses one named in CAPTURE)
    const std::string& text = entry.first;
    CAPTURE(text);
    CHECK_THROWS_WITH_AS(parse_panel_list(text, "p.json"), doctest::Contains(entry.second.c_str()), IoError);
  }

  // A camera that writes no black level at all (the Sequoia) can be calibrated by a panel; one
  // whose images disagree cannot.
  CaptureMeta no_black = parse_capture_meta(kMicaSense, "a.tif");
  no_black.black_level.reset();
  const BandPlan p = plan_band({no_black, no_black}, {"a.tif", "b.tif"}, Calibration::panel);
  CHECK(p.missing.empty());
  CHECK(!p.steps.black_level);
  CHECK(plan_band({no_black}, {"a.tif"}, Calibration::sun_sensor).missing.count("black level") == 1);
}

TEST_CASE("radiometry: a vignetting model that brightens the image's edge is an error") {
  // DJI's correction read as a fall-off would double the vignetting; so would the reverse.
  FrameRadiometry r;
  msgs::Image<float> img(100, 80, 1);
  r.exposure_s = 0.001;
  r.steps.vignetting = true;
  r.vignetting_cx = 50;
  r.vignetting_cy = 40;
  r.vignetting_poly = {0, 1e-4};  // 1 + 1e-4 r^2: 1.41 at the corner
  r.vignetting_kind = VignettingKind::falloff;
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"), doctest::Contains("x.tif: the vignetting model (a fall-off"), IoError);
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"),
                       doctest::Contains("makes the farthest pixel, 64 px from its centre, 1.41 times as bright"), IoError);
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"), doctest::Contains("--radiometry none"), IoError);
  r.vignetting_kind = VignettingKind::correction;
  CHECK_NOTHROW(normalise_image(img, r, "x.tif"));
  r.vignetting_poly = {0, -1e-4};  // a fall-off read as a correction
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"), doctest::Contains("(a correction polynomial)"), IoError);
  r.vignetting_kind = VignettingKind::falloff;
  CHECK_NOTHROW(normalise_image(img, r, "x.tif"));
  // A weak vignette whose fitted polynomial ends a little above 1 passes.
  r.vignetting_poly = {0, 0.04 / (64.0 * 64.0)};  // 1.04 at the corner, 64 px away
  CHECK_NOTHROW(normalise_image(img, r, "x.tif"));
}

TEST_CASE("capture meta: GPS positions in EXIF, DJI XMP and XMP exif forms") {
  // EXIF: degrees, minutes, seconds as rationals with reference letters; altitude ref 1 = below sea level.
  const CaptureMeta e = parse_capture_meta(
      "Exif.GPSInfo.GPSLatitudeRef                   S\n"
      "Exif.GPSInfo.GPSLatitude                      33/1 51/1 5400/100\n"
      "Exif.GPSInfo.GPSLongitudeRef                  E\n"
      "Exif.GPSInfo.GPSLongitude                     151/1 12/1 3600/100\n"
      "Exif.GPSInfo.GPSAltitudeRef                   1\n"
      "Exif.GPSInfo.GPSAltitude                      1250/100\n",
      "a.tif");
  REQUIRE(e.gps);
  CHECK((*e.gps)[0] == doctest::Approx(-(33 + 51 / 60.0 + 54 / 3600.0)));
  CHECK((*e.gps)[1] == doctest::Approx(151 + 12 / 60.0 + 36 / 3600.0));
  CHECK((*e.gps)[2] == doctest::Approx(-12.5));
  CHECK(e.source.at("gps") == "Exif.GPSInfo.GPSLatitude");

  // DJI: signed decimal degrees, some firmware's "GpsLongtitude", absolute altitude with a sign.
  const CaptureMeta d = parse_capture_meta(
      "Xmp.drone-dji.GpsLatitude                     +51.98001142\n"
      "Xmp.drone-dji.GpsLongtitude                   -0.1234\n"
      "Xmp.drone-dji.AbsoluteAltitude                +34.77\n",
      "DJI_x_MS_G.TIF");
  REQUIRE(d.gps);
  CHECK((*d.gps)[0] == doctest::Approx(51.98001142));
  CHECK((*d.gps)[1] == doctest::Approx(-0.1234));
  CHECK((*d.gps)[2] == doctest::Approx(34.77));

  // XMP exif: "DDD,MM.mmmK" or "DDD,MM,SSK"; no altitude is 0.
  const CaptureMeta x = parse_capture_meta(
      "Xmp.exif.GPSLatitude                          51,58.803168N\n"
      "Xmp.exif.GPSLongitude                         5,39,36W\n",
      "IMG_0001_2.tif");
  REQUIRE(x.gps);
  CHECK((*x.gps)[0] == doctest::Approx(51 + 58.803168 / 60.0));
  CHECK((*x.gps)[1] == doctest::Approx(-(5 + 39 / 60.0 + 36 / 3600.0)));
  CHECK((*x.gps)[2] == 0.0);

  // EXIF wins over XMP; no position at all leaves it unset without a problem.
  const CaptureMeta both = parse_capture_meta(
      "Exif.GPSInfo.GPSLatitudeRef N\nExif.GPSInfo.GPSLatitude 10/1 0/1 0/1\n"
      "Exif.GPSInfo.GPSLongitudeRef E\nExif.GPSInfo.GPSLongitude 20/1 0/1 0/1\n"
      "Xmp.drone-dji.GpsLatitude 1\nXmp.drone-dji.GpsLongitude 2\n",
      "b.tif");
  REQUIRE(both.gps);
  CHECK((*both.gps)[0] == 10.0);
  const CaptureMeta none = parse_capture_meta(kMicaSense, "IMG_0001_2.tif");
  CHECK(!none.gps);
  CHECK(none.gps_problem.empty());
}

TEST_CASE("capture meta: a malformed GPS position is no error, but says what was wrong") {
  // A position is optional (only --matching gps needs it): unreadable values leave it unset and
  // name the key, instead of stopping an import that does not use it.
  const char* bad[] = {
      "Exif.GPSInfo.GPSLatitudeRef N\nExif.GPSInfo.GPSLatitude 10/1 0/0 0/1\n"
      "Exif.GPSInfo.GPSLongitudeRef E\nExif.GPSInfo.GPSLongitude 20/1 0/1 0/1\n",  // division by zero
      "Exif.GPSInfo.GPSLatitudeRef X\nExif.GPSInfo.GPSLatitude 10/1 0/1 0/1\n"
      "Exif.GPSInfo.GPSLongitudeRef E\nExif.GPSInfo.GPSLongitude 20/1 0/1 0/1\n",  // no such reference
      "Exif.GPSInfo.GPSLatitude 10/1 0/1 0/1\n"
      "Exif.GPSInfo.GPSLongitudeRef E\nExif.GPSInfo.GPSLongitude 20/1 0/1 0/1\n",  // reference missing
      "Exif.GPSInfo.GPSLatitudeRef N\nExif.GPSInfo.GPSLatitude 10/1 75/1 0/1\n"
      "Exif.GPSInfo.GPSLongitudeRef E\nExif.GPSInfo.GPSLongitude 20/1 0/1 0/1\n",  // 75 minutes
      "Xmp.drone-dji.GpsLatitude 95.0\nXmp.drone-dji.GpsLongitude 2\n",          // beyond the pole
      "Xmp.drone-dji.GpsLatitude nan\nXmp.drone-dji.GpsLongitude 2\n",
      "Xmp.drone-dji.GpsLatitude 1\nXmp.drone-dji.GpsLongitude 200\n",
      "Xmp.exif.GPSLatitude 51,58.8Q\nXmp.exif.GPSLongitude 5,39.6E\n",
      "Xmp.exif.GPSLatitude 51,58.8N\nXmp.exif.GPSLongitude 5,39.6E\nXmp.exif.GPSAltitude 12/0\n",
  };
  for (const char* text : bad) {
    CaptureMeta m;
    REQUIRE_NOTHROW(m = parse_capture_meta(text, "x.tif"));
    CHECK_MESSAGE(!m.gps, text);
    CHECK_MESSAGE(m.gps_problem.find("is not a position") != std::string::npos, text);
    const std::string& why = m.gps_problem;  // names the key
    CHECK_MESSAGE((why.find("Latitude") != std::string::npos || why.find("Longitude") != std::string::npos ||
                   why.find("Altitude") != std::string::npos),
                  why);
  }
  const CaptureMeta lon = parse_capture_meta("Xmp.drone-dji.GpsLatitude 1\nXmp.drone-dji.GpsLongitude 200\n", "x.tif");
  CHECK(lon.gps_problem.rfind("Xmp.drone-dji.GpsLongitude '200'", 0) == 0);
}

TEST_CASE("capture meta: several files in one exiv2 output, junk lines ignored") {
  const std::vector<std::string> files = {"/d/a b.tif", "/d/a b.tif.2", "/d/c.tif"};
  const std::string text =
      "/d/a b.tif   Xmp.Camera.BandName   Red\n"
      "/d/a b.tif.2 Xmp.Camera.BandName   NIR\n"
      "Warning: Directory Image, entry 0x8769 has unknown Exif (TIFF) type 0; setting type size 1.\n"
      "/d/c.tif     Xmp.exif.ExposureTime 1/1000\n"
      "/d/c.tifX    Xmp.exif.ExposureTime 1/3\n"
      "\n\n\t\r\n";
  const auto per = split_exiv2_output(text, files);
  REQUIRE(per.size() == 3);
  CHECK(*parse_capture_meta(per[0], files[0]).band_name == "Red");
  CHECK(*parse_capture_meta(per[1], files[1]).band_name == "NIR");
  CHECK(*parse_capture_meta(per[2], files[2]).exposure_s == doctest::Approx(0.001));
  // Lines that are not KEY VALUE (continuations of multi-line values, binary junk) are skipped.
  const auto kv = parse_exiv2_kv("garbage line\nXmp.a\n\x01\x02\xff Xmp.Camera.BandName x\nXmp.Camera.BandName  Blue  \n");
  CHECK(kv.size() == 1);
  CHECK(kv.at("Xmp.Camera.BandName") == "Blue");
  CHECK(parse_capture_meta("", "empty.tif").source.empty());
}

TEST_CASE("capture meta: malformed values give errors naming the file and the key") {
  auto bad = [](const std::string& text) { return parse_capture_meta(text, "IMG_0001_2.tif"); };
  CHECK_THROWS_WITH_AS(bad("Xmp.exif.ExposureTime  1/0\n"), doctest::Contains("IMG_0001_2.tif: field 'Xmp.exif.ExposureTime'"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.exif.ExposureTime  -0.001\n"), doctest::Contains("exposure time"), IoError);
  CHECK_THROWS_WITH_AS(bad("Exif.Photo.ISOSpeed  fast\n"), doctest::Contains("an ISO value"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.Camera.BlackLevel  nan\n"), doctest::Contains("black level"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.Camera.BlackLevel  1e999\n"), doctest::Contains("black level"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.Camera.VignettingPolynomial 1, x\n"), doctest::Contains("polynomial coefficients"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.Camera.VignettingPolynomial 1\nXmp.Camera.VignettingCenter 3\n"),
                       doctest::Contains("two numbers"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.exif.FocalPlaneXResolution 20\nXmp.exif.FocalPlaneResolutionUnit 7\n"),
                       doctest::Contains("resolution unit"), IoError);
  CHECK_THROWS_WITH_AS(bad("Exif.Image.BitsPerSample 12.5\n"), doctest::Contains("bit depth"), IoError);
  CHECK_THROWS_WITH_AS(bad("Xmp.exif.ExposureTime " + std::string(5000, '9') + "\n"), doctest::Contains("exposure"), IoError);
  std::string seventeen = "Xmp.Camera.VignettingPolynomial 1";
  for (int i = 0; i < 16; ++i) seventeen += ",1";
  CHECK_THROWS_WITH_AS(bad(seventeen + "\n"),
                       doctest::Contains("up to 16"), IoError);
}

TEST_CASE("radiometry: known DN gives known relative radiance") {
  // DN = black + L * exposure * gain * falloff(r) * sensitivity; the normalisation returns L * sensitivity.
  FrameRadiometry r;
  r.steps = {true, true, true, true};
  r.dn_max = 65535;
  r.black_level = 4800;
  r.exposure_s = 1.0 / 1000;
  r.gain = 2;
  r.vignetting_poly = {0, -1e-4};  // 1 - 1e-4 r^2
  r.vignetting_cx = 10;
  r.vignetting_cy = 20;
  CHECK(vignetting_polynomial(r.vignetting_poly, 30.0) == doctest::Approx(1 - 0.09));
  CHECK(vignetting_falloff(r, 10, 20) == 1.0);
  CHECK(vignetting_falloff(r, 10 + 30, 20) == doctest::Approx(0.91));
  const double L = 0.25, sens = 1e7;
  const double dn_centre = 4800 + L * 0.001 * 2 * 1.0 * sens;   // 9800
  const double dn_edge = 4800 + L * 0.001 * 2 * 0.91 * sens;    // 9350
  CHECK(relative_radiance(dn_centre, 10, 20, r) == doctest::Approx(L * sens));
  CHECK(relative_radiance(dn_edge, 40, 20, r) == doctest::Approx(L * sens));

  msgs::Image<float> img(41, 21, 1);
  img.at(10, 20, 0) = float(dn_centre / 65535);
  img.at(40, 20, 0) = float(dn_edge / 65535);
  img.at(0, 0, 0) = float(100.0 / 65535);  // below the black level: 0, not negative
  r.scale = 1.0 / (L * sens);
  const auto n = normalise_image(img, r, "a.tif");
  CHECK(n.at(10, 20, 0) == doctest::Approx(1.0).epsilon(1e-5));
  CHECK(n.at(40, 20, 0) == doctest::Approx(1.0).epsilon(1e-5));
  CHECK(n.at(0, 0, 0) == 0.0f);
  CHECK(max_value(n) == doctest::Approx(1.0).epsilon(1e-5));
  CHECK(band_scale(4.0) == 0.25);
  CHECK(band_scale(0.0) == 1.0);

  // DJI convention: the polynomial is a correction that multiplies, i.e. fall-off 1 / p(r).
  r.vignetting_kind = VignettingKind::correction;
  r.vignetting_poly = {0, 1e-4};
  CHECK(vignetting_falloff(r, 40, 20) == doctest::Approx(1.0 / 1.09));
}

TEST_CASE("radiometry: a band without some tag leaves that step out for all its images") {
  CaptureMeta full = parse_capture_meta(kMicaSense, "a.tif");
  CaptureMeta no_black = full;
  no_black.black_level.reset();
  const BandPlan p = plan_band({full, no_black, full}, {"a.tif", "b.tif", "c.tif"});
  CHECK(!p.steps.black_level);
  CHECK(p.steps.exposure);
  CHECK(p.steps.gain);
  CHECK(p.steps.vignetting);
  REQUIRE(p.missing.count("black level"));
  CHECK(p.missing.at("black level") == std::vector<std::filesystem::path>{"b.tif"});
  const FrameRadiometry r = frame_radiometry(full, p.steps, 65535);
  CHECK(r.black_level == 0.0);
  CHECK(r.exposure_s == doctest::Approx(1.0 / 1246));
  CHECK(!plan_band({}, {}).steps.any());
}

TEST_CASE("radiometry: parameters that cannot be right are errors naming the file") {
  FrameRadiometry r;
  msgs::Image<float> img(100, 100, 1);
  r.exposure_s = 0;
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"), doctest::Contains("x.tif: radiometric parameters"), IoError);
  r.exposure_s = 0.001;
  r.steps.vignetting = true;
  r.vignetting_poly = {0, -1e-3};  // 1 - 1e-3 r^2 crosses zero at r = 31.6 px, inside the image
  r.vignetting_cx = 50;
  r.vignetting_cy = 50;
  CHECK_THROWS_WITH_AS(normalise_image(img, r, "x.tif"), doctest::Contains("vignetting polynomial is"), IoError);
}

}  // namespace test_radiometry
