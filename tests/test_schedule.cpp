// tests/test_schedule.cpp
// Tests of msgs/schedule.hpp: step-indexed schedules, backgrounds and round-robin band sampling.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "msgs/schedule.hpp"

namespace test_schedule {
using namespace msgs;

TEST_CASE("ScheduleScale rounds, keeps positive periods positive and zero at zero") {
  const ScheduleScale s{0.05};
  CHECK(s(120000) == 6000);
  CHECK(s(300) == 15);
  CHECK(s(500) == 25);
  CHECK(s(5000) == 250);
  CHECK(s(10) == 1);   // 0.5 rounds to 1 anyway
  CHECK(s(1) == 1);    // 0.05 would round to 0: a period must stay >= 1
  CHECK(s(0) == 0);
  CHECK(ScheduleScale{1.0}(12345) == 12345);
  CHECK(ScheduleScale{2.0}(3000) == 6000);
  CHECK_THROWS_AS(ScheduleScale{0.0}(10), std::invalid_argument);
  CHECK_THROWS_AS(ScheduleScale{-1.0}(10), std::invalid_argument);
  CHECK_THROWS_AS(ScheduleScale{std::nan("")}(10), std::invalid_argument);
  // A factor too large for the schedule says so in a line a person can read (not 301 digits).
  CHECK_THROWS_WITH_AS(ScheduleScale{1e300}(120000),
                       "ScheduleScale: 120000 steps x 1e+300 is more steps than an int holds (at most 2147483647); "
                       "a factor up to 17895.7 fits",
                       std::invalid_argument);
}

TEST_CASE("SH degree grows one per 5000 steps up to the maximum") {
  CHECK(sh_degree_at(0, 3) == 0);
  CHECK(sh_degree_at(4999, 3) == 0);
  CHECK(sh_degree_at(5000, 3) == 1);
  CHECK(sh_degree_at(9999, 3) == 1);
  CHECK(sh_degree_at(10000, 3) == 2);
  CHECK(sh_degree_at(15000, 3) == 3);
  CHECK(sh_degree_at(119999, 3) == 3);
  CHECK(sh_degree_at(20000, 1) == 1);  // capped by the model's degree
  CHECK(sh_degree_at(0, 3, 0) == 3);   // no schedule: full degree
  CHECK(sh_degree_at(-5, 3) == 0);
}

TEST_CASE("colour-only warm-up freezes geometry for the first 500 steps") {
  CHECK(geometry_frozen_at(0));
  CHECK(geometry_frozen_at(499));
  CHECK_FALSE(geometry_frozen_at(500));
  CHECK_FALSE(geometry_frozen_at(100000));
  CHECK_FALSE(geometry_frozen_at(0, 0));
}

TEST_CASE("resolution schedule: 1/4 until 3000, 1/2 until 6000, then full") {
  CHECK(downscale_at(0) == 4);
  CHECK(downscale_at(2999) == 4);
  CHECK(downscale_at(3000) == 2);
  CHECK(downscale_at(5999) == 2);
  CHECK(downscale_at(6000) == 1);
  CHECK(downscale_at(120000) == 1);
  CHECK(downscale_at(0, 3000, 0) == 1);
  CHECK(downscale_at(0, 1000, 3) == 8);
}

TEST_CASE("TrainSchedule scales every iteration count together") {
  const TrainSchedule full;
  const TrainSchedule s = full.scaled(ScheduleScale{0.05});
  CHECK(s.total_steps == 6000);
  CHECK(s.sh_degree_every == 250);
  CHECK(s.warmup_steps == 25);
  CHECK(s.resolution_every == 150);
  CHECK(s.num_downscales == 2);  // a count of halvings, not of iterations
  // The scaled schedule at step t behaves as the full one at t / 0.05.
  for (long long t : {0LL, 24LL, 25LL, 149LL, 150LL, 299LL, 300LL, 749LL, 750LL, 5999LL}) {
    const long long T = t * 20;
    CHECK(s.sh_degree(t, 3) == full.sh_degree(T, 3));
    CHECK(s.geometry_frozen(t) == full.geometry_frozen(T));
    CHECK(s.downscale(t) == full.downscale(T));
  }
}

TEST_CASE("exponential learning-rate decay is log-linear between its endpoints") {
  const ExponentialDecay d{1.6e-4, 1.6e-6, 120000};
  CHECK(d(0) == doctest::Approx(1.6e-4).epsilon(1e-12));
  CHECK(d(120000) == doctest::Approx(1.6e-6).epsilon(1e-12));
  CHECK(d(200000) == doctest::Approx(1.6e-6).epsilon(1e-12));  // constant after the end
  CHECK(d(-10) == doctest::Approx(1.6e-4).epsilon(1e-12));
  CHECK(d(60000) == doctest::Approx(std::sqrt(1.6e-4 * 1.6e-6)).epsilon(1e-12));  // geometric mean
  CHECK(d(30000) == doctest::Approx(1.6e-4 * std::pow(1e-2, 0.25)).epsilon(1e-12));
  // Monotone.
  double prev = d(0);
  for (int t = 1000; t <= 120000; t += 1000) {
    CHECK(d(t) < prev);
    prev = d(t);
  }
  const ExponentialDecay s = d.scaled(ScheduleScale{0.05});
  CHECK(s.max_steps == 6000);
  CHECK(s(3000) == doctest::Approx(d(60000)).epsilon(1e-12));
  CHECK_THROWS_AS(ExponentialDecay({0.0, 1e-6, 10})(1), std::invalid_argument);
}

TEST_CASE("random training background is a pure function of the step") {
  const auto a = random_background<float>(1234, 3, 7);
  const auto b = random_background<float>(1234, 3, 7);
  CHECK(a == b);
  CHECK(a.size() == 3);
  CHECK(random_background<float>(1235, 3, 7) != a);
  CHECK(random_background<float>(1234, 3, 8) != a);
  CHECK(random_background<float>(5, 0).empty());
  // Uniform in [0, 1): bounds and a loose mean check over many steps.
  double sum = 0;
  int n = 0;
  for (int t = 0; t < 4000; ++t)
    for (float v : random_background<float>(t, 1)) {
      CHECK(v >= 0.0f);
      CHECK(v < 1.0f);
      sum += v;
      ++n;
    }
  CHECK(sum / n == doctest::Approx(0.5).epsilon(0.05));
  CHECK_THROWS_AS(random_background<float>(0, -1), std::invalid_argument);
}

TEST_CASE("evaluation background: grey for RGB, its BT.601 luminance for one channel") {
  const auto rgb = eval_background<double>(3);
  REQUIRE(rgb.size() == 3);
  CHECK(rgb[0] == 0.1490);  // splatfacto's torch.tensor([0.1490, 0.1647, 0.2157]), not rounded
  CHECK(rgb[1] == 0.1647);
  CHECK(rgb[2] == 0.2157);
  const auto grey = eval_background<double>(1);
  REQUIRE(grey.size() == 1);
  CHECK(grey[0] == doctest::Approx(0.299 * 0.1490 + 0.587 * 0.1647 + 0.114 * 0.2157));
  CHECK(grey[0] == doctest::Approx(0.1658197).epsilon(1e-6));
  CHECK_THROWS_AS(eval_background<float>(7), std::invalid_argument);
}

TEST_CASE("band sampling is round-robin, covers every image and repeats short lists") {
  // Five bands like a Joint run; band 0 (RGB) has more images than the others.
  const std::vector<int> counts = {10, 7, 7, 6, 10};
  const BandSampler s = BandSampler::from_counts(counts, 42);
  CHECK(s.num_bands() == 5);
  CHECK(s.list_length() == 10);
  CHECK(s.period() == 50);
  std::vector<std::map<int, int>> seen(5);
  for (long long t = 0; t < s.period(); ++t) {
    const auto d = s.at(t);
    CHECK(d.band == static_cast<int>(t % 5));  // bands come round-robin
    CHECK(d.image >= 0);
    CHECK(d.image < counts[static_cast<std::size_t>(d.band)]);
    ++seen[static_cast<std::size_t>(d.band)][d.image];
  }
  for (std::size_t b = 0; b < 5; ++b) {
    CHECK(seen[b].size() == static_cast<std::size_t>(counts[b]));  // every image used
    for (auto [img, k] : seen[b]) {
      // Repeated to length 10: each image once or twice, never more.
      CHECK(k >= 10 / counts[b]);
      CHECK(k <= (10 + counts[b] - 1) / counts[b]);
    }
  }
  // The full-length bands see every image exactly once per period, in a shuffled order.
  std::vector<int> order0;
  for (long long t = 0; t < s.period(); t += 5) order0.push_back(s.at(t).image);
  std::vector<int> sorted = order0;
  std::sort(sorted.begin(), sorted.end());
  CHECK(sorted == std::vector<int>({0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
  CHECK(order0 != sorted);  // shuffled (10! orders; identity by chance is negligible)
}

TEST_CASE("band sampling is deterministic and resumable") {
  const std::vector<std::vector<int>> lists = {{100, 101, 102, 103}, {200, 201, 202}, {300, 301}};
  const BandSampler a(lists, 9);
  const BandSampler b(lists, 9);  // a "resumed" run rebuilds the sampler from the same inputs
  for (long long t : {0LL, 1LL, 2LL, 11LL, 12LL, 12345LL, 120000LL}) {
    CHECK(a.at(t) == b.at(t));
    CHECK(a.at(t) == a.at(t + a.period()));
    CHECK(a.at(t).image / 100 == a.at(t).band + 1);  // ids come from the band's own list
  }
  // Another seed gives another order.
  const BandSampler c(lists, 10);
  bool differs = false;
  for (long long t = 0; t < a.period(); ++t) differs = differs || !(a.at(t) == c.at(t));
  CHECK(differs);
  CHECK_THROWS_AS(BandSampler(std::vector<std::vector<int>>{}), std::invalid_argument);
  CHECK_THROWS_AS(BandSampler(std::vector<std::vector<int>>{{1}, {}}), std::invalid_argument);
  CHECK_THROWS_AS(a.at(-1), std::invalid_argument);
  CHECK_THROWS_AS(BandSampler().at(0), std::logic_error);
}

TEST_CASE("band sampling with a reshuffle on every pass (the reference's order)") {
  const std::vector<std::vector<int>> lists = {{100, 101, 102, 103, 104, 105}, {200, 201, 202}, {300, 301, 302, 303}};
  const BandSampler once(lists, 42, Shuffle::once);
  const BandSampler every(lists, 42, Shuffle::every_pass);
  const BandSampler again(lists, 42, Shuffle::every_pass);  // a resumed run
  CHECK(every.mode() == Shuffle::every_pass);
  // The first pass of every band is the shuffle-once order.
  for (long long t = 0; t < 3 * 3; ++t) CHECK(every.at(t) == once.at(t));
  // Each pass of each band is a permutation of its list, in its own order; bands stay round-robin.
  for (std::size_t b = 0; b < lists.size(); ++b) {
    const long long n = static_cast<long long>(lists[b].size());
    std::vector<std::vector<int>> passes;
    for (long long pass = 0; pass < 20; ++pass) {
      std::vector<int> order;
      for (long long k = 0; k < n; ++k) {
        const long long t = (pass * n + k) * 3 + static_cast<long long>(b);
        const auto d = every.at(t);
        CHECK(d.band == static_cast<int>(b));
        CHECK(d == again.at(t));
        order.push_back(d.image);
      }
      std::vector<int> sorted = order;
      std::sort(sorted.begin(), sorted.end());
      CHECK(sorted == lists[b]);
      passes.push_back(order);
    }
    // Reshuffled: with 20 passes of 3..6 images, the orders are not all the same.
    CHECK(std::any_of(passes.begin(), passes.end(), [&](const std::vector<int>& o) { return o != passes[0]; }));
  }
  // Shuffle::once repeats itself after period(); every_pass does not.
  bool differs = false;
  for (long long t = 0; t < once.period(); ++t) differs = differs || !(every.at(t + 5 * once.period()) == once.at(t));
  CHECK(differs);
}

}  // namespace test_schedule
