// include/msgs/detail/math.hpp
// Scalar helpers shared by forward and backward kernels: explicit fused multiply-add, a
// vectorisable exp(-x) for the blend loop, and a stable sigmoid.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <type_traits>

namespace msgs::detail {

/// a * b + c, fused where the target has FMA. Written explicitly (and builds use
/// -ffp-contract=off) so that forward and backward evaluate alpha with the same roundings.
template <class T>
inline T fmadd(T a, T b, T c) {
#if defined(__FMA__) || defined(__aarch64__)
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

/// exp(-s) for s >= 0, the Gaussian falloff of the blend stage. For float it is a branch-free
/// Cephes-style polynomial (about 1 ulp) that compilers vectorise without -ffast-math; the input
/// is clamped to [0, 87] so that it never overflows, underflows to a subnormal or returns NaN for
/// finite input. For double it is std::exp on the same clamped range.
template <class T>
inline T exp_neg(T s) {
  s = s < T(0) ? T(0) : s;
  s = s > T(87) ? T(87) : s;
  if constexpr (std::is_same_v<T, float>) {
    const float x = -s;
    // n = round(x / ln 2) by the 1.5 * 2^23 trick (exact in round-to-nearest, no libm call).
    const float shifter = 12582912.0f;
    const float n = (x * 1.44269504088896341f + shifter) - shifter;
    float r = fmadd(n, -0.693359375f, x);
    r = fmadd(n, 2.12194440e-4f, r);
    float p = 1.9875691500e-4f;
    p = fmadd(p, r, 1.3981999507e-3f);
    p = fmadd(p, r, 8.3334519073e-3f);
    p = fmadd(p, r, 4.1665795894e-2f);
    p = fmadd(p, r, 1.6666665459e-1f);
    p = fmadd(p, r, 5.0000001201e-1f);
    const float y = fmadd(p * r, r, r) + 1.0f;
    const std::int32_t e = (static_cast<std::int32_t>(n) + 127) << 23;
    return y * std::bit_cast<float>(e);
  } else {
    return std::exp(-s);
  }
}

/// Numerically stable logistic function.
template <class T>
inline T sigmoid(T x) {
  if (x >= T(0)) return T(1) / (T(1) + std::exp(-x));
  const T e = std::exp(x);
  return e / (T(1) + e);
}

/// Are all n values finite?
template <class T>
inline bool all_finite(const T* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

}  // namespace msgs::detail
