// tests/test_adam.cpp
// Checks adam.hpp against hand-computed Adam updates, and that masked groups and SH bands stay untouched.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdint>
#include <cstring>
#include <random>
#include <vector>

#include "msgs/adam.hpp"

namespace test_adam {
namespace {

using G7 = msgs::Gaussian<7, 1>;
using Model = msgs::GaussianModel<G7, float>;

using ModelD = msgs::GaussianModel<G7, double>;

template <class S>
void fill_random(msgs::GaussianModel<G7, S>& m, std::uint32_t seed, float lo, float hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<S> u(lo, hi);
  for (auto* v : {&m.means, &m.log_scales, &m.quats, &m.opacity_logits, &m.sh})
    for (auto& x : *v) x = u(rng);
}

/// Textbook Adam for one scalar, in double, from its own history of gradients.
double textbook(double p, const std::vector<double>& grads, const std::vector<double>& lrs) {
  const double b1 = 0.9, b2 = 0.999, eps = 1e-15;
  double m = 0, v = 0;
  for (std::size_t t = 1; t <= grads.size(); ++t) {
    const double g = grads[t - 1];
    m = b1 * m + (1 - b1) * g;
    v = b2 * v + (1 - b2) * g * g;
    const double mhat = m / (1 - std::pow(b1, double(t))), vhat = v / (1 - std::pow(b2, double(t)));
    p -= lrs[t - 1] * mhat / (std::sqrt(vhat) + eps);
  }
  return p;
}

/// Sets every value of the rows of `g` that `listed` leaves out to `v` (poison for a step that must
/// not read them, or the zeros a dense step reads there).
void set_unlisted(Model& g, const std::vector<bool>& listed, float v) {
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (listed[i]) continue;
    for (int a = 0; a < 3; ++a) g.means[3 * i + std::size_t(a)] = g.log_scales[3 * i + std::size_t(a)] = v;
    for (int a = 0; a < 4; ++a) g.quats[4 * i + std::size_t(a)] = v;
    g.opacity_logits[i] = v;
    for (int c = 0; c < G7::bands; ++c)
      for (int k = 0; k < G7::sh_coeffs; ++k) g.sh_at(i, k, c) = v;
  }
}

/// A model of `n` random Gaussians after one dense Adam step on a random gradient (moments warm
/// everywhere), twice (`p`, `dense`: the reference; `q`, `other`: the variant under test), and a
/// fresh random gradient `g` for the next step.
struct WarmStart {
  Model p, g, q;
  msgs::Adam<G7> dense, other;
  WarmStart(std::size_t n, std::uint32_t seed) : p(n), g(n), dense({}, n) {
    fill_random(p, seed, -1.0f, 1.0f);
    fill_random(g, seed + 1, -1.0f, 1.0f);
    dense.step(p, g);
    fill_random(g, seed + 2, -1.0f, 1.0f);
    q = p;
    other = dense;
  }
};

}  // namespace

TEST_CASE("position learning rate decays exponentially from lr0 to lr1 over T steps") {
  msgs::AdamConfig cfg;
  cfg.lr_means_steps = 1000;
  cfg.scene_scale = 2.0;
  msgs::Adam<G7> adam(cfg);
  CHECK(adam.lr_means_at(0) == doctest::Approx(2 * 1.6e-4).epsilon(1e-12));
  CHECK(adam.lr_means_at(500) == doctest::Approx(2 * 1.6e-5).epsilon(1e-12));  // geometric midpoint
  CHECK(adam.lr_means_at(1000) == doctest::Approx(2 * 1.6e-6).epsilon(1e-12));
  CHECK(adam.lr_means_at(5000) == doctest::Approx(2 * 1.6e-6).epsilon(1e-12));  // clamped after T
  CHECK(adam.lr_means_at(250) == doctest::Approx(2 * 1.6e-4 * std::pow(0.01, 0.25)).epsilon(1e-12));
}

TEST_CASE("three full steps match textbook Adam with per-group learning rates (double model)") {
  const std::size_t n = 5;
  ModelD p(n), p0(n);
  fill_random(p, 1, -1.0f, 1.0f);
  p0 = p;
  msgs::AdamConfig cfg;
  cfg.lr_means_steps = 10;
  msgs::Adam<G7, double> adam(cfg, n);
  std::vector<ModelD> grads;
  for (int s = 0; s < 3; ++s) {
    ModelD g(n);
    fill_random(g, 10u + static_cast<std::uint32_t>(s), -2.0f, 2.0f);
    adam.step(p, g);
    grads.push_back(g);
  }
  CHECK(adam.iteration == 3);
  CHECK(adam.steps.means == 3);
  CHECK(adam.steps.sh[6] == 3);

  // Compare the displacement from the start (not the value) so the tolerance is relative to the update.
  auto moved = [&](auto member, std::size_t idx) {
    return (p.*member)[idx] - (p0.*member)[idx];
  };
  auto expect = [&](auto member, std::size_t idx, std::vector<double> lrs) {
    std::vector<double> gs;
    for (const auto& g : grads) gs.push_back((g.*member)[idx]);
    const double start = (p0.*member)[idx];
    return doctest::Approx(textbook(start, gs, lrs) - start).epsilon(1e-9);
  };
  const std::vector<double> lr_pos = {adam.lr_means_at(0), adam.lr_means_at(1), adam.lr_means_at(2)};
  CHECK(lr_pos[1] < lr_pos[0]);
  for (std::size_t i = 0; i < 3 * n; ++i) {
    CHECK(moved(&ModelD::means, i) == expect(&ModelD::means, i, lr_pos));
    CHECK(moved(&ModelD::log_scales, i) == expect(&ModelD::log_scales, i, {5e-3, 5e-3, 5e-3}));
  }
  for (std::size_t i = 0; i < 4 * n; ++i)
    CHECK(moved(&ModelD::quats, i) == expect(&ModelD::quats, i, {1e-3, 1e-3, 1e-3}));
  for (std::size_t i = 0; i < n; ++i)
    CHECK(moved(&ModelD::opacity_logits, i) == expect(&ModelD::opacity_logits, i, {0.05, 0.05, 0.05}));
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < G7::sh_coeffs; ++k)
      for (int c = 0; c < 7; ++c) {
        const std::size_t idx = static_cast<std::size_t>(&p.sh_at(i, k, c) - p.sh.data());
        const double lr = k == 0 ? 2.5e-3 : 1.25e-4;
        CHECK(moved(&ModelD::sh, idx) == expect(&ModelD::sh, idx, {lr, lr, lr}));
      }
  // First step of Adam moves every parameter by about lr against the gradient sign.
  ModelD q = p0;
  msgs::Adam<G7, double> fresh(cfg, n);
  fresh.step(q, grads[0]);
  CHECK(q.opacity_logits[0] - p0.opacity_logits[0] ==
        doctest::Approx(grads[0].opacity_logits[0] > 0 ? -0.05 : 0.05).epsilon(1e-9));
}

TEST_CASE("masked groups and SH bands outside the range are bit-identical, moments included") {
  const std::size_t n = 9;
  Model p(n), g(n);
  fill_random(p, 3, -1.0f, 1.0f);
  msgs::Adam<G7> adam({}, n);
  // Warm up all moments so 'no change' is not just 'stays zero'.
  fill_random(g, 4, -1.0f, 1.0f);
  adam.step(p, g);
  fill_random(g, 5, -1.0f, 1.0f);
  const Model p_before = p, m_before = adam.exp_avg, v_before = adam.exp_avg_sq;

  msgs::AdamMask mask = msgs::AdamMask::colour_only(3, 2);  // channels 3 and 4
  adam.step(p, g, mask);
  for (auto member : {&Model::means, &Model::log_scales, &Model::quats, &Model::opacity_logits}) {
    CHECK((p.*member) == (p_before.*member));
    CHECK((adam.exp_avg.*member) == (m_before.*member));
    CHECK((adam.exp_avg_sq.*member) == (v_before.*member));
  }
  int changed = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < G7::sh_coeffs; ++k)
      for (int c = 0; c < 7; ++c) {
        const float a = p.sh_at(i, k, c), b = p_before.sh_at(i, k, c);
        const float ma = adam.exp_avg.sh_at(i, k, c), mb = m_before.sh_at(i, k, c);
        const float va = adam.exp_avg_sq.sh_at(i, k, c), vb = v_before.sh_at(i, k, c);
        if (c == 3 || c == 4) {
          changed += (a != b) && (ma != mb) && (va != vb);
        } else {
          CHECK(a == b);
          CHECK(ma == mb);
          CHECK(va == vb);
        }
      }
  CHECK(changed == static_cast<int>(n) * G7::sh_coeffs * 2);
  CHECK(adam.steps.means == 1);
  CHECK(adam.steps.opacities == 1);
  CHECK(adam.iteration == 2);

  // sh = false leaves every channel alone even with a range given.
  msgs::AdamMask none = msgs::AdamMask::colour_only(0, 7);
  none.sh = false;
  const Model p2 = p, m2 = adam.exp_avg;
  adam.step(p, g, none);
  CHECK(p.sh == p2.sh);
  CHECK(adam.exp_avg.sh == m2.sh);
}

TEST_CASE("per-channel SH step counters drive the bias correction of each band") {
  const std::size_t n = 4;
  Model p(n), g(n);
  fill_random(p, 6, -1.0f, 1.0f);
  fill_random(g, 7, -1.0f, 1.0f);
  msgs::Adam<G7> adam({}, n);
  adam.step(p, g, msgs::AdamMask::band(0, 3));
  adam.step(p, g, msgs::AdamMask::band(0, 3));
  const Model before = p;
  adam.step(p, g, msgs::AdamMask::band(3, 4));
  const std::array<std::int64_t, 7> want = {2, 2, 2, 1, 1, 1, 1};
  CHECK(adam.steps.sh == want);
  CHECK(adam.steps.means == 3);
  // Channel 5 had its first update at step 3: a first Adam step moves by lr against the gradient.
  for (std::size_t i = 0; i < n; ++i) {
    const double d = static_cast<double>(p.sh_at(i, 0, 5)) - before.sh_at(i, 0, 5);
    CHECK(d == doctest::Approx(g.sh_at(i, 0, 5) > 0 ? -2.5e-3 : 2.5e-3).epsilon(1e-4));
    const double dr = static_cast<double>(p.sh_at(i, 2, 5)) - before.sh_at(i, 2, 5);
    CHECK(dr == doctest::Approx(g.sh_at(i, 2, 5) > 0 ? -1.25e-4 : 1.25e-4).epsilon(1e-3));
  }
}

TEST_CASE("zero gradients leave parameters unchanged; zero state rows for appended Gaussians work") {
  Model p(3), g(3);
  fill_random(p, 8, -1.0f, 1.0f);
  g.set_zero();
  msgs::Adam<G7> adam({}, 3);
  const Model before = p;
  adam.step(p, g);
  CHECK(p.sh == before.sh);
  CHECK(p.means == before.means);
  // Densification appends rows with zeros to model, gradient and moments alike.
  for (auto* m : {&p, &g, &adam.exp_avg, &adam.exp_avg_sq}) m->resize(5);
  fill_random(g, 9, -1.0f, 1.0f);
  adam.step(p, g);
  for (auto* v : {&p.means, &p.sh, &adam.exp_avg_sq.sh})
    for (float x : *v) CHECK(std::isfinite(x));
}

TEST_CASE("size mismatches and bad SH ranges throw") {
  Model p(3), g(2);
  msgs::Adam<G7> adam({}, 3);
  CHECK_THROWS_AS(adam.step(p, g), std::invalid_argument);
  Model g3(3);
  msgs::Adam<G7> stale({}, 2);
  CHECK_THROWS_AS(stale.step(p, g3), std::invalid_argument);
  CHECK_THROWS_AS(adam.step(p, g3, msgs::AdamMask::band(5, 3)), std::invalid_argument);
  CHECK_THROWS_AS(adam.step(p, g3, msgs::AdamMask::band(-1, 1)), std::invalid_argument);
  CHECK(adam.iteration == 0);  // nothing applied on a rejected step
}

TEST_CASE("sparse Adam: listed rows update as dense Adam does, other rows and their moments stay, their gradients are never read") {
  const std::size_t n = 11;
  WarmStart w(n, 21);
  auto& [p, g, ps, dense, sparse] = w;
  const std::vector<std::uint32_t> rows = {0, 3, 4, 10};
  auto listed = [&](std::size_t i) { return std::find(rows.begin(), rows.end(), i) != rows.end(); };
  std::vector<bool> is_listed(n);
  for (std::size_t i = 0; i < n; ++i) is_listed[i] = listed(i);
  // Poison the gradient rows a sparse step must not read.
  Model gs = g;
  set_unlisted(gs, is_listed, std::numeric_limits<float>::quiet_NaN());
  const Model p_before = ps;
  const msgs::AdamMask mask = msgs::AdamMask::band(2, 3);
  dense.step(p, g, mask);
  sparse.step(ps, gs, mask, &rows);
  CHECK(sparse.steps.means == dense.steps.means);
  CHECK(sparse.steps.sh == dense.steps.sh);
  CHECK(sparse.iteration == dense.iteration);
  auto same_row = [&](const Model& a, const Model& b, std::size_t i) {
    bool same = a.opacity_logits[i] == b.opacity_logits[i];
    for (int x = 0; x < 3; ++x) same = same && a.means[3 * i + std::size_t(x)] == b.means[3 * i + std::size_t(x)] &&
                                       a.log_scales[3 * i + std::size_t(x)] == b.log_scales[3 * i + std::size_t(x)];
    for (int x = 0; x < 4; ++x) same = same && a.quats[4 * i + std::size_t(x)] == b.quats[4 * i + std::size_t(x)];
    for (int c = 0; c < 7; ++c)
      for (int k = 0; k < G7::sh_coeffs; ++k) same = same && a.sh_at(i, k, c) == b.sh_at(i, k, c);
    return same;
  };
  for (std::size_t i = 0; i < n; ++i) {
    INFO("row ", i);
    if (listed(i)) {
      CHECK(same_row(ps, p, i));  // bit for bit the dense update
      CHECK(same_row(sparse.exp_avg, dense.exp_avg, i));
      CHECK(same_row(sparse.exp_avg_sq, dense.exp_avg_sq, i));
    } else {
      CHECK(same_row(ps, p_before, i));
      CHECK_FALSE(same_row(p, p_before, i));  // dense Adam moved it on momentum
    }
  }
  // Rows must be ascending and inside the model.
  const std::vector<std::uint32_t> unsorted = {3, 1}, outside = {2, 11};
  CHECK_THROWS_AS(sparse.step(ps, g, mask, &unsorted), std::invalid_argument);
  CHECK_THROWS_AS(sparse.step(ps, g, mask, &outside), std::invalid_argument);
  // Long lists (a view's visible Gaussians) are checked in parallel: a fault deep inside is found.
  const std::size_t big = 40000;
  Model pb(big), gb(big);
  msgs::Adam<G7, float> adam_big({}, big);
  std::vector<std::uint32_t> all(big);
  for (std::size_t i = 0; i < big; ++i) all[i] = std::uint32_t(i);
  CHECK_NOTHROW(adam_big.step(pb, gb, mask, &all));
  for (const std::size_t at : {std::size_t(1), std::size_t(20001), big - 1}) {
    std::vector<std::uint32_t> repeat = all, past = all;
    repeat[at] = repeat[at - 1];
    past[at] = std::uint32_t(big);
    CHECK_THROWS_AS(adam_big.step(pb, gb, mask, &repeat), std::invalid_argument);
    CHECK_THROWS_AS(adam_big.step(pb, gb, mask, &past), std::invalid_argument);
  }
}

/// Unlisted::zero_gradient over `rows` against dense Adam over a gradient of zeros in the other
/// rows: the same bits in parameters and moments, with NaN in the unlisted gradient rows, which
/// the step must not read.
void check_zero_gradient_rows(std::size_t n, std::vector<std::uint32_t> rows) {
  for (std::uint32_t r : {2046u, 2047u, 2048u, 4095u, std::uint32_t(n - 1)})
    if (!std::binary_search(rows.begin(), rows.end(), r)) rows.insert(std::lower_bound(rows.begin(), rows.end(), r), r);
  WarmStart w(n, 31);
  auto& [p, g, pl, dense, lazy] = w;
  std::vector<bool> listed(n, false);
  for (std::uint32_t r : rows) listed[r] = true;
  REQUIRE(rows.size() > n / 3);
  REQUIRE(rows.size() < n);
  Model gz = g, gl = g;  // dense: zeros where not listed; lazy: NaN there, which it must not read
  set_unlisted(gz, listed, 0.0f);
  set_unlisted(gl, listed, std::numeric_limits<float>::quiet_NaN());
  const auto bits = [](const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
  };
  for (const msgs::AdamMask mask : {msgs::AdamMask::band(2, 3), msgs::AdamMask::all(), msgs::AdamMask::colour_only(6, 1)}) {
    dense.step(p, gz, mask);
    lazy.step(pl, gl, mask, &rows, msgs::Unlisted::zero_gradient);
    for (const auto& [a, b] : {std::pair{&p, &pl}, std::pair{&dense.exp_avg, &lazy.exp_avg},
                               std::pair{&dense.exp_avg_sq, &lazy.exp_avg_sq}}) {
      CHECK(bits(a->means, b->means));
      CHECK(bits(a->log_scales, b->log_scales));
      CHECK(bits(a->quats, b->quats));
      CHECK(bits(a->opacity_logits, b->opacity_logits));
      CHECK(bits(a->sh, b->sh));
    }
  }
  // An empty list: every row takes the zero-gradient update.
  const std::vector<std::uint32_t> none;
  Model zeros(n);
  dense.step(p, zeros);
  lazy.step(pl, gl, {}, &none, msgs::Unlisted::zero_gradient);
  CHECK(bits(p.means, pl.means));
  CHECK(bits(p.sh, pl.sh));
}

TEST_CASE("Unlisted::zero_gradient: dense Adam bit for bit, without reading the unlisted gradient rows") {
  const std::size_t n = 5000;
  std::mt19937 rng(33);
  SUBCASE("long runs: updated run by run") {
    // More rows than one parallel chunk (2048), listed rows in runs of every length, across chunk
    // boundaries, at both ends.
    std::vector<std::uint32_t> rows;
    for (std::uint32_t i = 0; i < n;) {
      const std::uint32_t run = 1 + rng() % 300, gap = rng() % 200;
      for (std::uint32_t r = i; r < std::min<std::uint32_t>(std::uint32_t(n), i + run); ++r) rows.push_back(r);
      i += run + gap;
    }
    check_zero_gradient_rows(n, rows);
  }
  SUBCASE("seen and unseen rows alternating: updated chunk by chunk over a copy of the gradient") {
    // Runs of one to three rows: every chunk takes the path of short runs (Adam::kShortRunRows);
    // the last chunk's listed runs are long, so both paths meet in one step.
    std::vector<std::uint32_t> rows;
    for (std::uint32_t i = 0; i < 4096;) {
      const std::uint32_t run = 1 + rng() % 3, gap = 1 + rng() % 3;
      for (std::uint32_t r = i; r < std::min<std::uint32_t>(4096u, i + run); ++r) rows.push_back(r);
      i += run + gap;
    }
    for (std::uint32_t r = 4096; r < n; ++r)
      if (r % 400 < 250) rows.push_back(r);
    check_zero_gradient_rows(n, rows);
  }
}

TEST_CASE("colour step applied row by row (a fused backward): the bits of one step, dense and sparse") {
  const std::size_t n = 3000;
  std::vector<std::uint32_t> rows;
  std::mt19937 rng(41);
  for (std::uint32_t i = 0; i < n; ++i)
    if (rng() % 3 != 0 || i == 0 || i == n - 1) rows.push_back(i);
  const auto bits = [](const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
  };
  for (const msgs::Unlisted unlisted : {msgs::Unlisted::zero_gradient, msgs::Unlisted::untouched}) {
    WarmStart w(n, 51);
    auto& [p, g, q, whole, split] = w;
    for (const auto& [first, count] : {std::pair{2, 3}, std::pair{6, 1}, std::pair{0, 7}}) {
      const msgs::AdamMask mask = msgs::AdamMask::band(first, count);
      whole.step(p, g, mask, &rows, unlisted);
      // The geometry as usual, the colour row by row in a scrambled order, then the rest.
      const auto colour = split.begin_colour(q, first, count);
      msgs::AdamMask geometry = mask;
      geometry.sh = false;
      split.step(q, g, geometry, &rows, unlisted);
      std::vector<std::uint32_t> order = rows;
      std::shuffle(order.begin(), order.end(), rng);
      for (std::uint32_t r : order)
        for (int c = first; c < first + count; ++c) colour.apply(r, c, g.sh_row(r, c));
      split.finish_colour(colour, rows, unlisted);
      CHECK(split.steps.sh == whole.steps.sh);
      CHECK(split.iteration == whole.iteration);
      for (const auto& [a, b] : {std::pair{&p, &q}, std::pair{&whole.exp_avg, &split.exp_avg},
                                 std::pair{&whole.exp_avg_sq, &split.exp_avg_sq}}) {
        CHECK(bits(a->means, b->means));
        CHECK(bits(a->quats, b->quats));
        CHECK(bits(a->sh, b->sh));
      }
      fill_random(g, std::uint32_t(first + 60 * count), -1.0f, 1.0f);
    }
  }
  msgs::Adam<G7> adam({}, 10);
  Model small(10);
  CHECK_THROWS_AS(adam.begin_colour(small, 5, 3), std::invalid_argument);
  Model other(11);
  CHECK_THROWS_AS(adam.begin_colour(other, 0, 1), std::invalid_argument);
}

}  // namespace test_adam
