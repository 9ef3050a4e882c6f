// tests/test_curve.cpp
// Quality-against-time curves (curve.hpp): the eval subset, a run's All curve over models trained
// one after another, where two curves cross, and the curve file kept next to a checkpoint.
#include <doctest/doctest.h>

#include "fixtures.hpp"

#include <msgs/curve.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace test_curve {
namespace fs = std::filesystem;
using namespace msgs;

TEST_CASE("curve_subset spreads k images evenly over the eval split, or takes all") {
  CHECK(curve_subset(10, 4) == std::vector<std::size_t>{0, 2, 5, 7});
  CHECK(curve_subset(3, 4) == std::vector<std::size_t>{0, 1, 2});
  CHECK(curve_subset(5, 0) == std::vector<std::size_t>{0, 1, 2, 3, 4});
  CHECK(curve_subset(0, 4).empty());
  CHECK(curve_subset(7, 1) == std::vector<std::size_t>{0});
}

TEST_CASE("all_curve: a Separate run's All appears once every band has a value, keeping finished bands' last values") {
  auto point = [](double s, long long step, const std::string& model, std::vector<std::string> bands, std::vector<double> p) {
    CurvePoint c;
    c.seconds = s;
    c.step = step;
    c.model = model;
    c.gaussians = 100;
    c.bands = std::move(bands);
    c.psnr = p;
    for (double& v : p) v /= 100.0;
    c.ssim = p;
    return c;
  };
  const std::vector<CurvePoint> pts = {point(0, 0, "D", {"D"}, {10}), point(5, 100, "D", {"D"}, {20}),
                                       point(5, 0, "MS_G", {"MS_G"}, {12}), point(9, 100, "MS_G", {"MS_G"}, {30})};
  const std::vector<AllPoint> all = all_curve(pts, {"D", "MS_G"});
  REQUIRE(all.size() == 2);
  CHECK(all[0].seconds == 5);
  CHECK(all[0].psnr == doctest::Approx(16.0));  // D's final 20 and G's start 12
  CHECK(all[0].ssim == doctest::Approx(0.16));
  CHECK(all[0].gaussians == 200);
  CHECK(all[1].psnr == doctest::Approx(25.0));
  // A Joint point carries every band.
  const auto joint = all_curve({point(1, 10, "joint", {"D", "MS_G"}, {20, 22})}, {"D", "MS_G"});
  REQUIRE(joint.size() == 1);
  CHECK(joint[0].psnr == doctest::Approx(21.0));
  CHECK(all_curve(pts, {"D", "MS_NIR"}).empty());  // a band never evaluated: no All
}

TEST_CASE("crossings: where the leader changes, linearly interpolated, on the common time range") {
  // a rises from 10 to 30 over [0, 10]; b is flat at 20 over [2, 20]: a overtakes b at t = 5.
  const auto x = crossings({0, 10}, {10, 30}, {2, 20}, {20, 20});
  REQUIRE(x.size() == 1);
  CHECK(x[0].seconds == doctest::Approx(5.0));
  CHECK(x[0].a_ahead_after);
  // And back: b's view of the same pair.
  const auto y = crossings({2, 20}, {20, 20}, {0, 10}, {10, 30});
  REQUIRE(y.size() == 1);
  CHECK_FALSE(y[0].a_ahead_after);
  // Three crossings, one through a tie (at t = 2 the curves touch, then a falls behind).
  const auto z = crossings({0, 1, 2, 3, 4}, {0, 2, 1, 0, 3}, {0, 4}, {1, 1});
  REQUIRE(z.size() == 3);
  CHECK(z[0].seconds == doctest::Approx(0.5));
  CHECK(z[1].seconds == doctest::Approx(2.0));
  CHECK_FALSE(z[1].a_ahead_after);
  CHECK(z[2].seconds == doctest::Approx(10.0 / 3.0));
  // Touching without changing sides is not a crossing.
  CHECK(crossings({0, 1, 2}, {2, 1, 2}, {0, 2}, {1, 1}).empty());
  // No overlap, no finite values, identical curves: nothing.
  CHECK(crossings({0, 1}, {0, 1}, {2, 3}, {0, 1}).empty());
  CHECK(crossings({0, 1}, {NAN, NAN}, {0, 1}, {0, 1}).empty());
  CHECK(crossings({0, 1, 2}, {1, 2, 3}, {0, 1, 2}, {1, 2, 3}).empty());
}

TEST_CASE("curve file: round trip, and a malformed file is an error naming file and line") {
  const fs::path dir = msgs::testing::scratch_dir("curve");
  fs::create_directories(dir);
  CurvePoint p;
  p.seconds = 1.25;
  p.step = 40;
  p.gaussians = 1234;
  p.bands = {"D", "MS_NIR"};
  p.psnr = {21.123456789012345, 25.5};
  p.ssim = {0.61, 0.7};
  save_curve(dir / "a.curve", 3.5, {p, p});
  const auto [clock, pts] = load_curve(dir / "a.curve");
  CHECK(clock == 3.5);
  REQUIRE(pts.size() == 2);
  CHECK(pts[1].step == 40);
  CHECK(pts[1].gaussians == 1234);
  CHECK(pts[1].bands == p.bands);
  CHECK(pts[1].psnr == p.psnr);  // 17 digits: exact
  CHECK(pts[1].ssim == p.ssim);
  std::ofstream(dir / "bad.curve") << "clock,1\npoint,1,2,x,3,D|G,20,0.5|0.6\n";
  try {
    (void)load_curve(dir / "bad.curve");
    FAIL("expected an error");
  } catch (const io::IoError& e) {
    const std::string m = e.what();
    CHECK(m.find("bad.curve") != std::string::npos);
    CHECK(m.find("line 2") != std::string::npos);
  }
  std::ofstream(dir / "bad2.curve") << "clock,abc\n";
  CHECK_THROWS_AS(load_curve(dir / "bad2.curve"), io::IoError);
  // Numbers that parse but that save_curve never writes: each names its line and the value.
  const std::pair<const char*, const char*> damaged[] = {
      {"clock,nan\n", "not finite ('nan')"},
      {"clock,-3\n", "negative time '-3'"},
      {"clock,1\npoint,1,inf,x,3,D,20,0.5\n", "not finite ('inf')"},
      {"clock,1\npoint,1,1e300,x,3,D,20,0.5\n", "'1e300' where a whole number >= 0 belongs"},
      {"clock,1\npoint,1,2,x,-4,D,20,0.5\n", "'-4' where a whole number >= 0 belongs"},
      {"clock,1\npoint,1,2.5,x,4,D,20,0.5\n", "'2.5' where a whole number >= 0 belongs"},
      {"clock,1\npoint,1,2,x,4,D,nan,0.5\n", "not finite ('nan')"},
  };
  for (const auto& [text, needle] : damaged) {
    std::ofstream(dir / "bad3.curve") << text;
    CHECK_THROWS_WITH_AS(load_curve(dir / "bad3.curve"), doctest::Contains(needle), io::IoError);
  }
  CHECK_THROWS_AS(load_curve(dir / "missing.curve"), io::IoError);
}

}  // namespace test_curve
