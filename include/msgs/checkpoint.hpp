// include/msgs/checkpoint.hpp
// Training checkpoints: everything a run needs to continue bit for bit (model, Adam moments and
// counters, densification statistics, the next step; the per-image exposure corrections and their
// Adam state when the run learns them) in one little-endian binary file, written
// atomically so an interrupted write never replaces a good checkpoint.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "adam.hpp"
#include "densify.hpp"
#include "exposure.hpp"
#include "gaussian.hpp"
#include "io/file.hpp"

namespace msgs {

/// The state of one model's training at a step boundary.
template <class G>
struct TrainState {
  long long step = 0;                 ///< the next step to run
  GaussianModel<G, float> model;
  GaussianModel<G, float> exp_avg, exp_avg_sq;
  typename Adam<G, float>::Steps adam_steps{};
  std::int64_t adam_iteration = 0;
  int stats_bands = 1;
  std::vector<float> stats_grad;          // [N, B]
  std::vector<std::uint32_t> stats_count; // [N, B]
  std::vector<float> stats_radius;        // [N]
  ExposureState exposure;                 ///< per-image corrections (empty unless TrainOptions::exposure)
};

/// A TrainState's fields by reference: what save_checkpoint writes, taken straight from a live
/// trainer without copying its model and moments. Valid while the objects it refers to are.
template <class G>
struct TrainStateView {
  long long step = 0;
  const GaussianModel<G, float>* model = nullptr;
  const GaussianModel<G, float>* exp_avg = nullptr;
  const GaussianModel<G, float>* exp_avg_sq = nullptr;
  typename Adam<G, float>::Steps adam_steps{};
  std::int64_t adam_iteration = 0;
  int stats_bands = 1;
  const std::vector<float>* stats_grad = nullptr;
  const std::vector<std::uint32_t>* stats_count = nullptr;
  const std::vector<float>* stats_radius = nullptr;
  const ExposureState* exposure = nullptr;  ///< nullptr or empty: no exposure section

  static TrainStateView of(const TrainState<G>& st) {
    return {st.step,        &st.model,      &st.exp_avg,     &st.exp_avg_sq,   st.adam_steps, st.adam_iteration,
            st.stats_bands, &st.stats_grad, &st.stats_count, &st.stats_radius, &st.exposure};
  }
};

namespace detail {

/// Version 2 stores SH in band planes [Bands, N, K]; version 1 (before 2026-11) stored [N, K, Bands]
/// and still loads (transposed on reading).
inline constexpr char kCheckpointMagic[8] = {'M', 'S', 'G', 'S', 'C', 'K', 'P', '2'};
inline constexpr char kCheckpointMagicV1[8] = {'M', 'S', 'G', 'S', 'C', 'K', 'P', '1'};
/// Optional section after the densification statistics, present only when the run learns exposure
/// corrections (exposure.hpp); its tag carries its own version. Checkpoints without it (every run
/// without exposure, every older file) end right after the statistics, as before.
inline constexpr char kExposureSectionTag[8] = {'E', 'X', 'P', 'O', 'S', 'R', 'E', '1'};

/// Writes the fields straight to the file: a checkpoint (the model and both Adam moments) is
/// never assembled in memory, which would double what a save needs at its peak.
class CkptWriter {
 public:
  explicit CkptWriter(std::ostream& out) : out_(out) {}
  template <class T>
  void pod(const T& v) { out_.write(reinterpret_cast<const char*>(&v), sizeof(T)); }
  template <class T>
  void vec(const std::vector<T>& v) {
    pod(std::uint64_t(v.size()));
    if (!v.empty()) bytes(v.data(), v.size() * sizeof(T));
  }
  void bytes(const void* p, std::size_t n) { out_.write(static_cast<const char*>(p), std::streamsize(n)); }

 private:
  std::ostream& out_;
};

class CkptReader {
 public:
  CkptReader(std::vector<unsigned char> bytes, std::filesystem::path path) : b_(std::move(bytes)), path_(std::move(path)) {}
  template <class T>
  T pod(const char* field) {
    need(sizeof(T), field);
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  template <class T>
  std::vector<T> vec(const char* field, std::uint64_t expected) {
    const auto n = pod<std::uint64_t>(field);
    if (n != expected)
      fail(field, "has " + std::to_string(n) + " values, expected " + std::to_string(expected));
    need(n * sizeof(T), field);
    std::vector<T> v(n);
    if (n) std::memcpy(v.data(), b_.data() + pos_, n * sizeof(T));
    pos_ += n * sizeof(T);
    return v;
  }
  /// The next value without consuming it.
  template <class T>
  T peek(const char* field) const {
    need(sizeof(T), field);
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    return v;
  }
  [[noreturn]] void fail(const char* field, const std::string& what) const {
    throw std::runtime_error("checkpoint " + path_.string() + ": field '" + field + "' " + what);
  }
  bool at_end() const { return pos_ == b_.size(); }
  std::size_t remaining() const { return b_.size() - pos_; }

 private:
  void need(std::uint64_t n, const char* field) const {
    if (n > b_.size() - pos_) fail(field, "is truncated");
  }
  std::vector<unsigned char> b_;
  std::size_t pos_ = 0;
  std::filesystem::path path_;
};

template <class G>
void write_model(CkptWriter& w, const GaussianModel<G, float>& m) {
  w.vec(m.means); w.vec(m.log_scales); w.vec(m.quats); w.vec(m.opacity_logits);
  // The band planes with N rows each, whatever their capacity: [Bands, N, K].
  const std::size_t n = m.size(), K = std::size_t(G::sh_coeffs);
  w.pod(std::uint64_t(n * std::size_t(G::sh_floats)));
  for (int c = 0; c < G::bands; ++c)
    if (n > 0) w.bytes(m.sh_row(0, c), n * K * sizeof(float));
}

/// `sh_interleaved`: a version-1 file, SH [N, K, Bands].
template <class G>
GaussianModel<G, float> read_model(CkptReader& r, std::uint64_t n, bool sh_interleaved) {
  GaussianModel<G, float> m;
  m.means = r.vec<float>("means", 3 * n);
  m.log_scales = r.vec<float>("log_scales", 3 * n);
  m.quats = r.vec<float>("quats", 4 * n);
  m.opacity_logits = r.vec<float>("opacity_logits", n);
  m.sh = r.vec<float>("sh", n * std::uint64_t(G::sh_floats));
  if (sh_interleaved && G::bands > 1) {
    const std::vector<float> old = std::move(m.sh);
    m.sh.assign(old.size(), 0.0f);
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < G::sh_coeffs; ++k)
        for (int c = 0; c < G::bands; ++c) m.sh_at(i, k, c) = old[(i * G::sh_coeffs + std::size_t(k)) * G::bands + std::size_t(c)];
  }
  return m;
}

/// What each value of a checkpoint may hold: the model's parameters are finite (the PLY writer
/// refuses anything else), Adam's moments and the statistics are not NaN, and second moments,
/// gradient norms and radii are not negative. A file of the right length that breaks this is
/// damaged (a bit flipped on disk, bytes overwritten) and would train on garbage.
enum class ValueRule { finite, not_nan, not_nan_nonneg };

inline void check_values(const CkptReader& r, const char* field, const std::vector<float>& v, ValueRule rule) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    const float x = v[i];
    const bool ok = rule == ValueRule::finite ? std::isfinite(x) : rule == ValueRule::not_nan ? !std::isnan(x) : x >= 0.0f;
    if (!ok)
      r.fail(field, "holds " + std::to_string(x) + " at value " + std::to_string(i) +
                        ", which training never writes: the file is damaged; resume from another checkpoint or "
                        "train afresh without --resume");
  }
}

template <class G>
void check_model_values(const CkptReader& r, const GaussianModel<G, float>& m, ValueRule rule) {
  check_values(r, "means", m.means, rule);
  check_values(r, "log_scales", m.log_scales, rule);
  check_values(r, "quats", m.quats, rule);
  check_values(r, "opacity_logits", m.opacity_logits, rule);
  check_values(r, "sh", m.sh, rule);
}

inline void check_count(const CkptReader& r, const char* field, std::int64_t v) {
  if (v < 0) r.fail(field, "is negative (" + std::to_string(v) + "): the file is damaged");
}

}  // namespace detail

/// Write `st` to `path` atomically (a temporary beside it, renamed when complete).
template <class G>
void save_checkpoint(const std::filesystem::path& path, const TrainStateView<G>& st) {
  if (!st.model || !st.exp_avg || !st.exp_avg_sq || !st.stats_grad || !st.stats_count || !st.stats_radius)
    throw std::invalid_argument("save_checkpoint: the state view of " + path.string() + " is missing a field");
  const bool exposure = st.exposure && !st.exposure->empty();
  if (exposure) st.exposure->validate("save_checkpoint");  // before anything is written
  io::write_stream_atomic(path, [&](std::ostream& out) {
    detail::CkptWriter w(out);
    for (char c : detail::kCheckpointMagic) w.pod(c);
    w.pod(std::int32_t(G::bands));
    w.pod(std::int32_t(G::sh_degree));
    w.pod(std::int64_t(st.step));
    w.pod(std::uint64_t(st.model->size()));
    detail::write_model(w, *st.model);
    detail::write_model(w, *st.exp_avg);
    detail::write_model(w, *st.exp_avg_sq);
    w.pod(std::int64_t(st.adam_steps.means));
    w.pod(std::int64_t(st.adam_steps.scales));
    w.pod(std::int64_t(st.adam_steps.quats));
    w.pod(std::int64_t(st.adam_steps.opacities));
    for (auto s : st.adam_steps.sh) w.pod(std::int64_t(s));
    w.pod(std::int64_t(st.adam_iteration));
    w.pod(std::int32_t(st.stats_bands));
    w.vec(*st.stats_grad);
    w.vec(*st.stats_count);
    w.vec(*st.stats_radius);
    if (exposure) {
      const ExposureState& e = *st.exposure;
      for (char c : detail::kExposureSectionTag) w.pod(c);
      w.vec(e.frames);
      w.vec(e.channels);
      w.vec(e.log_gain);
      w.vec(e.offset);
      w.vec(e.m_log_gain);
      w.vec(e.v_log_gain);
      w.vec(e.m_offset);
      w.vec(e.v_offset);
      w.vec(e.steps);
    }
  });
}

template <class G>
void save_checkpoint(const std::filesystem::path& path, const TrainState<G>& st) {
  save_checkpoint(path, TrainStateView<G>::of(st));
}

/// Read a checkpoint written by save_checkpoint for the same Gaussian type.
template <class G>
TrainState<G> load_checkpoint(const std::filesystem::path& path) {
  detail::CkptReader r(io::read_bytes(path), path);
  char magic[8];
  for (char& c : magic) c = r.pod<char>("magic");
  const bool v1 = std::equal(magic, magic + 8, detail::kCheckpointMagicV1);
  if (!v1 && !std::equal(magic, magic + 8, detail::kCheckpointMagic))
    r.fail("magic", "is not MSGSCKP2 or MSGSCKP1 (not an msgs checkpoint, or one from a newer msgs)");
  const auto bands = r.pod<std::int32_t>("bands");
  const auto deg = r.pod<std::int32_t>("sh_degree");
  if (bands != G::bands || deg != G::sh_degree)
    r.fail("bands", "describes Gaussian<" + std::to_string(bands) + ", " + std::to_string(deg) + ">, expected Gaussian<" +
                        std::to_string(G::bands) + ", " + std::to_string(G::sh_degree) + ">");
  TrainState<G> st;
  st.step = r.pod<std::int64_t>("step");
  const auto n = r.pod<std::uint64_t>("gaussians");
  if (n > (std::uint64_t(1) << 34)) r.fail("gaussians", "is implausibly large");
  st.model = detail::read_model<G>(r, n, v1);
  st.exp_avg = detail::read_model<G>(r, n, v1);
  st.exp_avg_sq = detail::read_model<G>(r, n, v1);
  st.adam_steps.means = r.pod<std::int64_t>("adam_steps");
  st.adam_steps.scales = r.pod<std::int64_t>("adam_steps");
  st.adam_steps.quats = r.pod<std::int64_t>("adam_steps");
  st.adam_steps.opacities = r.pod<std::int64_t>("adam_steps");
  for (auto& s : st.adam_steps.sh) s = r.pod<std::int64_t>("adam_steps");
  st.adam_iteration = r.pod<std::int64_t>("adam_iteration");
  st.stats_bands = r.pod<std::int32_t>("stats_bands");
  if (st.stats_bands < 1 || st.stats_bands > 64) r.fail("stats_bands", "is out of range");
  st.stats_grad = r.vec<float>("stats_grad", n * std::uint64_t(st.stats_bands));
  st.stats_count = r.vec<std::uint32_t>("stats_count", n * std::uint64_t(st.stats_bands));
  st.stats_radius = r.vec<float>("stats_radius", n);
  detail::check_count(r, "step", st.step);
  detail::check_model_values(r, st.model, detail::ValueRule::finite);
  detail::check_model_values(r, st.exp_avg, detail::ValueRule::not_nan);
  detail::check_model_values(r, st.exp_avg_sq, detail::ValueRule::not_nan_nonneg);
  for (const std::int64_t k : {st.adam_steps.means, st.adam_steps.scales, st.adam_steps.quats, st.adam_steps.opacities})
    detail::check_count(r, "adam_steps", k);
  for (const auto k : st.adam_steps.sh) detail::check_count(r, "adam_steps", std::int64_t(k));
  detail::check_count(r, "adam_iteration", st.adam_iteration);
  detail::check_values(r, "stats_grad", st.stats_grad, detail::ValueRule::not_nan_nonneg);
  detail::check_values(r, "stats_radius", st.stats_radius, detail::ValueRule::not_nan_nonneg);
  if (!r.at_end()) {
    // Anything after the statistics must be the exposure section; else it is trailing garbage.
    if (r.remaining() < sizeof detail::kExposureSectionTag) r.fail("end", "has trailing bytes");
    char tag[8];
    for (char& c : tag) c = r.pod<char>("exposure");
    if (!std::equal(tag, tag + 8, detail::kExposureSectionTag))
      r.fail("end", "has trailing bytes (not an exposure section EXPOSRE1)");
    ExposureState& e = st.exposure;
    const auto frames = r.peek<std::uint64_t>("exposure_frames");
    if (frames == 0 || frames > (std::uint64_t(1) << 32)) r.fail("exposure_frames", "is out of range");
    e.frames = r.vec<std::uint64_t>("exposure_frames", frames);
    e.channels = r.vec<std::int32_t>("exposure_channels", frames);
    std::uint64_t values = 0;
    for (auto c : e.channels) {
      if (c < 1 || c > 8) r.fail("exposure_channels", "holds a channel count outside 1..8");
      values += std::uint64_t(c);
    }
    e.log_gain = r.vec<float>("exposure_log_gain", values);
    e.offset = r.vec<float>("exposure_offset", values);
    e.m_log_gain = r.vec<float>("exposure_m_log_gain", values);
    e.v_log_gain = r.vec<float>("exposure_v_log_gain", values);
    e.m_offset = r.vec<float>("exposure_m_offset", values);
    e.v_offset = r.vec<float>("exposure_v_offset", values);
    e.steps = r.vec<std::int64_t>("exposure_steps", frames);
    try {
      e.validate("checkpoint " + path.string());
    } catch (const std::runtime_error& err) {
      r.fail("exposure", std::string("is inconsistent: ") + err.what());
    }
    if (!r.at_end()) r.fail("end", "has trailing bytes");
  }
  return st;
}

}  // namespace msgs
