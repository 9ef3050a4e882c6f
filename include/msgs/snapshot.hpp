// include/msgs/snapshot.hpp
// Snapshots of the models of a run while they train, for a live viewer in another thread: the
// training thread copies a model between steps (TrainOptions::on_step) and publishes the copy; a
// reader takes the latest set of copies without ever waiting for a step or touching the model
// being trained.
//
// Cost: one copy of the model per snapshot (the copy is what keeps training untouched) plus a
// pointer swap under a mutex. The copy goes into the buffers of the snapshot before last when no
// reader holds it any more (no allocation, no page faults). Snapshots are taken after a model's
// first and last step and otherwise at most every `min_seconds`, and never so often that copying
// takes more than `max_share` of the time (a 1M-Gaussian Joint model: every few seconds).
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "io/bands.hpp"
#include "io/ply.hpp"
#include "render_util.hpp"
#include "run.hpp"
#include "train.hpp"

namespace msgs {

/// One model as of a step.
struct ModelSnapshot {
  std::string key;                            ///< "joint", or the band id of a per-band model
  long long step = 0, begin = 0, end = 0;     ///< steps done and the model's step range
  std::shared_ptr<const LoadedModel> model;   ///< the copy, with band names as its PLY would carry
};

/// The latest snapshot of every model a run has trained so far, in the order they started.
struct TrainSnapshot {
  std::uint64_t version = 0;         ///< 1 for the first snapshot, +1 for each one after it
  std::vector<ModelSnapshot> models;
  const ModelSnapshot* current() const { return models.empty() ? nullptr : &models.back(); }
  std::size_t gaussians() const {
    std::size_t n = 0;
    for (const auto& m : models) n += m.model->size();
    return n;
  }
};

/// When a snapshot is due.
struct SnapshotPolicy {
  double min_seconds = 1.0;  ///< at most one snapshot per this many seconds (besides first and last)
  double max_share = 0.02;   ///< ... and waits at least (last copy's time / max_share) between two
  long long every = 0;       ///< > 0: also every this many steps (tests)
};

namespace detail {

/// Copy the model behind a StepView into `dst`, into its buffers when it holds the same type;
/// std::invalid_argument for a type that AnyModel cannot hold.
template <int C, int D = 0>
void copy_step_model(const StepView& v, AnyModel& dst) {
  if constexpr (D <= 3) {
    using M = GaussianModel<Gaussian<C, D>, float>;
    if (const M* m = v.model<Gaussian<C, D>>()) {
      // Band planes of N rows (the trainer's have room to grow); vectors keep their capacity.
      if (M* d = std::get_if<M>(&dst)) d->assign_shrunk(*m);
      else dst.emplace<M>().assign_shrunk(*m);
      return;
    }
    copy_step_model<C, D + 1>(v, dst);
  } else {
    if constexpr (C == 1) copy_step_model<3, 0>(v, dst);
    else if constexpr (C == 3) copy_step_model<7, 0>(v, dst);
    else
      throw std::invalid_argument("snapshot: a model of " + std::to_string(v.channels) + " channels and SH degree " +
                                  std::to_string(v.sh_degree) + " cannot be viewed");
  }
}

/// Channel names of a trained model, as run.hpp writes them into its PLY.
inline std::vector<std::string> step_channel_names(const StepView& v) {
  if (v.channels == int(io::joint_channel_names().size())) return io::joint_channel_names();
  if (v.bands && v.bands->size() == 1) return channel_names(v.bands->front());
  return {};
}

}  // namespace detail

/// Thread-safe store of the latest snapshots. The training thread calls on_step (through hook());
/// any other thread calls latest() / version().
class SnapshotStore {
 public:
  /// Time taken by the copies, for reports.
  struct Stats {
    std::size_t count = 0;
    double seconds = 0, max_seconds = 0;
  };

  explicit SnapshotStore(SnapshotPolicy p = {}) : policy_(p) {}

  /// The function to put into TrainOptions::on_step. The store must outlive the run.
  std::function<void(const StepView&)> hook() {
    return [this](const StepView& v) { on_step(v); };
  }

  /// Snapshot the model of `v` if one is due.
  void on_step(const StepView& v) {
    using clock = std::chrono::steady_clock;
    const auto now = clock::now();
    const std::string key = v.key.empty() ? "model" : v.key;
    const bool first = key != last_key_;
    const bool last = v.step >= v.end;
    const double wait = std::max(policy_.min_seconds, policy_.max_share > 0 ? last_cost_ / policy_.max_share : 0.0);
    const bool timed = std::chrono::duration<double>(now - last_time_).count() >= wait;
    const bool counted = policy_.every > 0 && v.step % policy_.every == 0;
    if (!(first || last || timed || counted)) return;
    take(v, key);
    last_key_ = key;
    last_time_ = clock::now();
    const double s = std::chrono::duration<double>(last_time_ - now).count();
    last_cost_ = s;
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.count;
    stats_.seconds += s;
    stats_.max_seconds = std::max(stats_.max_seconds, s);
  }

  /// Snapshot the model of `v` now.
  void take(const StepView& v, const std::string& key) {
    // The snapshot before last of this model, when no reader holds it any more, lends its buffers.
    std::shared_ptr<LoadedModel> lm;
    if (spare_ && spare_key_ == key && spare_.use_count() == 1) {
      std::atomic_thread_fence(std::memory_order_acquire);  // the last reader's release is seen
      lm = std::move(spare_);
    } else {
      lm = std::make_shared<LoadedModel>();
    }
    spare_.reset();
    lm->path = "model_" + key + ".ply";
    lm->info.vertices = v.gaussians;
    lm->info.gaussian = true;
    lm->info.channels = v.channels;
    lm->info.sh_degree = v.sh_degree;
    lm->info.band_names = detail::step_channel_names(v);
    detail::copy_step_model<1>(v, lm->model);  // the copy: the only part that costs
    ModelSnapshot ms{key, v.step, v.begin, v.end, std::move(lm)};

    std::shared_ptr<const LoadedModel> previous;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      auto next = std::make_shared<TrainSnapshot>(latest_ ? *latest_ : TrainSnapshot{});
      next->version = ++version_;
      auto it = std::find_if(next->models.begin(), next->models.end(), [&](const ModelSnapshot& m) { return m.key == key; });
      if (it == next->models.end()) {
        next->models.push_back(std::move(ms));
      } else {
        previous = std::move(it->model);
        *it = std::move(ms);
      }
      latest_ = std::move(next);
    }
    // Made non-const by this store, handed out as const: writable again once nobody else holds it.
    spare_ = std::const_pointer_cast<LoadedModel>(std::move(previous));
    spare_key_ = key;
  }

  /// The latest snapshots (nullptr before the first one). The result stays valid and unchanged
  /// however long the caller keeps it.
  std::shared_ptr<const TrainSnapshot> latest() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return latest_;
  }
  std::uint64_t version() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return version_;
  }
  Stats stats() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }

 private:
  SnapshotPolicy policy_;
  // Training thread only.
  std::string last_key_;
  std::chrono::steady_clock::time_point last_time_{};
  double last_cost_ = 0;                  ///< seconds the last snapshot took
  std::shared_ptr<LoadedModel> spare_;    ///< the snapshot before the latest of model spare_key_
  std::string spare_key_;
  // Shared, under mutex_.
  mutable std::mutex mutex_;
  std::shared_ptr<const TrainSnapshot> latest_;
  std::uint64_t version_ = 0;
  Stats stats_;
};

}  // namespace msgs
