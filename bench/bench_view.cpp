// bench/bench_view.cpp
// Frame rate of `msgs view`: what the server does per /api/render request (render the mode's
// bands with the rasteriser, compose, colour-map, encode JPEG), at 640x480 for a 7-channel Joint
// model of SH degree 3 from the seeded scene family, in the modes that cost differently: one
// narrow band, the RGB band, CIR and an index (NDVI). frames/s is the iteration rate.
//
// The 1M-Gaussian cases are opt-in (about 1 GB and seconds to build the scene):
//   MSGS_BENCH_LARGE=1 ./bench_view
// `--benchmark_filter=100k` etc. select sizes; `/encode:0` cases time the render alone.
//
// view_snapshot: what `msgs train --view` costs the training thread per snapshot (a copy of the
// model published into a SnapshotStore, msgs/snapshot.hpp); taken at most once a second.
#include <benchmark/benchmark.h>

#include <msgs/snapshot.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

#include "../examples/view_api.hpp"
#include "scene_family.hpp"

#include <cstdlib>
#include <memory>
#include <string>
#include <variant>
#include <vector>

using namespace msgs;

namespace {

using G = Gaussian<7, 3>;

struct SizeCase {
  std::size_t n;
  const char* name;
};
constexpr SizeCase kSizes[] = {{100000, "100k"}, {1000000, "1M"}};
constexpr int kWidth = 640, kHeight = 480;

/// The ModelSet of the family scene with kSizes[size].n Gaussians, built once per size.
const ModelSet& models_for(int size) {
  static int cached = -1;
  static std::unique_ptr<ModelSet> set;
  if (cached != size) {
    set.reset();
    LoadedModel m;
    m.path = "family.ply";
    m.info.gaussian = true;
    m.info.channels = G::bands;
    m.info.sh_degree = G::sh_degree;
    m.info.band_names = io::joint_channel_names();
    m.info.vertices = kSizes[size].n;
    m.model = bench::family_model<G, float>(bench::scene_spec(kSizes[size].n, kWidth, kHeight));
    std::vector<LoadedModel> ms;
    ms.push_back(std::move(m));
    set = std::make_unique<ModelSet>(ModelSet::from_models(std::move(ms), make_typed_renderer<G>));
    cached = size;
  }
  return *set;
}

void BM_view_frame(benchmark::State& st, int size, const char* mode_id, bool encode) {
  const ModelSet& models = models_for(size);
  const Camera<float> cam = bench::family_camera<float>(bench::scene_spec(kSizes[size].n, kWidth, kHeight));
  const view::Mode mode = view::parse_mode(mode_id);
  const view::Background bg;  // the evaluation grey, the server's default
  std::size_t bytes = 0;
  for (auto _ : st) {
    Image<float> shown = view::display(mode, view::render_values(models, mode, cam, bg), 1.0f);
    if (encode) {
      const view::Encoded e = view::encode(shown, view::Format::jpeg, 92);
      bytes = e.bytes.size();
      benchmark::DoNotOptimize(e.bytes.data());
    }
    benchmark::DoNotOptimize(shown.data.data());
  }
  st.counters["frames/s"] = benchmark::Counter(1.0, benchmark::Counter::kIsIterationInvariantRate);
  if (encode) st.counters["jpeg_kB"] = double(bytes) / 1024.0;
}

void BM_view_snapshot(benchmark::State& st, int size) {
  const ModelSet& models = models_for(size);
  const auto& model = std::get<GaussianModel<G, float>>(models.models()[0]->model);
  const std::vector<TrainBand> bands;
  SnapshotStore store(SnapshotPolicy{.min_seconds = 1e9, .every = 1});  // a snapshot at every call
  long long step = 0;
  for (auto _ : st) {
    StepView v = StepView::of(model, bands, ++step, 0, 1LL << 40);
    v.key = "joint";
    store.on_step(v);
  }
  st.counters["Gaussians/s"] =
      benchmark::Counter(double(model.size()), benchmark::Counter::kIsIterationInvariantRate);
  st.counters["MB"] = double(model.means.size() + model.log_scales.size() + model.quats.size() +
                             model.opacity_logits.size() + model.sh.size()) * 4.0 / 1e6;
}

const int registered = [] {
  const bool large = std::getenv("MSGS_BENCH_LARGE") != nullptr;
  for (int size = 0; size < 2; ++size) {
    if (size == 1 && !large) continue;
    for (const char* mode : {"MS_NIR", "rgb", "cir", "ndvi"})
      for (bool encode : {true, false}) {
        const std::string name = std::string("view_frame/") + kSizes[size].name + "_640x480/" + mode +
                                 "/encode:" + (encode ? "1" : "0");
        benchmark::RegisterBenchmark(name.c_str(), BM_view_frame, size, mode, encode)
            ->Unit(benchmark::kMillisecond)
            ->MinTime(2.0)
            ->UseRealTime();
      }
    benchmark::RegisterBenchmark((std::string("view_snapshot/") + kSizes[size].name).c_str(), BM_view_snapshot, size)
        ->Unit(benchmark::kMillisecond)
        ->MinTime(1.0)
        ->UseRealTime();
  }
  return 0;
}();

}  // namespace

BENCHMARK_MAIN();
