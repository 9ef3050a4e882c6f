// include/msgs/io/splat_formats.hpp
// Writers of the two compact 3DGS formats that web viewers open besides PLY: antimatter15's
// `.splat` and Niantic's `.spz`. Both hold three colour channels, so they take 3-channel models
// (see msgs/export.hpp for turning a band, a composite or an index into one).
//
// .splat (antimatter15/splat, read by its viewer, gsplat.js, SuperSplat, Spark): no header, 32
// bytes per Gaussian, little-endian:
//   float32 x, y, z | float32 exp(log-scale) x 3 | uint8 r, g, b, a | uint8 quaternion w, x, y, z
// r, g, b = 255 (0.5 + C0 dc) and a = 255 sigmoid(opacity), rounded and clamped to [0, 255];
// quaternion = 128 q / |q| + 128, rounded and clamped. Gaussians are sorted by descending
// exp(sum of log-scales) sigmoid(opacity), as the reference converter (convert.py) does; the key
// is compared in the log domain (sum of log-scales + log sigmoid), which orders the same without
// overflowing, ties in model order. View-dependent colour (SH degree >= 1) is dropped: the
// format has none. The reference converter truncates to uint8; rounding halves the error.
//
// .spz (nianticlabs/spz, read by Spark, SuperSplat and Niantic's tools): a gzip stream of
//   header  uint32 magic 0x5053474e ("NGSP"), uint32 version (2 or 3), uint32 number of points,
//           uint8 SH degree, uint8 fractional bits, uint8 flags (0x1 antialiased), uint8 0
//   then one array per attribute, Gaussian-major inside each:
//   positions  3 x 24-bit signed fixed point with `fractional bits` fractional bits
//   alphas     uint8 round(255 sigmoid(opacity))
//   colours    uint8 round(255 (0.15 dc) + 127.5) x 3 (0.15 instead of C0 leaves room above 1)
//   scales     uint8 round(16 (log-scale + 10)) x 3: log-scales in [-10, 5.94]
//   rotations  v3: the three smallest components of q / |q| (x y z w order) in 10 bits each
//              (sign + 9-bit magnitude of |q_i| / sqrt(1/2)) and the index of the largest in the
//              top 2 bits, one little-endian uint32; v2: x, y, z of q / |q| with w >= 0, each
//              uint8 round(127.5 q_i + 127.5)
//   SH         per Gaussian, coefficient-major with the channel inner (k1 r, k1 g, k1 b, k2 r ..),
//              each uint8 round(128 x) + 128 snapped to buckets of 2^(8 - bits) (5 bits for
//              degree 1, 4 above: Niantic's defaults; the reader reads plain bytes either way)
// Positions are written as they are (Niantic's ply_to_spz with default options converts no
// axes either), so the .ply, .splat and .spz of one model open the same way up. 12 fractional
// bits (0.24 mm at unit scale) unless the scene is too large for them: then as many as fit the
// largest |coordinate| into 24 bits; beyond 2^23 no spz is written.
//
// Both writers refuse Gaussians a viewer cannot draw (non-finite values, quaternions shorter
// than the rasteriser's kMinQuatNorm) with an IoError naming the file, field and Gaussian:
// msgs::prepare_export (export.hpp) drops them beforehand. Log-scales beyond the rasteriser's
// clamp (+-50) are clamped as it clamps them. Files are written atomically.
#pragma once

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "msgs/gaussian.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"
#include "msgs/project.hpp"
#include "msgs/sh.hpp"

namespace msgs::io {

/// Bytes of one Gaussian in a .splat file.
inline constexpr std::size_t splat_record_bytes = 32;

/// The .spz magic number, "NGSP" read as a little-endian uint32.
inline constexpr std::uint32_t spz_magic = 0x5053474e;
/// Scale of the DC term in .spz colours (Niantic's colorScale).
inline constexpr double spz_colour_scale = 0.15;
/// Fractional bits of .spz positions when the scene fits (Niantic's choice: 0.24 mm at scale 1).
inline constexpr int spz_default_fractional_bits = 12;

/// How .spz files are written.
struct SpzOptions {
  int version = 3;        ///< 3 (smallest-three quaternions, Niantic's default) or 2 (older readers)
  int sh1_bits = 5;       ///< precision kept of degree-1 SH bytes, 1..8 (Niantic's default 5)
  int sh_rest_bits = 4;   ///< of degree 2 and 3 (default 4)
  bool antialiased = false;  ///< flag 0x1: trained with antialiasing (msgs RasterOptions::antialiased)
};

namespace detail {

inline void put_u8(std::vector<unsigned char>& out, unsigned v) { out.push_back(static_cast<unsigned char>(v & 0xff)); }
inline void put_u32_le(std::vector<unsigned char>& out, std::uint32_t v) {
  for (int b = 0; b < 4; ++b) put_u8(out, v >> (8 * b));
}
inline void put_f32_le(std::vector<unsigned char>& out, float v) {
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  put_u32_le(out, u);
}

/// round(x) clamped to [0, 255]; NaN (never passed by the writers) gives 0.
inline unsigned to_u8(double x) {
  if (!(x > 0.0)) return 0;
  return static_cast<unsigned>(std::min(255.0, std::round(x)));
}

inline double sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }
/// log(sigmoid(x)) without overflow for large |x|.
inline double log_sigmoid(double x) { return x < 0 ? x - std::log1p(std::exp(x)) : -std::log1p(std::exp(-x)); }

inline double clamped_log_scale(float v) {
  return std::clamp(double(v), -ProjectConstants::kLogScaleClamp, ProjectConstants::kLogScaleClamp);
}

/// Refuse what no viewer can draw: every value finite, quaternion not degenerate.
template <class G>
void check_drawable(const std::filesystem::path& p, const GaussianModel<G, float>& m) {
  m.check_consistent();
  auto bad = [&](std::size_t i, const char* field, const char* what) {
    fail(p, field, cat("Gaussian ", i, " ", what, "; refusing to write (msgs::prepare_export drops such Gaussians)"));
  };
  for (std::size_t i = 0; i < m.size(); ++i) {
    for (int d = 0; d < 3; ++d)
      if (!std::isfinite(m.means[3 * i + std::size_t(d)])) bad(i, "x/y/z", "has a non-finite position");
    for (int d = 0; d < 3; ++d)
      if (!std::isfinite(m.log_scales[3 * i + std::size_t(d)])) bad(i, "scale", "has a non-finite log-scale");
    if (!std::isfinite(m.opacity_logits[i])) bad(i, "opacity", "has a non-finite opacity");
    double q2 = 0;
    for (int d = 0; d < 4; ++d) {
      const double q = m.quats[4 * i + std::size_t(d)];
      if (!std::isfinite(q)) bad(i, "rot", "has a non-finite quaternion");
      q2 += q * q;
    }
    if (!(std::sqrt(q2) >= ProjectConstants::kMinQuatNorm)) bad(i, "rot", "has a zero quaternion");
    for (int c = 0; c < G::bands; ++c)
      for (int k = 0; k < G::sh_coeffs; ++k)
        if (!std::isfinite(m.sh_at(i, k, c))) bad(i, k == 0 ? "f_dc" : "f_rest", "has a non-finite colour");
  }
}

/// Unit quaternion (w, x, y, z) of Gaussian i, in double.
template <class G>
std::array<double, 4> unit_quat(const GaussianModel<G, float>& m, std::size_t i) {
  std::array<double, 4> q;
  double n2 = 0;
  for (int d = 0; d < 4; ++d) {
    q[std::size_t(d)] = m.quats[4 * i + std::size_t(d)];
    n2 += q[std::size_t(d)] * q[std::size_t(d)];
  }
  const double inv = 1.0 / std::sqrt(n2);
  for (double& v : q) v *= inv;
  return q;
}

/// gzip (RFC 1952) of `n` bytes with zlib's default level.
inline std::vector<unsigned char> gzip_bytes(const std::filesystem::path& p, const unsigned char* data, std::size_t n) {
  z_stream zs{};
  // windowBits 16 + 15: a gzip wrapper instead of zlib's.
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 9, Z_DEFAULT_STRATEGY) != Z_OK)
    fail(p, "zlib: deflateInit2 failed");
  std::vector<unsigned char> out;
  std::vector<unsigned char> buf(1 << 16);
  zs.next_in = const_cast<Bytef*>(data);
  std::size_t left = n;
  int rc = Z_OK;
  do {
    // avail_in is a 32-bit count: feed large payloads in pieces.
    if (zs.avail_in == 0 && left > 0) {
      const std::size_t take = std::min<std::size_t>(left, std::numeric_limits<uInt>::max() / 2);
      zs.avail_in = static_cast<uInt>(take);
      left -= take;
    }
    zs.next_out = buf.data();
    zs.avail_out = static_cast<uInt>(buf.size());
    rc = deflate(&zs, left == 0 ? Z_FINISH : Z_NO_FLUSH);
    if (rc == Z_STREAM_ERROR) {
      deflateEnd(&zs);
      fail(p, "zlib: deflate failed");
    }
    out.insert(out.end(), buf.data(), buf.data() + (buf.size() - zs.avail_out));
  } while (rc != Z_STREAM_END);
  deflateEnd(&zs);
  return out;
}

/// Niantic's SH byte: round(128 x) + 128, snapped to a multiple of `bucket`, clamped to [0, 255].
inline unsigned spz_sh_byte(double x, int bucket) {
  const double q = std::clamp(std::round(x * 128.0) + 128.0, 0.0, 255.0);
  const int qi = static_cast<int>(q);
  return static_cast<unsigned>(std::min(255, (qi + bucket / 2) / bucket * bucket));
}

/// v3 rotation: smallest three of (x, y, z, w), see the top of this file.
inline std::uint32_t spz_pack_quat_v3(const std::array<double, 4>& wxyz) {
  const double q[4] = {wxyz[1], wxyz[2], wxyz[3], wxyz[0]};
  unsigned largest = 0;
  for (unsigned i = 1; i < 4; ++i)
    if (std::abs(q[i]) > std::abs(q[largest])) largest = i;
  const bool negate = q[largest] < 0;  // -q is the same rotation: make the largest positive
  std::uint32_t comp = largest;
  for (unsigned i = 0; i < 4; ++i) {
    if (i == largest) continue;
    const std::uint32_t neg = (q[i] < 0) != negate ? 1u : 0u;
    const double mag = std::min(511.0, std::floor(511.0 * (std::abs(q[i]) / std::sqrt(0.5)) + 0.5));
    comp = (comp << 10) | (neg << 9) | static_cast<std::uint32_t>(mag);
  }
  return comp;
}

}  // namespace detail

/// The order a .splat file stores the Gaussians in: descending exp(sum log-scales) sigmoid(opacity).
template <class G>
std::vector<std::size_t> splat_order(const GaussianModel<G, float>& m) {
  std::vector<double> key(m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    double s = 0;
    for (int d = 0; d < 3; ++d) s += detail::clamped_log_scale(m.log_scales[3 * i + std::size_t(d)]);
    key[i] = s + detail::log_sigmoid(m.opacity_logits[i]);
  }
  std::vector<std::size_t> order(m.size());
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] > key[b]; });
  return order;
}

/// The bytes of a .splat file (32 per Gaussian, see the top of this file). `p` names the file in
/// messages.
template <class G>
std::vector<unsigned char> encode_splat(const GaussianModel<G, float>& m, const std::filesystem::path& p) {
  static_assert(G::bands == 3, ".splat holds RGB: export a band or composite as 3 channels first (msgs/export.hpp)");
  detail::check_drawable(p, m);
  std::vector<unsigned char> out;
  out.reserve(m.size() * splat_record_bytes);
  for (std::size_t i : splat_order(m)) {
    for (int d = 0; d < 3; ++d) detail::put_f32_le(out, m.means[3 * i + std::size_t(d)]);
    for (int d = 0; d < 3; ++d) {
      const double log_scale = detail::clamped_log_scale(m.log_scales[3 * i + std::size_t(d)]);
      detail::put_f32_le(out, static_cast<float>(std::exp(log_scale)));
    }
    for (int c = 0; c < 3; ++c) detail::put_u8(out, detail::to_u8(255.0 * (0.5 + sh::C0 * m.sh_at(i, 0, c))));
    detail::put_u8(out, detail::to_u8(255.0 * detail::sigmoid(m.opacity_logits[i])));
    for (double q : detail::unit_quat(m, i)) detail::put_u8(out, detail::to_u8(128.0 * q + 128.0));
  }
  return out;
}

/// Write a 3-channel model as a .splat file, atomically.
template <class G>
void write_splat(const std::filesystem::path& p, const GaussianModel<G, float>& m) {
  const std::vector<unsigned char> bytes = encode_splat(m, p);
  write_bytes_atomic(p, bytes.data(), bytes.size());
}

/// The uncompressed .spz payload (header and arrays, see the top of this file).
template <class G>
std::vector<unsigned char> encode_spz_payload(const GaussianModel<G, float>& m, const SpzOptions& opt,
                                              const std::filesystem::path& p) {
  static_assert(G::bands == 3, ".spz holds RGB: export a band or composite as 3 channels first (msgs/export.hpp)");
  if (opt.version != 2 && opt.version != 3) fail(p, "version", cat("spz version must be 2 or 3, got ", opt.version));
  if (opt.sh1_bits < 1 || opt.sh1_bits > 8 || opt.sh_rest_bits < 1 || opt.sh_rest_bits > 8)
    fail(p, "sh bits", "SH quantisation bits must be 1..8");
  detail::check_drawable(p, m);
  const std::size_t n = m.size();
  if (n > std::numeric_limits<std::uint32_t>::max())
    fail(p, "numPoints", cat(n, " Gaussians do not fit the 32-bit count; export fewer or write .ply"));

  // Fractional bits: the default unless the largest |coordinate| needs the bits for its integer part.
  constexpr double max_fixed = double((1 << 23) - 1);
  double max_abs = 0;
  for (float v : m.means) max_abs = std::max(max_abs, double(std::abs(v)));
  int frac = spz_default_fractional_bits;
  while (frac > 0 && std::round(max_abs * std::ldexp(1.0, frac)) > max_fixed) --frac;
  if (std::round(max_abs) > max_fixed)
    fail(p, "x/y/z", cat("a coordinate of magnitude ", max_abs, " does not fit .spz's 24-bit fixed point (at most ",
                         max_fixed, "); write .ply or .splat, which store float32"));

  constexpr int K = G::sh_coeffs;
  const std::size_t rot_bytes = opt.version >= 3 ? 4 : 3;
  std::vector<unsigned char> out;
  out.reserve(16 + n * (9 + 1 + 3 + 3 + rot_bytes + std::size_t(3 * (K - 1))));
  detail::put_u32_le(out, spz_magic);
  detail::put_u32_le(out, static_cast<std::uint32_t>(opt.version));
  detail::put_u32_le(out, static_cast<std::uint32_t>(n));
  detail::put_u8(out, unsigned(G::sh_degree));
  detail::put_u8(out, unsigned(frac));
  detail::put_u8(out, opt.antialiased ? 1u : 0u);
  detail::put_u8(out, 0u);

  const double fixed_scale = std::ldexp(1.0, frac);
  for (std::size_t i = 0; i < 3 * n; ++i) {
    const auto v = static_cast<std::int32_t>(std::round(double(m.means[i]) * fixed_scale));
    const auto u = static_cast<std::uint32_t>(v);  // two's complement; the low 24 bits are stored
    for (int b = 0; b < 3; ++b) detail::put_u8(out, u >> (8 * b));
  }
  for (std::size_t i = 0; i < n; ++i) detail::put_u8(out, detail::to_u8(255.0 * detail::sigmoid(m.opacity_logits[i])));
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      detail::put_u8(out, detail::to_u8(m.sh_at(i, 0, c) * (spz_colour_scale * 255.0) + 0.5 * 255.0));
  for (std::size_t i = 0; i < 3 * n; ++i)
    detail::put_u8(out, detail::to_u8((detail::clamped_log_scale(m.log_scales[i]) + 10.0) * 16.0));
  for (std::size_t i = 0; i < n; ++i) {
    const std::array<double, 4> q = detail::unit_quat(m, i);
    if (opt.version >= 3) {
      detail::put_u32_le(out, detail::spz_pack_quat_v3(q));
    } else {
      const double s = q[0] < 0 ? -127.5 : 127.5;  // w >= 0, so the reader can recover it
      for (int d = 1; d < 4; ++d) detail::put_u8(out, detail::to_u8(s * q[std::size_t(d)] + 127.5));
    }
  }
  const int bucket1 = 1 << (8 - opt.sh1_bits), bucket_rest = 1 << (8 - opt.sh_rest_bits);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 1; k < K; ++k)
      for (int c = 0; c < 3; ++c)
        detail::put_u8(out, detail::spz_sh_byte(m.sh_at(i, k, c), k < 4 ? bucket1 : bucket_rest));
  return out;
}

/// Write a 3-channel model as a gzip-compressed .spz file, atomically.
template <class G>
void write_spz(const std::filesystem::path& p, const GaussianModel<G, float>& m, const SpzOptions& opt = {}) {
  const std::vector<unsigned char> payload = encode_spz_payload(m, opt, p);
  const std::vector<unsigned char> gz = detail::gzip_bytes(p, payload.data(), payload.size());
  write_bytes_atomic(p, gz.data(), gz.size());
}

}  // namespace msgs::io
