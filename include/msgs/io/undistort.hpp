// include/msgs/io/undistort.hpp
// Lens distortion of nerfstudio/OpenCV cameras (radial k1..k4 + tangential p1, p2, and the
// fisheye variant) and undistortion of images into the matching pinhole camera at load time.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>

#include "msgs/camera.hpp"
#include "msgs/image.hpp"
#include "msgs/io/error.hpp"

namespace msgs::io {

/// Distortion parameters in normalised camera coordinates (x = X/Z, y = Y/Z), so they do not
/// change when the image is downscaled.
///  - `opencv`: r2 = x² + y², d = 1 + k1 r2 + k2 r2² + k3 r2³ + k4 r2⁴,
///    x' = x d + 2 p1 x y + p2 (r2 + 2x²), y' = y d + p1 (r2 + 2y²) + 2 p2 x y
///    (OpenCV's model; nerfstudio stores k4 as the r⁸ term of the same polynomial).
///  - `rational`: COLMAP's FULL_OPENCV, OpenCV's rational model: d = (1 + k1 r2 + k2 r2² + k3 r2³) /
///    (1 + k4 r2 + k5 r2² + k6 r2³), tangential terms as `opencv`.
///  - `fisheye`: θ = atan(r), θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), (x', y') = (θd / r) (x, y).
struct Distortion {
  enum class Model { none, opencv, fisheye, rational };
  Model model = Model::none;
  double k1 = 0, k2 = 0, k3 = 0, k4 = 0, p1 = 0, p2 = 0;
  double k5 = 0, k6 = 0;  ///< `rational` only: the r2² and r2³ terms of the denominator

  /// True when applying the model changes nothing.
  bool is_identity() const {
    return model == Model::none || (k1 == 0 && k2 == 0 && k3 == 0 && k4 == 0 && k5 == 0 && k6 == 0 &&
                                    (model == Model::fisheye || (p1 == 0 && p2 == 0)));
  }

  /// Map an undistorted normalised point to where the lens puts it.
  void distort(double x, double y, double& xd, double& yd) const {
    if (model == Model::opencv || model == Model::rational) {
      const double r2 = x * x + y * y;
      const double d = model == Model::opencv ? 1 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
                                              : (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)));
      xd = x * d + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
      yd = y * d + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
    } else if (model == Model::fisheye) {
      const double r = std::sqrt(x * x + y * y);
      if (r < 1e-12) { xd = x; yd = y; return; }
      const double th = std::atan(r), t2 = th * th;
      const double thd = th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
      xd = x * thd / r;
      yd = y * thd / r;
    } else {
      xd = x; yd = y;
    }
  }

  /// Invert distort() by Newton's method with a numerical Jacobian (a few iterations suffice for
  /// lens-sized distortions). Returns false when it does not converge; (x, y) then holds the
  /// last iterate, which is always finite.
  bool undistort(double xd, double yd, double& x, double& y) const {
    x = xd; y = yd;
    if (is_identity()) return true;
    for (int it = 0; it < 50; ++it) {
      double fx, fy;
      distort(x, y, fx, fy);
      const double ex = fx - xd, ey = fy - yd;
      if (std::abs(ex) + std::abs(ey) < 1e-13) return true;
      const double h = 1e-7;
      double ax, ay, bx, by;
      distort(x + h, y, ax, ay);
      distort(x, y + h, bx, by);
      const double j00 = (ax - fx) / h, j10 = (ay - fy) / h, j01 = (bx - fx) / h, j11 = (by - fy) / h;
      const double det = j00 * j11 - j01 * j10;
      if (!(std::abs(det) > 1e-12) || !std::isfinite(det)) return false;
      const double nx = x - (j11 * ex - j01 * ey) / det, ny = y - (-j10 * ex + j00 * ey) / det;
      if (!std::isfinite(nx) || !std::isfinite(ny)) return false;
      x = nx; y = ny;
    }
    double fx, fy;
    distort(x, y, fx, fy);
    return std::abs(fx - xd) + std::abs(fy - yd) < 1e-9;
  }
};

/// Sample `img` bilinearly at continuous pixel coordinates (u, v), where pixel i covers [i, i + 1)
/// and its centre is i + 0.5. Coordinates outside the image take the nearest edge pixel.
inline void sample_bilinear(const Image<float>& img, double u, double v, float* out) {
  const double fx = std::clamp(u - 0.5, 0.0, double(img.width - 1));
  const double fy = std::clamp(v - 0.5, 0.0, double(img.height - 1));
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  const int x1 = std::min(x0 + 1, img.width - 1), y1 = std::min(y0 + 1, img.height - 1);
  const double ax = fx - x0, ay = fy - y0;
  for (int c = 0; c < img.channels; ++c) {
    const double top = (1 - ax) * img.at(x0, y0, c) + ax * img.at(x1, y0, c);
    const double bot = (1 - ax) * img.at(x0, y1, c) + ax * img.at(x1, y1, c);
    out[c] = static_cast<float>((1 - ay) * top + ay * bot);
  }
}

/// True when bilinear sampling at (u, v) interpolates between real pixels, without edge clamping.
inline bool sample_is_interior(double u, double v, int width, int height) {
  return u >= 0.5 && v >= 0.5 && u <= width - 0.5 && v <= height - 0.5;
}

/// Resample an image taken through `src` (pinhole intrinsics + `dist`) into the distortion-free
/// pinhole camera `dst` (same pose; usually the same intrinsics, see undistorted_camera). Each
/// output pixel centre is mapped through the inverse pinhole of `dst`, the lens model and the
/// pinhole of `src`, then sampled bilinearly. Samples that fall outside the source take the
/// nearest edge pixel; `valid` (optional, 1 channel) marks the pixels sampled without clamping.
inline Image<float> undistort_image(const Image<float>& img, const Camera<float>& src, const Distortion& dist,
                                    const Camera<float>& dst, Image<float>* valid = nullptr) {
  if (img.width != src.width || img.height != src.height)
    throw IoError(cat("undistort_image: image is ", img.width, "x", img.height, " but its camera says ", src.width,
                      "x", src.height));
  Image<float> out(dst.width, dst.height, img.channels);
  if (valid) valid->reset(dst.width, dst.height, 1, 0.0f);
  for (int v = 0; v < dst.height; ++v)
    for (int u = 0; u < dst.width; ++u) {
      const double x = (u + 0.5 - double(dst.cx)) / double(dst.fx), y = (v + 0.5 - double(dst.cy)) / double(dst.fy);
      double xd, yd;
      dist.distort(x, y, xd, yd);
      double us = double(src.fx) * xd + double(src.cx), vs = double(src.fy) * yd + double(src.cy);
      if (!std::isfinite(us) || !std::isfinite(vs)) { us = -1; vs = -1; }
      sample_bilinear(img, us, vs, &out.at(u, v, 0));
      if (valid)
        valid->at(u, v, 0) = sample_is_interior(us, vs, img.width, img.height) ? 1.0f : 0.0f;
    }
  return out;
}

/// Undistort into a pinhole camera with the same intrinsics and size.
inline Image<float> undistort_image(const Image<float>& img, const Camera<float>& cam, const Distortion& dist,
                                    Image<float>* valid = nullptr) {
  return undistort_image(img, cam, dist, cam, valid);
}

/// The pinhole camera to undistort into. With `zoom` false, the intrinsics are kept (a pincushion
/// (k1 > 0) lens then leaves edge-replicated pixels near the corners). With `zoom` true, the focal lengths
/// grow by the smallest factor that makes every output border pixel land inside the source image,
/// like OpenCV's getOptimalNewCameraMatrix with alpha = 0 but without changing the size.
inline Camera<float> undistorted_camera(const Camera<float>& cam, const Distortion& dist, bool zoom) {
  Camera<float> out = cam;
  if (!zoom || dist.is_identity()) return out;
  auto all_inside = [&](double s) {
    const int W = cam.width, H = cam.height;
    auto inside = [&](double u, double v) {
      const double x = (u - double(cam.cx)) / (double(cam.fx) * s), y = (v - double(cam.cy)) / (double(cam.fy) * s);
      double xd, yd;
      dist.distort(x, y, xd, yd);
      const double us = double(cam.fx) * xd + double(cam.cx), vs = double(cam.fy) * yd + double(cam.cy);
      return sample_is_interior(us, vs, W, H);
    };
    const int steps = 64;
    for (int i = 0; i <= steps; ++i) {
      const double a = double(i) / steps;
      if (!inside(a * W, 0.5) || !inside(a * W, H - 0.5) || !inside(0.5, a * H) || !inside(W - 0.5, a * H)) return false;
    }
    return true;
  };
  double lo = 1.0, hi = 1.0;
  if (all_inside(1.0)) return out;
  while (!all_inside(hi)) {
    hi *= 1.5;
    if (hi > 100) throw IoError("undistorted_camera: distortion too strong to fit the image");
  }
  for (int i = 0; i < 40; ++i) {
    const double mid = 0.5 * (lo + hi);
    (all_inside(mid) ? hi : lo) = mid;
  }
  out.fx = static_cast<float>(cam.fx * hi);
  out.fy = static_cast<float>(cam.fy * hi);
  return out;
}

}  // namespace msgs::io
