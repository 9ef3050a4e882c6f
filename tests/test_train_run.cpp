// tests/test_train_run.cpp
// Tests of run_experiment on the synthetic `tiny` scene at very small schedule scales: Separate
// trains one model per band with the right channel count, Split hands the RGB model's geometry
// over to the band models exactly, Joint trains one 7-channel model.
#include <doctest/doctest.h>

#include "fixtures.hpp"

#include <msgs/run.hpp>
#include <msgs/synth.hpp>

#include "run_experiment_sh0.hpp"  // run_experiment<0>, compiled once for the tests that run it

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

namespace test_train_run {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

// SH degree 0 throughout: run_experiment<0> instantiates the <7>, <3> and <1> trainers once.
constexpr int kDeg = 0;

fs::path scratch_dir() { return msgs::testing::scratch_dir("train_run"); }

/// The tiny synthetic scene, generated once per process.
const io::Dataset& tiny() { return msgs::testing::tiny_scene("train_run", 3); }

/// A fresh, empty output directory.
fs::path out_dir(const std::string& name) {
  const fs::path d = scratch_dir() / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

RunConfig config(const std::string& strategy, double scale) {
  RunConfig cfg;
  cfg.strategy = strategy;
  cfg.scale = scale;
  cfg.train.check_finite = true;
  return cfg;
}

template <int B>
void check_same_geometry(const GaussianModel<Gaussian<B, kDeg>, float>& m, const GaussianModel<Gaussian<3, kDeg>, float>& rgb) {
  REQUIRE(m.size() == rgb.size());
  CHECK(m.means == rgb.means);
  CHECK(m.log_scales == rgb.log_scales);
  CHECK(m.quats == rgb.quats);
  CHECK(m.opacity_logits == rgb.opacity_logits);
}

}  // namespace

TEST_CASE("Separate: one model per band, <3> for D and <1> for each narrow band") {
  const fs::path out = out_dir("separate");
  const RunConfig cfg = config("separate", 0.001);  // 30 steps per band
  const RunResult res = run_experiment<kDeg>(tiny(), cfg, out);
  CHECK(res.strategy == "separate");
  CHECK(res.plan.kind == StrategyKind::Separate);
  CHECK(res.plan.stage_steps == 30);
  CHECK_FALSE(res.interrupted);
  CHECK(res.steps == 5 * 30);
  CHECK(res.steps == res.plan.total_steps(4));
  const std::vector<std::string> bands = {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  REQUIRE(res.metrics.size() == 5);
  for (std::size_t b = 0; b < 5; ++b) {
    CAPTURE(bands[b]);
    CHECK(res.metrics[b].band == bands[b]);
    REQUIRE(res.metrics[b].psnr.size() == 1);  // one eval capture in tiny
    CHECK(std::isfinite(res.metrics[b].psnr[0]));
    REQUIRE(res.gaussians.count(bands[b]) == 1);
    CHECK(res.gaussians.at(bands[b]) > 0);
    REQUIRE(res.models.count(bands[b]) == 1);
    const io::PlyInfo info = io::inspect_ply(res.models.at(bands[b]));
    CHECK(info.gaussian);
    CHECK(info.sh_degree == kDeg);
    CHECK(info.vertices == res.gaussians.at(bands[b]));
    if (bands[b] == "D") {
      CHECK(info.channels == 3);
      CHECK(info.band_names == std::vector<std::string>{"D_R", "D_G", "D_B"});
    } else {
      CHECK(info.channels == 1);
      CHECK(info.band_names == std::vector<std::string>{bands[b]});
    }
  }
  CHECK(res.gaussians.size() == 5);
  CHECK(res.gaussians.count("joint") == 0);
}

TEST_CASE("Separate: a band subset trains only those bands") {
  RunConfig cfg = config("separate", 0.001);
  cfg.bands = {"MS_NIR"};
  const RunResult res = run_experiment<kDeg>(tiny(), cfg);  // no output directory: no files
  REQUIRE(res.metrics.size() == 1);
  CHECK(res.metrics[0].band == "MS_NIR");
  CHECK(res.gaussians.size() == 1);
  CHECK(res.models.empty());
  CHECK(res.steps == 30);
  cfg.bands = {"MS_XX"};
  CHECK_THROWS_AS(run_experiment<kDeg>(tiny(), cfg), std::invalid_argument);
}

TEST_CASE("Split: the band models start from the RGB model's exact geometry with fresh colour") {
  // Stop the run right at the stage boundary: stage 1 completes, each band model is made from the
  // RGB model and written before its first step (an interrupted run still writes its models).
  const fs::path out = out_dir("split_boundary");
  RunConfig cfg = config("split", 0.002);  // 60 + 60 steps
  cfg.bands = {"D", "MS_NIR"};  // the stop also skips any later band model
  std::atomic<bool> stop{false};
  cfg.train.stop = &stop;
  cfg.train.progress_every = 1;
  cfg.train.on_progress = [&](const TrainProgress& pr) {
    if (pr.step == 60) stop = true;
  };
  const RunResult res = run_experiment<kDeg>(tiny(), cfg, out);
  REQUIRE(res.plan.stage_steps == 60);
  CHECK(res.interrupted);
  CHECK(res.steps == 60);
  REQUIRE(res.models.count("D") == 1);
  REQUIRE(res.models.count("MS_NIR") == 1);

  const auto rgb = io::read_ply<Gaussian<3, kDeg>>(res.models.at("D"));
  CHECK(rgb.size() == res.gaussians.at("D"));
  const auto nir = io::read_ply<Gaussian<1, kDeg>>(res.models.at("MS_NIR"));
  check_same_geometry<1>(nir, rgb);
  // Fresh colour: SH DC uniform in [0, 1), not a channel of the RGB model.
  double mean = 0;
  std::size_t outside = 0, same_as_rgb = 0;
  for (std::size_t i = 0; i < nir.size(); ++i) {
    const float v = nir.sh_at(i, 0, 0);
    outside += !(v >= 0.0f && v < 1.0f);
    same_as_rgb += v == rgb.sh_at(i, 0, 0);
    mean += v;
  }
  CHECK(outside == 0);
  CHECK(same_as_rgb < nir.size() / 100);
  CHECK(mean / double(nir.size()) == doctest::Approx(0.5).epsilon(0.1));
}

TEST_CASE("Split: copy_geometry copies means, scales, rotations and opacities and nothing else") {
  GaussianModel<Gaussian<3, 1>, float> from(4);
  for (std::size_t i = 0; i < from.means.size(); ++i) from.means[i] = 0.1f * float(i) - 0.3f;
  for (std::size_t i = 0; i < from.log_scales.size(); ++i) from.log_scales[i] = -2.0f - 0.01f * float(i);
  for (std::size_t i = 0; i < from.quats.size(); ++i) from.quats[i] = 0.5f + 0.125f * float(i);
  for (std::size_t i = 0; i < from.opacity_logits.size(); ++i) from.opacity_logits[i] = float(i) - 1.5f;
  for (float& v : from.sh) v = 7.0f;
  GaussianModel<Gaussian<1, 1>, float> to(2);
  for (float& v : to.sh) v = -1.0f;
  detail::copy_geometry(from, to);
  REQUIRE(to.size() == 4);
  CHECK_NOTHROW(to.check_consistent());
  CHECK(to.means == from.means);
  CHECK(to.log_scales == from.log_scales);
  CHECK(to.quats == from.quats);
  CHECK(to.opacity_logits == from.opacity_logits);
  for (float v : to.sh) CHECK(v != 7.0f);  // colour is not geometry
  detail::fresh_colour(to, 5u);
  for (std::size_t i = 0; i < to.size(); ++i) {
    CHECK((to.sh_at(i, 0, 0) >= 0.0f && to.sh_at(i, 0, 0) < 1.0f));
    for (int k = 1; k < Gaussian<1, 1>::sh_coeffs; ++k) CHECK(to.sh_at(i, k, 0) == 0.0f);
  }
}

TEST_CASE("Split: a complete run trains the RGB model, then every band model on from step 30k (scaled)") {
  const fs::path out = out_dir("split_full");
  RunConfig cfg = config("split+extadc", 0.002);
  cfg.bands = {"D", "MS_RE"};
  std::vector<std::pair<long long, long long>> ranges;  // (begin, end) reported per model
  std::vector<std::vector<std::string>> progress_bands;  // the bands each report's PSNRs are of
  cfg.train.progress_every = 1000;
  cfg.train.on_progress = [&](const TrainProgress& pr) {
    ranges.emplace_back(pr.begin, pr.end);
    progress_bands.push_back(pr.band_ids);
    CHECK(pr.band_ids.size() == pr.band_psnr.size());
  };
  const RunResult res = run_experiment<kDeg>(tiny(), cfg, out);
  CHECK(res.strategy == "split+extadc");
  CHECK_FALSE(res.interrupted);
  CHECK(res.steps == 120);
  CHECK(res.steps == res.plan.total_steps(1));
  CHECK(ranges == std::vector<std::pair<long long, long long>>{{0, 60}, {60, 120}});
  // The band model's progress names its own band, not the run's first.
  CHECK(progress_bands == std::vector<std::vector<std::string>>{{"D"}, {"MS_RE"}});
  REQUIRE(res.metrics.size() == 2);
  CHECK(res.metrics[0].band == "D");
  CHECK(res.metrics[1].band == "MS_RE");
  CHECK(io::inspect_ply(res.models.at("D")).channels == 3);
  CHECK(io::inspect_ply(res.models.at("MS_RE")).channels == 1);
  // Stage 2 optimises geometry too: the band model moved away from the RGB model.
  const auto rgb = io::read_ply<Gaussian<3, kDeg>>(res.models.at("D"));
  const auto re = io::read_ply<Gaussian<1, kDeg>>(res.models.at("MS_RE"));
  CHECK((re.size() != rgb.size() || re.means != rgb.means));
}

TEST_CASE("Joint: one 7-channel model over every band") {
  const fs::path out = out_dir("joint");
  const RunConfig cfg = config("joint", 0.001);  // 120 steps
  const RunResult res = run_experiment<kDeg>(tiny(), cfg, out);
  CHECK(res.steps == 120);
  REQUIRE(res.gaussians.size() == 1);
  REQUIRE(res.models.count("joint") == 1);
  const io::PlyInfo info = io::inspect_ply(res.models.at("joint"));
  CHECK(info.channels == 7);
  CHECK(info.band_names == io::joint_channel_names());
  REQUIRE(res.metrics.size() == 5);
  std::set<std::string> seen;
  for (const auto& m : res.metrics) seen.insert(m.band);
  CHECK(seen.size() == 5);
}

TEST_CASE("num_downscales: -1 keeps splatfacto's resolution schedule, 0 trains at full resolution") {
  RunConfig cfg = config("joint", 0.001);
  const RunResult def = run_experiment<kDeg>(tiny(), cfg);
  CHECK(def.plan.schedule.num_downscales == 2);
  CHECK(def.plan.schedule.downscale(0) == 4);
  cfg.num_downscales = 0;
  const RunResult full = run_experiment<kDeg>(tiny(), cfg);
  CHECK(full.plan.schedule.num_downscales == 0);
  CHECK(full.plan.schedule.downscale(0) == 1);
  CHECK(full.steps == def.steps);
  // Different training images from the first step on: a different model.
  CHECK(BandMetrics::mean(full.metrics[0].psnr) != BandMetrics::mean(def.metrics[0].psnr));
}

TEST_CASE("Geometry band: strategies that need one refuse a capture without it before training") {
  // A capture without the RGB camera: only narrow bands.
  for (const char* s : {"split", "joint+specdelay+msad", "joint+sig", "split+extadc"}) {
    RunConfig cfg = config(s, 0.002);
    cfg.bands = {"MS_G", "MS_NIR"};
    std::string msg;
    try {
      validate_run(tiny(), cfg);
    } catch (const std::invalid_argument& e) {
      msg = e.what();
    }
    INFO(s, ": ", msg);
    CHECK(msg.find("geometry band") != std::string::npos);
    CHECK(msg.find("RGB band D") != std::string::npos);
    CHECK(msg.find("--geometry-band") != std::string::npos);
    CHECK(msg.find("MS_G, MS_NIR") != std::string::npos);
    CHECK_THROWS_AS(run_experiment<kDeg>(tiny(), cfg), std::invalid_argument);  // run_experiment checks too
    cfg.geometry_band = "MS_RE";  // a band that is not trained is no better
    CHECK_THROWS_WITH_AS(validate_run(tiny(), cfg), doctest::Contains("band 'MS_RE'"), std::invalid_argument);
    cfg.geometry_band = "MS_NIR";
    CHECK_NOTHROW(validate_run(tiny(), cfg));
  }
  for (const char* s : {"separate", "joint", "joint+msad", "joint+extadc"}) {
    RunConfig cfg = config(s, 0.002);
    cfg.bands = {"MS_G", "MS_NIR"};
    CHECK_NOTHROW(validate_run(tiny(), cfg));
  }
}

TEST_CASE("Geometry band: Split from a narrow band, SpecDelay trains the geometry band alone first") {
  {
    const fs::path out = out_dir("split_nir");
    RunConfig cfg = config("split", 0.002);  // 60 + 60 steps
    cfg.bands = {"MS_G", "MS_NIR"};
    cfg.geometry_band = "MS_NIR";
    std::vector<std::pair<long long, long long>> ranges;
    cfg.train.progress_every = 1000;
    cfg.train.on_progress = [&](const TrainProgress& pr) { ranges.emplace_back(pr.begin, pr.end); };
    const RunResult res = run_experiment<kDeg>(tiny(), cfg, out);
    CHECK(ranges == std::vector<std::pair<long long, long long>>{{0, 60}, {60, 120}});
    REQUIRE(res.models.count("MS_NIR") == 1);
    REQUIRE(res.models.count("MS_G") == 1);
    CHECK(io::inspect_ply(res.models.at("MS_NIR")).channels == 1);
    CHECK(io::inspect_ply(res.models.at("MS_G")).channels == 1);
  }
  {
    RunConfig cfg = config("joint+specdelay", 0.002);  // spectral bands from step 60 of 240
    cfg.bands = {"D", "MS_G", "MS_NIR"};
    cfg.geometry_band = "MS_NIR";  // D is then one of the bands that wait
    const long long start = parse_strategy(cfg.strategy, ScheduleScale{cfg.scale}).plan.spectral_start;
    REQUIRE(start > 10);
    std::vector<double> before;  // running training PSNR per band just before the delay ends
    cfg.train.progress_every = 1;
    cfg.train.on_progress = [&](const TrainProgress& pr) {
      if (pr.step == start) before = pr.band_psnr;  // steps 0 .. start-1 done
      if (pr.step == start + 20) throw std::runtime_error("enough");
    };
    CHECK_THROWS_WITH(run_experiment<kDeg>(tiny(), cfg), "enough");
    REQUIRE(before.size() == 3);  // D, MS_G, MS_NIR: only the geometry band was sampled
    CHECK(std::isnan(before[0]));
    CHECK(std::isnan(before[1]));
    CHECK(std::isfinite(before[2]));
  }
}

}  // namespace test_train_run
