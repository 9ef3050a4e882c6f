// bench/bench_loss.cpp
// Google Benchmark of the photometric loss (L1 + SSIM) with its gradient, reported as pixels/s.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <random>

#include "msgs/loss.hpp"
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

namespace {

msgs::Image<float> random_image(int w, int h, int c, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  msgs::Image<float> im(w, h, c);
  for (auto& v : im.data) v = u(rng);
  return im;
}

/// Arguments: width, height, channels. One iteration = loss value + full gradient, workspace reused
/// as in training.
void BM_PhotometricLossGrad(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1)),
            c = static_cast<int>(state.range(2));
  const auto render = random_image(w, h, c, 1);
  const auto gt = random_image(w, h, c, 2);
  msgs::Image<float> grad;
  msgs::SsimWorkspace<float> ws;
  for (auto _ : state) {
    const double loss = msgs::photometric_loss(render, gt, &grad, ws);
    benchmark::DoNotOptimize(loss);
    benchmark::DoNotOptimize(grad.data.data());
  }
  const double pixels = static_cast<double>(w) * h;
  state.counters["pixels/s"] =
      benchmark::Counter(pixels * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["values/s"] =
      benchmark::Counter(pixels * c * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

/// Loss value only (the evaluation path: SSIM forward without the derivative maps).
void BM_PhotometricLossValue(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0)), h = static_cast<int>(state.range(1)),
            c = static_cast<int>(state.range(2));
  const auto render = random_image(w, h, c, 1);
  const auto gt = random_image(w, h, c, 2);
  msgs::SsimWorkspace<float> ws;
  for (auto _ : state) {
    const double loss = msgs::photometric_loss(render, gt, static_cast<msgs::Image<float>*>(nullptr), ws);
    benchmark::DoNotOptimize(loss);
  }
  state.counters["pixels/s"] = benchmark::Counter(static_cast<double>(w) * h * static_cast<double>(state.iterations()),
                                                  benchmark::Counter::kIsRate);
}

void sizes(benchmark::internal::Benchmark* b) {
  for (int c : {1, 3})
    for (auto [w, h] : {std::pair{256, 256}, std::pair{640, 480}, std::pair{1280, 720}}) b->Args({w, h, c});
  b->ArgNames({"w", "h", "c"});
  b->Unit(benchmark::kMillisecond);
  b->UseRealTime();  // OpenMP: CPU time of the main thread alone would flatter the rate
}

}  // namespace

BENCHMARK(BM_PhotometricLossGrad)->Apply(sizes);
BENCHMARK(BM_PhotometricLossValue)->Apply(sizes);

BENCHMARK_MAIN();
