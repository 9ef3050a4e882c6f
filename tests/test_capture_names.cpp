// tests/test_capture_names.cpp
// Tests for include/msgs/io/capture_names.hpp: the MicaSense, DJI and Sequoia naming schemes,
// explicit --bands patterns, auto-detection, grouping into captures, junk names and clear refusals.
#include <doctest/doctest.h>

#include <msgs/io/capture_names.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace test_capture_names {
namespace fs = std::filesystem;
using namespace msgs::io;

TEST_CASE("capture names: MicaSense RedEdge band order, blue and thermal have no slot") {
  const std::pair<const char*, const char*> want[] = {
      {"IMG_0001_1.tif", ""}, {"IMG_0001_2.tif", "MS_G"}, {"IMG_0001_3.tif", "MS_R"},
      {"IMG_0001_4.tif", "MS_NIR"}, {"IMG_0001_5.tif", "MS_RE"}, {"img_0001_5.TIF", "MS_RE"}};
  for (const auto& [name, band] : want) {
    const auto m = match_camera_name("micasense", name);
    REQUIRE(m);
    CHECK(m->band == band);
    CHECK(m->capture == "IMG_0001");
  }
  CHECK(match_camera_name("micasense", "IMG_0001_1.tif")->camera_band == "Blue");
  CHECK(match_camera_name("micasense", "IMG_0001_6.tif")->band.empty());  // Altum thermal / Dual second camera
  CHECK(match_camera_name("micasense", "IMG_0001_6.tif")->camera_band.find("band 6") == 0);
  CHECK(match_camera_name("micasense", "IMG_12345_2.tif")->capture == "IMG_12345");
  for (const char* junk : {"IMG_0001_0.tif", "IMG_0001_11.tif", "IMG_001_2.tif", "IMG_0001_2.jpg", "IMG_0001_2",
                           "IMG_0001__2.tif", "IMG_00a1_2.tif", "DJI_0001_2.tif", "", ".", "IMG_0001_2.tif.bak"})
    CHECK_MESSAGE(!match_camera_name("micasense", junk), junk);
}

TEST_CASE("capture names: DJI Mavic 3M and Parrot Sequoia") {
  const auto g = match_camera_name("dji", "DJI_20240601100002_0002_MS_G.TIF");
  REQUIRE(g);
  CHECK(g->band == "MS_G");
  CHECK(g->capture == "0002");
  CHECK(match_camera_name("dji", "DJI_20240601100002_0002_MS_NIR.TIF")->band == "MS_NIR");
  CHECK(match_camera_name("dji", "DJI_20240601100002_0002_MS_RE.tif")->band == "MS_RE");
  CHECK(match_camera_name("dji", "DJI_20240601100002_0002_D.JPG")->band == "D");
  CHECK(match_camera_name("dji", "DJI_20240601100002_0002_T.JPG")->band.empty());  // thermal: skipped
  for (const char* junk : {"DJI_2024060110000_0002_MS_G.TIF", "DJI_20240601100002_002_MS_G.TIF",
                           "DJI_20240601100002_0002_MS_X.TIF", "DJI_20240601100002_0002.TIF", "DJI_0002.JPG",
                           "DJI_20240601100002_0002_MS_G.png"})
    CHECK_MESSAGE(!match_camera_name("dji", junk), junk);

  // P4 Multispectral: a run of ten numbers per capture, the last digit the band.
  const auto p = match_camera_name("p4m", "DJI_0123.TIF");
  REQUIRE(p);
  CHECK(p->band == "MS_R");
  CHECK(p->capture == "DJI_012");
  CHECK(match_camera_name("p4m", "DJI_0120.JPG")->band == "D");
  CHECK(match_camera_name("p4m", "dji_0125.tif")->band == "MS_NIR");
  CHECK(match_camera_name("p4m", "DJI_0124.TIF")->band == "MS_RE");
  CHECK(match_camera_name("p4m", "DJI_0121.TIF")->band.empty());  // blue: skipped
  CHECK(match_camera_name("p4m", "DJI_0121.TIF")->camera_band == "Blue");
  for (const char* junk : {"DJI_0126.TIF", "DJI_0120.TIF", "DJI_0123.JPG", "DJI_012.TIF", "DJI_01230.TIF", "DJI_01a3.TIF",
                           "DJI_20240601100002_0002_MS_G.TIF", "IMG_0123.TIF", "DJI_0123.png"})
    CHECK_MESSAGE(!match_camera_name("p4m", junk), junk);
  CHECK(!match_camera_name("dji", "DJI_0123.TIF"));

  const auto s = match_camera_name("sequoia", "IMG_240601_100004_0003_REG.TIF");
  REQUIRE(s);
  CHECK(s->band == "MS_RE");
  CHECK(s->capture == "0003");
  CHECK(match_camera_name("sequoia", "IMG_240601_100004_0003_GRE.TIF")->band == "MS_G");
  CHECK(match_camera_name("sequoia", "IMG_240601_100004_0003_RED.TIF")->band == "MS_R");
  CHECK(match_camera_name("sequoia", "IMG_240601_100004_0003_NIR.TIF")->band == "MS_NIR");
  CHECK(match_camera_name("sequoia", "IMG_240601_100004_0003_RGB.JPG")->band == "D");
  CHECK(!match_camera_name("sequoia", "IMG_240601_100004_0003_BLU.TIF"));
  CHECK(!match_camera_name("sequoia", "IMG_0001_2.tif"));
  CHECK_THROWS_AS(match_camera_name("nikon", "x.tif"), std::invalid_argument);
}

TEST_CASE("capture names: glob patterns, groups and pathological inputs") {
  std::vector<std::string> g;
  CHECK(glob_match("IMG_*_2.tif", "img_0007_2.TIF", &g));
  REQUIRE(g.size() == 1);
  CHECK(g[0] == "0007");
  CHECK(glob_match("a?c*", "abcdef", &g));
  CHECK(g == std::vector<std::string>{"b", "def"});
  CHECK(!glob_match("IMG_*_2.tif", "IMG_0007_3.tif"));
  CHECK(glob_match("*", ""));
  CHECK(!glob_match("?", ""));
  // Many stars against a long non-matching name: quadratic, not exponential.
  const std::string name(4000, 'a');
  CHECK(!glob_match("*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*b", name));
  CHECK(!glob_match(std::string(600, '*'), "x"));  // over-long pattern: no match, no blow-up

  const auto p = parse_band_patterns("IMG_*_2.tif=MS_G,IMG_*_3.tif=MS_R,,IMG_*_1.tif=skip");
  REQUIRE(p.size() == 3);
  CHECK(p[2].band.empty());
  const auto m = match_patterns(p, "IMG_0042_3.tif");
  REQUIRE(m);
  CHECK(m->band == "MS_R");
  CHECK(m->capture == "0042");
  CHECK(match_patterns(p, "IMG_0042_1.tif")->band.empty());
  CHECK(!match_patterns(p, "IMG_0042_4.tif"));

  CHECK_THROWS_WITH_AS(parse_band_patterns("IMG_0001_2.tif=MS_G"), doctest::Contains("no * or ?"), std::invalid_argument);
  CHECK_THROWS_WITH_AS(parse_band_patterns("IMG_*_2.tif=BLUE"), doctest::Contains("unknown band 'BLUE'"), std::invalid_argument);
  CHECK_THROWS_WITH_AS(parse_band_patterns("IMG_*_2.tif"), doctest::Contains("is not PATTERN=ID"), std::invalid_argument);
  CHECK_THROWS_WITH_AS(parse_band_patterns("=MS_G"), doctest::Contains("is not PATTERN=ID"), std::invalid_argument);
  CHECK_THROWS_WITH_AS(parse_band_patterns("a/*.tif=MS_G"), doctest::Contains("folder separator"), std::invalid_argument);
  CHECK_THROWS_AS(parse_band_patterns(",,"), std::invalid_argument);
}

TEST_CASE("capture names: scanning a folder listing groups captures and refuses clearly") {
  std::vector<fs::path> files;
  for (int c = 1; c <= 3; ++c)
    for (int b = 1; b <= 5; ++b) files.emplace_back("flight/IMG_000" + std::to_string(c) + "_" + std::to_string(b) + ".tif");
  files.emplace_back("flight/notes.txt");
  files.emplace_back("other/IMG_0001_2.tif");  // same capture number in another folder: another capture
  const CaptureScan s = scan_capture_names("/data", files, "auto");
  CHECK(s.camera == "micasense");
  REQUIRE(s.captures.size() == 4);
  CHECK(s.captures[0].key == "flight/IMG_0001");
  CHECK(s.captures[0].bands.size() == 4);
  CHECK(s.captures[0].bands.at("MS_NIR") == fs::path("flight/IMG_0001_4.tif"));
  CHECK(s.captures[3].key == "other/IMG_0001");
  CHECK(s.skipped.at("Blue").size() == 3);
  REQUIRE(s.unmatched.size() == 1);
  CHECK(s.band_counts().at("MS_G") == 4);

  // DJI names are recognised by auto too; explicit patterns override the camera.
  const CaptureScan d = scan_capture_names("/d", {"DJI_20240601100000_0001_MS_G.TIF", "DJI_20240601100000_0001_D.JPG"}, "auto");
  CHECK(d.camera == "dji");
  CHECK(d.captures.size() == 1);
  const CaptureScan p4 = scan_capture_names("/p", {"DJI_0010.JPG", "DJI_0011.TIF", "DJI_0012.TIF", "DJI_0013.TIF",
                                                   "DJI_0014.TIF", "DJI_0015.TIF", "DJI_0022.TIF"}, "auto");
  CHECK(p4.camera == "p4m");
  REQUIRE(p4.captures.size() == 2);
  CHECK(p4.captures[0].bands.size() == 5);
  CHECK(p4.captures[1].bands.at("MS_G") == fs::path("DJI_0022.TIF"));
  CHECK(p4.skipped.at("Blue").size() == 1);
  const CaptureScan e = scan_capture_names("/e", {"a_1_g.tif", "a_1_r.tif", "a_2_g.tif"}, "auto",
                                           parse_band_patterns("a_*_g.tif=MS_G,a_*_r.tif=MS_R"));
  CHECK(e.camera == "patterns");
  REQUIRE(e.captures.size() == 2);
  CHECK(e.captures[0].bands.size() == 2);

  // Nothing recognised: the message names the folder, the patterns tried and some files.
  CHECK_THROWS_WITH_AS(scan_capture_names("/junk", {"a.txt", "b.png"}, "auto"),
                       doctest::Contains("MicaSense RedEdge/Altum: IMG_<nnnn>"), IoError);
  CHECK_THROWS_WITH_AS(scan_capture_names("/junk", {"a.txt", "b.png"}, "auto"), doctest::Contains("a.txt, b.png"), IoError);
  CHECK_THROWS_WITH_AS(scan_capture_names("/junk", {}, "dji"), doctest::Contains("among 0 files"), IoError);
  CHECK_THROWS_WITH_AS(scan_capture_names("/b", {"IMG_0001_1.tif"}, "micasense"),
                       doctest::Contains("only bands without a msgs slot: Blue"), IoError);
  // Two files claiming one band of one capture.
  CHECK_THROWS_WITH_AS(scan_capture_names("/dup", {"a_1_g.tif", "A_1_G.TIF"}, "auto", parse_band_patterns("a_*_g.tif=MS_G")),
                       doctest::Contains("two files for band MS_G"), IoError);
  CHECK_THROWS_AS(scan_capture_names("/x", {"a"}, "canon"), std::invalid_argument);
}

}  // namespace test_capture_names
