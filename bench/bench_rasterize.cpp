// bench/bench_rasterize.cpp
// Google Benchmark suite of the tile rasterizer: projection, binning, forward and backward for 1/3/7 bands,
// SH degree 0/3, three scene sizes and 1/2 threads, reported as fragments/s and Gaussians/s.
//
// The 1M-Gaussian 1280x720 cases are opt-in (they need ~1 GB and seconds per iteration):
//   MSGS_BENCH_LARGE=1 ./bench_rasterize
// Usual filters apply, e.g. --benchmark_filter='forward/B7_SH3'.
#include <benchmark/benchmark.h>

#include <msgs/project.hpp>
#include <msgs/rasterize.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

#include "scene_family.hpp"

#include <omp.h>

#include <bit>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

using namespace msgs;
using msgs::bench::SceneSpec;

namespace {

/// The (N, resolution) grid of the family.
struct SizeCase {
  std::size_t n;
  int width, height;
  const char* name;
};
constexpr SizeCase kSizes[] = {
    {10000, 256, 256, "10k_256x256"},
    {100000, 640, 480, "100k_640x480"},
    {1000000, 1280, 720, "1M_1280x720"},
};

SceneSpec spec_of(int size) { return bench::scene_spec(kSizes[size].n, kSizes[size].width, kSizes[size].height); }

/// One model per Gaussian type, rebuilt only when the size changes (benchmarks run in
/// registration order, grouped by size), so setup stays outside the timed loops and memory
/// holds one scene per type at a time.
template <class G>
const GaussianModel<G, float>& model_for(int size) {
  static int cached = -1;
  static std::unique_ptr<GaussianModel<G, float>> model;
  if (cached != size) {
    model.reset();
    model = std::make_unique<GaussianModel<G, float>>(bench::family_model<G, float>(spec_of(size)));
    cached = size;
  }
  return *model;
}

void set_rates(benchmark::State& st, std::uint64_t fragments, std::size_t n) {
  st.counters["fragments/s"] = benchmark::Counter(double(fragments), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["gaussians/s"] = benchmark::Counter(double(n), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["fragments"] = double(fragments);
}

template <class G>
void bm_forward(benchmark::State& st, int size, int threads, RenderSettings<float> rs) {
  omp_set_num_threads(threads);
  const SceneSpec spec = spec_of(size);
  const GaussianModel<G, float>& m = model_for<G>(size);
  const Camera<float> cam = bench::family_camera<float>(spec);
  Rasterizer<G, float> r;
  r.forward(m, cam, rs);  // allocate the frame buffers before timing
  for (auto _ : st) {
    r.forward(m, cam, rs);
    benchmark::DoNotOptimize(r.image().data.data());
  }
  set_rates(st, r.fragments(), m.size());
  st.counters["visible"] = double(r.visible_count());
}

/// The binning of a forward alone (depth sort and tile lists of the visible Gaussians), timed by
/// the rasteriser's own stage clock: each iteration runs a whole forward, and only its binning is
/// the iteration's time. Reports pairs/s (Gaussian-tile intersections) and Gaussians/s (visible).
void bm_bin(benchmark::State& st, int size, int threads) {
  using G = Gaussian<1, 0>;
  omp_set_num_threads(threads);
  const SceneSpec spec = spec_of(size);
  const GaussianModel<G, float>& m = model_for<G>(size);
  const Camera<float> cam = bench::family_camera<float>(spec);
  Rasterizer<G, float> r;
  r.forward(m, cam, {});  // allocate the frame buffers before timing
  for (auto _ : st) {
    r.timings().reset();
    r.forward(m, cam, {});
    st.SetIterationTime(r.timings().bin);
  }
  st.counters["pairs/s"] = benchmark::Counter(double(r.intersections()), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["gaussians/s"] = benchmark::Counter(double(r.visible_count()), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["pairs"] = double(r.intersections());
}

template <class G, RasterOptions Opt = RasterOptions{}>
void bm_backward(benchmark::State& st, int size, int threads, RenderSettings<float> rs) {
  omp_set_num_threads(threads);
  const SceneSpec spec = spec_of(size);
  const GaussianModel<G, float>& m = model_for<G>(size);
  const Camera<float> cam = bench::family_camera<float>(spec);
  Rasterizer<G, float, Opt> r;
  r.forward(m, cam, rs);
  const Image<float> d_image = bench::family_image_grad<float>(spec, r.image().channels);
  Gradients<G, float> grads;
  r.backward(d_image, nullptr, nullptr, grads);  // allocate the gradient buffers before timing
  for (auto _ : st) {
    r.backward(d_image, nullptr, nullptr, grads);
    benchmark::DoNotOptimize(grads.model.means.data());
  }
  set_rates(st, r.fragments(), m.size());
}

/// The projection stage alone (geometry only): a vector of Gaussians at a time as the rasteriser
/// runs it (detail::project_lanes; D = detail::ProjVec in double, detail::ProjVecF in single
/// precision), or with `scalar` one at a time (project_fwd, double), for comparison.
template <class D>
void bm_project(benchmark::State& st, int size, int threads, bool scalar) {
  using G = Gaussian<1, 0>;
  constexpr int L = detail::Lanes<D>::kCount;
  omp_set_num_threads(threads);
  const SceneSpec spec = spec_of(size);
  const GaussianModel<G, float>& m = model_for<G>(size);
  const ProjectCamera pcam = ProjectCamera::from(bench::family_camera<float>(spec));
  const std::int64_t n = std::int64_t(m.size()) / L * L;  // whole batches
  std::vector<ProjectedGaussian> out(scalar ? m.size() : 0);
  std::vector<detail::ProjectedLanes<D>> out_lanes(scalar ? 0 : std::size_t(n / L));
  std::int64_t visible = 0;
  for (auto _ : st) {
    visible = 0;
    if (scalar) {
#pragma omp parallel for schedule(static) reduction(+ : visible)
      for (std::int64_t i = 0; i < n; ++i) {
        const std::size_t k = std::size_t(i);
        GaussianGeometry g;
        g.mean = Eigen::Vector3d(m.means[3 * k], m.means[3 * k + 1], m.means[3 * k + 2]);
        g.log_scale = Eigen::Vector3d(m.log_scales[3 * k], m.log_scales[3 * k + 1], m.log_scales[3 * k + 2]);
        g.quat = Eigen::Vector4d(m.quats[4 * k], m.quats[4 * k + 1], m.quats[4 * k + 2], m.quats[4 * k + 3]);
        g.opacity_logit = m.opacity_logits[k];
        visible += project_fwd<false>(g, pcam, out[k]) ? 1 : 0;
      }
      benchmark::DoNotOptimize(out.data());
    } else {
#pragma omp parallel for schedule(static) reduction(+ : visible)
      for (std::int64_t b = 0; b < n / L; ++b) {
        std::uint32_t ids[L];
        for (int l = 0; l < L; ++l) ids[l] = std::uint32_t(b * L + l);
        detail::GeometryLanes<D> g;
        detail::gather_geometry(m, ids, g);
        const auto vis = detail::project_lanes<false>(g, pcam, out_lanes[std::size_t(b)], nullptr, false);
        visible += std::popcount(detail::lane_bits(vis));
      }
      benchmark::DoNotOptimize(out_lanes.data());
    }
  }
  st.counters["gaussians/s"] = benchmark::Counter(double(n), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["visible"] = double(visible);
}

void tune(benchmark::internal::Benchmark* b, int size) {
  b->UseRealTime()->Unit(benchmark::kMillisecond);
  if (size == 2) b->Iterations(2);
  else b->MinTime(0.3);
}

/// Forward and backward of one Gaussian type at one size and thread count.
template <class G>
void register_type(const std::string& tag, int size, int threads, const RenderSettings<float>& rs = {}) {
  const std::string suffix = std::string("/") + kSizes[size].name + "/threads:" + std::to_string(threads);
  tune(benchmark::RegisterBenchmark(("forward/" + tag + suffix).c_str(),
                                    [=](benchmark::State& st) { bm_forward<G>(st, size, threads, rs); }),
       size);
  tune(benchmark::RegisterBenchmark(("backward/" + tag + suffix).c_str(),
                                    [=](benchmark::State& st) { bm_backward<G>(st, size, threads, rs); }),
       size);
}

}  // namespace

int main(int argc, char** argv) {
  const char* large = std::getenv("MSGS_BENCH_LARGE");
  const int sizes = (large && std::string(large) != "0") ? 3 : 2;
  for (int size = 0; size < sizes; ++size) {
    for (int threads : {1, 2})
      for (const char* mode : {"project", "project_single", "project_scalar"}) {
        const std::string name = std::string(mode) + "/" + kSizes[size].name + "/threads:" + std::to_string(threads);
        const bool single = std::string(mode) == "project_single", scalar = std::string(mode) == "project_scalar";
        tune(benchmark::RegisterBenchmark(name.c_str(),
                                          [=](benchmark::State& st) {
                                            if (single) bm_project<detail::ProjVecF>(st, size, threads, false);
                                            else bm_project<detail::ProjVec>(st, size, threads, scalar);
                                          }),
             size);
      }
    for (int threads : {1, 2}) {
      auto* b = benchmark::RegisterBenchmark(
          (std::string("bin/") + kSizes[size].name + "/threads:" + std::to_string(threads)).c_str(),
          [=](benchmark::State& st) { bm_bin(st, size, threads); });
      b->UseManualTime()->Unit(benchmark::kMillisecond);  // tune() without its real time
      if (size == 2) b->Iterations(2);
      else b->MinTime(0.3);
    }
    for (int threads : {1, 2}) {
      register_type<Gaussian<1, 0>>("B1_SH0", size, threads);
      register_type<Gaussian<1, 3>>("B1_SH3", size, threads);
      register_type<Gaussian<3, 0>>("B3_SH0", size, threads);
      register_type<Gaussian<3, 3>>("B3_SH3", size, threads);
      register_type<Gaussian<7, 0>>("B7_SH0", size, threads);
      register_type<Gaussian<7, 3>>("B7_SH3", size, threads);
      // One narrow band of a Joint model, to compare with B1_SH3 (same geometry, same seed).
      RenderSettings<float> one_band;
      one_band.band_first = 3;
      one_band.band_count = 1;
      register_type<Gaussian<7, 3>>("B7_SH3_band3only", size, threads, one_band);
      // What absgrad (opt-in; training turns it on for densification) adds to the backward.
      constexpr RasterOptions kAbsGrad{.absgrad = true};
      tune(benchmark::RegisterBenchmark(
               (std::string("backward/B3_SH0_absgrad/") + kSizes[size].name + "/threads:" + std::to_string(threads)).c_str(),
               [=](benchmark::State& st) { bm_backward<Gaussian<3, 0>, kAbsGrad>(st, size, threads, {}); }),
           size);
    }
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
