// bench/bench_train_step.cpp
// Google Benchmark of ONE WHOLE TRAINING STEP, composed as Trainer::train in train.hpp does it:
// forward of one band, photometric loss (L1 + SSIM) with its gradient image and the running PSNR,
// backward, the scale regulariser every 10th step, Adam with the band's mask and the density
// statistics (MSAD per-band accumulators). Refinement (step_post_backward) is left out: it runs
// every few hundred steps, not every step. Models: B1_SH3 (Gaussian<1, 3>), B3_SH3 (Gaussian<3, 3>,
// all three channels rendered) and B7_SH3_band3 (Gaussian<7, 3> rendering channel 3 alone, the same
// geometry as B1_SH3); the "_half" scenes move about half of the Gaussians out of the view, as in
// real training where a view sees only part of the model, with the seen and unseen ones interleaved
// in memory; "_half_ordered" is the same scene in spatial order (spatial_order.hpp), the order in
// which training keeps its models (DensifyConfig::reorder_every).
//
// Counters: steps/s, gaussians/s (N per step), visible (Gaussians the view saw), bytes_per_step
// (the memory traffic a step cannot avoid, see step_bytes below), triad_GBps (a STREAM triad
// measured in this binary at the case's thread count) and bound_ratio = measured seconds per step /
// (bytes_per_step / triad bandwidth): 1 would be a step running at the memory bound.
// bound_ratio_visible is the same for the Gaussians the view saw only (the bound of a step that
// touches only those). forward_ms, loss_ms, backward_ms (with the regulariser), adam_ms and
// stats_ms split the step into its stages (milliseconds per step); project_ms, bin_ms and blend_ms
// split the forward, blend_backward_ms and gaussians_backward_ms the backward. fragments (blended
// pixel-Gaussian pairs), intersections (Gaussian-tile pairs), blend_ns_per_fragment (blend
// forward + backward per fragment) and lane_use (the share of the blend's evaluated lanes that
// blended) measure the per-pixel work, which the bound does not count. Except in the dense_zeroed
// cases, the colour update of the visible Gaussians runs inside the backward (as in training,
// TrainOptions::fused_colour) and counts in gaussians_backward_ms, not in adam_ms.
//
//   ./build/bench/bench_train_step
//   ./build/bench/bench_train_step --benchmark_filter='100k_240x180' --benchmark_min_time=0.2   # the demo's image size
//   ./build/bench/bench_train_step --benchmark_filter='100k_640x480' --benchmark_min_time=0.2
//   MSGS_BENCH_LARGE=1 ./build/bench/bench_train_step --benchmark_filter='1M'   # 1M Gaussians, 1280x960
//   (8 steps per 1M case; MSGS_BENCH_ITERATIONS=N sets another count)
#include <benchmark/benchmark.h>

#include <msgs/adam.hpp>
#include <msgs/densify.hpp>
#include <msgs/loss.hpp>
#include <msgs/rasterize.hpp>
#include <msgs/schedule.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

#include "scene_family.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <map>
#include <optional>
#include <memory>
#include <random>
#include <span>
#include <string>
#include <vector>

using namespace msgs;
using msgs::bench::SceneSpec;

namespace {

/// The (N, resolution) grid: the demo's model size at the demo's full image size (the `small`
/// scene's 240x180; its early steps render at 1/4 and 1/2 of that), at 640x480 and at 1280x960;
/// 1M only with MSGS_BENCH_LARGE.
struct SizeCase {
  std::size_t n;
  int width, height;
  const char* name;
  bool half;  ///< also register the "_half" and "_half_ordered" scenes at this size
};
constexpr SizeCase kSizes[] = {
    {100000, 240, 180, "100k_240x180", true},
    {100000, 640, 480, "100k_640x480", true},
    {100000, 1280, 960, "100k_1280x960", false},
    {1000000, 1280, 960, "1M_1280x960", true},
};

SceneSpec spec_of(int size) { return bench::scene_spec(kSizes[size].n, kSizes[size].width, kSizes[size].height); }

/// The family model, or with `half` the family model with about half of the Gaussians (a seeded
/// coin per Gaussian, from its own stream so every band count moves the same ones) moved sideways
/// out of the view: x shifted by 6 away from the centre gives |x| in [4, 8] at z in [3, 5], i.e.
/// |x / z| >= 0.8 against the view's half-width of 0.5 W / fx = 0.625, farther than any footprint
/// (3 sigma <= 0.15). They are still in front of the camera, so projection does its full work on
/// them; the moved ones are interleaved with the seen ones in memory, as in a model refined in
/// gsplat's row order (survivors, then copies and split samples appended).
/// With `ordered`, the rows are then put into spatial order.
template <class G>
GaussianModel<G, float> scene_model(const SceneSpec& spec, bool half, bool ordered) {
  GaussianModel<G, float> m = bench::family_model<G, float>(spec);
  if (half) {
    std::mt19937_64 coin(spec.seed ^ 0x4a1f5e11d00dull);
    for (std::size_t i = 0; i < m.size(); ++i)
      if (coin() & 1u) m.means[3 * i] += m.means[3 * i] < 0 ? -6.0f : 6.0f;
  }
  if (ordered) apply(spatial_order_plan(m), m);
  return m;
}

/// The scenes of one size: every Gaussian in view, about half out of view (rows interleaved), and
/// the same half scene in spatial order.
enum class Variant { full, half, half_ordered };
const char* suffix(Variant v) { return v == Variant::full ? "" : v == Variant::half ? "_half" : "_half_ordered"; }

/// Bytes one step must move, the bound bound_ratio compares with. Every Gaussian the step touches
/// has P = 11 + 16 C floats that it updates: 11 geometry (mean 3, log-scale 3, quaternion 4,
/// opacity 1) and the K = 16 SH coefficients (degree 3) of each of the C rendered channels. For
/// each of them the step must at least read the parameter, its gradient and Adam's exp_avg and
/// exp_avg_sq (4 floats) and write the parameter, exp_avg and exp_avg_sq (3 floats):
///
///     bytes_per_step = touched x (4 + 3) x (11 + 16 C) x sizeof(float) = 28 (11 + 16 C) touched
///
/// e.g. 756 B per Gaussian for one channel, 1652 B for three. Everything else (the images, the
/// rasteriser's per-Gaussian and per-intersection buffers, the backward's writes of the gradients,
/// the density statistics, the other channels' SH) is extra, so this is a lower bound.
double step_bytes(std::size_t touched, int channels) {
  constexpr int kGeometry = 3 + 3 + 4 + 1;
  constexpr int kShPerChannel = 16;  // (3 + 1)^2
  return double(touched) * (4 + 3) * double(kGeometry + kShPerChannel * channels) * sizeof(float);
}

/// STREAM triad c[i] = a[i] + s b[i] over three 256 MiB arrays of doubles, OpenMP-parallel with
/// `threads` threads; bytes counted as 3 arrays x 256 MiB (write-allocate traffic not counted, as
/// STREAM). Best of 5 timed passes after one warm-up pass. Measured for 1 and 2 threads on the
/// first call and cached (the arrays are freed again before any step runs).
double triad_gbps(int threads) {
  static std::map<int, double> cache;
  if (cache.empty()) {
    constexpr std::size_t kBytes = std::size_t(256) << 20;
    constexpr std::ptrdiff_t n = std::ptrdiff_t(kBytes / sizeof(double));
    std::unique_ptr<double[]> a_buf(new double[n]), b_buf(new double[n]), c_buf(new double[n]);
    double *a = a_buf.get(), *b = b_buf.get(), *c = c_buf.get();
    const int saved = omp_get_max_threads();
    for (int t : {1, 2}) {
      omp_set_num_threads(t);
      // First touch with this thread count, so pages land where the threads run.
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t i = 0; i < n; ++i) {
        a[i] = 1.0;
        b[i] = 2.0;
        c[i] = 0.0;
      }
      double best = 1e30;
      for (int rep = 0; rep < 6; ++rep) {
        const double s = 0.5 + 1e-3 * rep;
        const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static)
        for (std::ptrdiff_t i = 0; i < n; ++i) c[i] = a[i] + s * b[i];
        const auto t1 = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(c);
        benchmark::ClobberMemory();
        if (rep > 0) best = std::min(best, std::chrono::duration<double>(t1 - t0).count());
      }
      cache[t] = 3.0 * double(kBytes) / best / 1e9;
    }
    omp_set_num_threads(saved);
  }
  const auto it = cache.find(threads);
  return it != cache.end() ? it->second : cache.rbegin()->second;
}

/// The trainer's rasteriser options, msgs::kTrainRaster in train.hpp (absgrad on: MSAD reads it).
/// Repeated here, as bench_memory does, so this benchmark does not pull in the trainer and its I/O.
constexpr RasterOptions kStepRaster{.absgrad = true, .single_precision = true};

/// One training step of a model of type G rendering channels [first, first + count). Every call
/// into the library a step makes is in this struct (constructor, step, touched), so that an API
/// change is adapted here only.
/// How the step updates what the view did not see. `dense`: as Trainer::train with dense Adam, the
/// unseen gradient rows never written and taken as zero by Adam (Unlisted::zero_gradient), except
/// at a step of the scale regulariser, and the colour update of the visible rows taken inside the
/// backward (TrainOptions::fused_colour); `dense_zeroed`: the same update with every gradient row
/// stored, the unseen ones zeroed by the backward, and read by Adam (GradientFill::dense, the
/// formulation before 2026-11-25, the same bits); `sparse`: TrainOptions::sparse, gradients, Adam
/// and the regulariser for the visible rows only, the colour update inside the backward.
enum class AdamMode { dense, dense_zeroed, sparse };

template <class G>
struct StepBench {
  GaussianModel<G, float> model;
  Camera<float> cam;
  Image<float> gt;
  int first, count;
  AdamMode mode;
  Adam<G, float> adam;
  DensityControl density;
  Rasterizer<G, float, kStepRaster> raster;
  Gradients<G, float> grads;
  Image<float> d_image;
  SsimWorkspace<float> ws;
  long long step_index = 1000;  // a step inside the densification window, a multiple of 10 first
  double loss = 0, psnr_value = 0;
  /// Seconds spent in each stage since the last reset: rasteriser forward, loss, rasteriser
  /// backward and the regulariser, Adam, density statistics.
  struct Stages {
    double forward = 0, loss = 0, backward = 0, adam = 0, stats = 0;
  } stages;

  /// The density control of the default (MSAD) configuration with refine_stop pushed out, so the
  /// statistics accumulate at every benchmarked step; one accumulator per model channel.
  static DensifyConfig densify_config() {
    DensifyConfig c = DensifyConfig::msad();
    c.refine_stop = INT_MAX;
    return c;
  }

  StepBench(const SceneSpec& spec, Variant v, int first_channel, int channels, AdamMode adam_mode)
      : model(scene_model<G>(spec, v != Variant::full, v == Variant::half_ordered)),
        cam(bench::family_camera<float>(spec)),
        // The target: a fixed seeded image in [0, 1) with the rendered band's channels.
        gt(bench::family_image_grad<float>(spec, channels)),
        first(first_channel),
        count(channels),
        mode(adam_mode),
        adam(AdamConfig{}, model.size()),
        density(densify_config(), G::bands, /*num_train_images=*/100) {}

  /// Forward, loss, backward, Adam, density statistics: Trainer::train's steps 2 to 6 without the
  /// strategy hooks (the mask is AdamMask::band, what the default hooks leave) and without refinement.
  void step() {
    using clock = std::chrono::steady_clock;
    const auto seconds = [](clock::time_point a, clock::time_point b) {
      return std::chrono::duration<double>(b - a).count();
    };
    const auto t0 = clock::now();
    RenderSettings<float> rs;
    rs.band_first = first;
    rs.band_count = count;
    rs.sh_degree = G::sh_degree;
    rs.background = random_background<float>(step_index, count, 0);
    const Image<float>& render = raster.forward(model, cam, rs);
    const auto t1 = clock::now();
    loss = photometric_loss(render, gt, &d_image, ws, PhotometricLossConfig{});
    psnr_value = psnr(render, gt);
    const auto t2 = clock::now();
    const std::vector<std::uint32_t>& seen = raster.visible();
    const bool reg_step = step_index % 10 == 0;  // TrainOptions::scale_reg_every
    const bool sparse = mode == AdamMode::sparse;
    const bool seen_only = sparse || (mode == AdamMode::dense && !reg_step);
    const std::vector<std::uint32_t>* rows = seen_only ? &seen : nullptr;
    const Unlisted unlisted = sparse ? Unlisted::untouched : Unlisted::zero_gradient;
    const bool fuse = mode != AdamMode::dense_zeroed;
    std::optional<typename Adam<G, float>::ColourStep> colour;
    if (fuse) colour.emplace(adam.begin_colour(model, first, count));
    raster.backward(d_image, nullptr, nullptr, grads, seen_only ? GradientFill::visible : GradientFill::dense,
                    fuse ? &*colour : nullptr);
    if (reg_step)
      scale_reg<float>(std::span<const float>(model.log_scales), std::span<float>(grads.model.log_scales),
                       ScaleRegConfig{}, rows);
    const auto t3 = clock::now();
    AdamMask mask = AdamMask::band(first, count);
    if (fuse) mask.sh = false;
    adam.step(model, grads.model, mask, rows, unlisted);
    if (fuse) adam.finish_colour(*colour, seen, unlisted);
    const auto t4 = clock::now();
    if (density.accumulates_at(step_index))
      density.observe_gradients(step_index, first, grads, raster.radii(), cam.width, cam.height, &seen);
    const auto t5 = clock::now();
    stages.forward += seconds(t0, t1);
    stages.loss += seconds(t1, t2);
    stages.backward += seconds(t2, t3);
    stages.adam += seconds(t3, t4);
    stages.stats += seconds(t4, t5);
    ++step_index;
  }

  /// Gaussians whose parameters and moments the step reads and writes: all of them for dense Adam
  /// (every row moves, seen or not), the visible ones for a sparse step.
  std::size_t touched() const { return mode == AdamMode::sparse ? raster.visible_count() : model.size(); }
  std::size_t visible() const { return raster.visible_count(); }
};

template <class G>
void bm_train_step(benchmark::State& st, int size, Variant v, int threads, int first, int count, AdamMode mode) {
  omp_set_num_threads(threads);
  const double gbps = triad_gbps(threads);
  omp_set_num_threads(threads);
  const SceneSpec spec = spec_of(size);
  StepBench<G> b(spec, v, first, count, mode);
  b.step();  // allocate the rasteriser, loss and gradient buffers before timing
  b.stages = {};
  b.raster.timings().reset();
  const auto t0 = std::chrono::steady_clock::now();
  for (auto _ : st) {
    b.step();
    benchmark::DoNotOptimize(b.model.means.data());
    benchmark::DoNotOptimize(b.loss);
    benchmark::DoNotOptimize(b.psnr_value);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() /
                         double(std::max<benchmark::IterationCount>(st.iterations(), 1));
  const double n = double(b.model.size());
  const double bytes = step_bytes(b.touched(), count);
  const double bytes_visible = step_bytes(b.visible(), count);
  auto& k = st.counters;
  k["steps/s"] = benchmark::Counter(1.0, benchmark::Counter::kIsIterationInvariantRate);
  k["gaussians/s"] = benchmark::Counter(n, benchmark::Counter::kIsIterationInvariantRate);
  k["visible"] = double(b.visible());
  k["bytes_per_step"] = bytes;
  k["triad_GBps"] = gbps;
  k["bound_ratio"] = seconds / (bytes / (gbps * 1e9));
  k["bound_ratio_visible"] = seconds / (bytes_visible / (gbps * 1e9));
  const double per_step_ms = 1e3 / double(std::max<benchmark::IterationCount>(st.iterations(), 1));
  k["forward_ms"] = b.stages.forward * per_step_ms;
  k["loss_ms"] = b.stages.loss * per_step_ms;
  k["backward_ms"] = b.stages.backward * per_step_ms;
  k["adam_ms"] = b.stages.adam * per_step_ms;
  k["stats_ms"] = b.stages.stats * per_step_ms;
  const RasterTimings& rt = b.raster.timings();  // the rasteriser's own split of forward and backward
  k["project_ms"] = rt.project * per_step_ms;
  k["bin_ms"] = rt.bin * per_step_ms;
  k["blend_ms"] = rt.blend * per_step_ms;
  k["blend_backward_ms"] = rt.blend_backward * per_step_ms;
  k["gaussians_backward_ms"] = rt.project_backward * per_step_ms;
  // The per-pixel work the bound leaves out: blended pixel-Gaussian pairs and Gaussian-tile pairs
  // of the last step, the blend's forward and backward time per fragment, and the share of the
  // lanes it evaluated that blended.
  const double fragments = double(b.raster.fragments());
  k["fragments"] = fragments;
  k["intersections"] = double(b.raster.intersections());
  k["blend_ns_per_fragment"] = fragments > 0 ? (rt.blend + rt.blend_backward) * per_step_ms * 1e6 / fragments : 0.0;
  const double lanes = double(b.raster.blend_lanes());
  k["lane_use"] = lanes > 0 ? fragments / lanes : 0.0;
}

void tune(benchmark::internal::Benchmark* b, int size) {
  b->UseRealTime()->Unit(benchmark::kMillisecond);
  // 1M: a fixed number of steps (MSGS_BENCH_ITERATIONS, default 8). The first steps after the
  // warm-up run slower for a 7-band model (2 steps measured 1.96x the 1-band step, 10 steps 1.19x),
  // so fewer than about 8 overstate its cost.
  if (kSizes[size].n >= 1000000) {
    const char* it = std::getenv("MSGS_BENCH_ITERATIONS");
    b->Iterations(it ? std::max(1, std::atoi(it)) : 8);
  }
}

template <class G>
void register_case(const std::string& tag, int size, Variant v, int threads, int first, int count) {
  for (const AdamMode mode : {AdamMode::dense, AdamMode::dense_zeroed, AdamMode::sparse}) {
    const char* mode_name = mode == AdamMode::dense ? "/dense" : mode == AdamMode::dense_zeroed ? "/dense_zeroed" : "/sparse";
    const std::string name = "train_step/" + tag + "/" + kSizes[size].name + suffix(v) + mode_name + "/threads:" +
                             std::to_string(threads);
    tune(benchmark::RegisterBenchmark(name.c_str(),
                                      [=](benchmark::State& st) {
                                        bm_train_step<G>(st, size, v, threads, first, count, mode);
                                      }),
         size);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const char* large = std::getenv("MSGS_BENCH_LARGE");
  constexpr int kAll = int(sizeof(kSizes) / sizeof(kSizes[0]));
  const int sizes = (large && std::string(large) != "0") ? kAll : kAll - 1;
  for (int size = 0; size < sizes; ++size)
    for (Variant v : {Variant::full, Variant::half, Variant::half_ordered}) {
      if (v != Variant::full && !kSizes[size].half) continue;
      for (int threads : {1, 2}) {
        register_case<Gaussian<1, 3>>("B1_SH3", size, v, threads, 0, 1);
        register_case<Gaussian<3, 3>>("B3_SH3", size, v, threads, 0, 3);
        // One narrow band of a Joint model: same geometry as B1_SH3 (same seed), channel 3 only.
        register_case<Gaussian<7, 3>>("B7_SH3_band3", size, v, threads, 3, 1);
      }
    }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
