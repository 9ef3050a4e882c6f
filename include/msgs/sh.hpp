// include/msgs/sh.hpp
// Real spherical harmonics up to degree 3 in the 3DGS ordering: the basis, its gradient with
// respect to the (normalised) view direction, and colour evaluation for a band range.
#pragma once

#include <array>
#include <cmath>
#include <type_traits>

namespace msgs::sh {

/// The 3DGS real SH constants.
inline constexpr double C0 = 0.28209479177387814;
inline constexpr double C1 = 0.4886025119029199;
inline constexpr std::array<double, 5> C2 = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                             -1.0925484305920792, 0.5462742152960396};
inline constexpr std::array<double, 7> C3 = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                                             0.3731763325901154,  -0.4570457994644658, 1.445305721320277,
                                             -0.5900435899266435};

/// The constant x in the scalar or lane type T (a vector type of the GCC/Clang extension gets x in
/// every lane), so that the basis below runs on one Gaussian or a vector register of them with the
/// same operations.
template <class T>
constexpr T cst(double x) {
  if constexpr (std::is_arithmetic_v<T>) return T(x);
  else return std::remove_cvref_t<decltype(T{}[0])>(x) - T{};
}

/// Maximum number of coefficients (degree 3).
inline constexpr int kMaxCoeffs = 16;

/// Basis values Y[0 .. (deg+1)^2) for the unit direction (x, y, z). Degree 0 needs no direction.
template <class T>
constexpr void basis(int deg, T x, T y, T z, T* Y) {
  Y[0] = cst<T>(C0);
  if (deg < 1) return;
  Y[1] = -cst<T>(C1) * y;
  Y[2] = cst<T>(C1) * z;
  Y[3] = -cst<T>(C1) * x;
  if (deg < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  Y[4] = cst<T>(C2[0]) * xy;
  Y[5] = cst<T>(C2[1]) * yz;
  Y[6] = cst<T>(C2[2]) * (cst<T>(2) * zz - xx - yy);
  Y[7] = cst<T>(C2[3]) * xz;
  Y[8] = cst<T>(C2[4]) * (xx - yy);
  if (deg < 3) return;
  Y[9] = cst<T>(C3[0]) * y * (cst<T>(3) * xx - yy);
  Y[10] = cst<T>(C3[1]) * xy * z;
  Y[11] = cst<T>(C3[2]) * y * (cst<T>(4) * zz - xx - yy);
  Y[12] = cst<T>(C3[3]) * z * (cst<T>(2) * zz - cst<T>(3) * xx - cst<T>(3) * yy);
  Y[13] = cst<T>(C3[4]) * x * (cst<T>(4) * zz - xx - yy);
  Y[14] = cst<T>(C3[5]) * z * (xx - yy);
  Y[15] = cst<T>(C3[6]) * x * (xx - cst<T>(3) * yy);
}

/// Given dL/dY for the first (deg+1)^2 basis functions, accumulate dL/d(x, y, z) of the unit
/// direction into g[3].
template <class T>
constexpr void basis_backward(int deg, T x, T y, T z, const T* dY, T* g) {
  if (deg < 1) return;
  g[0] += -cst<T>(C1) * dY[3];
  g[1] += -cst<T>(C1) * dY[1];
  g[2] += cst<T>(C1) * dY[2];
  if (deg < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z;
  {
    const T c0 = cst<T>(C2[0]), c1 = cst<T>(C2[1]), c2 = cst<T>(C2[2]), c3 = cst<T>(C2[3]), c4 = cst<T>(C2[4]);
    g[0] += c0 * y * dY[4] - cst<T>(2) * c2 * x * dY[6] + c3 * z * dY[7] + cst<T>(2) * c4 * x * dY[8];
    g[1] += c0 * x * dY[4] + c1 * z * dY[5] - cst<T>(2) * c2 * y * dY[6] - cst<T>(2) * c4 * y * dY[8];
    g[2] += c1 * y * dY[5] + cst<T>(4) * c2 * z * dY[6] + c3 * x * dY[7];
  }
  if (deg < 3) return;
  const T c0 = cst<T>(C3[0]), c1 = cst<T>(C3[1]), c2 = cst<T>(C3[2]), c3 = cst<T>(C3[3]), c4 = cst<T>(C3[4]), c5 = cst<T>(C3[5]), c6 = cst<T>(C3[6]);
  g[0] += c0 * cst<T>(6) * x * y * dY[9] + c1 * y * z * dY[10] - c2 * cst<T>(2) * x * y * dY[11] -
          c3 * cst<T>(6) * x * z * dY[12] + c4 * (cst<T>(4) * zz - cst<T>(3) * xx - yy) * dY[13] + c5 * cst<T>(2) * x * z * dY[14] +
          c6 * cst<T>(3) * (xx - yy) * dY[15];
  g[1] += c0 * cst<T>(3) * (xx - yy) * dY[9] + c1 * x * z * dY[10] + c2 * (cst<T>(4) * zz - xx - cst<T>(3) * yy) * dY[11] -
          c3 * cst<T>(6) * y * z * dY[12] - c4 * cst<T>(2) * x * y * dY[13] - c5 * cst<T>(2) * y * z * dY[14] -
          c6 * cst<T>(6) * x * y * dY[15];
  g[2] += c1 * x * y * dY[10] + c2 * cst<T>(8) * y * z * dY[11] + c3 * (cst<T>(6) * zz - cst<T>(3) * xx - cst<T>(3) * yy) * dY[12] +
          c4 * cst<T>(8) * x * z * dY[13] + c5 * (xx - yy) * dY[14];
}

}  // namespace msgs::sh
