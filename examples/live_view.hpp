// examples/live_view.hpp
// `msgs train --view`: the viewer of `msgs view` (view_server.hpp) on the models of a run while
// they train. The training thread publishes snapshots into a SnapshotStore (msgs/snapshot.hpp);
// the server, on threads of its own, renders the latest one and rebuilds its scene whenever a
// newer snapshot exists. Nothing here touches the models being trained.
//
// Kept free of cpp-httplib so that cmd_train.cpp compiles without it: live_view.cpp holds the
// server and is built only when cpp-httplib is found (MSGS_HAVE_VIEW).
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstddef>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <msgs/io/dataset.hpp>
#include <msgs/run.hpp>
#include <msgs/snapshot.hpp>
#include <msgs/strategy.hpp>

#include "commands.hpp"

namespace msgs::cli {

struct LiveViewOptions {
  std::string host = "127.0.0.1";
  long port = 8080;                 ///< 0: any free port
  bool quiet = false;               ///< do not log failed requests
  std::string strategy;             ///< shown on the page
  std::size_t expected_models = 1;  ///< models the run will train (1 for Joint, one per band otherwise)
};

/// A running live viewer; destroying it stops the server.
class LiveView {
 public:
  /// Bind and serve on a thread of its own. Throws std::runtime_error naming host and port when
  /// it cannot listen there (call it before training starts). `ds` and `store` must outlive it.
  static std::unique_ptr<LiveView> start(const io::Dataset& ds, const SnapshotStore& store, const LiveViewOptions& opt);
  virtual ~LiveView() = default;
  virtual std::string url() const = 0;
  /// The run has ended (the page says so).
  virtual void finished(bool interrupted) = 0;
};

/// `--view` takes an optional port: `--view`, `--view 8081` and `--view=8081` become
/// `--view=PORT` (8080 when none is given) for Args.
inline std::vector<std::string> view_option_argv(std::vector<std::string> argv) {
  for (std::size_t i = 0; i < argv.size(); ++i) {
    if (argv[i] != "--view") continue;
    const bool port = i + 1 < argv.size() && !argv[i + 1].empty() &&
                      std::all_of(argv[i + 1].begin(), argv[i + 1].end(), [](char c) { return c >= '0' && c <= '9'; });
    argv[i] = "--view=" + (port ? argv[i + 1] : std::string("8080"));
    if (port) argv.erase(argv.begin() + std::ptrdiff_t(i) + 1);
  }
  return argv;
}

/// With --view: start the live viewer on `ds` and route the run's snapshots into `store`
/// (cfg.train.on_step). nullptr without --view. Throws UsageError for a bad port or host, and
/// std::runtime_error when the port cannot be bound, before anything trains.
inline std::unique_ptr<LiveView> start_live_view(const Args& args, const io::Dataset& ds, SnapshotStore& store,
                                                 RunConfig& cfg, std::size_t bands) {
  if (!args.has("view")) {
    if (args.has("host")) throw UsageError("--host needs --view");
    return nullptr;
  }
  LiveViewOptions opt;
  opt.port = args.integer("view", 8080);
  if (opt.port < 0 || opt.port > 65535) throw UsageError("--view PORT must be 0..65535");
  opt.host = args.get("host", "127.0.0.1");
  if (opt.host.empty()) throw UsageError("--host must not be empty");
  opt.quiet = args.flag("quiet");
  const TrainPlan plan = parse_strategy(cfg.strategy).plan;
  opt.strategy = plan.name;
  opt.expected_models = plan.kind == StrategyKind::Joint ? 1 : bands;
#ifdef MSGS_HAVE_VIEW
  std::unique_ptr<LiveView> live = LiveView::start(ds, store, opt);
  cfg.train.on_step = store.hook();
  if (!(opt.host == "127.0.0.1" || opt.host == "localhost" || opt.host == "::1"))
    std::fprintf(stderr, "msgs train: warning: --view listens on %s: anyone who can reach this machine can use it\n",
                 opt.host.c_str());
  std::printf("msgs train: live view at %s\n", live->url().c_str());
  std::fflush(stdout);
  return live;
#else
  (void)ds;
  (void)store;
  throw UsageError("--view: this msgs was built without cpp-httplib (apt-get install libcpp-httplib-dev)");
#endif
}

/// After the run: a finished run keeps the viewer serving until Ctrl-C (which sets `stop`
/// through `on_sigint`); an interrupted one stops it at once.
inline void serve_after_run(LiveView& live, const SnapshotStore& store, bool interrupted, std::atomic<bool>& stop,
                            void (*on_sigint)(int)) {
  live.finished(interrupted);
  const SnapshotStore::Stats st = store.stats();
  if (st.count > 0)
    std::fprintf(stderr, "msgs train: %zu snapshots for the viewer, %.2f ms each on average (largest %.2f ms)\n",
                 st.count, 1e3 * st.seconds / double(st.count), 1e3 * st.max_seconds);
  if (interrupted) return;
  stop.store(false);
  std::signal(SIGINT, on_sigint);
  std::printf("msgs train: training done; viewer still at %s, Ctrl-C to quit\n", live.url().c_str());
  std::fflush(stdout);
  while (!stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::signal(SIGINT, SIG_DFL);
}

}  // namespace msgs::cli
