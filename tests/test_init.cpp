// tests/test_init.cpp
// Checks init.hpp: kNN scales against known distances and brute force, duplicates, determinism, defaults.
#include <doctest/doctest.h>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "msgs/init.hpp"

namespace test_init {
namespace {

using G3 = msgs::Gaussian<3, 2>;

/// O(N^2) reference: mean distance to the k nearest other points.
std::vector<double> brute_knn(const std::vector<float>& xyz, int k) {
  const std::size_t n = xyz.size() / 3;
  std::vector<double> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<double> d;
    for (std::size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      double s = 0;
      for (std::size_t a = 0; a < 3; ++a) {
        const double e = double(xyz[3 * i + a]) - double(xyz[3 * j + a]);
        s += e * e;
      }
      d.push_back(std::sqrt(s));
    }
    std::sort(d.begin(), d.end());
    const std::size_t m = std::min<std::size_t>(static_cast<std::size_t>(k), d.size());
    double sum = 0;
    for (std::size_t j = 0; j < m; ++j) sum += d[j];
    out[i] = m ? sum / double(m) : 0.0;
  }
  return out;
}

std::vector<float> random_cloud(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  std::vector<float> xyz(3 * n);
  for (auto& v : xyz) v = u(rng);
  return xyz;
}

}  // namespace

TEST_CASE("kNN scales on an anisotropic grid: neighbours at 1, 1.5 and 1.75") {
  // 2x2x2 grid with spacings 1 (x), 1.5 (y), 1.75 (z): every corner's 3 nearest are at 1, 1.5, 1.75
  // (the face diagonals are longer: sqrt(1 + 2.25) > 1.75).
  std::vector<float> xyz;
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) xyz.insert(xyz.end(), {1.0f * x, 1.5f * y, 1.75f * z});
  const auto m = msgs::init_from_points<G3>(xyz);
  REQUIRE(m.size() == 8);
  for (std::size_t i = 0; i < 8; ++i)
    for (int a = 0; a < 3; ++a) CHECK(m.log_scales[3 * i + a] == doctest::Approx(std::log(4.25 / 3.0)).epsilon(1e-6));
  CHECK(m.means == xyz);
  // With k = 1 it is the nearest only.
  msgs::InitConfig cfg;
  cfg.knn = 1;
  const auto m1 = msgs::init_from_points<G3>(xyz, cfg);
  CHECK(m1.log_scales[0] == doctest::Approx(0.0));
}

TEST_CASE("kNN mean distance matches brute force on a random cloud, whatever the thread count") {
  const auto xyz = random_cloud(700, 5);
  const auto ref = brute_knn(xyz, 3);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto d1 = msgs::knn_mean_distance(xyz, 3);
  omp_set_num_threads(3);
  const auto d3 = msgs::knn_mean_distance(xyz, 3);
  omp_set_num_threads(saved);
  REQUIRE(d1.size() == ref.size());
  for (std::size_t i = 0; i < ref.size(); ++i) CHECK(d1[i] == doctest::Approx(ref[i]).epsilon(1e-12));
  CHECK(d1 == d3);
}

TEST_CASE("duplicate points give finite, floored scales; tiny clouds work") {
  msgs::InitConfig cfg;
  // Four copies of one point: all distances 0, floored.
  std::vector<float> dup = {1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 3};
  const auto m = msgs::init_from_points<G3>(dup, cfg);
  for (float v : m.log_scales) {
    CHECK(std::isfinite(v));
    CHECK(v == doctest::Approx(std::log(cfg.min_distance)).epsilon(1e-6));
  }
  // One duplicate among spread points: the duplicate counts at distance 0 for its twin.
  std::vector<float> mixed = {0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3};
  const auto d = msgs::knn_mean_distance(mixed, 3);
  CHECK(d[0] == doctest::Approx((0.0 + 1.0 + 2.0) / 3));
  CHECK(d[1] == doctest::Approx((0.0 + 1.0 + 2.0) / 3));
  CHECK(d == brute_knn(mixed, 3));
  // Fewer points than k + 1.
  const auto two = msgs::init_from_points<G3>({0, 0, 0, 0, 0, 0.5f});
  CHECK(two.log_scales[0] == doctest::Approx(std::log(0.5)));
  const auto one = msgs::init_from_points<G3>({4, 5, 6});
  CHECK(one.log_scales[0] == doctest::Approx(std::log(cfg.isolated_distance)));
  CHECK(msgs::init_from_points<G3>({}).empty());
}

TEST_CASE("defaults: identity rotation, opacity 0.1, SH DC in [0, 1), higher orders 0") {
  const auto xyz = random_cloud(50, 9);
  const auto m = msgs::init_from_points<G3>(xyz);
  m.check_consistent();
  for (std::size_t i = 0; i < m.size(); ++i) {
    CHECK(m.quats[4 * i] == 1.0f);
    CHECK(m.quats[4 * i + 1] == 0.0f);
    CHECK(m.quats[4 * i + 2] == 0.0f);
    CHECK(m.quats[4 * i + 3] == 0.0f);
    CHECK(1.0 / (1.0 + std::exp(-double(m.opacity_logits[i]))) == doctest::Approx(0.1).epsilon(1e-6));
    for (int k = 0; k < G3::sh_coeffs; ++k)
      for (int c = 0; c < 3; ++c) {
        const float v = m.sh_at(i, k, c);
        if (k == 0) {
          CHECK(v >= 0.0f);
          CHECK(v < 1.0f);
        } else {
          CHECK(v == 0.0f);
        }
      }
  }
  // The DC colours are not all the same value (a broken generator would be).
  CHECK(m.sh_at(0, 0, 0) != m.sh_at(1, 0, 0));
}

TEST_CASE("initialisation is deterministic and the seed matters") {
  const auto xyz = random_cloud(200, 11);
  msgs::InitConfig cfg;
  cfg.seed = 42;
  const auto a = msgs::init_from_points<msgs::Gaussian<7, 1>>(xyz, cfg);
  const auto b = msgs::init_from_points<msgs::Gaussian<7, 1>>(xyz, cfg);
  CHECK(a.sh == b.sh);
  CHECK(a.log_scales == b.log_scales);
  cfg.seed = 43;
  const auto c = msgs::init_from_points<msgs::Gaussian<7, 1>>(xyz, cfg);
  CHECK(a.sh != c.sh);
  CHECK(a.log_scales == c.log_scales);
}

TEST_CASE("random init in a box") {
  msgs::InitConfig cfg;
  cfg.seed = 3;
  const auto a = msgs::init_random<G3>(300, {-1.0f, 0.0f, 2.0f}, {1.0f, 0.5f, 2.0f}, cfg);
  const auto b = msgs::init_random<G3>(300, {-1.0f, 0.0f, 2.0f}, {1.0f, 0.5f, 2.0f}, cfg);
  REQUIRE(a.size() == 300);
  CHECK(a.means == b.means);
  CHECK(a.sh == b.sh);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a.means[3 * i] >= -1.0f);
    CHECK(a.means[3 * i] <= 1.0f);
    CHECK(a.means[3 * i + 1] >= 0.0f);
    CHECK(a.means[3 * i + 1] <= 0.5f);
    CHECK(a.means[3 * i + 2] == 2.0f);  // flat box
    CHECK(std::isfinite(a.log_scales[3 * i]));
  }
  // Colours are not the point coordinates recycled from the same stream.
  CHECK(a.sh_at(0, 0, 0) != (a.means[0] + 1.0f) / 2.0f);
}

TEST_CASE("malformed input is rejected with a named field") {
  CHECK_THROWS_WITH_AS(msgs::init_from_points<G3>({1, 2}), doctest::Contains("xyz"), std::invalid_argument);
  CHECK_THROWS_WITH_AS(msgs::init_from_points<G3>({1, 2, NAN}), doctest::Contains("not finite"),
                       std::invalid_argument);
  msgs::InitConfig bad;
  bad.initial_opacity = 1.0;
  CHECK_THROWS_AS(msgs::init_from_points<G3>({1, 2, 3}, bad), std::invalid_argument);
  CHECK_THROWS_AS(msgs::init_random<G3>(4, {1, 0, 0}, {0, 1, 1}), std::invalid_argument);
  CHECK_THROWS_AS(msgs::knn_mean_distance({0, 0, 0}, 0), std::invalid_argument);
}

}  // namespace test_init
