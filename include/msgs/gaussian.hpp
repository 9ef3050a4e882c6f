// include/msgs/gaussian.hpp
// Gaussian<Bands, SHDeg>: the compile-time description of one splat, its traits, and the
// structure-of-arrays model container. Every compile-time size in msgs comes from here.
#pragma once

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <type_traits>
#include <string>
#include <vector>

namespace msgs {

/// Compile-time description of a Gaussian primitive with `Bands` colour channels and spherical
/// harmonics up to degree `SHDeg`. A Separate RGB model is `Gaussian<3, 3>`, a single narrow band
/// `Gaussian<1, 3>`, a Joint model `Gaussian<7, 3>`.
template <int Bands, int SHDeg>
struct Gaussian {
  static_assert(Bands >= 1, "a Gaussian needs at least one colour channel");
  static_assert(SHDeg >= 0 && SHDeg <= 3, "spherical harmonics degree must be 0..3");
  /// Number of colour channels carried by each Gaussian.
  static constexpr int bands = Bands;
  /// Highest spherical-harmonics degree.
  static constexpr int sh_degree = SHDeg;
  /// SH coefficients per channel: (SHDeg + 1)^2.
  static constexpr int sh_coeffs = (SHDeg + 1) * (SHDeg + 1);
  /// Floats of SH per Gaussian: coefficients x channels.
  static constexpr int sh_floats = sh_coeffs * Bands;
  /// Scalars per Gaussian: mean 3, log-scale 3, quaternion 4, opacity logit 1, SH.
  static constexpr int params = 3 + 3 + 4 + 1 + sh_floats;
};

/// Number of SH coefficients per channel for degree `deg` (runtime or compile time).
constexpr int sh_coeffs_for_degree(int deg) { return (deg + 1) * (deg + 1); }

/// Colour channels of a Gaussian type.
template <class G> inline constexpr int bands_v = G::bands;
/// SH degree of a Gaussian type.
template <class G> inline constexpr int sh_degree_v = G::sh_degree;
/// SH coefficients per channel of a Gaussian type.
template <class G> inline constexpr int sh_coeffs_v = G::sh_coeffs;

/// Trait: is `T` an instantiation of `Gaussian`?
template <class T> struct is_gaussian : std::false_type {};
template <int B, int D> struct is_gaussian<Gaussian<B, D>> : std::true_type {};
template <class T> inline constexpr bool is_gaussian_v = is_gaussian<T>::value;

/// N Gaussians of type `G` as structure of arrays, scalar type `S` (float for training, double
/// for gradient checks). Storage conventions follow 3DGS: log-scales, wxyz quaternions (not
/// necessarily normalised), opacity logits. SH coefficients are stored in band planes,
/// [Bands, C, K]: plane c holds the K coefficients of channel c of every Gaussian, contiguous per
/// Gaussian. A step that renders one band of a Joint model then reads and writes that plane only
/// (in the model, its gradients and Adam's moments), never the cache lines of the other bands.
/// A plane has room for C >= N Gaussians (sh_capacity(): sh.size() / sh_floats), so that
/// densification can add Gaussians without moving every plane; the rows [N, C) of every plane are
/// zero. A model assembled by hand with sh.size() == N x sh_floats has C = N. Read the planes
/// through sh_row / sh_plane_stride, never as N x sh_floats values.
template <class G, class S = float>
struct GaussianModel {
  static_assert(is_gaussian_v<G>, "GaussianModel<G>: G must be msgs::Gaussian<Bands, SHDeg>");
  using gaussian_type = G;
  using scalar_type = S;
  static constexpr int bands = G::bands;
  static constexpr int sh_coeffs = G::sh_coeffs;

  std::vector<S> means;           ///< [N, 3] world position
  std::vector<S> log_scales;      ///< [N, 3] log of the standard deviations along the local axes
  std::vector<S> quats;           ///< [N, 4] rotation quaternion w, x, y, z
  std::vector<S> opacity_logits;  ///< [N]    logit of the opacity
  std::vector<S> sh;              ///< [Bands, N, K] SH coefficients in band planes, K = sh_coeffs

  GaussianModel() = default;
  explicit GaussianModel(std::size_t n)
      : means(n * 3), log_scales(n * 3), quats(n * 4), opacity_logits(n), sh(n * static_cast<std::size_t>(G::sh_floats)) {}

  /// Number of Gaussians.
  std::size_t size() const { return opacity_logits.size(); }
  bool empty() const { return opacity_logits.empty(); }

  /// Resize every array to hold `n` Gaussians (new entries are zero; each band plane keeps its
  /// first min(old, n) Gaussians). The planes end up with room for exactly `n` (sh_capacity() = n).
  void resize(std::size_t n) {
    const std::size_t old = size();
    constexpr std::size_t K = static_cast<std::size_t>(G::sh_coeffs);
    const bool planes_ok = old > 0 && sh.size() % static_cast<std::size_t>(G::sh_floats) == 0 && sh_capacity() >= old;
    const std::size_t cap = planes_ok ? sh_capacity() : 0;
    means.resize(n * 3);
    log_scales.resize(n * 3);
    quats.resize(n * 4);
    opacity_logits.resize(n);
    if (!planes_ok) {  // nothing to keep (or a model whose planes disagree with its size)
      if (G::bands > 1) sh.assign(n * static_cast<std::size_t>(G::sh_floats), S(0));
      else sh.resize(n * K);
      return;
    }
    if (G::bands == 1) {  // one plane: rows [old, cap) are zero already
      sh.resize(n * K);
      return;
    }
    if (cap == n) return;
    std::vector<S> planes(n * static_cast<std::size_t>(G::sh_floats), S(0));
    const std::size_t keep = std::min(old, n) * K;
    for (std::size_t c = 0; c < static_cast<std::size_t>(G::bands); ++c)
      std::copy_n(sh.begin() + static_cast<std::ptrdiff_t>(c * cap * K), keep,
                  planes.begin() + static_cast<std::ptrdiff_t>(c * n * K));
    sh.swap(planes);
  }

  /// Give the band planes room for exactly N Gaussians (sh_capacity() = size()): the layout of a
  /// model assembled by hand, of a checkpoint and of a PLY file. Values are kept.
  void shrink_planes() { resize(size()); }

  /// Become a copy of `o` whose band planes have room for exactly its N Gaussians, in this model's
  /// buffers (no allocation when they are large enough).
  void assign_shrunk(const GaussianModel& o) {
    means = o.means;
    log_scales = o.log_scales;
    quats = o.quats;
    opacity_logits = o.opacity_logits;
    const std::size_t rows = o.size() * static_cast<std::size_t>(G::sh_coeffs);
    sh.resize(o.size() * static_cast<std::size_t>(G::sh_floats));
    for (int c = 0; c < G::bands; ++c) std::copy_n(o.sh.data() + std::size_t(c) * o.sh_plane_stride(), rows, sh.data() + std::size_t(c) * rows);
  }

  /// Resize every array to `n` Gaussians without keeping the values: the contents are unspecified
  /// (band planes shift; storage that grows starts over, with room for half as many again), there
  /// is no copy. For buffers that are rewritten anyway (gradients); `resize` keeps values.
  void reshape(std::size_t n) {
    const auto fit = [](std::vector<S>& v, std::size_t count) {  // as detail::resize_for_overwrite
      if (count > v.capacity()) {
        std::vector<S>().swap(v);
        v.reserve(count + count / 2);
      }
      v.resize(count);
    };
    fit(means, n * 3);
    fit(log_scales, n * 3);
    fit(quats, n * 4);
    fit(opacity_logits, n);
    fit(sh, n * static_cast<std::size_t>(G::sh_floats));
  }

  /// Fill every array with zero (keeps the size); used for gradient buffers.
  void set_zero() {
    for (auto* v : {&means, &log_scales, &quats, &opacity_logits, &sh}) v->assign(v->size(), S(0));
  }

  /// Gaussians a band plane has room for (C >= N).
  std::size_t sh_capacity() const { return sh.size() / static_cast<std::size_t>(G::sh_floats); }
  /// Distance between the band planes of `sh`: C x K values.
  std::size_t sh_plane_stride() const { return sh_capacity() * static_cast<std::size_t>(G::sh_coeffs); }
  /// The K coefficients of channel c of Gaussian i (contiguous; channel c + 1 is sh_plane_stride() further).
  S* sh_row(std::size_t i, int c) { return sh.data() + static_cast<std::size_t>(c) * sh_plane_stride() + i * G::sh_coeffs; }
  const S* sh_row(std::size_t i, int c) const {
    return sh.data() + static_cast<std::size_t>(c) * sh_plane_stride() + i * G::sh_coeffs;
  }
  /// SH coefficient k of channel c of Gaussian i.
  S& sh_at(std::size_t i, int k, int c) { return sh_row(i, c)[k]; }
  const S& sh_at(std::size_t i, int k, int c) const { return sh_row(i, c)[k]; }

  /// Throw std::invalid_argument if the arrays disagree on N (a model assembled by hand).
  void check_consistent() const {
    const std::size_t n = size();
    if (means.size() != 3 * n || log_scales.size() != 3 * n || quats.size() != 4 * n ||
        sh.size() % static_cast<std::size_t>(G::sh_floats) != 0 || sh_capacity() < n)
      throw std::invalid_argument("GaussianModel: arrays disagree on the number of Gaussians (" +
                                  std::to_string(n) + " opacities)");
  }
};

}  // namespace msgs
