// include/msgs/loss.hpp
// Training losses and evaluation metrics: 0.8 L1 + 0.2 (1 - SSIM) with its gradient, the scale-ratio regulariser, PSNR, SSIM.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "msgs/gaussian.hpp"
#include "msgs/image.hpp"

namespace msgs {

// ---------------------------------------------------------------------------------------------
// SSIM (forward and backward side by side)
// ---------------------------------------------------------------------------------------------

/// Side length of the SSIM window (3DGS / gsplat: 11).
inline constexpr int ssim_window_size = 11;
/// Half width of the SSIM window; the reference convolves with zero padding of this many pixels.
inline constexpr int ssim_window_radius = ssim_window_size / 2;
/// Standard deviation of the Gaussian SSIM window in pixels.
inline constexpr double ssim_sigma = 1.5;
/// SSIM stabilisers for a dynamic range of 1: C1 = (0.01)^2, C2 = (0.03)^2.
inline constexpr double ssim_c1 = 0.01 * 0.01;
inline constexpr double ssim_c2 = 0.03 * 0.03;

/// The normalised 1-D SSIM window; the 2-D window is its outer product, so filtering separates.
template <class S>
std::array<S, ssim_window_size> ssim_window_1d() {
  std::array<double, ssim_window_size> g{};
  double sum = 0;
  for (int k = 0; k < ssim_window_size; ++k) {
    const double u = k - ssim_window_radius;
    g[static_cast<std::size_t>(k)] = std::exp(-u * u / (2 * ssim_sigma * ssim_sigma));
    sum += g[static_cast<std::size_t>(k)];
  }
  std::array<S, ssim_window_size> w{};
  for (std::size_t k = 0; k < w.size(); ++k) w[k] = static_cast<S>(g[k] / sum);
  return w;
}

/// Scratch buffers of the SSIM forward/backward, reusable across calls so that a training step does
/// not allocate. All buffers are row-major over the interleaved image: [H, W * C].
template <class S>
struct SsimWorkspace {
  int width = 0, height = 0, channels = 0;
  std::vector<S> hx, hy, hxx, hyy, hxy;  ///< [H, W*C] horizontally filtered x, y, x^2, y^2, xy
  std::vector<S> d_mu, d_exx, d_exy;     ///< [H, W*C] dSSIM(p)/d mu_x(p), /d E[x^2](p), /d E[xy](p)
  std::vector<double> row_sums;          ///< [H, C]   sum over x of the SSIM map, per row and channel
  bool has_bwd_state = false;            ///< d_* hold the maps of the last forward

  void resize(int w, int h, int c) {
    width = w; height = h; channels = c;
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c);
    for (auto* v : {&hx, &hy, &hxx, &hyy, &hxy}) v->resize(n);
    row_sums.resize(static_cast<std::size_t>(h) * static_cast<std::size_t>(c));
    has_bwd_state = false;
  }
};

namespace detail {

inline void check_same_shape(const char* what, int w0, int h0, int c0, int w1, int h1, int c1) {
  if (w0 != w1 || h0 != h1 || c0 != c1 || w0 < 0 || h0 < 0 || c0 < 0)
    throw std::invalid_argument(std::string(what) + ": images must have the same shape, got " +
                                std::to_string(w0) + "x" + std::to_string(h0) + "x" + std::to_string(c0) + " and " +
                                std::to_string(w1) + "x" + std::to_string(h1) + "x" + std::to_string(c1));
}

template <class S>
void check_image(const char* what, const char* field, const Image<S>& im) {
  if (im.width < 0 || im.height < 0 || im.channels < 0 ||
      im.data.size() != static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height) *
                            static_cast<std::size_t>(im.channels))
    throw std::invalid_argument(std::string(what) + ": image '" + field + "' has " + std::to_string(im.data.size()) +
                                " values, expected width*height*channels = " + std::to_string(im.width) + "*" +
                                std::to_string(im.height) + "*" + std::to_string(im.channels));
}

/// One interleaved row filtered horizontally with zero padding:
/// out[x*C + c] = sum_k w[k] in[(x + k - R)*C + c] over x + k - R inside the row. The loop over k is
/// outermost so that every inner loop is a contiguous, vectorisable axpy, and each output sums its
/// terms in the same order (k ascending) whatever the threading.
template <class S>
inline void ssim_hfilter_row(const S* in, S* out, int width, int channels, const S* w) {
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(width) * channels;
  std::fill(out, out + len, S(0));
  for (int k = 0; k < ssim_window_size; ++k) {
    const std::ptrdiff_t d = static_cast<std::ptrdiff_t>(k - ssim_window_radius) * channels;
    const std::ptrdiff_t lo = std::max<std::ptrdiff_t>(0, -d), hi = std::min<std::ptrdiff_t>(len, len - d);
    const S wk = w[k];
    for (std::ptrdiff_t j = lo; j < hi; ++j) out[j] += wk * in[j + d];
  }
}

/// Output row `r` of the vertical pass over an [H, len] buffer, zero padding above and below.
template <class S>
inline void ssim_vfilter_row(const S* src, S* out, int r, int height, std::ptrdiff_t len, const S* w) {
  std::fill(out, out + len, S(0));
  for (int k = 0; k < ssim_window_size; ++k) {
    const int rr = r + k - ssim_window_radius;
    if (rr < 0 || rr >= height) continue;
    const S* row = src + static_cast<std::ptrdiff_t>(rr) * len;
    const S wk = w[k];
    for (std::ptrdiff_t j = 0; j < len; ++j) out[j] += wk * row[j];
  }
}

}  // namespace detail

/// SSIM forward: mean over pixels and channels of the SSIM map of `x` against `y` ([H, W, C], any C),
/// the 11x11 Gaussian window summing over the zero-padded images ("same" convolution, as the 3DGS
/// reference `F.conv2d(..., padding=5, groups=C)`). With `keep_for_bwd` the per-pixel partial
/// derivatives of the map are kept in `ws` for `ssim_bwd`. `per_channel` (optional) receives the mean
/// over pixels of each channel. Deterministic: rows are independent and reductions run in row order.
template <class S>
double ssim_fwd(const Image<S>& x, const Image<S>& y, SsimWorkspace<S>& ws, bool keep_for_bwd = false,
                std::vector<double>* per_channel = nullptr) {
  detail::check_image("ssim", "x", x);
  detail::check_image("ssim", "y", y);
  detail::check_same_shape("ssim", x.width, x.height, x.channels, y.width, y.height, y.channels);
  const int W = x.width, H = x.height, C = x.channels;
  ws.resize(W, H, C);
  if (keep_for_bwd)
    for (auto* v : {&ws.d_mu, &ws.d_exx, &ws.d_exy}) v->resize(ws.hx.size());
  if (per_channel) per_channel->assign(static_cast<std::size_t>(C), 0.0);
  if (x.data.empty()) {
    ws.has_bwd_state = keep_for_bwd;
    return 0.0;
  }
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(W) * C;
  const auto win = ssim_window_1d<S>();
  const S* w = win.data();

  // Horizontal pass of x, y, x^2, y^2, xy.
#pragma omp parallel
  {
    std::vector<S> pxx(static_cast<std::size_t>(len)), pyy(pxx.size()), pxy(pxx.size());
#pragma omp for schedule(static)
    for (int r = 0; r < H; ++r) {
      const S* xr = x.data.data() + r * len;
      const S* yr = y.data.data() + r * len;
      for (std::ptrdiff_t j = 0; j < len; ++j) {
        pxx[static_cast<std::size_t>(j)] = xr[j] * xr[j];
        pyy[static_cast<std::size_t>(j)] = yr[j] * yr[j];
        pxy[static_cast<std::size_t>(j)] = xr[j] * yr[j];
      }
      const std::ptrdiff_t o = r * len;
      detail::ssim_hfilter_row(xr, ws.hx.data() + o, W, C, w);
      detail::ssim_hfilter_row(yr, ws.hy.data() + o, W, C, w);
      detail::ssim_hfilter_row(pxx.data(), ws.hxx.data() + o, W, C, w);
      detail::ssim_hfilter_row(pyy.data(), ws.hyy.data() + o, W, C, w);
      detail::ssim_hfilter_row(pxy.data(), ws.hxy.data() + o, W, C, w);
    }
  }

  // Vertical pass, SSIM map and its partial derivatives w.r.t. the filtered statistics of x.
  const S c1 = static_cast<S>(ssim_c1), c2 = static_cast<S>(ssim_c2);
#pragma omp parallel
  {
    std::vector<S> mx(static_cast<std::size_t>(len)), my(mx.size()), exx(mx.size()), eyy(mx.size()), exy(mx.size());
    std::vector<double> sums(static_cast<std::size_t>(C));
#pragma omp for schedule(static)
    for (int r = 0; r < H; ++r) {
      detail::ssim_vfilter_row(ws.hx.data(), mx.data(), r, H, len, w);
      detail::ssim_vfilter_row(ws.hy.data(), my.data(), r, H, len, w);
      detail::ssim_vfilter_row(ws.hxx.data(), exx.data(), r, H, len, w);
      detail::ssim_vfilter_row(ws.hyy.data(), eyy.data(), r, H, len, w);
      detail::ssim_vfilter_row(ws.hxy.data(), exy.data(), r, H, len, w);
      std::fill(sums.begin(), sums.end(), 0.0);
      const std::ptrdiff_t o = r * len;
      for (std::ptrdiff_t j = 0; j < len; ++j) {
        const std::size_t u = static_cast<std::size_t>(j);
        const S ux = mx[u], uy = my[u];
        const S ux2 = ux * ux, uy2 = uy * uy, uxy = ux * uy;
        const S a1 = 2 * uxy + c1;
        const S a2 = 2 * (exy[u] - uxy) + c2;
        const S b1 = ux2 + uy2 + c1;
        // Both variances are >= 0 in exact arithmetic (the window weights sum to <= 1), so b2 >= C2.
        const S b2 = (exx[u] - ux2) + (eyy[u] - uy2) + c2;
        const S inv = S(1) / (b1 * b2);
        const S s = a1 * a2 * inv;
        sums[static_cast<std::size_t>(j % C)] += static_cast<double>(s);
        if (keep_for_bwd) {
          // S = A1 A2 / (B1 B2) with A1 = 2 ux uy + C1, A2 = 2 (Exy - ux uy) + C2, B1 = ux^2 + uy^2 + C1,
          // B2 = Exx - ux^2 + Eyy - uy^2 + C2.
          ws.d_mu[static_cast<std::size_t>(o + j)] = 2 * inv * (uy * (a2 - a1) - ux * s * (b2 - b1));
          ws.d_exx[static_cast<std::size_t>(o + j)] = -s / b2;
          ws.d_exy[static_cast<std::size_t>(o + j)] = 2 * a1 * inv;
        }
      }
      std::copy(sums.begin(), sums.end(), ws.row_sums.begin() + static_cast<std::ptrdiff_t>(r) * C);
    }
  }
  ws.has_bwd_state = keep_for_bwd;

  // Fixed-order reduction: channel sums over rows in row order, then channels in order.
  double total = 0;
  for (int c = 0; c < C; ++c) {
    double sc = 0;
    for (int r = 0; r < H; ++r) sc += ws.row_sums[static_cast<std::size_t>(r) * static_cast<std::size_t>(C) + static_cast<std::size_t>(c)];
    if (per_channel) (*per_channel)[static_cast<std::size_t>(c)] = sc / static_cast<double>(x.pixels());
    total += sc;
  }
  return total / static_cast<double>(x.size());
}

/// SSIM backward: `grad_x += scale * d(mean SSIM)/dx` for the images of the last
/// `ssim_fwd(x, y, ws, true)`. `grad_x` must already have the shape of `x`.
///
/// Each map value depends on x only through mu_x = G*x, E[x^2] = G*x^2 and E[xy] = G*(xy), so
/// dS/dx(q) = (G^T*d_mu)(q) + 2 x(q) (G^T*d_exx)(q) + y(q) (G^T*d_exy)(q). The adjoint of a symmetric
/// zero-padded "same" filter is the same filter, so the backward reuses the separable passes.
template <class S>
void ssim_bwd(const Image<S>& x, const Image<S>& y, SsimWorkspace<S>& ws, S scale, Image<S>& grad_x) {
  detail::check_same_shape("ssim_bwd", x.width, x.height, x.channels, y.width, y.height, y.channels);
  detail::check_same_shape("ssim_bwd (gradient)", x.width, x.height, x.channels, grad_x.width, grad_x.height,
                           grad_x.channels);
  if (!ws.has_bwd_state || ws.width != x.width || ws.height != x.height || ws.channels != x.channels)
    throw std::logic_error("ssim_bwd: call ssim_fwd(x, y, ws, /*keep_for_bwd=*/true) on the same images first");
  if (x.data.empty()) return;
  const int W = x.width, H = x.height, C = x.channels;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(W) * C;
  const auto win = ssim_window_1d<S>();
  const S* w = win.data();
  // The forward's horizontal buffers are free now; reuse three of them.
  S* ha = ws.hx.data();
  S* hb = ws.hxx.data();
  S* hc = ws.hxy.data();
#pragma omp parallel for schedule(static)
  for (int r = 0; r < H; ++r) {
    const std::ptrdiff_t o = r * len;
    detail::ssim_hfilter_row(ws.d_mu.data() + o, ha + o, W, C, w);
    detail::ssim_hfilter_row(ws.d_exx.data() + o, hb + o, W, C, w);
    detail::ssim_hfilter_row(ws.d_exy.data() + o, hc + o, W, C, w);
  }
  ws.has_bwd_state = false;  // the horizontal buffers no longer hold the forward's statistics
  const S k = scale / static_cast<S>(x.size());  // the mean's 1/(H W C)
#pragma omp parallel
  {
    std::vector<S> fa(static_cast<std::size_t>(len)), fb(fa.size()), fc(fa.size());
#pragma omp for schedule(static)
    for (int r = 0; r < H; ++r) {
      detail::ssim_vfilter_row(ha, fa.data(), r, H, len, w);
      detail::ssim_vfilter_row(hb, fb.data(), r, H, len, w);
      detail::ssim_vfilter_row(hc, fc.data(), r, H, len, w);
      const std::ptrdiff_t o = r * len;
      const S* xr = x.data.data() + o;
      const S* yr = y.data.data() + o;
      S* gr = grad_x.data.data() + o;
      for (std::ptrdiff_t j = 0; j < len; ++j) {
        const std::size_t u = static_cast<std::size_t>(j);
        gr[j] += k * (fa[u] + 2 * xr[j] * fb[u] + yr[j] * fc[u]);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Photometric loss
// ---------------------------------------------------------------------------------------------

/// Weights of the photometric loss (1 - lambda) L1 + lambda (1 - SSIM).
struct PhotometricLossConfig {
  double ssim_weight = 0.2;  ///< lambda; 3DGS and the multi-spectral implementation use 0.2
};

/// Value of the photometric loss and, when `grad_render` is non-null, its gradient with respect to
/// `render` (overwritten, resized to the render's shape). L1 is the mean absolute difference over
/// pixels and channels; its derivative at a tie is 0 (as torch.sign). `ws` is scratch space.
template <class S>
double photometric_loss(const Image<S>& render, const Image<S>& gt, Image<S>* grad_render, SsimWorkspace<S>& ws,
                        const PhotometricLossConfig& cfg = {}) {
  detail::check_image("photometric_loss", "render", render);
  detail::check_image("photometric_loss", "gt", gt);
  detail::check_same_shape("photometric_loss", render.width, render.height, render.channels, gt.width, gt.height,
                           gt.channels);
  const bool want_grad = grad_render != nullptr;
  const double ssim_value = ssim_fwd(render, gt, ws, want_grad);
  if (render.data.empty()) {
    if (want_grad) grad_render->reset(render.width, render.height, render.channels);
    return 0.0;
  }
  const double lambda = cfg.ssim_weight;
  const int H = render.height;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(render.width) * render.channels;
  if (want_grad) grad_render->reset(render.width, render.height, render.channels);
  const S l1_scale = static_cast<S>((1.0 - lambda) / static_cast<double>(render.size()));
  std::vector<double> row_l1(static_cast<std::size_t>(H));
#pragma omp parallel for schedule(static)
  for (int r = 0; r < H; ++r) {
    const std::ptrdiff_t o = r * len;
    const S* xr = render.data.data() + o;
    const S* yr = gt.data.data() + o;
    double acc = 0;
    for (std::ptrdiff_t j = 0; j < len; ++j) acc += static_cast<double>(std::abs(xr[j] - yr[j]));
    row_l1[static_cast<std::size_t>(r)] = acc;
    if (want_grad) {
      S* gr = grad_render->data.data() + o;
      for (std::ptrdiff_t j = 0; j < len; ++j) {
        const S d = xr[j] - yr[j];
        gr[j] = d > 0 ? l1_scale : (d < 0 ? -l1_scale : S(0));
      }
    }
  }
  double l1 = 0;
  for (double v : row_l1) l1 += v;
  l1 /= static_cast<double>(render.size());
  if (want_grad) ssim_bwd(render, gt, ws, static_cast<S>(-lambda), *grad_render);
  return (1.0 - lambda) * l1 + lambda * (1.0 - ssim_value);
}

/// Loss value only (allocates its own scratch space).
template <class S>
double photometric_loss(const Image<S>& render, const Image<S>& gt, const PhotometricLossConfig& cfg = {}) {
  SsimWorkspace<S> ws;
  return photometric_loss(render, gt, static_cast<Image<S>*>(nullptr), ws, cfg);
}

// ---------------------------------------------------------------------------------------------
// Scale-ratio regulariser
// ---------------------------------------------------------------------------------------------

/// Parameters of the scale regulariser weight * mean_i(max(max_scale_i / min_scale_i, max_ratio) - max_ratio).
struct ScaleRegConfig {
  double weight = 0.1;      ///< the multi-spectral implementation (splatfacto) uses 0.1 every 10 steps
  double max_ratio = 10.0;  ///< anisotropy allowed before the penalty starts
  /// The ratio is exp(max log-scale - min log-scale); the exponent is clamped here so that a runaway
  /// Gaussian gives a large finite penalty instead of inf. The gradient uses the clamped ratio.
  double max_log_ratio = 80.0;
};

/// Scale regulariser forward and backward over log-scales [N, 3]. Returns the value; when
/// `grad_log_scales` is non-empty ([N, 3]) the gradient is ADDED into it. With ratio = exp(l_max - l_min)
/// the derivative is +weight*ratio/N on the largest log-scale and -weight*ratio/N on the smallest;
/// ties share it evenly (as torch.amax/amin). Deterministic: fixed blocks, summed in order.
template <class S>
double scale_reg(std::span<const S> log_scales, std::span<S> grad_log_scales, const ScaleRegConfig& cfg = {}) {
  if (log_scales.size() % 3 != 0)
    throw std::invalid_argument("scale_reg: log_scales has " + std::to_string(log_scales.size()) +
                                " values, expected a multiple of 3 ([N, 3])");
  const bool want_grad = !grad_log_scales.empty();
  if (want_grad && grad_log_scales.size() != log_scales.size())
    throw std::invalid_argument("scale_reg: grad_log_scales has " + std::to_string(grad_log_scales.size()) +
                                " values, expected " + std::to_string(log_scales.size()) + " ([N, 3])");
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(log_scales.size() / 3);
  if (n == 0) return 0.0;
  constexpr std::ptrdiff_t block = 4096;
  const std::ptrdiff_t nblocks = (n + block - 1) / block;
  std::vector<double> partial(static_cast<std::size_t>(nblocks), 0.0);
  const double gscale = cfg.weight / static_cast<double>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < nblocks; ++b) {
    double acc = 0;
    const std::ptrdiff_t end = std::min(n, (b + 1) * block);
    for (std::ptrdiff_t i = b * block; i < end; ++i) {
      const S* l = log_scales.data() + 3 * i;
      const S lmax = std::max({l[0], l[1], l[2]});
      const S lmin = std::min({l[0], l[1], l[2]});
      const double ratio = std::exp(std::min(static_cast<double>(lmax) - static_cast<double>(lmin), cfg.max_log_ratio));
      if (!(ratio > cfg.max_ratio)) continue;  // also skips a NaN log-scale rather than spreading it
      acc += ratio - cfg.max_ratio;
      if (want_grad) {
        const int nmax = (l[0] == lmax) + (l[1] == lmax) + (l[2] == lmax);
        const int nmin = (l[0] == lmin) + (l[1] == lmin) + (l[2] == lmin);
        S* g = grad_log_scales.data() + 3 * i;
        for (int a = 0; a < 3; ++a) {
          if (l[a] == lmax) g[a] += static_cast<S>(gscale * ratio / nmax);
          if (l[a] == lmin) g[a] -= static_cast<S>(gscale * ratio / nmin);
        }
      }
    }
    partial[static_cast<std::size_t>(b)] = acc;
  }
  double sum = 0;
  for (double v : partial) sum += v;
  return cfg.weight * sum / static_cast<double>(n);
}

/// Scale regulariser on a model; adds the gradient into `grad->log_scales` when `grad` is non-null.
template <class G, class S>
double scale_reg(const GaussianModel<G, S>& model, GaussianModel<G, S>* grad, const ScaleRegConfig& cfg = {}) {
  return scale_reg<S>(std::span<const S>(model.log_scales),
                      grad ? std::span<S>(grad->log_scales) : std::span<S>(), cfg);
}

// ---------------------------------------------------------------------------------------------
// Evaluation metrics
// ---------------------------------------------------------------------------------------------

/// Smallest mean squared error used by PSNR, so that identical images give a finite 100 dB
/// (with max_value 1) instead of inf, which would poison averages over a test set.
inline constexpr double psnr_min_mse = 1e-10;

/// PSNR per channel in dB, 10 log10(max_value^2 / MSE_c), for images in [0, max_value].
template <class S>
std::vector<double> psnr_per_channel(const Image<S>& a, const Image<S>& b, double max_value = 1.0) {
  detail::check_image("psnr", "a", a);
  detail::check_image("psnr", "b", b);
  detail::check_same_shape("psnr", a.width, a.height, a.channels, b.width, b.height, b.channels);
  const std::size_t C = static_cast<std::size_t>(a.channels), P = a.pixels();
  std::vector<double> mse(C, 0.0);
  for (std::size_t p = 0; p < P; ++p)
    for (std::size_t c = 0; c < C; ++c) {
      const double d = static_cast<double>(a.data[p * C + c]) - static_cast<double>(b.data[p * C + c]);
      mse[c] += d * d;
    }
  std::vector<double> out(C);
  for (std::size_t c = 0; c < C; ++c)
    out[c] = 10.0 * std::log10(max_value * max_value / std::max(P ? mse[c] / static_cast<double>(P) : 0.0, psnr_min_mse));
  return out;
}

/// PSNR in dB of the whole image (MSE over pixels and channels), as the 3DGS evaluation.
template <class S>
double psnr(const Image<S>& a, const Image<S>& b, double max_value = 1.0) {
  detail::check_image("psnr", "a", a);
  detail::check_image("psnr", "b", b);
  detail::check_same_shape("psnr", a.width, a.height, a.channels, b.width, b.height, b.channels);
  double mse = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    const double d = static_cast<double>(a.data[i]) - static_cast<double>(b.data[i]);
    mse += d * d;
  }
  mse = a.data.empty() ? 0.0 : mse / static_cast<double>(a.data.size());
  return 10.0 * std::log10(max_value * max_value / std::max(mse, psnr_min_mse));
}

/// Mean SSIM (same window and borders as the training loss) over pixels and channels.
template <class S>
double ssim(const Image<S>& a, const Image<S>& b) {
  SsimWorkspace<S> ws;
  return ssim_fwd(a, b, ws);
}

/// Mean SSIM of each channel.
template <class S>
std::vector<double> ssim_per_channel(const Image<S>& a, const Image<S>& b) {
  SsimWorkspace<S> ws;
  std::vector<double> out;
  ssim_fwd(a, b, ws, false, &out);
  return out;
}

}  // namespace msgs
