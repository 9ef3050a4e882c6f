// tests/test_light_sensor_heading.cpp
// The heading check of a light sensor's readings (msgs/io/light_sensor_heading.hpp): a known
// heading effect comes back with the sun climbing meanwhile, on flight lines that turn back (two
// opposite headings, where only part of the heading term is determined) and on four headings; the
// correction leaves the change in time alone; noise alone is not called an effect; and the inputs
// the check cannot use give a reason, not a number.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <numbers>
#include <random>
#include <vector>

#include <msgs/io/capture_meta.hpp>
#include <msgs/io/light_sensor_heading.hpp>

namespace test_light_sensor_heading {
using namespace msgs::io;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// A flight of `n` captures 2 s apart whose headings cycle through `headings`.
struct Flight {
  std::vector<double> time_s, heading_deg;
};

Flight flight(std::size_t n, const std::vector<double>& headings) {
  Flight f;
  for (std::size_t i = 0; i < n; ++i) {
    f.time_s.push_back(36000.0 + 2.0 * double(i));
    f.heading_deg.push_back(headings[i % headings.size()]);
  }
  return f;
}

/// A deterministic value in [-1, 1) (a 64-bit linear congruential generator's high bits).
double noise(std::uint64_t& state) {
  state = state * 6364136223846793005ULL + 1442695040888963407ULL;
  return double(state >> 11) / double(1ULL << 52) - 1.0;
}

}  // namespace

TEST_CASE("fit_heading_bias: flight lines that turn back, the sun climbing by 10% meanwhile") {
  // A sensor that reads 1 + 0.06 cos(heading - 20 degrees) x the light: 1.06 on the line flown at
  // 20 degrees, 0.94 on the one flown back at 200; the light grows linearly by 10%.
  const Flight f = flight(12, {20.0, 200.0});
  std::vector<double> light, reading;
  for (std::size_t i = 0; i < f.time_s.size(); ++i) {
    light.push_back(800.0 * (1.0 + 0.1 * (f.time_s[i] - f.time_s[0]) / 22.0));
    reading.push_back(light.back() * (1.0 + 0.06 * std::cos((f.heading_deg[i] - 20.0) * kDeg)));
  }
  const HeadingFit fit = fit_heading_bias(reading, f.time_s, f.heading_deg);
  REQUIRE(fit.problem.empty());
  CHECK(fit.captures == 12);
  CHECK(fit.lines == 12);  // the heading turns back at every capture
  // log(1 + 0.1 t) is not quite quadratic in t: the residual is tiny, and so is the error.
  CHECK(fit.ratio == doctest::Approx(1.06 / 0.94).epsilon(2e-4).scale(0));
  CHECK(fit.high_heading_deg == 20.0);
  CHECK(fit.low_heading_deg == 200.0);
  CHECK(fit.scatter < 1e-4);
  CHECK(fit.significant());
  // Divided by the factor, the readings follow the light alone, at its level (the mean of the
  // factors' logarithms is zero: on average the reading stays where it was).
  REQUIRE(fit.heading_factor.size() == 12);
  double log_mean = 0.0;
  for (std::size_t i = 0; i < 12; ++i) {
    CAPTURE(i);
    CHECK(reading[i] / fit.heading_factor[i] / light[i] == doctest::Approx(std::sqrt(1.06 * 0.94)).epsilon(2e-4).scale(0));
    log_mean += std::log(fit.heading_factor[i]) / 12.0;
  }
  CHECK(std::abs(log_mean) < 1e-12);
}

TEST_CASE("fit_heading_bias: four headings, an effect of exactly the fitted form") {
  // log E = a + b tau + c tau^2 + 0.05 cos(heading - 30 degrees): the fit is exact.
  const Flight f = flight(16, {0.0, 90.0, 180.0, 270.0});
  std::vector<double> reading;
  for (std::size_t i = 0; i < f.time_s.size(); ++i) {
    const double tau = (f.time_s[i] - f.time_s[0]) / 15.0 - 1.0;
    reading.push_back(std::exp(6.0 + 0.08 * tau - 0.03 * tau * tau + 0.05 * std::cos((f.heading_deg[i] - 30.0) * kDeg)));
  }
  const HeadingFit fit = fit_heading_bias(reading, f.time_s, f.heading_deg);
  REQUIRE(fit.problem.empty());
  // Highest flying 0 degrees (cos 30), lowest flying 180 (cos 150).
  CHECK(fit.ratio == doctest::Approx(std::exp(0.05 * 2.0 * std::cos(30.0 * kDeg))).epsilon(1e-9).scale(0));
  CHECK(fit.high_heading_deg == 0.0);
  CHECK(fit.low_heading_deg == 180.0);
  CHECK_FALSE(fit.one_axis);  // the lines cross: both of the heading's columns
  CHECK(fit.scatter < 1e-9);
  CHECK(fit.significant());
}

TEST_CASE("fit_heading_bias: the light changing in time alone is no heading effect") {
  const Flight f = flight(10, {20.0, 200.0});
  std::vector<double> reading;
  for (std::size_t i = 0; i < f.time_s.size(); ++i) reading.push_back(500.0 * (1.0 + 0.02 * double(i)));
  const HeadingFit fit = fit_heading_bias(reading, f.time_s, f.heading_deg);
  REQUIRE(fit.problem.empty());
  CHECK(fit.ratio == doctest::Approx(1.0).epsilon(1e-4).scale(0));
  CHECK(std::isfinite(fit.ratio_log_se));
  CHECK_FALSE(fit.significant());
  for (double h : fit.heading_factor) CHECK(h == doctest::Approx(1.0).epsilon(1e-4).scale(0));
}

TEST_CASE("fit_heading_bias: passing clouds are not called a heading effect; a real one stands out of them") {
  // Each capture's light varies by up to +-3% at random.
  int false_alarms = 0, found = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    std::uint64_t state = seed;
    const Flight f = flight(40, {20.0, 200.0});
    std::vector<double> calm, biased;
    for (std::size_t i = 0; i < f.time_s.size(); ++i) {
      const double light = 900.0 * (1.0 + 0.03 * noise(state));
      calm.push_back(light);
      biased.push_back(light * (1.0 + 0.06 * std::cos((f.heading_deg[i] - 20.0) * kDeg)));
    }
    const HeadingFit a = fit_heading_bias(calm, f.time_s, f.heading_deg);
    const HeadingFit b = fit_heading_bias(biased, f.time_s, f.heading_deg);
    REQUIRE(a.problem.empty());
    REQUIRE(b.problem.empty());
    CAPTURE(seed);
    // Uniform +-3% has a standard deviation of 1.7%.
    CHECK(a.scatter == doctest::Approx(0.0173).epsilon(0.35).scale(0));
    // The effect comes back within three standard errors.
    CHECK(std::abs(std::log(b.ratio) - std::log(1.06 / 0.94)) < 3.0 * b.ratio_log_se);
    false_alarms += a.significant();
    found += b.significant();
  }
  CHECK(false_alarms == 0);
  CHECK(found == 20);
}

TEST_CASE("fit_heading_bias: a cloud over a whole flight line is not a heading effect") {
  // A lawn-mower flight: 8 lines of 10 captures, flown at 20 and 200 degrees in turn, crabbing
  // a few degrees into the wind; the light changes slowly, by +-4% over about three lines, as a
  // cloud bank passes, and each reading has 0.5% of noise. The captures of a line share its light:
  // taken one by one they would count each line's cloud ten times over.
  const auto lawn_mower = [](double bias, std::uint64_t seed) {
    Flight f;
    std::vector<double> reading;
    std::uint64_t state = seed;
    for (int line = 0; line < 8; ++line)
      for (int k = 0; k < 10; ++k) {
        const double t = 36000.0 + 2.0 * (10 * line + k) + 8.0 * line;  // 8 s to turn
        const double heading = (line % 2 ? 200.0 : 20.0) + 3.0 * noise(state);
        const double light = 1000.0 * (1.0 + 0.04 * std::sin(2.0 * std::numbers::pi * (t - 36000.0) / 65.0));
        f.time_s.push_back(t);
        f.heading_deg.push_back(heading < 0 ? heading + 360.0 : heading);
        reading.push_back(light * (1.0 + 0.005 * noise(state)) * (1.0 + bias * std::cos((heading - 20.0) * kDeg)));
      }
    return std::pair{f, reading};
  };
  int false_alarms = 0, found = 0;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    CAPTURE(seed);
    const auto [f, calm] = lawn_mower(0.0, seed);
    const HeadingFit a = fit_heading_bias(calm, f.time_s, f.heading_deg);
    REQUIRE(a.problem.empty());
    CHECK(a.lines == 8);
    CHECK(a.one_axis);
    CHECK(a.degrees_of_freedom == 4);  // 8 lines, 4 parameters: the term along the lines' axis
    false_alarms += a.significant();
    // An effect of 1 +- 0.15 (35% between the lines) stands out of the clouds even so.
    const auto [g, biased] = lawn_mower(0.15, seed);
    const HeadingFit b = fit_heading_bias(biased, g.time_s, g.heading_deg);
    REQUIRE(b.problem.empty());
    CHECK(b.ratio == doctest::Approx(1.15 / 0.85).epsilon(0.05).scale(0));
    found += b.significant();
  }
  CHECK(false_alarms == 0);
  CHECK(found >= 8);
}

TEST_CASE("HeadingFit::student_t_3sigma: the t quantiles of three standard errors") {
  CHECK(HeadingFit::student_t_3sigma(0) == std::numeric_limits<double>::infinity());
  CHECK(HeadingFit::student_t_3sigma(2) == doctest::Approx(19.207));
  CHECK(HeadingFit::student_t_3sigma(30) == doctest::Approx(3.270));
  // The expansion beyond the table meets it, and tends to the normal's 3.
  CHECK(HeadingFit::student_t_3sigma(31) == doctest::Approx(3.260).epsilon(0.002));
  CHECK(HeadingFit::student_t_3sigma(100000) == doctest::Approx(3.0).epsilon(1e-4));
  for (int v = 1; v < 60; ++v) CHECK(HeadingFit::student_t_3sigma(v + 1) < HeadingFit::student_t_3sigma(v));
}

TEST_CASE("heading_spread_deg: the widest angle between two headings, as over all pairs") {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> any(-1000.0, 1000.0), near(-30.0, 30.0);
  for (int trial = 0; trial < 300; ++trial) {
    const std::size_t n = 1 + std::size_t(trial % 40);
    std::vector<double> h(n);
    // Headings anywhere (beyond [0, 360) too), or bunched around two or three directions.
    const double centre = any(rng);
    for (std::size_t i = 0; i < n; ++i) h[i] = trial % 3 == 0 ? any(rng) : centre + 120.0 * double(i % (2 + trial % 2)) + near(rng);
    double all_pairs = 0.0;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j) all_pairs = std::max(all_pairs, detail::heading_gap_deg(h[i], h[j]));
    CAPTURE(trial);
    CHECK(detail::heading_spread_deg(h) == doctest::Approx(all_pairs).epsilon(1e-9));
  }
  CHECK(detail::heading_spread_deg({}) == 0.0);
  CHECK(detail::heading_spread_deg({359.5, -0.5, 0.25}) == doctest::Approx(0.75));
  CHECK(detail::heading_spread_deg({-1e-17, 180.0}) == doctest::Approx(180.0));
  CHECK(detail::heading_spread_deg({10.0, 190.0, 100.0}) == doctest::Approx(180.0));
}

TEST_CASE("fit_heading_bias: what the check cannot use gives a reason") {
  const Flight f = flight(8, {20.0, 200.0});
  const std::vector<double> reading(8, 700.0);
  SUBCASE("too few flight lines") {
    const HeadingFit fit = fit_heading_bias({1, 2, 3, 4, 5}, {0, 2, 4, 6, 8}, {20, 200, 20, 200, 20});
    CHECK(fit.problem.find("5 flight lines") != std::string::npos);
    CHECK_FALSE(fit.significant());
    // 40 captures on 5 lines are no more.
    std::vector<double> r, t, h;
    for (int i = 0; i < 40; ++i) {
      r.push_back(100.0 + i % 3);
      t.push_back(2.0 * i);
      h.push_back(i / 8 % 2 ? 200.0 : 20.0);
    }
    const HeadingFit lines = fit_heading_bias(r, t, h);
    CHECK(lines.problem.find("5 flight lines, runs of captures on one heading (the check takes 6)") != std::string::npos);
    CHECK(lines.captures == 40);
  }
  SUBCASE("one heading") {
    const HeadingFit fit = fit_heading_bias(reading, f.time_s, std::vector<double>(8, 20.0));
    CHECK(fit.problem == "the headings flown lie within 0 degrees (the check takes 90)");
  }
  SUBCASE("headings 60 degrees apart, across north") {
    std::vector<double> h;
    for (int i = 0; i < 8; ++i) h.push_back(i % 2 ? 330.0 : 30.0);
    const HeadingFit fit = fit_heading_bias(reading, f.time_s, h);
    CHECK(fit.problem.find("within 60 degrees") != std::string::npos);
  }
  SUBCASE("a reading that is zero, negative or not a number") {
    for (double bad : {0.0, -1.0, std::nan("")}) {
      std::vector<double> r = reading;
      r[3] = bad;
      const HeadingFit fit = fit_heading_bias(r, f.time_s, f.heading_deg);
      CHECK_FALSE(fit.problem.empty());
      CHECK_FALSE(fit.significant());
    }
  }
  SUBCASE("readings hundreds of orders of magnitude apart: a reason, not an infinite ratio") {
    std::vector<double> r;
    for (int i = 0; i < 8; ++i) r.push_back(i % 2 ? 1e-300 : 1e300);
    const HeadingFit fit = fit_heading_bias(r, f.time_s, f.heading_deg);
    CHECK(fit.problem.find("too far apart") != std::string::npos);
    CHECK(fit.heading_factor.empty());
    CHECK_FALSE(fit.significant());
  }
  SUBCASE("lists of different lengths") {
    const HeadingFit fit = fit_heading_bias(reading, f.time_s, {20.0, 200.0});
    CHECK(fit.problem.find("do not pair up") != std::string::npos);
  }
  SUBCASE("all captures at one time: the heading is still told apart") {
    std::vector<double> r;
    for (int i = 0; i < 8; ++i) r.push_back(i % 2 ? 660.0 : 740.0);
    const HeadingFit fit = fit_heading_bias(r, std::vector<double>(8, 100.0), f.heading_deg);
    REQUIRE(fit.problem.empty());
    CHECK(fit.ratio == doctest::Approx(740.0 / 660.0).epsilon(1e-9).scale(0));
  }
}

TEST_CASE("parse_capture_meta: the drone's heading, in [0, 360) degrees clockwise from north") {
  // DJI writes the aircraft's yaw in degrees, -180 to 180; MicaSense's light sensor in radians.
  const auto heading = [](const std::string& exiv2) { return parse_capture_meta(exiv2, "x.tif").heading_deg; };
  REQUIRE(heading("Xmp.drone-dji.FlightYawDegree -160.3\n").has_value());
  CHECK(*heading("Xmp.drone-dji.FlightYawDegree -160.3\n") == doctest::Approx(199.7).epsilon(1e-12));
  CHECK(*heading("Xmp.drone-dji.FlightYawDegree 180\n") == doctest::Approx(180.0));
  CHECK(*heading("Xmp.drone-dji.FlightYawDegree -0\n") == 0.0);
  CHECK(*heading("Xmp.drone-dji.FlightYawDegree 720.5\n") == doctest::Approx(0.5).epsilon(1e-12));
  CHECK(*heading("Xmp.drone-dji.FlightYawDegree -1e-17\n") == 0.0);  // not 360
  CHECK(*heading("Xmp.DLS.Yaw -2.7427257414198345\n") ==
        doctest::Approx(360.0 - 2.7427257414198345 * 180.0 / std::numbers::pi).epsilon(1e-12));
  // DJI's key first where a file has both.
  const CaptureMeta both = parse_capture_meta("Xmp.DLS.Yaw 1.0\nXmp.drone-dji.FlightYawDegree 10\n", "x.tif");
  CHECK(*both.heading_deg == doctest::Approx(10.0));
  CHECK(both.source.at("heading") == "Xmp.drone-dji.FlightYawDegree");
  // No heading tag, or one so large that it overflows: no heading.
  CHECK_FALSE(heading("Xmp.Camera.BandName NIR\n").has_value());
  CHECK_FALSE(heading("Xmp.DLS.Yaw 1e308\n").has_value());
}

}  // namespace test_light_sensor_heading
