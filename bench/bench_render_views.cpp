// bench/bench_render_views.cpp
// The rasteriser's stages on a TRAINED model over the training views of its scene: for every
// training image, forward of the image's band with its own camera, the photometric loss with its
// gradient image (as training: L1 + 0.2 D-SSIM, SSIM over the valid windows) and the backward into
// the gradients of the Gaussians the view saw. No Adam and no refinement: bench_train_step times a
// whole step on a seeded scene; this one shows the rasteriser on the splat sizes, overlaps and
// per-pixel depths that training really produces, which a seeded scene does not.
//
// One iteration is one pass over all training images. Counters, in seconds per pass:
// project_s, bin_s, blend_s, loss_s, blend_backward_s, gaussians_backward_s; and views/s,
// fragments/s (blended fragments of the forward per second of the whole pass), fragments_per_view,
// visible_per_view, lane_use (the share of the blend's evaluated lanes that blended,
// Rasterizer::blend_lanes). The label is a hash of every rendered image, alpha image and gradient
// row of the seen Gaussians in one untimed pass before the timed ones: two builds that give the
// same label computed the same bits on this scene.
//
// The scene and the model come from the environment (the benchmark is skipped without them):
//   MSGS_BENCH_DATA    the dataset directory (any layout `msgs train --data` reads)
//   MSGS_BENCH_MODEL   the trained model: a PLY or a directory of model_*.ply, as `msgs train` wrote
//                      it with its default orientation (--orient center); SH degree 3
//   MSGS_BENCH_IMAGES  the image folder of a COLMAP scene (default images)
// Cases: /factor:F renders at 1/F of the full resolution (training's resolution schedule uses 4, 2
// and 1), /threads:T with T OpenMP threads. E.g. after `bash scripts/demo.sh`:
//   export MSGS_BENCH_DATA=out/small MSGS_BENCH_MODEL=out/demo_joint_optimized/model_joint.ply
//   ./build/bench/bench_render_views --benchmark_filter='factor:1/threads:2'
#include <benchmark/benchmark.h>

#include <msgs/io/load_scene.hpp>
#include <msgs/loss.hpp>
#include <msgs/model_set.hpp>
#include <msgs/rasterize.hpp>
#include <msgs/train.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

#include <omp.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

using namespace msgs;

namespace {

const char* env(const char* name) {
  const char* v = std::getenv(name);
  return v && *v ? v : nullptr;
}

/// FNV-1a over 8-byte words (the tail byte by byte): a fingerprint of results, not a checksum
/// against tampering.
struct Fingerprint {
  std::uint64_t h = 1469598103934665603ull;
  void add(const void* p, std::size_t n) {
    constexpr std::uint64_t kPrime = 1099511628211ull;
    const unsigned char* c = static_cast<const unsigned char*>(p);
    std::uint64_t x = h;  // a local: stores through `c` could otherwise alias h
    std::size_t i = 0;
    for (; i + 8 <= n; i += 8) {
      std::uint64_t w;
      std::memcpy(&w, c + i, 8);
      x = (x ^ w) * kPrime;
    }
    for (; i < n; ++i) x = (x ^ c[i]) * kPrime;
    h = x;
  }
};

/// The loss training uses (L1 + 0.2 D-SSIM over the valid windows).
const PhotometricLossConfig kTrainingLoss = TrainOptions{}.loss;

/// Seconds per stage, summed over views.
struct Stages {
  double project = 0, bin = 0, blend = 0, loss = 0, blend_backward = 0, gaussians_backward = 0;
  std::uint64_t fragments = 0, lanes = 0, visible = 0;
  Stages& operator+=(const Stages& o) {
    project += o.project;
    bin += o.bin;
    blend += o.blend;
    loss += o.loss;
    blend_backward += o.blend_backward;
    gaussians_backward += o.gaussians_backward;
    fragments += o.fragments;
    lanes += o.lanes;
    visible += o.visible;
    return *this;
  }
};

/// What one training image needs: its target, camera, and which channels of which model it renders.
struct View {
  Image<float> target;
  Camera<float> cam;
  BandSource src;
};

/// A model of type G with the rasteriser and gradients that render and differentiate its views.
template <class G>
struct ModelBench {
  const GaussianModel<G, float>* model;
  Rasterizer<G, float, kTrainRaster> raster;
  Gradients<G, float> grads;

  /// Forward, loss, backward of one view; stage times added to `t`, results to `fp` when given.
  void run(const View& v, Image<float>& d_image, SsimWorkspace<float>& ws, Stages& t, Fingerprint* fp) {
    RenderSettings<float> rs;
    rs.band_first = v.src.first_channel;
    rs.band_count = v.src.channels;
    raster.timings().reset();
    const Image<float>& img = raster.forward(*model, v.cam, rs);
    const auto t0 = std::chrono::steady_clock::now();
    photometric_loss(img, v.target, &d_image, ws, kTrainingLoss);
    t.loss += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    raster.backward(d_image, nullptr, nullptr, grads, GradientFill::visible);
    const RasterTimings& rt = raster.timings();
    t.project += rt.project;
    t.bin += rt.bin;
    t.blend += rt.blend;
    t.blend_backward += rt.blend_backward;
    t.gaussians_backward += rt.project_backward;
    t.fragments += raster.fragments();
    t.lanes += raster.blend_lanes();
    t.visible += raster.visible_count();
    if (!fp) return;
    fp->add(img.data.data(), img.data.size() * sizeof(float));
    fp->add(raster.alpha().data.data(), raster.alpha().data.size() * sizeof(float));
    const std::size_t K = std::size_t(G::sh_coeffs);
    for (const std::uint32_t g : raster.visible()) {
      fp->add(&grads.mean2d[2 * g], 2 * sizeof(float));
      fp->add(&grads.absgrad[2 * g], 2 * sizeof(float));
      fp->add(&grads.model.means[3 * g], 3 * sizeof(float));
      fp->add(&grads.model.log_scales[3 * g], 3 * sizeof(float));
      fp->add(&grads.model.quats[4 * g], 4 * sizeof(float));
      fp->add(&grads.model.opacity_logits[g], sizeof(float));
      for (int ch = v.src.first_channel; ch < v.src.first_channel + v.src.channels; ++ch)
        fp->add(grads.model.sh_row(g, ch), K * sizeof(float));
    }
  }
};

using AnyBench = std::variant<ModelBench<Gaussian<1, 3>>, ModelBench<Gaussian<3, 3>>, ModelBench<Gaussian<7, 3>>>;

/// The scene's models and training views, loaded once; views per resolution factor on first use.
struct Scene {
  io::Dataset ds;
  ModelSet models;
  std::vector<std::unique_ptr<AnyBench>> benches;  // one per model, in ModelSet order
  std::map<int, std::vector<View>> views;          // factor -> training views

  static ModelSet load_models(const std::filesystem::path& p) {
    // Only the band routing and the loaded models are used; rendering goes through ModelBench.
    return ModelSet::load(p, [](std::shared_ptr<const LoadedModel>) -> ChannelRenderer {
      return [](const Camera<float>&, const RenderSettings<float>&) -> Image<float> {
        throw std::logic_error("bench_render_views renders through its own rasterisers");
      };
    });
  }

  static io::Dataset load_data(const std::filesystem::path& root) {
    io::LoadOptions lo;
    lo.load_points = false;
    if (io::detect_scene(root).layout == io::SceneLayout::colmap) lo.eval_every = 8;  // as `msgs train`
    const char* images = env("MSGS_BENCH_IMAGES");
    return io::load_scene(root, lo, images ? images : "images");
  }

  Scene(const std::filesystem::path& data, const std::filesystem::path& model)
      : ds(load_data(data)), models(load_models(model)) {
    for (const auto& m : models.models()) {
      if (m->sh_degree() != 3)
        throw std::invalid_argument(m->path.string() + ": SH degree " + std::to_string(m->sh_degree()) +
                                    "; this benchmark instantiates SH degree 3 models only");
      std::visit(
          [&](const auto& typed) {
            using M = std::decay_t<decltype(typed)>;
            using G = typename M::gaussian_type;
            if constexpr (G::sh_degree == 3) {
              auto b = std::make_unique<AnyBench>(std::in_place_type<ModelBench<G>>);
              std::get<ModelBench<G>>(*b).model = &typed;
              benches.push_back(std::move(b));
            }
          },
          m->model);
    }
  }

  const std::vector<View>& views_at(int factor) {
    auto it = views.find(factor);
    if (it != views.end()) return it->second;
    std::vector<View> out;
    for (const io::Frame& f : ds.frames) {
      if (!f.train()) continue;
      const BandSource* s = models.source(f.band);
      if (!s) continue;  // a band no model renders (e.g. a Separate run trained on some bands only)
      out.push_back(View{io::load_frame_image(ds, f, factor), io::frame_camera(ds, f, factor), *s});
    }
    if (out.empty()) throw std::invalid_argument("no training image of the dataset has a band the model renders");
    return views.emplace(factor, std::move(out)).first->second;
  }

  /// One pass over the views at `factor`.
  Stages pass(int factor, Fingerprint* fp) {
    Stages t;
    Image<float> d_image;
    SsimWorkspace<float> ws;
    for (const View& v : views_at(factor))
      std::visit([&](auto& b) { b.run(v, d_image, ws, t, fp); }, *benches[v.src.model]);
    return t;
  }
};

Scene* scene_or_skip(benchmark::State& st) {
  static std::unique_ptr<Scene> scene;
  static std::string error;
  if (!scene && error.empty()) {
    const char* data = env("MSGS_BENCH_DATA");
    const char* model = env("MSGS_BENCH_MODEL");
    if (!data || !model) {
      error = "set MSGS_BENCH_DATA (a dataset) and MSGS_BENCH_MODEL (a model msgs train wrote for it)";
    } else {
      try {
        scene = std::make_unique<Scene>(data, model);
      } catch (const std::exception& e) {
        error = e.what();
      }
    }
  }
  if (!scene) st.SkipWithError(error.c_str());
  return scene.get();
}

void bm_render_views(benchmark::State& st, int factor, int threads) {
  Scene* scene = scene_or_skip(st);
  if (!scene) return;
  omp_set_num_threads(threads);
  std::size_t n_views = 0;
  try {
    n_views = scene->views_at(factor).size();
  } catch (const std::exception& e) {
    st.SkipWithError(e.what());
    return;
  }
  Fingerprint fp;
  scene->pass(factor, &fp);  // untimed: fills the buffers and fingerprints the results
  Stages sum;
  for (auto _ : st) sum += scene->pass(factor, nullptr);
  const double passes = double(std::max<benchmark::IterationCount>(st.iterations(), 1));
  auto& k = st.counters;
  k["views/s"] = benchmark::Counter(double(n_views), benchmark::Counter::kIsIterationInvariantRate);
  k["fragments/s"] = benchmark::Counter(double(sum.fragments) / passes, benchmark::Counter::kIsIterationInvariantRate);
  k["fragments_per_view"] = double(sum.fragments) / passes / double(n_views);
  k["visible_per_view"] = double(sum.visible) / passes / double(n_views);
  k["lane_use"] = sum.lanes > 0 ? double(sum.fragments) / double(sum.lanes) : 0.0;
  k["project_s"] = sum.project / passes;
  k["bin_s"] = sum.bin / passes;
  k["blend_s"] = sum.blend / passes;
  k["loss_s"] = sum.loss / passes;
  k["blend_backward_s"] = sum.blend_backward / passes;
  k["gaussians_backward_s"] = sum.gaussians_backward / passes;
  char label[40];
  std::snprintf(label, sizeof label, "hash %016llx", static_cast<unsigned long long>(fp.h));
  st.SetLabel(label);
}

}  // namespace

int main(int argc, char** argv) {
  for (int factor : {1, 2, 4})
    for (int threads : {1, 2}) {
      const std::string name = "render_views/factor:" + std::to_string(factor) + "/threads:" + std::to_string(threads);
      benchmark::RegisterBenchmark(name.c_str(), [=](benchmark::State& st) { bm_render_views(st, factor, threads); })
          ->UseRealTime()
          ->Unit(benchmark::kSecond);
    }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
