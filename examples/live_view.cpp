// examples/live_view.cpp
// The server side of `msgs train --view` (live_view.hpp): a view_server.hpp Server whose scene is
// rebuilt from the newest training snapshot when one arrives, and /api/live with the run's state.
#include "live_view.hpp"

#include <atomic>
#include <chrono>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

#include "render_dispatch.hpp"
#include "view_api.hpp"
#include "view_server.hpp"

namespace msgs::cli {
namespace {

class LiveViewImpl final : public LiveView {
 public:
  LiveViewImpl(const io::Dataset& ds, const SnapshotStore& store, const LiveViewOptions& opt)
      : store_(&store), opt_(opt), t0_(std::chrono::steady_clock::now()) {
    st_.ds = &ds;
    st_.frames = view::FrameIndex(ds);
    st_.name = "msgs train --view";
    st_.scene = [this] { return scene(); };
    st_.live = [this] { return live(); };
    svr_ = std::make_unique<view::Server>(st_, opt.host, opt.quiet);
    if (svr_->bind(opt.port) < 0)
      throw std::runtime_error("--view: cannot listen on " + opt.host + " port " + std::to_string(opt.port) +
                               " (in use, or not an address of this machine); pick another with --view PORT");
    thread_ = std::thread([this] { svr_->listen(); });
  }
  ~LiveViewImpl() override {
    svr_->stop();
    if (thread_.joinable()) thread_.join();
  }
  std::string url() const override { return svr_->url(); }
  void finished(bool interrupted) override { phase_ = interrupted ? 2 : 1; }

 private:
  /// The scene of the newest snapshot, rebuilt (a copy of each model, new renderers) when the
  /// snapshot is newer than the scene.
  std::shared_ptr<const view::Scene> scene() {
    const std::shared_ptr<const TrainSnapshot> snap = store_->latest();
    if (!snap) throw view::ViewError(503, "no model yet: training has not finished its first step");
    std::lock_guard<std::mutex> lock(scene_mutex_);
    if (!scene_ || scene_->version != snap->version) {
      std::vector<LoadedModel> models;
      for (const auto& m : snap->models) models.push_back(*m.model);
      scene_ = view::make_scene(ModelSet::from_models(std::move(models), make_any_renderer), st_.ds, &st_.frames,
                                snap->version, snapshot_json(*snap));
    }
    return scene_;
  }

  nlohmann::json snapshot_json(const TrainSnapshot& s) const {
    nlohmann::json models = nlohmann::json::array();
    for (const auto& m : s.models)
      models.push_back({{"key", m.key}, {"step", m.step}, {"begin", m.begin}, {"end", m.end},
                        {"gaussians", m.model->size()}});
    return {{"version", s.version}, {"models", models}, {"gaussians", s.gaussians()}};
  }

  /// /api/live: the run's state and its newest snapshot (cheap: no model is copied).
  nlohmann::json live() const {
    const std::shared_ptr<const TrainSnapshot> snap = store_->latest();
    nlohmann::json j = snap ? snapshot_json(*snap) : nlohmann::json{{"version", 0}, {"models", nlohmann::json::array()},
                                                                    {"gaussians", 0}};
    const int phase = phase_.load();
    j["state"] = phase == 0 ? "training" : phase == 1 ? "done" : "interrupted";
    j["strategy"] = opt_.strategy;
    j["expected_models"] = opt_.expected_models;
    j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    const SnapshotStore::Stats s = store_->stats();
    j["snapshots"] = s.count;
    j["snapshot_ms_mean"] = s.count ? 1e3 * s.seconds / double(s.count) : 0.0;
    return j;
  }

  const SnapshotStore* store_;
  LiveViewOptions opt_;
  std::chrono::steady_clock::time_point t0_;
  view::ServerState st_;
  std::unique_ptr<view::Server> svr_;
  std::thread thread_;
  std::mutex scene_mutex_;
  std::shared_ptr<const view::Scene> scene_;
  std::atomic<int> phase_{0};  // 0 training, 1 done, 2 interrupted
};

}  // namespace

std::unique_ptr<LiveView> LiveView::start(const io::Dataset& ds, const SnapshotStore& store, const LiveViewOptions& opt) {
  return std::make_unique<LiveViewImpl>(ds, store, opt);
}

}  // namespace msgs::cli
