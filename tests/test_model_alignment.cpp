// tests/test_model_alignment.cpp
// A second COLMAP model carried into the main model's frame through the captures both hold
// (msgs/io/model_alignment.hpp): a survey flight whose NIR and red-edge cameras form a model of
// their own, in a frame rotated, shifted and scaled against the main one; with centimetre lens
// offsets and registration noise, a misregistered capture, too few shared captures, captures
// along one line, and a model that does not belong to the flight.
#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include <msgs/io/model_alignment.hpp>

namespace test_model_alignment {
using msgs::io::CaptureCentres;
using msgs::io::RigPose;
using Cameras = std::vector<std::pair<std::size_t, RigPose>>;

namespace {

Eigen::Matrix3d rot(double ax, double ay, double az) {
  return (Eigen::AngleAxisd(az, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(ay, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(ax, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

/// The frame a model is reconstructed in: x_model = scale R x_world + t.
const msgs::io::Similarity kMainFrame{0.37, rot(0.3, -0.2, 1.1), Eigen::Vector3d(4, -2, 7)};
const msgs::io::Similarity kOtherFrame{2.9, rot(-1.2, 0.4, 2.5), Eigen::Vector3d(-30, 11, 0.5)};

/// A world-to-camera pose in a model's frame, from the camera's world rotation and centre.
RigPose in_frame(const Eigen::Matrix3d& R_world, const Eigen::Vector3d& centre, const msgs::io::Similarity& f) {
  RigPose p;
  p.R = R_world * f.R.transpose();
  p.t = -(p.R * f(centre));
  return p;
}

/// A lawnmower survey: `rows` lines of `per_row` captures, 3 m apart along a line and 5 m
/// between lines (one line only with rows = 1), at 30 m, looking down. Each capture has four
/// lenses a few centimetres apart with boresights a degree apart: lenses 0 and 1 (RGB, green)
/// registered in the main model, lenses 2 and 3 (red-edge, NIR) in the other. `noise` (metres)
/// moves every camera centre at random.
struct Survey {
  Cameras main, other;
  std::vector<Eigen::Matrix3d> R_world;  // [capture * 4 + lens]
  std::vector<Eigen::Vector3d> centre;
  std::size_t captures = 0;
};

Survey fly(int rows, int per_row, double noise, unsigned seed) {
  Survey s;
  const Eigen::Vector3d lens[4] = {{0, 0, 0}, {0.03, 0.02, 0}, {-0.025, 0.02, 0.005}, {0.01, -0.04, 0}};
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (int r = 0; r < rows; ++r)
    for (int k = 0; k < per_row; ++k) {
      const std::size_t c = s.captures++;
      const Eigen::Vector3d pos(3.0 * (r % 2 ? per_row - 1 - k : k), 5.0 * r, 30.0 + 0.2 * std::sin(double(c)));
      const Eigen::Matrix3d body = rot(M_PI + 0.03 * std::sin(double(c)), 0.02 * std::cos(double(c)), r % 2 ? M_PI : 0.0);
      for (int l = 0; l < 4; ++l) {
        const Eigen::Matrix3d Rw = rot(0.01 * l, -0.015 * l, 0.005 * l) * body;
        const Eigen::Vector3d centre =
            pos + body.transpose() * lens[l] + noise * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
        s.R_world.push_back(Rw);
        s.centre.push_back(centre);
        (l < 2 ? s.main : s.other).emplace_back(c, in_frame(Rw, centre, l < 2 ? kMainFrame : kOtherFrame));
      }
    }
  return s;
}

/// Largest distance (metres, in the world) of the other model's cameras, carried into the main
/// frame by `to_main`, from where the main frame has them, leaving out the captures `skip`; and
/// the largest rotation error (degrees).
std::pair<double, double> carried_error(const Survey& s, const msgs::io::Similarity& to_main,
                                        const std::vector<std::size_t>& skip = {}) {
  double pos = 0, ang = 0;
  std::size_t i = 0;
  for (std::size_t c = 0; c < s.captures; ++c)
    for (int l = 2; l < 4; ++l, ++i) {
      if (std::find(skip.begin(), skip.end(), c) != skip.end()) continue;
      const RigPose p = msgs::io::pose_in_main_frame(s.other[i].second, to_main);
      const RigPose want = in_frame(s.R_world[4 * c + std::size_t(l)], s.centre[4 * c + std::size_t(l)], kMainFrame);
      const Eigen::Vector3d got_centre = -(p.R.transpose() * p.t), want_centre = -(want.R.transpose() * want.t);
      pos = std::max(pos, (got_centre - want_centre).norm() / kMainFrame.scale);
      ang = std::max(ang, msgs::io::detail::rotation_angle_deg(p.R, want.R));
    }
  return {pos, ang};
}

}  // namespace

TEST_CASE("align_by_captures: a band model of a survey lands where the main model has its cameras") {
  const Survey s = fly(3, 6, 0.0, 1);
  const CaptureCentres main = msgs::io::capture_centres(s.main, s.captures), other = msgs::io::capture_centres(s.other, s.captures);
  const msgs::io::ModelAlignment a = msgs::io::align_by_captures(main, other);
  REQUIRE_MESSAGE(a.to_main, a.problem);
  CHECK(a.problem.empty());
  CHECK(a.shared == 18);
  CHECK(a.agreeing == 18);
  CHECK(a.disagreeing.empty());
  CHECK(a.capture_spacing == doctest::Approx(3.0 * kMainFrame.scale).epsilon(1e-3));
  // The lenses sit centimetres apart, so the capture centres of the two models differ by that
  // much, turning with the heading from line to line: every camera is carried over to within the
  // lenses' separation (4 cm), against captures 3 m apart.
  CHECK(a.to_main->scale == doctest::Approx(kMainFrame.scale / kOtherFrame.scale).epsilon(1e-3));
  CHECK(a.max_residual < 0.02);
  const auto [pos, ang] = carried_error(s, *a.to_main);
  MESSAGE("carried cameras: up to " << pos << " m and " << ang << " degrees from the truth");
  CHECK(pos < 0.03);
  CHECK(ang < 0.05);

  // A camera carried over projects a point of the main frame where the truth does (the scale of
  // camera coordinates moves no pixel).
  const RigPose p = msgs::io::pose_in_main_frame(s.other.back().second, *a.to_main);
  const RigPose want = in_frame(s.R_world.back(), s.centre.back(), kMainFrame);
  const Eigen::Vector3d x = kMainFrame(Eigen::Vector3d(20, 4, 0.5));
  const Eigen::Vector3d cg = p.R * x + p.t, cw = want.R * x + want.t;
  CHECK(std::abs(cg.x() / cg.z() - cw.x() / cw.z()) < 1e-3);
  CHECK(std::abs(cg.y() / cg.z() - cw.y() / cw.z()) < 1e-3);
}

TEST_CASE("align_by_captures: registration noise is absorbed, a misregistered capture is dropped") {
  Survey s = fly(3, 6, 0.05, 2);  // 5 cm of scatter on every camera
  // Capture 7 of the other model registered 4 m off (both of its cameras).
  for (auto& [c, pose] : s.other)
    if (c == 7) pose.t -= pose.R * (kOtherFrame.scale * (kOtherFrame.R * Eigen::Vector3d(4, 0, 0)));
  const msgs::io::ModelAlignment a =
      msgs::io::align_by_captures(msgs::io::capture_centres(s.main, s.captures), msgs::io::capture_centres(s.other, s.captures));
  REQUIRE_MESSAGE(a.to_main, a.problem);
  CHECK(a.shared == 18);
  CHECK(a.agreeing == 17);
  CHECK(a.disagreeing == std::vector<std::size_t>{7});
  CHECK(a.max_residual < 0.15);
  CHECK(a.median_residual < a.max_residual + 1e-12);
  const auto [pos, ang] = carried_error(s, *a.to_main, a.disagreeing);
  MESSAGE("with noise: the other cameras carried over to within " << pos << " m and " << ang << " degrees of the truth");
  CHECK(pos < 0.25);  // 5 cm of scatter on each camera, 3 m between captures
  CHECK(ang < 0.5);
}

TEST_CASE("align_by_captures: what it cannot align, it says why") {
  const Survey s = fly(3, 6, 0.0, 3);
  const CaptureCentres main = msgs::io::capture_centres(s.main, s.captures);
  SUBCASE("too few shared captures") {
    CaptureCentres other = msgs::io::capture_centres(s.other, s.captures);
    for (std::size_t c = 2; c < other.size(); ++c) other[c].reset();
    const auto a = msgs::io::align_by_captures(main, other);
    CHECK(!a.to_main);
    CHECK(a.shared == 2);
    CHECK(a.problem == "shares 2 captures with the main model, 3 needed to align it");
  }
  SUBCASE("captures along one line") {
    const Survey line = fly(1, 8, 0.0, 4);
    const auto a = msgs::io::align_by_captures(msgs::io::capture_centres(line.main, line.captures),
                                               msgs::io::capture_centres(line.other, line.captures));
    CHECK(!a.to_main);
    CHECK(a.problem.find("lie along one line") != std::string::npos);
  }
  SUBCASE("a model that is not of this flight") {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-20.0, 20.0);
    CaptureCentres other(s.captures);
    for (auto& c : other) c = Eigen::Vector3d(u(rng), u(rng), u(rng));
    const auto a = msgs::io::align_by_captures(main, other);
    CHECK(!a.to_main);
    CHECK(a.problem.find("does not fit the main model") != std::string::npos);
  }
  SUBCASE("a model whose captures all sit at one place, and an empty one") {
    CaptureCentres other(s.captures, Eigen::Vector3d(1, 2, 3));
    CHECK(msgs::io::align_by_captures(main, other).problem.find("do not spread") != std::string::npos);
    const auto none = msgs::io::align_by_captures(main, CaptureCentres{});
    CHECK(!none.to_main);
    CHECK(none.shared == 0);
  }
  SUBCASE("non-finite centres never align") {
    CaptureCentres other = msgs::io::capture_centres(s.other, s.captures);
    for (auto& c : other) c = Eigen::Vector3d(NAN, 0, 0);
    const auto a = msgs::io::align_by_captures(main, other);
    CHECK(!a.to_main);
    CHECK(!a.problem.empty());
  }
}

TEST_CASE("capture_centres: the mean centre of each capture's cameras; captures out of range ignored") {
  Cameras cams;
  RigPose a, b;
  a.t = Eigen::Vector3d(-1, 0, 0);  // centre (1, 0, 0)
  b.t = Eigen::Vector3d(-3, 0, 0);  // centre (3, 0, 0)
  cams.emplace_back(1, a);
  cams.emplace_back(1, b);
  cams.emplace_back(9, a);
  const CaptureCentres c = msgs::io::capture_centres(cams, 3);
  REQUIRE(c.size() == 3);
  CHECK(!c[0]);
  REQUIRE(c[1]);
  CHECK((*c[1] - Eigen::Vector3d(2, 0, 0)).norm() < 1e-15);
  CHECK(!c[2]);
}

}  // namespace test_model_alignment
