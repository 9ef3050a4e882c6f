// include/msgs/project.hpp
// Stage 1 of the rasteriser: project one 3D Gaussian to a 2D screen-space Gaussian (EWA splatting,
// 3DGS/gsplat conventions) and its analytic backward, side by side. Internally double precision:
// it is per-Gaussian work (cheap next to blending), and it keeps extreme scales finite.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "camera.hpp"
#include "gaussian.hpp"
#include "detail/math.hpp"
#include "sh.hpp"

namespace msgs {

/// Constants of the projection stage (REFERENCE §6).
struct ProjectConstants {
  static constexpr double kDilation = 0.3;          ///< added to the diagonal of cov2d (low-pass filter)
  static constexpr double kFovClampMargin = 0.3;    ///< tan-fov clamp margin, fraction of tan(fov/2)
  static constexpr double kMinAlpha = 1.0 / 255.0;  ///< fragments below this alpha are skipped
  static constexpr double kLogScaleClamp = 50.0;    ///< |log-scale| beyond this is clamped (exp overflow)
  static constexpr double kMinQuatNorm = 1e-8;      ///< quaternions shorter than this are culled
  static constexpr double kMinCompensation = 0.005; ///< floor of the antialiasing opacity factor
};

/// Camera in the double form the projection uses.
struct ProjectCamera {
  Eigen::Matrix3d R;
  Eigen::Vector3d t, position;
  double fx, fy, cx, cy, near_plane, far_plane;
  int width, height;

  template <class S>
  static ProjectCamera from(const Camera<S>& c) {
    ProjectCamera p;
    p.R = c.R.template cast<double>();
    p.t = c.t.template cast<double>();
    p.position = -(p.R.transpose() * p.t);
    p.fx = double(c.fx); p.fy = double(c.fy); p.cx = double(c.cx); p.cy = double(c.cy);
    p.near_plane = double(c.near_plane); p.far_plane = double(c.far_plane);
    p.width = c.width; p.height = c.height;
    return p;
  }
};

/// The parameters of one Gaussian's geometry, gathered in double.
struct GaussianGeometry {
  Eigen::Vector3d mean;
  Eigen::Vector3d log_scale;
  Eigen::Vector4d quat;  // w, x, y, z (unnormalised)
  double opacity_logit;
};

/// Forward result of projecting one Gaussian.
struct ProjectedGaussian {
  bool visible = false;
  double mean2d[2] = {0, 0};  ///< pixel coordinates of the centre
  double conic[3] = {0, 0, 0};///< inverse of cov2d + dilation: (a, b, c) of [[a, b], [b, c]]
  double depth = 0;           ///< camera-space z
  double opacity = 0;         ///< sigmoid(logit), times the antialiasing factor when enabled
  double extent[2] = {0, 0};  ///< half-extent in pixels (x, y) of the region where alpha >= 1/255
};

namespace detail {

/// Rotation matrix of a unit quaternion (w, x, y, z).
inline Eigen::Matrix3d quat_to_rotation(const Eigen::Vector4d& q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix3d R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

/// dL/dq for a unit quaternion q given dL/dR.
inline Eigen::Vector4d quat_to_rotation_backward(const Eigen::Vector4d& q, const Eigen::Matrix3d& G) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Vector4d d;
  d[0] = 2 * (-z * G(0, 1) + y * G(0, 2) + z * G(1, 0) - x * G(1, 2) - y * G(2, 0) + x * G(2, 1));
  d[1] = 2 * (y * G(0, 1) + z * G(0, 2) + y * G(1, 0) - 2 * x * G(1, 1) - w * G(1, 2) + z * G(2, 0) +
              w * G(2, 1) - 2 * x * G(2, 2));
  d[2] = 2 * (-2 * y * G(0, 0) + x * G(0, 1) + w * G(0, 2) + x * G(1, 0) + z * G(1, 2) - w * G(2, 0) +
              z * G(2, 1) - 2 * y * G(2, 2));
  d[3] = 2 * (-2 * z * G(0, 0) - w * G(0, 1) + x * G(0, 2) + w * G(1, 0) - 2 * z * G(1, 1) + y * G(1, 2) +
              x * G(2, 0) + y * G(2, 1));
  return d;
}

/// Intermediate values of the projection that the backward pass reuses.
struct ProjectionCache {
  Eigen::Vector4d qhat;      // normalised quaternion
  double qnorm;
  Eigen::Vector3d scale;     // exp(clamped log-scale)
  Eigen::Vector3d scale_active;  // 1 where the log-scale was not clamped
  Eigen::Matrix3d Rq;        // rotation of the Gaussian
  Eigen::Matrix3d M;         // Rq * diag(scale)
  Eigen::Matrix3d cov_cam;   // W Sigma W^T
  Eigen::Vector3d tcam;      // camera-space mean
  double lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;
  double txz, tyz;           // tx / tz, ty / tz before clamping
  Eigen::Matrix<double, 2, 3> J;
  Eigen::Matrix2d cov2d;     // before dilation
  Eigen::Matrix2d cov2d_blur;// after dilation
  double det_blur, det_orig;
  double compensation;       // antialiasing factor (1 when disabled)
  bool compensation_floored;
  double sig;                // sigmoid(logit)
};

}  // namespace detail

/// Project one Gaussian. Returns false (and `out.visible = false`) when the Gaussian is culled:
/// non-finite parameters, degenerate quaternion, outside (near, far], invisible opacity,
/// degenerate screen covariance, or entirely off-screen. `Antialiased` multiplies the opacity by
/// sqrt(det cov2d / det(cov2d + 0.3 I)) (floored at 0.005), gsplat's antialiased mode.
template <bool Antialiased>
inline bool project_fwd(const GaussianGeometry& g, const ProjectCamera& cam, ProjectedGaussian& out,
                        detail::ProjectionCache* cache_out = nullptr) {
  using PC = ProjectConstants;
  out.visible = false;
  if (!g.mean.allFinite() || !g.log_scale.allFinite() || !g.quat.allFinite() || !std::isfinite(g.opacity_logit))
    return false;
  detail::ProjectionCache c;
  c.tcam = cam.R * g.mean + cam.t;
  const double tz = c.tcam.z();
  if (!(tz > cam.near_plane) || tz > cam.far_plane) return false;

  c.qnorm = g.quat.norm();
  if (!(c.qnorm >= PC::kMinQuatNorm)) return false;
  c.qhat = g.quat / c.qnorm;

  c.sig = detail::sigmoid(g.opacity_logit);
  if (!(c.sig >= PC::kMinAlpha)) return false;

  // Tan-fov clamp limits (generalised for off-centre principal points).
  const double tan_fovx = 0.5 * cam.width / cam.fx, tan_fovy = 0.5 * cam.height / cam.fy;
  c.lim_x_pos = (cam.width - cam.cx) / cam.fx + PC::kFovClampMargin * tan_fovx;
  c.lim_x_neg = cam.cx / cam.fx + PC::kFovClampMargin * tan_fovx;
  c.lim_y_pos = (cam.height - cam.cy) / cam.fy + PC::kFovClampMargin * tan_fovy;
  c.lim_y_neg = cam.cy / cam.fy + PC::kFovClampMargin * tan_fovy;
  c.txz = c.tcam.x() / tz;
  c.tyz = c.tcam.y() / tz;
  const double txc = std::min(c.lim_x_pos, std::max(-c.lim_x_neg, c.txz));
  const double tyc = std::min(c.lim_y_pos, std::max(-c.lim_y_neg, c.tyz));
  const double mean_x = cam.fx * c.txz + cam.cx, mean_y = cam.fy * c.tyz + cam.cy;

  // Far off-screen? Most Gaussians of a large scene are outside any one view, so bound the screen
  // extent before building the covariance: cov2d(0,0) = j0^T cov_cam j0 <= s_max^2 |j0|^2 with
  // |j0|^2 = (fx/tz)^2 (1 + txc^2), and the antialiasing compensation only lowers the opacity.
  // A Gaussian culled here is one the exact test below would cull too.
  {
    const double smax = std::exp(std::clamp(g.log_scale.maxCoeff(), -PC::kLogScaleClamp, PC::kLogScaleClamp));
    const double kb = std::sqrt(std::max(0.0, 2.0 * std::log(c.sig / PC::kMinAlpha)));
    const double sx = smax * cam.fx / tz, sy = smax * cam.fy / tz;
    const double bx = kb * std::sqrt(sx * sx * (1.0 + txc * txc) + PC::kDilation) * (1.0 + 1e-6) + 1e-6;
    const double by = kb * std::sqrt(sy * sy * (1.0 + tyc * tyc) + PC::kDilation) * (1.0 + 1e-6) + 1e-6;
    if (mean_x + bx < -1.0 || mean_x - bx > cam.width + 1.0 || mean_y + by < -1.0 || mean_y - by > cam.height + 1.0)
      return false;
  }

  for (int i = 0; i < 3; ++i) {
    const double ls = g.log_scale[i];
    const double cl = std::clamp(ls, -PC::kLogScaleClamp, PC::kLogScaleClamp);
    c.scale_active[i] = (ls == cl) ? 1.0 : 0.0;
    c.scale[i] = std::exp(cl);
  }
  c.Rq = detail::quat_to_rotation(c.qhat);
  c.M = c.Rq * c.scale.asDiagonal();
  // cov_cam = W Sigma W^T = (W M)(W M)^T: one 3x3 product and a symmetric one instead of four.
  const Eigen::Matrix3d WM = cam.R * c.M;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j <= i; ++j) c.cov_cam(i, j) = c.cov_cam(j, i) = WM.row(i).dot(WM.row(j));

  // EWA Jacobian with the generalised tan-fov clamp.
  const double tx = tz * txc;
  const double ty = tz * tyc;
  c.J << cam.fx / tz, 0, -cam.fx * tx / (tz * tz),
         0, cam.fy / tz, -cam.fy * ty / (tz * tz);
  // cov2d = J cov_cam J^T = (J W M)(J W M)^T, with J's zeros skipped; symmetric by construction.
  const Eigen::RowVector3d T0 = c.J(0, 0) * WM.row(0) + c.J(0, 2) * WM.row(2);
  const Eigen::RowVector3d T1 = c.J(1, 1) * WM.row(1) + c.J(1, 2) * WM.row(2);
  c.cov2d(0, 0) = T0.dot(T0);
  c.cov2d(1, 1) = T1.dot(T1);
  c.cov2d(0, 1) = c.cov2d(1, 0) = T0.dot(T1);
  c.cov2d_blur = c.cov2d;
  c.cov2d_blur(0, 0) += PC::kDilation;
  c.cov2d_blur(1, 1) += PC::kDilation;
  c.det_blur = c.cov2d_blur(0, 0) * c.cov2d_blur(1, 1) - c.cov2d_blur(0, 1) * c.cov2d_blur(0, 1);
  if (!(c.det_blur > 0) || !std::isfinite(c.det_blur)) return false;

  c.compensation = 1.0;
  c.compensation_floored = false;
  c.det_orig = c.cov2d(0, 0) * c.cov2d(1, 1) - c.cov2d(0, 1) * c.cov2d(0, 1);
  if constexpr (Antialiased) {
    const double comp = std::sqrt(std::max(0.0, c.det_orig / c.det_blur));
    c.compensation_floored = !(comp > PC::kMinCompensation);
    c.compensation = c.compensation_floored ? PC::kMinCompensation : comp;
  }
  const double opacity = c.sig * c.compensation;
  if (!(opacity >= PC::kMinAlpha)) return false;

  out.mean2d[0] = mean_x;
  out.mean2d[1] = mean_y;
  out.conic[0] = c.cov2d_blur(1, 1) / c.det_blur;
  out.conic[1] = -c.cov2d_blur(0, 1) / c.det_blur;
  out.conic[2] = c.cov2d_blur(0, 0) / c.det_blur;
  out.depth = tz;
  out.opacity = opacity;
  // alpha >= 1/255  <=>  sigma <= ln(255 o): the exact support, no 3-sigma cut-off, so the tiled
  // renderer paints exactly what a per-pixel loop over all Gaussians would.
  const double k2 = 2.0 * std::log(opacity / PC::kMinAlpha);
  const double k = std::sqrt(std::max(0.0, k2));
  out.extent[0] = k * std::sqrt(c.cov2d_blur(0, 0));
  out.extent[1] = k * std::sqrt(c.cov2d_blur(1, 1));
  if (!std::isfinite(out.mean2d[0]) || !std::isfinite(out.mean2d[1]) || !std::isfinite(out.extent[0]) ||
      !std::isfinite(out.extent[1]))
    return false;
  // Entirely off-screen (with a pixel of margin)?
  if (out.mean2d[0] + out.extent[0] < -1.0 || out.mean2d[0] - out.extent[0] > cam.width + 1.0 ||
      out.mean2d[1] + out.extent[1] < -1.0 || out.mean2d[1] - out.extent[1] > cam.height + 1.0)
    return false;
  out.visible = true;
  if (cache_out) *cache_out = c;
  return true;
}

/// Screen-space gradients flowing into the projection backward.
struct ProjectedGrad {
  double mean2d[2] = {0, 0};
  double conic[3] = {0, 0, 0};  ///< dL/da, dL/db, dL/dc of sigma = 0.5(a dx^2 + c dy^2) + b dx dy
  double opacity = 0;           ///< dL/d(effective opacity)
  double depth = 0;             ///< dL/d(camera z) from the depth output
};

/// Gradients of one Gaussian's geometry parameters.
struct GeometryGrad {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d log_scale = Eigen::Vector3d::Zero();
  Eigen::Vector4d quat = Eigen::Vector4d::Zero();
  double opacity_logit = 0;
};

/// Backward of project_fwd: accumulates into `grad` the gradient of the loss with respect to the
/// Gaussian's parameters, given the gradients `v` of its screen-space quantities.
template <bool Antialiased>
inline void project_bwd(const GaussianGeometry& g, const ProjectCamera& cam, const ProjectedGrad& v,
                        GeometryGrad& grad) {
  ProjectedGaussian out;
  detail::ProjectionCache c;
  if (!project_fwd<Antialiased>(g, cam, out, &c)) return;
  const double tz = c.tcam.z();

  // Opacity: o = sigmoid(logit) * compensation.
  grad.opacity_logit += v.opacity * c.compensation * c.sig * (1.0 - c.sig);

  // Conic = inverse(cov2d_blur): dL/dCov = -Q^T dL/dQ Q^T with Q symmetric; b appears twice in Q.
  Eigen::Matrix2d Q;
  Q << out.conic[0], out.conic[1], out.conic[1], out.conic[2];
  Eigen::Matrix2d vQ;
  vQ << v.conic[0], 0.5 * v.conic[1], 0.5 * v.conic[1], v.conic[2];
  Eigen::Matrix2d v_cov = -(Q * vQ * Q);  // gradient w.r.t. cov2d_blur (full symmetric matrix)

  if constexpr (Antialiased) {
    if (!c.compensation_floored) {
      // compensation = sqrt(det_orig / det_blur); d det(A)/dA = det(A) A^{-T}.
      const double v_comp = v.opacity * c.sig;
      const double r = c.det_orig / c.det_blur;
      const double v_r = v_comp * 0.5 / std::sqrt(r);
      Eigen::Matrix2d adj_orig, adj_blur;
      adj_orig << c.cov2d(1, 1), -c.cov2d(0, 1), -c.cov2d(0, 1), c.cov2d(0, 0);
      adj_blur << c.cov2d_blur(1, 1), -c.cov2d_blur(0, 1), -c.cov2d_blur(0, 1), c.cov2d_blur(0, 0);
      // r depends on cov2d through both determinants (cov2d_blur = cov2d + 0.3 I).
      v_cov += v_r * (adj_orig / c.det_blur - c.det_orig / (c.det_blur * c.det_blur) * adj_blur);
    }
  }

  // cov2d = J C J^T  ->  dL/dC = J^T G J, dL/dJ = 2 G J C (G, C symmetric).
  const Eigen::Matrix3d v_cov_cam = c.J.transpose() * v_cov * c.J;
  const Eigen::Matrix<double, 2, 3> v_J = 2.0 * v_cov * c.J * c.cov_cam;

  // J entries -> camera-space mean (clamped components only depend on tz).
  Eigen::Vector3d v_t = Eigen::Vector3d::Zero();
  const double tz2 = tz * tz, tz3 = tz2 * tz;
  v_t.z() += -cam.fx / tz2 * v_J(0, 0) - cam.fy / tz2 * v_J(1, 1);
  const bool x_clamped = c.txz > c.lim_x_pos || c.txz < -c.lim_x_neg;
  const bool y_clamped = c.tyz > c.lim_y_pos || c.tyz < -c.lim_y_neg;
  if (x_clamped) {
    const double L = std::min(c.lim_x_pos, std::max(-c.lim_x_neg, c.txz));
    v_t.z() += cam.fx * L / tz2 * v_J(0, 2);  // J02 = -fx L / tz
  } else {
    v_t.x() += -cam.fx / tz2 * v_J(0, 2);
    v_t.z() += 2.0 * cam.fx * c.tcam.x() / tz3 * v_J(0, 2);
  }
  if (y_clamped) {
    const double L = std::min(c.lim_y_pos, std::max(-c.lim_y_neg, c.tyz));
    v_t.z() += cam.fy * L / tz2 * v_J(1, 2);
  } else {
    v_t.y() += -cam.fy / tz2 * v_J(1, 2);
    v_t.z() += 2.0 * cam.fy * c.tcam.y() / tz3 * v_J(1, 2);
  }
  // Projected mean (unclamped).
  v_t.x() += cam.fx / tz * v.mean2d[0];
  v_t.y() += cam.fy / tz * v.mean2d[1];
  v_t.z() += -cam.fx * c.tcam.x() / tz2 * v.mean2d[0] - cam.fy * c.tcam.y() / tz2 * v.mean2d[1];
  v_t.z() += v.depth;
  grad.mean += cam.R.transpose() * v_t;

  // cov_cam = W Sigma W^T; Sigma = M M^T with M = Rq diag(s).
  const Eigen::Matrix3d v_sigma = cam.R.transpose() * v_cov_cam * cam.R;
  const Eigen::Matrix3d v_M = 2.0 * v_sigma * c.M;
  for (int j = 0; j < 3; ++j) {
    const double v_s = c.Rq.col(j).dot(v_M.col(j));
    grad.log_scale[j] += v_s * c.scale[j] * c.scale_active[j];
  }
  const Eigen::Matrix3d v_Rq = v_M * c.scale.asDiagonal();
  const Eigen::Vector4d v_qhat = detail::quat_to_rotation_backward(c.qhat, v_Rq);
  grad.quat += (v_qhat - c.qhat * c.qhat.dot(v_qhat)) / c.qnorm;
}

/// Colour of one Gaussian for channels [first, first + count): SH (degree `deg`) evaluated along
/// the unit view direction `dir`, plus 0.5, clamped at 0. `sh` points at the Gaussian's
/// coefficients laid out [K, bands].
template <class S>
inline void colour_fwd(const S* sh, int bands, int first, int count, int deg, const double dir[3], double* out) {
  double Y[sh::kMaxCoeffs];
  sh::basis(deg, dir[0], dir[1], dir[2], Y);
  const int K = sh_coeffs_for_degree(deg);
  for (int ch = 0; ch < count; ++ch) {
    double v = 0.5;
    for (int k = 0; k < K; ++k) v += double(sh[k * bands + first + ch]) * Y[k];
    out[ch] = v > 0.0 ? v : 0.0;
  }
}

/// Backward of colour_fwd: writes dL/dSH for the rendered channels (`v_sh`, same layout as `sh`)
/// and accumulates dL/d(mean) through the view direction `raw_dir` = mean - camera position.
template <class S>
inline void colour_bwd(const S* sh, int bands, int first, int count, int deg, const Eigen::Vector3d& raw_dir,
                       const double* v_colour, S* v_sh, Eigen::Vector3d& v_mean) {
  const double len = raw_dir.norm();
  double dir[3] = {0, 0, 1};
  if (len > 0 && std::isfinite(len)) { dir[0] = raw_dir[0] / len; dir[1] = raw_dir[1] / len; dir[2] = raw_dir[2] / len; }
  double Y[sh::kMaxCoeffs];
  sh::basis(deg, dir[0], dir[1], dir[2], Y);
  const int K = sh_coeffs_for_degree(deg);
  double dY[sh::kMaxCoeffs] = {};
  for (int ch = 0; ch < count; ++ch) {
    double v = 0.5;
    for (int k = 0; k < K; ++k) v += double(sh[k * bands + first + ch]) * Y[k];
    const double g = v > 0.0 ? v_colour[ch] : 0.0;
    for (int k = 0; k < K; ++k) {
      v_sh[k * bands + first + ch] = S(g * Y[k]);
      dY[k] += g * double(sh[k * bands + first + ch]);
    }
  }
  if (deg < 1 || !(len > 0) || !std::isfinite(len)) return;
  double gdir[3] = {0, 0, 0};
  sh::basis_backward(deg, dir[0], dir[1], dir[2], dY, gdir);
  const Eigen::Vector3d gd(gdir[0], gdir[1], gdir[2]);
  const Eigen::Vector3d d(dir[0], dir[1], dir[2]);
  v_mean += (gd - d * d.dot(gd)) / len;
}

}  // namespace msgs
