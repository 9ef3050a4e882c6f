// bench/bench_memory.cpp
// Peak resident memory of one training step of a 1M-Gaussian Joint model (Gaussian<7, 3>) at
// 1280x720: forward of the RGB band, L1 + SSIM loss, backward, Adam. Target: under 3 GB.
//
// Counters (MiB): peak_rss (VmHWM over the step, reset before the benchmark when the kernel
// allows), then the RSS added by each phase (model, adam state, forward, loss, backward, adam
// step) and the sizes of the buffers that should dominate, computed from their element counts:
// model/gradients/moments (N x 123 floats each), per-Gaussian rasterizer buffers, and the
// per-intersection buffers (tile list, pair slots, row masks, gradient records). The rasterizer has
// the trainer's options (absgrad on, as msgs::kTrainRaster in train.hpp).
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include <msgs/adam.hpp>
#include <msgs/loss.hpp>
#include <msgs/rasterize.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

#include "scene_family.hpp"

namespace {

using namespace msgs;

constexpr double kMiB = 1024.0 * 1024.0;

/// A value of /proc/self/status in MiB ("VmRSS", "VmHWM"); -1 when unavailable.
double status_mib(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string prefix = std::string(key) + ":";
  while (std::getline(in, line))
    if (line.rfind(prefix, 0) == 0) return std::atof(line.c_str() + prefix.size()) / 1024.0;
  return -1.0;
}

/// Reset VmHWM to the current RSS (Linux >= 4.0); false when refused (then the peak is the process's).
bool reset_peak() {
  std::ofstream f("/proc/self/clear_refs");
  f << "5";
  f.flush();
  return bool(f);
}

template <class G>
double model_mib(std::size_t n) {
  return double(n) * double(3 + 3 + 4 + 1 + G::sh_floats) * sizeof(float) / kMiB;
}

void BM_TrainStepMemory(benchmark::State& state) {
  using G = Gaussian<7, 3>;
  constexpr int first = 0, count = 3;  // the RGB band of a Joint model
  bench::SceneSpec spec;
  spec.n = static_cast<std::size_t>(state.range(0));
  spec.width = 1280;
  spec.height = 720;
  const bool reset_ok = reset_peak();
  const double rss0 = status_mib("VmRSS");

  GaussianModel<G, float> model = bench::family_model<G, float>(spec);
  const double rss_model = status_mib("VmRSS");
  Adam<G, float> adam(AdamConfig{}, model.size());
  // The moments are value-initialised vectors: their pages are written, so RSS sees them now.
  const double rss_adam = status_mib("VmRSS");
  const Camera<float> cam = bench::family_camera<float>(spec);
  const Image<float> gt = bench::family_image_grad<float>(spec, count);  // a [0, 1) target image

  constexpr RasterOptions kTrainOptions{.absgrad = true, .single_precision = true};  // = msgs::kTrainRaster
  Rasterizer<G, float, kTrainOptions> raster;
  Gradients<G, float> grads;
  Image<float> d_image;
  SsimWorkspace<float> ws;
  RenderSettings<float> rs;
  rs.band_first = first;
  rs.band_count = count;
  rs.background = {0.2f, 0.3f, 0.4f};
  double rss_fwd = 0, rss_loss = 0, rss_bwd = 0, rss_step = 0;
  for (auto _ : state) {
    const double a = status_mib("VmRSS");
    const Image<float>& render = raster.forward(model, cam, rs);
    const double b = status_mib("VmRSS");
    benchmark::DoNotOptimize(photometric_loss(render, gt, &d_image, ws));
    const double c = status_mib("VmRSS");
    raster.backward(d_image, nullptr, nullptr, grads);
    const double d = status_mib("VmRSS");
    adam.step(model, grads.model, AdamMask::band(first, count));
    const double e = status_mib("VmRSS");
    rss_fwd = b - a; rss_loss = c - b; rss_bwd = d - c; rss_step = e - d;
  }

  const double M = double(raster.intersections()), N = double(model.size()), V = double(raster.visible_count());
  auto& k = state.counters;
  k["peak_rss_MiB"] = status_mib("VmHWM");
  k["peak_is_process_wide"] = reset_ok ? 0 : 1;
  k["rss_start_MiB"] = rss0;
  k["d_model_MiB"] = rss_model - rss0;
  k["d_adam_MiB"] = rss_adam - rss_model;
  k["d_forward_MiB"] = rss_fwd;
  k["d_loss_MiB"] = rss_loss;
  k["d_backward_MiB"] = rss_bwd;
  k["d_adam_step_MiB"] = rss_step;
  // Expected sizes from element counts.
  k["model_MiB"] = model_mib<G>(model.size());
  k["grads_MiB"] = model_mib<G>(model.size()) + N * 4 * sizeof(float) / kMiB;  // + mean2d, absgrad [N, 2]
  k["adam_moments_MiB"] = 2 * model_mib<G>(model.size());
  k["raster_per_gaussian_MiB"] =
      N * double(sizeof(Splat<float>) + count * sizeof(float) + sizeof(float) + sizeof(PixelRect) + 2 * sizeof(std::int32_t) + 1 +
                 sizeof(std::uint64_t)) / kMiB +  // ..., first pairs by id
      V * (4 + 4 + 8) / kMiB;  // visible ids, depth order, pair offsets
  k["raster_per_intersection_MiB"] =
      M * double(sizeof(std::uint32_t) + sizeof(std::uint16_t)) / kMiB;  // tile_list, block_mask
  k["grad_records_MiB"] = M * double(BlendRecord<false, true>::size(count)) * sizeof(float) / kMiB;
  k["images_MiB"] = double(spec.width) * spec.height * (3 * count + 3) * sizeof(float) / kMiB;  // render, gt, d_image, alpha, T, last
  k["intersections"] = M;
  k["visible"] = V;
  k["fragments"] = double(raster.fragments());
}
BENCHMARK(BM_TrainStepMemory)->Arg(1000000)->Iterations(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
