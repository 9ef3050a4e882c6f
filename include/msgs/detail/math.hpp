// include/msgs/detail/math.hpp
// Scalar helpers (a stable sigmoid, for densification's opacity tests). The projection's lane-generic
// functions are in project.hpp, the blend stage's vector helpers in block_simd.hpp.
#pragma once

#include <cmath>

namespace msgs::detail {

/// Numerically stable logistic function.
template <class T>
inline T sigmoid(T x) {
  if (x >= T(0)) return T(1) / (T(1) + std::exp(-x));
  const T e = std::exp(x);
  return e / (T(1) + e);
}

}  // namespace msgs::detail
