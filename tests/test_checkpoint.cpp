// tests/test_checkpoint.cpp
// Checkpoints and determinism: a run on one thread stopped at step k, saved, loaded into a fresh
// trainer and continued ends bit for bit where the uninterrupted run on two threads ends (model,
// Adam state, densification statistics); the file format refuses the wrong model type,
// truncation and trailing bytes.
#include <doctest/doctest.h>

#include "fixtures.hpp"
#include "shared_trainers.hpp"  // Trainer<G>, compiled once for the tests that drive it

#include <msgs/checkpoint.hpp>
#include <msgs/run.hpp>
#include <msgs/synth.hpp>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <tuple>

#include <omp.h>

namespace test_checkpoint {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

using G = Gaussian<7, 1>;

fs::path scratch() { return msgs::testing::scratch_dir("checkpoint"); }

const io::Dataset& tiny() { return msgs::testing::tiny_scene("checkpoint", 3); }

/// `reorder`: DensifyConfig::reorder_every (0: gsplat's row order).
Trainer<G> make_trainer(TrainOptions opt = {}, bool sparse = true, int reorder = 0) {
  opt.sparse = sparse;
  // Joint-Optimized at a scale where refinement, an opacity reset and SpecDelay all fall inside
  // the first 240 steps (refine every 6 from step 60, spectral bands from step 120; the strategies'
  // floor of 250 on the refinement start is lowered for that).
  StrategySpec s = parse_strategy("joint+specdelay+msad", ScheduleScale{0.004});
  s.plan.densify.refine_start = 60;
  s.plan.densify.reorder_every = reorder;
  RunConfig cfg;
  return Trainer<G>(tiny(), detail::run_bands(tiny(), {}), detail::initial_model<G>(tiny(), cfg), s.plan, s.hooks, opt);
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void check_same(const TrainState<G>& a, const TrainState<G>& b) {
  CHECK(a.step == b.step);
  CHECK(a.model.size() == b.model.size());
  CHECK(same_bits(a.model.means, b.model.means));
  CHECK(same_bits(a.model.log_scales, b.model.log_scales));
  CHECK(same_bits(a.model.quats, b.model.quats));
  CHECK(same_bits(a.model.opacity_logits, b.model.opacity_logits));
  CHECK(same_bits(a.model.sh, b.model.sh));
  CHECK(same_bits(a.exp_avg.sh, b.exp_avg.sh));
  CHECK(same_bits(a.exp_avg_sq.means, b.exp_avg_sq.means));
  CHECK(a.adam_iteration == b.adam_iteration);
  CHECK(a.adam_steps.sh == b.adam_steps.sh);
  CHECK(same_bits(a.stats_grad, b.stats_grad));
  CHECK(a.stats_count == b.stats_count);
}

constexpr long long kEnd = 240, kStop = 131;  // the stop falls between refinements

/// Sets the OpenMP thread count for its lifetime.
class Threads {
 public:
  explicit Threads(int n) : saved_(omp_get_max_threads()) { omp_set_num_threads(n); }
  ~Threads() { omp_set_num_threads(saved_); }
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;

 private:
  int saved_;
};

/// A run to kEnd on one thread, interrupted at kStop by the stop flag (as Ctrl-C does, the
/// checkpoint `name` written on the way out), then resumed from that checkpoint in a fresh trainer:
/// its end state. The cases compare it with the uninterrupted run on two threads, so one equality
/// shows both that a resumed run continues bit for bit and that the thread count changes no bit.
TrainState<G> interrupted_and_resumed(const std::string& name, bool sparse, int reorder) {
  const Threads one(1);
  const fs::path ckpt = scratch() / name;
  fs::remove(ckpt);
  std::atomic<bool> stop{false};
  TrainOptions opt;
  opt.checkpoint_path = ckpt;
  opt.stop = &stop;
  opt.progress_every = 1;
  opt.on_progress = [&](const TrainProgress& p) { if (p.step >= kStop) stop.store(true); };
  Trainer<G> first = make_trainer(opt, sparse, reorder);
  REQUIRE(first.train(0, kEnd) == kStop);
  REQUIRE(fs::exists(ckpt));
  Trainer<G> second = make_trainer({}, sparse, reorder);
  const long long at = second.restore(load_checkpoint<G>(ckpt));
  CHECK(at == kStop);
  REQUIRE(second.train(at, kEnd) == kEnd);
  return second.state(kEnd);
}

/// The end state of an uninterrupted run to kEnd on two threads (sparse or dense Adam,
/// reorder_every `reorder`). The cases compare several checks against the same runs, and a run
/// takes seconds (half a minute under the sanitizers), so each is trained once per process.
const TrainState<G>& straight_run(bool sparse, int reorder) {
  static std::map<std::tuple<bool, int>, TrainState<G>> done;
  const auto key = std::make_tuple(sparse, reorder);
  if (const auto it = done.find(key); it != done.end()) return it->second;
  const Threads two(2);
  Trainer<G> t = make_trainer({}, sparse, reorder);
  REQUIRE(t.train(0, kEnd) == kEnd);
  return done.emplace(key, t.state(kEnd)).first->second;
}

}  // namespace

// The cases that train with dense Adam have "(dense Adam)" in their names: ctest runs them as
// test_checkpoint_part2, beside the others, so that the two cores share the runs (see
// tests/CMakeLists.txt). Each process trains four runs of 240 steps.

TEST_CASE("a run stopped and resumed on one thread ends bit for bit as the run on two threads (sparse Adam)") {
  check_same(interrupted_and_resumed("sparse.ckpt", true, 0), straight_run(true, 0));
}

TEST_CASE("a run stopped and resumed on one thread ends bit for bit as the run on two threads (dense Adam)") {
  check_same(interrupted_and_resumed("dense.ckpt", false, 0), straight_run(false, 0));
}

TEST_CASE("sparse and dense Adam train differently") {
  CHECK_FALSE(same_bits(straight_run(true, 0).model.means, straight_run(false, 0).model.means));
}

TEST_CASE("with spatial reordering a run stopped and resumed on one thread ends as on two (dense Adam)") {
  constexpr int kReorder = 2;  // every second refinement: a sort every 12 steps
  const TrainState<G>& want = straight_run(false, kReorder);
  check_same(interrupted_and_resumed("reordered.ckpt", false, kReorder), want);
  // The sorts happened: consecutive rows are mostly in Morton order, unlike gsplat's row order.
  const auto descents = [](const GaussianModel<G, float>& m) {
    const std::vector<std::uint64_t> c = morton_codes(m.means.data(), m.size());
    std::size_t d = 0;
    for (std::size_t i = 1; i < c.size(); ++i) d += c[i] < c[i - 1];
    return d;
  };
  const std::size_t sorted_d = descents(want.model), plain_d = descents(straight_run(false, 0).model);
  INFO("descents: reordered ", sorted_d, ", gsplat order ", plain_d, " of ", want.model.size());
  CHECK(plain_d > 4 * sorted_d);
}

namespace {

/// Rows of a training state ordered by the bits of their values (geometry, colour, both Adam
/// moments): a canonical order, so that two states holding the same Gaussians in different rows
/// compare. (A copy that has not moved yet has its original's geometry; its moments differ.)
std::vector<std::size_t> canonical_rows(const TrainState<G>& st) {
  const auto key = [&st](std::size_t i) {
    std::vector<std::uint32_t> k;
    for (const GaussianModel<G, float>* m : {&st.model, &st.exp_avg, &st.exp_avg_sq}) {
      const auto add = [&k](const float* p, std::size_t n) {
        for (std::size_t j = 0; j < n; ++j) k.push_back(std::bit_cast<std::uint32_t>(p[j]));
      };
      add(&m->means[3 * i], 3);
      add(&m->log_scales[3 * i], 3);
      add(&m->quats[4 * i], 4);
      add(&m->opacity_logits[i], 1);
      for (int c = 0; c < G::bands; ++c) add(m->sh_row(i, c), std::size_t(G::sh_coeffs));
    }
    return k;
  };
  std::vector<std::size_t> rows(st.model.size());
  for (std::size_t i = 0; i < rows.size(); ++i) rows[i] = i;
  std::vector<std::vector<std::uint32_t>> keys(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) keys[i] = key(i);
  std::stable_sort(rows.begin(), rows.end(), [&](std::size_t a, std::size_t b) { return keys[a] < keys[b]; });
  return rows;
}

/// The rows `rows` of every per-Gaussian array of a training state, in that order.
TrainState<G> gathered(const TrainState<G>& st, const std::vector<std::size_t>& rows) {
  TrainState<G> out = st;
  const auto gather = [&rows](const std::vector<float>& from, std::vector<float>& to, std::size_t w) {
    for (std::size_t r = 0; r < rows.size(); ++r)
      for (std::size_t a = 0; a < w; ++a) to[r * w + a] = from[rows[r] * w + a];
  };
  const auto model = [&](const GaussianModel<G, float>& from, GaussianModel<G, float>& to) {
    gather(from.means, to.means, 3);
    gather(from.log_scales, to.log_scales, 3);
    gather(from.quats, to.quats, 4);
    gather(from.opacity_logits, to.opacity_logits, 1);
    for (std::size_t r = 0; r < rows.size(); ++r)
      for (int c = 0; c < G::bands; ++c)
        for (int k = 0; k < G::sh_coeffs; ++k) to.sh_at(r, k, c) = from.sh_at(rows[r], k, c);
  };
  model(st.model, out.model);
  model(st.exp_avg, out.exp_avg);
  model(st.exp_avg_sq, out.exp_avg_sq);
  gather(st.stats_grad, out.stats_grad, std::size_t(st.stats_bands));
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (int b = 0; b < st.stats_bands; ++b)
      out.stats_count[r * std::size_t(st.stats_bands) + std::size_t(b)] = st.stats_count[rows[r] * std::size_t(st.stats_bands) + std::size_t(b)];
  gather(st.stats_radius, out.stats_radius, 1);
  return out;
}

}  // namespace

namespace {

/// Split samples draw their offsets from the parent's geometry, not its row, and nothing else
/// depends on where a row is, so sorting changes the order of the rows and nothing else.
void check_reordering_moves_rows_only(bool sparse) {
  const TrainState<G>& a = straight_run(sparse, 0);
  const TrainState<G>& b = straight_run(sparse, 2);
  REQUIRE(a.model.size() == b.model.size());
  CHECK_FALSE(same_bits(a.model.means, b.model.means));  // the rows did move
  check_same(gathered(a, canonical_rows(a)), gathered(b, canonical_rows(b)));
}

}  // namespace

TEST_CASE("spatial reordering moves rows only: the run holds the same Gaussians as without it (sparse Adam)") {
  check_reordering_moves_rows_only(true);
}

TEST_CASE("spatial reordering moves rows only: the run holds the same Gaussians as without it (dense Adam)") {
  check_reordering_moves_rows_only(false);
}

TEST_CASE("a version-1 checkpoint (SH interleaved [N, K, Bands]) still loads, transposed into band planes") {
  Trainer<G> t = make_trainer();
  t.train(0, 20);
  const TrainState<G> st = t.state(20);
  const fs::path p = scratch() / "v2.ckpt";
  save_checkpoint(p, st);
  // Rewrite it as version 1: magic '1' and the three SH arrays interleaved.
  auto bytes = io::read_bytes(p);
  bytes[7] = '1';
  const std::size_t n = st.model.size(), F = std::size_t(G::sh_floats);
  std::size_t at = 32;  // magic, bands, degree, step, count
  for (const GaussianModel<G, float>* m : {&st.model, &st.exp_avg, &st.exp_avg_sq}) {
    at += (8 + 3 * n * 4) * 2 + (8 + 4 * n * 4) + (8 + n * 4) + 8;  // means, log_scales, quats, opacities, sh count
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < G::sh_coeffs; ++k)
        for (int c = 0; c < G::bands; ++c) {
          const float v = m->sh_at(i, k, c);
          std::memcpy(bytes.data() + at + ((i * G::sh_coeffs + std::size_t(k)) * G::bands + std::size_t(c)) * 4, &v, 4);
        }
    at += n * F * 4;
  }
  const fs::path v1 = scratch() / "v1.ckpt";
  io::write_bytes_atomic(v1, bytes.data(), bytes.size());
  check_same(load_checkpoint<G>(v1), st);
  CHECK(same_bits(load_checkpoint<G>(v1).exp_avg_sq.sh, st.exp_avg_sq.sh));
}

TEST_CASE("checkpoint files refuse the wrong model type, truncation and trailing bytes") {
  Trainer<G> t = make_trainer();
  t.train(0, 20);
  const fs::path p = scratch() / "small.ckpt";
  save_checkpoint(p, t.state(20));
  check_same(load_checkpoint<G>(p), t.state(20));
  // A trainer's checkpoint is written from a view of its live state, without a copy: the same bytes.
  const fs::path viewed = scratch() / "viewed.ckpt";
  save_checkpoint(viewed, t.state_view(20));
  CHECK(io::read_bytes(viewed) == io::read_bytes(p));
  TrainStateView<G> partial = t.state_view(20);
  partial.exp_avg = nullptr;
  CHECK_THROWS_WITH_AS(save_checkpoint(scratch() / "partial.ckpt", partial), doctest::Contains("missing a field"),
                       std::invalid_argument);
  CHECK_FALSE(fs::exists(scratch() / "partial.ckpt"));

  using Rgb = Gaussian<3, 1>;
  CHECK_THROWS_WITH_AS(load_checkpoint<Rgb>(p), doctest::Contains("expected Gaussian<3"), std::runtime_error);

  const auto bytes = io::read_bytes(p);
  const fs::path cut = scratch() / "cut.ckpt";
  io::write_bytes_atomic(cut, bytes.data(), bytes.size() - 7);
  CHECK_THROWS_WITH_AS(load_checkpoint<G>(cut), doctest::Contains("truncated"), std::runtime_error);

  auto longer = bytes;
  longer.push_back(0);
  const fs::path tail = scratch() / "tail.ckpt";
  io::write_bytes_atomic(tail, longer.data(), longer.size());
  CHECK_THROWS_WITH_AS(load_checkpoint<G>(tail), doctest::Contains("trailing"), std::runtime_error);

  // Damaged values in a file of the right length: a NaN mean, a negative second moment, a
  // negative step. Offsets: magic, bands, degree, step, count (32 bytes), then per model five
  // arrays, each a 64-bit count and its floats (Gaussian<7, 1>: 3 + 3 + 4 + 1 + 28 floats a row).
  {
    const std::size_t n = t.model().size(), model_bytes = 5 * 8 + 4 * n * (3 + 3 + 4 + 1 + 28);
    const auto damaged = [&](const char* name, std::size_t offset, const auto value) {
      auto b = bytes;
      std::memcpy(b.data() + offset, &value, sizeof value);
      const fs::path d = scratch() / name;
      io::write_bytes_atomic(d, b.data(), b.size());
      return d;
    };
    const fs::path nan_mean = damaged("nan_mean.ckpt", 40, std::numeric_limits<float>::quiet_NaN());
    CHECK_THROWS_WITH_AS(load_checkpoint<G>(nan_mean), doctest::Contains("field 'means' holds nan at value 0"), std::runtime_error);
    CHECK_THROWS_WITH_AS(load_checkpoint<G>(nan_mean), doctest::Contains("resume from another checkpoint"), std::runtime_error);
    const fs::path neg_v = damaged("neg_v.ckpt", 32 + 2 * model_bytes + 8 + 4, -1.0f);
    CHECK_THROWS_WITH_AS(load_checkpoint<G>(neg_v), doctest::Contains("field 'means' holds -1.0"), std::runtime_error);
    const fs::path neg_step = damaged("neg_step.ckpt", 16, std::int64_t(-5));
    CHECK_THROWS_WITH_AS(load_checkpoint<G>(neg_step), doctest::Contains("field 'step' is negative (-5)"), std::runtime_error);
    // The same place in the first moments may hold any number: -1 there loads.
    CHECK(load_checkpoint<G>(damaged("neg_m.ckpt", 32 + model_bytes + 8 + 4, -1.0f)).exp_avg.means[1] == -1.0f);
  }

  const fs::path junk = scratch() / "junk.ckpt";
  io::write_text_atomic(junk, "not a checkpoint at all");
  CHECK_THROWS_WITH_AS(load_checkpoint<G>(junk), doctest::Contains("magic"), std::runtime_error);

  // A save that cannot write says where and why, and leaves the old checkpoint as it was.
  const fs::path nowhere = scratch() / "no_such_folder" / "x.ckpt";
  CHECK_THROWS_WITH_AS(save_checkpoint(nowhere, t.state(20)), doctest::Contains("cannot open for writing"),
                       std::runtime_error);
  CHECK_FALSE(fs::exists(nowhere.parent_path()));
  TrainState<G> bad = t.state(20);
  bad.exposure.frames = {0};  // an exposure section whose arrays do not match
  CHECK_THROWS_AS(save_checkpoint(p, bad), std::runtime_error);
  CHECK(io::read_bytes(p) == bytes);
  for (const auto& e : fs::directory_iterator(p.parent_path()))
    CHECK(e.path().filename().string().find(".tmp-") == std::string::npos);
}

}  // namespace test_checkpoint
