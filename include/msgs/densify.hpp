// include/msgs/densify.hpp
// Adaptive density control: model surgery as a replayable plan, screen-space gradient statistics
// (one accumulator, or one per band for MSAD), duplicate / split / prune and the opacity reset.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__SSE__)
#include <immintrin.h>  // _mm_stream_ps (detail::stream_copy)
#endif

#include "msgs/detail/math.hpp"
#include "msgs/detail/overwrite_vector.hpp"
#include "msgs/gaussian.hpp"
#include "msgs/schedule.hpp"
#include "msgs/spatial_order.hpp"

namespace msgs {

// ---------------------------------------------------------------------------------------------
// Model surgery
// ---------------------------------------------------------------------------------------------

/// A change of the set of Gaussians, written as data so that every per-Gaussian array can follow
/// it: the model, the optimiser moments, the densification statistics, anything else a caller
/// keeps in parallel. Output row i copies input row `source[i]`; `fresh[i]` marks a new Gaussian
/// whose optimiser state must start at zero (apply_zero_fresh). A row whose source is `none` is
/// a brand new Gaussian that starts as zeros everywhere; the caller fills it in.
struct RefinePlan {
  /// Source index of a row that copies nothing.
  static constexpr std::uint32_t none = 0xFFFFFFFFu;

  std::size_t input_size = 0;         ///< rows of the array the plan applies to
  std::vector<std::uint32_t> source;  ///< [M] input row copied into each output row, or `none`
  std::vector<bool> fresh;            ///< [M] true for new Gaussians (zero optimiser state)

  /// Rows after the plan.
  std::size_t size() const { return source.size(); }
  /// Number of new Gaussians.
  std::size_t fresh_count() const { return static_cast<std::size_t>(std::count(fresh.begin(), fresh.end(), true)); }

  /// Throw std::invalid_argument when the plan is malformed.
  void validate() const {
    if (fresh.size() != source.size())
      throw std::invalid_argument("RefinePlan: source has " + std::to_string(source.size()) + " rows, fresh has " +
                                  std::to_string(fresh.size()));
    for (std::size_t i = 0; i < source.size(); ++i) {
      if (source[i] == none) {
        if (!fresh[i]) throw std::invalid_argument("RefinePlan: row " + std::to_string(i) + " has no source but is not fresh");
      } else if (source[i] >= input_size) {
        throw std::invalid_argument("RefinePlan: row " + std::to_string(i) + " copies input row " +
                                    std::to_string(source[i]) + " of " + std::to_string(input_size));
      }
    }
  }

  /// Every row kept in place.
  static RefinePlan identity(std::size_t n) {
    RefinePlan p = empty_plan(n);
    for (std::size_t i = 0; i < n; ++i) p.push(i, false);
    return p;
  }
  /// Keep the rows where `keep` is true, in order.
  static RefinePlan keep(const std::vector<bool>& keep_mask) {
    RefinePlan p = empty_plan(keep_mask.size());
    for (std::size_t i = 0; i < keep_mask.size(); ++i)
      if (keep_mask[i]) p.push(i, false);
    return p;
  }
  /// Remove the rows where `mask` is true, keep the others in order.
  static RefinePlan remove(const std::vector<bool>& mask) {
    RefinePlan p = empty_plan(mask.size());
    for (std::size_t i = 0; i < mask.size(); ++i)
      if (!mask[i]) p.push(i, false);
    return p;
  }
  /// All rows, then a fresh copy of every masked row appended in order (3DGS clone).
  static RefinePlan duplicate(const std::vector<bool>& mask) {
    RefinePlan p = identity(mask.size());
    for (std::size_t i = 0; i < mask.size(); ++i)
      if (mask[i]) p.push(i, true);
    return p;
  }
  /// The unmasked rows in order, then `samples` blocks each holding a fresh copy of every masked
  /// row (block k, masked row j at rest + k * selected + j): the layout of gsplat's split.
  static RefinePlan split(const std::vector<bool>& mask, int samples) {
    if (samples < 1) throw std::invalid_argument("RefinePlan::split: samples must be >= 1");
    RefinePlan p = empty_plan(mask.size());
    std::vector<std::size_t> sel;
    for (std::size_t i = 0; i < mask.size(); ++i) {
      if (mask[i]) sel.push_back(i);
      else p.push(i, false);
    }
    for (int k = 0; k < samples; ++k)
      for (std::size_t j : sel) p.push(j, true);
    return p;
  }
  /// Every row, in the order `order` lists them (a permutation of 0 .. order.size() - 1).
  static RefinePlan reorder(std::vector<std::uint32_t> order) {
    RefinePlan p = empty_plan(order.size());
    std::vector<bool> seen(order.size(), false);
    for (std::uint32_t s : order) {
      if (s >= order.size() || seen[s]) throw std::invalid_argument("RefinePlan::reorder: not a permutation");
      seen[s] = true;
    }
    p.source = std::move(order);
    p.fresh.assign(p.source.size(), false);
    return p;
  }
  /// All `n` rows, then `count` new zero rows for the caller to fill.
  static RefinePlan append(std::size_t n, std::size_t count) {
    RefinePlan p = identity(n);
    for (std::size_t i = 0; i < count; ++i) {
      p.source.push_back(none);
      p.fresh.push_back(true);
    }
    return p;
  }

  /// This plan followed by `next` (which must apply to this plan's output) as one plan; a row is
  /// fresh when either step made it new.
  RefinePlan then(const RefinePlan& next) const {
    if (next.input_size != size())
      throw std::invalid_argument("RefinePlan::then: next plan expects " + std::to_string(next.input_size) +
                                  " rows, this plan produces " + std::to_string(size()));
    next.validate();
    RefinePlan r;
    r.input_size = input_size;
    r.source.resize(next.size());
    r.fresh.resize(next.size());
    for (std::size_t i = 0; i < next.size(); ++i) {
      const std::uint32_t s = next.source[i];
      r.source[i] = s == none ? none : source[s];
      r.fresh[i] = next.fresh[i] || s == none || fresh[s];
    }
    return r;
  }

 private:
  static RefinePlan empty_plan(std::size_t n) {
    if (n >= std::size_t(none)) throw std::invalid_argument("RefinePlan: too many Gaussians for 32-bit row indices");
    RefinePlan p;
    p.input_size = n;
    return p;
  }
  void push(std::size_t src, bool is_fresh) {
    source.push_back(static_cast<std::uint32_t>(src));
    fresh.push_back(is_fresh);
  }
};

namespace detail {
/// memmove(dst, src, n values) spread over the OpenMP threads. Where the two ranges overlap
/// (shift d = |dst - src| < n), the move runs in waves of d values, starting at the
/// end that is written first (the top when moving up): within a wave source and destination are
/// disjoint, and a wave only overwrites values an earlier wave has already moved. Short moves and
/// shifts too small to be worth a wave stay one serial memmove. The result is memmove's.
template <class T>
void parallel_move(T* dst, const T* src, std::size_t n) {
  if (dst == src || n == 0) return;
  constexpr std::size_t kMinWave = std::size_t(1) << 16;  // values per wave worth a fork
  const std::size_t d = dst > src ? std::size_t(dst - src) : std::size_t(src - dst);
  const std::size_t wave = std::min(d, n);
  if (wave < kMinWave) {
    std::memmove(dst, src, n * sizeof(T));
    return;
  }
  const bool up = dst > src;
  const std::size_t waves = (n + wave - 1) / wave;
  constexpr std::size_t kPiece = std::size_t(1) << 14;  // values per task within a wave
#pragma omp parallel
  for (std::size_t k = 0; k < waves; ++k) {
    // Wave k: values [lo, hi) of the source (from the top when moving up, from the bottom down).
    const std::size_t lo = up ? (n > (k + 1) * wave ? n - (k + 1) * wave : 0) : k * wave;
    const std::size_t hi = up ? n - k * wave : std::min(n, (k + 1) * wave);
    const std::ptrdiff_t pieces = std::ptrdiff_t((hi - lo + kPiece - 1) / kPiece);
#pragma omp for schedule(static)
    for (std::ptrdiff_t p = 0; p < pieces; ++p) {
      const std::size_t a = lo + std::size_t(p) * kPiece, b = std::min(hi, a + kPiece);
      std::memcpy(dst + a, src + a, (b - a) * sizeof(T));
    }
  }
}

/// Apply `plan` to `rows`, `planes` consecutive planes of plan.input_size rows of `width` values
/// each (one plane for most arrays, the band planes for SH), in place: no new array of the model's
/// size, so a refinement costs the rows that move, not an allocation (and its page faults) per
/// array. The leading output rows that copy old rows in ascending order (the surviving Gaussians
/// of a refinement) are compacted in place, a run of consecutive rows per memmove; the other
/// output rows (copies, split samples, fresh rows) are staged in a buffer of their own size first.
/// When most rows move (a refinement that also reorders), each plane is gathered through one
/// plane-sized buffer instead.
template <class T>
void apply_rows_impl(const RefinePlan& plan, std::vector<T>& rows, std::size_t width, bool zero_fresh,
                     const char* what, std::size_t planes = 1, bool validated = false) {
  if (!validated) plan.validate();
  const std::size_t n = plan.input_size, m = plan.size(), w = width;
  if (rows.size() != planes * n * w)
    throw std::invalid_argument(std::string(what) + ": array has " + std::to_string(rows.size()) + " values, plan expects " +
                                std::to_string(planes) + " x " + std::to_string(n) + " rows of " +
                                std::to_string(width));
  // Leading rows copied in place: ascending sources at or after their output row.
  std::size_t kept = 0;
  for (std::uint32_t prev = 0; kept < m; ++kept) {
    const std::uint32_t s = plan.source[kept];
    if (s == RefinePlan::none || (zero_fresh && plan.fresh[kept]) || s < kept || (kept > 0 && s <= prev)) break;
    prev = s;
  }
  if (kept < m / 2) {
    // Most rows move (a refinement that reorders): each plane is gathered into one plane-sized
    // buffer in a parallel pass and copied to its place, the planes taken in the order that reads
    // every old plane before its space is overwritten (the stride changes from n to m rows).
    std::vector<T> plane(m * w);
    if (m > n) {
      if (planes * m * w > rows.capacity()) rows.reserve(planes * m * w + planes * m * w / 4);  // room for later growth
      rows.resize(planes * m * w);
    }
    const std::ptrdiff_t sm = static_cast<std::ptrdiff_t>(m);
    for (std::size_t i = 0; i < planes; ++i) {
      const std::size_t q = m > n ? planes - 1 - i : i;
      const T* from = rows.data() + q * n * w;
#pragma omp parallel for schedule(static, 1024)
      for (std::ptrdiff_t ff = 0; ff < sm; ++ff) {
        const std::size_t f = static_cast<std::size_t>(ff);
        const std::uint32_t s = plan.source[f];
        if (s == RefinePlan::none || (zero_fresh && plan.fresh[f])) std::fill_n(plane.data() + f * w, w, T(0));
        else std::copy_n(from + std::size_t(s) * w, w, plane.data() + f * w);
      }
      parallel_move(rows.data() + q * m * w, plane.data(), m * w);
    }
    rows.resize(planes * m * w);
    return;
  }
  const std::size_t tail = m - kept;
  std::vector<T> staged(planes * tail * w, T(0));  // zero for fresh rows
  for (std::size_t q = 0; q < planes; ++q)
    for (std::size_t t = 0; t < tail; ++t) {
      const std::uint32_t s = plan.source[kept + t];
      if (s == RefinePlan::none || (zero_fresh && plan.fresh[kept + t])) continue;
      std::copy_n(rows.data() + (q * n + s) * w, w, staged.data() + (q * tail + t) * w);
    }
  // Compact each plane's kept rows towards its start (destination <= source, ascending); the planes
  // are disjoint, so they are compacted in parallel.
  const std::ptrdiff_t splanes = static_cast<std::ptrdiff_t>(planes);
#pragma omp parallel for schedule(static, 1) if (planes > 1)
  for (std::ptrdiff_t sq = 0; sq < splanes; ++sq) {
    const std::size_t q = static_cast<std::size_t>(sq);
    T* base = rows.data() + q * n * w;
    for (std::size_t f = 0; f < kept;) {
      const std::size_t s = plan.source[f];
      std::size_t e = f + 1;
      while (e < kept && plan.source[e] == s + (e - f)) ++e;  // a run of consecutive sources
      if (s != f) std::memmove(base + f * w, base + s * w, (e - f) * w * sizeof(T));
      f = e;
    }
  }
  // Planes to their new stride m (upwards from the last plane when growing, downwards otherwise).
  if (planes * m * w > rows.capacity()) rows.reserve(planes * m * w + planes * m * w / 4);  // room for later growth
  if (m > n) {
    rows.resize(planes * m * w);
    for (std::size_t q = planes; q-- > 1;) parallel_move(rows.data() + q * m * w, rows.data() + q * n * w, kept * w);
  } else {
    for (std::size_t q = 1; q < planes; ++q) parallel_move(rows.data() + q * m * w, rows.data() + q * n * w, kept * w);
    rows.resize(planes * m * w);
  }
  for (std::size_t q = 0; q < planes; ++q)
    std::copy_n(staged.data() + q * tail * w, tail * w, rows.data() + (q * m + kept) * w);
}

/// Copies n values to dst with non-temporal stores where the target has them (SSE; floats in
/// 16-byte aligned groups of four): a destination that is written whole need not be read into
/// the cache first, which spares a third of a gather's memory traffic. Other types and
/// alignments copy as std::copy_n. The values are the same either way.
template <class T>
inline void stream_copy(const T* src, T* dst, std::size_t n) {
#if defined(__SSE__)
  if constexpr (std::is_same_v<T, float>) {
    if (reinterpret_cast<std::uintptr_t>(dst) % 16 == 0 && n % 4 == 0) {
      for (std::size_t k = 0; k < n; k += 4) _mm_stream_ps(dst + k, _mm_loadu_ps(src + k));
      return;
    }
  }
#endif
  std::copy_n(src, n, dst);
}

/// Orders this thread's stream_copy stores before its later stores (an OpenMP barrier after it
/// then publishes them to every thread).
inline void stream_fence() {
#if defined(__SSE__)
  _mm_sfence();
#endif
}

/// Apply `plan` to `rows` (`planes` planes of `in_cap` >= plan.input_size rows of `width` values)
/// out of place: every output row is gathered into `spare`, planes of `out_cap` >= plan.size() rows
/// (rows past plan.size() zero), in one parallel pass (each kept row read once, each output row
/// written once; the planes change stride on the way), then `rows` and `spare` swap, so that
/// `spare` holds the old values' memory for the next array of the same shape. Reusing that memory
/// from one refinement to the next spares the page faults of a fresh allocation; headroom of a
/// half is reserved when it grows (resize_for_overwrite). The values are those of apply_rows_impl.
template <class T>
void gather_rows(const RefinePlan& plan, std::vector<T>& rows, std::vector<T>& spare, std::size_t width,
                 std::size_t planes, bool zero_fresh, const char* what, std::size_t in_cap, std::size_t out_cap) {
  const std::size_t n = plan.input_size, m = plan.size(), w = width;
  if (rows.size() != planes * in_cap * w || in_cap < n || out_cap < m)
    throw std::invalid_argument(std::string(what) + ": array has " + std::to_string(rows.size()) + " values, plan expects " +
                                std::to_string(planes) + " x " + std::to_string(n) + " rows of " +
                                std::to_string(width));
  resize_for_overwrite(spare, planes * out_cap * w);  // nothing to keep: no copy into a new block
  const std::ptrdiff_t sm = static_cast<std::ptrdiff_t>(m);
  const std::uint32_t* source = plan.source.data();
#pragma omp parallel
  {
    for (std::size_t q = 0; q < planes; ++q) {
      const T* from = rows.data() + q * in_cap * w;
      T* to = spare.data() + q * out_cap * w;
#pragma omp for schedule(static, 1024) nowait  // the planes are disjoint: no barrier between them
      for (std::ptrdiff_t ff = 0; ff < sm; ++ff) {
        const std::size_t f = static_cast<std::size_t>(ff);
        const std::uint32_t s = source[f];
        if (s == RefinePlan::none || (zero_fresh && plan.fresh[f])) std::fill_n(to + f * w, w, T(0));
        else stream_copy(from + std::size_t(s) * w, to + f * w, w);
      }
    }
    stream_fence();  // before the region's closing barrier: every thread's rows are in place after it
  }
  if (out_cap > m)
    for (std::size_t q = 0; q < planes; ++q) std::fill_n(spare.data() + (q * out_cap + m) * w, (out_cap - m) * w, T(0));
  rows.swap(spare);
}

template <class T>
void gather_rows(const RefinePlan& plan, std::vector<T>& rows, std::vector<T>& spare, std::size_t width,
                 std::size_t planes, bool zero_fresh, const char* what) {
  gather_rows(plan, rows, spare, width, planes, zero_fresh, what, plan.input_size, plan.size());
}

/// The output rows of `plan` that change, ascending: those that are not a copy of the row already
/// at their index (with `zero_fresh`, new Gaussians' rows change too: their state starts at zero).
inline std::vector<std::uint32_t> changed_rows(const RefinePlan& plan, bool zero_fresh) {
  std::vector<std::uint32_t> out;
  for (std::size_t f = 0; f < plan.size(); ++f)
    if (plan.source[f] != f || (zero_fresh && plan.fresh[f])) out.push_back(std::uint32_t(f));
  return out;
}

/// The moves of an in-place refinement (apply_changed_rows), the same for every array it applies
/// to: found once per plan, not once per array.
struct RowChanges {
  std::vector<std::uint32_t> rows;    ///< changed_rows, ascending
  /// [rows.size()] 1 where the row copies a source that is itself the place of a changed row (the
  /// row of a split Gaussian that its samples copy): staged before any row is written.
  std::vector<std::uint8_t> staged;
  std::vector<std::uint32_t> hazard;  ///< the indices j into `rows` with staged[j]
};

inline RowChanges row_changes(const RefinePlan& plan, bool zero_fresh) {
  RowChanges c;
  c.rows = changed_rows(plan, zero_fresh);
  std::vector<std::uint8_t> written(std::max(plan.input_size, plan.size()), 0);
  for (const std::uint32_t f : c.rows) written[f] = 1;
  c.staged.assign(c.rows.size(), 0);
  for (std::size_t j = 0; j < c.rows.size(); ++j) {
    const std::size_t f = c.rows[j];
    const std::uint32_t s = plan.source[f];
    if (s != RefinePlan::none && !(zero_fresh && plan.fresh[f]) && written[s]) {
      c.staged[j] = 1;
      c.hazard.push_back(std::uint32_t(j));
    }
  }
  return c;
}

/// Apply `plan` to `rows` in place, writing only the output rows `changes.rows` (row_changes of
/// the same plan and zero_fresh), each copied straight from its source, except a source that is
/// itself the place of a changed row: those are read into a buffer before any row is written.
/// `planes` planes of `cap` rows (cap >= both sizes, unchanged: the planes do not move), or one
/// plane that is resized to plan.size() rows. Rows a shrinking plan leaves behind in a plane are
/// zeroed. The cost is that of the changed rows, not of the array.
template <class T>
void apply_changed_rows(const RefinePlan& plan, const RowChanges& changes, std::vector<T>& rows,
                        std::size_t width, std::size_t planes, std::size_t cap, bool zero_fresh) {
  const std::vector<std::uint32_t>& changed = changes.rows;
  const std::vector<std::uint32_t>& hazard = changes.hazard;
  const std::size_t n = plan.input_size, m = plan.size(), w = width, c = changed.size();
  const std::size_t in_stride = planes == 1 ? n : cap, out_stride = planes == 1 ? m : cap;
  std::vector<T> staged(planes * hazard.size() * w);
  for (std::size_t h = 0; h < hazard.size(); ++h)
    for (std::size_t q = 0; q < planes; ++q)
      std::copy_n(rows.data() + (q * in_stride + plan.source[changed[hazard[h]]]) * w, w, staged.data() + (q * hazard.size() + h) * w);
  if (planes == 1 && m > n) {  // room first (the old rows stay where they are)
    if (m * w > rows.capacity()) rows.reserve(m * w + m * w / 4);  // room for later growth
    rows.resize(m * w);
  }
  // Every other changed row straight from its source: no source of these is written here.
  const std::ptrdiff_t sc = static_cast<std::ptrdiff_t>(c);
  const bool parallel = c * planes * w > 16384;
#pragma omp parallel for schedule(static, 256) if (parallel)
  for (std::ptrdiff_t jj = 0; jj < sc; ++jj) {
    const std::size_t j = std::size_t(jj);
    if (changes.staged[j]) continue;
    const std::size_t f = changed[j];
    const std::uint32_t s = plan.source[f];
    const bool zero = s == RefinePlan::none || (zero_fresh && plan.fresh[f]);
    for (std::size_t q = 0; q < planes; ++q) {
      T* to = rows.data() + (q * out_stride + f) * w;
      if (zero) std::fill_n(to, w, T(0));
      else std::copy_n(rows.data() + (q * in_stride + s) * w, w, to);
    }
  }
  for (std::size_t h = 0; h < hazard.size(); ++h)
    for (std::size_t q = 0; q < planes; ++q)
      std::copy_n(staged.data() + (q * hazard.size() + h) * w, w, rows.data() + (q * out_stride + changed[hazard[h]]) * w);
  if (planes == 1) rows.resize(m * w);  // shrinking: after the rows past the end were read
  else if (m < n)
    for (std::size_t q = 0; q < planes; ++q) std::fill_n(rows.data() + (q * cap + m) * w, (n - m) * w, T(0));
}

/// Calls f(array, row width, planes) for every per-Gaussian array of a model (SH: one plane per band).
template <class G, class S, class F>
void for_each_array(GaussianModel<G, S>& m, F&& f) {
  f(m.means, std::size_t(3), std::size_t(1));
  f(m.log_scales, std::size_t(3), std::size_t(1));
  f(m.quats, std::size_t(4), std::size_t(1));
  f(m.opacity_logits, std::size_t(1), std::size_t(1));
  f(m.sh, static_cast<std::size_t>(G::sh_coeffs), static_cast<std::size_t>(G::bands));
}

/// Memory the geometry arrays of a refinement are gathered into (gather_rows), one vector per row
/// width: the arrays of a width (means and log-scales; rotations; opacities), of the model and of
/// every optimiser state, pass one old array's memory on to the next.
template <class S>
struct GeometrySpares {
  std::vector<S> w1, w3, w4;
  std::vector<S>& of_width(std::size_t w) { return w == 1 ? w1 : w == 3 ? w3 : w4; }
};

/// Apply `plan` to every array of a model or of optimiser state in the model's layout: fresh rows
/// zero with `zero_fresh`. When few rows change (a refinement that keeps the surviving Gaussians in
/// their rows and puts new ones into the rows of removed ones) and the band planes have room for
/// the result, only those rows are written (apply_changed_rows). Otherwise with a `spare`, the band
/// planes are gathered out of place through it (gather_rows), their capacity grown by a quarter
/// when the result does not fit; with `geometry`, the other arrays too (in parallel, where the
/// in-place move of apply_rows_impl is one thread's memmove), else they move in place.
template <class G, class S>
void apply_arrays(const RefinePlan& plan, GaussianModel<G, S>& m, bool zero_fresh,
                  std::type_identity_t<std::vector<S>>* spare, const char* what,
                  GeometrySpares<std::type_identity_t<S>>* geometry = nullptr) {
  m.check_consistent();
  plan.validate();
  const std::size_t rows_out = plan.size(), cap = m.sh_capacity();
  const RowChanges changes = row_changes(plan, zero_fresh);
  const bool few = changes.rows.size() * 2 <= rows_out;
  for_each_array(m, [&](auto& v, std::size_t w, std::size_t planes) {
    const bool sh = &v == &m.sh;
    const std::size_t in_cap = sh ? cap : plan.input_size;
    if (few && (planes == 1 || rows_out <= in_cap)) {
      apply_changed_rows(plan, changes, v, w, planes, in_cap, zero_fresh);
      return;
    }
    if (sh && (spare || in_cap != plan.input_size)) {
      const std::size_t out_cap = planes == 1 ? rows_out : rows_out <= in_cap ? in_cap : rows_out + rows_out / 4;
      std::vector<S> temporary;
      gather_rows(plan, v, spare ? *spare : temporary, w, planes, zero_fresh, what, in_cap, out_cap);
    } else if (geometry && !sh) {
      gather_rows(plan, v, geometry->of_width(w), w, planes, zero_fresh, what);
    } else {
      apply_rows_impl(plan, v, w, zero_fresh, what, planes, true);
    }
  });
}
}  // namespace detail

/// Apply `plan` to a per-Gaussian array of `width` values per row (rows copied, `none` rows zero).
template <class T>
void apply_rows(const RefinePlan& plan, std::vector<T>& rows, std::size_t width) {
  detail::apply_rows_impl(plan, rows, width, false, "apply_rows");
}

/// Apply `plan` to per-Gaussian optimiser state: surviving rows follow their Gaussian, fresh
/// rows are zero.
template <class T>
void apply_rows_zero_fresh(const RefinePlan& plan, std::vector<T>& rows, std::size_t width) {
  detail::apply_rows_impl(plan, rows, width, true, "apply_rows_zero_fresh");
}

/// Apply `plan` to a model: every parameter of output row i is a copy of input row source[i]
/// (SH of all bands included).
template <class G, class S>
void apply(const RefinePlan& plan, GaussianModel<G, S>& model) {
  detail::apply_arrays(plan, model, false, nullptr, "apply(model)");
}

/// `apply` with the band planes gathered out of place through `spare` (detail::gather_rows): one
/// pass over the colour coefficients, which are most of a model, instead of a compaction and a
/// restride; `spare` ends up holding the old planes' memory, to be passed again with the next
/// model or state of the same layout. The geometry arrays are moved in place. Same values as apply.
template <class G, class S>
void apply(const RefinePlan& plan, GaussianModel<G, S>& model, std::vector<S>& spare) {
  detail::apply_arrays(plan, model, false, &spare, "apply(model)");
}

/// Apply `plan` to optimiser state stored with the model's layout (Adam's exp_avg, exp_avg_sq):
/// rows of surviving Gaussians follow them, fresh Gaussians get zeros.
template <class G, class S>
void apply_zero_fresh(const RefinePlan& plan, GaussianModel<G, S>& state) {
  detail::apply_arrays(plan, state, true, nullptr, "apply_zero_fresh(state)");
}

/// `apply_zero_fresh` with the band planes gathered out of place through `spare`, as
/// apply(plan, model, spare). Same values as apply_zero_fresh.
template <class G, class S>
void apply_zero_fresh(const RefinePlan& plan, GaussianModel<G, S>& state, std::vector<S>& spare) {
  detail::apply_arrays(plan, state, true, &spare, "apply_zero_fresh(state)");
}

/// The plan that puts the rows of `model` into spatial order (spatial_order.hpp), for the model and
/// every array that follows it.
template <class G, class S>
RefinePlan spatial_order_plan(const GaussianModel<G, S>& model) {
  model.check_consistent();
  return RefinePlan::reorder(order_by_code(morton_codes(model.means.data(), model.size())));
}

// ---------------------------------------------------------------------------------------------
// Configuration
// ---------------------------------------------------------------------------------------------

/// Every threshold and every step range of adaptive density control. The step fields are
/// integers so that ScheduleScale can shorten them with the rest of the run (`scaled`).
/// Scales are relative to the scene scale passed to DensityControl; screen sizes are relative
/// to max(image width, height).
struct DensifyConfig {
  // ---- growth ----
  double grow_grad2d = 0.0008;      ///< densify where the average screen-space gradient norm (NDC) exceeds this
  bool absgrad = true;              ///< accumulate Gradients::absgrad instead of Gradients::mean2d
  bool per_band = true;             ///< MSAD: one accumulator per band, densify on the maximum over bands
  double grow_scale3d = 0.01;       ///< duplicate where max scale <= this x scene scale, split otherwise
  double grow_scale2d = 0.05;       ///< also split where the max screen radius exceeds this (step < screen_stop)
  int split_samples = 2;            ///< Gaussians that replace a split one
  double split_scale_divisor = 1.6; ///< split samples get scale / this

  // ---- pruning ----
  double prune_opacity = 0.1;       ///< remove opacity below this
  double prune_scale3d = 0.5;       ///< after the first opacity reset remove max scale above this x scene scale
  double prune_scale2d = 0.15;      ///< after the first reset and while step < screen_stop remove screen radius above this

  // ---- opacity reset ----
  double reset_opacity = 0.2;       ///< opacities are clamped to at most this at every reset

  // ---- budget ----
  /// Most Gaussians a refinement may grow the model to (0 = no limit). When the candidates would
  /// exceed it, those with the largest average screen-space gradient grow first (ties: lower
  /// index); the rest wait for the next refinement. Pruning is not affected.
  std::size_t max_gaussians = 0;
  /// Stop with DensifyLimitError when a refinement would grow the model beyond this many
  /// Gaussians, before it allocates anything (0 = never). A guard against runaway growth running
  /// out of memory: unlike max_gaussians it never changes a result, it only ends a run that would
  /// not fit (`msgs train` sets it from the memory the machine has available).
  std::size_t stop_gaussians = 0;

  // ---- step ranges (integers, scaled by ScheduleScale) ----
  int refine_start = 500;           ///< refine only at step > refine_start
  int refine_stop = 60000;          ///< from this step on: no statistics, no refinement, no opacity reset
  int refine_every = 300;           ///< refine at multiples of this
  int reset_every = 9000;           ///< opacity reset at positive multiples of this (30 x refine_every); 0 = never
  int screen_stop = 4000;           ///< screen-space split / prune only while step < this; 0 = never
  int pause_begin = 0;              ///< refinement (and statistics) paused for pause_begin < step <= pause_end
  int pause_end = 0;                ///< equal to pause_begin: no pause window
  /// No refinement while step % reset_every < this, i.e. for this many steps after each reset.
  /// -1 = automatic: num_train_images x images_scale + refine_every (the reference's choice: one
  /// pass over the training images so that every view has re-rendered the reset opacities).
  int pause_after_reset = -1;
  double images_scale = 1.0;        ///< multiplies num_train_images in the automatic pause (scaled() sets it)

  std::uint64_t seed = 0;           ///< seed of the split samples
  /// Sort the Gaussians into spatial order (spatial_order.hpp) as part of every reorder_every-th
  /// refinement (steps that are multiples of reorder_every x refine_every) and of a refinement that
  /// no other follows within that span (the last before refine_stop or a pause), so that a view's
  /// Gaussians are runs of consecutive rows. The refinements in between keep every surviving
  /// Gaussian in its row and put the new ones into the rows of removed ones (fill_removed_rows),
  /// so that they write the rows that change, not the whole model and both moments.
  /// 0 = never, and rows stay in gsplat's order (survivors, then copies, then split samples): every
  /// refinement moves every row after the first removed one. It moves rows and nothing else: split samples draw from the
  /// parent's values (content_key), not its row, and the trainer's rasteriser orders Gaussians at
  /// equal depth by their means (RasterOptions::ties_by_mean), so a run with it holds the same
  /// Gaussians, bit for bit, as the run without, in another order (test_checkpoint). Counted in refinements, so that ScheduleScale leaves it
  /// alone; at most 10^6.
  int reorder_every = 8;

  /// The multi-spectral implementation's defaults (splatfacto thresholds with absgrad, MSAD
  /// per-band accumulators) for the recommended 120k-step Joint run: refine every 300 from 500
  /// to 60000, opacity reset every 30 x 300 steps to 0.2, prune opacity < 0.1.
  static DensifyConfig msad() { return DensifyConfig{}; }

  /// gsplat's DefaultStrategy / 3DGS: threshold 0.0002 on the plain (non-abs) gradient with one
  /// accumulator, refine every 100 from 500 to 15000, prune opacity < 0.005, reset every 3000
  /// to 0.01, prune scale > 0.1 after the first reset, no screen-space rules, no pause after resets.
  static DensifyConfig gsplat_default() {
    DensifyConfig c;
    c.grow_grad2d = 0.0002;
    c.absgrad = false;
    c.per_band = false;
    c.grow_scale3d = 0.01;
    c.grow_scale2d = 0.05;
    c.prune_opacity = 0.005;
    c.prune_scale3d = 0.1;
    c.prune_scale2d = 0.15;
    c.reset_opacity = 0.01;
    c.refine_start = 500;
    c.refine_stop = 15000;
    c.refine_every = 100;
    c.reset_every = 3000;
    c.screen_stop = 0;
    c.pause_after_reset = 0;
    return c;
  }

  /// Every step field multiplied by `s`. reset_every keeps its ratio to refine_every when it was a
  /// multiple of it, so resets still land on refinement steps after rounding.
  DensifyConfig scaled(const ScheduleScale& s) const {
    s.validate();
    DensifyConfig r = *this;
    r.refine_start = s(refine_start);
    r.refine_stop = s(refine_stop);
    r.refine_every = s(refine_every);
    if (reset_every > 0 && refine_every > 0 && reset_every % refine_every == 0)
      r.reset_every = (reset_every / refine_every) * r.refine_every;
    else
      r.reset_every = s(reset_every);
    r.screen_stop = s(screen_stop);
    r.pause_begin = s(pause_begin);
    r.pause_end = s(pause_end);
    if (pause_after_reset > 0) r.pause_after_reset = s(pause_after_reset);
    r.images_scale = images_scale * s.factor;
    return r;
  }

  /// Steps without refinement after each opacity reset for a dataset of `num_train_images`.
  int pause_after_reset_for(int num_train_images) const {
    if (pause_after_reset >= 0) return pause_after_reset;
    return static_cast<int>(std::lround(double(std::max(num_train_images, 0)) * images_scale)) + refine_every;
  }

  /// Throw std::invalid_argument naming the first field out of range.
  void validate() const {
    auto bad = [](const std::string& field, const std::string& expected) {
      throw std::invalid_argument("DensifyConfig: " + field + " must be " + expected);
    };
    auto finite_nonneg = [&](double v, const char* f) {
      if (!(std::isfinite(v) && v >= 0.0)) bad(f, "finite and >= 0, got " + std::to_string(v));
    };
    finite_nonneg(grow_grad2d, "grow_grad2d");
    finite_nonneg(grow_scale3d, "grow_scale3d");
    finite_nonneg(grow_scale2d, "grow_scale2d");
    finite_nonneg(prune_scale3d, "prune_scale3d");
    finite_nonneg(prune_scale2d, "prune_scale2d");
    if (split_samples < 1) bad("split_samples", ">= 1");
    if (!(std::isfinite(split_scale_divisor) && split_scale_divisor > 0.0)) bad("split_scale_divisor", "finite and > 0");
    if (!(prune_opacity >= 0.0 && prune_opacity < 1.0)) bad("prune_opacity", "in [0, 1)");
    if (!(reset_opacity > 0.0 && reset_opacity < 1.0)) bad("reset_opacity", "in (0, 1)");
    if (refine_every < 1) bad("refine_every", ">= 1");
    if (refine_start < 0) bad("refine_start", ">= 0");
    if (refine_stop < 0) bad("refine_stop", ">= 0");
    if (reset_every < 0) bad("reset_every", ">= 0");
    if (screen_stop < 0) bad("screen_stop", ">= 0");
    if (pause_begin < 0 || pause_end < pause_begin) bad("pause_begin/pause_end", "0 <= pause_begin <= pause_end");
    if (pause_after_reset < -1) bad("pause_after_reset", ">= 0 or -1 (automatic)");
    if (!(std::isfinite(images_scale) && images_scale > 0.0)) bad("images_scale", "finite and > 0");
    if (reorder_every < 0 || reorder_every > 1000000) bad("reorder_every", "in 0 .. 10^6 (0 = never)");
  }
};

// ---------------------------------------------------------------------------------------------
// Statistics
// ---------------------------------------------------------------------------------------------

/// Per-Gaussian, per-band accumulators of the screen-space gradient. The gradient w.r.t. the
/// projected mean in pixels is multiplied by (W/2, H/2), which makes it the gradient w.r.t. the
/// NDC position as in gsplat, so thresholds do not depend on the resolution.
class DensityStats {
 public:
  DensityStats() = default;
  DensityStats(std::size_t n, int bands) { reset(n, bands); }

  /// Zero every accumulator for `n` Gaussians and `bands` bands.
  void reset(std::size_t n, int bands) {
    if (bands < 1) throw std::invalid_argument("DensityStats: bands must be >= 1, got " + std::to_string(bands));
    n_ = n;
    bands_ = bands;
    zero_with_room(grad_, n * static_cast<std::size_t>(bands));
    zero_with_room(count_, n * static_cast<std::size_t>(bands));
    zero_with_room(radius_, n);
  }
  /// Zero every accumulator for `n` Gaussians, same bands.
  void reset(std::size_t n) { reset(n, bands_); }

  /// Gaussians tracked.
  std::size_t size() const { return n_; }
  /// Accumulator bands.
  int bands() const { return bands_; }

  /// Accumulate one rendered view of `band`. `grad2d` [N, 2] is dL/d(projected mean) in pixels
  /// (or its absgrad variant), `radii` [N, 2] the screen half-extents in pixels ({0, 0} = not
  /// visible). A Gaussian counts as visible when both radii are > 0 (gsplat). Non-finite
  /// gradients are skipped rather than poisoning the running sum. `rows`: nullptr looks at every
  /// Gaussian; a list (ascending, e.g. Rasterizer::visible()) looks at those only and reads
  /// `grad2d` and `radii` only there, which gives the same sums when every Gaussian outside the
  /// list has zero radii.
  template <class S>
  void add(int band, const std::vector<S>& grad2d, const std::vector<std::int32_t>& radii, int width, int height,
           const std::vector<std::uint32_t>* rows = nullptr) {
    if (band < 0 || band >= bands_)
      throw std::invalid_argument("DensityStats::add: band " + std::to_string(band) + " outside [0, " +
                                  std::to_string(bands_) + ")");
    if (grad2d.size() != 2 * n_ || radii.size() != 2 * n_)
      throw std::invalid_argument("DensityStats::add: expected grad2d and radii of " + std::to_string(n_) +
                                  " x 2 values, got " + std::to_string(grad2d.size()) + " and " + std::to_string(radii.size()));
    if (width < 1 || height < 1) throw std::invalid_argument("DensityStats::add: image size must be >= 1");
    if (rows)
      for (std::uint32_t i : *rows)
        if (i >= n_) throw std::invalid_argument("DensityStats::add: row " + std::to_string(i) + " outside " + std::to_string(n_));
    const double sx = 0.5 * width, sy = 0.5 * height;
    const double inv_size = 1.0 / double(std::max(width, height));
    const auto b = static_cast<std::size_t>(band), nb = static_cast<std::size_t>(bands_);
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(rows ? rows->size() : n_);
    // Rows are distinct, so the iterations write disjoint entries: any thread count, same sums.
#pragma omp parallel for schedule(static, 4096)
    for (std::ptrdiff_t j = 0; j < n; ++j) {
      const std::size_t i = rows ? std::size_t((*rows)[std::size_t(j)]) : std::size_t(j);
      const std::int32_t rx = radii[2 * i], ry = radii[2 * i + 1];
      if (rx <= 0 || ry <= 0) continue;
      const double gx = double(grad2d[2 * i]) * sx, gy = double(grad2d[2 * i + 1]) * sy;
      const double norm = std::sqrt(gx * gx + gy * gy);
      if (!std::isfinite(norm)) continue;
      grad_[i * nb + b] += static_cast<float>(norm);
      count_[i * nb + b] += 1u;
      radius_[i] = std::max(radius_[i], static_cast<float>(double(std::max(rx, ry)) * inv_size));
    }
  }

  /// Accumulated gradient norm of Gaussian i in `band`.
  float grad_sum(std::size_t i, int band) const { return grad_[i * std::size_t(bands_) + std::size_t(band)]; }
  /// Views of `band` in which Gaussian i was visible.
  std::uint32_t count(std::size_t i, int band) const { return count_[i * std::size_t(bands_) + std::size_t(band)]; }
  /// Average gradient norm of Gaussian i in `band`: sum / max(count, 1).
  double average(std::size_t i, int band) const {
    return double(grad_sum(i, band)) / double(std::max<std::uint32_t>(count(i, band), 1u));
  }
  /// Largest per-band average of Gaussian i (MSAD's criterion; with one band, the average).
  double max_average(std::size_t i) const {
    double m = 0.0;
    for (int b = 0; b < bands_; ++b) m = std::max(m, average(i, b));
    return m;
  }
  /// Largest screen radius of Gaussian i seen since the last reset, relative to max(W, H).
  float max_radius(std::size_t i) const { return radius_[i]; }
  /// [N] the same for all Gaussians.
  const std::vector<float>& max_radii() const { return radius_; }

  /// Raw accumulators, for checkpoints: [N, B] gradient sums, [N, B] counts, [N] max radii.
  const std::vector<float>& grad_sums() const { return grad_; }
  const std::vector<std::uint32_t>& counts() const { return count_; }
  /// Restore accumulators saved from grad_sums()/counts()/max_radii() of `n` Gaussians, `bands` bands.
  void restore(std::size_t n, int bands, std::vector<float> grad, std::vector<std::uint32_t> count,
               std::vector<float> radius) {
    if (bands < 1 || grad.size() != n * std::size_t(bands) || count.size() != n * std::size_t(bands) ||
        radius.size() != n)
      throw std::invalid_argument("DensityStats::restore: arrays do not match " + std::to_string(n) + " Gaussians x " +
                                  std::to_string(bands) + " bands");
    n_ = n;
    bands_ = bands;
    grad_ = std::move(grad);
    count_ = std::move(count);
    radius_ = std::move(radius);
  }

 private:
  std::size_t n_ = 0;
  int bands_ = 1;
  /// `v` as `size` zeros, grown as detail::resize_for_overwrite grows it (with room to spare): the
  /// model grows at nearly every refinement of the growth phase, and a reallocation to the exact
  /// size each time would take fresh pages (and their faults) at every one.
  template <class T>
  static void zero_with_room(std::vector<T>& v, std::size_t size) {
    detail::resize_for_overwrite(v, size);
    std::fill(v.begin(), v.end(), T(0));
  }

  std::vector<float> grad_;            // [N, B] sum of NDC gradient norms over visible views
  std::vector<std::uint32_t> count_;   // [N, B] visible views
  std::vector<float> radius_;          // [N]    max screen radius / max(W, H)
};

// ---------------------------------------------------------------------------------------------
// Density control
// ---------------------------------------------------------------------------------------------

/// What one refinement did, for logging.
struct RefineCounts {
  std::size_t duplicated = 0;  ///< Gaussians cloned (each adds one)
  std::size_t split = 0;       ///< Gaussians replaced by split_samples samples
  std::size_t pruned = 0;      ///< Gaussians removed (after growth)
};

/// Outcome of DensityControl::step_post_backward.
/// Thrown by DensityControl::refine when a refinement would grow the model beyond
/// DensifyConfig::stop_gaussians: the run stops before it runs out of memory.
struct DensifyLimitError : std::runtime_error {
  long long step;
  std::size_t before, after, limit;
  DensifyLimitError(long long s, std::size_t n, std::size_t grown, std::size_t lim)
      : std::runtime_error("densification at step " + std::to_string(s) + " would grow the model from " +
                           std::to_string(n) + " to " + std::to_string(grown) + " Gaussians, above the limit of " + std::to_string(lim) +
                           " (`msgs train --stop-gaussians`, by default what fits in memory); the run is stopped. " +
                           "Runaway growth (the " +
                           "statistics exceed the growth threshold almost everywhere) usually means training images " +
                           "so small that every Gaussian covers a large part of one (the resolution schedule starts " +
                           "at a quarter of their size: `--num-downscales 0` trains at full size), colours far " +
                           "from the images, or a schedule too dense for the scene: see README, \"Presets, " +
                           "reference parity and convergence\". --max-gaussians N caps the growth instead."),
        step(s), before(n), after(grown), limit(lim) {}
};

struct DensifyReport {
  bool refined = false;        ///< grow + prune ran at this step
  bool opacity_reset = false;  ///< opacities were reset at this step
  RefineCounts counts;
  std::size_t before = 0;      ///< Gaussians before the step
  std::size_t after = 0;       ///< Gaussians after the step
  /// The surgery, for further per-Gaussian arrays; only meaningful when `refined` (otherwise it
  /// is empty and applying it to a non-empty array throws, rather than silently clearing it).
  RefinePlan plan;
};

/// Adaptive density control of 3DGS as gsplat's DefaultStrategy and the multi-spectral
/// implementation run it (REFERENCE §5). After each backward the caller feeds the screen-space
/// gradients (`observe`), then calls `step_post_backward`, passing the optimiser moments kept
/// with the model's layout so that they follow every change:
///
///     dc.observe_gradients(step, band, grads, raster.radii(), cam.width, cam.height);
///     auto rep = dc.step_post_backward(step, model, adam.exp_avg, adam.exp_avg_sq);
///
/// Everything is deterministic: split samples are hashes of (seed, step, the parent's geometry bits,
/// sample, axis), so that they do not depend on where a Gaussian's row is.
class DensityControl {
 public:
  /// `num_bands`: bands a training step may render (accumulators per band when cfg.per_band);
  /// `num_train_images`: for the automatic pause after resets; `scene_scale`: multiplies the 3-D
  /// scale thresholds.
  DensityControl(DensifyConfig cfg, int num_bands, int num_train_images, double scene_scale = 1.0)
      : cfg_(std::move(cfg)), num_bands_(num_bands), scene_scale_(scene_scale) {
    cfg_.validate();
    if (num_bands < 1) throw std::invalid_argument("DensityControl: num_bands must be >= 1");
    if (num_train_images < 0) throw std::invalid_argument("DensityControl: num_train_images must be >= 0");
    if (!(std::isfinite(scene_scale) && scene_scale > 0.0))
      throw std::invalid_argument("DensityControl: scene_scale must be finite and > 0");
    pause_after_reset_ = cfg_.pause_after_reset_for(num_train_images);
    if (cfg_.reset_every > 0 && pause_after_reset_ >= cfg_.reset_every)
      throw std::invalid_argument("DensityControl: the pause after an opacity reset (" + std::to_string(pause_after_reset_) +
                                  " steps) is not shorter than reset_every (" + std::to_string(cfg_.reset_every) +
                                  "): densification would never run");
    stats_.reset(0, cfg_.per_band ? num_bands : 1);
  }

  const DensifyConfig& config() const { return cfg_; }
  const DensityStats& stats() const { return stats_; }
  /// Mutable statistics, for restoring a checkpoint.
  DensityStats& stats() { return stats_; }
  double scene_scale() const { return scene_scale_; }
  int num_bands() const { return num_bands_; }
  /// Steps after each opacity reset without refinement (resolved from num_train_images).
  int pause_after_reset() const { return pause_after_reset_; }

  /// Whether statistics are collected at `step`: before refine_stop and outside the pause window
  /// (a pause exists to let new bands settle; their first gradients should not drive growth).
  bool accumulates_at(long long step) const { return step < cfg_.refine_stop && !paused_at(step); }

  /// Whether `step` grows and prunes: step > refine_start, a multiple of refine_every, before
  /// refine_stop, outside the pause window, and step % reset_every >= pause_after_reset (gsplat's
  /// rule: not within that many steps after an opacity reset).
  bool refines_at(long long step) const {
    if (step <= cfg_.refine_start || step >= cfg_.refine_stop) return false;
    if (step % cfg_.refine_every != 0 || paused_at(step)) return false;
    return cfg_.reset_every <= 0 || step % cfg_.reset_every >= pause_after_reset_;
  }

  /// Whether the refinement at `step` also sorts the Gaussians into spatial order
  /// (DensifyConfig::reorder_every): a multiple of reorder_every x refine_every, or a refinement
  /// step after which no refinement follows within that many steps. Depends on the configuration
  /// and the step only, so a resumed run sorts where the uninterrupted one did.
  bool reorders_at(long long step) const {
    if (cfg_.reorder_every <= 0 || !refines_at(step)) return false;
    const long long span = static_cast<long long>(cfg_.reorder_every) * cfg_.refine_every;
    if (step % span == 0) return true;
    for (long long t = step + cfg_.refine_every; t <= step + span && t < cfg_.refine_stop; t += cfg_.refine_every)
      if (refines_at(t)) return false;
    return true;
  }

  /// Whether `step` resets opacities: a positive multiple of reset_every before refine_stop and
  /// outside the pause window (the reference stops resets there too).
  bool resets_opacity_at(long long step) const {
    return cfg_.reset_every > 0 && step > 0 && step % cfg_.reset_every == 0 && step < cfg_.refine_stop &&
           !paused_at(step);
  }

  /// Forget the statistics, for a model of `n` Gaussians changed outside this class.
  void reset_stats(std::size_t n) { stats_.reset(n); }

  /// Accumulate the screen-space gradients of one rendered view. `grad2d` [N, 2] must be
  /// Gradients::absgrad when config().absgrad, else Gradients::mean2d; `radii` [N, 2] the
  /// rasteriser's radii; `band` the band the view belongs to (ignored without per-band stats).
  /// `rows`: as DensityStats::add (nullptr: every Gaussian; else the ones the view saw).
  template <class S>
  void observe(long long step, int band, const std::vector<S>& grad2d, const std::vector<std::int32_t>& radii, int width,
               int height, const std::vector<std::uint32_t>* rows = nullptr) {
    if (band < 0 || band >= num_bands_)
      throw std::invalid_argument("DensityControl::observe: band " + std::to_string(band) + " outside [0, " +
                                  std::to_string(num_bands_) + ")");
    if (!accumulates_at(step)) return;
    const std::size_t n = grad2d.size() / 2;
    if (stats_.size() != n) {
      if (stats_.size() != 0)
        throw std::invalid_argument("DensityControl::observe: gradients for " + std::to_string(n) +
                                    " Gaussians, statistics for " + std::to_string(stats_.size()) +
                                    "; call reset_stats(n) after changing the model outside DensityControl");
      stats_.reset(n);  // first view since construction
    }
    stats_.add(cfg_.per_band ? band : 0, grad2d, radii, width, height, rows);
  }

  /// `observe` with the gradient array chosen from a rasteriser Gradients object (anything with
  /// `mean2d` and `absgrad` members) according to config().absgrad.
  template <class Grads>
  void observe_gradients(long long step, int band, const Grads& grads, const std::vector<std::int32_t>& radii, int width,
                         int height, const std::vector<std::uint32_t>* rows = nullptr) {
    if (cfg_.absgrad && grads.absgrad.size() != grads.mean2d.size())
      throw std::invalid_argument("DensityControl::observe_gradients: absgrad densification needs "
                                  "Gradients::absgrad, which is empty; render with RasterOptions{.absgrad = true}");
    observe(step, band, cfg_.absgrad ? grads.absgrad : grads.mean2d, radii, width, height, rows);
  }

  /// The hook after each backward (and after `observe`): refines when `refines_at(step)`, then
  /// resets opacities when `resets_opacity_at(step)`. `states` are per-Gaussian optimiser arrays
  /// with the model's layout (GaussianModel<G, T>); they follow the plan with zeros for new rows,
  /// and their opacity entries are zeroed at a reset, as the references do with Adam's moments.
  template <class G, class S, class... States>
  DensifyReport step_post_backward(long long step, GaussianModel<G, S>& model, States&... states) {
    DensifyReport rep;
    rep.before = model.size();
    // Check every state before touching anything, so a mismatch cannot leave half-applied surgery.
    [[maybe_unused]] auto check = [&](const auto& st) {
      st.check_consistent();
      if (st.size() != model.size())
        throw std::invalid_argument("DensityControl::step_post_backward: optimiser state holds " + std::to_string(st.size()) +
                                    " Gaussians, model " + std::to_string(model.size()));
    };
    (check(states), ...);
    if (refines_at(step)) {
      rep.plan = refine(step, model, rep.counts);
      (apply_state(rep.plan, states), ...);
      rep.refined = true;
    }
    if (resets_opacity_at(step)) {
      reset_opacity(model, states...);
      rep.opacity_reset = true;
    }
    if (step + 1 >= cfg_.refine_stop) {  // no refinement follows: give the spares' memory back
      spare_float_ = {};
      spare_double_ = {};
    }
    rep.after = model.size();
    return rep;
  }

  /// Grow and prune now (whatever the schedule says; `step` selects the screen-space and
  /// after-reset rules and seeds the split samples), then zero the statistics. Returns the plan,
  /// which the caller applies to every other per-Gaussian array (apply_zero_fresh for optimiser
  /// state). Order as gsplat: duplicate (copies appended), split (originals removed, samples
  /// appended), then prune on the grown set; copies and samples inherit screen radii.
  template <class G, class S>
  RefinePlan refine(long long step, GaussianModel<G, S>& model, RefineCounts& counts) {
    model.check_consistent();
    const std::size_t n = model.size();
    if (stats_.size() != n) {
      if (stats_.size() != 0)
        throw std::invalid_argument("DensityControl::refine: statistics for " + std::to_string(stats_.size()) +
                                    " Gaussians, model has " + std::to_string(n));
      stats_.reset(n);  // nothing observed yet: all statistics are zero
    }
    const bool screen = step < cfg_.screen_stop;
    const bool after_reset = cfg_.reset_every > 0 && step > cfg_.reset_every;
    counts = {};

    // ---- growth decisions on the current set ----
    std::vector<bool> dup(n, false), split(n, false);
    const double small_limit = cfg_.grow_scale3d * scene_scale_;
    {
      std::vector<std::uint8_t> flags(n);  // bit 0 duplicate, bit 1 split; bytes, so threads can write them
      const std::ptrdiff_t sn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static, 4096)
      for (std::ptrdiff_t ii = 0; ii < sn; ++ii) {
        const std::size_t i = static_cast<std::size_t>(ii);
        const bool high = stats_.max_average(i) > cfg_.grow_grad2d;
        const bool small = max_scale(model, i) <= small_limit;
        // gsplat ORs the screen rule in regardless of size: a small, high-gradient Gaussian that is
        // also large on screen is cloned and split (three Gaussians).
        const bool sp = (high && !small) || (screen && double(stats_.max_radius(i)) > cfg_.grow_scale2d);
        flags[i] = std::uint8_t((high && small ? 1 : 0) | (sp ? 2 : 0));
      }
      for (std::size_t i = 0; i < n; ++i) {
        dup[i] = flags[i] & 1;
        split[i] = flags[i] & 2;
      }
    }
    if (cfg_.max_gaussians > 0) limit_growth(model, dup, split);
    for (std::size_t i = 0; i < n; ++i) {
      counts.duplicated += dup[i];
      counts.split += split[i];
    }
    const std::size_t grown_to = n + counts.duplicated + counts.split * std::size_t(cfg_.split_samples - 1);
    if (cfg_.stop_gaussians > 0 && grown_to > cfg_.stop_gaussians)
      throw DensifyLimitError(step, n, grown_to, cfg_.stop_gaussians);

    // The surgery is planned on row indices first and applied to the model once at the end: one
    // pass over every array instead of one per stage (duplicate, split, prune).
    // ---- duplicate: copies appended; they are not split ----
    const RefinePlan p_dup = RefinePlan::duplicate(dup);
    split.resize(p_dup.size(), false);

    // ---- split: originals removed, samples appended in blocks ----
    const RefinePlan p_split = RefinePlan::split(split, cfg_.split_samples);
    std::vector<std::size_t> sel;  // rows of the duplicated set; all < n, since copies are not split
    for (std::size_t i = 0; i < split.size(); ++i)
      if (split[i]) sel.push_back(i);
    const std::size_t samples = sel.size() * static_cast<std::size_t>(cfg_.split_samples);
    RefinePlan plan = p_dup.then(p_split);
    const std::size_t grown = plan.size(), rest = grown - samples;
    // Sample rows: the parent's mean moved by an offset drawn in its frame, scales divided.
    std::vector<S> sample_mean(samples * 3), sample_log_scale(samples * 3);
    const double dlog = std::log(cfg_.split_scale_divisor);
    const std::vector<std::uint64_t> draw_key = split_draw_keys(model, sel);
    // Every sample is drawn from its own key and written to its own row: in parallel, the same bits.
    const std::ptrdiff_t nsel = static_cast<std::ptrdiff_t>(sel.size());
#pragma omp parallel for schedule(static, 64)
    for (std::ptrdiff_t jj = 0; jj < nsel; ++jj)
      for (int k = 0; k < cfg_.split_samples; ++k) {
        const std::size_t j = static_cast<std::size_t>(jj);
        const std::size_t c = static_cast<std::size_t>(k) * sel.size() + j, parent = sel[j];
        double offset[3];
        sample_offset(model, parent, draw_key[j], step, k, offset);
        for (std::size_t a = 0; a < 3; ++a) {
          sample_mean[c * 3 + a] = static_cast<S>(double(model.means[parent * 3 + a]) + offset[a]);
          sample_log_scale[c * 3 + a] = static_cast<S>(double(model.log_scales[parent * 3 + a]) - dlog);
        }
      }

    // ---- prune on the grown set ----
    std::vector<float> radius = stats_.max_radii();  // [N] follows the growth: copies inherit
    apply_rows(plan, radius, 1);
    std::vector<std::uint8_t> prune_flag(grown, 0);
    const std::vector<std::uint8_t> finite = rows_finite(model);  // by source row
    const double big_limit = cfg_.prune_scale3d * scene_scale_;
    const std::ptrdiff_t sgrown = static_cast<std::ptrdiff_t>(grown);
#pragma omp parallel for schedule(static, 4096)
    for (std::ptrdiff_t rr = 0; rr < sgrown; ++rr) {
      const std::size_t r = static_cast<std::size_t>(rr);
      const std::size_t src = plan.source[r];
      const S* ls = r < rest ? &model.log_scales[3 * src] : &sample_log_scale[3 * (r - rest)];
      const double o = detail::sigmoid(double(model.opacity_logits[src]));
      bool p = o < cfg_.prune_opacity || !finite[src] ||  // a NaN row would never recover
               (r >= rest && !(detail::finite_point(&sample_mean[3 * (r - rest)]) && detail::finite_point(ls)));
      if (after_reset) {
        p = p || max_scale(ls) > big_limit;
        if (screen) p = p || double(radius[r]) > cfg_.prune_scale2d;
      }
      prune_flag[r] = p;
    }
    std::vector<bool> prune(grown, false);
    for (std::size_t r = 0; r < grown; ++r) {
      prune[r] = prune_flag[r] != 0;
      counts.pruned += prune_flag[r];
    }
    const RefinePlan p_prune = RefinePlan::remove(prune);
    // grown_row[f]: the row of the grown set that output row f holds.
    std::vector<std::uint32_t> grown_row = p_prune.source;

    // ---- spatial order of the result, from the means it will have ----
    if (reorders_at(step)) {
      const std::size_t m = p_prune.size();
      std::vector<S> out_mean(3 * m);
      for (std::size_t f = 0; f < m; ++f) {
        const std::size_t r = grown_row[f];
        const S* src = r < rest ? &model.means[3 * std::size_t(plan.source[r])] : &sample_mean[3 * (r - rest)];
        std::copy_n(src, 3, &out_mean[3 * f]);
      }
      const std::vector<std::uint32_t> order = order_by_code(morton_codes(out_mean.data(), m));
      for (std::size_t f = 0; f < m; ++f) grown_row[f] = p_prune.source[order[f]];
    } else if (cfg_.reorder_every > 0) {
      // Between the sorts every surviving Gaussian stays in its row, the new ones take the rows
      // of the removed ones, and only what is left over moves to the end or into the remaining
      // gaps (Gaussians with equal means keep their relative order, the one thing a row's place
      // decides: fill_removed_rows). A refinement then writes the rows that change instead of
      // every row of the model and of both moments.
      const auto mean_of = [&](std::uint32_t r) {
        return r < rest ? &model.means[3 * std::size_t(plan.source[r])] : &sample_mean[3 * (r - rest)];
      };
      grown_row = fill_removed_rows(grown_row, plan, rest, mean_of);
    }
    RefinePlan p_out = p_prune;  // the kept rows of the grown set, in output order
    p_out.source = grown_row;
    plan = plan.then(p_out);

    // ---- apply once, then place the split samples' means and scales ----
    apply_spared(plan, model, false, "apply(model)");
    for (std::size_t f = 0; f < grown_row.size(); ++f) {
      const std::size_t r = grown_row[f];
      if (r < rest) continue;
      std::copy_n(&sample_mean[3 * (r - rest)], 3, &model.means[3 * f]);
      std::copy_n(&sample_log_scale[3 * (r - rest)], 3, &model.log_scales[3 * f]);
    }

    stats_.reset(model.size());
    return plan;
  }

  /// Clamp every opacity to at most config().reset_opacity (the logit is stored; NaN becomes the
  /// cap) and zero the opacity entries of the given optimiser states.
  template <class G, class S, class... States>
  void reset_opacity(GaussianModel<G, S>& model, States&... states) {
    const double v = cfg_.reset_opacity;
    const S cap = static_cast<S>(std::log(v / (1.0 - v)));
    for (auto& l : model.opacity_logits)
      if (!(l <= cap)) l = cap;
    (zero_all(states.opacity_logits), ...);
  }

 private:
  /// Keep only as many growth candidates as fit under max_gaussians: a duplicate adds one
  /// Gaussian, a split split_samples - 1, a Gaussian both duplicated and split split_samples.
  /// Candidates are taken by decreasing average gradient (index order among equals), so the
  /// choice is deterministic and independent of thread count.
  template <class G, class S>
  void limit_growth(const GaussianModel<G, S>& model, std::vector<bool>& dup, std::vector<bool>& split) const {
    const std::size_t n = model.size();
    const std::size_t per_split = static_cast<std::size_t>(cfg_.split_samples) - 1;
    auto growth_of = [&](std::size_t i) { return (dup[i] ? 1u : 0u) + (split[i] ? per_split : 0u); };
    std::size_t want = 0;
    std::vector<std::size_t> cand;
    for (std::size_t i = 0; i < n; ++i)
      if (dup[i] || split[i]) {
        cand.push_back(i);
        want += growth_of(i);
      }
    const std::size_t budget = n >= cfg_.max_gaussians ? 0 : cfg_.max_gaussians - n;
    if (want <= budget) return;
    // Equal gradients are ordered by the Gaussians' values, not their rows (content_key), so that
    // the choice does not depend on the row order (only bit-identical Gaussians stay in row order).
    std::vector<std::uint64_t> key(cand.size());
    const std::ptrdiff_t nc = static_cast<std::ptrdiff_t>(cand.size());
#pragma omp parallel for schedule(static, 64)
    for (std::ptrdiff_t j = 0; j < nc; ++j) key[std::size_t(j)] = content_key(model, cand[std::size_t(j)]);
    std::vector<std::size_t> order(cand.size());
    for (std::size_t j = 0; j < order.size(); ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      const auto ga = stats_.max_average(cand[a]), gb = stats_.max_average(cand[b]);
      return ga != gb ? ga > gb : key[a] < key[b];
    });
    for (std::size_t& j : order) j = cand[j];
    cand.swap(order);
    std::size_t used = 0;
    for (std::size_t i : cand) {
      const std::size_t g = growth_of(i);
      if (used + g <= budget) {
        used += g;
      } else {
        dup[i] = false;
        split[i] = false;
      }
    }
  }

  /// The kept rows of a grown set (`kept`, ascending rows of the set `grown` = p_dup.then(p_split),
  /// whose first `rest` rows are the unsplit ones) in an output order that moves few rows: a
  /// surviving Gaussian (not fresh, input row s) takes output row s when there is one; the rest
  /// (new Gaussians, and survivors whose row is past the end) fill the free rows in ascending
  /// order, in the order of `kept`.
  ///
  /// Gaussians whose means are bit-identical (a copy and its source until either moves) blend in
  /// row order at their common depth (RasterOptions::ties_by_mean), and their optimiser states
  /// differ: their order is the one thing a row's place decides. Within every such group the rows
  /// are therefore handed out in the order of `kept`, which is the order gsplat's row order gives
  /// them (a group's earlier rows keep their order in every refinement and in the stable spatial
  /// sort). So the result holds the same Gaussians, bit for bit, as with gsplat's order.
  /// `mean_of(r)`: the mean grown row r will have. A function of the plan and the means only, so
  /// the thread count changes nothing.
  template <class MeanOf>
  static std::vector<std::uint32_t> fill_removed_rows(const std::vector<std::uint32_t>& kept, const RefinePlan& grown,
                                                      std::size_t rest, const MeanOf& mean_of) {
    const std::size_t m = kept.size();
    std::vector<std::uint32_t> out(m, RefinePlan::none), movers;
    for (const std::uint32_t r : kept) {
      const std::uint32_t s = grown.source[r];
      if (r < rest && !grown.fresh[r] && s < m) out[s] = r;
      else movers.push_back(r);
    }
    std::size_t j = 0;
    for (std::size_t f = 0; f < m; ++f)
      if (out[f] == RefinePlan::none) out[f] = movers[j++];
    // Groups of bit-identical means that hold a row that moved (only those can have changed their
    // order): an open-addressing table of the movers' means, then one pass over every row.
    using Mean = std::remove_cvref_t<decltype(*mean_of(0u))>;
    constexpr std::size_t B = 3 * sizeof(Mean);
    const auto hash = [](const Mean* p) {
      unsigned char bytes[B];
      std::memcpy(bytes, p, B);
      std::uint64_t h = 0x6d73677368617368ULL;
      for (std::size_t k = 0; k < B; k += 4) {
        std::uint32_t word = 0;
        std::memcpy(&word, bytes + k, 4);
        h = (h ^ word) * 0x9e3779b97f4a7c15ULL;
      }
      return h ^ (h >> 29);
    };
    std::size_t slots = 16;
    while (slots < 2 * movers.size()) slots *= 2;
    std::vector<std::uint32_t> table(slots, RefinePlan::none);  // a mover's row per used slot
    const auto find = [&](const Mean* p) {
      std::size_t at = hash(p) & (slots - 1);
      while (table[at] != RefinePlan::none && std::memcmp(mean_of(table[at]), p, B) != 0) at = (at + 1) & (slots - 1);
      return at;
    };
    for (const std::uint32_t r : movers) {
      const std::size_t at = find(mean_of(r));
      if (table[at] == RefinePlan::none) table[at] = r;
    }
    // Each row's slot, in parallel (the table is only read from here on); kNoSlot where its mean
    // is no mover's, as for most rows, which the serial pass below then skips.
    constexpr std::size_t kNoSlot = std::numeric_limits<std::size_t>::max();
    std::vector<std::size_t> slot(m);
    const std::ptrdiff_t sm = static_cast<std::ptrdiff_t>(m);
#pragma omp parallel for schedule(static, 4096)
    for (std::ptrdiff_t ff = 0; ff < sm; ++ff) {
      const std::size_t at = find(mean_of(out[std::size_t(ff)]));
      slot[std::size_t(ff)] = table[at] == RefinePlan::none ? kNoSlot : at;
    }
    // Members of each slot's group, in ascending output rows (a linked list through `next`).
    std::vector<std::uint32_t> first(slots, RefinePlan::none), last(slots, RefinePlan::none), next(m, RefinePlan::none);
    std::vector<std::uint32_t> used;  // slots with two or more members
    for (std::size_t f = 0; f < m; ++f) {
      const std::size_t at = slot[f];
      if (at == kNoSlot) continue;
      if (first[at] == RefinePlan::none) {
        first[at] = std::uint32_t(f);
      } else {
        if (first[at] == last[at]) used.push_back(std::uint32_t(at));
        next[last[at]] = std::uint32_t(f);
      }
      last[at] = std::uint32_t(f);
    }
    std::vector<std::uint32_t> group;
    for (const std::uint32_t at : used) {  // the group's places, ascending, get its rows in order
      group.clear();
      for (std::uint32_t f = first[at]; f != RefinePlan::none; f = next[f]) group.push_back(out[f]);
      std::sort(group.begin(), group.end());
      std::size_t k = 0;
      for (std::uint32_t f = first[at]; f != RefinePlan::none; f = next[f]) out[f] = group[k++];
    }
    return out;
  }

  bool paused_at(long long step) const { return cfg_.pause_begin < step && step <= cfg_.pause_end; }

  template <class T>
  static void zero_all(std::vector<T>& v) { std::fill(v.begin(), v.end(), T(0)); }

  template <class S>
  static double max_scale(const S* log_scale) {
    return std::exp(std::max({double(log_scale[0]), double(log_scale[1]), double(log_scale[2])}));
  }
  template <class G, class S>
  static double max_scale(const GaussianModel<G, S>& m, std::size_t i) { return max_scale(&m.log_scales[3 * i]); }

  /// Whether every parameter of each row is finite: [N] flags, 1 = finite. A pass per array and
  /// per band plane, each read in order without an early exit, so that it streams the model.
  template <class G, class S>
  static std::vector<std::uint8_t> rows_finite(const GaussianModel<G, S>& m) {
    const std::size_t n = m.size();
    std::vector<std::uint8_t> ok(n, 1);
    // Non-finite values are rare: each array is scanned a block of rows at a time by an OR of
    // exponent tests, which vectorises (std::isfinite per value and an AND per row did not, and
    // this pass reads the whole model at every refinement), and only a block that holds one is
    // looked at row by row.
    using Bits = std::conditional_t<sizeof(S) == 4, std::uint32_t, std::uint64_t>;
    static_assert(sizeof(Bits) == sizeof(S) && std::numeric_limits<S>::is_iec559);
    constexpr Bits kExponent = sizeof(S) == 4 ? Bits(0x7f800000u) : Bits(0x7ff0000000000000ull);
    constexpr std::size_t kBlockRows = 256;
    const std::ptrdiff_t blocks = static_cast<std::ptrdiff_t>((n + kBlockRows - 1) / kBlockRows);
    constexpr std::size_t K = static_cast<std::size_t>(G::sh_coeffs);
#pragma omp parallel
    {
      // Rows [0, n) of an array whose row i is the `width` values from base + width i.
      const auto scan = [&](const S* base, std::size_t width) {
#pragma omp for schedule(static)
        for (std::ptrdiff_t b = 0; b < blocks; ++b) {
          const std::size_t r0 = std::size_t(b) * kBlockRows, r1 = std::min(n, r0 + kBlockRows);
          const S* v = base + r0 * width;
          Bits bad = 0;
          for (std::size_t k = 0, e = (r1 - r0) * width; k < e; ++k) {
            Bits u;
            std::memcpy(&u, v + k, sizeof u);
            bad |= Bits((u & kExponent) == kExponent);  // infinity or NaN
          }
          if (bad == 0) continue;
          for (std::size_t i = r0; i < r1; ++i)
            for (std::size_t k = 0; k < width; ++k)
              if (!std::isfinite(base[i * width + k])) ok[i] = 0;
        }
      };
      scan(m.means.data(), 3);
      scan(m.log_scales.data(), 3);
      scan(m.quats.data(), 4);
      scan(m.opacity_logits.data(), 1);
      for (int c = 0; c < G::bands; ++c) scan(m.sh_row(0, c), K);
    }
    return ok;
  }

  /// What a split sample's random draw is keyed by instead of the row: a hash of the bits of
  /// everything a sample inherits from its parent (mean, log-scales, rotation, opacity, colour). A permutation of the rows (the
  /// spatial order) then changes no draw, so a run with reordering takes the same course as one
  /// without (split_draw_keys separates Gaussians of identical geometry).
  template <class G, class S>
  static std::uint64_t content_key(const GaussianModel<G, S>& m, std::size_t i) {
    std::uint64_t h = 0x6d73677373706c74ULL;
    const auto mix = [&h](const S* p, std::size_t n) {
      for (std::size_t j = 0; j < n; ++j) {
        std::uint64_t bits = 0;
        std::memcpy(&bits, p + j, sizeof(S));
        h = detail::sched_mix(h ^ bits);
      }
    };
    mix(&m.means[3 * i], 3);
    mix(&m.log_scales[3 * i], 3);
    mix(&m.quats[4 * i], 4);
    mix(&m.opacity_logits[i], 1);
    for (int c = 0; c < G::bands; ++c) mix(m.sh_row(i, c), static_cast<std::size_t>(G::sh_coeffs));
    return h;
  }

  /// The key of each split parent's draws (rows `sel`): its content_key, and among parents with
  /// the same content (copies that have not moved yet) its rank in row order. Identical parents
  /// then still draw independent samples, and since they are identical, which of them takes
  /// which draw does not show in the result.
  template <class G, class S>
  static std::vector<std::uint64_t> split_draw_keys(const GaussianModel<G, S>& model, const std::vector<std::size_t>& sel) {
    std::vector<std::uint64_t> key(sel.size());
    const std::ptrdiff_t ns = static_cast<std::ptrdiff_t>(sel.size());
#pragma omp parallel for schedule(static, 64)
    for (std::ptrdiff_t j = 0; j < ns; ++j) key[std::size_t(j)] = content_key(model, sel[std::size_t(j)]);
    std::vector<std::size_t> order(sel.size());
    for (std::size_t j = 0; j < order.size(); ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] < key[b]; });
    std::vector<std::uint64_t> out(sel.size());
    std::uint64_t rank = 0;
    for (std::size_t q = 0; q < order.size(); ++q) {
      rank = q > 0 && key[order[q]] == key[order[q - 1]] ? rank + 1 : 0;
      out[order[q]] = detail::sched_mix(key[order[q]] ^ detail::sched_mix(rank));
    }
    return out;
  }

  /// Offset of split sample k of row i: R (s * z) with z ~ N(0, I) in the Gaussian's local frame,
  /// z drawn from (seed, step, `who` = the parent's split_draw_keys entry, sample, axis).
  template <class G, class S>
  void sample_offset(const GaussianModel<G, S>& m, std::size_t i, std::uint64_t who, long long step, int k,
                     double* out) const {
    double q[4] = {double(m.quats[4 * i]), double(m.quats[4 * i + 1]), double(m.quats[4 * i + 2]), double(m.quats[4 * i + 3])};
    const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(qn > 1e-12) || !std::isfinite(qn)) {
      q[0] = 1; q[1] = q[2] = q[3] = 0;  // degenerate rotation: sample axis-aligned
    } else {
      for (double& c : q) c /= qn;
    }
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    double local[3];
    for (int a = 0; a < 3; ++a) {
      // Clamped exponent: an absurd log-scale still gives a finite (if useless) sample.
      const double s = std::exp(std::min(double(m.log_scales[3 * i + std::size_t(a)]), 30.0));
      const auto key = static_cast<std::uint64_t>(k * 3 + a);
      const double zn = detail::sched_normal(detail::sched_hash(cfg_.seed, 0xD5ULL, step, who, key, 0),
                                             detail::sched_hash(cfg_.seed, 0xD5ULL, step, who, key, 1));
      local[a] = std::isfinite(s) ? s * zn : 0.0;
    }
    for (int r = 0; r < 3; ++r) out[r] = R[r][0] * local[0] + R[r][1] * local[1] + R[r][2] * local[2];
  }

  /// Memory the arrays of a refinement are gathered into (detail::gather_rows), kept from one
  /// refinement to the next and released after the last step before refine_stop; a copy of the
  /// controller starts without it.
  template <class T>
  struct Spare {
    std::vector<T> planes;                    // the band planes
    detail::GeometrySpares<T> geometry;       // the other arrays, by row width
    Spare() = default;
    Spare(const Spare&) {}
    Spare& operator=(const Spare&) { return *this; }
    Spare(Spare&&) = default;
    Spare& operator=(Spare&&) = default;
  };
  Spare<float> spare_float_;
  Spare<double> spare_double_;

  /// detail::apply_arrays through the spares of S (in place for other scalar types).
  template <class G, class S>
  void apply_spared(const RefinePlan& plan, GaussianModel<G, S>& arrays, bool zero_fresh, const char* what) {
    if constexpr (std::is_same_v<S, float> || std::is_same_v<S, double>) {
      Spare<S>& sp = [this]() -> Spare<S>& {
        if constexpr (std::is_same_v<S, float>) return spare_float_;
        else return spare_double_;
      }();
      detail::apply_arrays(plan, arrays, zero_fresh, &sp.planes, what, &sp.geometry);
    } else {
      detail::apply_arrays(plan, arrays, zero_fresh, nullptr, what);
    }
  }

  /// Optimiser state follows the plan (zeros for new rows), through the spares.
  template <class G, class T>
  void apply_state(const RefinePlan& plan, GaussianModel<G, T>& state) {
    apply_spared(plan, state, true, "apply_zero_fresh(state)");
  }

  DensifyConfig cfg_;
  int num_bands_ = 1;
  double scene_scale_ = 1.0;
  int pause_after_reset_ = 0;
  DensityStats stats_;
};

}  // namespace msgs
