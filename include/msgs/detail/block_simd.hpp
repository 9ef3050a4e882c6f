// include/msgs/detail/block_simd.hpp
// A block of 16 pixels (4x4 of a tile, see blend.hpp) as one or more vectors of the GCC/Clang
// vector extension, sized to the target's widest registers (one 16-lane vector with AVX-512, two 8-lane with AVX/AVX2, four
// 4-lane with SSE or NEON), for the blend loops: element-wise IEEE arithmetic and selects, with no
// reliance on the auto-vectoriser's if-conversion (which, under plain AVX2 or SSE, gives up on the
// blend loop and runs it scalar, and under AVX-512 emits masked stores that the next load of the
// same block cannot forward from).
//
// Helpers write their result through a reference instead of returning a vector: returning a
// vector wider than the target's registers changes the calling convention and GCC warns (-Wpsabi).
#pragma once

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <utility>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace msgs::detail {

/// Pixels in a block (the lanes the blend loops work on at once).
inline constexpr int kBlockLanes = 16;

/// Bytes of the widest vector registers of the target: 64 (AVX-512), 32 (AVX), else 16.
#if defined(__AVX512F__)
inline constexpr int kVectorBytes = 64;
#elif defined(__AVX__)
inline constexpr int kVectorBytes = 32;
#else
inline constexpr int kVectorBytes = 16;
#endif

/// Vector types of a block in scalar S, kChunks vectors of kLanes lanes each: V (values),
/// M (comparison masks: all ones = true, the signed integer type of S's width), U and I (32-bit
/// unsigned / signed per lane: list positions, counts).
template <class S>
struct BlockVec {
  static constexpr int kLanes = kVectorBytes / int(sizeof(S)) < kBlockLanes ? kVectorBytes / int(sizeof(S)) : kBlockLanes;
  static constexpr int kChunks = kBlockLanes / kLanes;
  static_assert(kChunks * kLanes == kBlockLanes);
  using MaskScalar = std::conditional_t<sizeof(S) == 4, std::int32_t, std::int64_t>;
  typedef S V __attribute__((vector_size(kLanes * sizeof(S))));
  typedef MaskScalar M __attribute__((vector_size(kLanes * sizeof(S))));
  typedef std::uint32_t U __attribute__((vector_size(kLanes * sizeof(std::uint32_t))));
  typedef std::int32_t I __attribute__((vector_size(kLanes * sizeof(std::int32_t))));
};

/// Every lane of `v` set to `x` (exact, also for -0 and NaN: x - 0 is x). Written as a
/// vector-scalar operation, which GCC always emits as one splat; an element-wise loop is sometimes
/// compiled to one masked insert per lane.
template <class V, class S>
inline void broadcast(V& v, S x) {
  using Lane = std::remove_cvref_t<decltype(v[0])>;
  v = Lane(x) - V{};
}

/// The vector whose lane j is lane Index{}(j) of the concatenation (a, b) (indices from 0 to
/// 2n - 1 for n-lane vectors): __builtin_shufflevector with the indices of a constexpr function
/// object, which GCC (12 and later) and Clang both take; GCC's __builtin_shuffle, with an index
/// vector, is not in Clang.
template <class Index, class Vec, std::size_t... J>
inline Vec shuffle_lanes(const Vec& a, const Vec& b, std::index_sequence<J...>) {
  return __builtin_shufflevector(a, b, Index{}(int(J))...);
}
template <class Index, class Vec>
inline Vec shuffle_lanes(const Vec& a, const Vec& b) {
  return shuffle_lanes<Index>(a, b, std::make_index_sequence<sizeof(Vec) / sizeof(a[0])>{});
}

/// Bit i set when lane i of mask `m` (all ones = true) is set: one instruction on x86.
template <class M>
inline std::uint32_t lane_bits(const M& m) {
  constexpr int n = int(sizeof(M) / sizeof(m[0]));
  static_assert(n <= 32);
#if defined(__AVX512F__)
  if constexpr (sizeof(M) == 64) {
    const __m512i v = std::bit_cast<__m512i>(m);
    if constexpr (n == 16) return _mm512_test_epi32_mask(v, v);
    else return _mm512_test_epi64_mask(v, v);
  }
#endif
#if defined(__AVX__)
  if constexpr (sizeof(M) == 32) {
    if constexpr (n == 8) return std::uint32_t(_mm256_movemask_ps(std::bit_cast<__m256>(m)));
    else return std::uint32_t(_mm256_movemask_pd(std::bit_cast<__m256d>(m)));
  }
#endif
#if defined(__SSE2__)
  if constexpr (sizeof(M) == 16) {
    if constexpr (n == 4) return std::uint32_t(_mm_movemask_ps(std::bit_cast<__m128>(m)));
    else return std::uint32_t(_mm_movemask_pd(std::bit_cast<__m128d>(m)));
  }
#endif
  std::uint32_t bits = 0;
  for (int i = 0; i < n; ++i) bits |= std::uint32_t(m[i] != 0) << i;
  return bits;
}

/// Is any lane of mask `m` set?
template <class M>
inline bool any_lane(const M& m) {
  return lane_bits(m) != 0;
}

/// Is there a lane where a <= b and c > d (both false at NaN)? With AVX-512 the two comparisons
/// stay in mask registers: the generic form turns the first mask into a vector and back.
template <class V>
inline bool any_le_and_gt(const V& a, const V& b, const V& c, const V& d) {
#if defined(__AVX512F__)
  if constexpr (sizeof(V) == 64 && sizeof(a[0]) == 4) {
    const __m512 va = std::bit_cast<__m512>(a), vb = std::bit_cast<__m512>(b), vc = std::bit_cast<__m512>(c),
                 vd = std::bit_cast<__m512>(d);
    return _mm512_mask_cmp_ps_mask(_mm512_cmp_ps_mask(vc, vd, _CMP_GT_OQ), va, vb, _CMP_LE_OQ) != 0;
  }
#endif
  return any_lane((a <= b) & (c > d));
}

/// out = |v| lane by lane (clears the sign bits).
template <class V>
inline void abs_into(V& out, const V& v) {
  using Lane = std::remove_cvref_t<decltype(v[0])>;
  using Bits = std::conditional_t<sizeof(Lane) == 4, std::uint32_t, std::uint64_t>;
  typedef Bits BV __attribute__((vector_size(sizeof(V))));
  out = std::bit_cast<V>(std::bit_cast<BV>(v) & ~(Bits(1) << (8 * sizeof(Lane) - 1)));
}

/// The sum of the lanes of `v` reduced to 4 lanes by halving (out4[0..3]); fewer lanes are copied.
template <class S, class Vv>
inline void halve_to_four(const Vv& v, S* out4) {
  constexpr int W = int(sizeof(Vv) / sizeof(S));
  if constexpr (W <= 4) {
    for (int i = 0; i < W; ++i) out4[i] = v[i];
  } else {
    typedef S H __attribute__((vector_size(sizeof(Vv) / 2)));
    struct Halves { H lo, hi; };
    const Halves p = std::bit_cast<Halves>(v);
    const H h = p.lo + p.hi;
    halve_to_four<S>(h, out4);
  }
}

/// sum[l] = the sum of the 16 lanes of group l (one block's worth of an accumulator), stored as kChunks vectors at v[l * kChunks ...],
/// for l < n. The summation tree is fixed (lane i plus lane i + 8, then i + 4, then
/// (0 + 2) + (1 + 3)), the same for every vector width, so a group sums to the same bits with
/// AVX-512, AVX or SSE. Always inlined: called out of line (as GCC chose), the accumulators it
/// reads had to live in memory throughout the blend backward's loop, a store and a load each per
/// chunk, and each call cost a vzeroupper.
template <class S, class V>
[[gnu::always_inline]] inline void sum_rows(const V* v, int n, S* sum) {
  constexpr int NH = BlockVec<S>::kChunks, L = BlockVec<S>::kLanes;
  if constexpr (L == 16 && NH == 1) {
    // One 16-lane vector per row: reduce four rows at a time with shuffles that pack the partial
    // sums of different rows into one vector (the same tree, a third of the instructions).
    V zero;
    broadcast(zero, S(0));
    for (int l0 = 0; l0 < n; l0 += 4) {
      const V a = v[l0], b = l0 + 1 < n ? v[l0 + 1] : zero, c = l0 + 2 < n ? v[l0 + 2] : zero,
              d = l0 + 3 < n ? v[l0 + 3] : zero;
      // lane i + lane i + 8: rows a, b in one vector, c, d in another.
      const V ab = __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23) +
                   __builtin_shufflevector(a, b, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
      const V cd = __builtin_shufflevector(c, d, 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23) +
                   __builtin_shufflevector(c, d, 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31);
      // then i + i + 4: four partials q0..q3 of row a, b, c, d in lanes 0-3, 4-7, 8-11, 12-15.
      const V u = __builtin_shufflevector(ab, cd, 0, 1, 2, 3, 8, 9, 10, 11, 16, 17, 18, 19, 24, 25, 26, 27) +
                  __builtin_shufflevector(ab, cd, 4, 5, 6, 7, 12, 13, 14, 15, 20, 21, 22, 23, 28, 29, 30, 31);
      // then (q0 + q2) + (q1 + q3) in the first lane of each group.
      const V w = u + __builtin_shufflevector(u, u, 2, 3, 0, 1, 6, 7, 4, 5, 10, 11, 8, 9, 14, 15, 12, 13);
      const V x = w + __builtin_shufflevector(w, w, 1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10, 13, 12, 15, 14);
      for (int k = 0; k < 4 && l0 + k < n; ++k) sum[l0 + k] = x[4 * k];
    }
    return;
  }
  for (int l = 0; l < n; ++l) {
    V c[NH];
    for (int h = 0; h < NH; ++h) c[h] = v[l * NH + h];
    for (int w = NH / 2; w >= 1; w /= 2)
      for (int h = 0; h < w; ++h) c[h] = c[h] + c[h + w];
    S q[4];
    halve_to_four<S>(c[0], q);
    sum[l] = L >= 4 ? (q[0] + q[2]) + (q[1] + q[3]) : q[0] + q[1];
  }
}

/// out = a * b + c lane by lane, fused (one rounding) where the target has FMA, else a multiply
/// and an add. Every kernel that needs the same value calls this, so they agree within a build.
template <class T>
inline void fmadd_into(T& out, const T& a, const T& b, const T& c) {
  if constexpr (std::is_same_v<std::remove_cvref_t<decltype(a[0])>, float>) {
#if defined(__AVX512F__)
    if constexpr (sizeof(T) == 64) {
      out = std::bit_cast<T>(_mm512_fmadd_ps(std::bit_cast<__m512>(a), std::bit_cast<__m512>(b), std::bit_cast<__m512>(c)));
      return;
    }
#endif
#if defined(__FMA__)
    if constexpr (sizeof(T) == 32) {
      out = std::bit_cast<T>(_mm256_fmadd_ps(std::bit_cast<__m256>(a), std::bit_cast<__m256>(b), std::bit_cast<__m256>(c)));
      return;
    }
    if constexpr (sizeof(T) == 16) {
      out = std::bit_cast<T>(_mm_fmadd_ps(std::bit_cast<__m128>(a), std::bit_cast<__m128>(b), std::bit_cast<__m128>(c)));
      return;
    }
#endif
  }
  out = a * b + c;
}

/// out = Max ? (a > b ? a : b) : (a < b ? a : b) lane by lane (so b where either is NaN): one
/// MAXPS/MINPS on x86, which GCC does not match from the generic form for vector-extension types.
template <bool Max, class T>
inline void min_or_max_into(T& out, const T& a, const T& b) {
  if constexpr (std::is_same_v<std::remove_cvref_t<decltype(a[0])>, float>) {
#if defined(__AVX512F__)
    if constexpr (sizeof(T) == 64) {
      // The masked forms with a full mask: GCC 12's _mm512_min_ps/_mm512_max_ps trip
      // -Wmaybe-uninitialized on their internal undefined pass-through operand.
      const __m512 aa = std::bit_cast<__m512>(a), bb = std::bit_cast<__m512>(b);
      const __mmask16 all = 0xffff;
      out = std::bit_cast<T>(Max ? _mm512_mask_max_ps(bb, all, aa, bb) : _mm512_mask_min_ps(bb, all, aa, bb));
      return;
    }
#endif
#if defined(__AVX__)
    if constexpr (sizeof(T) == 32) {
      const __m256 aa = std::bit_cast<__m256>(a), bb = std::bit_cast<__m256>(b);
      out = std::bit_cast<T>(Max ? _mm256_max_ps(aa, bb) : _mm256_min_ps(aa, bb));
      return;
    }
#endif
#if defined(__SSE2__)
    if constexpr (sizeof(T) == 16) {
      const __m128 aa = std::bit_cast<__m128>(a), bb = std::bit_cast<__m128>(b);
      out = std::bit_cast<T>(Max ? _mm_max_ps(aa, bb) : _mm_min_ps(aa, bb));
      return;
    }
#endif
  }
  if constexpr (Max) out = a > b ? a : b;
  else out = a < b ? a : b;
}

template <class T>
inline void min_into(T& out, const T& a, const T& b) { min_or_max_into<false>(out, a, b); }
template <class T>
inline void max_into(T& out, const T& a, const T& b) { min_or_max_into<true>(out, a, b); }

/// acc = ok ? acc + a b : acc lane by lane (fused where the target has FMA): one masked FMA with
/// AVX-512, where GCC otherwise emits an FMA and a blend.
template <class T, class M>
inline void fmadd_where(T& acc, const M& ok, const T& a, const T& b) {
  if constexpr (std::is_same_v<std::remove_cvref_t<decltype(a[0])>, float>) {
#if defined(__AVX512F__)
    if constexpr (sizeof(T) == 64) {
      const __mmask16 k = __mmask16(lane_bits(ok));
      acc = std::bit_cast<T>(
          _mm512_mask3_fmadd_ps(std::bit_cast<__m512>(a), std::bit_cast<__m512>(b), std::bit_cast<__m512>(acc), k));
      return;
    }
#endif
  }
  T t;
  fmadd_into(t, a, b, acc);
  acc = ok ? t : acc;
}

/// out = exp(-s) for s >= 0, lane by lane: the Gaussian falloff of the blend
/// stage. For float a branch-free Cephes-style polynomial (about 1 ulp; FMA where the target has it);
/// the input is
/// clamped to [0, 87] so it never overflows, underflows to a subnormal or returns NaN for finite
/// input (NaN input gives 0 or exp(-87), never NaN). For double, std::exp on the same clamped range.
template <class T>
inline void exp_neg_into(T& out, const T& s_in) {
  using Lane = std::remove_cvref_t<decltype(std::declval<T>()[0])>;
  T s = s_in;
  T zero, hi;
  broadcast(zero, Lane(0));
  broadcast(hi, Lane(87));
  // min first: NaN -> 87 -> exp(-87).
  min_into(s, s, hi);
  max_into(s, s, zero);
  if constexpr (std::is_same_v<Lane, float>) {
    typedef std::int32_t IV __attribute__((vector_size(sizeof(T))));
    const T x = -s;
    T c[8];
    const float cs[8] = {-0.693359375f, 2.12194440e-4f,  1.9875691500e-4f, 1.3981999507e-3f, 8.3334519073e-3f,
                         4.1665795894e-2f, 1.6666665459e-1f, 5.0000001201e-1f};
    for (int k = 0; k < 8; ++k) broadcast(c[k], cs[k]);
    // n = round(x / ln 2) by the 1.5 * 2^23 trick (exact in round-to-nearest, no libm call).
    T log2e, shift, n;
    broadcast(log2e, 1.44269504088896341f);
    broadcast(shift, 12582912.0f);
    fmadd_into(n, x, log2e, shift);
    n = n - shift;
    T r, y;
    fmadd_into(r, n, c[0], x);  // x - n ln 2 in two parts (Cody-Waite)
    fmadd_into(r, n, c[1], r);
    // exp(r) - 1 = r + r^2 p(r), p of degree 5 by Estrin's scheme (three dependent steps instead
    // of Horner's five: the blend loops wait on this chain).
    const T r2 = r * r;
    T p01, p23, p45, p;
    fmadd_into(p01, c[6], r, c[7]);
    fmadd_into(p23, c[4], r, c[5]);
    fmadd_into(p45, c[2], r, c[3]);
    const T r4 = r2 * r2;
    fmadd_into(p, p23, r2, p01);
    fmadd_into(p, p45, r4, p);
    fmadd_into(y, p, r2, r);  // exp(r) - 1
    // exp(x) = (y + 1) 2^n = y 2^n + 2^n: one FMA; 2^n is exact and x >= -87 keeps it normal.
    const T scale = std::bit_cast<T>((__builtin_convertvector(n, IV) + 127) << 23);
    fmadd_into(out, y, scale, scale);
  } else {
    T r = s;  // filled lane by lane from an initialised vector (GCC otherwise warns on `out`)
    for (int i = 0; i < int(sizeof(T) / sizeof(Lane)); ++i) r[i] = std::exp(-s[i]);
    out = r;
  }
}

}  // namespace msgs::detail
