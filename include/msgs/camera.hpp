// include/msgs/camera.hpp
// Pinhole camera with its own intrinsics, resolution and world-to-camera pose (OpenCV axes:
// x right, y down, looking down +z), plus conversions from the OpenGL camera-to-world matrices
// that nerfstudio-style datasets store.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace msgs {

/// A pinhole camera. Pixel centres sit at (i + 0.5, j + 0.5); a camera-space point (x, y, z)
/// lands at (fx x / z + cx, fy y / z + cy).
template <class S = float>
struct Camera {
  using Mat3 = Eigen::Matrix<S, 3, 3>;
  using Vec3 = Eigen::Matrix<S, 3, 1>;

  S fx = 1, fy = 1;  ///< focal lengths in pixels
  S cx = 0, cy = 0;  ///< principal point in pixels
  int width = 1, height = 1;
  Mat3 R = Mat3::Identity();  ///< world-to-camera rotation
  Vec3 t = Vec3::Zero();      ///< world-to-camera translation: x_cam = R x_world + t
  S near_plane = S(0.01);     ///< Gaussians at depth <= near are culled
  S far_plane = S(1e10);      ///< Gaussians at depth > far are culled

  /// Camera centre in world coordinates, -R^T t.
  Vec3 position() const { return -(R.transpose() * t); }

  /// Throw std::invalid_argument when the camera cannot be rendered with.
  void validate() const {
    auto bad = [](const std::string& what) {
      throw std::invalid_argument("Camera: " + what);
    };
    if (width < 1 || height < 1)
      bad("width and height must be >= 1, got " + std::to_string(width) + "x" + std::to_string(height));
    if (!(std::isfinite(double(fx)) && std::isfinite(double(fy)) && fx > 0 && fy > 0))
      bad("fx and fy must be finite and > 0");
    if (!(std::isfinite(double(cx)) && std::isfinite(double(cy)))) bad("cx and cy must be finite");
    if (!R.allFinite() || !t.allFinite()) bad("pose must be finite");
    if (!(near_plane > 0) || !(far_plane > near_plane)) bad("need 0 < near < far");
  }

  /// The same camera with intrinsics and resolution divided by `factor` (images_2/4/8 folders).
  Camera downscaled(int factor) const {
    Camera c = *this;
    if (factor <= 1) return c;
    c.width = std::max(1, (width + factor - 1) / factor);
    c.height = std::max(1, (height + factor - 1) / factor);
    const S sx = S(c.width) / S(width), sy = S(c.height) / S(height);
    c.fx *= sx; c.cx *= sx;
    c.fy *= sy; c.cy *= sy;
    return c;
  }

  /// Build a camera from a 4x4 camera-to-world matrix in OpenGL axes (x right, y up, looking
  /// down -z), as in nerfstudio's transforms.json.
  static Camera from_opengl_c2w(const Eigen::Matrix<S, 4, 4>& c2w) {
    Mat3 rot = c2w.template block<3, 3>(0, 0);
    Vec3 pos = c2w.template block<3, 1>(0, 3);
    // OpenGL -> OpenCV camera axes: flip y and z.
    rot.col(1) = -rot.col(1);
    rot.col(2) = -rot.col(2);
    Camera c;
    c.R = rot.transpose();
    c.t = -(c.R * pos);
    return c;
  }

  /// The inverse of from_opengl_c2w: this camera's pose as an OpenGL camera-to-world matrix.
  Eigen::Matrix<S, 4, 4> opengl_c2w() const {
    Eigen::Matrix<S, 4, 4> m = Eigen::Matrix<S, 4, 4>::Identity();
    Mat3 rot = R.transpose();
    rot.col(1) = -rot.col(1);
    rot.col(2) = -rot.col(2);
    m.template block<3, 3>(0, 0) = rot;
    m.template block<3, 1>(0, 3) = position();
    return m;
  }

  /// Convert to another scalar type (double cameras for gradient checks).
  template <class T>
  Camera<T> cast() const {
    Camera<T> c;
    c.fx = T(fx); c.fy = T(fy); c.cx = T(cx); c.cy = T(cy);
    c.width = width; c.height = height;
    c.R = R.template cast<T>(); c.t = t.template cast<T>();
    c.near_plane = T(near_plane); c.far_plane = T(far_plane);
    return c;
  }
};

}  // namespace msgs
