// bench/bench_bin.cpp
// Stage 2 of the rasteriser alone: bin_gaussians (depth sort, tile count, tile scatter) on a frame
// shaped like the demo's (240x180, 82k Gaussians of which about 60% visible, splats of 1 to 4
// tiles: about 1.7 pairs each) and on a larger one (1280x960, 1M Gaussians). Uses the public API
// only (pixel_rect, bin_gaussians, and for BM_BinTiesByMean TiesByMean, in bin.hpp since
// 2026-11-30), so BM_Bin builds against older headers for a side-by-side run. Reports splats/s
// (visible Gaussians binned per second) and pairs.
//   ./build/bench/bench_bin --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>
#include <vector>

#include <msgs/bin.hpp>

namespace {

using namespace msgs;

struct Frame {
  TileGrid grid;
  std::vector<float> depth;
  std::vector<PixelRect> rects;
  std::vector<std::uint32_t> visible;
};

/// n Gaussians, about 59% visible, uniform depths in [2, 30] (some tied, as clones and parents
/// are), extents up to `max_extent` pixels.
Frame frame(int width, int height, std::size_t n, double max_extent) {
  Frame f;
  f.grid = TileGrid(width, height);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> z(2.f, 30.f), x(0.f, float(width)), y(0.f, float(height)),
      e(1.f, float(max_extent));
  f.depth.resize(n);
  f.rects.resize(n);
  for (std::size_t g = 0; g < n; ++g) {
    f.depth[g] = g > 0 && rng() % 10 == 0 ? f.depth[g - 1] : z(rng);
    const double ext = e(rng);
    f.rects[g] = pixel_rect(x(rng), y(rng), ext, ext, width, height);
    if (rng() % 1000 < 594 && !f.rects[g].empty()) f.visible.push_back(std::uint32_t(g));
  }
  return f;
}

void BM_Bin(benchmark::State& st) {
  const bool large = st.range(0) != 0;
  const Frame f = large ? frame(1280, 960, 1000000, 12.0) : frame(240, 180, 82000, 5.0);
  Binning b;
  for (auto _ : st) {
    bin_gaussians(f.visible, f.depth.data(), f.rects.data(), f.grid, b);
    benchmark::DoNotOptimize(b.tile_list.data());
  }
  st.counters["pairs"] = double(b.pairs());
  st.counters["splats/s"] = benchmark::Counter(double(f.visible.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Bin)->ArgName("large")->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMicrosecond);

/// BM_Bin with ties ordered by the means' bits (TiesByMean, new on 2026-11-30), as `msgs train`
/// bins (about 7% of the visible Gaussians tie with a neighbour in depth order on the large
/// frame).
void BM_BinTiesByMean(benchmark::State& st) {
  const bool large = st.range(0) != 0;
  const Frame f = large ? frame(1280, 960, 1000000, 12.0) : frame(240, 180, 82000, 5.0);
  std::vector<float> means(3 * f.depth.size());
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (float& m : means) m = u(rng);
  Binning b;
  const TiesByMean<float> key{means.data()};
  for (auto _ : st) {
    bin_gaussians(f.visible, f.depth.data(), f.rects.data(), f.grid, b, key);
    benchmark::DoNotOptimize(b.tile_list.data());
  }
  st.counters["pairs"] = double(b.pairs());
  st.counters["splats/s"] = benchmark::Counter(double(f.visible.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_BinTiesByMean)->ArgName("large")->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
