// include/msgs/project.hpp
// Stage 1 of the rasteriser: project one 3D Gaussian to a 2D screen-space Gaussian (EWA splatting,
// 3DGS/gsplat conventions) and its analytic backward, side by side. Internally double precision,
// which keeps extreme scales finite; the rasteriser projects a vector register's worth of
// Gaussians at once (detail::project_lanes), the public project_fwd / project_bwd one at a time,
// both to the same bits. The same code in single precision (lane types float and ProjVecF, twice
// the lanes) serves RasterOptions::single_precision, which hands the Gaussians beyond
// ProjectPrecisionLimits to the double-precision projection.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "camera.hpp"
#include "gaussian.hpp"
#include "detail/block_simd.hpp"
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

/// Where the single-precision projection (RasterOptions::single_precision) hands a Gaussian to the
/// double-precision one, which takes every input: any |log-scale| above kLogScale (its squared
/// scale would leave float's range), any |mean component| above kMean or |quaternion component|
/// above kQuat (non-finite ones included), a camera-space depth |z| below (2 max|mean| + max|t|) /
/// kDepthRatio (the rounding of the camera transform, about 2^-24 of |mean| + |t|, would no
/// longer be small against z: at most 1/128 of a focal length in pixels at kDepthRatio = 128),
/// and a screen covariance above kCov2d px^2 (sigma 10^4 px; a larger one would overflow the
/// backward's squared determinants). Each test reads only the Gaussian's own parameters and the
/// camera, so a Gaussian takes the same path in the forward and in the backward.
struct ProjectPrecisionLimits {
  static constexpr double kLogScale = 20.0;
  static constexpr double kMean = 1e7;
  static constexpr double kQuat = 1e15;
  static constexpr double kDepthRatio = 128.0;
  static constexpr double kCov2d = 1e8;
};

/// Camera in the double form the projection uses: world-to-camera rotation and translation as
/// plain arrays, and the camera centre in world space (for view directions).
struct ProjectCamera {
  double rot[9];    ///< R, row-major
  double trans[3];  ///< t
  Eigen::Vector3d position;  ///< -R^T t
  double fx, fy, cx, cy, near_plane, far_plane;
  int width, height;
  /// Tan-fov clamp limits of x/z and y/z (generalised for off-centre principal points).
  double lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;

  template <class S>
  static ProjectCamera from(const Camera<S>& c) {
    ProjectCamera p;
    const Eigen::Matrix3d R = c.R.template cast<double>();
    const Eigen::Vector3d t = c.t.template cast<double>();
    p.position = -(R.transpose() * t);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) p.rot[3 * i + j] = R(i, j);
      p.trans[i] = t[i];
    }
    p.fx = double(c.fx); p.fy = double(c.fy); p.cx = double(c.cx); p.cy = double(c.cy);
    p.near_plane = double(c.near_plane); p.far_plane = double(c.far_plane);
    p.width = c.width; p.height = c.height;
    using PC = ProjectConstants;
    const double tan_fovx = 0.5 * p.width / p.fx, tan_fovy = 0.5 * p.height / p.fy;
    p.lim_x_pos = (p.width - p.cx) / p.fx + PC::kFovClampMargin * tan_fovx;
    p.lim_x_neg = p.cx / p.fx + PC::kFovClampMargin * tan_fovx;
    p.lim_y_pos = (p.height - p.cy) / p.fy + PC::kFovClampMargin * tan_fovy;
    p.lim_y_neg = p.cy / p.fy + PC::kFovClampMargin * tan_fovy;
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
  double support = 0;         ///< ln(255 opacity): alpha >= 1/255 exactly where sigma <= support
};

// Small fixed-trip loops of the projection are unrolled completely before the vectoriser sees
// them: vectorised, they mix 8-byte stores with 16/32-byte reloads of the same stack slots, and
// every such reload stalls on store forwarding (the projection ran ~25% slower).
#define MSGS_UNROLL _Pragma("GCC unroll 9")

namespace detail {

// The projection works on plain row-major 3x3 arrays: written out, the small products compile to
// straight-line code, where Eigen's fixed-size packets stored element by element and reloaded as
// vectors stall on store forwarding (the projection ran ~25% slower with them).
//
// Every function below is written once for a lane type D: double (one Gaussian) or ProjVec (a
// vector of kProjLanes doubles, as many Gaussians at once: 8 with AVX-512, 4 with AVX, 2 with
// SSE2), or in single precision float (one Gaussian) or ProjVecF (kProjLanesF floats); constants
// and camera values enter in the lane's precision (T(x)), which changes nothing in double. Lane by
// lane the scalar and vector forms of a precision compute the same IEEE operations (exp and log
// included: lexp, llog), so a Gaussian projects to the same bits either way (tested). Culling becomes a lane mask; the
// scalar form returns as soon as its one lane is culled, the vector form when all are. Culled
// lanes of a vector compute on (possibly non-finite) garbage that is masked out.

/// Doubles per projection vector.
inline constexpr int kProjLanes = kVectorBytes / int(sizeof(double));
typedef double ProjVec __attribute__((vector_size(kProjLanes * sizeof(double))));
/// Floats per single-precision projection vector (twice as many Gaussians per instruction).
inline constexpr int kProjLanesF = kVectorBytes / int(sizeof(float));
typedef float ProjVecF __attribute__((vector_size(kProjLanesF * sizeof(float))));

/// Masks, selects and the elementary functions for lane type D (see above).
template <class D>
struct Lanes;

template <>
struct Lanes<double> {
  using T = double;  // the scalar of a lane
  using M = bool;
  static constexpr int kCount = 1;
  static double splat(double x) { return x; }
  static double sel(bool m, double a, double b) { return m ? a : b; }
  static bool any(bool m) { return m; }
  static bool not_(bool m) { return !m; }
  static double sqrt(double x) { return std::sqrt(x); }
};

template <>
struct Lanes<float> {
  using T = float;
  using M = bool;
  static constexpr int kCount = 1;
  static float splat(double x) { return float(x); }
  static float sel(bool m, float a, float b) { return m ? a : b; }
  static bool any(bool m) { return m; }
  static bool not_(bool m) { return !m; }
  static float sqrt(float x) { return std::sqrt(x); }
};

template <>
struct Lanes<ProjVec> {
  using T = double;
  using M = decltype(ProjVec{} < ProjVec{});  // the compiler's comparison type (long or long long lanes)
  static constexpr int kCount = kProjLanes;
  static ProjVec splat(double x) { return x - ProjVec{}; }
  static ProjVec sel(const M& m, const ProjVec& a, const ProjVec& b) { return m ? a : b; }
  static bool any(const M& m) { return lane_bits(m) != 0; }
  static M not_(const M& m) { return ~m; }
  static ProjVec sqrt(const ProjVec& x) {  // (kVectorBytes follows the same macros)
#if defined(__AVX512F__)
    // The masked form with a full mask: GCC 12's _mm512_sqrt_pd trips -Wmaybe-uninitialized on its
    // internal undefined pass-through operand.
    const __m512d v = std::bit_cast<__m512d>(x);
    return std::bit_cast<ProjVec>(_mm512_mask_sqrt_pd(v, __mmask8(0xff), v));
#elif defined(__AVX__)
    return std::bit_cast<ProjVec>(_mm256_sqrt_pd(std::bit_cast<__m256d>(x)));
#elif defined(__SSE2__)
    return std::bit_cast<ProjVec>(_mm_sqrt_pd(std::bit_cast<__m128d>(x)));
#else
    ProjVec r = x;
    for (int i = 0; i < kCount; ++i) r[i] = std::sqrt(x[i]);
    return r;
#endif
  }
};

template <>
struct Lanes<ProjVecF> {
  using T = float;
  using M = decltype(ProjVecF{} < ProjVecF{});  // 32-bit integer lanes
  static constexpr int kCount = kProjLanesF;
  static ProjVecF splat(double x) { return float(x) - ProjVecF{}; }
  static ProjVecF sel(const M& m, const ProjVecF& a, const ProjVecF& b) { return m ? a : b; }
  static bool any(const M& m) { return lane_bits(m) != 0; }
  static M not_(const M& m) { return ~m; }
  static ProjVecF sqrt(const ProjVecF& x) {
#if defined(__AVX512F__)
    const __m512 v = std::bit_cast<__m512>(x);
    return std::bit_cast<ProjVecF>(_mm512_mask_sqrt_ps(v, __mmask16(0xffff), v));
#elif defined(__AVX__)
    return std::bit_cast<ProjVecF>(_mm256_sqrt_ps(std::bit_cast<__m256>(x)));
#elif defined(__SSE2__)
    return std::bit_cast<ProjVecF>(_mm_sqrt_ps(std::bit_cast<__m128>(x)));
#else
    ProjVecF r = x;
    for (int i = 0; i < kCount; ++i) r[i] = std::sqrt(x[i]);
    return r;
#endif
  }
};

/// Is lane type D single precision (the fast projection, see project_lanes)?
template <class D>
inline constexpr bool kSingleLanes = std::is_same_v<typename Lanes<D>::T, float>;

/// Lane l of x (x itself for a one-lane type), and whether lane l of mask m is set.
template <class D>
inline typename Lanes<D>::T lane(const D& x, int l) {
  if constexpr (std::is_arithmetic_v<D>) return (void)l, x;
  else return x[l];
}
template <class M>
inline bool lane_on(const M& m, int l) {
  if constexpr (std::is_same_v<M, bool>) return (void)l, m;
  else return m[l] != 0;
}
/// Set lane l of x to v (x itself for a one-lane type).
template <class D>
inline void set_lane(D& x, int l, typename Lanes<D>::T v) {
  if constexpr (std::is_arithmetic_v<D>) (void)l, x = v;
  else x[l] = v;
}

/// Transpose an L x L block held as L vectors of L lanes (r[i] lane j becomes r[j] lane i), for
/// vector lane types (L a power of two): log2(L) rounds of two-vector lane shuffles, round B
/// swapping the off-diagonal B x B blocks of every 2B x 2B block. Moves bits only. For 16 floats
/// that is 64 shuffles where lane-by-lane copies take 256 loads and 256 stores.
template <class D, int B = Lanes<D>::kCount / 2>
inline void transpose_square(D* r) {
  constexpr int L = Lanes<D>::kCount;
  static_assert(L > 1 && (L & (L - 1)) == 0 && B >= 1, "transpose_square: vector lanes, a power of two");
  // Lanes j with bit B set come from the partner vector.
  struct Lo {
    constexpr int operator()(int j) const { return (j & B) ? L + j - B : j; }
  };
  struct Hi {
    constexpr int operator()(int j) const { return (j & B) ? L + j : j + B; }
  };
  for (int i = 0; i < L; ++i)
    if (!(i & B)) {
      const D a = r[i], c = r[i + B];
      r[i] = shuffle_lanes<Lo>(a, c);
      r[i + B] = shuffle_lanes<Hi>(a, c);
    }
  if constexpr (B > 1) transpose_square<D, B / 2>(r);
}

/// Logical and / or of masks: && and || for one lane, & and | for vector masks.
template <class M>
inline M mand(const M& a, const M& b) {
  if constexpr (std::is_same_v<M, bool>) return a && b;
  else return a & b;
}
template <class M, class... R>
inline M mand(const M& a, const M& b, const R&... rest) { return mand(mand(a, b), rest...); }
template <class M>
inline M mor(const M& a, const M& b) {
  if constexpr (std::is_same_v<M, bool>) return a || b;
  else return a | b;
}
template <class M, class... R>
inline M mor(const M& a, const M& b, const R&... rest) { return mor(mor(a, b), rest...); }

/// std::min, std::max and std::clamp, lane by lane with the same comparisons.
template <class D>
inline D lmin(const D& a, const D& b) { return Lanes<D>::sel(b < a, b, a); }
template <class D>
inline D lmax(const D& a, const D& b) { return Lanes<D>::sel(a < b, b, a); }
template <class D>
inline D lclamp(const D& v, double lo, double hi) {  // lo, hi exact in D's scalar
  using L = Lanes<D>;
  return L::sel(v < L::splat(lo), L::splat(lo), L::sel(L::splat(hi) < v, L::splat(hi), v));
}
/// Finite (neither infinite nor NaN): x - x is 0 exactly then.
template <class D>
inline auto lfinite(const D& x) { return (x - x) == Lanes<D>::splat(0.0); }

/// 64-bit integer lanes of D (the bit patterns of its doubles) and conversions to them.
template <class D>
struct LaneInts;
template <>
struct LaneInts<double> {
  using I = std::int64_t;
  static I from_integral(double x) { return I(x); }  // x integral and small
  static I one_where(bool m) { return m ? 1 : 0; }
};
template <>
struct LaneInts<ProjVec> {
  using I = Lanes<ProjVec>::M;  // signed 64-bit lanes
  static I from_integral(const ProjVec& x) { return __builtin_convertvector(x, I); }
  static I one_where(const I& m) { return -m; }  // true lanes are -1
};
/// 32-bit integer lanes of the single-precision types.
template <>
struct LaneInts<float> {
  using I = std::int32_t;
  static I from_integral(float x) { return I(x); }
  static I one_where(bool m) { return m ? 1 : 0; }
};
template <>
struct LaneInts<ProjVecF> {
  using I = Lanes<ProjVecF>::M;  // signed 32-bit lanes
  static I from_integral(const ProjVecF& x) { return __builtin_convertvector(x, I); }
  static I one_where(const I& m) { return -m; }
};

/// e^x in single precision, within 1 ulp or so (tested against std::exp): as lexp below with
/// Cephes' two-part ln 2 (n ln2_hi exact for |n| < 2^15) and the Taylor polynomial of degree 7
/// (truncation below 6e-9 on |r| <= ln(2) / 2).
template <class D>
inline D lexp_single(const D& x_in) {
  using L = Lanes<D>;
  using LI = LaneInts<D>;
  using I = typename LI::I;
  const D x = lclamp(x_in, -170.0, 170.0);             // beyond: 0 or inf anyway; NaN stays NaN
  const D shift = L::splat(12582912.0);                // 1.5 * 2^23: adding it rounds to an integer
  D n = (x * 1.44269504f + shift) - shift;             // round(x / ln 2)
  n = L::sel(n == n, n, L::splat(0.0));
  const D r = (x - n * 0.693359375f) - n * -2.12194440e-4f;
  constexpr float c[8] = {1.0f / 5040.0f, 1.0f / 720.0f, 1.0f / 120.0f, 1.0f / 24.0f, 1.0f / 6.0f, 0.5f, 1.0f, 1.0f};
  D p = L::splat(c[0]);
  for (int k = 1; k < 8; ++k) p = p * r + c[k];
  const I k = LI::from_integral(n);
  const I k1 = k >> 1, k2 = k - k1;  // |k1|, |k2| <= 123: both powers of two are normal floats
  const D s1 = std::bit_cast<D>((k1 + 127) << 23), s2 = std::bit_cast<D>((k2 + 127) << 23);
  return (p * s1) * s2;
}

/// ln x in single precision for positive normal finite x (NaN otherwise), within about 1 ulp: as
/// llog below with fdlibm's single-precision minimax polynomial (e_logf.c) and ln 2 in two parts.
template <class D>
inline D llog_single(const D& x) {
  using L = Lanes<D>;
  using LI = LaneInts<D>;
  using I = typename LI::I;
  const I bits = std::bit_cast<I>(x);
  I e = ((bits >> 23) & 0xff) - 127;
  D m = std::bit_cast<D>((bits & 0x007fffff) | (I{} + (127 << 23)));  // [1, 2)
  const auto big = m > L::splat(1.41421356f);
  m = L::sel(big, m * 0.5f, m);
  e = e + LI::one_where(big);
  const D f = m - 1.0f;  // exact (Sterbenz)
  const D s = f / (2.0f + f), z = s * s;
  const D R = z * (0x1.555554p-1f + z * (0x1.999c26p-2f + z * (0x1.23d3dcp-2f + z * 0x1.f13c4cp-3f)));
  const D hfsq = 0.5f * f * f;
  D de = L::splat(0.0);
  if constexpr (std::is_arithmetic_v<D>) de = float(e);
  else de = __builtin_convertvector(e, D);
  const D r = de * 6.9313812256e-01f + (f - (hfsq - (s * (hfsq + R) + de * 9.0580006145e-06f)));
  const auto normal = mand(x >= L::splat(0x1p-126), x <= L::splat(0x1.fffffep127));
  return L::sel(normal, r, L::splat(std::numeric_limits<double>::quiet_NaN()));
}

/// e^x, lane by lane, within 1 ulp or so of the exact value (tested against std::exp): x = n ln 2 + r
/// with |r| <= ln(2) / 2 (Cody-Waite, ln 2 in two parts), e^r by its Taylor polynomial of degree 13
/// (truncation below 1e-17), and 2^n applied as two exact powers of two so that results that
/// overflow, underflow or are subnormal come out as IEEE would round them. NaN gives NaN, +inf
/// gives inf, -inf gives 0. Written once for both lane types, so the vector and scalar projections
/// agree bit for bit without calling libm lane by lane.
template <class D>
inline D lexp_double(const D& x_in) {
  using L = Lanes<D>;
  using LI = LaneInts<D>;
  using I = typename LI::I;
  const D x = lclamp(x_in, -1100.0, 1100.0);           // beyond: 0 or inf anyway; NaN stays NaN
  const D shift = L::splat(6755399441055744.0);        // 1.5 * 2^52: adding it rounds to an integer
  D n = (x * 1.4426950408889634 + shift) - shift;      // round(x / ln 2)
  n = L::sel(n == n, n, L::splat(0.0));                // NaN lanes: any n (r stays NaN)
  const D r = (x - n * 0x1.62e42fee00000p-1) - n * 0x1.a39ef35793c76p-33;  // n ln2_hi is exact
  constexpr double c[14] = {1.0 / 6227020800.0, 1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0,
                            1.0 / 362880.0,     1.0 / 40320.0,     1.0 / 5040.0,     1.0 / 720.0,
                            1.0 / 120.0,        1.0 / 24.0,        1.0 / 6.0,        0.5,
                            1.0,                1.0};
  D p = L::splat(c[0]);
  for (int k = 1; k < 14; ++k) p = p * r + c[k];
  const I k = LI::from_integral(n);
  const I k1 = k >> 1, k2 = k - k1;  // |k1|, |k2| <= 794: both powers of two are normal doubles
  const D s1 = std::bit_cast<D>((k1 + 1023) << 52), s2 = std::bit_cast<D>((k2 + 1023) << 52);
  return (p * s1) * s2;
}

/// ln x, lane by lane, within about 1 ulp (tested against std::log), for positive normal finite x
/// (the projection's arguments are in [1, 255]); every other input gives NaN. x = 2^e m with m in
/// [sqrt(2)/2, sqrt(2)), and ln m = ln(1 + f) from s = f / (2 + f) with fdlibm's minimax polynomial
/// (the coefficients of its e_log.c) and ln 2 in two parts.
template <class D>
inline D llog_double(const D& x) {
  using L = Lanes<D>;
  using LI = LaneInts<D>;
  using I = typename LI::I;
  const I bits = std::bit_cast<I>(x);
  I e = ((bits >> 52) & 0x7ff) - 1023;
  D m = std::bit_cast<D>((bits & 0x000fffffffffffffLL) | (I{} + (std::int64_t(1023) << 52)));  // [1, 2)
  const auto big = m > L::splat(1.4142135623730951);
  m = L::sel(big, m * 0.5, m);
  e = e + LI::one_where(big);
  const D f = m - 1.0;  // exact (Sterbenz)
  const D s = f / (2.0 + f), z = s * s;
  const D R = z * (6.666666666666735130e-01 +
                   z * (3.999999999940941908e-01 +
                        z * (2.857142874366239149e-01 +
                             z * (2.222219843214978396e-01 +
                                  z * (1.818357216161805012e-01 + z * (1.531383769920937332e-01 + z * 1.479819860511658591e-01))))));
  const D hfsq = 0.5 * f * f;
  D de = L::splat(0.0);
  if constexpr (std::is_same_v<D, double>) de = double(e);
  else de = __builtin_convertvector(e, D);
  const D r = de * 0x1.62e42fee00000p-1 + (f - (hfsq - (s * (hfsq + R) + de * 0x1.a39ef35793c76p-33)));
  const auto normal = mand(x >= L::splat(0x1p-1022), x <= L::splat(0x1.fffffffffffffp1023));
  return L::sel(normal, r, L::splat(std::numeric_limits<double>::quiet_NaN()));
}

/// e^x and ln x in D's precision (lexp_double / lexp_single, llog_double / llog_single).
template <class D>
inline D lexp(const D& x) {
  if constexpr (kSingleLanes<D>) return lexp_single(x);
  else return lexp_double(x);
}
template <class D>
inline D llog(const D& x) {
  if constexpr (kSingleLanes<D>) return llog_single(x);
  else return llog_double(x);
}

/// Numerically stable logistic function: 1 / (1 + e^-x) for x >= 0, e^x / (1 + e^x) below,
/// with one exponential, e^-|x|, for both.
template <class D>
inline D lsigmoid(const D& x) {
  using L = Lanes<D>;
  using T = typename L::T;
  const D e = lexp(L::sel(x < L::splat(0.0), x, -x));
  return L::sel(x >= L::splat(0.0), T(1) / (T(1) + e), e / (T(1) + e));
}

/// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
template <class D>
inline void quat_to_rotation(const D q[4], D R[9]) {
  const D w = q[0], x = q[1], y = q[2], z = q[3];
  R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
  R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
  R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
}

/// dL/dq for a unit quaternion q given dL/dR (row-major G).
template <class D>
inline void quat_to_rotation_backward(const D q[4], const D G[9], D d[4]) {
  const D w = q[0], x = q[1], y = q[2], z = q[3];
  auto g = [G](int i, int j) { return G[3 * i + j]; };
  d[0] = 2 * (-z * g(0, 1) + y * g(0, 2) + z * g(1, 0) - x * g(1, 2) - y * g(2, 0) + x * g(2, 1));
  d[1] = 2 * (y * g(0, 1) + z * g(0, 2) + y * g(1, 0) - 2 * x * g(1, 1) - w * g(1, 2) + z * g(2, 0) +
              w * g(2, 1) - 2 * x * g(2, 2));
  d[2] = 2 * (-2 * y * g(0, 0) + x * g(0, 1) + w * g(0, 2) + x * g(1, 0) + z * g(1, 2) - w * g(2, 0) +
              z * g(2, 1) - 2 * y * g(2, 2));
  d[3] = 2 * (-2 * z * g(0, 0) - w * g(0, 1) + x * g(0, 2) + w * g(1, 0) - 2 * z * g(1, 1) + y * g(1, 2) +
              x * g(2, 0) + y * g(2, 1));
}

/// C = A B for row-major 3x3 matrices.
template <class D, class DA>
inline void mul33(const DA A[9], const D B[9], D C[9]) {
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i)
    MSGS_UNROLL
    for (int j = 0; j < 3; ++j) C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}

/// C = A^T B for row-major 3x3 matrices.
template <class D, class DA>
inline void mul33_tn(const DA A[9], const D B[9], D C[9]) {
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i)
    MSGS_UNROLL
    for (int j = 0; j < 3; ++j) C[3 * i + j] = A[i] * B[j] + A[3 + i] * B[3 + j] + A[6 + i] * B[6 + j];
}

/// A Gaussian's geometry parameters in lane type D.
template <class D>
struct GeometryLanes {
  D mean[3], log_scale[3], quat[4], opacity_logit;
};

/// The forward result in lane type D (see ProjectedGaussian); `visible` is the lane mask. `hard`
/// (single precision only): lanes left to the double-precision projection (see project_lanes),
/// never visible here.
template <class D>
struct ProjectedLanes {
  typename Lanes<D>::M visible, hard;
  D mean2d[2], conic[3], depth, opacity, extent[2], support;
};

/// Screen-space gradients in lane type D (see ProjectedGrad).
template <class D>
struct ProjectedGradLanes {
  D mean2d[2], conic[3], opacity, depth;
};

/// Geometry gradients in lane type D (see GeometryGrad).
template <class D>
struct GeometryGradLanes {
  D mean[3], log_scale[3], quat[4], opacity_logit;
};

/// Intermediate values of the projection that the backward pass reuses.
template <class D>
struct ProjectionCacheLanes {
  D qhat[4];          // normalised quaternion
  D qnorm;
  D scale[3];         // exp(clamped log-scale)
  D scale_active[3];  // 1 where the log-scale was not clamped
  D Rq[9];            // rotation of the Gaussian (row-major)
  D WM[9];            // W Rq diag(scale): Sigma_cam = WM WM^T
  D tcam[3];          // camera-space mean
  D inv_tz;           // 1 / tcam[2]
  D txz, tyz;         // tx / tz, ty / tz before clamping
  D J00, J02, J11, J12;  // EWA Jacobian [[J00, 0, J02], [0, J11, J12]]
  D cov2d[3];         // before dilation: xx, xy, yy
  D blur[3];          // after dilation
  D det_blur, det_orig;
  D compensation;     // antialiasing factor (1 when disabled)
  typename Lanes<D>::M compensation_floored;
  D sig;              // sigmoid(logit)
};
using ProjectionCache = ProjectionCacheLanes<double>;

/// project_fwd in lane type D; returns the visible mask (also out.visible). See project_fwd.
template <bool Antialiased, class D>
inline typename Lanes<D>::M project_lanes(const GeometryLanes<D>& g, const ProjectCamera& cam, ProjectedLanes<D>& out,
                                          std::type_identity_t<ProjectionCacheLanes<D>>* cache_out,
                                          bool known_visible) {
  using PC = ProjectConstants;
  using PL = ProjectPrecisionLimits;
  using L = Lanes<D>;
  using T = typename L::T;
  using M = typename L::M;
  constexpr bool kSingle = kSingleLanes<D>;
  const D zero = L::splat(0.0);
  M alive = lfinite(g.opacity_logit);
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i) alive = mand(alive, lfinite(g.mean[i]), lfinite(g.log_scale[i]));
  MSGS_UNROLL
  for (int i = 0; i < 4; ++i) alive = mand(alive, lfinite(g.quat[i]));
  D mean_max = zero;  // max |mean component| (single precision only)
  out.hard = M{};
  if constexpr (kSingle) {
    // Inputs beyond the limits (non-finite ones too) go to the double-precision projection.
    M tame = alive;
    MSGS_UNROLL
    for (int i = 0; i < 3; ++i) {
      mean_max = lmax(mean_max, lmax(g.mean[i], -g.mean[i]));
      tame = mand(tame, g.log_scale[i] <= L::splat(PL::kLogScale), -g.log_scale[i] <= L::splat(PL::kLogScale));
    }
    tame = mand(tame, mean_max <= L::splat(PL::kMean));
    MSGS_UNROLL
    for (int i = 0; i < 4; ++i) tame = mand(tame, g.quat[i] <= L::splat(PL::kQuat), -g.quat[i] <= L::splat(PL::kQuat));
    out.hard = L::not_(tame);
    alive = tame;
  }
  out.visible = alive;
  if (!L::any(alive)) return alive;
  ProjectionCacheLanes<D> c;
  T W[9];  // the camera in D's precision
  MSGS_UNROLL
  for (int i = 0; i < 9; ++i) W[i] = T(cam.rot[i]);
  const T fx = T(cam.fx), fy = T(cam.fy);
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i)
    c.tcam[i] = ((W[3 * i] * g.mean[0] + W[3 * i + 1] * g.mean[1]) + W[3 * i + 2] * g.mean[2]) + T(cam.trans[i]);
  const D tz = c.tcam[2];
  if constexpr (kSingle) {
    // The camera-space mean carries an absolute rounding error of about 2^-24 (|mean| + |t|):
    // where that is not small against the depth, project in double.
    const T t_max = T(std::max({std::abs(cam.trans[0]), std::abs(cam.trans[1]), std::abs(cam.trans[2])}));
    const M shallow = L::not_(T(2) * mean_max + t_max <= T(PL::kDepthRatio) * lmax(tz, -tz));
    out.hard = mor(out.hard, mand(alive, shallow));
    alive = mand(alive, L::not_(shallow));
  }
  alive = mand(alive, tz > L::splat(cam.near_plane), L::not_(tz > L::splat(cam.far_plane)));
  if (!L::any(alive)) return out.visible = alive;

  const D* quat = g.quat;
  c.qnorm = L::sqrt(quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3]);
  alive = mand(alive, c.qnorm >= L::splat(PC::kMinQuatNorm));
  if (!L::any(alive)) return out.visible = alive;
  const D inv_qnorm = T(1) / c.qnorm;  // divisions are the projection's slowest operations
  MSGS_UNROLL
  for (int i = 0; i < 4; ++i) c.qhat[i] = quat[i] * inv_qnorm;

  c.sig = lsigmoid(g.opacity_logit);
  alive = mand(alive, c.sig >= L::splat(PC::kMinAlpha));
  if (!L::any(alive)) return out.visible = alive;

  c.inv_tz = T(1) / tz;
  c.txz = c.tcam[0] * c.inv_tz;
  c.tyz = c.tcam[1] * c.inv_tz;
  const D txc = lmin(L::splat(cam.lim_x_pos), lmax(L::splat(-cam.lim_x_neg), c.txz));
  const D tyc = lmin(L::splat(cam.lim_y_pos), lmax(L::splat(-cam.lim_y_neg), c.tyz));
  const D mean_x = fx * c.txz + T(cam.cx), mean_y = fy * c.tyz + T(cam.cy);

  // Far off-screen? Most Gaussians of a large scene are outside any one view, so bound the screen
  // extent before building the covariance: cov2d(0,0) = j0^T cov_cam j0 <= s_max^2 |j0|^2 with
  // |j0|^2 = (fx/tz)^2 (1 + txc^2), and the antialiasing compensation only lowers the opacity.
  // A Gaussian culled here is one the exact test below would cull too, so the backward (which
  // recomputes the projection of a Gaussian it knows to be visible, with cache_out set) skips it.
  // Without antialiasing the opacity is sig, so kb is also the extent's factor below.
  D kb = L::splat(-1.0), log_sig = zero;
  if (!cache_out) {
    const D ls_max = lmax(g.log_scale[0], lmax(g.log_scale[1], g.log_scale[2]));
    const D smax = lexp(lclamp(ls_max, -PC::kLogScaleClamp, PC::kLogScaleClamp));
    log_sig = llog(c.sig / T(PC::kMinAlpha));
    kb = L::sqrt(lmax(zero, T(2) * log_sig));
    const D sx = smax * fx * c.inv_tz, sy = smax * fy * c.inv_tz;
    // A bound with a relative margin of 1e-6 (single precision: 1e-4) against rounding.
    constexpr T kMargin = kSingle ? T(1e-4) : T(1e-6);
    const D bx = kb * L::sqrt(sx * sx * (T(1) + txc * txc) + T(PC::kDilation)) * (T(1) + kMargin) + kMargin;
    const D by = kb * L::sqrt(sy * sy * (T(1) + tyc * tyc) + T(PC::kDilation)) * (T(1) + kMargin) + kMargin;
    const M off = mor(mean_x + bx < L::splat(-1.0), mean_x - bx > L::splat(cam.width + 1.0),
                      mean_y + by < L::splat(-1.0), mean_y - by > L::splat(cam.height + 1.0));
    alive = mand(alive, L::not_(off));
    if (!L::any(alive)) return out.visible = alive;
  }

  MSGS_UNROLL
  for (int i = 0; i < 3; ++i) {
    const D cl = lclamp(g.log_scale[i], -PC::kLogScaleClamp, PC::kLogScaleClamp);
    c.scale_active[i] = L::sel(g.log_scale[i] == cl, L::splat(1.0), zero);
    c.scale[i] = lexp(cl);
  }
  quat_to_rotation(c.qhat, c.Rq);
  // WM = W Rq diag(scale); cov_cam = W Sigma W^T = WM WM^T.
  {
    D Mx[9];
    MSGS_UNROLL
    for (int i = 0; i < 3; ++i)
      MSGS_UNROLL
      for (int j = 0; j < 3; ++j) Mx[3 * i + j] = c.Rq[3 * i + j] * c.scale[j];
    mul33(W, Mx, c.WM);
  }

  // EWA Jacobian with the generalised tan-fov clamp.
  // J02 = -fx tx / tz^2 with tx = tz txc, i.e. -fx txc / tz.
  c.J00 = fx * c.inv_tz;
  c.J02 = -c.J00 * txc;
  c.J11 = fy * c.inv_tz;
  c.J12 = -c.J11 * tyc;
  // cov2d = J cov_cam J^T = (J WM)(J WM)^T, with J's zeros skipped; symmetric by construction.
  D T0[3], T1[3];
  MSGS_UNROLL
  for (int j = 0; j < 3; ++j) {
    T0[j] = c.J00 * c.WM[j] + c.J02 * c.WM[6 + j];
    T1[j] = c.J11 * c.WM[3 + j] + c.J12 * c.WM[6 + j];
  }
  c.cov2d[0] = T0[0] * T0[0] + T0[1] * T0[1] + T0[2] * T0[2];
  c.cov2d[1] = T0[0] * T1[0] + T0[1] * T1[1] + T0[2] * T1[2];
  c.cov2d[2] = T1[0] * T1[0] + T1[1] * T1[1] + T1[2] * T1[2];
  c.blur[0] = c.cov2d[0] + T(PC::kDilation);
  c.blur[1] = c.cov2d[1];
  c.blur[2] = c.cov2d[2] + T(PC::kDilation);
  if constexpr (kSingle) {
    // Screen footprints beyond the limit go to the double-precision projection.
    const M huge = L::not_(lmax(c.cov2d[0], c.cov2d[2]) <= L::splat(PL::kCov2d));
    out.hard = mor(out.hard, mand(alive, huge));
    alive = mand(alive, L::not_(huge));
    // det cov2d = det(T T^T) for the 2x3 matrix T = [T0; T1] as a sum of squared 2x2 minors
    // (Cauchy-Binet): never negative, and free of the cancellation of a c - b^2 for needles, which
    // in single precision can exceed the 0.3 px^2 filter's share of the determinant.
    const D m01 = T0[0] * T1[1] - T0[1] * T1[0], m02 = T0[0] * T1[2] - T0[2] * T1[0];
    const D m12 = T0[1] * T1[2] - T0[2] * T1[1];
    c.det_orig = (m01 * m01 + m02 * m02) + m12 * m12;
    c.det_blur = (c.det_orig + T(PC::kDilation) * (c.cov2d[0] + c.cov2d[2])) + T(PC::kDilation * PC::kDilation);
  } else {
    c.det_blur = c.blur[0] * c.blur[2] - c.blur[1] * c.blur[1];
    c.det_orig = c.cov2d[0] * c.cov2d[2] - c.cov2d[1] * c.cov2d[1];
  }
  alive = mand(alive, c.det_blur > zero, lfinite(c.det_blur));
  if (!L::any(alive)) return out.visible = alive;

  c.compensation = L::splat(1.0);
  c.compensation_floored = M{};
  if constexpr (Antialiased) {
    const D comp = L::sqrt(lmax(zero, c.det_orig / c.det_blur));
    c.compensation_floored = L::not_(comp > L::splat(PC::kMinCompensation));
    c.compensation = L::sel(c.compensation_floored, L::splat(PC::kMinCompensation), comp);
  }
  const D opacity = c.sig * c.compensation;
  alive = mand(alive, opacity >= L::splat(PC::kMinAlpha));
  if (!L::any(alive)) return out.visible = alive;

  out.mean2d[0] = mean_x;
  out.mean2d[1] = mean_y;
  const D inv_det = T(1) / c.det_blur;
  out.conic[0] = c.blur[2] * inv_det;
  out.conic[1] = -c.blur[1] * inv_det;
  out.conic[2] = c.blur[0] * inv_det;
  out.depth = tz;
  out.opacity = opacity;
  if (!(cache_out && known_visible)) {
    // alpha >= 1/255  <=>  sigma <= ln(255 o): the exact support, no 3-sigma cut-off, so the tiled
    // renderer paints exactly what a per-pixel loop over all Gaussians would.
    const bool reuse = !Antialiased && !cache_out;  // opacity == sig: the pre-test's values hold
    out.support = reuse ? log_sig : llog(opacity / T(PC::kMinAlpha));
    const D k = reuse ? kb : L::sqrt(lmax(zero, T(2) * out.support));
    out.extent[0] = k * L::sqrt(c.blur[0]);
    out.extent[1] = k * L::sqrt(c.blur[2]);
    alive = mand(alive, lfinite(out.mean2d[0]), lfinite(out.mean2d[1]), lfinite(out.extent[0]), lfinite(out.extent[1]));
    // Entirely off-screen (with a pixel of margin)?
    const M off = mor(out.mean2d[0] + out.extent[0] < L::splat(-1.0), out.mean2d[0] - out.extent[0] > L::splat(cam.width + 1.0),
                      out.mean2d[1] + out.extent[1] < L::splat(-1.0), out.mean2d[1] - out.extent[1] > L::splat(cam.height + 1.0));
    alive = mand(alive, L::not_(off));
  }
  out.visible = alive;
  if (cache_out && L::any(alive)) *cache_out = c;
  return alive;
}

// GCC cannot tell that project_lanes fills `out` and `c` whenever a lane survives (the only case in
// which project_bwd_lanes reads them), and zero-initialising them cost ~6% of the backward's
// projection. The warning is silenced for this function only.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
/// project_bwd in lane type D: accumulates into `grad` the gradients of the lanes that project
/// (the others are left as they are). Returns the lanes left to the double-precision projection
/// (ProjectedLanes::hard; none in double), whose gradients are not touched either. See project_bwd.
template <bool Antialiased, class D>
inline typename Lanes<D>::M project_bwd_lanes(const GeometryLanes<D>& g, const ProjectCamera& cam,
                                              const ProjectedGradLanes<D>& v, GeometryGradLanes<D>& grad,
                                              bool known_visible) {
  using L = Lanes<D>;
  using T = typename L::T;
  using M = typename L::M;
  const D zero = L::splat(0.0);
  ProjectedLanes<D> out;
  ProjectionCacheLanes<D> c;  // both set by project_lanes whenever a lane projects
  const M alive = project_lanes<Antialiased>(g, cam, out, &c, known_visible);
  if (!L::any(alive)) return out.hard;
  T W[9];
  MSGS_UNROLL
  for (int i = 0; i < 9; ++i) W[i] = T(cam.rot[i]);
  const T fx = T(cam.fx), fy = T(cam.fy);
  // Gradients of culled lanes (only with vectors; the scalar form returned above) are dropped.
  auto add = [&](D& acc, const D& d) {
    if constexpr (std::is_arithmetic_v<D>) acc += d;
    else acc += L::sel(alive, d, zero);
  };

  // Opacity: o = sigmoid(logit) * compensation.
  add(grad.opacity_logit, v.opacity * c.compensation * c.sig * (T(1) - c.sig));

  // Conic Q = inverse(cov2d_blur): dL/dCov = -Q dL/dQ Q with Q symmetric; b appears twice in Q,
  // so dL/dQ has b's gradient halved off the diagonal. G = v_cov is the gradient w.r.t.
  // cov2d_blur as a full 2x2 matrix [[G00, G01], [G10, G11]].
  const D qa = out.conic[0], qb = out.conic[1], qc = out.conic[2];
  const D va = v.conic[0], vb = T(0.5) * v.conic[1], vc = v.conic[2];
  const D P00 = qa * va + qb * vb, P01 = qa * vb + qb * vc, P10 = qb * va + qc * vb, P11 = qb * vb + qc * vc;
  D G00 = -(P00 * qa + P01 * qb), G01 = -(P00 * qb + P01 * qc);
  D G10 = -(P10 * qa + P11 * qb), G11 = -(P10 * qb + P11 * qc);

  if constexpr (Antialiased) {
    // compensation = sqrt(det_orig / det_blur); d det(A)/dA = det(A) A^{-T} = adj(A)^T.
    // No gradient where the compensation is floored.
    const D v_comp = L::sel(c.compensation_floored, zero, v.opacity * c.sig);
    const D r = c.det_orig / c.det_blur;
    const D v_r = L::sel(c.compensation_floored, zero, v_comp * T(0.5) / L::sqrt(r));
    // r depends on cov2d through both determinants (cov2d_blur = cov2d + 0.3 I).
    const D k_orig = v_r / c.det_blur, k_blur = v_r * c.det_orig / (c.det_blur * c.det_blur);
    G00 += k_orig * c.cov2d[2] - k_blur * c.blur[2];
    G11 += k_orig * c.cov2d[0] - k_blur * c.blur[0];
    G01 += -k_orig * c.cov2d[1] + k_blur * c.blur[1];
    G10 += -k_orig * c.cov2d[1] + k_blur * c.blur[1];
  }

  // cov2d = J C J^T with C = WM WM^T  ->  dL/dC = J^T G J, dL/dJ = 2 G J C (G, C symmetric).
  // GJ = G J (2x3), J = [[J00, 0, J02], [0, J11, J12]].
  const D GJ[2][3] = {{G00 * c.J00, G01 * c.J11, G00 * c.J02 + G01 * c.J12},
                      {G10 * c.J00, G11 * c.J11, G10 * c.J02 + G11 * c.J12}};
  // v_cc2 = 2 v_cov_cam = 2 J^T GJ (3x3, row-major); the 2 is the one of dL/dM below.
  const D Jcol[3][2] = {{c.J00, zero}, {zero, c.J11}, {c.J02, c.J12}};  // column i of J
  D v_cc2[9];
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i)
    MSGS_UNROLL
    for (int j = 0; j < 3; ++j) v_cc2[3 * i + j] = T(2) * (Jcol[i][0] * GJ[0][j] + Jcol[i][1] * GJ[1][j]);
  // C = WM WM^T; v_J = 2 GJ C, needed at (0,0), (0,2), (1,1), (1,2).
  D C[9];
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i)
    MSGS_UNROLL
    for (int j = 0; j < 3; ++j)
      C[3 * i + j] = c.WM[3 * i] * c.WM[3 * j] + c.WM[3 * i + 1] * c.WM[3 * j + 1] + c.WM[3 * i + 2] * c.WM[3 * j + 2];
  auto v_J = [&](int a, int j) { return T(2) * (GJ[a][0] * C[j] + GJ[a][1] * C[3 + j] + GJ[a][2] * C[6 + j]); };
  const D vJ00 = v_J(0, 0), vJ02 = v_J(0, 2), vJ11 = v_J(1, 1), vJ12 = v_J(1, 2);

  // J entries -> camera-space mean (clamped components only depend on tz).
  D v_t[3] = {zero, zero, zero};
  const D iz = c.inv_tz, iz2 = iz * iz, iz3 = iz2 * iz;
  v_t[2] += -fx * iz2 * vJ00 - fy * iz2 * vJ11;
  const M x_clamped = mor(c.txz > L::splat(cam.lim_x_pos), c.txz < L::splat(-cam.lim_x_neg));
  const M y_clamped = mor(c.tyz > L::splat(cam.lim_y_pos), c.tyz < L::splat(-cam.lim_y_neg));
  {
    const D Lx = lmin(L::splat(cam.lim_x_pos), lmax(L::splat(-cam.lim_x_neg), c.txz));
    // clamped: J02 = -fx L / tz depends on tz only; else on tx and tz.
    v_t[2] += L::sel(x_clamped, fx * Lx * iz2 * vJ02, T(2) * fx * c.tcam[0] * iz3 * vJ02);
    v_t[0] += L::sel(x_clamped, zero, -fx * iz2 * vJ02);
    const D Ly = lmin(L::splat(cam.lim_y_pos), lmax(L::splat(-cam.lim_y_neg), c.tyz));
    v_t[2] += L::sel(y_clamped, fy * Ly * iz2 * vJ12, T(2) * fy * c.tcam[1] * iz3 * vJ12);
    v_t[1] += L::sel(y_clamped, zero, -fy * iz2 * vJ12);
  }
  // Projected mean (unclamped).
  v_t[0] += fx * iz * v.mean2d[0];
  v_t[1] += fy * iz * v.mean2d[1];
  v_t[2] += -fx * c.tcam[0] * iz2 * v.mean2d[0] - fy * c.tcam[1] * iz2 * v.mean2d[1];
  v_t[2] += v.depth;
  MSGS_UNROLL
  for (int i = 0; i < 3; ++i) add(grad.mean[i], W[i] * v_t[0] + W[3 + i] * v_t[1] + W[6 + i] * v_t[2]);

  // cov_cam = W Sigma W^T; Sigma = M M^T with M = Rq diag(s):
  // dL/dM = 2 W^T v_cov_cam W M = W^T (v_cc2 WM).
  D X[9], v_M[9];
  mul33(v_cc2, c.WM, X);
  mul33_tn(W, X, v_M);
  D v_Rq[9];
  MSGS_UNROLL
  for (int j = 0; j < 3; ++j) {
    const D v_s = c.Rq[j] * v_M[j] + c.Rq[3 + j] * v_M[3 + j] + c.Rq[6 + j] * v_M[6 + j];
    add(grad.log_scale[j], v_s * c.scale[j] * c.scale_active[j]);
    MSGS_UNROLL
    for (int i = 0; i < 3; ++i) v_Rq[3 * i + j] = v_M[3 * i + j] * c.scale[j];
  }
  D v_qhat[4];
  quat_to_rotation_backward(c.qhat, v_Rq, v_qhat);
  const D qdot = c.qhat[0] * v_qhat[0] + c.qhat[1] * v_qhat[1] + c.qhat[2] * v_qhat[2] + c.qhat[3] * v_qhat[3];
  const D inv_qnorm = T(1) / c.qnorm;
  MSGS_UNROLL
  for (int i = 0; i < 4; ++i) add(grad.quat[i], (v_qhat[i] - c.qhat[i] * qdot) * inv_qnorm);
  return out.hard;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

/// Lanes 0 .. L) of `out` [W][L] from the W interleaved values of L consecutive rows at `src`
/// (src[W l + k] goes to out[k][l]): a loop the vectoriser turns into whole-vector loads and
/// permutations, where a lane at a time is one insert per value.
template <int W, int L, class T, class S>
inline void deinterleave_rows(const S* __restrict src, T (*__restrict out)[L]) {
  for (int l = 0; l < L; ++l)
    for (int k = 0; k < W; ++k) out[k][l] = T(src[W * l + k]);
}

/// The geometry of the Gaussians ids[0 .. Lanes<D>::kCount) of `m` as the lanes of D.
template <class D, class G, class S>
inline void gather_geometry(const GaussianModel<G, S>& m, const std::uint32_t* ids, GeometryLanes<D>& g) {
  using T = typename Lanes<D>::T;
  constexpr int L = Lanes<D>::kCount;
  if constexpr (L > 1) {
    // Consecutive rows (the projection of the whole model runs over them in order): whole rows.
    bool consecutive = true;
    for (int l = 1; l < L; ++l) consecutive &= ids[l] == ids[0] + std::uint32_t(l);
    if (consecutive) {
      const std::size_t i = ids[0];
      alignas(64) T mean[3][L], log_scale[3][L], quat[4][L], opacity[1][L];
      deinterleave_rows<3, L>(m.means.data() + 3 * i, mean);
      deinterleave_rows<3, L>(m.log_scales.data() + 3 * i, log_scale);
      deinterleave_rows<4, L>(m.quats.data() + 4 * i, quat);
      deinterleave_rows<1, L>(m.opacity_logits.data() + i, opacity);
      for (int k = 0; k < 3; ++k) {
        std::memcpy(&g.mean[k], mean[k], sizeof(D));
        std::memcpy(&g.log_scale[k], log_scale[k], sizeof(D));
      }
      for (int k = 0; k < 4; ++k) std::memcpy(&g.quat[k], quat[k], sizeof(D));
      std::memcpy(&g.opacity_logit, opacity[0], sizeof(D));
      return;
    }
  }
  for (int l = 0; l < L; ++l) {
    const std::size_t i = ids[l];
    for (int k = 0; k < 3; ++k) {
      set_lane(g.mean[k], l, T(m.means[3 * i + std::size_t(k)]));
      set_lane(g.log_scale[k], l, T(m.log_scales[3 * i + std::size_t(k)]));
    }
    for (int k = 0; k < 4; ++k) set_lane(g.quat[k], l, T(m.quats[4 * i + std::size_t(k)]));
    set_lane(g.opacity_logit, l, T(m.opacity_logits[i]));
  }
}

/// One Gaussian's geometry as one lane.
inline GeometryLanes<double> geometry_lanes(const GaussianGeometry& g) {
  GeometryLanes<double> gl;
  for (int i = 0; i < 3; ++i) {
    gl.mean[i] = g.mean[i];
    gl.log_scale[i] = g.log_scale[i];
  }
  for (int i = 0; i < 4; ++i) gl.quat[i] = g.quat[i];
  gl.opacity_logit = g.opacity_logit;
  return gl;
}
}  // namespace detail

/// Project one Gaussian. Returns false (and `out.visible = false`) when the Gaussian is culled:
/// non-finite parameters, degenerate quaternion, outside (near, far], invisible opacity,
/// degenerate screen covariance, or entirely off-screen. `Antialiased` multiplies the opacity by
/// sqrt(det cov2d / det(cov2d + 0.3 I)) (floored at 0.005), gsplat's antialiased mode.
/// `known_visible` (with `cache_out`, for a backward pass of a Gaussian its forward found visible
/// with the same inputs): skip the screen-extent tests, which could only pass again; `out.extent`
/// and `out.support` are then not set. detail::project_lanes projects several Gaussians at once,
/// to the same bits.
template <bool Antialiased>
inline bool project_fwd(const GaussianGeometry& g, const ProjectCamera& cam, ProjectedGaussian& out,
                        detail::ProjectionCache* cache_out = nullptr, bool known_visible = false) {
  detail::ProjectedLanes<double> o;
  out.visible = detail::project_lanes<Antialiased>(detail::geometry_lanes(g), cam, o, cache_out, known_visible);
  if (!out.visible) return false;
  out.mean2d[0] = o.mean2d[0];
  out.mean2d[1] = o.mean2d[1];
  for (int i = 0; i < 3; ++i) out.conic[i] = o.conic[i];
  out.depth = o.depth;
  out.opacity = o.opacity;
  if (!(cache_out && known_visible)) {
    out.extent[0] = o.extent[0];
    out.extent[1] = o.extent[1];
    out.support = o.support;
  }
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
/// Gaussian's parameters, given the gradients `v` of its screen-space quantities. `known_visible`:
/// the caller's forward found this Gaussian visible with the same inputs (see project_fwd).
/// detail::project_bwd_lanes does several Gaussians at once, to the same bits.
template <bool Antialiased>
inline void project_bwd(const GaussianGeometry& g, const ProjectCamera& cam, const ProjectedGrad& v,
                        GeometryGrad& grad, bool known_visible = false) {
  detail::ProjectedGradLanes<double> vl;
  vl.mean2d[0] = v.mean2d[0];
  vl.mean2d[1] = v.mean2d[1];
  for (int i = 0; i < 3; ++i) vl.conic[i] = v.conic[i];
  vl.opacity = v.opacity;
  vl.depth = v.depth;
  detail::GeometryGradLanes<double> gg;
  for (int i = 0; i < 3; ++i) {
    gg.mean[i] = grad.mean[i];
    gg.log_scale[i] = grad.log_scale[i];
  }
  for (int i = 0; i < 4; ++i) gg.quat[i] = grad.quat[i];
  gg.opacity_logit = grad.opacity_logit;
  detail::project_bwd_lanes<Antialiased>(detail::geometry_lanes(g), cam, vl, gg, known_visible);
  for (int i = 0; i < 3; ++i) {
    grad.mean[i] = gg.mean[i];
    grad.log_scale[i] = gg.log_scale[i];
  }
  for (int i = 0; i < 4; ++i) grad.quat[i] = gg.quat[i];
  grad.opacity_logit = gg.opacity_logit;
}

namespace detail {

/// Unit view direction per lane from raw = mean - camera position, and |raw|; (0, 0, 1) where
/// |raw| is 0 or not finite (the colour then does not depend on the direction's gradient).
template <class D>
inline void view_dir(const D raw[3], D dir[3], D& len) {
  using L = Lanes<D>;
  len = L::sqrt((raw[0] * raw[0] + raw[1] * raw[1]) + raw[2] * raw[2]);
  const auto ok = mand(len > L::splat(0.0), lfinite(len));
  dir[0] = L::sel(ok, raw[0] / len, L::splat(0.0));
  dir[1] = L::sel(ok, raw[1] / len, L::splat(0.0));
  dir[2] = L::sel(ok, raw[2] / len, L::splat(1.0));
}

/// Colour of `count` channels in lane type D (one Gaussian with D = double, a vector register of
/// them with ProjVec): SH of degree `deg` along the unit direction `dir`, plus 0.5, clamped at 0
/// (NaN becomes 0). `coef(ch, k)` gives coefficient k of channel ch.
template <class D, class Coef>
inline void colour_fwd_lanes(int count, int deg, const D dir[3], Coef&& coef, D* out) {
  using L = Lanes<D>;
  D Y[sh::kMaxCoeffs];
  sh::basis<D>(deg, dir[0], dir[1], dir[2], Y);
  const int K = sh_coeffs_for_degree(deg);
  for (int ch = 0; ch < count; ++ch) {
    D v = L::splat(0.5);
    for (int k = 0; k < K; ++k) v += coef(ch, k) * Y[k];
    out[ch] = L::sel(v > L::splat(0.0), v, L::splat(0.0));
  }
}

/// Backward of colour_fwd_lanes for raw = mean - camera position: `store(ch, k, value)` receives
/// dL/dSH of the active coefficients of each channel, and dL/d(mean) through the view direction is
/// added to `v_mean`. `v_colour[ch]` is dL/d(colour).
template <class D, class Coef, class Store>
inline void colour_bwd_lanes(int count, int deg, const D raw[3], Coef&& coef, const D* v_colour, Store&& store,
                             D v_mean[3]) {
  using L = Lanes<D>;
  // Degree 0 is constant over directions: no direction (a square root and three divisions) needed.
  D dir[3] = {L::splat(0.0), L::splat(0.0), L::splat(1.0)}, len = L::splat(0.0);
  if (deg >= 1) view_dir(raw, dir, len);
  D Y[sh::kMaxCoeffs];
  sh::basis<D>(deg, dir[0], dir[1], dir[2], Y);
  const int K = sh_coeffs_for_degree(deg);
  D dY[sh::kMaxCoeffs];
  for (int k = 0; k < K; ++k) dY[k] = L::splat(0.0);
  for (int ch = 0; ch < count; ++ch) {
    D c[sh::kMaxCoeffs];
    D v = L::splat(0.5);
    for (int k = 0; k < K; ++k) {
      c[k] = coef(ch, k);
      v += c[k] * Y[k];
    }
    const D g = L::sel(v > L::splat(0.0), v_colour[ch], L::splat(0.0));
    for (int k = 0; k < K; ++k) {
      store(ch, k, g * Y[k]);
      dY[k] += g * c[k];
    }
  }
  if (deg < 1) return;
  D gdir[3] = {L::splat(0.0), L::splat(0.0), L::splat(0.0)};
  sh::basis_backward<D>(deg, dir[0], dir[1], dir[2], dY, gdir);
  const D dot = (dir[0] * gdir[0] + dir[1] * gdir[1]) + dir[2] * gdir[2];
  const auto ok = mand(len > L::splat(0.0), lfinite(len));
  for (int i = 0; i < 3; ++i) v_mean[i] += L::sel(ok, (gdir[i] - dir[i] * dot) / len, L::splat(0.0));
}

}  // namespace detail

}  // namespace msgs
