// tests/test_snapshot.cpp
// Snapshots of models while they train (snapshot.hpp, TrainOptions::on_step): a run with a
// snapshot after every step, read by another thread the whole time, writes the same models and
// metrics bit for bit as a run without; a multi-model run (Separate) ends with one snapshot per
// band model equal to the model it wrote; the policy snapshots first and last steps only when no
// time has passed; a snapshot handed out never changes.
#include <doctest/doctest.h>

#include "fixtures.hpp"

#include <msgs/io/ply.hpp>
#include <msgs/run.hpp>
#include <msgs/snapshot.hpp>

#include "run_experiment_sh0.hpp"  // run_experiment<0>, compiled once for the tests that run it

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace test_snapshot {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

constexpr int kDeg = 0;  // run_experiment<0>: the <7>, <3> and <1> trainers, compiled once

const io::Dataset& tiny() { return msgs::testing::tiny_scene("snapshot", 4); }

fs::path out_dir(const std::string& name) {
  const fs::path d = msgs::testing::scratch_dir("snapshot") / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

/// Every model file and every metric of two runs, compared exactly.
void check_identical(const RunResult& a, const RunResult& b) {
  REQUIRE(a.models.size() == b.models.size());
  for (const auto& entry : a.models) {
    const auto& key = entry.first;  // not a structured binding: CAPTURE's lambda names it
    const auto& path = entry.second;
    CAPTURE(key);
    REQUIRE(b.models.count(key) == 1);
    const std::string x = slurp(path), y = slurp(b.models.at(key));
    CHECK(!x.empty());
    CHECK(x == y);
  }
  REQUIRE(a.metrics.size() == b.metrics.size());
  for (std::size_t i = 0; i < a.metrics.size(); ++i) {
    CHECK(a.metrics[i].band == b.metrics[i].band);
    CHECK(a.metrics[i].psnr == b.metrics[i].psnr);
    CHECK(a.metrics[i].ssim == b.metrics[i].ssim);
  }
  CHECK(a.gaussians == b.gaussians);
  CHECK(a.steps == b.steps);
}

/// Reads every snapshot it can get, as a viewer thread would, until told to stop.
class Reader {
 public:
  explicit Reader(const SnapshotStore& s) : thread_([this, &s] {
      while (!stop_.load()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        const auto snap = s.latest();
        if (!snap) continue;
        double sum = 0;
        for (const auto& m : snap->models)
          std::visit([&](const auto& g) { for (float x : g.means) sum += double(x); }, m.model->model);
        if (std::isfinite(sum)) ++reads_;
      }
    }) {}
  ~Reader() { join(); }
  long join() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    return reads_;
  }

 private:
  std::atomic<bool> stop_{false};
  long reads_ = 0;
  std::thread thread_;
};

}  // namespace

TEST_CASE("snapshots after every step, read by another thread, leave a Joint run bit-identical") {
  RunConfig cfg;
  cfg.strategy = "joint+msad";
  cfg.scale = 0.0045;  // 540 steps: densification prunes and grows the model while it is snapshotted
  const RunResult plain = run_experiment<kDeg>(tiny(), cfg, out_dir("joint_plain"));

  SnapshotStore store(SnapshotPolicy{.min_seconds = 1e9, .every = 1});  // every step
  cfg.train.on_step = store.hook();
  Reader reader(store);
  const RunResult viewed = run_experiment<kDeg>(tiny(), cfg, out_dir("joint_viewed"));
  CHECK(reader.join() > 0);
  check_identical(plain, viewed);

  const auto snap = store.latest();
  REQUIRE(snap);
  CHECK(store.stats().count == std::size_t(plain.steps));
  CHECK(snap->version == std::uint64_t(plain.steps));
  REQUIRE(snap->models.size() == 1);
  const ModelSnapshot& m = snap->models[0];
  CHECK(m.key == "joint");
  CHECK(m.step == m.end);
  CHECK(m.model->info.band_names == io::joint_channel_names());
  // The last snapshot is the model the run wrote.
  const auto* copy = std::get_if<GaussianModel<Gaussian<7, kDeg>, float>>(&m.model->model);
  REQUIRE(copy);
  const auto written = io::read_ply<Gaussian<7, kDeg>>(plain.models.at("joint"));
  CHECK(copy->means == written.means);
  CHECK(copy->sh == written.sh);
  CHECK(copy->opacity_logits == written.opacity_logits);
  CHECK(m.model->size() == plain.gaussians.at("joint"));
  CHECK(m.model->size() != tiny().points.xyz.size() / 3);  // densification changed it while snapshotted
  MESSAGE("snapshot copy: " << 1e3 * store.stats().seconds / double(store.stats().count) << " ms mean, "
                            << 1e3 * store.stats().max_seconds << " ms max for " << m.model->size() << " Gaussians");
}

TEST_CASE("Separate: one snapshot per band model, in training order, each the model written") {
  RunConfig cfg;
  cfg.strategy = "separate";
  cfg.scale = 0.001;  // 30 steps per band
  const RunResult plain = run_experiment<kDeg>(tiny(), cfg, out_dir("separate_plain"));

  // No time passes between steps as far as this policy is concerned: first and last step only.
  SnapshotStore store(SnapshotPolicy{.min_seconds = 1e9});
  cfg.train.on_step = store.hook();
  const RunResult viewed = run_experiment<kDeg>(tiny(), cfg, out_dir("separate_viewed"));
  check_identical(plain, viewed);

  const auto snap = store.latest();
  REQUIRE(snap);
  const std::vector<std::string> bands = {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  CHECK(store.stats().count == 2 * bands.size());
  REQUIRE(snap->models.size() == bands.size());
  for (std::size_t b = 0; b < bands.size(); ++b) {
    const ModelSnapshot& m = snap->models[b];
    CAPTURE(bands[b]);
    CHECK(m.key == bands[b]);
    CHECK(m.step == 30);
    CHECK(m.end == 30);
    CHECK(m.model->channels() == (b == 0 ? 3 : 1));
    CHECK(m.model->info.band_names == (b == 0 ? std::vector<std::string>{"D_R", "D_G", "D_B"}
                                              : std::vector<std::string>{bands[b]}));
    CHECK(m.model->size() == plain.gaussians.at(bands[b]));
  }
  // A band ModelSet from the snapshot renders every band, as the live viewer's does.
  std::vector<LoadedModel> models;
  for (const auto& m : snap->models) models.push_back(*m.model);
  const ModelSet set = ModelSet::from_models(std::move(models), [](std::shared_ptr<const LoadedModel>) {
    return ChannelRenderer([](const Camera<float>&, const RenderSettings<float>&) { return Image<float>(); });
  });
  for (const auto& b : bands) CHECK(set.named_source(b) != nullptr);
}

TEST_CASE("a snapshot handed out never changes; StepView gives the model back only as its own type") {
  using G = Gaussian<3, 1>;
  GaussianModel<G, float> model;
  model.resize(4);
  std::vector<TrainBand> bands(1);
  bands[0].id = "D";
  bands[0].channels = 3;
  StepView v = StepView::of(model, bands, 1, 0, 3);
  v.key = "D";
  CHECK(v.model<G>() == &model);
  CHECK(v.model<Gaussian<3, 0>>() == nullptr);
  CHECK(v.model<Gaussian<7, 1>>() == nullptr);
  CHECK(v.channels == 3);
  CHECK(v.sh_degree == 1);

  SnapshotStore store(SnapshotPolicy{.min_seconds = 1e9});
  CHECK(store.latest() == nullptr);
  store.on_step(v);  // first step of model D: taken
  const auto first = store.latest();
  REQUIRE(first);
  CHECK(first->version == 1);
  model.means[0] = 42.0f;
  model.resize(6);
  v = StepView::of(model, bands, 2, 0, 3);
  v.key = "D";
  store.on_step(v);  // neither first nor last nor due: skipped
  CHECK(store.version() == 1);
  v = StepView::of(model, bands, 3, 0, 3);
  v.key = "D";
  store.on_step(v);  // last step: taken
  CHECK(store.version() == 2);
  // The first snapshot still holds the model as it was.
  CHECK(first->models[0].step == 1);
  CHECK(first->models[0].model->size() == 4);
  CHECK(std::get<GaussianModel<G, float>>(first->models[0].model->model).means[0] != 42.0f);
  CHECK(store.latest()->models[0].model->size() == 6);
  CHECK(store.latest()->models[0].model->info.band_names == std::vector<std::string>{"D_R", "D_G", "D_B"});

  // While a reader holds the snapshot before last, the next copy gets buffers of its own; once
  // nobody holds it, the snapshot before last lends its buffers to the next one.
  const LoadedModel* s1 = first->models[0].model.get();
  const LoadedModel* s2 = store.latest()->models[0].model.get();  // no reference kept
  store.on_step(v);  // step 3 again: the last step, so taken
  CHECK(store.version() == 3);
  CHECK(store.latest()->models[0].model.get() != s1);
  CHECK(first->models[0].model->size() == 4);
  CHECK(std::get<GaussianModel<G, float>>(first->models[0].model->model).means[0] != 42.0f);
  store.on_step(v);
  CHECK(store.version() == 4);
  CHECK(store.latest()->models[0].model.get() == s2);
  CHECK(store.latest()->models[0].model->size() == 6);
}

}  // namespace test_snapshot
