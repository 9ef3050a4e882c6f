// tests/test_similarity.cpp
// fit_similarity (msgs/io/similarity.hpp): a known similarity is recovered from exact points, a
// mirrored set still gives a rotation, noise leaves the least-squares fit, and bad input is refused.
#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include <msgs/io/similarity.hpp>

namespace test_similarity {
using msgs::io::fit_similarity;

namespace {

std::vector<Eigen::Vector3d> cloud(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 5.0);
  std::vector<Eigen::Vector3d> p;
  for (std::size_t i = 0; i < n; ++i) p.emplace_back(g(rng), g(rng), 0.2 * g(rng));  // a flat-ish flight
  return p;
}

}  // namespace

TEST_CASE("fit_similarity: recovers scale, rotation and shift") {
  const auto src = cloud(30, 1);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
  const Eigen::Vector3d t(4, -2, 7);
  std::vector<Eigen::Vector3d> dst;
  for (const auto& p : src) dst.push_back(0.37 * (R * p) + t);
  const msgs::io::Similarity s = fit_similarity(src, dst);
  CHECK(s.scale == doctest::Approx(0.37).epsilon(1e-12));
  CHECK((s.R - R).norm() < 1e-12);
  CHECK((s.t - t).norm() < 1e-11);
  for (std::size_t i = 0; i < src.size(); ++i) CHECK((s(src[i]) - dst[i]).norm() < 1e-11);
}

TEST_CASE("fit_similarity: a mirrored set gives the best rotation, not a reflection; noise averages out") {
  auto src = cloud(40, 2);
  std::vector<Eigen::Vector3d> mirrored;
  for (const auto& p : src) mirrored.emplace_back(p.x(), p.y(), -p.z());
  const msgs::io::Similarity m = fit_similarity(src, mirrored);
  CHECK(m.R.determinant() == doctest::Approx(1.0));
  CHECK((m.R * m.R.transpose() - Eigen::Matrix3d::Identity()).norm() < 1e-12);

  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<Eigen::Vector3d> dst;
  for (const auto& p : src) dst.push_back(2.0 * p + Eigen::Vector3d(1, 1, 1) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  const msgs::io::Similarity s = fit_similarity(src, dst);
  CHECK(s.scale == doctest::Approx(2.0).epsilon(1e-3));
  CHECK((s.R - Eigen::Matrix3d::Identity()).norm() < 1e-2);
  double rms = 0;
  for (std::size_t i = 0; i < src.size(); ++i) rms += (s(src[i]) - dst[i]).squaredNorm() / double(src.size());
  CHECK(std::sqrt(rms) < 0.03);  // about sqrt(3) x the noise
}

TEST_CASE("fit_similarity: too few points, different sizes and no spread are refused") {
  const auto src = cloud(5, 4);
  CHECK_THROWS_AS(fit_similarity({src[0], src[1]}, {src[0], src[1]}), std::invalid_argument);
  CHECK_THROWS_AS(fit_similarity(src, {src[0], src[1], src[2]}), std::invalid_argument);
  const std::vector<Eigen::Vector3d> same(4, Eigen::Vector3d(1, 2, 3));
  CHECK_THROWS_AS(fit_similarity(same, std::vector<Eigen::Vector3d>(src.begin(), src.begin() + 4)), std::invalid_argument);
}

}  // namespace test_similarity
