// tests/test_sunshine_sensor.cpp
// Tests for include/msgs/io/sunshine_sensor.hpp (a Parrot Sequoia's sunshine sensor: the
// IrradianceList records, the gains' calibration, the reading at a capture) and its place in
// capture_meta.hpp: known values through base64, the same irradiance at every gain, the window of
// the last second, and lists msgs cannot read saying why instead of failing the import.
#include <doctest/doctest.h>

#include <msgs/io/capture_meta.hpp>
#include <msgs/io/radiometry.hpp>
#include <msgs/io/sunshine_sensor.hpp>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace test_sunshine_sensor {
using namespace msgs::io;

namespace {

// A calibration like a real unit's (Parrot's forum): 600 ms at every gain index, the last saturated.
const char* kCalibration = "0,600,33,17,1,600,820,417,2,600,13526,6824,3,600,65535,65535";

SunshineReading reading(std::uint64_t time_us, int ch0, int gain_index, int integration_ms) {
  SunshineReading r;
  r.time_us = time_us;
  r.ch0 = std::uint16_t(ch0);
  r.ch1 = std::uint16_t(ch0 / 2);
  r.gain_index = std::uint16_t(gain_index);
  r.integration_ms = std::uint16_t(integration_ms);
  r.yaw = 12.5f;
  r.pitch = -3.0f;
  r.roll = 1.25f;
  return r;
}

}  // namespace

TEST_CASE("sunshine sensor: base64 of 28-byte records, decoded field by field") {
  // Known bytes: one record, every field set, encoded by hand (Python's struct "<QHHHHfff").
  // time 1000000, CH0 1234, CH1 617, gain index 1, 100 ms, yaw 1.0, pitch -2.0, roll 0.5.
  const std::string b64 = "QEIPAAAAAADSBGkCAQBkAAAAgD8AAADAAAAAPw==";
  const SunshineList l = parse_sunshine_list(b64);
  REQUIRE_MESSAGE(l.problem.empty(), l.problem);
  REQUIRE(l.readings.size() == 1);
  const SunshineReading& r = l.readings[0];
  CHECK(r.time_us == 1000000u);
  CHECK(r.ch0 == 1234);
  CHECK(r.ch1 == 617);
  CHECK(r.gain_index == 1);
  CHECK(r.integration_ms == 100);
  CHECK(r.yaw == 1.0f);
  CHECK(r.pitch == -2.0f);
  CHECK(r.roll == 0.5f);
  CHECK(sunshine_list_base64(l.readings) == b64);  // the writer is the reader's inverse

  // Every length of list round-trips, padding and all; XMP line breaks are skipped.
  std::vector<SunshineReading> many;
  for (int k = 0; k < 7; ++k) many.push_back(reading(5000000u + 200000u * std::uint64_t(k), 100 + k, k % 4, 20 + k));
  for (std::size_t n = 1; n <= many.size(); ++n) {
    const std::vector<SunshineReading> part(many.begin(), many.begin() + std::ptrdiff_t(n));
    std::string text = sunshine_list_base64(part);
    text.insert(text.size() / 2, "\n  ");
    const SunshineList back = parse_sunshine_list(text);
    REQUIRE_MESSAGE(back.problem.empty(), back.problem);
    REQUIRE(back.readings.size() == n);
    CHECK(back.readings.back().ch0 == part.back().ch0);
    CHECK(back.readings.back().time_us == part.back().time_us);
  }
}

TEST_CASE("sunshine sensor: lists msgs cannot read say why") {
  CHECK(parse_sunshine_list("not*base64").problem == "not base64");
  CHECK(parse_sunshine_list("QUJD=A==").problem == "not base64");  // data after the padding
  CHECK(parse_sunshine_list("QUJ").problem == "not base64");       // not whole
  CHECK(parse_sunshine_list("").problem == "an empty list");
  // 20-byte readings, as firmware before 1.1.0 wrote them.
  const std::string old20(27, 'A');  // 27 digits + '=' = 20 bytes
  CHECK(parse_sunshine_list(old20 + "=").problem.find("20 bytes, not a whole number of 28-byte readings (firmware before 1.1.0") == 0);
  // Times that go back, and implausible fields: a list of another format read as this one.
  const auto back = parse_sunshine_list(sunshine_list_base64({reading(2000000, 10, 1, 100), reading(1000000, 10, 1, 100)}));
  CHECK(back.problem == "reading 1 is earlier than reading 0: not the 28-byte format");
  CHECK(back.readings.empty());
  CHECK(parse_sunshine_list(sunshine_list_base64({reading(1, 10, 1, 0)})).problem.find("reading 0 is not plausible") == 0);
  SunshineReading nan = reading(1, 10, 1, 100);
  nan.yaw = std::numeric_limits<float>::quiet_NaN();
  CHECK(parse_sunshine_list(sunshine_list_base64({nan})).problem.find("reading 0 is not plausible") == 0);

  // Calibration rows: whole rows, integer gain indices, each once.
  CHECK(sunshine_calibration({0, 600, 33, 17, 1, 600, 820}) == std::nullopt);
  CHECK(sunshine_calibration({0.5, 600, 33, 17}) == std::nullopt);
  CHECK(sunshine_calibration({1, 600, 33, 17, 1, 600, 820, 417}) == std::nullopt);
  CHECK(sunshine_calibration({}) == std::nullopt);
}

TEST_CASE("sunshine sensor: the same light at any gain and integration time, the last second only") {
  const auto rows = sunshine_calibration(*detail::parse_number_list(kCalibration));
  REQUIRE(rows);
  REQUIRE(rows->size() == 4);
  // Light 3x the calibration's: gain index 1 counts 820 / 600 x 3 per ms, gain index 2 13526 / 600 x 3.
  const double rate1 = 820.0 / 600.0 * 3.0, rate2 = 13526.0 / 600.0 * 3.0;
  std::vector<SunshineReading> list = {
      reading(1000000, 999, 1, 100),                   // 1.6 s before the last: outside the window
      reading(2000000, int(std::lround(rate1 * 100)), 1, 100),
      reading(2200000, int(std::lround(rate2 * 20)), 2, 20),
      reading(2400000, int(std::lround(rate1 * 50)), 1, 50),
      reading(2600000, int(std::lround(rate2 * 10)), 2, 10)};
  SunshineIrradiance e = sunshine_irradiance(list, *rows);
  REQUIRE_MESSAGE(e.problem.empty(), e.problem);
  CHECK(e.readings == 4);
  CHECK(e.irradiance == doctest::Approx(3.0).epsilon(2e-3));

  // Saturated readings and a gain index whose row is saturated (3) or missing (7) are left out.
  list.push_back(reading(2700000, 65535, 1, 100));
  list.push_back(reading(2800000, 500, 3, 100));
  list.push_back(reading(2900000, 500, 7, 100));
  e = sunshine_irradiance(list, *rows);
  CHECK(e.readings == 4);  // (the window now starts at 1.9 s: the four readings at 2.0-2.6 s)
  CHECK(e.irradiance == doctest::Approx(3.0).epsilon(2e-3));
  // Nothing usable in the window: a problem, no reading.
  e = sunshine_irradiance({reading(5000000, 65535, 1, 100), reading(5100000, 40, 3, 100)}, *rows);
  CHECK(e.readings == 0);
  CHECK(e.problem == "none of its 2 readings of the last 1 s is usable (1 at count 0 or saturated, 1 at a gain index "
                     "without an unsaturated row in Xmp.Camera.IrradianceCalibrationMeasurement)");
  CHECK(sunshine_irradiance({}, *rows).problem == "no reading");
}

TEST_CASE("capture meta: a Sequoia's sunshine sensor as the light sensor's reading, in its own units") {
  const std::vector<SunshineReading> list = {reading(2000000, 273, 1, 100)};
  const std::string base =
      "Exif.Image.Model                              Sequoia\n"
      "Xmp.Camera.BandName                           NIR\n"
      "Xmp.Camera.IrradianceList                     " +
      sunshine_list_base64(list) + "\n";
  const CaptureMeta m = parse_capture_meta(base + "Xmp.Camera.IrradianceCalibrationMeasurement  " + kCalibration + "\n",
                                           "IMG_0001_NIR.TIF");
  REQUIRE_MESSAGE(m.irradiance, m.irradiance_problem);
  // 273 counts in 100 ms at gain index 1, against 820 in 600 ms: 2.0 x the calibration's light.
  CHECK(*m.irradiance == doctest::Approx((273.0 / 100.0) / (820.0 / 600.0)));
  CHECK(!m.irradiance_si);
  CHECK(m.light_sensor_readings == 1);
  CHECK(m.source.at("irradiance") == "Xmp.Camera.IrradianceList");
  // panel+dls takes it; sun-sensor wants a band calibration the Sequoia does not write.
  CHECK(plan_band({m}, {"a.TIF"}, Calibration::panel_and_sun_sensor).missing.count(
            "light sensor reading (MicaSense DLS 2 HorizontalIrradiance, DJI Irradiance)") == 0);
  CHECK(plan_band({m}, {"a.TIF"}, Calibration::sun_sensor_relative)
            .missing.count("band calibration (DJI SensorGainAdjustment, MicaSense RadiometricCalibration)") == 1);

  // Without the calibration, with a malformed one or an unreadable list: no reading, no error, and why.
  const CaptureMeta none = parse_capture_meta(base, "a.TIF");
  CHECK(!none.irradiance);
  CHECK(none.irradiance_problem == "no Xmp.Camera.IrradianceCalibrationMeasurement, which gives the sunshine sensor's gains");
  const CaptureMeta bad = parse_capture_meta(base + "Xmp.Camera.IrradianceCalibrationMeasurement 1,2,3\n", "a.TIF");
  CHECK(!bad.irradiance);
  CHECK(bad.irradiance_problem.find("Xmp.Camera.IrradianceCalibrationMeasurement: value '1,2,3' is not rows") == 0);
  const CaptureMeta junk = parse_capture_meta(std::string("Xmp.Camera.IrradianceList ###\n") +
                                                  "Xmp.Camera.IrradianceCalibrationMeasurement " + kCalibration + "\n",
                                              "a.TIF");
  CHECK(!junk.irradiance);
  CHECK(junk.irradiance_problem == "Xmp.Camera.IrradianceList: not base64");
}

}  // namespace test_sunshine_sensor
