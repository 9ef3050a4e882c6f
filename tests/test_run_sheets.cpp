// tests/test_run_sheets.cpp
// Tests of EvalOptions::max_sheets (fewer sheets, metrics still over every eval frame) and of
// examples/run_sheets.hpp, the contact sheets `msgs train` and `msgs study` write per run.
#include <doctest/doctest.h>

#include "fixtures.hpp"

#include "../examples/run_sheets.hpp"

#include <msgs/init.hpp>
#include <msgs/io/file.hpp>
#include <msgs/render_util.hpp>

#include <algorithm>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

namespace test_run_sheets {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

using G7 = Gaussian<7, 0>;  // the only model type here: one Rasterizer instantiation

/// The tiny scene with its first three captures as eval frames (the scene has only one eval
/// capture of its own, and a limit on sheets needs several to cut).
const io::Dataset& tiny() {
  static const io::Dataset ds = [] {
    io::Dataset d = msgs::testing::tiny_scene("run_sheets", 5);
    std::vector<std::string> keys;
    for (io::Frame& f : d.frames) {
      const std::string key = capture_key(f.file_path);
      if (std::find(keys.begin(), keys.end(), key) == keys.end()) keys.push_back(key);
      if (std::find(keys.begin(), keys.end(), key) - keys.begin() < 3) f.split = io::Split::eval;
    }
    return d;
  }();
  return ds;
}

/// A fresh, empty directory.
fs::path fresh_dir(const std::string& name) {
  const fs::path d = msgs::testing::scratch_dir("run_sheets") / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

ChannelRenderer factory(std::shared_ptr<const LoadedModel> m) { return make_typed_renderer<G7>(std::move(m)); }

/// A Joint model initialised from the scene's points (no training), written once as a PLY.
const fs::path& joint_ply() {
  static const fs::path p = [] {
    InitConfig ic;
    ic.initial_opacity = 0.6;
    ic.seed = 11;
    const auto model = init_from_points<G7>(tiny().points.xyz, ic);
    const fs::path path = fresh_dir("model") / "model_joint.ply";
    io::write_ply(path, model, io::joint_channel_names());
    return path;
  }();
  return p;
}

const ModelSet& joint_models() {
  static const ModelSet s = ModelSet::load(joint_ply(), factory);
  return s;
}

/// Keys of the eval captures in the dataset's frame order (first appearance), computed here
/// from the file names rather than with group_captures.
std::vector<std::string> eval_capture_keys(const io::Dataset& ds) {
  std::vector<std::string> keys;
  for (const io::Frame& f : ds.frames) {
    if (f.split != io::Split::eval) continue;
    const std::string stem = fs::path(f.file_path).stem().string();
    const std::string key = stem.substr(stem.find_last_not_of("0123456789") + 1);
    if (std::find(keys.begin(), keys.end(), key) == keys.end()) keys.push_back(key);
  }
  return keys;
}

/// Names of the regular files and directories directly in `dir`.
std::set<std::string> entries(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
  return out;
}

RunResult joint_run() {
  RunResult r;
  r.strategy = "joint";
  r.models["joint"] = joint_ply();
  return r;
}

}  // namespace

TEST_CASE("evaluate_models: max_sheets limits the sheets to the first captures, metrics cover every frame") {
  const io::Dataset& ds = tiny();
  const std::vector<std::string> keys = eval_capture_keys(ds);
  REQUIRE(keys.size() >= 3);  // the limit must be able to cut something

  const fs::path all_dir = fresh_dir("eval_all");
  const EvalResult all = evaluate_models(ds, joint_models(), all_dir);  // default: every capture
  REQUIRE(all.files.size() == keys.size());
  std::size_t eval_frames = 0;
  for (const io::Frame& f : ds.frames) eval_frames += f.split == io::Split::eval;
  std::size_t counted = 0;
  for (const auto& m : all.metrics) counted += m.psnr.size();
  CHECK(counted == eval_frames);

  for (int k : {0, 1, 2, int(keys.size()) + 5}) {
    CAPTURE(k);
    const fs::path dir = fresh_dir("eval_" + std::to_string(k));
    EvalOptions opt;
    opt.max_sheets = k;
    const EvalResult res = evaluate_models(ds, joint_models(), dir, opt);
    const std::size_t want = std::min<std::size_t>(std::size_t(k), keys.size());
    REQUIRE(res.files.size() == want);
    CHECK(entries(dir).size() == want);  // nothing else (no temporaries) in the directory
    for (std::size_t i = 0; i < want; ++i) {
      CHECK(res.files[i] == "sheet_" + keys[i] + ".png");
      // The same sheet as with no limit, byte for byte.
      CHECK(io::read_bytes(dir / res.files[i]) == io::read_bytes(all_dir / res.files[i]));
    }
    // Metrics do not depend on the limit: every eval frame, the same values.
    REQUIRE(res.metrics.size() == all.metrics.size());
    for (std::size_t b = 0; b < res.metrics.size(); ++b) {
      CHECK(res.metrics[b].band == all.metrics[b].band);
      CHECK(res.metrics[b].psnr == all.metrics[b].psnr);
      CHECK(res.metrics[b].ssim == all.metrics[b].ssim);
      CHECK(res.frames[b] == all.frames[b]);
    }
  }

  EvalOptions bad;
  bad.max_sheets = -2;
  CHECK_THROWS_AS((void)evaluate_models(ds, joint_models(), fresh_dir("eval_bad"), bad), std::invalid_argument);
}

TEST_CASE("write_run_sheets: <run>/sheets with the first N captures, replaced whole, 0 = off") {
  const io::Dataset& ds = tiny();
  const std::vector<std::string> keys = eval_capture_keys(ds);
  REQUIRE(keys.size() >= 3);
  const fs::path run = fresh_dir("run");
  const std::string result_text = "{\"metrics\": \"from the trainer\"}\n";
  io::write_text_atomic(run / "result.json", result_text);

  SUBCASE("off, interrupted or bad arguments: nothing written") {
    cli::RunSheets s = cli::write_run_sheets(ds, joint_run(), run, 0, factory);
    CHECK(s.files.empty());
    CHECK(s.skipped == "off");
    RunResult stopped = joint_run();
    stopped.interrupted = true;
    s = cli::write_run_sheets(ds, stopped, run, 3, factory);
    CHECK(s.files.empty());
    CHECK(!s.skipped.empty());
    CHECK_THROWS_AS((void)cli::write_run_sheets(ds, joint_run(), run, -2, factory), std::invalid_argument);
    CHECK(entries(run) == std::set<std::string>{"result.json"});
  }

  SUBCASE("the default count, then fewer: the directory is replaced, nothing else changes") {
    REQUIRE(cli::default_run_sheets == 3);
    cli::RunSheets s = cli::write_run_sheets(ds, joint_run(), run, cli::default_run_sheets, factory);
    CHECK(s.skipped.empty());
    REQUIRE(s.files.size() == 3);
    std::set<std::string> want;
    for (std::size_t i = 0; i < 3; ++i) {
      CHECK(s.files[i] == "sheets/sheet_" + keys[i] + ".png");
      want.insert("sheet_" + keys[i] + ".png");
    }
    CHECK(entries(run / "sheets") == want);
    CHECK(entries(run) == std::set<std::string>{"result.json", "sheets"});  // no staging left behind
    CHECK(io::read_text(run / "result.json") == result_text);

    // The same image as `msgs eval` writes for that capture.
    const fs::path ref = fresh_dir("run_ref");
    (void)evaluate_models(ds, joint_models(), ref);
    CHECK(io::read_bytes(run / "sheets" / ("sheet_" + keys[0] + ".png")) ==
          io::read_bytes(ref / ("sheet_" + keys[0] + ".png")));

    s = cli::write_run_sheets(ds, joint_run(), run, 1, factory);
    REQUIRE(s.files.size() == 1);
    CHECK(entries(run / "sheets") == std::set<std::string>{"sheet_" + keys[0] + ".png"});
    CHECK(entries(run) == std::set<std::string>{"result.json", "sheets"});

    // 0 leaves existing sheets alone.
    s = cli::write_run_sheets(ds, joint_run(), run, 0, factory);
    CHECK(entries(run / "sheets") == std::set<std::string>{"sheet_" + keys[0] + ".png"});
  }

  SUBCASE("a model that cannot be read: an error naming it, the previous sheets kept") {
    (void)cli::write_run_sheets(ds, joint_run(), run, 2, factory);
    const std::set<std::string> before = entries(run / "sheets");
    REQUIRE(before.size() == 2);
    RunResult broken = joint_run();
    broken.models["joint"] = run / "model_missing.ply";
    CHECK_THROWS_WITH_AS((void)cli::write_run_sheets(ds, broken, run, 3, factory),
                         doctest::Contains("model_missing.ply"), io::IoError);
    CHECK(entries(run / "sheets") == before);
    CHECK(entries(run) == std::set<std::string>{"result.json", "sheets"});
  }
}

}  // namespace test_run_sheets
