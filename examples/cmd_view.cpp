// examples/cmd_view.cpp
// `msgs view`: an interactive multi-spectral viewer in the browser. A small HTTP server (cpp-httplib)
// renders the model with msgs' own rasteriser on request and serves one self-contained page.
// Request parsing, cameras, modes and images live in view_api.hpp; this file is the HTTP wiring.
//
// Concurrency: httplib answers requests on a thread pool, but every request that renders or reads
// the dataset takes one mutex. The renderers of a ModelSet each own one Rasterizer whose buffers
// are reused between frames (no allocation per frame), so two renders must never overlap; the
// rasteriser itself spreads each frame over the cores with OpenMP. /api/info and the page are
// answered without the lock.
#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "data_options.hpp"
#include "render_dispatch.hpp"
#include "view_api.hpp"
#include "view_page.hpp"

// After Eigen (via view_api.hpp): httplib includes <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

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
    "  /                   the viewer page (self-contained, no external scripts)\n"
    "  /api/info           JSON: Gaussians, bands, modes, colour scales, scene extent, dataset cameras\n"
    "  /api/render         width, height, fx [fy cx cy] | fovy, R (9, row-major) + t (3) world-to-camera\n"
    "                      in OpenCV axes | eye + target [+ up], mode, bg, gain, format, quality\n"
    "                      -> image; X-Render-Ms header\n"
    "  /api/frame          id, what=render|gt|error, mode (default the frame's band), bg, gain, scale,\n"
    "                      format, quality -> image at that dataset camera; X-PSNR (bands, RGB, CIR)\n"
    "                      or X-MAE (indices) headers\n";

using msgs::view::ViewError;

struct State {
  msgs::ModelSet models;
  std::optional<msgs::io::Dataset> ds;
  msgs::view::FrameIndex frames;
  std::string info;  // /api/info body, built once
  std::size_t gaussians = 0;

  // Serialises every use of the renderers (each reuses one Rasterizer's buffers) and the cache.
  std::mutex render_mutex;
  // The last frame comparison, so the page's three requests (gt, render, error) render once.
  std::string cached_key;
  msgs::view::FrameComparison cached;
  double cached_ms = 0;
};

void send_error(httplib::Response& res, int status, const std::string& msg) {
  res.status = status;
  res.set_header("X-Error", msgs::view::Query::printable(msg));
  res.set_content(nlohmann::json{{"error", msg}}.dump(), "application/json");
}

void send_image(httplib::Response& res, const msgs::Image<float>& img, msgs::view::Format fmt, int quality) {
  msgs::view::Encoded enc = msgs::view::encode(img, fmt, quality);
  res.set_header("X-Width", std::to_string(img.width));
  res.set_header("X-Height", std::to_string(img.height));
  res.set_content(std::move(enc.bytes), enc.content_type);
}

std::string fmt_ms(double ms) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", ms);
  return buf;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void handle_render(State& st, const httplib::Request& req, httplib::Response& res) {
  const msgs::view::Query q(req.params, {"width", "height", "fx", "fy", "cx", "cy", "fovy", "R", "t", "eye", "target",
                                         "up", "mode", "bg", "gain", "format", "quality"});
  const msgs::Camera<float> cam = msgs::view::parse_camera(q);
  const msgs::view::Mode mode = msgs::view::parse_mode(q.str("mode", "rgb"));
  const msgs::view::Background bg = msgs::view::parse_background(q);
  const float gain = msgs::view::parse_gain(q);
  const auto [fmt, quality] = msgs::view::parse_format(q);
  msgs::view::require_mode(st.models, mode);
  msgs::Image<float> shown;
  double ms = 0;
  {
    std::lock_guard<std::mutex> lock(st.render_mutex);
    const auto t0 = std::chrono::steady_clock::now();
    shown = msgs::view::display(mode, msgs::view::render_values(st.models, mode, cam, bg), gain);
    ms = ms_since(t0);
  }
  res.set_header("X-Render-Ms", fmt_ms(ms));
  res.set_header("X-Gaussians", std::to_string(st.gaussians));
  res.set_header("X-Mode", mode.id());
  send_image(res, shown, fmt, quality);
}

void handle_frame(State& st, const httplib::Request& req, httplib::Response& res) {
  if (!st.ds) throw ViewError(404, "no dataset: start msgs view with --data DIR to see dataset cameras");
  const msgs::view::Query q(req.params, {"id", "what", "mode", "bg", "gain", "scale", "format", "quality"});
  if (!q.has("id")) msgs::view::bad_request("id is required");
  const msgs::io::Dataset& ds = *st.ds;
  const long long id = q.integer("id", 0, 0, (1LL << 40));
  if (std::size_t(id) >= ds.frames.size())
    throw ViewError(404, "unknown frame id " + std::to_string(id) + " (the dataset has " +
                             std::to_string(ds.frames.size()) + " frames, ids 0.." +
                             std::to_string(ds.frames.size() - 1) + ")");
  const std::size_t fi = std::size_t(id);
  const msgs::io::Frame& f = ds.frames[fi];
  const std::string what = q.str("what", "render");
  if (what != "render" && what != "gt" && what != "error")
    msgs::view::bad_request("what expects render, gt or error, got '" + msgs::view::Query::printable(what) + "'");
  const msgs::view::Mode mode = msgs::view::parse_mode(q.str("mode", f.band));
  const msgs::view::Background bg = msgs::view::parse_background(q);
  const float gain = msgs::view::parse_gain(q);
  const auto [fmt, quality] = msgs::view::parse_format(q);
  const int factor = msgs::view::frame_factor(q, ds, f);
  msgs::view::require_mode(st.models, mode);

  msgs::Image<float> shown;
  std::lock_guard<std::mutex> lock(st.render_mutex);
  const std::string key =
      std::to_string(fi) + "|" + mode.id() + "|" + q.str("bg", "eval") + "|" + std::to_string(factor);
  if (key != st.cached_key) {
    st.cached_key.clear();
    const auto t0 = std::chrono::steady_clock::now();
    st.cached = msgs::view::compare_frame(st.models, ds, st.frames, fi, mode, bg, factor);
    st.cached_ms = ms_since(t0);
    st.cached_key = key;
  }
  const msgs::view::FrameComparison& c = st.cached;
  if (what == "render") shown = msgs::view::display(mode, c.render, gain);
  else if (what == "gt") {
    if (!c.gt_error.empty()) throw ViewError(422, c.gt_error);
    shown = msgs::view::display(mode, c.gt, gain);
  } else {
    shown = msgs::view::error_image(mode, c);
  }
  res.set_header("X-Render-Ms", fmt_ms(st.cached_ms));
  res.set_header("X-Gaussians", std::to_string(st.gaussians));
  res.set_header("X-Mode", mode.id());
  res.set_header("X-Frame", std::to_string(fi));
  res.set_header("X-Scale", std::to_string(factor));
  char buf[64];
  if (!c.gt_error.empty()) {
    res.set_header("X-GT-Missing", msgs::view::Query::printable(c.gt_error));
  } else if (mode.is_index()) {
    std::snprintf(buf, sizeof buf, "%.6f", c.mae);
    res.set_header("X-MAE", buf);
  } else {
    std::snprintf(buf, sizeof buf, "%.4f", c.psnr);
    res.set_header("X-PSNR", buf);
  }
  if (what == "error") {
    std::snprintf(buf, sizeof buf, "%g", double(msgs::view::error_scale(mode)));
    res.set_header("X-Error-Scale", buf);
  }
  send_image(res, shown, fmt, quality);
}

/// Host header names that mean this machine: with the default loopback binding every other name
/// is refused, so a web page elsewhere cannot reach the server through DNS rebinding.
bool local_host_header(const std::string& host) {
  std::string h = host;
  if (!h.empty() && h[0] == '[') {
    const auto close = h.find(']');
    h = close == std::string::npos ? h : h.substr(0, close + 1);
  } else if (const auto colon = h.rfind(':'); colon != std::string::npos) {
    h = h.substr(0, colon);
  }
  return h == "127.0.0.1" || h == "localhost" || h == "[::1]";
}

bool loopback(const std::string& host) { return host == "127.0.0.1" || host == "localhost" || host == "::1"; }

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

  State st{msgs::ModelSet::load(model, msgs::cli::make_any_renderer), {}, {}, {}, 0, {}, {}, {}, 0};
  for (const auto& m : st.models.models()) st.gaussians += m->size();
  if (args.has("data")) {
    msgs::io::LoadOptions lo;
    lo.orient_and_center = msgs::cli::orient_and_center(args);
    lo.load_points = false;
    st.ds = msgs::cli::load_data(args, lo, "view");
    st.frames = msgs::view::FrameIndex(*st.ds);
  } else if (args.has("orient") || args.flag("no-orient")) {
    throw msgs::cli::UsageError("--orient needs --data (it orients the dataset's cameras)");
  }
  st.info = msgs::view::info_json(st.models, st.ds ? &*st.ds : nullptr, st.ds ? &st.frames : nullptr).dump();

  httplib::Server svr;
  // httplib's default also sets SO_REUSEPORT, with which a second server (or another user's
  // process) could bind the same port and take a share of the connections. SO_REUSEADDR alone
  // still allows a quick restart on the port.
  svr.set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  svr.set_payload_max_length(64 * 1024);  // nothing here takes a body
  svr.set_read_timeout(10, 0);
  svr.set_write_timeout(30, 0);
  const bool local = loopback(host);
  svr.set_pre_routing_handler([local](const httplib::Request& req, httplib::Response& res) {
    if (req.method != "GET" && req.method != "HEAD") {
      send_error(res, 405, "only GET is served");
      res.set_header("Allow", "GET, HEAD");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (local && req.has_header("Host") && !local_host_header(req.get_header_value("Host"))) {
      send_error(res, 403, "this server answers requests for 127.0.0.1 / localhost only");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  svr.set_post_routing_handler([](const httplib::Request&, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Content-Type-Options", "nosniff");
  });
  // Unknown paths (including ../ traversal: nothing is served from the file system) get a JSON 404.
  svr.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (res.body.empty())
      send_error(res, res.status, res.status == 404 ? "no such page: " + msgs::view::Query::printable(req.path)
                                                    : "request failed");
  });
  svr.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    std::string msg = "internal error";
    try {
      if (ep) std::rethrow_exception(ep);
    } catch (const std::exception& e) {
      msg += std::string(": ") + e.what();
    } catch (...) {
    }
    send_error(res, 500, msg);
  });
  if (!quiet)
    svr.set_logger([](const httplib::Request& req, const httplib::Response& res) {
      if (res.status < 400) return;
      std::fprintf(stderr, "msgs view: %d %s %s: %s\n", res.status, req.method.c_str(),
                   msgs::view::Query::printable(req.path).c_str(), res.get_header_value("X-Error").c_str());
    });

  // Every handler answers a ViewError with its status; anything else a render throws is a 500
  // and the server keeps serving.
  auto guarded = [&st](void (*fn)(State&, const httplib::Request&, httplib::Response&)) {
    return [&st, fn](const httplib::Request& req, httplib::Response& res) {
      try {
        fn(st, req, res);
      } catch (const ViewError& e) {
        send_error(res, e.status, e.what());
      } catch (const std::exception& e) {
        send_error(res, 500, std::string("internal error: ") + e.what());
      }
    };
  };
  svr.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_header("Content-Security-Policy",
                   "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                   "img-src 'self' blob:; connect-src 'self'; base-uri 'none'; form-action 'none'");
    res.set_content(msgs::view::page_html, "text/html; charset=utf-8");
  });
  svr.Get("/api/info", [&st](const httplib::Request& req, httplib::Response& res) {
    if (!req.params.empty()) return send_error(res, 400, "/api/info takes no parameters");
    res.set_content(st.info, "application/json");
  });
  svr.Get("/api/render", guarded(handle_render));
  svr.Get("/api/frame", guarded(handle_frame));

  // SIGINT / SIGTERM stop the server cleanly: block them in every thread (the pool and OpenMP
  // threads inherit the mask) and wait for them on a thread of their own.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  int bound = -1;
  if (port == 0) bound = svr.bind_to_any_port(host);
  else bound = svr.bind_to_port(host, int(port)) ? int(port) : -1;
  if (bound <= 0) {
    std::fprintf(stderr, "msgs view: cannot listen on %s port %ld (in use, or not an address of this machine)\n",
                 host.c_str(), port);
    return 1;
  }
  std::string bands;
  for (const auto& b : msgs::io::standard_bands())
    if (st.models.renders(b.id)) bands += (bands.empty() ? "" : " ") + b.id;
  std::fprintf(stderr, "msgs view: %zu Gaussians, bands %s%s\n", st.gaussians, bands.c_str(),
               st.ds ? (", " + std::to_string(st.ds->frames.size()) + " dataset cameras").c_str() : "");
  if (!local)
    std::fprintf(stderr, "msgs view: warning: listening on %s: anyone who can reach this machine can use the viewer\n",
                 host.c_str());
  const std::string url_host = host.find(':') != std::string::npos ? "[" + host + "]" : host;
  std::printf("msgs view: serving http://%s:%d/ (Ctrl-C stops)\n", url_host.c_str(), bound);
  std::fflush(stdout);

  std::atomic<bool> signalled{false};
  std::thread waiter([&svr, &signalled, sigs] {
    int sig = 0;
    sigwait(&sigs, &sig);
    signalled = true;
    svr.stop();
  });
  const bool ok = svr.listen_after_bind();
  // The server stopped on its own (an error): wake the waiter with a signal it consumes.
  if (!signalled) pthread_kill(waiter.native_handle(), SIGTERM);
  waiter.join();
  std::fprintf(stderr, "msgs view: stopped\n");
  return ok ? 0 : 1;
}

}  // namespace

MSGS_COMMAND("view", "Interactive viewer in the browser: any band, RGB, CIR, spectral indices, dataset cameras",
             run_view);
