// include/msgs/init.hpp
// Initial Gaussians from a sparse point cloud (kNN scales via nanoflann) or at random in a box, as REFERENCE §3.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <nanoflann.hpp>

#include "msgs/gaussian.hpp"

namespace msgs {

/// Settings of the initialisation. Defaults: the multi-spectral implementation (splatfacto).
struct InitConfig {
  double initial_opacity = 0.1;  ///< stored as its logit
  int knn = 3;                   ///< the initial scale is the mean distance to this many nearest neighbours
  /// Floor of that mean distance, so duplicated points (distance 0) get a finite log-scale. The value is
  /// sqrt(1e-7), the floor 3DGS puts on the squared distance.
  double min_distance = 3.1622776601683795e-4;
  /// Mean distance used for a cloud of a single point, which has no neighbour at all.
  double isolated_distance = 0.01;
  std::uint32_t seed = 0;  ///< seeds the SH DC colours (and the points of init_random)
};

namespace detail {

/// nanoflann dataset over a flat float array [N, 3]; coordinates are handed out as double so that the
/// tree and the distances it compares are in double.
struct PointCloudAdaptor {
  const float* xyz;
  std::size_t n;
  std::size_t kdtree_get_point_count() const { return n; }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return static_cast<double>(xyz[3 * i + d]); }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const { return false; }
};

/// Uniform float in [0, 1) from the top 24 bits of one mt19937 draw: identical on every standard library
/// (std::uniform_real_distribution is not).
inline float uniform01(std::mt19937& rng) { return static_cast<float>(rng() >> 8) * 0x1p-24f; }

inline void check_points(const std::vector<float>& xyz, const char* who) {
  if (xyz.size() % 3 != 0)
    throw std::invalid_argument(std::string(who) + ": xyz has " + std::to_string(xyz.size()) +
                                " values, expected a multiple of 3 ([N, 3])");
  for (std::size_t i = 0; i < xyz.size(); ++i)
    if (!std::isfinite(xyz[i]))
      throw std::invalid_argument(std::string(who) + ": xyz point " + std::to_string(i / 3) + " coordinate " +
                                  std::to_string(i % 3) + " is not finite");
}

}  // namespace detail

/// Mean Euclidean distance from each point of `xyz` [N, 3] to its `k` nearest OTHER points ([N], double),
/// exact kNN with a nanoflann kd-tree. With fewer than k other points, the mean over those there are;
/// a lone point gets 0. Duplicates count as neighbours at distance 0. Deterministic: the tree is built
/// single-threaded and each point's query is independent.
inline std::vector<double> knn_mean_distance(const std::vector<float>& xyz, int k) {
  detail::check_points(xyz, "knn_mean_distance");
  if (k < 1) throw std::invalid_argument("knn_mean_distance: k = " + std::to_string(k) + ", expected >= 1");
  const std::size_t n = xyz.size() / 3;
  std::vector<double> out(n, 0.0);
  if (n < 2) return out;
  using Adaptor = detail::PointCloudAdaptor;
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Adaptor, double>, Adaptor, 3>;
  const Adaptor cloud{xyz.data(), n};
  Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  // One more than k: the query point itself (or a duplicate of it) comes back at distance 0.
  const std::size_t want = std::min<std::size_t>(static_cast<std::size_t>(k) + 1, n);
  const std::ptrdiff_t nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel
  {
    std::vector<std::uint32_t> idx(want);
    std::vector<double> d2(want), dist(want);
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < nn; ++i) {
      const double q[3] = {cloud.kdtree_get_pt(static_cast<std::size_t>(i), 0),
                           cloud.kdtree_get_pt(static_cast<std::size_t>(i), 1),
                           cloud.kdtree_get_pt(static_cast<std::size_t>(i), 2)};
      const std::size_t got = tree.knnSearch(q, want, idx.data(), d2.data());
      for (std::size_t j = 0; j < got; ++j) dist[j] = std::sqrt(d2[j]);
      std::sort(dist.begin(), dist.begin() + static_cast<std::ptrdiff_t>(got));
      // The smallest is the zero distance of the point to itself (or to an identical point, which
      // leaves the same multiset of distances): drop it.
      double sum = 0;
      for (std::size_t j = 1; j < got; ++j) sum += dist[j];
      out[static_cast<std::size_t>(i)] = got > 1 ? sum / static_cast<double>(got - 1) : 0.0;
    }
  }
  return out;
}

/// Gaussians at the points of a sparse cloud `xyz` [N, 3] (REFERENCE §3): isotropic log-scale of the
/// (floored) mean distance to the `cfg.knn` nearest neighbours, identity rotation, opacity
/// logit(cfg.initial_opacity), SH DC of every channel uniform in [0, 1) from mt19937(cfg.seed), higher
/// orders 0. Throws std::invalid_argument on a malformed or non-finite cloud.
template <class G>
GaussianModel<G, float> init_from_points(const std::vector<float>& xyz, const InitConfig& cfg = {}) {
  detail::check_points(xyz, "init_from_points");
  if (!(cfg.initial_opacity > 0.0 && cfg.initial_opacity < 1.0))
    throw std::invalid_argument("init_from_points: initial_opacity = " + std::to_string(cfg.initial_opacity) +
                                ", expected a value in (0, 1)");
  if (!(cfg.min_distance > 0.0) || !(cfg.isolated_distance > 0.0))
    throw std::invalid_argument("init_from_points: min_distance and isolated_distance must be > 0");
  const std::size_t n = xyz.size() / 3;
  GaussianModel<G, float> m(n);
  if (n == 0) return m;
  const std::vector<double> dist = knn_mean_distance(xyz, cfg.knn);
  const float logit = static_cast<float>(std::log(cfg.initial_opacity / (1.0 - cfg.initial_opacity)));
  std::mt19937 rng(cfg.seed);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) m.means[3 * i + static_cast<std::size_t>(a)] = xyz[3 * i + static_cast<std::size_t>(a)];
    const double d = n == 1 ? cfg.isolated_distance : std::max(dist[i], cfg.min_distance);
    const float ls = static_cast<float>(std::log(d));
    for (int a = 0; a < 3; ++a) m.log_scales[3 * i + static_cast<std::size_t>(a)] = ls;
    m.quats[4 * i] = 1.0f;  // w; x, y, z stay 0
    m.opacity_logits[i] = logit;
    for (int c = 0; c < G::bands; ++c) m.sh_at(i, 0, c) = detail::uniform01(rng);  // higher orders stay 0
  }
  return m;
}

/// `n` Gaussians at points uniform in the box [box_min, box_max] (for scenes without a point cloud),
/// otherwise initialised as `init_from_points`. Points and colours come from two generators derived
/// from `cfg.seed`, so both are reproducible.
template <class G>
GaussianModel<G, float> init_random(std::size_t n, const std::array<float, 3>& box_min,
                                    const std::array<float, 3>& box_max, const InitConfig& cfg = {}) {
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(box_min[static_cast<std::size_t>(a)]) || !std::isfinite(box_max[static_cast<std::size_t>(a)]) ||
        !(box_min[static_cast<std::size_t>(a)] <= box_max[static_cast<std::size_t>(a)]))
      throw std::invalid_argument("init_random: box axis " + std::to_string(a) +
                                  " needs finite box_min <= box_max");
  std::seed_seq seq{cfg.seed, 0x9e3779b9u};
  std::mt19937 rng(seq);
  std::vector<float> xyz(3 * n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < 3; ++a) {
      const float lo = box_min[a], hi = box_max[a];
      xyz[3 * i + a] = std::min(hi, lo + (hi - lo) * detail::uniform01(rng));  // min: rounding may land on hi
    }
  return init_from_points<G>(xyz, cfg);
}

}  // namespace msgs
