// tests/test_view_browser.cpp
// The viewer page in a real browser: `msgs view` serves a Joint model of the tiny synthetic scene,
// headless Chromium opens a deep link to one dataset camera in one band (?frame=ID&mode=MS_NIR,
// PNG frames, the view as wide as the camera), and the screenshot must contain, somewhere, the
// image `msgs render` writes for that camera. The test finds the region itself (an exhaustive
// search over the screenshot), so it checks what a user sees, not how the page lays it out.
//
// Skips itself (a message and exit status 77, which ctest shows as "Skipped") when no Chromium is
// installed: apt-get install chromium, or point MSGS_CHROMIUM at a Chrome / Chromium binary.
#include <doctest/doctest.h>

#include "fixtures.hpp"
#include "msgs_process.hpp"

#include <msgs/gaussian.hpp>
#include <msgs/init.hpp>
#include <msgs/io/bands.hpp>
#include <msgs/io/image_io.hpp>
#include <msgs/io/ply.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace test_view_browser {
namespace fs = std::filesystem;

namespace {

/// The browser to drive: $MSGS_CHROMIUM, else the first of the usual names on PATH.
std::optional<fs::path> find_chromium() {
  if (const char* env = std::getenv("MSGS_CHROMIUM"); env && *env) {
    if (access(env, X_OK) == 0) return fs::path(env);
    return std::nullopt;
  }
  const char* path = std::getenv("PATH");
  if (!path) return std::nullopt;
  for (const char* name : {"chromium", "chromium-browser", "google-chrome", "google-chrome-stable"}) {
    std::stringstream dirs(path);
    std::string dir;
    while (std::getline(dirs, dir, ':'))
      if (!dir.empty() && access((fs::path(dir) / name).c_str(), X_OK) == 0) return fs::path(dir) / name;
  }
  return std::nullopt;
}

/// Where in `shot` (RGB or RGBA, values in [0, 1]) the grey image `ref` sits: the offset with
/// the smallest mean absolute difference over a fixed sample of pixels, then scored in full.
struct Match {
  int x = -1, y = -1;
  double mean = 1e9, worst = 1e9, within2 = 0;  // mean / largest |difference| in 8-bit steps; share <= 2 steps
};

Match locate(const msgs::Image<float>& shot, const msgs::Image<float>& ref) {
  const int C = shot.channels;
  auto at = [&](int x, int y, int c) { return shot.data[(std::size_t(y) * std::size_t(shot.width) + std::size_t(x)) * std::size_t(C) + std::size_t(c)]; };
  // A sample that spans the image: every 5th pixel of a coarse grid.
  std::vector<std::pair<int, int>> sample;
  for (int y = 0; y < ref.height; y += 3)
    for (int x = (y * 7) % 5; x < ref.width; x += 5) sample.emplace_back(x, y);
  Match best;
  double best_sum = std::numeric_limits<double>::max();
  for (int oy = 0; oy + ref.height <= shot.height; ++oy)
    for (int ox = 0; ox + ref.width <= shot.width; ++ox) {
      double s = 0;
      for (const auto& [x, y] : sample) {
        s += std::abs(double(at(ox + x, oy + y, 0)) - double(ref.data[std::size_t(y) * std::size_t(ref.width) + std::size_t(x)]));
        if (s >= best_sum) break;
      }
      if (s < best_sum) { best_sum = s; best.x = ox; best.y = oy; }
    }
  if (best.x < 0) return best;
  double sum = 0, worst = 0;
  std::size_t ok = 0;
  for (int y = 0; y < ref.height; ++y)
    for (int x = 0; x < ref.width; ++x)
      for (int c = 0; c < std::min(C, 3); ++c) {  // grey: R, G and B all equal the band
        const double d = 255.0 * std::abs(double(at(best.x + x, best.y + y, c)) -
                                           double(ref.data[std::size_t(y) * std::size_t(ref.width) + std::size_t(x)]));
        sum += d;
        worst = std::max(worst, d);
        ok += d <= 2.0 ? 1 : 0;
      }
  const double n = double(ref.pixels()) * double(std::min(C, 3));
  best.mean = sum / n;
  best.worst = worst;
  best.within2 = double(ok) / n;
  return best;
}

}  // namespace

TEST_CASE("browser: a deep link to a dataset camera and band shows what msgs render writes for it") {
  const std::optional<fs::path> chromium = find_chromium();
  if (!chromium) {
    // Exit status 77: ctest reports the test as skipped (SKIP_RETURN_CODE in tests/CMakeLists.txt).
    std::fprintf(stderr, "test_view_browser: SKIPPED: no Chromium found (apt-get install chromium, or set "
                         "MSGS_CHROMIUM to a Chrome binary)\n");
    std::exit(77);
  }
  const auto t_start = std::chrono::steady_clock::now();
  const msgs::io::Dataset& ds = msgs::testing::tiny_scene("view_browser", 6);
  const fs::path dir = msgs::testing::scratch_dir("view_browser");
  const fs::path model = dir / "model_joint.ply";
  {
    msgs::InitConfig cfg;
    cfg.initial_opacity = 0.95;  // nearly opaque: the front Gaussians' random colours show
    auto m = msgs::init_from_points<msgs::Gaussian<7, 1>>(ds.points.xyz, cfg);
    // Colours over the whole range (colour = 0.5 + 0.282 DC), so the picture has contrast.
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> dc(-1.7f, 1.7f);
    for (std::size_t i = 0; i < m.size(); ++i)
      for (int c = 0; c < 7; ++c) m.sh_at(i, 0, c) = dc(rng);
    msgs::io::write_ply(model, m, msgs::io::joint_channel_names());
  }
  // The reference: `msgs render` at every dataset camera.
  const fs::path out = dir / "rendered";
  fs::remove_all(out);
  const std::string render_cmd = std::string(MSGS_BIN) + " render --data '" + ds.root.string() + "' --model '" +
                                 model.string() + "' --out '" + out.string() + "' --no-composites > '" +
                                 (dir / "render.log").string() + "' 2>&1";
  REQUIRE(std::system(render_cmd.c_str()) == 0);

  msgs::testing::MsgsServer server("view", {"--model", model.string(), "--data", ds.root.string(), "--port", "0", "--quiet"},
                                   dir);
  for (const char* band : {"MS_NIR", "MS_RE"}) {
    CAPTURE(band);
    std::size_t id = 0;
    while (ds.frames[id].band != band) ++id;
    const msgs::Image<float> ref =
        msgs::io::read_image(out / (fs::path(ds.frames[id].file_path).stem().string() + ".png"));
    REQUIRE(ref.channels == 1);
    // Enough structure that only the right region matches.
    const auto [lo, hi] = std::minmax_element(ref.data.begin(), ref.data.end());
    REQUIRE(255.0f * (*hi - *lo) > 20.0f);
    const std::string url = "http://127.0.0.1:" + std::to_string(server.port()) + "/?frame=" + std::to_string(id) +
                            "&mode=" + band + "&size=" + std::to_string(ref.width) + "&bg=black&format=png";
    const fs::path shot = dir / (std::string("shot_") + band + ".png");
    fs::remove(shot);
    // A fresh profile each time; virtual time runs only while no request is pending, so the
    // budget is spent after the page's renders have arrived.
    const std::string cmd = "timeout 60 '" + chromium->string() +
                            "' --headless --no-sandbox --disable-gpu --hide-scrollbars --no-first-run"
                            " --force-device-scale-factor=1 --window-size=1000,700 --virtual-time-budget=10000"
                            " --user-data-dir='" + (dir / "profile").string() + "' --screenshot='" + shot.string() +
                            "' '" + url + "' > '" + (dir / "chromium.log").string() + "' 2>&1";
    fs::remove_all(dir / "profile");
    const int rc = std::system(cmd.c_str());
    REQUIRE_MESSAGE(rc == 0, "chromium failed: " << msgs::testing::slurp(dir / "chromium.log"));
    REQUIRE_MESSAGE(fs::exists(shot), "no screenshot: " << msgs::testing::slurp(dir / "chromium.log"));
    const msgs::Image<float> img = msgs::io::read_image(shot);
    REQUIRE(img.channels >= 3);
    CHECK(img.width == 1000);
    CHECK(img.height == 700);
    const Match m = locate(img, ref);
    MESSAGE(std::string(band) << " frame " << id << " (" << ref.width << "x" << ref.height << ", values over "
                              << 255.0f * (*hi - *lo) << " 8-bit steps) found at " << m.x << "," << m.y
                 << ": mean |difference| " << m.mean << ", largest " << m.worst << " 8-bit steps, "
                 << 100 * m.within2 << "% within 2");
    REQUIRE(m.x >= 0);
    // PNG frames are 8-bit, the reference 16-bit: half a step apart at most, plus the camera's
    // round trip through the page's JavaScript (a few edge pixels may move).
    CHECK(m.mean <= 0.75);
    CHECK(m.within2 >= 0.99);
    CHECK(m.worst <= 8.0);
  }
  CHECK(server.stop() == 0);
  MESSAGE("browser test: " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count()
                           << " s");
}

}  // namespace test_view_browser
