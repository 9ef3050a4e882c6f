// bench/bench_blend_kernels.cpp
// Google Benchmark of the arithmetic every evaluated 16-lane vector of the blend pays, forward and
// backward alike, before any blending: the falloff exp(-sigma) alone, and sigma, exponential and
// alpha as the blend's passes 2 and 3 compute them (detail::BlendBatch). Inputs are cache
// resident, so these rates are what the core can do, not what memory allows: a frame's blend
// forward costs at least its evaluated vectors (`bench_train_step`'s fragments / lane_use / 16)
// times s_per_vector here, and the backward pays it again for every vector it evaluates anew.
//   ./bench_blend_kernels
#include <benchmark/benchmark.h>

#include <msgs/blend.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

using namespace msgs;

namespace {

using BV = detail::BlockVec<float>;
using V = BV::V;

/// Reports vectors/s and ns per vector for `vectors` vectors an iteration.
void rate(benchmark::State& state, double vectors) {
  const double total = vectors * static_cast<double>(state.iterations());
  state.counters["vectors/s"] = benchmark::Counter(total, benchmark::Counter::kIsRate);
  state.counters["s_per_vector"] = benchmark::Counter(total, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

/// exp(-sigma) of 256 independent vectors (16 KiB, in L1), sigma spread over [0, 20] as in a blend.
void BM_Falloff(benchmark::State& state) {
  constexpr int n = 256;
  std::vector<V> sigma(n), out(n);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 20.0f);
  for (V& v : sigma)
    for (int l = 0; l < BV::kLanes; ++l) v[l] = u(rng);
  for (auto _ : state) {
    for (int i = 0; i < n; ++i) detail::exp_neg_into(out[std::size_t(i)], sigma[std::size_t(i)]);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  rate(state, n * BV::kChunks);
}

/// Sigma, exponential and alpha of every chunk of 16 splats' 16 blocks each (one batch of a tile's
/// list, all its chunks listed): BlendBatch's passes 2 and 3 without the listing test.
void BM_SigmaAlpha(benchmark::State& state) {
  using TBk = detail::TileBlocks;
  constexpr int NH = BV::kChunks;
  V lx[NH], ly[NH];
  detail::block_lane_offsets<float>(lx, ly);
  const detail::TileCentres<float> centres(lx, ly, 32, 48);
  detail::BlendBatch<float, 1> batch;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(32.0f, 48.0f), inv(0.05f, 0.5f), op(0.05f, 0.99f);
  const float colour = 0.5f;
  for (int k = 0; k < kBlendBatch; ++k) {
    Splat<float> s{};
    s.mx = pos(rng);
    s.my = pos(rng) + 16.0f;
    s.a = inv(rng);
    s.c = inv(rng);
    s.b = 0.25f * std::min(s.a, s.c);
    s.o = op(rng);
    set_sigma_cut(s, std::log(255.0 * double(s.o)));
    batch.add(k, s, &colour, 1, 0xffffu);
  }
  V max_alpha;
  detail::broadcast(max_alpha, BlendConstants<float>::kMaxAlpha);
  for (auto _ : state) {
    batch.chunks = 0;
    for (int i = 0; i < batch.blocks; ++i) {
      const int b = batch.block[i], k = batch.block_splat[i];
      for (int h = 0; h < NH; ++h)
        batch.list(b * NH + h, k, batch.sigma_of[k].at(centres, b % TBk::kPerSide, b / TBk::kPerSide, h), true);
    }
    batch.alphas(max_alpha);
    benchmark::DoNotOptimize(batch.alpha);
    benchmark::ClobberMemory();
  }
  rate(state, double(kBlendBatch) * TBk::kCount * NH);
}

BENCHMARK(BM_Falloff);
BENCHMARK(BM_SigmaAlpha);

}  // namespace

BENCHMARK_MAIN();
