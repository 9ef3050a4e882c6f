// examples/view_server.hpp
// The HTTP side of the viewer, shared by `msgs view` (a model read from disk) and `msgs train
// --view` (snapshots of the models while they train): routes, strict errors, the Host check,
// binding. Request parsing, cameras, modes and images live in view_api.hpp.
//
// Concurrency: httplib answers requests on a thread pool, but every request that renders or reads
// the dataset takes one mutex. The renderers of a ModelSet each own one Rasterizer whose buffers
// are reused between frames (no allocation per frame), so two renders must never overlap; the
// rasteriser itself spreads each frame over the cores with OpenMP. The scene (model set and its
// /api/info) is immutable and handed out as a shared_ptr, so a live view swaps in a new one
// without waiting for renders of the old one to finish.
#pragma once

#include <sys/socket.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "view_api.hpp"
#include "view_page.hpp"

// After Eigen (via view_api.hpp): httplib includes <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace msgs::view {

/// What the handlers render: a model set and its /api/info body, never changed once made.
struct Scene {
  ModelSet models;
  std::string info;            ///< /api/info body
  std::size_t gaussians = 0;
  std::uint64_t version = 0;   ///< changes whenever the models do (live views)
};

/// A scene of `models` with the dataset's cameras in its /api/info; `live` (an object) is added
/// to the info as "live" when given.
inline std::shared_ptr<const Scene> make_scene(ModelSet models, const io::Dataset* ds, const FrameIndex* fx,
                                               std::uint64_t version, const nlohmann::json& live = nullptr) {
  auto s = std::make_shared<Scene>(Scene{std::move(models), {}, 0, version});
  for (const auto& m : s->models.models()) s->gaussians += m->size();
  nlohmann::json info = info_json(s->models, ds, fx);
  if (!live.is_null()) info["live"] = live;
  s->info = info.dump();
  return s;
}

/// Everything the handlers share.
struct ServerState {
  const io::Dataset* ds = nullptr;  ///< dataset cameras and ground truth (nullptr: none)
  FrameIndex frames;
  /// The scene to render now; throws ViewError (503) while there is none yet.
  std::function<std::shared_ptr<const Scene>()> scene;
  /// /api/live: training progress as JSON; empty for a model from disk (404).
  std::function<nlohmann::json()> live;
  std::string name = "msgs view";  ///< in log lines

  // Serialises every use of the renderers (each reuses one Rasterizer's buffers) and the cache.
  std::mutex render_mutex;
  // The last frame comparison, so the page's three requests (gt, render, error) render once.
  std::string cached_key;
  FrameComparison cached;
  double cached_ms = 0;
};

inline void send_error(httplib::Response& res, int status, const std::string& msg) {
  res.status = status;
  res.set_header("X-Error", Query::printable(msg));
  res.set_content(nlohmann::json{{"error", msg}}.dump(), "application/json");
}

inline void send_image(httplib::Response& res, const Image<float>& img, Format fmt, int quality) {
  Encoded enc = encode(img, fmt, quality);
  res.set_header("X-Width", std::to_string(img.width));
  res.set_header("X-Height", std::to_string(img.height));
  res.set_content(std::move(enc.bytes), enc.content_type);
}

inline std::string fmt_ms(double ms) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", ms);
  return buf;
}

inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

inline void scene_headers(httplib::Response& res, const Scene& sc) {
  res.set_header("X-Gaussians", std::to_string(sc.gaussians));
  res.set_header("X-Version", std::to_string(sc.version));
}

inline void handle_render(ServerState& st, const httplib::Request& req, httplib::Response& res) {
  const Query q(req.params, {"width", "height", "fx", "fy", "cx", "cy", "fovy", "R", "t", "eye", "target", "up", "mode",
                             "bg", "gain", "format", "quality"});
  const Camera<float> cam = parse_camera(q);
  const Mode mode = parse_mode(q.str("mode", "rgb"));
  const Background bg = parse_background(q);
  const float gain = parse_gain(q);
  const auto [fmt, quality] = parse_format(q);
  const std::shared_ptr<const Scene> sc = st.scene();
  require_mode(sc->models, mode);
  Image<float> shown;
  double ms = 0;
  {
    std::lock_guard<std::mutex> lock(st.render_mutex);
    const auto t0 = std::chrono::steady_clock::now();
    shown = display(mode, render_values(sc->models, mode, cam, bg), gain);
    ms = ms_since(t0);
  }
  res.set_header("X-Render-Ms", fmt_ms(ms));
  scene_headers(res, *sc);
  res.set_header("X-Mode", mode.id());
  send_image(res, shown, fmt, quality);
}

inline void handle_frame(ServerState& st, const httplib::Request& req, httplib::Response& res) {
  if (!st.ds) throw ViewError(404, "no dataset: start msgs view with --data DIR to see dataset cameras");
  const Query q(req.params, {"id", "what", "mode", "bg", "gain", "scale", "format", "quality"});
  if (!q.has("id")) bad_request("id is required");
  const io::Dataset& ds = *st.ds;
  const long long id = q.integer("id", 0, 0, (1LL << 40));
  if (std::size_t(id) >= ds.frames.size())
    throw ViewError(404, "unknown frame id " + std::to_string(id) + " (the dataset has " +
                             std::to_string(ds.frames.size()) + " frames, ids 0.." +
                             std::to_string(ds.frames.size() - 1) + ")");
  const std::size_t fi = std::size_t(id);
  const io::Frame& f = ds.frames[fi];
  const std::string what = q.str("what", "render");
  if (what != "render" && what != "gt" && what != "error")
    bad_request("what expects render, gt or error, got '" + Query::printable(what) + "'");
  const Mode mode = parse_mode(q.str("mode", f.band));
  const Background bg = parse_background(q);
  const float gain = parse_gain(q);
  const auto [fmt, quality] = parse_format(q);
  const int factor = frame_factor(q, ds, f);
  const std::shared_ptr<const Scene> sc = st.scene();
  require_mode(sc->models, mode);

  Image<float> shown;
  std::lock_guard<std::mutex> lock(st.render_mutex);
  const std::string key = std::to_string(sc->version) + "|" + std::to_string(fi) + "|" + mode.id() + "|" +
                          q.str("bg", "eval") + "|" + std::to_string(factor);
  if (key != st.cached_key) {
    st.cached_key.clear();
    const auto t0 = std::chrono::steady_clock::now();
    st.cached = compare_frame(sc->models, ds, st.frames, fi, mode, bg, factor);
    st.cached_ms = ms_since(t0);
    st.cached_key = key;
  }
  const FrameComparison& c = st.cached;
  if (what == "render") shown = display(mode, c.render, gain);
  else if (what == "gt") {
    if (!c.gt_error.empty()) throw ViewError(422, c.gt_error);
    shown = display(mode, c.gt, gain);
  } else {
    shown = error_image(mode, c);
  }
  res.set_header("X-Render-Ms", fmt_ms(st.cached_ms));
  scene_headers(res, *sc);
  res.set_header("X-Mode", mode.id());
  res.set_header("X-Frame", std::to_string(fi));
  res.set_header("X-Scale", std::to_string(factor));
  char buf[64];
  if (!c.gt_error.empty()) {
    res.set_header("X-GT-Missing", Query::printable(c.gt_error));
  } else if (mode.is_index()) {
    std::snprintf(buf, sizeof buf, "%.6f", c.mae);
    res.set_header("X-MAE", buf);
  } else {
    std::snprintf(buf, sizeof buf, "%.4f", c.psnr);
    res.set_header("X-PSNR", buf);
  }
  if (what == "error") {
    std::snprintf(buf, sizeof buf, "%g", double(error_scale(mode)));
    res.set_header("X-Error-Scale", buf);
  }
  send_image(res, shown, fmt, quality);
}

inline void handle_info(ServerState& st, const httplib::Request& req, httplib::Response& res) {
  if (!req.params.empty()) bad_request("/api/info takes no parameters");
  const std::shared_ptr<const Scene> sc = st.scene();
  scene_headers(res, *sc);
  res.set_content(sc->info, "application/json");
}

inline void handle_live(ServerState& st, const httplib::Request& req, httplib::Response& res) {
  if (!st.live) throw ViewError(404, "not a live view: /api/live answers during msgs train --view");
  if (!req.params.empty()) bad_request("/api/live takes no parameters");
  res.set_content(st.live().dump(), "application/json");
}

/// Host header names that mean this machine: with the default loopback binding every other name
/// is refused, so a web page elsewhere cannot reach the server through DNS rebinding.
inline bool local_host_header(const std::string& host) {
  std::string h = host;
  if (!h.empty() && h[0] == '[') {
    const auto close = h.find(']');
    h = close == std::string::npos ? h : h.substr(0, close + 1);
  } else if (const auto colon = h.rfind(':'); colon != std::string::npos) {
    h = h.substr(0, colon);
  }
  return h == "127.0.0.1" || h == "localhost" || h == "[::1]";
}

inline bool loopback(const std::string& host) { return host == "127.0.0.1" || host == "localhost" || host == "::1"; }

/// The viewer's HTTP server on `st`: configure, bind, then listen (blocking) until stop().
class Server {
 public:
  Server(ServerState& st, std::string host, bool quiet) : st_(&st), host_(std::move(host)) {
    // httplib's default also sets SO_REUSEPORT, with which a second server (or another user's
    // process) could bind the same port and take a share of the connections. SO_REUSEADDR alone
    // still allows a quick restart on the port.
    svr_.set_socket_options([](socket_t sock) {
      int yes = 1;
      setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });
    svr_.set_payload_max_length(64 * 1024);  // nothing here takes a body
    svr_.set_read_timeout(10, 0);
    svr_.set_write_timeout(30, 0);
    const bool local = loopback(host_);
    svr_.set_pre_routing_handler([local](const httplib::Request& req, httplib::Response& res) {
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
    svr_.set_post_routing_handler([](const httplib::Request&, httplib::Response& res) {
      res.set_header("Cache-Control", "no-store");
      res.set_header("X-Content-Type-Options", "nosniff");
    });
    // Unknown paths (including ../ traversal: nothing is served from the file system) get a JSON 404.
    svr_.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
      if (res.body.empty())
        send_error(res, res.status, res.status == 404 ? "no such page: " + Query::printable(req.path) : "request failed");
    });
    svr_.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
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
      svr_.set_logger([name = st.name](const httplib::Request& req, const httplib::Response& res) {
        if (res.status < 400 || res.status == 503) return;  // 503: a live view before its first snapshot
        std::fprintf(stderr, "%s: %d %s %s: %s\n", name.c_str(), res.status, req.method.c_str(),
                     Query::printable(req.path).c_str(), res.get_header_value("X-Error").c_str());
      });

    // Every handler answers a ViewError with its status; anything else a render throws is a 500
    // and the server keeps serving.
    ServerState* s = st_;
    auto guarded = [s](void (*fn)(ServerState&, const httplib::Request&, httplib::Response&)) {
      return [s, fn](const httplib::Request& req, httplib::Response& res) {
        try {
          fn(*s, req, res);
        } catch (const ViewError& e) {
          send_error(res, e.status, e.what());
        } catch (const std::exception& e) {
          send_error(res, 500, std::string("internal error: ") + e.what());
        }
      };
    };
    svr_.Get("/", [](const httplib::Request&, httplib::Response& res) {
      res.set_header("Content-Security-Policy",
                     "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                     "img-src 'self' blob:; connect-src 'self'; base-uri 'none'; form-action 'none'");
      res.set_content(page_html, "text/html; charset=utf-8");
    });
    svr_.Get("/api/info", guarded(handle_info));
    svr_.Get("/api/live", guarded(handle_live));
    svr_.Get("/api/render", guarded(handle_render));
    svr_.Get("/api/frame", guarded(handle_frame));
  }

  /// Bind `port` (0: any free port); the bound port, or -1 when the port is taken or `host` is
  /// not an address of this machine.
  int bind(long port) {
    if (port == 0) port_ = svr_.bind_to_any_port(host_);
    else port_ = svr_.bind_to_port(host_, int(port)) ? int(port) : -1;
    if (port_ <= 0) port_ = -1;
    return port_;
  }
  /// Serve until stop(); false when the server stopped on an error.
  bool listen() { return svr_.listen_after_bind(); }
  void stop() { svr_.stop(); }
  bool local() const { return loopback(host_); }
  const std::string& host() const { return host_; }
  std::string url() const {
    const std::string h = host_.find(':') != std::string::npos ? "[" + host_ + "]" : host_;
    return "http://" + h + ":" + std::to_string(port_) + "/";
  }

 private:
  ServerState* st_;
  std::string host_;
  int port_ = -1;
  httplib::Server svr_;
};

}  // namespace msgs::view
