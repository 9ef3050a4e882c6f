// bench/bench_refine.cpp
// One refinement's moves: a plan applied to a Joint model (Gaussian<7, 3>) and both Adam moments,
// as DensityControl applies it (detail::apply_arrays through spare arrays kept between refinements). A share of the rows is removed and as
// many new Gaussians (copies of random rows) are added, in the two row orders a refinement can
// produce:
//   holes:  survivors stay in their rows, the new Gaussians take the removed rows (the default
//           between spatial sorts): only the changed rows are written;
//   gsplat: survivors in order, the new Gaussians appended (reorder_every = 0): every row after the
//           first removed one moves, so the arrays are gathered whole.
// Reports rows/s (the model's rows per second of refinement) and the changed rows.
// Arguments: Gaussians, removed rows per thousand.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <vector>

#include <msgs/densify.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

namespace {

using namespace msgs;
using G = Gaussian<7, 3>;
using Model = GaussianModel<G, float>;

/// n Gaussians with arbitrary values, planes with room to spare (as after a refinement).
Model filled(std::size_t n, std::uint32_t seed) {
  Model m(n);
  std::mt19937 rng(seed);
  for (auto* v : {&m.means, &m.log_scales, &m.quats, &m.opacity_logits, &m.sh})
    for (float& x : *v) x = float(rng() % 1024) / 64.0f;
  std::vector<float> spare;
  apply(RefinePlan::append(n, 0), m, spare);  // no change: the planes keep their room
  return m;
}

/// Remove `removed` random rows of n and add as many copies of random survivors, in either order.
RefinePlan churn(std::size_t n, std::size_t removed, bool holes, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<bool> gone(n, false);
  for (std::size_t k = 0; k < removed;) {
    const std::size_t i = rng() % n;
    if (!gone[i]) gone[i] = true, ++k;
  }
  auto survivor = [&] {
    for (;;) {
      const std::uint32_t s = std::uint32_t(rng() % n);
      if (!gone[s]) return s;
    }
  };
  RefinePlan p;
  p.input_size = n;
  if (holes) {
    for (std::size_t i = 0; i < n; ++i) {
      p.source.push_back(gone[i] ? survivor() : std::uint32_t(i));
      p.fresh.push_back(gone[i]);
    }
  } else {
    for (std::size_t i = 0; i < n; ++i)
      if (!gone[i]) p.source.push_back(std::uint32_t(i)), p.fresh.push_back(false);
    for (std::size_t k = 0; k < removed; ++k) p.source.push_back(survivor()), p.fresh.push_back(true);
  }
  return p;
}

void BM_Refine(benchmark::State& state, bool holes) {
  const std::size_t n = std::size_t(state.range(0)), removed = n * std::size_t(state.range(1)) / 1000;
  Model model = filled(n, 1), m1 = filled(n, 2), m2 = filled(n, 3);
  std::vector<float> spare;  // DensityControl keeps these between refinements
  detail::GeometrySpares<float> geometry;
  std::uint32_t seed = 7;
  const auto refine = [&](const RefinePlan& plan) {
    detail::apply_arrays(plan, model, false, &spare, "model", &geometry);  // as DensityControl
    detail::apply_arrays(plan, m1, true, &spare, "exp_avg", &geometry);
    detail::apply_arrays(plan, m2, true, &spare, "exp_avg_sq", &geometry);
  };
  for (int warm = 0; warm < 2; ++warm) refine(churn(n, removed, false, seed++));  // the spares exist
  std::size_t changed = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const RefinePlan plan = churn(n, removed, holes, seed++);
    changed = detail::changed_rows(plan, true).size();
    state.ResumeTiming();
    refine(plan);
    benchmark::DoNotOptimize(model.sh.data());
  }
  state.counters["rows/s"] = benchmark::Counter(double(n) * double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["changed_rows"] = double(changed);
}

}  // namespace

BENCHMARK_CAPTURE(BM_Refine, holes, true)
    ->ArgsProduct({{100000, 1000000}, {10, 50, 200}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Refine, gsplat, false)
    ->ArgsProduct({{100000, 1000000}, {10, 50, 200}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
