// include/msgs/io/similarity.hpp
// The similarity transform (scale, rotation, translation) that best maps one set of points onto
// another in the least-squares sense (Umeyama 1991). A COLMAP model is the world up to such a
// transform, so camera centres compare with known positions (a synthetic scene's, or surveyed
// ones) only after it.
#pragma once

#include <Eigen/Core>
#include <Eigen/SVD>
#include <cstddef>
#include <stdexcept>
#include <vector>

namespace msgs::io {

/// x -> scale R x + t.
struct Similarity {
  double scale = 1;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return scale * (R * x) + t; }
};

/// The similarity minimising sum |dst_i - (scale R src_i + t)|^2, R a rotation (never a
/// reflection). std::invalid_argument when the sets differ in size, hold fewer than 3 points, or
/// `src` has no spread (all points at one place).
inline Similarity fit_similarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst) {
  if (src.size() != dst.size()) throw std::invalid_argument("fit_similarity: point sets of different sizes");
  if (src.size() < 3) throw std::invalid_argument("fit_similarity: at least 3 point pairs needed");
  const double n = double(src.size());
  Eigen::Vector3d mu_src = Eigen::Vector3d::Zero(), mu_dst = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < src.size(); ++i) {
    mu_src += src[i] / n;
    mu_dst += dst[i] / n;
  }
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var = 0;
  for (std::size_t i = 0; i < src.size(); ++i) {
    cov += (dst[i] - mu_dst) * (src[i] - mu_src).transpose() / n;
    var += (src[i] - mu_src).squaredNorm() / n;
  }
  if (!(var > 0)) throw std::invalid_argument("fit_similarity: the source points do not spread (all at one place)");
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d d(1, 1, (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1);
  Similarity s;
  s.R = svd.matrixU() * d.asDiagonal() * svd.matrixV().transpose();
  s.scale = svd.singularValues().dot(d) / var;
  s.t = mu_dst - s.scale * (s.R * mu_src);
  return s;
}

}  // namespace msgs::io
