// tests/test_view_http.cpp
// `msgs view` over HTTP: starts the tool on a free port (--port 0) with a small Joint model of the
// tiny synthetic scene, sends a burst of bad requests (each must be a 4xx and the server must keep
// serving), then good ones: a render decodes to the requested size, and /api/frame's render of a
// dataset camera matches what `msgs render` writes for that camera. `msgs train --view`: the live
// viewer follows a Separate run model by model, ends on the models the run wrote, keeps serving
// after the run until Ctrl-C, and a second run on the same port fails before it trains.
#include <doctest/doctest.h>

#include "fixtures.hpp"
#include "msgs_process.hpp"

#include <msgs/gaussian.hpp>
#include <msgs/init.hpp>
#include <msgs/io/bands.hpp>
#include <msgs/io/image_io.hpp>
#include <msgs/io/ply.hpp>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

// After Eigen (via the msgs headers): httplib includes <resolv.h>, whose `_res` macro breaks Eigen.
#include <httplib.h>

namespace test_view_http {
namespace fs = std::filesystem;

namespace {

msgs::Image<float> decode(const std::string& bytes, const fs::path& p) {
  std::ofstream(p, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  return msgs::io::read_image(p);
}

std::string csv(const std::vector<float>& v) {
  std::string s;
  char buf[32];
  for (float x : v) {
    std::snprintf(buf, sizeof buf, "%.9g", double(x));
    if (!s.empty()) s += ',';
    s += buf;
  }
  return s;
}

}  // namespace

TEST_CASE("msgs view: bad requests are 4xx, renders decode at their size, frames match msgs render") {
  const msgs::io::Dataset& ds = msgs::testing::tiny_scene("view_http", 5);
  const fs::path dir = msgs::testing::scratch_dir("view_http");
  const fs::path model = dir / "model_joint.ply";
  {
    msgs::InitConfig cfg;
    cfg.initial_opacity = 0.5;
    const auto m = msgs::init_from_points<msgs::Gaussian<7, 1>>(ds.points.xyz, cfg);
    msgs::io::write_ply(model, m, msgs::io::joint_channel_names());
  }
  msgs::testing::MsgsServer server("view", {"--model", model.string(), "--data", ds.root.string(), "--port", "0"}, dir);
  httplib::Client cli("127.0.0.1", server.port());
  cli.set_read_timeout(30, 0);

  // A valid camera: dataset frame 1 as R, t.
  const msgs::Camera<float>& c1 = ds.frames[1].camera;
  std::vector<float> R, t;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) R.push_back(c1.R(r, k));
  for (int r = 0; r < 3; ++r) t.push_back(c1.t(r));
  const std::string pose = "R=" + csv(R) + "&t=" + csv(t);
  const std::string ok = "/api/render?width=80&height=60&fovy=60&" + pose;

  SUBCASE("a burst of bad requests: each a 4xx, the server keeps serving") {
    const std::string nan_fx = "/api/render?width=80&height=60&fx=nan&" + pose;
    const std::vector<std::string> bad = {
        "/../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/etc/passwd", "/index.html", "/api", "/api/",
        "/api/render", "/api/render?width=80", ok + "&mode=bogus", ok + "&mode=",
        ok + "&width=90",  // httplib folds identical repeats; a different value is a 400
        ok + "&foo=1", nan_fx, "/api/render?width=80&height=60&fx=inf&" + pose,
        "/api/render?width=80&height=60&fx=1e999&" + pose, "/api/render?width=0&height=60&fovy=60&" + pose,
        "/api/render?width=100000&height=60&fovy=60&" + pose, "/api/render?width=4096&height=4096&fovy=60&" + pose,
        "/api/render?width=-1&height=60&fovy=60&" + pose, "/api/render?width=80&height=60&fovy=60&R=1,2,3&t=0,0,0",
        "/api/render?width=80&height=60&fovy=60&R=1,0,0,0,1,0,0,0,-1&t=0,0,0",
        "/api/render?width=80&height=60&fovy=60&R=" + csv(R) + "&t=0,0",
        "/api/render?width=80&height=60&fovy=60&eye=0,0,0&target=0,0,0", ok + "&bg=7", ok + "&gain=0",
        ok + "&format=gif", ok + "&quality=101", "/api/frame", "/api/frame?id=99999", "/api/frame?id=-1",
        "/api/frame?id=abc", "/api/frame?id=1&what=all", "/api/frame?id=1&scale=0", "/api/frame?id=1&mode=xyz",
        "/api/info?x=1", "/api/render?" + std::string(5000, 'a'), "/api/render?width=80&height=60&fovy=60&R=" +
        std::string(3000, '1') + "&t=0,0,0"};
    for (int round = 0; round < 2; ++round)
      for (const auto& path : bad) {
        const std::string shown = path.size() > 200 ? path.substr(0, 60) + "..." + path.substr(path.size() - 60) : path;
        CAPTURE(shown);
        const auto res = cli.Get(path.c_str());
        REQUIRE(res);
        CHECK(res->status >= 400);
        CHECK(res->status < 500);
      }
    const auto post = cli.Post("/api/render", "x", "text/plain");
    REQUIRE(post);
    CHECK(post->status == 405);
    httplib::Headers evil = {{"Host", "evil.example:80"}};
    const auto rebound = cli.Get("/", evil);
    REQUIRE(rebound);
    CHECK(rebound->status == 403);
    // Errors are JSON with a message.
    const auto e = cli.Get((ok + "&mode=bogus").c_str());
    REQUIRE(e);
    CHECK(nlohmann::json::parse(e->body)["error"].get<std::string>().find("unknown mode") != std::string::npos);
    // Still serving.
    const auto good = cli.Get(ok.c_str());
    REQUIRE(good);
    CHECK(good->status == 200);
  }

  SUBCASE("info, page and renders in every mode") {
    const auto page = cli.Get("/");
    REQUIRE(page);
    CHECK(page->status == 200);
    CHECK(page->body.find("/api/render") != std::string::npos);
    CHECK(page->get_header_value("Content-Security-Policy").find("default-src 'none'") != std::string::npos);
    const auto info = cli.Get("/api/info");
    REQUIRE(info);
    const nlohmann::json j = nlohmann::json::parse(info->body);
    CHECK(j["gaussians"].get<std::size_t>() == ds.points.xyz.size() / 3);
    CHECK(j["cameras"].size() == ds.frames.size());
    for (const char* mode : {"D", "MS_NIR", "rgb", "cir", "ndvi", "ndre", "gndvi", "ndwi", "savi"}) {
      CAPTURE(mode);
      for (const char* format : {"png", "jpeg"}) {
        const auto res = cli.Get((ok + "&mode=" + mode + "&format=" + format).c_str());
        REQUIRE(res);
        REQUIRE(res->status == 200);
        CHECK(res->get_header_value("Content-Type") == std::string("image/") + format);
        CHECK(std::isfinite(std::stod(res->get_header_value("X-Render-Ms"))));
        const msgs::Image<float> img = decode(res->body, dir / (std::string("r.") + format));
        CHECK(img.width == 80);
        CHECK(img.height == 60);
      }
    }
  }

  SUBCASE("/api/frame render equals msgs render at that camera; ground truth and error come with PSNR") {
    const fs::path out = dir / "rendered";
    fs::remove_all(out);
    const std::string cmd = std::string(MSGS_BIN) + " render --data '" + ds.root.string() + "' --model '" +
                            model.string() + "' --out '" + out.string() + "' --no-composites > '" +
                            (dir / "render.log").string() + "' 2>&1";
    REQUIRE(std::system(cmd.c_str()) == 0);
    for (const char* band : {"D", "MS_NIR"}) {
      CAPTURE(band);
      std::size_t id = 0;
      while (ds.frames[id].band != band) ++id;
      const std::string q = "/api/frame?id=" + std::to_string(id) + "&bg=black&scale=1&format=png";
      const auto res = cli.Get((q + "&what=render").c_str());
      REQUIRE(res);
      REQUIRE(res->status == 200);
      const msgs::Image<float> mine = decode(res->body, dir / "frame.png");
      const fs::path ref_file = out / (fs::path(ds.frames[id].file_path).stem().string() + ".png");
      const msgs::Image<float> ref = msgs::io::read_image(ref_file);
      REQUIRE(mine.width == ref.width);
      REQUIRE(mine.height == ref.height);
      REQUIRE(mine.channels == ref.channels);
      // 8-bit here, 8-bit (RGB) or 16-bit (single bands) there: at most one 8-bit step apart.
      float worst = 0;
      for (std::size_t i = 0; i < mine.data.size(); ++i) worst = std::max(worst, std::abs(mine.data[i] - ref.data[i]));
      CHECK(worst <= 1.01f / 255.0f);
      const double psnr = std::stod(res->get_header_value("X-PSNR"));
      CHECK(std::isfinite(psnr));

      const auto gt = cli.Get((q + "&what=gt").c_str());
      REQUIRE(gt);
      REQUIRE(gt->status == 200);
      const msgs::Image<float> g = decode(gt->body, dir / "gt.png");
      const msgs::Image<float> truth = msgs::io::load_frame_image(ds, ds.frames[id], 1);
      REQUIRE(g.data.size() == truth.data.size());
      for (std::size_t i = 0; i < g.data.size(); i += 7) CHECK(std::abs(g.data[i] - truth.data[i]) <= 0.51f / 255.0f);
      const auto err = cli.Get((q + "&what=error").c_str());
      REQUIRE(err);
      REQUIRE(err->status == 200);
      CHECK(decode(err->body, dir / "err.png").channels == 3);
      CHECK(std::stod(err->get_header_value("X-PSNR")) == psnr);
    }
    // An index at a multispectral camera: the mean index difference instead of a PSNR.
    std::size_t nir = 0;
    while (ds.frames[nir].band != "MS_NIR") ++nir;
    const auto idx = cli.Get(("/api/frame?id=" + std::to_string(nir) + "&mode=ndvi&what=error").c_str());
    REQUIRE(idx);
    CHECK(idx->status == 200);
    CHECK(std::stod(idx->get_header_value("X-MAE")) >= 0.0);
  }

  SUBCASE("a second server on the same port fails instead of sharing it") {
    const std::string cmd = "timeout 30 " + std::string(MSGS_BIN) + " view --model '" + model.string() +
                            "' --port " + std::to_string(server.port()) + " > '" + (dir / "second.log").string() +
                            "' 2>&1";
    const int rc = std::system(cmd.c_str());
    CHECK(WIFEXITED(rc));
    CHECK(WEXITSTATUS(rc) == 1);
    CHECK(msgs::testing::slurp(dir / "second.log").find("cannot listen") != std::string::npos);
    const auto still = cli.Get("/api/info");
    REQUIRE(still);
    CHECK(still->status == 200);
  }

  CHECK(server.stop() == 0);  // SIGTERM shuts down cleanly
}

TEST_CASE("msgs train --view: live snapshots of every band model, served until Ctrl-C after the run") {
  const msgs::io::Dataset& ds = msgs::testing::tiny_scene("view_http", 5);
  const fs::path dir = msgs::testing::scratch_dir("view_http_live");
  const fs::path run = dir / "run";
  fs::remove_all(run);
  // Separate: five band models one after the other, 60 steps each.
  msgs::testing::MsgsServer server("train", {"--data", ds.root.string(), "--out", run.string(), "--strategy", "separate",
                                             "--scale", "0.002", "--sheets", "0", "--quiet", "--view", "0"},
                                   dir, 120);
  httplib::Client cli("127.0.0.1", server.port());
  cli.set_read_timeout(30, 0);

  // Follow the run: snapshot versions only grow, band models appear one by one.
  std::uint64_t last_version = 0;
  std::size_t most_models = 0;
  nlohmann::json live;
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(120)) {
    const auto r = cli.Get("/api/live");
    REQUIRE(r);
    REQUIRE(r->status == 200);
    live = nlohmann::json::parse(r->body);
    const auto v = live["version"].get<std::uint64_t>();
    CHECK(v >= last_version);
    last_version = v;
    most_models = std::max(most_models, live["models"].size());
    if (v == 0) {
      const auto info = cli.Get("/api/info");  // nothing to show yet: 503, not an error page
      REQUIRE(info);
      CHECK((info->status == 503 || info->status == 200));
    }
    if (live["state"] != "training") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  REQUIRE(live["state"] == "done");
  MESSAGE("followed the run to snapshot " << last_version << "; at most " << most_models << " models while polling");
  CHECK(live["strategy"] == "separate");
  CHECK(live["expected_models"] == 5);
  REQUIRE(live["models"].size() == 5);
  std::size_t gaussians = 0;
  for (const auto& m : live["models"]) {
    CHECK(m["step"] == m["end"]);
    gaussians += m["gaussians"].get<std::size_t>();
  }
  const std::string out = server.out();
  CHECK(out.find("training done; viewer still at http://127.0.0.1:") != std::string::npos);
  CHECK(fs::exists(run / "result.json"));

  // The page sees the live run; the last snapshots are the models the run wrote: a frame renders
  // as `msgs render` renders the written PLYs.
  const auto info = cli.Get("/api/info");
  REQUIRE(info);
  REQUIRE(info->status == 200);
  const nlohmann::json j = nlohmann::json::parse(info->body);
  CHECK(j.contains("live"));
  CHECK(j["gaussians"].get<std::size_t>() == gaussians);
  const fs::path rendered = dir / "rendered";
  fs::remove_all(rendered);
  const std::string cmd = std::string(MSGS_BIN) + " render --data '" + ds.root.string() + "' --model '" + run.string() +
                          "' --out '" + rendered.string() + "' --no-composites > '" + (dir / "render.log").string() +
                          "' 2>&1";
  REQUIRE(std::system(cmd.c_str()) == 0);
  for (const char* band : {"D", "MS_NIR"}) {
    CAPTURE(band);
    std::size_t id = 0;
    while (ds.frames[id].band != band) ++id;
    const auto res = cli.Get(("/api/frame?id=" + std::to_string(id) + "&bg=black&scale=1&format=png").c_str());
    REQUIRE(res);
    REQUIRE(res->status == 200);
    const msgs::Image<float> mine = decode(res->body, dir / "frame.png");
    const msgs::Image<float> ref =
        msgs::io::read_image(rendered / (fs::path(ds.frames[id].file_path).stem().string() + ".png"));
    REQUIRE(mine.data.size() == ref.data.size());
    float worst = 0;
    for (std::size_t i = 0; i < mine.data.size(); ++i) worst = std::max(worst, std::abs(mine.data[i] - ref.data[i]));
    CHECK(worst <= 1.01f / 255.0f);
  }

  // Another run asking for the same port fails before it trains (no output directory).
  const fs::path run2 = dir / "run2";
  fs::remove_all(run2);
  const std::string busy = "timeout 60 " + std::string(MSGS_BIN) + " train --data '" + ds.root.string() + "' --out '" +
                           run2.string() + "' --strategy separate --scale 0.002 --view " +
                           std::to_string(server.port()) + " > '" + (dir / "busy.log").string() + "' 2>&1";
  const int rc = std::system(busy.c_str());
  CHECK(WIFEXITED(rc));
  CHECK(WEXITSTATUS(rc) != 0);
  CHECK(msgs::testing::slurp(dir / "busy.log").find("cannot listen") != std::string::npos);
  CHECK_FALSE(fs::exists(run2 / "result.json"));

  CHECK(server.stop(SIGINT) == 0);  // Ctrl-C ends the viewer after a finished run
}

}  // namespace test_view_http
