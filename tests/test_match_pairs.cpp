// tests/test_match_pairs.cpp
// The image pairs `msgs import` has COLMAP match (msgs/io/match_pairs.hpp), against pair sets
// written out by hand and against counts worked out by formula.
#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <msgs/io/match_pairs.hpp>

namespace test_match_pairs {
using msgs::io::PairImage;
using msgs::io::window_pairs;
using Pairs = std::vector<std::pair<std::size_t, std::size_t>>;

namespace {

/// captures x bands images, capture-major (as `msgs import` lists them).
std::vector<PairImage> flight(std::size_t captures, const std::vector<std::string>& bands) {
  std::vector<PairImage> v;
  for (std::size_t c = 0; c < captures; ++c)
    for (const auto& b : bands) v.push_back({c, b});
  return v;
}

}  // namespace

TEST_CASE("window_pairs: the bands of a capture with each other, a band with itself in the next captures") {
  // Images 0..7: capture 0 (D, G), capture 1 (D, G), capture 2 (D, G), capture 3 (D, G).
  const auto images = flight(4, {"D", "MS_G"});
  const Pairs want1 = {{0, 1}, {0, 2}, {1, 3}, {2, 3}, {2, 4}, {3, 5}, {4, 5}, {4, 6}, {5, 7}, {6, 7}};
  CHECK(window_pairs(images, 1) == want1);
  const Pairs want0 = {{0, 1}, {2, 3}, {4, 5}, {6, 7}};
  CHECK(window_pairs(images, 0) == want0);
  // A window as long as the flight: within a capture every pair, across captures the same band only.
  const Pairs all = window_pairs(images, 3);
  CHECK(all.size() == 4 + 2 * 6);  // 4 captures' (D, G) pairs + C(4, 2) capture pairs per band
  for (const auto& [i, j] : all) CHECK((images[i].capture == images[j].capture || images[i].band == images[j].band));
  CHECK(window_pairs(images, 3) == window_pairs(images, 100));
}

TEST_CASE("window_pairs: one band and a window over the whole flight is every pair") {
  const auto images = flight(9, {"MS_NIR"});
  const Pairs p = window_pairs(images, 8);
  CHECK(p.size() == msgs::io::exhaustive_pair_count(images.size()));
  CHECK(window_pairs(images, 2).size() == 8 + 7);  // neighbours 1 and 2 apart
}

TEST_CASE("window_pairs: ascending, i < j, each pair once, whatever order the images come in") {
  // Captures listed out of order and bands shuffled: the distance is between capture positions.
  const std::vector<PairImage> images = {{3, "D"}, {0, "MS_R"}, {1, "D"}, {0, "D"}, {2, "MS_R"}, {3, "MS_R"}, {1, "MS_R"}};
  const Pairs p = window_pairs(images, 1);
  CHECK(std::is_sorted(p.begin(), p.end()));
  CHECK(std::set<std::pair<std::size_t, std::size_t>>(p.begin(), p.end()).size() == p.size());
  for (const auto& [i, j] : p) {
    CHECK(i < j);
    const std::size_t a = images[i].capture, b = images[j].capture, apart = a < b ? b - a : a - b;
    CHECK((apart == 0 || (apart == 1 && images[i].band == images[j].band)));
  }
  // Every qualifying pair is there: brute force over all pairs.
  std::size_t expected = 0;
  for (std::size_t i = 0; i < images.size(); ++i)
    for (std::size_t j = i + 1; j < images.size(); ++j) {
      const std::size_t a = images[i].capture, b = images[j].capture, apart = a < b ? b - a : a - b;
      expected += apart == 0 || (apart == 1 && images[i].band == images[j].band);
    }
  CHECK(p.size() == expected);
}

TEST_CASE("window_pairs: a long flight has pairs in proportion to its images, not their square") {
  // 200 captures x 5 bands, window 6: 10 pairs within each capture, and per band the capture
  // pairs 1 to 6 apart: sum over d of (200 - d) = 1200 - 21.
  const auto images = flight(200, {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"});
  const Pairs p = window_pairs(images, 6);
  CHECK(p.size() == 200 * 10 + 5 * (1200 - 21));
  CHECK(msgs::io::exhaustive_pair_count(images.size()) == 1000 * 999 / 2);
  CHECK(msgs::io::exhaustive_pair_count(0) == 0);
  CHECK(msgs::io::exhaustive_pair_count(1) == 0);
  CHECK(window_pairs({}, 6).empty());
  CHECK(window_pairs({{0, "D"}}, 6).empty());
}

TEST_CASE("neighbour_pairs: the nearest captures on the ground, whatever their order in the files") {
  // A survey grid flown as a lawnmower: line 1 east (captures 0-3), line 2 back west (4-7), 30 m
  // apart, 10 m between captures. Capture 7 sits next to capture 0, three files away in no window.
  std::vector<std::array<double, 3>> pos;
  for (int i = 0; i < 4; ++i) pos.push_back({10.0 * i, 0.0, 50.0});
  for (int i = 3; i >= 0; --i) pos.push_back({10.0 * i, 30.0, 50.0});
  const auto images = flight(8, {"D"});
  // Two nearest: the neighbours on the line (10 m) first; at the ends of a line the next nearest
  // is the capture across (30 m) or two along (20 m): 20 m wins.
  const Pairs p2 = msgs::io::neighbour_pairs(images, pos, 2);
  const std::set<std::pair<std::size_t, std::size_t>> s2(p2.begin(), p2.end());
  CHECK(s2.count({0, 1}));
  CHECK(s2.count({0, 2}));
  CHECK(!s2.count({0, 7}));
  // Three nearest: capture 0's third is a tie at 30 m between 3 (along) and 7 (across); the lower
  // index wins. Capture 1's three are 0, 2 (10 m) and 3 (20 m), not 6 across (30 m).
  const Pairs p3 = msgs::io::neighbour_pairs(images, pos, 3);
  const std::set<std::pair<std::size_t, std::size_t>> s3(p3.begin(), p3.end());
  CHECK(s3.count({0, 3}));
  CHECK(!s3.count({1, 6}));
  // Four nearest reach across the grid everywhere: every capture is paired with the one facing it.
  const Pairs p4 = msgs::io::neighbour_pairs(images, pos, 4);
  const std::set<std::pair<std::size_t, std::size_t>> s4(p4.begin(), p4.end());
  for (std::size_t i = 0; i < 4; ++i) CHECK_MESSAGE(s4.count({i, 7 - i}), i);
  // Pairs are ascending and unique, and k past the flight is every pair.
  CHECK(std::is_sorted(p4.begin(), p4.end()));
  CHECK(s4.size() == p4.size());
  CHECK(msgs::io::neighbour_pairs(images, pos, 100).size() == msgs::io::exhaustive_pair_count(8));
  // With several bands: within a capture every pair, across linked captures the same band only.
  const auto two = flight(8, {"D", "MS_NIR"});
  const Pairs b = msgs::io::neighbour_pairs(two, pos, 2);
  for (const auto& [i, j] : b) CHECK((two[i].capture == two[j].capture || two[i].band == two[j].band));
  CHECK(b.size() == 8 + 2 * p2.size());
}

TEST_CASE("local_metres and local_to_gps: degrees to metres east, north and up, and back") {
  const auto o = msgs::io::local_metres({51.98, 5.66, 20.0}, 51.98, 5.66);
  CHECK(o[0] == 0.0);
  CHECK(o[1] == 0.0);
  CHECK(o[2] == 20.0);
  const auto n = msgs::io::local_metres({51.981, 5.66, 20.0}, 51.98, 5.66);
  CHECK(n[1] == doctest::Approx(111.195).epsilon(1e-4));  // a thousandth of a degree of latitude
  const auto e = msgs::io::local_metres({51.98, 5.661, 20.0}, 51.98, 5.66);
  CHECK(e[0] == doctest::Approx(111.195 * std::cos(51.98 * 3.14159265358979323846 / 180.0)).epsilon(1e-4));
  // local_to_gps takes it back.
  const std::array<double, 3> enu = {-1234.5, 678.25, 42.0};
  const auto back = msgs::io::local_metres(msgs::io::local_to_gps(enu, -33.9, 151.2), -33.9, 151.2);
  for (int i = 0; i < 3; ++i) CHECK(back[std::size_t(i)] == doctest::Approx(enu[std::size_t(i)]).epsilon(1e-9));
}

}  // namespace test_match_pairs
