// tests/test_densify.cpp
// Tests of msgs/densify.hpp on synthetic screen-space gradients (no rasteriser needed).
#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "msgs/densify.hpp"
#include "msgs/spatial_order.hpp"

namespace test_densify {
using namespace msgs;

namespace {

using G = Gaussian<7, 1>;  // a Joint-like model: seven channels, so row copies must move all of them
using Model = GaussianModel<G, float>;

double logit(double p) { return std::log(p / (1.0 - p)); }
double sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

/// n Gaussians with distinct, recognisable values: small (scale 0.005), opaque (0.9).
Model make_model(std::size_t n) {
  Model m(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      m.means[3 * i + a] = float(10 * i + a);
      m.log_scales[3 * i + a] = float(std::log(0.005));
    }
    m.quats[4 * i] = 1.0f;
    m.opacity_logits[i] = float(logit(0.9));
    for (int k = 0; k < G::sh_coeffs; ++k)
      for (int c = 0; c < G::bands; ++c) m.sh_at(i, k, c) = float(1000 * i + 10 * k + c);
  }
  return m;
}

/// Stand-in for the rasteriser's Gradients: the two screen-space arrays densification reads.
struct FakeGrads {
  std::vector<float> mean2d;   // [N, 2]
  std::vector<float> absgrad;  // [N, 2]
};

/// Screen-space gradients whose NDC norm is `ndc[i]` (along x) for an image of width w.
FakeGrads grads_with_ndc_norm(const std::vector<double>& ndc, int w) {
  FakeGrads g;
  g.mean2d.assign(2 * ndc.size(), 0.0f);
  for (std::size_t i = 0; i < ndc.size(); ++i) g.mean2d[2 * i] = float(ndc[i] / (0.5 * w));
  g.absgrad = g.mean2d;
  return g;
}

std::vector<std::int32_t> radii_all(std::size_t n, std::int32_t r) { return std::vector<std::int32_t>(2 * n, r); }

/// Row i of `m` equals row j of `ref` in every parameter (SH of all channels included).
bool same_row(const Model& m, std::size_t i, const Model& ref, std::size_t j) {
  for (int a = 0; a < 3; ++a)
    if (m.means[3 * i + a] != ref.means[3 * j + a] || m.log_scales[3 * i + a] != ref.log_scales[3 * j + a]) return false;
  for (int a = 0; a < 4; ++a)
    if (m.quats[4 * i + a] != ref.quats[4 * j + a]) return false;
  if (m.opacity_logits[i] != ref.opacity_logits[j]) return false;
  for (int k = 0; k < G::sh_coeffs; ++k)
    for (int c = 0; c < G::bands; ++c)
      if (m.sh_at(i, k, c) != ref.sh_at(j, k, c)) return false;
  return true;
}

bool row_is_zero(const Model& m, std::size_t i) {
  return same_row(m, i, Model(1), 0);
}

/// Four Gaussians refined at step 600 under `cfg` (two bands) with two optimiser states: g0 small
/// and g1 large with a high gradient in band 1 (g0 duplicated, g1 split), g3 faint (pruned).
struct RefinedFour {
  Model m, ref, exp_avg, exp_avg_sq, ref_avg, ref_sq;
  DensifyReport rep;
  explicit RefinedFour(const DensifyConfig& cfg) : m(make_model(4)), exp_avg(make_model(4)), exp_avg_sq(make_model(4)) {
    m.log_scales[3] = float(std::log(0.05));     // g1 large -> split
    m.opacity_logits[3] = float(logit(0.01));    // g3 faint -> pruned
    ref = m;
    for (auto& v : exp_avg_sq.means) v += 0.5f;  // distinguish the two states
    ref_avg = exp_avg;
    ref_sq = exp_avg_sq;
    DensityControl dc(cfg, 2, 0);
    // (Distinct values on purpose: GCC 12.2 with -mavx512f folds the constant {a, a, 0, 0} into a
    // broadcast {a, a, a, a}, a wrong-code bug.)
    dc.observe(600, 1, grads_with_ndc_norm({0.01, 0.012, 0.0, 0.0}, 64).absgrad, radii_all(4, 1), 64, 64);
    rep = dc.step_post_backward(600, m, exp_avg, exp_avg_sq);
  }
  /// Every row follows the plan: the states' rows of new Gaussians are zero, the other rows copy
  /// their source.
  void check_rows_follow() const {
    REQUIRE(exp_avg.size() == m.size());
    REQUIRE(exp_avg_sq.size() == m.size());
    for (std::size_t i = 0; i < m.size(); ++i) {
      if (rep.plan.fresh[i]) {
        CHECK(row_is_zero(exp_avg, i));
        CHECK(row_is_zero(exp_avg_sq, i));
      } else {
        CHECK(same_row(exp_avg, i, ref_avg, rep.plan.source[i]));
        CHECK(same_row(exp_avg_sq, i, ref_sq, rep.plan.source[i]));
        CHECK(same_row(m, i, ref, rep.plan.source[i]));
      }
    }
  }
};

}  // namespace

TEST_CASE("RefinePlan: remove, duplicate, split, append and composition") {
  const std::vector<bool> mask = {false, true, false, true};
  const auto none = RefinePlan::none;

  const RefinePlan rm = RefinePlan::remove(mask);
  CHECK(rm.source == std::vector<std::uint32_t>{0, 2});
  CHECK(rm.fresh_count() == 0);
  CHECK(RefinePlan::keep(mask).source == std::vector<std::uint32_t>{1, 3});

  const RefinePlan dup = RefinePlan::duplicate(mask);
  CHECK(dup.source == std::vector<std::uint32_t>{0, 1, 2, 3, 1, 3});
  CHECK(dup.fresh == std::vector<bool>{false, false, false, false, true, true});

  const RefinePlan sp = RefinePlan::split(mask, 2);
  CHECK(sp.source == std::vector<std::uint32_t>{0, 2, 1, 3, 1, 3});
  CHECK(sp.fresh == std::vector<bool>{false, false, true, true, true, true});

  const RefinePlan ap = RefinePlan::append(2, 1);
  CHECK(ap.source == std::vector<std::uint32_t>{0, 1, none});
  CHECK(ap.fresh == std::vector<bool>{false, false, true});

  // Duplicate, then drop output rows 0 and 5.
  const RefinePlan both = dup.then(RefinePlan::remove({true, false, false, false, false, true}));
  CHECK(both.input_size == 4);
  CHECK(both.source == std::vector<std::uint32_t>{1, 2, 3, 1});
  CHECK(both.fresh == std::vector<bool>{false, false, false, true});
  // Freshness survives composition, and a `none` row stays `none`.
  const RefinePlan c2 = ap.then(RefinePlan::duplicate({false, false, true}));
  CHECK(c2.source == std::vector<std::uint32_t>{0, 1, none, none});
  CHECK(c2.fresh == std::vector<bool>{false, false, true, true});

  CHECK_THROWS_AS(dup.then(RefinePlan::identity(4)), std::invalid_argument);
  RefinePlan bad = RefinePlan::identity(2);
  bad.source[1] = 2;
  CHECK_THROWS_AS(bad.validate(), std::invalid_argument);
  CHECK_THROWS_AS(RefinePlan::split(mask, 0), std::invalid_argument);

  // Plain arrays of any row width follow the same plan.
  std::vector<int> rows = {0, 1, 10, 11, 20, 21, 30, 31};  // [4, 2]
  std::vector<int> state = rows;
  apply_rows(dup, rows, 2);
  CHECK(rows == std::vector<int>{0, 1, 10, 11, 20, 21, 30, 31, 10, 11, 30, 31});
  apply_rows_zero_fresh(dup, state, 2);
  CHECK(state == std::vector<int>{0, 1, 10, 11, 20, 21, 30, 31, 0, 0, 0, 0});
  std::vector<int> wrong(6);
  CHECK_THROWS_AS(apply_rows(dup, wrong, 2), std::invalid_argument);
}

TEST_CASE("apply / apply_zero_fresh move whole rows of the model and of optimiser state") {
  const Model ref = make_model(3);
  Model m = ref;
  Model state = make_model(3);  // stands in for Adam's exp_avg: same layout, recognisable values
  const RefinePlan plan = RefinePlan::split({false, true, false}, 2).then(RefinePlan::remove({true, false, false, false}));
  // split -> rows {0, 2, 1', 1''}; remove output 0 -> {2, 1', 1''}
  REQUIRE(plan.source == std::vector<std::uint32_t>{2, 1, 1});
  apply(plan, m);
  apply_zero_fresh(plan, state);
  REQUIRE(m.size() == 3);
  m.check_consistent();
  state.check_consistent();
  CHECK(same_row(m, 0, ref, 2));
  CHECK(same_row(m, 1, ref, 1));
  CHECK(same_row(m, 2, ref, 1));
  CHECK(same_row(state, 0, ref, 2));
  CHECK(row_is_zero(state, 1));
  CHECK(row_is_zero(state, 2));

  Model small = make_model(2);
  CHECK_THROWS_AS(apply(plan, small), std::invalid_argument);

  // Through a spare (the band planes gathered out of place): the same rows, and the spare ends up
  // with the old planes of the last array applied.
  std::vector<float> spare;
  Model m2 = ref, state2 = make_model(3);
  apply(plan, m2, spare);
  apply_zero_fresh(plan, state2, spare);
  CHECK(m2.sh == m.sh);
  CHECK(m2.means == m.means);
  CHECK(state2.sh == state.sh);
  CHECK(state2.quats == state.quats);
  CHECK(spare == make_model(3).sh);
  CHECK_THROWS_AS(apply(plan, small, spare), std::invalid_argument);
}

TEST_CASE("screen-space statistics: NDC scaling, visible views only, max relative radius") {
  DensityStats st(3, 2);
  const int W = 200, H = 100;
  // Gaussian 0: pixel gradient (0.01, 0.02) -> NDC (1, 1), norm sqrt(2). Gaussian 1: one radius 0
  // (gsplat counts a Gaussian only when both radii are positive). Gaussian 2: culled.
  st.add(0, std::vector<float>{0.01f, 0.02f, 5.f, 5.f, 7.f, 7.f}, std::vector<std::int32_t>{3, 4, 0, 5, 0, 0}, W, H);
  CHECK(st.grad_sum(0, 0) == doctest::Approx(std::sqrt(2.0)).epsilon(1e-6));
  CHECK(st.count(0, 0) == 1);
  CHECK(st.count(1, 0) == 0);
  CHECK(st.count(2, 0) == 0);
  CHECK(st.max_radius(0) == doctest::Approx(4.0 / 200.0));
  CHECK(st.max_radius(1) == 0.0f);
  // A second view of band 0 in which Gaussian 0 is not visible does not dilute its average.
  st.add(0, std::vector<float>{9.f, 9.f, 0.f, 0.f, 0.f, 0.f}, std::vector<std::int32_t>{0, 0, 0, 0, 0, 0}, W, H);
  CHECK(st.average(0, 0) == doctest::Approx(std::sqrt(2.0)).epsilon(1e-6));
  // A view of band 1 with a bigger radius and zero gradient: band 1 average 0, count 1.
  st.add(1, std::vector<float>{0.f, 0.f, 0.f, 0.f, 0.f, 0.f}, std::vector<std::int32_t>{30, 2, 0, 0, 0, 0}, W, H);
  CHECK(st.count(0, 1) == 1);
  CHECK(st.average(0, 1) == 0.0);
  CHECK(st.max_average(0) == doctest::Approx(std::sqrt(2.0)).epsilon(1e-6));
  CHECK(st.max_radius(0) == doctest::Approx(30.0 / 200.0));
  CHECK(st.average(2, 1) == 0.0);  // never seen: sum / max(count, 1) = 0, not NaN
  // Non-finite gradients are skipped.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  st.add(1, std::vector<float>{nan, 0.f, 0.f, 0.f, 0.f, 0.f}, std::vector<std::int32_t>{1, 1, 0, 0, 0, 0}, W, H);
  CHECK(st.count(0, 1) == 1);
  CHECK(std::isfinite(st.max_average(0)));

  CHECK_THROWS_AS(st.add(2, std::vector<float>(6), std::vector<std::int32_t>(6), W, H), std::invalid_argument);
  CHECK_THROWS_AS(st.add(0, std::vector<float>(4), std::vector<std::int32_t>(6), W, H), std::invalid_argument);
  st.reset(1);
  CHECK(st.size() == 1);
  CHECK(st.bands() == 2);
  CHECK(st.count(0, 0) == 0);
}

TEST_CASE("MSAD densifies on one band's gradient where the averaged default rule does not") {
  // Five bands visited round-robin; Gaussian 0 has NDC gradient 0.0009 in band 2 only, so its
  // band-2 average is 0.0009 > 0.0008 (MSAD) while the single average is 0.00018 < 0.0002.
  const int W = 320, H = 240, bands = 5;
  const long long step = 600;
  auto run = [&](DensifyConfig cfg, double& avg) {
    DensityControl dc(cfg, bands, 10);
    REQUIRE(dc.refines_at(step));
    Model m = make_model(2);
    for (long long t = step - 9; t <= step; ++t) {
      const int band = static_cast<int>(t % bands);
      const FakeGrads g = grads_with_ndc_norm({band == 2 ? 0.0009 : 0.0, 0.0}, W);
      dc.observe_gradients(t, band, g, radii_all(2, 2), W, H);
    }
    avg = dc.stats().max_average(0);
    const DensifyReport rep = dc.step_post_backward(step, m);
    CHECK(rep.refined);
    CHECK(rep.counts.split == 0);
    CHECK(rep.counts.pruned == 0);
    return rep;
  };
  double avg_msad = 0, avg_default = 0;
  const DensifyReport msad = run(DensifyConfig::msad(), avg_msad);
  const DensifyReport dflt = run(DensifyConfig::gsplat_default(), avg_default);
  CHECK(avg_msad == doctest::Approx(0.0009).epsilon(1e-4));
  CHECK(avg_default == doctest::Approx(0.0009 / bands).epsilon(1e-4));
  CHECK(msad.counts.duplicated == 1);
  CHECK(msad.after == 3);
  CHECK(dflt.counts.duplicated == 0);
  CHECK(dflt.after == 2);
}

TEST_CASE("absgrad mode reads Gradients::absgrad, the default mode Gradients::mean2d") {
  FakeGrads g;
  g.mean2d = {0.0f, 0.0f};
  g.absgrad = {0.01f, 0.0f};
  DensityControl a(DensifyConfig::msad(), 1, 0);
  DensityControl d(DensifyConfig::gsplat_default(), 1, 0);
  a.observe_gradients(1, 0, g, radii_all(1, 1), 100, 100);
  d.observe_gradients(1, 0, g, radii_all(1, 1), 100, 100);
  CHECK(a.stats().average(0, 0) == doctest::Approx(0.5));
  CHECK(d.stats().average(0, 0) == 0.0);
  // A rasteriser without RasterOptions::absgrad leaves Gradients::absgrad empty: absgrad
  // densification must say so instead of accumulating nothing.
  g.absgrad.clear();
  CHECK_THROWS_WITH_AS(a.observe_gradients(2, 0, g, radii_all(1, 1), 100, 100),
                       doctest::Contains("RasterOptions{.absgrad = true}"), std::invalid_argument);
  d.observe_gradients(2, 0, g, radii_all(1, 1), 100, 100);  // the default mode reads mean2d only
}

TEST_CASE("duplicate where the max scale is small, split where it is large, relative to the scene scale") {
  Model ref = make_model(2);
  // Gaussian 1: max scale 0.05 > 0.01 -> split; Gaussian 0: 0.005 -> duplicate.
  ref.log_scales[3] = float(std::log(0.05));
  ref.log_scales[4] = ref.log_scales[5] = float(std::log(0.001));
  auto refine_with = [&](double scene_scale, RefineCounts& counts) {
    DensityControl dc(DensifyConfig::msad(), 1, 0, scene_scale);
    dc.observe(600, 0, grads_with_ndc_norm({0.01, 0.01}, 100).absgrad, radii_all(2, 1), 100, 100);
    Model m = ref;
    const RefinePlan plan = dc.refine(600, m, counts);
    CHECK(plan.size() == m.size());
    CHECK(dc.stats().size() == m.size());
    return std::make_pair(m, plan);
  };
  RefineCounts c1;
  const auto [m1, p1] = refine_with(1.0, c1);
  CHECK(c1.duplicated == 1);
  CHECK(c1.split == 1);
  CHECK(c1.pruned == 0);
  REQUIRE(m1.size() == 4);  // g0, its copy, two samples of g1
  CHECK(p1.source == std::vector<std::uint32_t>{0, 0, 1, 1});
  CHECK(p1.fresh == std::vector<bool>{false, true, true, true});
  CHECK(same_row(m1, 0, ref, 0));
  CHECK(same_row(m1, 1, ref, 0));  // a clone is an exact copy
  for (std::size_t r : {2u, 3u}) {
    CHECK(m1.log_scales[3 * r] == doctest::Approx(std::log(0.05 / 1.6)).epsilon(1e-6));
    CHECK(m1.opacity_logits[r] == ref.opacity_logits[1]);
    for (int k = 0; k < G::sh_coeffs; ++k)
      for (int c = 0; c < G::bands; ++c) CHECK(m1.sh_at(r, k, c) == ref.sh_at(1, k, c));
  }
  // With scene scale 10 the limit is 0.1: both are duplicated.
  RefineCounts c10;
  const auto [m10, p10] = refine_with(10.0, c10);
  CHECK(c10.duplicated == 2);
  CHECK(c10.split == 0);
  CHECK(p10.source == std::vector<std::uint32_t>{0, 1, 0, 1});
  // Below the threshold nothing grows.
  DensityControl quiet(DensifyConfig::msad(), 1, 0);
  quiet.observe(600, 0, grads_with_ndc_norm({0.0007, 0.0007}, 100).absgrad, radii_all(2, 1), 100, 100);
  Model m = ref;
  RefineCounts cq;
  quiet.refine(600, m, cq);
  CHECK(cq.duplicated + cq.split + cq.pruned == 0);
  CHECK(m.size() == 2);
}

TEST_CASE("max_gaussians: the largest gradients grow first, the rest wait, pruning still applies") {
  // Five small Gaussians (duplicate candidates) with NDC gradients 0.002, 0.005, 0.003, 0.005, 0.0001
  // (the last is below the 0.0008 threshold) and one large one (split candidate, gradient 0.004).
  Model ref = make_model(6);
  for (int a = 0; a < 3; ++a) ref.log_scales[3 * 5 + a] = float(std::log(0.05));
  const std::vector<double> grad{0.002, 0.005, 0.003, 0.005, 0.0001, 0.004};
  auto refine_capped = [&](std::size_t cap, RefineCounts& counts, Model& m) {
    DensifyConfig cfg = DensifyConfig::msad();
    cfg.max_gaussians = cap;
    DensityControl dc(cfg, 1, 0, 1.0);
    dc.observe(600, 0, grads_with_ndc_norm(grad, 100).absgrad, radii_all(6, 1), 100, 100);
    m = ref;
    return dc.refine(600, m, counts);
  };
  Model m;
  RefineCounts c;
  // Unlimited (0) and a cap that fits everything: 4 duplicates + 1 split = 6 + 4 + 1 = 11.
  refine_capped(0, c, m);
  CHECK(c.duplicated == 4);
  CHECK(c.split == 1);
  CHECK(m.size() == 11);
  refine_capped(11, c, m);
  CHECK(m.size() == 11);
  // Cap 9 (budget 3): gradients 0.005 (#1), 0.005 (#3, equal: lower index first), 0.004 (#5, a
  // split adds one) fit; 0.003 and 0.002 wait.
  const RefinePlan p9 = refine_capped(9, c, m);
  CHECK(c.duplicated == 2);
  CHECK(c.split == 1);
  REQUIRE(m.size() == 9);
  CHECK(p9.source == std::vector<std::uint32_t>{0, 1, 2, 3, 4, 1, 3, 5, 5});
  // Cap 8 (budget 2): #1 and #3; the split of #5 would exceed it, and it is not partly applied.
  refine_capped(8, c, m);
  CHECK(c.duplicated == 2);
  CHECK(c.split == 0);
  CHECK(m.size() == 8);
  // A model already at or above the cap does not grow, but still prunes.
  ref.opacity_logits[0] = float(logit(0.01));
  refine_capped(4, c, m);
  CHECK(c.duplicated + c.split == 0);
  CHECK(c.pruned == 1);
  CHECK(m.size() == 5);
}

TEST_CASE("stop_gaussians: a refinement that would grow past it throws before touching the model") {
  // The growth of the max_gaussians case above: 6 -> 11 Gaussians unlimited.
  Model ref = make_model(6);
  for (int a = 0; a < 3; ++a) ref.log_scales[3 * 5 + a] = float(std::log(0.05));
  const std::vector<double> grad{0.002, 0.005, 0.003, 0.005, 0.0001, 0.004};
  auto refine_stopped = [&](std::size_t stop, std::size_t cap, Model& m) {
    DensifyConfig cfg = DensifyConfig::msad();
    cfg.stop_gaussians = stop;
    cfg.max_gaussians = cap;
    DensityControl dc(cfg, 1, 0, 1.0);
    dc.observe(600, 0, grads_with_ndc_norm(grad, 100).absgrad, radii_all(6, 1), 100, 100);
    m = ref;
    RefineCounts c;
    return dc.refine(600, m, c);
  };
  Model m;
  // At or above the grown size: no effect, the same plan as without the guard.
  const RefinePlan free = refine_stopped(0, 0, m);
  CHECK(m.size() == 11);
  CHECK(refine_stopped(11, 0, m).source == free.source);
  CHECK(m.size() == 11);
  // One below: the error names the step, both sizes and the limit; the model is unchanged.
  try {
    refine_stopped(10, 0, m);
    FAIL("expected DensifyLimitError");
  } catch (const DensifyLimitError& e) {
    CHECK(e.step == 600);
    CHECK(e.before == 6);
    CHECK(e.after == 11);
    CHECK(e.limit == 10);
    CHECK(std::string(e.what()).find("from 6 to 11 Gaussians") != std::string::npos);
    CHECK(std::string(e.what()).find("--max-gaussians") != std::string::npos);
  }
  CHECK(m.size() == 6);
  CHECK(m.means == ref.means);
  // The growth budget applies first: capped at 9, a stop at 9 is not reached.
  refine_stopped(9, 9, m);
  CHECK(m.size() == 9);
}

TEST_CASE("split samples keep scale / 1.6 and are distributed as the parent Gaussian") {
  const std::size_t n = 3000;
  Model ref(n);
  const double s[3] = {0.2, 0.05, 0.1};
  // A non-normalised stored quaternion: the sample must use the normalised rotation.
  const double qw = 0.8, qx = 0.3, qy = -0.4, qz = 0.5;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      ref.means[3 * i + a] = float(a + 1);
      ref.log_scales[3 * i + a] = float(std::log(s[a]));
    }
    ref.quats[4 * i] = float(2 * qw);
    ref.quats[4 * i + 1] = float(2 * qx);
    ref.quats[4 * i + 2] = float(2 * qy);
    ref.quats[4 * i + 3] = float(2 * qz);
    ref.opacity_logits[i] = float(logit(0.7));
  }
  auto split_all = [&](std::uint64_t seed) {
    DensifyConfig cfg = DensifyConfig::msad();
    cfg.seed = seed;
    DensityControl dc(cfg, 1, 0);
    dc.observe(900, 0, std::vector<float>(2 * n, 1.0f), radii_all(n, 1), 100, 100);
    Model m = ref;
    RefineCounts c;
    dc.refine(900, m, c);
    CHECK(c.split == n);
    CHECK(c.duplicated == 0);
    return m;
  };
  const Model m = split_all(1);
  REQUIRE(m.size() == 2 * n);
  // Independent reference for the rotation.
  const Eigen::Matrix3d R = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
  const Eigen::Vector3d mu(1, 2, 3);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  double max_abs = 0;
  for (std::size_t r = 0; r < m.size(); ++r) {
    for (int a = 0; a < 3; ++a) CHECK(m.log_scales[3 * r + a] == doctest::Approx(std::log(s[a] / 1.6)).epsilon(1e-5));
    CHECK(m.opacity_logits[r] == ref.opacity_logits[0]);
    const Eigen::Vector3d x(m.means[3 * r], m.means[3 * r + 1], m.means[3 * r + 2]);
    Eigen::Vector3d z = R.transpose() * (x - mu);  // back to the local frame
    for (int a = 0; a < 3; ++a) z[a] /= s[a];      // in units of the parent's standard deviations
    sum += z;
    sum2 += z * z.transpose();
    max_abs = std::max(max_abs, z.cwiseAbs().maxCoeff());
  }
  const double N = double(m.size());
  const Eigen::Vector3d mean = sum / N;
  const Eigen::Matrix3d cov = sum2 / N - mean * mean.transpose();
  for (int a = 0; a < 3; ++a) {
    CHECK(std::abs(mean[a]) < 0.06);              // 6000 samples: standard error 0.013
    CHECK(cov(a, a) == doctest::Approx(1.0).epsilon(0.08));
    for (int b = 0; b < a; ++b) CHECK(std::abs(cov(a, b)) < 0.06);  // axes independent
  }
  CHECK(max_abs < 6.0);  // near the mean
  // The two samples of a parent differ (independent draws).
  CHECK(m.means[0] != m.means[3 * n]);
  // Deterministic for a seed, different across seeds.
  const Model again = split_all(1);
  CHECK(again.means == m.means);
  const Model other = split_all(2);
  CHECK(other.means != m.means);
}

TEST_CASE("prune by opacity (0.1 MSAD, 0.005 default) and by 3-D size after the first reset") {
  Model ref = make_model(5);
  ref.opacity_logits[0] = float(logit(0.05));   // below 0.1, above 0.005
  ref.opacity_logits[1] = float(logit(0.003));  // below both
  ref.log_scales[6] = float(std::log(0.6));     // g2: larger than 0.5 (and 0.1)
  ref.log_scales[9] = float(std::log(0.3));     // g3: between 0.1 and 0.5
  ref.means[12] = std::numeric_limits<float>::quiet_NaN();  // g4: broken row
  auto pruned_rows = [&](DensifyConfig cfg, long long step) {
    cfg.reorder_every = 0;  // gsplat's row order: the survivors in order
    DensityControl dc(cfg, 1, 0);
    Model m = ref;
    RefineCounts c;
    const RefinePlan plan = dc.refine(step, m, c);  // no statistics: nothing grows
    CHECK(c.duplicated + c.split == 0);
    CHECK(c.pruned == ref.size() - m.size());
    std::vector<std::uint32_t> kept = plan.source;
    for (std::size_t i = 0; i < m.size(); ++i) CHECK(same_row(m, i, ref, plan.source[i]));
    return kept;
  };
  using V = std::vector<std::uint32_t>;
  // MSAD: before the first reset (9000) only opacity; after it also scale > 0.5.
  CHECK(pruned_rows(DensifyConfig::msad(), 600) == V{2, 3});
  CHECK(pruned_rows(DensifyConfig::msad(), 9300) == V{3});
  // Default: opacity < 0.005; after the first reset (3000) scale > 0.1.
  CHECK(pruned_rows(DensifyConfig::gsplat_default(), 600) == V{0, 2, 3});
  CHECK(pruned_rows(DensifyConfig::gsplat_default(), 3100) == V{0});
}

TEST_CASE("a row with a non-finite value in any array or band plane is pruned, its neighbours kept") {
  // Enough rows for several of the finiteness pass's chunks on every thread; one broken value per
  // broken row, in each array and in each band plane (first and last coefficient).
  const std::size_t n = 20000;
  const Model ref = make_model(n);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  std::vector<std::uint32_t> broken;
  Model m = ref;
  auto mark = [&](std::size_t row, float* v, float bad) {
    *v = bad;
    broken.push_back(std::uint32_t(row));
  };
  mark(3, &m.means[3 * 3 + 1], nan);
  mark(4100, &m.log_scales[3 * 4100 + 2], inf);
  mark(8191, &m.quats[4 * 8191 + 3], -inf);
  mark(8192, &m.opacity_logits[8192], nan);
  for (int c = 0; c < G::bands; ++c) {
    const std::size_t r1 = 9000 + std::size_t(c) * 1013, r2 = r1 + 1;
    mark(r1, &m.sh_at(r1, 0, c), nan);
    mark(r2, &m.sh_at(r2, G::sh_coeffs - 1, c), inf);
  }
  mark(n - 1, &m.sh_at(n - 1, 1, G::bands - 1), nan);
  std::sort(broken.begin(), broken.end());
  DensifyConfig cfg = DensifyConfig::gsplat_default();
  cfg.reorder_every = 0;  // gsplat's row order: the survivors in order
  DensityControl dc(cfg, 1, 0);
  RefineCounts c;
  const RefinePlan plan = dc.refine(600, m, c);  // no statistics: nothing grows, only pruning
  CHECK(c.pruned == broken.size());
  REQUIRE(m.size() == n - broken.size());
  std::size_t b = 0, f = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (b < broken.size() && broken[b] == i) {
      ++b;
      continue;
    }
    REQUIRE(plan.source[f] == i);
    CHECK(same_row(m, f, ref, i));
    ++f;
  }
}

TEST_CASE("screen-space split and prune apply only until screen_stop") {
  // splatfacto-like timing in which the first reset (3000) comes before screen_stop (4000).
  DensifyConfig cfg = DensifyConfig::msad();
  cfg.refine_every = 100;
  cfg.reset_every = 3000;
  cfg.reorder_every = 0;  // gsplat's row order: survivors, then samples
  const int W = 1000, H = 500;
  auto refine_at = [&](long long step, RefineCounts& c) {
    DensityControl dc(cfg, 1, 0);
    // Zero gradient; screen radii 200 px (0.2 of max(W, H)), 100 px (0.1), 10 px (0.01).
    dc.observe(step, 0, std::vector<float>(6, 0.0f), std::vector<std::int32_t>{200, 200, 100, 100, 10, 10}, W, H);
    Model m = make_model(3);
    const RefinePlan plan = dc.refine(step, m, c);
    return plan.source;
  };
  using V = std::vector<std::uint32_t>;
  RefineCounts c;
  // Step 3500: g0 and g1 are split (radius > 0.05); g0's samples inherit radius 0.2 > 0.15 and are
  // pruned; g1's samples (0.1) stay.
  CHECK(refine_at(3500, c) == V{2, 1, 1});
  CHECK(c.split == 2);
  CHECK(c.pruned == 2);
  // Step 4100: screen rules off, nothing happens.
  CHECK(refine_at(4100, c) == V{0, 1, 2});
  CHECK(c.split + c.pruned == 0);
  // Before the first reset the screen rule splits but does not prune (gsplat nests it).
  CHECK(refine_at(2500, c) == V{2, 0, 1, 0, 1});
  CHECK(c.pruned == 0);
}

TEST_CASE("optimiser state rows follow the refine plan with zeros for fresh rows") {
  DensifyConfig cfg = DensifyConfig::msad();
  cfg.reorder_every = 0;  // gsplat's row order: survivors, copies, samples
  const RefinedFour r(cfg);
  const DensifyReport& rep = r.rep;
  REQUIRE(rep.refined);
  CHECK_FALSE(rep.opacity_reset);
  CHECK(rep.counts.duplicated == 1);
  CHECK(rep.counts.split == 1);
  CHECK(rep.counts.pruned == 1);
  CHECK(rep.before == 4);
  REQUIRE(rep.after == 5);  // 4 + 1 copy + 1 (split adds one net) - 1 pruned
  // Order: kept {0, 2}, copy of 0, samples of 1 (3 was pruned).
  CHECK(rep.plan.source == std::vector<std::uint32_t>{0, 2, 0, 1, 1});
  CHECK(rep.plan.fresh == std::vector<bool>{false, false, true, true, true});
  r.check_rows_follow();
  // A state of the wrong size is refused before anything changes.
  DensityControl dc2(DensifyConfig::msad(), 1, 0);
  Model m2 = make_model(3), bad_state = make_model(2);
  dc2.observe(600, 0, grads_with_ndc_norm({0.01, 0.01, 0.01}, 64).absgrad, radii_all(3, 1), 64, 64);
  CHECK_THROWS_AS(dc2.step_post_backward(600, m2, bad_state), std::invalid_argument);
  CHECK(m2.size() == 3);
}

TEST_CASE("between spatial sorts, survivors keep their rows and new Gaussians take the rows of removed ones") {
  // The refinement of the test above in the default order (reorder_every 8; step 600 does not sort).
  REQUIRE_FALSE(DensityControl(DensifyConfig::msad(), 2, 0).reorders_at(600));
  const RefinedFour r(DensifyConfig::msad());
  const Model &m = r.m, &ref = r.ref;
  REQUIRE(r.rep.after == 5);
  // g0 and g2 stay in rows 0 and 2; the copy of g0 and the samples of g1 fill rows 1 and 3 (those
  // of g1 and g3) and row 4.
  CHECK(r.rep.plan.source == std::vector<std::uint32_t>{0, 0, 2, 1, 1});
  CHECK(r.rep.plan.fresh == std::vector<bool>{false, true, false, true, true});
  r.check_rows_follow();
  CHECK(same_row(m, 1, ref, 0));  // the copy
  // The samples: the parent's colour and rotation, their own means and smaller scales.
  for (std::size_t i : {std::size_t(3), std::size_t(4)}) {
    CHECK(m.sh_at(i, 1, 5) == ref.sh_at(1, 1, 5));
    CHECK(m.log_scales[3 * i] == doctest::Approx(ref.log_scales[3] - std::log(1.6)).epsilon(1e-5));
  }
}

TEST_CASE("Gaussians with the same mean keep their order when rows are filled (they blend in row order)") {
  // g1 and g3 share a mean (a copy and its source that have not moved). Pruning g0 frees row 0;
  // g3 lies past the end (3 rows remain) and must move, but not in front of g1: the pair blends
  // in row order at its common depth, and the two rows' optimiser states differ.
  Model m = make_model(4);
  for (int a = 0; a < 3; ++a) m.means[3 * 3 + a] = m.means[3 * 1 + a];
  m.sh_at(3, 0, 2) = 12345.0f;  // tell them apart
  m.opacity_logits[0] = float(logit(0.01));  // g0 faint -> pruned
  const Model ref = m;
  DensityControl dc(DensifyConfig::msad(), 1, 0);
  REQUIRE_FALSE(dc.reorders_at(600));
  RefineCounts c;
  const RefinePlan plan = dc.refine(600, m, c);
  CHECK(c.pruned == 1);
  CHECK(plan.source == std::vector<std::uint32_t>{1, 3, 2});  // g3 takes g1's row, g1 the free row 0
  for (std::size_t i = 0; i < 3; ++i) CHECK(same_row(m, i, ref, plan.source[i]));
  // Without the tie, the row past the end simply fills the free row.
  Model u = make_model(4);
  u.opacity_logits[0] = float(logit(0.01));
  DensityControl du(DensifyConfig::msad(), 1, 0);
  CHECK(du.refine(600, u, c).source == std::vector<std::uint32_t>{3, 1, 2});
}

TEST_CASE("band planes with room to grow: in-place refinement, growth by a quarter, zero spare rows") {
  // A model whose planes have room for 10 Gaussians and hold 6.
  Model m = make_model(6);
  {
    std::vector<float> planes(10 * std::size_t(G::sh_floats), 0.0f);
    for (int c = 0; c < G::bands; ++c)
      std::copy_n(m.sh_row(0, c), 6 * G::sh_coeffs, planes.data() + std::size_t(c) * 10 * G::sh_coeffs);
    m.sh.swap(planes);
  }
  REQUIRE(m.sh_capacity() == 10);
  m.check_consistent();
  const Model six = make_model(6);
  for (std::size_t i = 0; i < 6; ++i) CHECK(same_row(m, i, six, i));
  auto spare_rows_zero = [](const Model& x) {
    for (int c = 0; c < G::bands; ++c)
      for (std::size_t i = x.size(); i < x.sh_capacity(); ++i)
        for (int k = 0; k < G::sh_coeffs; ++k)
          if (x.sh_row(i, c)[k] != 0.0f) return false;
    return true;
  };
  // Few rows change (row 2 removed, its place taken by a copy of row 4, a copy of row 0 appended):
  // in place, the capacity stays.
  RefinePlan p;
  p.input_size = 6;
  p.source = {0, 1, 4, 3, 4, 5, 0};
  p.fresh = {false, false, true, false, false, false, true};
  std::vector<float> spare;
  Model a = m, state = m;
  apply(p, a, spare);
  apply_zero_fresh(p, state, spare);
  CHECK(a.sh_capacity() == 10);
  REQUIRE(a.size() == 7);
  for (std::size_t i = 0; i < 7; ++i) {
    CHECK(same_row(a, i, six, p.source[i]));
    if (p.fresh[i]) CHECK(row_is_zero(state, i));
    else CHECK(same_row(state, i, six, p.source[i]));
  }
  CHECK(spare_rows_zero(a));
  // Shrinking in place zeroes the rows left behind.
  RefinePlan shrink;
  shrink.input_size = 7;
  shrink.source = {0, 1, 2, 3, 4};
  shrink.fresh.assign(5, false);
  apply(shrink, a, spare);
  CHECK(a.sh_capacity() == 10);
  CHECK(spare_rows_zero(a));
  // Growing past the capacity gathers into planes with room for a quarter more.
  const RefinePlan grow = RefinePlan::append(5, 7);
  const Model before = a;
  apply(grow, a, spare);
  REQUIRE(a.size() == 12);
  CHECK(a.sh_capacity() == 15);
  for (std::size_t i = 0; i < 5; ++i) CHECK(same_row(a, i, before, i));
  for (std::size_t i = 5; i < 12; ++i) CHECK(row_is_zero(a, i));
  CHECK(spare_rows_zero(a));
  // The same plans without a spare, and through apply_rows of a model of exact planes, agree.
  Model b = m;
  apply(p, b);
  apply(shrink, b);
  apply(grow, b);
  REQUIRE(b.size() == 12);
  for (std::size_t i = 0; i < 12; ++i) CHECK(same_row(b, i, a, i));
  // A copy with exact planes, as checkpoints and PLY files hold them; resize keeps the values.
  Model exact;
  exact.assign_shrunk(a);
  CHECK(exact.sh_capacity() == 12);
  CHECK(exact.sh.size() == 12 * std::size_t(G::sh_floats));
  for (std::size_t i = 0; i < 12; ++i) CHECK(same_row(exact, i, a, i));
  Model r = a;
  r.resize(13);
  CHECK(r.sh_capacity() == 13);
  for (std::size_t i = 0; i < 12; ++i) CHECK(same_row(r, i, a, i));
  CHECK(row_is_zero(r, 12));
  // Planes too small for the Gaussians are refused.
  Model bad = make_model(3);
  bad.sh.resize(2 * std::size_t(G::sh_floats));
  CHECK_THROWS_AS(bad.check_consistent(), std::invalid_argument);
}

TEST_CASE("opacity reset clamps opacities and zeroes the opacity moments") {
  DensityControl dc(DensifyConfig::msad(), 1, 100);
  Model m = make_model(3);
  m.opacity_logits[1] = float(logit(0.05));  // already below the cap: unchanged
  m.opacity_logits[2] = std::numeric_limits<float>::quiet_NaN();
  Model avg = make_model(3);
  const Model ref_avg = avg;
  // Step 9000 resets (and does not refine: it lies in the pause after the reset).
  CHECK(dc.resets_opacity_at(9000));
  CHECK_FALSE(dc.refines_at(9000));
  const DensifyReport rep = dc.step_post_backward(9000, m, avg);
  CHECK(rep.opacity_reset);
  CHECK_FALSE(rep.refined);
  CHECK(sigmoid(m.opacity_logits[0]) == doctest::Approx(0.2).epsilon(1e-5));
  CHECK(sigmoid(m.opacity_logits[1]) == doctest::Approx(0.05).epsilon(1e-5));
  CHECK(sigmoid(m.opacity_logits[2]) == doctest::Approx(0.2).epsilon(1e-5));  // NaN replaced
  for (float v : avg.opacity_logits) CHECK(v == 0.0f);
  CHECK(avg.means == ref_avg.means);  // other moments untouched
  CHECK(avg.sh == ref_avg.sh);

  // Default: every 3000 steps to 0.01, on a refinement step (no pause after resets).
  DensityControl d(DensifyConfig::gsplat_default(), 1, 100);
  Model md = make_model(2);
  const DensifyReport r2 = d.step_post_backward(3000, md);
  CHECK(r2.refined);
  CHECK(r2.opacity_reset);
  CHECK(sigmoid(md.opacity_logits[0]) == doctest::Approx(0.01).epsilon(1e-4));
  CHECK_FALSE(d.resets_opacity_at(15000));  // no resets once refinement has stopped
  CHECK_FALSE(d.resets_opacity_at(0));
}

TEST_CASE("refine timing: start, period, pause window, after-reset window, stop") {
  DensifyConfig cfg = DensifyConfig::msad();  // refine every 300 from 500 to 60000, reset every 9000
  cfg.pause_begin = 29000;
  cfg.pause_end = 32000;
  const DensityControl dc(cfg, 5, 100);  // pause after reset: 100 images + 300 = 400 steps
  CHECK(dc.pause_after_reset() == 400);
  CHECK_FALSE(dc.refines_at(300));   // not after 500
  CHECK_FALSE(dc.refines_at(500));
  CHECK(dc.refines_at(600));
  CHECK_FALSE(dc.refines_at(700));   // not a multiple of 300
  CHECK(dc.refines_at(8700));
  CHECK_FALSE(dc.refines_at(9000));  // reset step
  CHECK_FALSE(dc.refines_at(9300));  // 300 < 400 steps after the reset
  CHECK(dc.refines_at(9600));
  CHECK(dc.refines_at(28800));
  CHECK_FALSE(dc.refines_at(29100));  // pause window (29000, 32000]
  CHECK_FALSE(dc.refines_at(31800));
  CHECK(dc.refines_at(32100));
  // Opacity resets stop in the pause too (the reference's rule): move a reset step into a window.
  DensifyConfig reset_cfg = DensifyConfig::msad();
  CHECK(DensityControl(reset_cfg, 5, 100).resets_opacity_at(9000));
  reset_cfg.pause_begin = 8999;
  reset_cfg.pause_end = 9001;
  CHECK_FALSE(DensityControl(reset_cfg, 5, 100).resets_opacity_at(9000));
  CHECK(DensityControl(reset_cfg, 5, 100).resets_opacity_at(18000));
  CHECK(dc.refines_at(59700));
  CHECK_FALSE(dc.refines_at(60000));  // stop
  CHECK(dc.accumulates_at(29000));
  CHECK_FALSE(dc.accumulates_at(29001));
  CHECK_FALSE(dc.accumulates_at(32000));
  CHECK(dc.accumulates_at(32001));
  CHECK_FALSE(dc.accumulates_at(60000));
  CHECK(dc.resets_opacity_at(27000));
  CHECK_FALSE(dc.resets_opacity_at(63000));

  // Pause boundaries at a finer period: begin is exclusive, end inclusive.
  DensifyConfig fine = cfg;
  fine.refine_every = 100;
  fine.reset_every = 3000;
  const DensityControl df(fine, 5, 100);  // pause after reset: 200
  CHECK(df.refines_at(29000));
  CHECK_FALSE(df.refines_at(32000));
  CHECK(df.refines_at(32300));
  CHECK_FALSE(df.refines_at(33100));  // 33000 is a reset: 100 < 200

  // The default has no pause after a reset and stops at 15000.
  const DensityControl dd(DensifyConfig::gsplat_default(), 1, 100);
  CHECK(dd.pause_after_reset() == 0);
  CHECK(dd.refines_at(3000));
  CHECK(dd.refines_at(14900));
  CHECK_FALSE(dd.refines_at(15000));
}

TEST_CASE("a scaled configuration keeps the shape of the schedule") {
  const DensifyConfig s = DensifyConfig::msad().scaled(ScheduleScale{0.05});
  CHECK(s.refine_start == 25);
  CHECK(s.refine_stop == 3000);
  CHECK(s.refine_every == 15);
  CHECK(s.reset_every == 450);  // still 30 x refine_every
  CHECK(s.screen_stop == 200);
  CHECK(s.pause_after_reset_for(100) == 5 + 15);
  CHECK(s.grow_grad2d == DensifyConfig::msad().grow_grad2d);  // thresholds are not steps
  // Rounding would break 30 x refine_every; the ratio is kept instead.
  const DensifyConfig r = DensifyConfig::msad().scaled(ScheduleScale{0.033});
  CHECK(r.refine_every == 10);
  CHECK(r.reset_every == 300);
  const DensityControl dc(s, 5, 500);  // pause 25 + 15 = 40 < 450
  CHECK(dc.refines_at(60));
  CHECK_FALSE(dc.refines_at(465));
  CHECK(dc.refines_at(495));
  CHECK(dc.resets_opacity_at(450));
}

TEST_CASE("statistics reset after each refine and stop accumulating at refine_stop") {
  DensityControl dc(DensifyConfig::gsplat_default(), 1, 0);
  Model m = make_model(2);
  dc.observe(550, 0, std::vector<float>{0.f, 0.f, 1e-6f, 0.f}, radii_all(2, 1), 100, 100);
  CHECK(dc.stats().count(1, 0) == 1);
  dc.step_post_backward(600, m);
  REQUIRE(dc.stats().size() == m.size());
  for (std::size_t i = 0; i < m.size(); ++i) {
    CHECK(dc.stats().count(i, 0) == 0);
    CHECK(dc.stats().grad_sum(i, 0) == 0.0f);
    CHECK(dc.stats().max_radius(i) == 0.0f);
  }
  dc.observe(15000, 0, std::vector<float>{1.f, 1.f, 1.f, 1.f}, radii_all(2, 1), 100, 100);
  CHECK(dc.stats().count(0, 0) == 0);
  // Gradients for a model of another size are refused until the statistics are reset.
  CHECK_THROWS_AS(dc.observe(601, 0, std::vector<float>(6), radii_all(3, 1), 100, 100), std::invalid_argument);
  dc.reset_stats(3);
  dc.observe(601, 0, std::vector<float>(6), radii_all(3, 1), 100, 100);
  CHECK(dc.stats().count(2, 0) == 1);
  CHECK_THROWS_AS(dc.observe(602, 1, std::vector<float>(6), radii_all(3, 1), 100, 100), std::invalid_argument);
}

TEST_CASE("presets and validation") {
  const DensifyConfig a = DensifyConfig::msad();
  CHECK(a.grow_grad2d == 0.0008);
  CHECK(a.absgrad);
  CHECK(a.per_band);
  CHECK(a.prune_opacity == 0.1);
  CHECK(a.prune_scale3d == 0.5);
  CHECK(a.reset_opacity == 0.2);
  CHECK(a.reset_every == 30 * a.refine_every);
  CHECK(a.screen_stop == 4000);
  const DensifyConfig d = DensifyConfig::gsplat_default();
  CHECK(d.grow_grad2d == 0.0002);
  CHECK_FALSE(d.absgrad);
  CHECK_FALSE(d.per_band);
  CHECK(d.prune_opacity == 0.005);
  CHECK(d.prune_scale3d == 0.1);
  CHECK(d.reset_opacity == 0.01);
  CHECK(d.refine_every == 100);
  CHECK(d.refine_stop == 15000);
  CHECK(d.reset_every == 3000);
  a.validate();
  d.validate();
  DensifyConfig bad = a;
  bad.refine_every = 0;
  CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("refine_every"), std::invalid_argument);
  bad = a;
  bad.reset_opacity = 1.0;
  CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("reset_opacity"), std::invalid_argument);
  bad = a;
  bad.pause_end = -1;
  CHECK_THROWS_AS(bad.validate(), std::invalid_argument);
  // A pause after resets as long as the reset period would silently disable densification.
  bad = a;
  bad.pause_after_reset = a.reset_every;
  CHECK_THROWS_AS(DensityControl(bad, 1, 0), std::invalid_argument);
  CHECK_THROWS_AS(DensityControl(a, 1, 9000), std::invalid_argument);
  CHECK_THROWS_AS(DensityControl(a, 0, 10), std::invalid_argument);
  CHECK_THROWS_AS(DensityControl(a, 1, 10, 0.0), std::invalid_argument);
}

TEST_CASE("statistics over a row list equal the statistics over every row when the others were not seen") {
  const std::size_t n = 9000;  // several parallel chunks
  std::vector<float> g(2 * n);
  std::vector<std::int32_t> radii(2 * n, 0);
  std::vector<std::uint32_t> rows;
  for (std::size_t i = 0; i < n; ++i) {
    g[2 * i] = float(i % 13) * 0.01f - 0.05f;
    g[2 * i + 1] = float(i % 7) * 0.02f;
    if (i % 3 != 1) {  // seen
      radii[2 * i] = 1 + int(i % 5);
      radii[2 * i + 1] = 2;
      rows.push_back(std::uint32_t(i));
    } else {
      g[2 * i] = std::numeric_limits<float>::quiet_NaN();  // stale gradients of rows the view did not see
    }
  }
  g[2 * 3] = std::numeric_limits<float>::infinity();  // a seen row with a non-finite gradient is skipped either way
  DensityStats all(n, 2), listed(n, 2);
  for (int band : {0, 1, 0}) {
    all.add(band, g, radii, 640, 480);
    listed.add(band, g, radii, 640, 480, &rows);
  }
  CHECK(all.grad_sums() == listed.grad_sums());
  CHECK(all.counts() == listed.counts());
  CHECK(all.max_radii() == listed.max_radii());
  CHECK(listed.count(0, 0) == 2);
  CHECK(listed.count(1, 0) == 0);
  CHECK(listed.count(3, 0) == 0);
  const std::vector<std::uint32_t> outside = {std::uint32_t(n)};
  CHECK_THROWS_AS(listed.add(0, g, radii, 640, 480, &outside), std::invalid_argument);
}

TEST_CASE("in-place row application equals a plain out-of-place copy for random plans, planes, growth and shrinkage") {
  std::mt19937 rng(11);
  std::vector<float> spare;  // reused across trials, as a refinement reuses it: sizes up and down
  for (int trial = 0; trial < 200; ++trial) {
    const std::size_t n = 1 + rng() % 60, planes = 1 + rng() % 3, w = 1 + rng() % 5;
    // A refinement-like plan (ascending survivors, then copies, fresh and new rows) or an arbitrary one.
    RefinePlan plan;
    plan.input_size = n;
    const bool arbitrary = trial % 4 == 3;
    for (std::size_t i = 0; i < n; ++i)
      if (arbitrary ? rng() % 3 != 0 : rng() % 4 != 0) {
        plan.source.push_back(arbitrary ? std::uint32_t(rng() % n) : std::uint32_t(i));
        plan.fresh.push_back(false);
      }
    const std::size_t extra = rng() % (2 * n);
    for (std::size_t e = 0; e < extra; ++e) {
      const bool none = rng() % 5 == 0;
      plan.source.push_back(none ? RefinePlan::none : std::uint32_t(rng() % n));
      plan.fresh.push_back(none || rng() % 2 == 0);
    }
    std::vector<float> rows(planes * n * w);
    for (std::size_t k = 0; k < rows.size(); ++k) rows[k] = float(k) + 0.5f;
    for (const bool zero_fresh : {false, true}) {
      INFO("trial ", trial, " zero_fresh ", zero_fresh);
      std::vector<float> want(planes * plan.size() * w, 0.0f);
      for (std::size_t q = 0; q < planes; ++q)
        for (std::size_t i = 0; i < plan.size(); ++i) {
          const std::uint32_t s = plan.source[i];
          if (s == RefinePlan::none || (zero_fresh && plan.fresh[i])) continue;
          for (std::size_t a = 0; a < w; ++a) want[(q * plan.size() + i) * w + a] = rows[(q * n + s) * w + a];
        }
      std::vector<float> got = rows;
      detail::apply_rows_impl(plan, got, w, zero_fresh, "test", planes);
      CHECK(got == want);
      std::vector<float> gathered = rows;
      detail::gather_rows(plan, gathered, spare, w, planes, zero_fresh, "test");
      CHECK(gathered == want);
      CHECK(spare.size() == rows.size());  // the spare holds the old values' memory
    }
  }
}

TEST_CASE("parallel_move equals memmove for overlapping moves up and down, in waves and serial") {
  // Shifts below, at and above the wave threshold (2^16 values), moves longer and shorter than
  // the shift, up and down; the buffer holds distinct values so any misplaced one shows.
  const std::size_t n = 300000;
  for (const std::size_t d : {std::size_t(1), std::size_t(100), std::size_t(65536), std::size_t(70001),
                              std::size_t(150000), std::size_t(400000)})
    for (const std::size_t len : {std::size_t(1000), std::size_t(200000), n})
      for (const bool up : {true, false}) {
        INFO("shift ", d, " length ", len, " up ", up);
        std::vector<std::uint32_t> want(n + d + 16), got;
        for (std::size_t k = 0; k < want.size(); ++k) want[k] = std::uint32_t(k * 2654435761u);
        got = want;
        const std::size_t src = up ? 3 : 3 + d, dst = up ? 3 + d : 3;
        std::memmove(want.data() + dst, want.data() + src, len * sizeof(std::uint32_t));
        detail::parallel_move(got.data() + dst, got.data() + src, len);
        CHECK(got == want);
      }
}

TEST_CASE("in-place row application of a large plan equals the plain copy (parallel restride of the planes)") {
  // Large enough for the restride moves of the planes to run in parallel waves.
  std::mt19937 rng(5);
  for (const bool grow : {true, false}) {
    const std::size_t n = 60000, planes = 3, w = 16;
    RefinePlan plan;
    plan.input_size = n;
    for (std::size_t i = 0; i < n; ++i)
      if (rng() % 10 != 0) {
        plan.source.push_back(std::uint32_t(i));
        plan.fresh.push_back(false);
      }
    const std::size_t extra = grow ? n / 5 : n / 50;
    for (std::size_t e = 0; e < extra; ++e) {
      plan.source.push_back(std::uint32_t(rng() % n));
      plan.fresh.push_back(rng() % 2 == 0);
    }
    std::vector<float> rows(planes * n * w);
    for (std::size_t k = 0; k < rows.size(); ++k) rows[k] = float(k % 1000003) + 0.25f;
    std::vector<float> want(planes * plan.size() * w, 0.0f);
    for (std::size_t q = 0; q < planes; ++q)
      for (std::size_t i = 0; i < plan.size(); ++i) {
        if (plan.fresh[i]) continue;
        for (std::size_t a = 0; a < w; ++a) want[(q * plan.size() + i) * w + a] = rows[(q * n + plan.source[i]) * w + a];
      }
    detail::apply_rows_impl(plan, rows, w, true, "test", planes);
    CHECK(rows == want);
  }
}

TEST_CASE("Morton codes: spatial order within the bounding box, ties in row order, non-finite points last") {
  // Two clusters far apart, listed interleaved: sorted, each cluster's points are consecutive.
  std::vector<float> pts;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> jitter(-0.5f, 0.5f);
  for (int i = 0; i < 20; ++i) {
    const float cx = i % 2 == 0 ? 0.0f : 100.0f;
    for (int a = 0; a < 3; ++a) pts.push_back(cx + jitter(rng));
  }
  const std::vector<std::uint32_t> order = order_by_code(morton_codes(pts.data(), 20));
  REQUIRE(order.size() == 20);
  for (int k = 0; k < 10; ++k) CHECK(order[std::size_t(k)] % 2 == order[0] % 2);
  for (int k = 10; k < 20; ++k) CHECK(order[std::size_t(k)] % 2 != order[0] % 2);
  // Along one axis the order is the order of the coordinate (x fills the lowest bit of each triple).
  const std::vector<float> line = {3, 0, 0, 1, 0, 0, 2, 0, 0, 0, 0, 0};
  CHECK(order_by_code(morton_codes(line.data(), 4)) == std::vector<std::uint32_t>{3, 1, 2, 0});
  // Equal points keep their rows' order; a NaN or infinite coordinate sorts last; a single point or
  // a flat box (zero extent on an axis) is no special case.
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  const std::vector<float> odd = {nan, 0, 0, 1, 1, 1, 0, 0, inf, 1, 1, 1, 0, 0, 0};
  const std::vector<std::uint64_t> c = morton_codes(odd.data(), 5);
  CHECK(c[0] == ~std::uint64_t(0));
  CHECK(c[2] == ~std::uint64_t(0));
  CHECK(c[1] == c[3]);
  CHECK(order_by_code(c) == std::vector<std::uint32_t>{4, 1, 3, 0, 2});
  const float one[3] = {5, -2, 7};
  CHECK(morton_codes(one, 1) == std::vector<std::uint64_t>{0});
  // Coordinates at float's limits still get finite codes (and so do doubles whose extent overflows).
  const float big = std::numeric_limits<float>::max();
  const std::vector<float> wide = {-big, 0, 0, big, 0, 0};
  const std::vector<std::uint64_t> cw = morton_codes(wide.data(), 2);
  CHECK(cw[0] != ~std::uint64_t(0));
  CHECK(cw[1] != ~std::uint64_t(0));
  const double dbig = std::numeric_limits<double>::max();
  const std::vector<double> dwide = {-dbig, 0, 0, dbig, 0, 0};
  CHECK(morton_codes(dwide.data(), 2) == std::vector<std::uint64_t>{0, 0});
  CHECK(morton_codes(wide.data(), 0).empty());
}

TEST_CASE("reorder timing: every reorder_every-th refinement and the last one before a pause or the stop") {
  DensifyConfig cfg = DensifyConfig::gsplat_default();  // refine every 100 from 500 to 15000, reset every 3000
  CHECK(cfg.reorder_every == 8);                       // on by default: it changes no result
  CHECK(DensityControl(cfg, 1, 0).reorders_at(800));
  CHECK_FALSE(DensityControl(cfg, 1, 0).reorders_at(400));
  cfg.reorder_every = 0;                               // gsplat's row order
  CHECK_FALSE(DensityControl(cfg, 1, 0).reorders_at(800));
  cfg.reorder_every = 4;
  cfg.pause_begin = 6150;
  cfg.pause_end = 7000;
  const DensityControl dc(cfg, 1, 0);
  CHECK(dc.reorders_at(800));         // a multiple of 4 x 100
  CHECK_FALSE(dc.reorders_at(900));
  CHECK_FALSE(dc.reorders_at(850));   // no refinement there
  CHECK(dc.reorders_at(6100));        // the last refinement before the pause
  CHECK_FALSE(dc.reorders_at(5900));
  CHECK_FALSE(dc.reorders_at(6200));  // paused
  CHECK_FALSE(dc.reorders_at(7100));  // refinements go on after the pause
  CHECK(dc.reorders_at(14900));       // the last refinement before refine_stop
  CHECK_FALSE(dc.reorders_at(14700));
  CHECK_FALSE(dc.reorders_at(15200)); // past refine_stop: no refinement at all
  cfg.reorder_every = -1;
  CHECK_THROWS_AS(cfg.validate(), std::invalid_argument);
  cfg.reorder_every = 1000001;
  CHECK_THROWS_AS(cfg.validate(), std::invalid_argument);
}

TEST_CASE("a reordering refinement is the plain refinement followed by a sort of its result") {
  // Gaussians at random places: some duplicated, some split (large), some pruned (faint).
  const std::size_t n = 64;
  Model m = make_model(n);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> pos(-5.0f, 5.0f);
  std::vector<double> ndc(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) m.means[3 * i + a] = pos(rng);
    if (i % 5 == 1) m.log_scales[3 * i] = float(std::log(0.05));  // large: split
    if (i % 7 == 3) m.opacity_logits[i] = float(logit(0.001));    // faint: pruned
    ndc[i] = i % 3 == 0 ? 0.01 : 0.0;
  }
  DensifyConfig cfg = DensifyConfig::gsplat_default();
  Model plain = m, sorted = m;
  Model avg_plain = make_model(n), avg_sorted = make_model(n);
  DensityControl dp(cfg, 1, 0);
  cfg.reorder_every = 2;
  DensityControl ds(cfg, 1, 0);
  REQUIRE(ds.reorders_at(1000));
  for (DensityControl* dc : {&dp, &ds}) dc->observe(1000, 0, grads_with_ndc_norm(ndc, 64).mean2d, radii_all(n, 1), 64, 64);
  const DensifyReport rp = dp.step_post_backward(1000, plain, avg_plain);
  const DensifyReport rs = ds.step_post_backward(1000, sorted, avg_sorted);
  REQUIRE(rp.refined);
  REQUIRE(rs.refined);
  CHECK(rs.counts.duplicated == rp.counts.duplicated);
  CHECK(rs.counts.split == rp.counts.split);
  CHECK(rs.counts.pruned == rp.counts.pruned);
  CHECK(rp.counts.duplicated > 0);
  CHECK(rp.counts.split > 0);
  CHECK(rp.counts.pruned > 0);
  REQUIRE(sorted.size() == plain.size());
  sorted.check_consistent();
  // Row f of the sorted result is row order[f] of the plain one, for the model (split samples
  // included: their draws do not depend on where they end up) and for the optimiser state.
  const std::vector<std::uint32_t> order = order_by_code(morton_codes(plain.means.data(), plain.size()));
  CHECK(order != RefinePlan::identity(plain.size()).source);
  for (std::size_t f = 0; f < sorted.size(); ++f) {
    CHECK(same_row(sorted, f, plain, order[f]));
    CHECK(same_row(avg_sorted, f, avg_plain, order[f]));
    CHECK(rs.plan.source[f] == rp.plan.source[order[f]]);
    CHECK(rs.plan.fresh[f] == rp.plan.fresh[order[f]]);
  }
  // The result is in spatial order: sorting it again changes nothing.
  CHECK(order_by_code(morton_codes(sorted.means.data(), sorted.size())) == RefinePlan::identity(sorted.size()).source);
}

}  // namespace test_densify
