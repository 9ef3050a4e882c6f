// tests/test_rig_poses.cpp
// Placing the images COLMAP did not register through the other bands of their capture
// (msgs/io/rig_poses.hpp): a known rig flown along a path, seen in a COLMAP-like frame (rotated,
// shifted and scaled), with pose noise, missing images, a misregistered image and a band that
// does not move with the rig.
#include <doctest/doctest.h>

#include <cmath>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <msgs/io/rig_poses.hpp>

namespace test_rig_poses {
using msgs::io::RigPose;
using Poses = std::vector<std::vector<std::optional<RigPose>>>;

namespace {

const std::vector<std::string> kNames = {"D", "MS_G", "MS_R", "MS_NIR"};

Eigen::Matrix3d rot(double ax, double ay, double az) {
  return (Eigen::AngleAxisd(az, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(ay, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(ax, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

/// A four-lens rig (boresights a degree or two apart, lenses centimetres apart) flown over
/// `captures` positions 3 m apart along a line and a turn, pointing down with a changing heading;
/// world-to-camera poses in a frame like COLMAP's: the metric world rotated, shifted and scaled by
/// 0.37. `noise` adds that much rotation (radians) and relative translation (of the capture
/// spacing) to every pose.
struct Flight {
  Poses truth;
  std::vector<RigPose> offsets;  // band from the rig body
  double spacing = 3.0 * 0.37;
};

Flight fly(std::size_t captures, double noise, unsigned seed) {
  Flight f;
  const std::vector<Eigen::Vector3d> lens = {{0, 0, 0}, {0.03, 0.02, 0}, {-0.025, 0.02, 0.005}, {0.01, -0.04, 0}};
  const std::vector<Eigen::Vector3d> boresight = {{0, 0, 0}, {0.02, -0.01, 0.005}, {-0.015, 0.01, 0.0}, {0.01, 0.025, -0.01}};
  const Eigen::Matrix3d frame = rot(0.3, -0.2, 1.1);  // metric world -> COLMAP world
  const Eigen::Vector3d shift(4, -2, 7);
  const double scale = 0.37;
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (std::size_t c = 0; c < captures; ++c) {
    const double s = double(c);
    const Eigen::Vector3d pos(3.0 * s, c > 6 ? 0.4 * (s - 6) * (s - 6) : 0.0, 30.0 + 0.2 * std::sin(s));
    const Eigen::Matrix3d body = rot(M_PI + 0.05 * std::sin(s), 0.04 * std::cos(s), 0.3 * s);  // looking down
    std::vector<std::optional<RigPose>> cap;
    for (std::size_t b = 0; b < lens.size(); ++b) {
      const Eigen::Matrix3d Rb = rot(boresight[b].x(), boresight[b].y(), boresight[b].z()) * body;
      const Eigen::Vector3d centre = pos + body.transpose() * lens[b];
      // In the COLMAP frame: x' = scale frame x + shift, so R' = R frame^T, centre' likewise.
      RigPose p;
      p.R = Rb * frame.transpose();
      const Eigen::Vector3d c2 = scale * (frame * centre) + shift;
      if (noise > 0) {
        p.R = rot(noise * n01(rng), noise * n01(rng), noise * n01(rng)) * p.R;
        const Eigen::Vector3d jitter(n01(rng), n01(rng), n01(rng));
        p.t = -(p.R * (c2 + noise * f.spacing * jitter));
      } else {
        p.t = -(p.R * c2);
      }
      cap.push_back(p);
    }
    f.truth.push_back(cap);
  }
  return f;
}

double angle_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return msgs::io::detail::rotation_angle_deg(a, b);
}

Eigen::Vector3d centre(const RigPose& p) { return -(p.R.transpose() * p.t); }

}  // namespace

TEST_CASE("rig: missing images are placed where the rig put them") {
  const Flight f = fly(12, 0.0, 1);
  Poses poses = f.truth;
  poses[2][1].reset();  // a band missing here and there
  poses[5][3].reset();
  poses[7][0].reset();  // the reference missing: placed from another band
  poses[7][2].reset();
  poses[9][1].reset();
  const msgs::io::Rig rig = msgs::io::estimate_rig(poses, 4, kNames);
  CHECK(rig.reference == 0);  // the first of the bands with the most registered captures (11)
  CHECK(rig.problems.empty());
  CHECK(rig.capture_spacing == doctest::Approx(f.spacing).epsilon(0.01));  // 3 m apart, give or take the height changes
  for (int b = 1; b < 4; ++b) {
    REQUIRE(rig.bands[std::size_t(b)]);
    CHECK(rig.bands[std::size_t(b)]->inliers == rig.bands[std::size_t(b)]->samples);
    CHECK(rig.bands[std::size_t(b)]->rotation_spread_deg < 1e-5);
    CHECK(rig.bands[std::size_t(b)]->translation_spread < 1e-9);
  }
  const auto placed = msgs::io::place_by_rig(poses, rig);
  REQUIRE(placed.size() == 5);
  CHECK(placed[0].capture == 2);
  CHECK(placed[0].band == 1);
  CHECK(placed[0].from == 0);
  // Capture 7 lost the reference: D and MS_R come from MS_NIR, the band registered there with the
  // most captures (MS_NIR 11, MS_G 10).
  CHECK(placed[2].capture == 7);
  CHECK(placed[2].band == 0);
  CHECK(placed[2].from == 3);
  CHECK(placed[3].band == 2);
  CHECK(placed[3].from == 3);
  for (const auto& p : placed) {
    const RigPose& got = *poses[p.capture][p.band];
    const RigPose& want = *f.truth[p.capture][p.band];
    CHECK(angle_deg(got.R, want.R) < 1e-5);
    CHECK((centre(got) - centre(want)).norm() < 1e-7);
  }
}

TEST_CASE("rig: noisy poses, a misregistered image left out of the estimate") {
  const double noise = 0.0005;  // 0.03 degrees and 0.05% of the spacing, as COLMAP scatters
  const Flight f = fly(20, noise, 2);
  Poses poses = f.truth;
  // Capture 4's NIR registered in the wrong place: 5 degrees off and a capture spacing away.
  poses[4][3]->R = rot(0.09, 0, 0) * poses[4][3]->R;
  poses[4][3]->t += Eigen::Vector3d(f.spacing, 0, 0);
  poses[11][3].reset();
  poses[13][2].reset();
  const msgs::io::Rig rig = msgs::io::estimate_rig(poses, 4, kNames);
  REQUIRE(rig.bands[3]);
  CHECK(rig.bands[3]->samples == 19);
  CHECK(rig.bands[3]->inliers == 18);  // capture 4's NIR is out
  CHECK(rig.bands[3]->rotation_spread_deg < 0.3);
  CHECK(rig.bands[3]->translation_spread < 0.02);
  const auto placed = msgs::io::place_by_rig(poses, rig);
  REQUIRE(placed.size() == 2);
  for (const auto& p : placed) {
    const RigPose& got = *poses[p.capture][p.band];
    const RigPose& want = *f.truth[p.capture][p.band];
    CHECK(angle_deg(got.R, want.R) < 0.15);
    CHECK((centre(got) - centre(want)).norm() < 0.01 * f.spacing);
  }
}

TEST_CASE("rig: a band that does not move with the others, or registered too rarely, gets no offset") {
  const Flight f = fly(10, 0.0, 3);
  Poses poses = f.truth;
  // MS_R turns with the capture (a camera on its own gimbal, or a different flight): no rig.
  for (std::size_t c = 0; c < poses.size(); ++c) poses[c][2]->R = rot(0, 0, 0.2 * double(c)) * poses[c][2]->R;
  poses[3][2].reset();
  // MS_NIR registered in two captures only.
  for (std::size_t c = 2; c < poses.size(); ++c) poses[c][3].reset();
  const msgs::io::Rig rig = msgs::io::estimate_rig(poses, 4, kNames);
  CHECK(rig.bands[1]);
  CHECK_FALSE(rig.bands[2]);
  CHECK_FALSE(rig.bands[3]);
  REQUIRE(rig.problems.size() == 2);
  CHECK(rig.problems[0].find("MS_R: only") == 0);
  CHECK(rig.problems[0].find("do not move as one rig") != std::string::npos);
  CHECK(rig.problems[1].find("MS_NIR: registered together with D in 2 captures, 3 needed") == 0);
  const auto placed = msgs::io::place_by_rig(poses, rig);
  CHECK(placed.empty());  // neither band can be placed
  CHECK_FALSE(poses[3][2]);
  CHECK_FALSE(poses[5][3]);
}

TEST_CASE("rig: nothing registered, a capture with no band registered, no bands") {
  Poses none(4, std::vector<std::optional<RigPose>>(3));
  msgs::io::Rig rig = msgs::io::estimate_rig(none, 3, kNames);
  CHECK(rig.reference == -1);
  CHECK(msgs::io::place_by_rig(none, rig).empty());
  CHECK(msgs::io::estimate_rig({}, 0, {}).reference == -1);

  const Flight f = fly(6, 0.0, 4);
  Poses poses = f.truth;
  for (auto& p : poses[2]) p.reset();  // a capture lost entirely
  poses[4][1].reset();
  rig = msgs::io::estimate_rig(poses, 4, kNames);
  const auto placed = msgs::io::place_by_rig(poses, rig);
  REQUIRE(placed.size() == 1);
  CHECK(placed[0].capture == 4);
  for (const auto& p : poses[2]) CHECK_FALSE(p);

  // Every capture at one spot (a camera on a tripod): the spacing is 0 and only rotations count.
  Poses still;
  for (int c = 0; c < 5; ++c) still.push_back(f.truth[0]);
  still[1][2].reset();
  rig = msgs::io::estimate_rig(still, 4, kNames);
  CHECK(rig.capture_spacing == 0.0);
  REQUIRE(rig.bands[2]);
  CHECK(std::isfinite(rig.bands[2]->translation_spread));
  CHECK(msgs::io::place_by_rig(still, rig).size() == 1);
  CHECK((centre(*still[1][2]) - centre(*f.truth[0][2])).norm() < 1e-9);
}

}  // namespace test_rig_poses
