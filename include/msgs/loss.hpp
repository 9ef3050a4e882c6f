// include/msgs/loss.hpp
// Training losses and metrics: 0.8 L1 + 0.2 (1 - SSIM) with its gradient, scale regulariser, PSNR, SSIM.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <stdexcept>
#include <string>
#include <cstdint>
#include <tuple>
#include <utility>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

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

/// Which pixels the SSIM mean runs over.
enum class SsimBorder {
  /// Every pixel, the window summing over the zero-padded images ("same" convolution): the 3DGS
  /// reference, `F.conv2d(..., padding=5, groups=C)`.
  same,
  /// Only the pixels whose whole 11x11 window lies inside the image ("valid" convolution, no
  /// padding): pytorch-msssim's `ssim(..., data_range=1)`, which the multi-spectral implementation
  /// uses in its loss and evaluation. An image dimension shorter than the window keeps all its
  /// pixels (pytorch-msssim skips filtering along it; msgs filters it with zero padding).
  valid,
};

/// The pixels [lo, hi) along a dimension of `n` pixels that a `border` SSIM mean covers.
inline std::pair<int, int> ssim_covered(int n, SsimBorder border) {
  if (border == SsimBorder::valid && n >= ssim_window_size) return {ssim_window_radius, n - ssim_window_radius};
  return {0, n};
}

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

/// Scratch space of the SSIM forward/backward, reusable across calls so that a training step neither
/// allocates nor page-faults. The derivative maps are stored with zero borders of R*C values on both
/// sides of each row, so the backward's horizontal pass reads them in place.
template <class S>
struct SsimWorkspace {
  int width = 0, height = 0, channels = 0;
  std::vector<S> d_mu, d_exx, d_exy;  ///< [H, W*C + 2 R C] dSSIM(p)/d mu_x(p), /d E[x^2](p), /d E[xy](p)
  std::vector<double> row_sums;       ///< [H, C] sum over x of the SSIM map, per row and channel
  std::vector<std::vector<S>> thread_scratch;  ///< per OpenMP thread: its row rings and row buffers (two in the fused loss pass)
  bool has_bwd_state = false;         ///< d_* hold the maps of the last forward
  /// The pixels the last forward averaged over (ssim_covered): rows [r_lo, r_hi), columns [c_lo, c_hi).
  int r_lo = 0, r_hi = 0, c_lo = 0, c_hi = 0;
  /// Number of values the last forward averaged over: (r_hi - r_lo) (c_hi - c_lo) C.
  std::size_t covered() const {
    return static_cast<std::size_t>(r_hi - r_lo) * static_cast<std::size_t>(c_hi - c_lo) * static_cast<std::size_t>(channels);
  }

  /// Row stride of the derivative maps.
  std::ptrdiff_t map_stride() const {
    return static_cast<std::ptrdiff_t>(width + 2 * ssim_window_radius) * channels;
  }

  void resize(int w, int h, int c, bool with_maps) {
    const bool same = w == width && h == height && c == channels;
    width = w; height = h; channels = c;
    row_sums.resize(static_cast<std::size_t>(h) * static_cast<std::size_t>(c));
    const std::size_t n = static_cast<std::size_t>(h) * static_cast<std::size_t>(map_stride());
    // Borders must be zero; only the interiors are ever written, so a same-shape reuse keeps them.
    if (with_maps && (!same || d_mu.size() != n))
      for (auto* v : {&d_mu, &d_exx, &d_exy}) v->assign(n, S(0));
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

/// Contiguous block [first, last) of `n` rows for thread `t` of `nt`. Which thread computes a row
/// never changes its value: every row is computed by the same sequence of operations.
inline void thread_rows(int n, int& first, int& last) {
#ifdef _OPENMP
  const long t = omp_get_thread_num(), nt = omp_get_num_threads();
#else
  const long t = 0, nt = 1;
#endif
  first = static_cast<int>(n * t / nt);
  last = static_cast<int>(n * (t + 1) / nt);
}

/// The window's 11 taps applied to a0..a10, using its symmetry w[k] = w[10 - k] (exact: the weights
/// are computed from u^2): w0 (a0 + a10) + w1 (a1 + a9) + ... + w4 (a4 + a6) + w5 a5, summed in that
/// order. Six products instead of eleven; the filter stays exactly symmetric, so it is its own adjoint.
template <class S>
inline S ssim_taps(const S* __restrict w, S a0, S a1, S a2, S a3, S a4, S a5, S a6, S a7, S a8, S a9, S a10) {
  return w[0] * (a0 + a10) + w[1] * (a1 + a9) + w[2] * (a2 + a8) + w[3] * (a3 + a7) + w[4] * (a4 + a6) + w[5] * a5;
}

/// Horizontal pass over one interleaved row: out[x*C + c] = sum_k w[k] in[(x + k - R)*C + c]. `in` is
/// padded with R*C zeros on both sides (the reference's zero padding), so every output sums the same
/// terms in the same order (ssim_taps), and the loop over j vectorises.
template <class S>
inline void ssim_hfilter_row(const S* __restrict in, S* __restrict out, std::ptrdiff_t len, int channels,
                             const S* __restrict w) {
  const std::ptrdiff_t c = channels;
  for (std::ptrdiff_t j = 0; j < len; ++j)
    out[j] = ssim_taps(w, in[j], in[j + c], in[j + 2 * c], in[j + 3 * c], in[j + 4 * c], in[j + 5 * c], in[j + 6 * c],
                       in[j + 7 * c], in[j + 8 * c], in[j + 9 * c], in[j + 10 * c]);
}

/// Output rows the vertical pass computes together: each horizontally filtered row it loads serves
/// four outputs (14 row reads for 4 rows instead of 44), which is what bounds the pass once the rows
/// no longer fit in L1.
inline constexpr int ssim_row_group = 4;

/// Vertical pass for one output row from the 11 horizontally filtered rows around it (a zero row
/// stands for rows outside the image), the same taps as the horizontal pass.
template <class S>
inline void ssim_vfilter_row(const S* const* rows, S* __restrict out, std::ptrdiff_t len, const S* __restrict w) {
  const S *r0 = rows[0], *r1 = rows[1], *r2 = rows[2], *r3 = rows[3], *r4 = rows[4], *r5 = rows[5], *r6 = rows[6],
          *r7 = rows[7], *r8 = rows[8], *r9 = rows[9], *r10 = rows[10];
  for (std::ptrdiff_t j = 0; j < len; ++j)
    out[j] = ssim_taps(w, r0[j], r1[j], r2[j], r3[j], r4[j], r5[j], r6[j], r7[j], r8[j], r9[j], r10[j]);
}

/// Vertical pass for `g` consecutive output rows (g <= ssim_row_group) from the 10 + g filtered rows
/// around them; out[i] receives output row i. Every value is the ssim_vfilter_row value, bit for bit.
template <class S>
inline void ssim_vfilter_rows(const S* const* rows, S* const* out, int g, std::ptrdiff_t len, const S* __restrict w) {
  static_assert(ssim_row_group == 4);
  if (g != 4) {
    for (int i = 0; i < g; ++i) ssim_vfilter_row(rows + i, out[i], len, w);
    return;
  }
  const S *r0 = rows[0], *r1 = rows[1], *r2 = rows[2], *r3 = rows[3], *r4 = rows[4], *r5 = rows[5], *r6 = rows[6],
          *r7 = rows[7], *r8 = rows[8], *r9 = rows[9], *r10 = rows[10], *r11 = rows[11], *r12 = rows[12],
          *r13 = rows[13];
  S* __restrict o0 = out[0];
  S* __restrict o1 = out[1];
  S* __restrict o2 = out[2];
  S* __restrict o3 = out[3];
  // The outputs never alias the rows (they are the caller's separate buffers); with this many
  // pointers GCC would otherwise give up on its runtime alias checks and run the loop scalar.
#pragma GCC ivdep
  for (std::ptrdiff_t j = 0; j < len; ++j) {
    const S a0 = r0[j], a1 = r1[j], a2 = r2[j], a3 = r3[j], a4 = r4[j], a5 = r5[j], a6 = r6[j], a7 = r7[j],
            a8 = r8[j], a9 = r9[j], a10 = r10[j], a11 = r11[j], a12 = r12[j], a13 = r13[j];
    o0[j] = ssim_taps(w, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10);
    o1[j] = ssim_taps(w, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11);
    o2[j] = ssim_taps(w, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12);
    o3[j] = ssim_taps(w, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13);
  }
}

/// Per-thread sliding window of horizontally filtered rows for `Q` quantities: slot (row % slots)
/// holds row `row`, so the rows around a group of output rows are always resident and each is
/// filtered once (plus a 10-row halo per thread), instead of going through full-size intermediate
/// images. Lives in caller-provided storage (reused across calls) followed by `extra` values for the
/// caller.
template <class S, int Q>
struct SsimRowRing {
  static constexpr int slots = ssim_window_size + ssim_row_group - 1;
  std::ptrdiff_t len, pad;
  int height;
  S* ring;    // [Q, slots, len]
  S* padded;  // [Q, len + 2 pad] inputs of the horizontal pass, zero borders
  S* zero;    // [len]
  S* edge;    // [2, 3 pad] the ends of an unpadded row with their zeros (filter_unpadded)
  S* extra;   // [extra]
  int next = 0;  // next image row to filter into the ring

  SsimRowRing(std::vector<S>& storage, std::ptrdiff_t len_, int channels, int height_, std::ptrdiff_t extra_len)
      : len(len_), pad(static_cast<std::ptrdiff_t>(ssim_window_radius) * channels), height(height_) {
    const std::ptrdiff_t n_ring = Q * slots * len, n_pad = Q * (len + 2 * pad);
    storage.resize(static_cast<std::size_t>(n_ring + n_pad + len + 6 * pad + extra_len));
    ring = storage.data();
    padded = ring + n_ring;
    zero = padded + n_pad;
    edge = zero + len;
    extra = edge + 6 * pad;
    std::fill(padded, extra, S(0));
  }

  /// Interior of the padded input row of quantity q, to be filled before `filter`.
  S* input(int q) { return padded + q * (len + 2 * pad) + pad; }
  S* slot(int q, int row) { return ring + (q * slots + row % slots) * len; }
  /// Horizontal pass of quantity q of image row `row` into its slot: from input(q), or from `src`,
  /// the interior of a row padded like it.
  void filter_padded(int q, int row, int channels, const S* w, const S* src = nullptr) {
    ssim_hfilter_row((src ? src : input(q)) - pad, slot(q, row), len, channels, w);
  }
  /// filter_padded for every quantity (from `src[q]` when given).
  void filter(int row, int channels, const S* w, const S* const* src = nullptr) {
    for (int q = 0; q < Q; ++q) filter_padded(q, row, channels, w, src ? src[q] : nullptr);
  }
  /// Horizontal pass of quantity q of image row `row` straight from the unpadded row `src` [len]:
  /// the values of copying it into input(q) and calling `filter`, without the copy. The interior
  /// reads `src` in place; the R*C outputs at either end read `edge`, where the zeros are.
  void filter_unpadded(int q, int row, const S* src, int channels, const S* w) {
    S* out = slot(q, row);
    if (len < 2 * pad) {
      std::copy(src, src + len, input(q));
      filter_padded(q, row, channels, w);
      return;
    }
    S* left = edge;             // [pad zeros, src[0, 2 pad)]
    S* right = edge + 3 * pad;  // [src[len - 2 pad, len), pad zeros]
    std::copy(src, src + 2 * pad, left + pad);
    std::copy(src + len - 2 * pad, src + len, right);
    ssim_hfilter_row(left, out, pad, channels, w);
    ssim_hfilter_row(src, out + pad, len - 2 * pad, channels, w);
    ssim_hfilter_row(right, out + len - pad, pad, channels, w);
  }
  /// The 10 + g rows of quantity q around output rows r .. r + g - 1 (zero rows outside the image).
  void rows_around(int q, int r, int g, const S** rows) {
    for (int k = 0; k < ssim_window_size - 1 + g; ++k) {
      const int rr = r + k - ssim_window_radius;
      rows[k] = (rr < 0 || rr >= height) ? zero : slot(q, rr);
    }
  }
  /// Vertical pass of quantity q for output rows r .. r + g - 1: row i into out + i * out_stride.
  void vfilter(int q, int r, int g, const S* w, S* out, std::ptrdiff_t out_stride) {
    const S* rows[ssim_window_size - 1 + ssim_row_group];
    S* outs[ssim_row_group];
    rows_around(q, r, g, rows);
    for (int i = 0; i < g; ++i) outs[i] = out + i * out_stride;
    ssim_vfilter_rows(rows, outs, g, len, w);
  }
};

/// Per-thread scratch vectors of a workspace, `per_thread` per possible OpenMP thread (call outside
/// parallel).
template <class S>
inline void reserve_thread_scratch(std::vector<std::vector<S>>& scratch, std::size_t per_thread = 1) {
#ifdef _OPENMP
  const std::size_t n = static_cast<std::size_t>(omp_get_max_threads()) * per_thread;
#else
  const std::size_t n = per_thread;
#endif
  if (scratch.size() < n) scratch.resize(n);
}

inline int thread_index() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

/// Products the forward filters besides x and y, for one row: x^2 + y^2 and xy. The map needs E[x^2]
/// and E[y^2] only as their sum (the variances enter as sigma_x^2 + sigma_y^2), so one filter does.
template <class S>
inline void ssim_products_row(const S* __restrict xr, const S* __restrict yr, S* __restrict pss, S* __restrict pxy,
                              std::ptrdiff_t len) {
  for (std::ptrdiff_t j = 0; j < len; ++j) {
    pss[j] = xr[j] * xr[j] + yr[j] * yr[j];
    pxy[j] = xr[j] * yr[j];
  }
}

/// Quantities the forward filters (x, y, x^2 + y^2, xy) and the backward (the three derivative maps).
inline constexpr int ssim_fwd_quantities = 4;
inline constexpr int ssim_bwd_quantities = 3;

/// SSIM map of one row from its filtered statistics (mu_x, mu_y, E[x^2] + E[y^2], E[xy], rows
/// `stride` apart) and, with `Keep`, its partial derivatives with respect to mu_x, E[x^2], E[xy]:
/// S = A1 A2 / (B1 B2), A1 = 2 mx my + C1, A2 = 2 (Exy - mx my) + C2, B1 = mx^2 + my^2 + C1,
/// B2 = (Exx + Eyy) - (mx^2 + my^2) + C2. Branch-free so that it vectorises.
template <bool Keep, class S>
inline void ssim_map_row(const S* stats, std::ptrdiff_t stride, std::ptrdiff_t len, S c1, S c2, S* __restrict smap,
                         S* __restrict d_mu, S* __restrict d_exx, S* __restrict d_exy) {
  const S* __restrict mx = stats;
  const S* __restrict my = stats + stride;
  const S* __restrict ess = stats + 2 * stride;
  const S* __restrict exy = stats + 3 * stride;
  for (std::ptrdiff_t j = 0; j < len; ++j) {
    const S ux = mx[j], uy = my[j];
    const S ux2 = ux * ux, uy2 = uy * uy, uxy = ux * uy;
    const S a1 = 2 * uxy + c1;
    const S a2 = 2 * (exy[j] - uxy) + c2;
    const S m2 = ux2 + uy2;
    const S b1 = m2 + c1;
    // Both variances are >= 0 in exact arithmetic (the window weights sum to <= 1), so b2 >= C2 > 0.
    const S b2 = (ess[j] - m2) + c2;
    const S inv = S(1) / (b1 * b2);
    const S s = a1 * a2 * inv;
    smap[j] = s;
    if constexpr (Keep) {
      d_mu[j] = 2 * inv * (uy * (a2 - a1) - ux * s * (b2 - b1));
      d_exx[j] = -s / b2;
      d_exy[j] = 2 * a1 * inv;
    }
  }
}

/// Filtered statistics of output rows r .. r + g - 1 (g <= ssim_row_group) on a thread's ring:
/// filters the input rows they need that are not in the ring yet, then runs the vertical pass.
/// Row i's quantity q lands at stats + (q * ssim_row_group + i) * len.
template <class S>
inline void ssim_fwd_stats(SsimRowRing<S, ssim_fwd_quantities>& ring, const Image<S>& x, const Image<S>& y, int r,
                           int g, const S* w, S* stats) {
  const int H = x.height, C = x.channels;
  const std::ptrdiff_t len = ring.len;
  for (; ring.next <= std::min(H - 1, r + g - 1 + ssim_window_radius); ++ring.next) {
    const S* xr = x.data.data() + ring.next * len;
    const S* yr = y.data.data() + ring.next * len;
    ssim_products_row(xr, yr, ring.input(2), ring.input(3), len);
    ring.filter_unpadded(0, ring.next, xr, C, w);
    ring.filter_unpadded(1, ring.next, yr, C, w);
    for (int q = 2; q < ssim_fwd_quantities; ++q) ring.filter_padded(q, ring.next, C, w);
  }
  for (int q = 0; q < ssim_fwd_quantities; ++q) ring.vfilter(q, r, g, w, stats + q * ssim_row_group * len, len);
}

/// Row r's SSIM map from its statistics (row i of ssim_fwd_stats: stats + i * len) and, with `Keep`,
/// its derivative rows, zero outside the pixels the mean covers (which do not depend on x).
template <bool Keep, class S>
inline void ssim_fwd_row(const SsimWorkspace<S>& ws, int r, const S* stats, S* smap, S* d_mu, S* d_exx, S* d_exy) {
  const int C = ws.channels;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(ws.width) * C;
  ssim_map_row<Keep>(stats, ssim_row_group * len, len, static_cast<S>(ssim_c1), static_cast<S>(ssim_c2), smap, d_mu,
                     d_exx, d_exy);
  if constexpr (Keep) {
    const bool row_covered = r >= ws.r_lo && r < ws.r_hi;
    if (!row_covered || ws.c_lo > 0 || ws.c_hi < ws.width) {
      const std::ptrdiff_t a = row_covered ? std::ptrdiff_t(ws.c_lo) * C : len;
      const std::ptrdiff_t b = row_covered ? std::ptrdiff_t(ws.c_hi) * C : len;
      for (S* d : {d_mu, d_exx, d_exy}) {
        std::fill(d, d + a, S(0));
        std::fill(d + b, d + len, S(0));
      }
    }
  }
}

/// Per-channel sums in double of `n` interleaved pixels (p[i * C + c]) into out[0, C): 16 partial
/// sums per channel (lane l of each block of 16 C values belongs to channel l % C), combined in a
/// fixed order. Deterministic, and a loop the compiler vectorises (float to double conversions and
/// adds), unlike a sum per channel with stride C.
template <class S>
inline void channel_sums(const S* p, std::ptrdiff_t n, int C, double* out) {
  constexpr int kLanes = 16, kMaxChannels = 8;
  for (int c = 0; c < C; ++c) out[c] = 0.0;
  std::ptrdiff_t i = 0;
  const std::ptrdiff_t total = n * C;
  if (C <= kMaxChannels) {
    double acc[kLanes * kMaxChannels] = {};
    const std::ptrdiff_t block = static_cast<std::ptrdiff_t>(kLanes) * C;
    for (; i + block <= total; i += block)
      for (std::ptrdiff_t l = 0; l < block; ++l) acc[l] += static_cast<double>(p[i + l]);
    for (int k = 0; k < kLanes; ++k)
      for (int c = 0; c < C; ++c) out[c] += acc[k * C + c];
  }
  // The tail (and every value when C > kMaxChannels) one by one; i is a multiple of C here.
  for (; i < total; i += C)
    for (int c = 0; c < C; ++c) out[c] += static_cast<double>(p[i + c]);
}

/// Checks the images and prepares `ws` for an SSIM pass over them (maps only `with_maps`); false
/// when the images are empty.
template <class S>
bool ssim_begin(const Image<S>& x, const Image<S>& y, SsimWorkspace<S>& ws, bool with_maps, SsimBorder border) {
  check_image("ssim", "x", x);
  check_image("ssim", "y", y);
  check_same_shape("ssim", x.width, x.height, x.channels, y.width, y.height, y.channels);
  ws.resize(x.width, x.height, x.channels, with_maps);
  std::tie(ws.r_lo, ws.r_hi) = ssim_covered(x.height, border);
  std::tie(ws.c_lo, ws.c_hi) = ssim_covered(x.width, border);
  return !x.data.empty();
}

/// Sums of row r's SSIM map over the covered columns, per channel, into ws.row_sums.
template <class S>
inline void ssim_row_sums(SsimWorkspace<S>& ws, int r, const S* smap) {
  const int C = ws.channels;
  double* out = ws.row_sums.data() + static_cast<std::ptrdiff_t>(r) * C;
  if (r >= ws.r_lo && r < ws.r_hi)
    channel_sums(smap + std::ptrdiff_t(ws.c_lo) * C, ws.c_hi - ws.c_lo, C, out);
  else
    std::fill(out, out + C, 0.0);
}

/// Mean SSIM from ws.row_sums, in a fixed order: channel sums over rows in row order, then channels
/// in order. `per_channel` (optional) receives each channel's mean.
template <class S>
double ssim_mean(const SsimWorkspace<S>& ws, std::vector<double>* per_channel) {
  const int C = ws.channels, H = ws.height;
  if (per_channel) per_channel->assign(static_cast<std::size_t>(C), 0.0);
  if (ws.covered() == 0) return 0.0;
  double total = 0;
  for (int c = 0; c < C; ++c) {
    double sc = 0;
    for (int r = 0; r < H; ++r)
      sc += ws.row_sums[static_cast<std::size_t>(r) * static_cast<std::size_t>(C) + static_cast<std::size_t>(c)];
    if (per_channel)
      (*per_channel)[static_cast<std::size_t>(c)] = sc / static_cast<double>(ws.covered() / static_cast<std::size_t>(C));
    total += sc;
  }
  return total / static_cast<double>(ws.covered());
}

/// The backward's filtered derivative maps of output rows r .. r + g - 1 from the thread's ring:
/// row i's map q at f + (q * ssim_row_group + i) * len.
template <class S>
inline void ssim_bwd_filtered_rows(SsimRowRing<S, ssim_bwd_quantities>& ring, int r, int g, const S* w, S* f) {
  for (int q = 0; q < ssim_bwd_quantities; ++q) ring.vfilter(q, r, g, w, f + q * ssim_row_group * ring.len, ring.len);
}

/// The SSIM gradient of one pixel value from the filtered derivative maps (see ssim_bwd).
template <class S>
inline S ssim_grad_value(S fa, S fb, S fc, S x, S y) {
  return fa + 2 * x * fb + y * fc;
}

/// Derivative of scale |x - y| with respect to x; 0 at a tie (as torch.sign).
template <class S>
inline S l1_grad(S x, S y, S scale) {
  const S d = x - y;
  return d > 0 ? scale : (d < 0 ? -scale : S(0));
}

/// Gradient row r of the SSIM backward, the i-th of a group whose filtered maps are at f
/// (ssim_bwd_filtered_rows): gr += k dSSIM/dx, or with `WithL1` gr = l1_grad + k dSSIM/dx.
template <bool WithL1, class S>
inline void ssim_grad_row(const Image<S>& x, const Image<S>& y, int r, const S* f, int i, S k, S l1_scale,
                          S* grad) {
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(x.width) * x.channels, o = r * len;
  const S* __restrict xr = x.data.data() + o;
  const S* __restrict yr = y.data.data() + o;
  const S* __restrict fa = f + i * len;
  const S* __restrict fb = f + (ssim_row_group + i) * len;
  const S* __restrict fc = f + (2 * ssim_row_group + i) * len;
  S* __restrict gr = grad + o;
  for (std::ptrdiff_t j = 0; j < len; ++j) {
    if constexpr (WithL1)
      gr[j] = l1_grad(xr[j], yr[j], l1_scale) + k * ssim_grad_value(fa[j], fb[j], fc[j], xr[j], yr[j]);
    else
      gr[j] += k * ssim_grad_value(fa[j], fb[j], fc[j], xr[j], yr[j]);
  }
}

}  // namespace detail

/// SSIM forward: mean over pixels and channels of the SSIM map of `x` against `y` ([H, W, C], any C),
/// the 11x11 Gaussian window summing over the zero-padded images ("same" convolution, as the 3DGS
/// reference `F.conv2d(..., padding=5, groups=C)`); with SsimBorder::valid the mean runs over the
/// pixels whose window lies inside the image only (pytorch-msssim). With `keep_for_bwd` the per-pixel
/// partial derivatives of the map are kept in `ws` for `ssim_bwd`. `per_channel` (optional) receives
/// the mean over pixels of each channel. Deterministic whatever the thread count: every row is
/// computed by the same operations, and reductions run in row order. An empty image gives 0.
template <class S>
double ssim_fwd(const Image<S>& x, const Image<S>& y, SsimWorkspace<S>& ws, bool keep_for_bwd = false,
                std::vector<double>* per_channel = nullptr, SsimBorder border = SsimBorder::same) {
  if (!detail::ssim_begin(x, y, ws, keep_for_bwd, border)) {
    if (per_channel) per_channel->assign(static_cast<std::size_t>(x.channels), 0.0);
    ws.has_bwd_state = keep_for_bwd;
    return 0.0;
  }
  constexpr int G = detail::ssim_row_group;
  const int H = x.height, C = x.channels;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(x.width) * C;
  const std::ptrdiff_t ms = ws.map_stride(), mpad = static_cast<std::ptrdiff_t>(ssim_window_radius) * C;
  const auto win = ssim_window_1d<S>();
  const S* w = win.data();
  detail::reserve_thread_scratch(ws.thread_scratch);

#pragma omp parallel
  {
    int r0 = 0, r1 = 0;
    detail::thread_rows(H, r0, r1);
    if (r0 < r1) {
      // extra: the statistics of a group of rows and the SSIM map row.
      detail::SsimRowRing<S, detail::ssim_fwd_quantities> ring(
          ws.thread_scratch[static_cast<std::size_t>(detail::thread_index())], len, C, H,
          (detail::ssim_fwd_quantities * G + 1) * len);
      S* stats = ring.extra;
      S* smap = ring.extra + detail::ssim_fwd_quantities * G * len;
      ring.next = std::max(0, r0 - ssim_window_radius);
      for (int r = r0; r < r1; r += G) {
        const int g = std::min(G, r1 - r);
        detail::ssim_fwd_stats(ring, x, y, r, g, w, stats);
        for (int i = 0; i < g; ++i) {
          const std::ptrdiff_t o = (r + i) * ms + mpad;
          if (keep_for_bwd)
            detail::ssim_fwd_row<true>(ws, r + i, stats + i * len, smap, ws.d_mu.data() + o, ws.d_exx.data() + o,
                                       ws.d_exy.data() + o);
          else
            detail::ssim_fwd_row<false, S>(ws, r + i, stats + i * len, smap, nullptr, nullptr, nullptr);
          detail::ssim_row_sums(ws, r + i, smap);
        }
      }
    }
  }
  ws.has_bwd_state = keep_for_bwd;
  return detail::ssim_mean(ws, per_channel);
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
  constexpr int G = detail::ssim_row_group;
  const int W = x.width, H = x.height, C = x.channels;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(W) * C;
  const auto win = ssim_window_1d<S>();
  const S* w = win.data();
  const S k = scale / static_cast<S>(ws.covered());  // the mean's 1/(H W C), or over the valid pixels
  const std::ptrdiff_t ms = ws.map_stride(), mpad = static_cast<std::ptrdiff_t>(ssim_window_radius) * C;
  detail::reserve_thread_scratch(ws.thread_scratch);
#pragma omp parallel
  {
    int r0 = 0, r1 = 0;
    detail::thread_rows(H, r0, r1);
    if (r0 < r1) {
      // The maps are read in place (they are padded); extra: the filtered maps of a group of rows.
      detail::SsimRowRing<S, detail::ssim_bwd_quantities> ring(
          ws.thread_scratch[static_cast<std::size_t>(detail::thread_index())], len, C, H,
          detail::ssim_bwd_quantities * G * len);
      S* f = ring.extra;
      ring.next = std::max(0, r0 - ssim_window_radius);
      for (int r = r0; r < r1; r += G) {
        const int g = std::min(G, r1 - r);
        for (; ring.next <= std::min(H - 1, r + g - 1 + ssim_window_radius); ++ring.next) {
          const std::ptrdiff_t o = ring.next * ms + mpad;
          const S* src[3] = {ws.d_mu.data() + o, ws.d_exx.data() + o, ws.d_exy.data() + o};
          ring.filter(ring.next, C, w, src);
        }
        detail::ssim_bwd_filtered_rows(ring, r, g, w, f);
        for (int i = 0; i < g; ++i) detail::ssim_grad_row<false>(x, y, r + i, f, i, k, S(0), grad_x.data.data());
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
  SsimBorder ssim_border = SsimBorder::same;  ///< pixels of the SSIM mean (valid: the multi-spectral implementation)
};

namespace detail {

/// Sum of |x - y| over one row and, with `se`, of (x - y)^2 in double: four partial sums combined in
/// a fixed order (deterministic, and not one long dependency chain).
template <class S>
inline void l1_row_sums(const S* xr, const S* yr, std::ptrdiff_t len, double& l1, double* se) {
  double a0 = 0, a1 = 0, a2 = 0, a3 = 0;
  std::ptrdiff_t j = 0;
  for (; j + 4 <= len; j += 4) {
    a0 += static_cast<double>(std::abs(xr[j] - yr[j]));
    a1 += static_cast<double>(std::abs(xr[j + 1] - yr[j + 1]));
    a2 += static_cast<double>(std::abs(xr[j + 2] - yr[j + 2]));
    a3 += static_cast<double>(std::abs(xr[j + 3] - yr[j + 3]));
  }
  for (; j < len; ++j) a0 += static_cast<double>(std::abs(xr[j] - yr[j]));
  l1 = (a0 + a1) + (a2 + a3);
  if (se) {
    double e0 = 0, e1 = 0, e2 = 0, e3 = 0;
    const auto sq = [&](std::ptrdiff_t i) {
      const double d = static_cast<double>(xr[i]) - static_cast<double>(yr[i]);
      return d * d;
    };
    for (j = 0; j + 4 <= len; j += 4) {
      e0 += sq(j);
      e1 += sq(j + 1);
      e2 += sq(j + 2);
      e3 += sq(j + 3);
    }
    for (; j < len; ++j) e0 += sq(j);
    *se = (e0 + e1) + (e2 + e3);
  }
}

/// SSIM forward and backward in one pass over the images, with the L1 term of the photometric
/// loss: grad = l1_scale sign(x - y) + ssim_scale d(mean SSIM)/dx (overwritten), row_l1[r] and
/// (optional) row_se[r] the row sums of |x - y| and (x - y)^2; returns the mean SSIM.
///
/// Each thread runs the forward over its rows plus a halo of R rows on either side and feeds every
/// derivative row straight into the backward's horizontal pass, R rows behind: the derivative maps
/// never go to memory, and x and y are read while their rows are still in cache. The values are
/// those of ssim_fwd followed by ssim_bwd, bit for bit (the same operations on every row, whichever
/// thread computes it), so this path is as deterministic.
template <class S>
double ssim_fwd_bwd_with_l1(const Image<S>& x, const Image<S>& y, SsimWorkspace<S>& ws, SsimBorder border,
                            S ssim_scale, S l1_scale, Image<S>& grad, double* row_l1, double* row_se) {
  if (!ssim_begin(x, y, ws, false, border)) return 0.0;
  constexpr int R = ssim_window_radius;
  const int H = x.height, C = x.channels;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(x.width) * C;
  const auto win = ssim_window_1d<S>();
  const S* w = win.data();
  const S k = ssim_scale / static_cast<S>(ws.covered());
  reserve_thread_scratch(ws.thread_scratch, 2);
  constexpr int G = ssim_row_group;
#pragma omp parallel
  {
    int r0 = 0, r1 = 0;
    thread_rows(H, r0, r1);
    if (r0 < r1) {
      const std::size_t t = 2 * static_cast<std::size_t>(thread_index());
      // Forward extra: the statistics of a group of rows and the SSIM map row. Backward: its padded
      // inputs are the derivative rows, written there by the forward; extra: a group's filtered maps.
      SsimRowRing<S, ssim_fwd_quantities> fr(ws.thread_scratch[t], len, C, H, (ssim_fwd_quantities * G + 1) * len);
      SsimRowRing<S, ssim_bwd_quantities> br(ws.thread_scratch[t + 1], len, C, H, ssim_bwd_quantities * G * len);
      S* stats = fr.extra;
      S* smap = fr.extra + ssim_fwd_quantities * G * len;
      S* f = br.extra;
      const int f0 = std::max(0, r0 - R), f1 = std::min(H, r1 + R);
      fr.next = std::max(0, f0 - R);
      int rb = r0;  // first output row of the backward's next group
      for (int rf = f0; rf < f1; rf += G) {
        const int g = std::min(G, f1 - rf);
        ssim_fwd_stats(fr, x, y, rf, g, w, stats);
        for (int i = 0; i < g; ++i) {
          const int r = rf + i;
          ssim_fwd_row<true>(ws, r, stats + i * len, smap, br.input(0), br.input(1), br.input(2));
          if (r >= r0 && r < r1) ssim_row_sums(ws, r, smap);
          br.filter(r, C, w);
          // Each backward group as soon as the derivative rows it needs are filtered (the ring
          // holds the last 10 + G of them, as many as a group needs).
          for (int gb = std::min(G, r1 - rb); rb < r1 && std::min(H - 1, rb + gb - 1 + R) <= r;
               rb += gb, gb = std::min(G, r1 - rb)) {
            ssim_bwd_filtered_rows(br, rb, gb, w, f);
            for (int ib = 0; ib < gb; ++ib) {
              ssim_grad_row<true>(x, y, rb + ib, f, ib, k, l1_scale, grad.data.data());
              const std::ptrdiff_t o = (rb + ib) * len;
              l1_row_sums(x.data.data() + o, y.data.data() + o, len, row_l1[rb + ib],
                          row_se ? row_se + rb + ib : nullptr);
            }
          }
        }
      }
    }
  }
  return ssim_mean(ws, nullptr);
}

}  // namespace detail

/// Value of the photometric loss and, when `grad_render` is non-null, its gradient with respect to
/// `render` (overwritten, resized to the render's shape). L1 is the mean absolute difference over
/// pixels and channels; its derivative at a tie is 0 (as torch.sign). `ws` is scratch space.
/// `mse` (optional) receives the mean squared difference over pixels and channels, summed in the
/// same pass as L1 (a training step's PSNR, psnr_from_mse, without a serial pass of its own).
/// With a gradient, SSIM's forward and backward and the L1 term run as one pass
/// (detail::ssim_fwd_bwd_with_l1): the same values as ssim_fwd + ssim_bwd, without their maps.
template <class S>
double photometric_loss(const Image<S>& render, const Image<S>& gt, Image<S>* grad_render, SsimWorkspace<S>& ws,
                        const PhotometricLossConfig& cfg = {}, double* mse = nullptr) {
  detail::check_image("photometric_loss", "render", render);
  detail::check_image("photometric_loss", "gt", gt);
  detail::check_same_shape("photometric_loss", render.width, render.height, render.channels, gt.width, gt.height,
                           gt.channels);
  const bool want_grad = grad_render != nullptr;
  const double lambda = cfg.ssim_weight;
  const int H = render.height;
  const std::ptrdiff_t len = static_cast<std::ptrdiff_t>(render.width) * render.channels;
  // Every gradient value is written, so only reshape (no fill) when needed.
  if (want_grad && (grad_render->width != render.width || grad_render->height != render.height ||
                    grad_render->channels != render.channels || grad_render->size() != render.size()))
    grad_render->reset(render.width, render.height, render.channels);
  std::vector<double> row_l1(static_cast<std::size_t>(H)), row_se(mse ? static_cast<std::size_t>(H) : 0);
  double* se = mse ? row_se.data() : nullptr;
  double ssim_value = 0;
  if (want_grad) {
    const S l1_scale = static_cast<S>((1.0 - lambda) / static_cast<double>(std::max<std::size_t>(render.size(), 1)));
    ssim_value = detail::ssim_fwd_bwd_with_l1(render, gt, ws, cfg.ssim_border, static_cast<S>(-lambda), l1_scale,
                                              *grad_render, row_l1.data(), se);
  } else {
    ssim_value = ssim_fwd(render, gt, ws, false, nullptr, cfg.ssim_border);
#pragma omp parallel for schedule(static)
    for (int r = 0; r < H; ++r)
      detail::l1_row_sums(render.data.data() + r * len, gt.data.data() + r * len, len,
                          row_l1[static_cast<std::size_t>(r)], se ? se + r : nullptr);
  }
  if (render.data.empty()) {
    if (mse) *mse = 0.0;
    return 0.0;
  }
  double l1 = 0;
  for (double v : row_l1) l1 += v;
  l1 /= static_cast<double>(render.size());
  if (mse) {
    double s = 0;
    for (double v : row_se) s += v;
    *mse = s / static_cast<double>(render.size());
  }
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
/// `rows` (ascending Gaussian indices, or nullptr for all): the value and gradient are taken over
/// those Gaussians only, still normalised by N (a sparse step regularises what its view saw).
template <class S>
double scale_reg(std::span<const S> log_scales, std::span<S> grad_log_scales, const ScaleRegConfig& cfg = {},
                 const std::vector<std::uint32_t>* rows = nullptr) {
  if (log_scales.size() % 3 != 0)
    throw std::invalid_argument("scale_reg: log_scales has " + std::to_string(log_scales.size()) +
                                " values, expected a multiple of 3 ([N, 3])");
  const bool want_grad = !grad_log_scales.empty();
  if (want_grad && grad_log_scales.size() != log_scales.size())
    throw std::invalid_argument("scale_reg: grad_log_scales has " + std::to_string(grad_log_scales.size()) +
                                " values, expected " + std::to_string(log_scales.size()) + " ([N, 3])");
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(log_scales.size() / 3);
  if (n == 0) return 0.0;
  if (rows)
    for (std::uint32_t r : *rows)
      if (std::ptrdiff_t(r) >= n)
        throw std::invalid_argument("scale_reg: row " + std::to_string(r) + " outside " + std::to_string(n) + " Gaussians");
  const std::ptrdiff_t m = rows ? static_cast<std::ptrdiff_t>(rows->size()) : n;
  constexpr std::ptrdiff_t block = 4096;
  const std::ptrdiff_t nblocks = (m + block - 1) / block;
  std::vector<double> partial(static_cast<std::size_t>(nblocks), 0.0);
  const double gscale = cfg.weight / static_cast<double>(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t b = 0; b < nblocks; ++b) {
    double acc = 0;
    const std::ptrdiff_t end = std::min(m, (b + 1) * block);
    for (std::ptrdiff_t j = b * block; j < end; ++j) {
      const std::ptrdiff_t i = rows ? std::ptrdiff_t((*rows)[std::size_t(j)]) : j;
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

/// PSNR in dB of a mean squared error (floored at psnr_min_mse) for signals in [0, max_value].
inline double psnr_from_mse(double mse, double max_value = 1.0) {
  return 10.0 * std::log10(max_value * max_value / std::max(mse, psnr_min_mse));
}

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
  for (std::size_t c = 0; c < C; ++c) {
    const double m = P ? mse[c] / static_cast<double>(P) : 0.0;
    out[c] = psnr_from_mse(m, max_value);
  }
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
  return psnr_from_mse(mse, max_value);
}

/// Mean SSIM (same window as the training loss) over pixels and channels.
template <class S>
double ssim(const Image<S>& a, const Image<S>& b, SsimBorder border = SsimBorder::same) {
  SsimWorkspace<S> ws;
  return ssim_fwd(a, b, ws, false, nullptr, border);
}

/// Mean SSIM of each channel.
template <class S>
std::vector<double> ssim_per_channel(const Image<S>& a, const Image<S>& b, SsimBorder border = SsimBorder::same) {
  SsimWorkspace<S> ws;
  std::vector<double> out;
  ssim_fwd(a, b, ws, false, &out, border);
  return out;
}

}  // namespace msgs
