// examples/cmd_view.cpp
// `msgs view`: an interactive multi-spectral viewer in the browser. A small HTTP server (cpp-httplib,
// view_server.hpp) renders the model with msgs' own rasteriser on request and serves one
// self-contained page. Request parsing, cameras, modes and images live in view_api.hpp.
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "data_options.hpp"
#include "render_dispatch.hpp"
#include "view_api.hpp"
#include "view_server.hpp"

namespace cmd_view {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs view --model PLY|DIR [--data DIR] [--port P] [--host H] [--orient none|center]\n"
    "                 [--images NAME] [--eval-every N] [--quiet]\n"
    "\n"
    "Serve an interactive viewer of a trained model at http://127.0.0.1:8080/ : orbit, pan and zoom\n"
    "with the mouse or WASD / arrow keys; show any band of the model, the RGB band, colour infrared\n"
    "(NIR, R, G) or a spectral index (NDVI, NDRE, GNDVI, NDWI, SAVI) on a colour scale. With --data,\n"
    "jump to any dataset camera and see ground truth | render | error side by side with PSNR.\n"
    "Frames are rendered on this machine's CPU, one at a time.\n"
    "\n"
    "  --model PLY|DIR     a model PLY, or a directory of model_*.ply files (as `msgs train` writes)\n"
    "  --port P            TCP port (default 8080; 0 = any free port, printed at start)\n"
    "  --host H            address to listen on (default 127.0.0.1, this machine only; 0.0.0.0\n"
    "                      serves every network the machine is on, without authentication)\n"
    "  --orient none       the model was trained with --orient none\n"
    "  --quiet             do not log failed requests to stderr\n"
    MSGS_DATA_OPTIONS_USAGE
    "\n"
    "HTTP API (GET; errors are JSON {\"error\": ...} with status 400, 404 or 422):\n"
    "  /                   the viewer page (self-contained, no external scripts); deep links\n"
    "                      ?frame=ID&mode=M&size=W&bg=eval|black|white&format=png open it at a\n"
    "                      dataset camera in a mode, W pixels wide\n"
    "  /api/info           JSON: Gaussians, bands, modes, colour scales, scene extent, dataset cameras\n"
    "  /api/render         width, height, fx [fy cx cy] | fovy, R (9, row-major) + t (3) world-to-camera\n"
    "                      in OpenCV axes | eye + target [+ up], mode, bg, gain, format, quality\n"
    "                      -> image; X-Render-Ms header\n"
    "  /api/frame          id, what=render|gt|error, mode (default the frame's band), bg, gain, scale,\n"
    "                      format, quality -> image at that dataset camera; X-PSNR (bands, RGB, CIR)\n"
    "                      or X-MAE (indices) headers\n";

int run_view(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(argv, {"model", "data", "images", "eval-every", "port", "host", "orient"},
                             {"help", "no-orient", "quiet"});
  if (args.flag("help")) { std::fputs(kUsage, stdout); return 0; }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  const std::filesystem::path model = args.require("model");
  const long port = args.integer("port", 8080);
  if (port < 0 || port > 65535) throw msgs::cli::UsageError("--port must be 0..65535");
  const std::string host = args.get("host", "127.0.0.1");
  if (host.empty()) throw msgs::cli::UsageError("--host must not be empty");
  const bool quiet = args.flag("quiet");
  if (!args.has("data") && (args.has("images") || args.has("eval-every")))
    throw msgs::cli::UsageError("--images and --eval-every need --data");

  msgs::ModelSet models = msgs::ModelSet::load(model, msgs::cli::make_any_renderer);
  std::optional<msgs::io::Dataset> ds;
  msgs::view::ServerState st;
  if (args.has("data")) {
    msgs::io::LoadOptions lo;
    lo.orient_and_center = msgs::cli::orient_and_center(args);
    lo.load_points = false;
    ds = msgs::cli::load_data(args, lo, "view");
    st.ds = &*ds;
    st.frames = msgs::view::FrameIndex(*ds);
  } else if (args.has("orient") || args.flag("no-orient")) {
    throw msgs::cli::UsageError("--orient needs --data (it orients the dataset's cameras)");
  }
  const std::shared_ptr<const msgs::view::Scene> scene =
      msgs::view::make_scene(std::move(models), st.ds, st.ds ? &st.frames : nullptr, 1);
  st.scene = [scene] { return scene; };
  msgs::view::Server svr(st, host, quiet);

  // SIGINT / SIGTERM stop the server cleanly: block them in every thread (the pool and OpenMP
  // threads inherit the mask) and wait for them on a thread of their own.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  if (svr.bind(port) < 0) {
    std::fprintf(stderr, "msgs view: cannot listen on %s port %ld (in use, or not an address of this machine)\n",
                 host.c_str(), port);
    return 1;
  }
  std::string bands;
  for (const auto& b : msgs::io::standard_bands())
    if (scene->models.renders(b.id)) bands += (bands.empty() ? "" : " ") + b.id;
  std::fprintf(stderr, "msgs view: %zu Gaussians, bands %s%s\n", scene->gaussians, bands.c_str(),
               ds ? (", " + std::to_string(ds->frames.size()) + " dataset cameras").c_str() : "");
  if (!svr.local())
    std::fprintf(stderr, "msgs view: warning: listening on %s: anyone who can reach this machine can use the viewer\n",
                 host.c_str());
  std::printf("msgs view: serving %s (Ctrl-C stops)\n", svr.url().c_str());
  std::fflush(stdout);

  std::atomic<bool> signalled{false};
  std::thread waiter([&svr, &signalled, sigs] {
    int sig = 0;
    sigwait(&sigs, &sig);
    signalled = true;
    svr.stop();
  });
  const bool ok = svr.listen();
  // The server stopped on its own (an error): wake the waiter with a signal it consumes.
  if (!signalled) pthread_kill(waiter.native_handle(), SIGTERM);
  waiter.join();
  std::fprintf(stderr, "msgs view: stopped\n");
  return ok ? 0 : 1;
}

}  // namespace
}  // namespace cmd_view

MSGS_COMMAND("view", "Interactive viewer in the browser: any band, RGB, CIR, spectral indices, dataset cameras",
             cmd_view::run_view);
