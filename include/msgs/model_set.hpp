// include/msgs/model_set.hpp
// Loading PLY models of any channel count / SH degree by run-time dispatch (load_model ->
// Gaussian<C, D>, C in {1, 3, 7}, D in {0..3}), their renderers, and ModelSet: which model
// renders which band. Rendering a model type instantiates a Rasterizer; a RendererFactory decides
// which types are compiled where, so a tool can spread the twelve instantiations over several
// translation units.
#pragma once

#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <variant>
#include <vector>

#include "camera.hpp"
#include "gaussian.hpp"
#include "image.hpp"
#include "io/bands.hpp"
#include "io/error.hpp"
#include "io/image_io.hpp"  // io::detail::lower_extension
#include "io/ply.hpp"
#include "rasterize.hpp"

namespace msgs {

/// Channels [first, first + count) of `img` as an image of their own.
inline Image<float> channel_slice(const Image<float>& img, int first, int count) {
  if (first < 0 || count < 1 || first + count > img.channels)
    throw std::invalid_argument("channel_slice: channels [" + std::to_string(first) + ", " +
                                std::to_string(first + count) + ") outside an image of " +
                                std::to_string(img.channels));
  Image<float> out(img.width, img.height, count);
  const std::size_t C = std::size_t(img.channels), n = std::size_t(count);
  for (std::size_t p = 0; p < img.pixels(); ++p)
    for (std::size_t c = 0; c < n; ++c) out.data[p * n + c] = img.data[p * C + std::size_t(first) + c];
  return out;
}

/// The model type msgs reads for `C` channels and SH degree `D`.
template <int C, int D>
using ModelOf = GaussianModel<Gaussian<C, D>, float>;

/// Any model a PLY can hold: C in {1, 3, 7} (a narrow band, RGB, Joint), degree 0..3.
using AnyModel = std::variant<ModelOf<1, 0>, ModelOf<1, 1>, ModelOf<1, 2>, ModelOf<1, 3>,  //
                              ModelOf<3, 0>, ModelOf<3, 1>, ModelOf<3, 2>, ModelOf<3, 3>,  //
                              ModelOf<7, 0>, ModelOf<7, 1>, ModelOf<7, 2>, ModelOf<7, 3>>;

/// A model read from a PLY file together with what its header says.
struct LoadedModel {
  std::filesystem::path path;
  io::PlyInfo info;  ///< channels, SH degree, band names (empty for files from other tools)
  AnyModel model;
  int channels() const { return info.channels; }
  int sh_degree() const { return info.sh_degree; }
  std::size_t size() const {
    return std::visit([](const auto& m) { return m.size(); }, model);
  }
};

namespace detail {
template <int C>
AnyModel read_model_with_channels(const std::filesystem::path& p, int degree) {
  switch (degree) {
    case 0: return io::read_ply<Gaussian<C, 0>>(p);
    case 1: return io::read_ply<Gaussian<C, 1>>(p);
    case 2: return io::read_ply<Gaussian<C, 2>>(p);
    case 3: return io::read_ply<Gaussian<C, 3>>(p);
    default: io::fail(p, "f_rest_*", io::cat("SH degree ", degree, " is not 0..3"));
  }
}
}  // namespace detail

/// Read a Gaussian model PLY as the Gaussian<C, D> its header describes (io::inspect_ply). Throws
/// io::IoError naming the file and field for anything else: point clouds, other channel counts,
/// malformed or truncated files.
inline LoadedModel load_model(const std::filesystem::path& p) {
  LoadedModel m;
  m.path = p;
  m.info = io::inspect_ply(p);
  if (!m.info.gaussian) io::fail(p, "not a Gaussian model (needs f_dc_* and opacity properties)");
  switch (m.info.channels) {
    case 1: m.model = detail::read_model_with_channels<1>(p, m.info.sh_degree); break;
    case 3: m.model = detail::read_model_with_channels<3>(p, m.info.sh_degree); break;
    case 7: m.model = detail::read_model_with_channels<7>(p, m.info.sh_degree); break;
    default:
      io::fail(p, "f_dc_*", io::cat(m.info.channels, " colour channels; msgs renders models with 1 (one band), ",
                                    "3 (RGB) or 7 (Joint) channels"));
  }
  return m;
}

/// Renders channels of one loaded model: (camera, settings) -> image [H, W, band_count].
using ChannelRenderer = std::function<Image<float>(const Camera<float>&, const RenderSettings<float>&)>;
/// Makes the renderer of a loaded model; decides which Rasterizer types are compiled.
using RendererFactory = std::function<ChannelRenderer(std::shared_ptr<const LoadedModel>)>;

/// Renderer for a model held as exactly GaussianModel<G>; std::invalid_argument for another type.
/// The renderer keeps the model and one Rasterizer (its buffers are reused between frames).
template <class G>
ChannelRenderer make_typed_renderer(std::shared_ptr<const LoadedModel> m) {
  using Model = GaussianModel<G, float>;
  const Model* model = std::get_if<Model>(&m->model);
  if (!model)
    throw std::invalid_argument("make_typed_renderer: " + m->path.string() + " holds " +
                                std::to_string(m->channels()) + " channels of SH degree " +
                                std::to_string(m->sh_degree()) + ", not Gaussian<" + std::to_string(G::bands) + ", " +
                                std::to_string(G::sh_degree) + ">");
  auto raster = std::make_shared<Rasterizer<G, float>>();
  return [m, model, raster](const Camera<float>& cam, const RenderSettings<float>& rs) {
    return raster->forward(*model, cam, rs);
  };
}

/// Renderer for a model with `C` channels and any SH degree (instantiates four Rasterizers).
template <int C>
ChannelRenderer make_channel_renderer(std::shared_ptr<const LoadedModel> m) {
  if (m->channels() != C)
    throw std::invalid_argument("make_channel_renderer<" + std::to_string(C) + ">: " + m->path.string() + " has " +
                                std::to_string(m->channels()) + " channels");
  switch (m->sh_degree()) {
    case 0: return make_typed_renderer<Gaussian<C, 0>>(std::move(m));
    case 1: return make_typed_renderer<Gaussian<C, 1>>(std::move(m));
    case 2: return make_typed_renderer<Gaussian<C, 2>>(std::move(m));
    default: return make_typed_renderer<Gaussian<C, 3>>(std::move(m));
  }
}

/// Where a band's channels live: which model of a ModelSet, which of its channels.
struct BandSource {
  std::size_t model = 0;  ///< index into ModelSet::models()
  int first_channel = 0;
  int channels = 1;
};

/// The models that render a dataset's bands: one Joint PLY, one RGB or single-band PLY, or a
/// directory of per-band PLYs (model_D.ply, model_MS_NIR.ply ... as `msgs train` writes them).
/// Bands come from the `msgs_bands` header comment; a file without names is read as the RGB band
/// D (3 channels), the standard Joint layout (7), or a single band that renders any 1-channel
/// band it is asked for (1).
class ModelSet {
 public:
  /// Load `ply_or_dir` (a PLY file, or a directory whose model_*.ply files are all loaded) and
  /// make a renderer for each model with `factory`. Throws io::IoError naming the file for
  /// unreadable models, unknown band names and two models claiming the same band.
  static ModelSet load(const std::filesystem::path& ply_or_dir, const RendererFactory& factory) {
    namespace fs = std::filesystem;
    std::vector<fs::path> files;
    std::error_code ec;
    if (fs::is_directory(ply_or_dir, ec)) {
      for (const auto& e : fs::directory_iterator(ply_or_dir, ec)) {
        const std::string name = e.path().filename().string();
        if (e.is_regular_file() && name.rfind("model_", 0) == 0 && io::detail::lower_extension(e.path()) == ".ply")
          files.push_back(e.path());
      }
      if (ec) io::fail(ply_or_dir, io::cat("cannot list directory: ", ec.message()));
      if (files.empty()) io::fail(ply_or_dir, "directory holds no model_*.ply files");
      std::sort(files.begin(), files.end());
    } else if (fs::exists(ply_or_dir, ec)) {
      files.push_back(ply_or_dir);
    } else {
      io::fail(ply_or_dir, "model file or directory does not exist");
    }
    std::vector<LoadedModel> models;
    for (const auto& f : files) models.push_back(load_model(f));
    return from_models(std::move(models), factory);
  }

  /// A set from models already in memory (their `path` is used in messages only).
  static ModelSet from_models(std::vector<LoadedModel> models, const RendererFactory& factory) {
    if (models.empty()) throw std::invalid_argument("ModelSet: no models");
    ModelSet s;
    for (auto& m : models) {
      auto shared = std::make_shared<const LoadedModel>(std::move(m));
      s.add_bands(*shared, s.models_.size());
      s.renderers_.push_back(factory(shared));
      s.models_.push_back(std::move(shared));
    }
    return s;
  }

  const std::vector<std::shared_ptr<const LoadedModel>>& models() const { return models_; }

  /// The source of `band`: a named one, else the unnamed single-band model for a 1-channel band;
  /// nullptr when no model renders it.
  const BandSource* source(std::string_view band) const {
    if (auto it = named_.find(std::string(band)); it != named_.end()) return &it->second;
    const io::BandInfo* b = io::find_band(band);
    if (wildcard_ && b && b->channels == 1) return &*wildcard_;
    return nullptr;
  }
  /// Like source() but only a model that names the band: composites need distinct bands.
  const BandSource* named_source(std::string_view band) const {
    auto it = named_.find(std::string(band));
    return it == named_.end() ? nullptr : &it->second;
  }
  /// True when some model renders `band`.
  bool renders(std::string_view band) const { return source(band) != nullptr; }

  /// Render `band` from `cam`. `background`: empty (0), one value or one per band channel;
  /// `sh_degree` < 0 renders the model's full degree, otherwise at most that degree.
  Image<float> render(std::string_view band, const Camera<float>& cam, const std::vector<float>& background = {},
                      int sh_degree = -1) const {
    return render_bands({std::string(band)}, cam, {background}, sh_degree).front();
  }

  /// Render several bands from one camera (the same viewpoint), one image per band in the order
  /// given. Bands held in adjacent channels of one model (G, R, RE, NIR of a Joint model) share
  /// one forward pass. `backgrounds[i]` as in render() for bands[i] (or empty vector: all 0).
  std::vector<Image<float>> render_bands(const std::vector<std::string>& bands, const Camera<float>& cam,
                                         const std::vector<std::vector<float>>& backgrounds = {},
                                         int sh_degree = -1) const {
    if (!backgrounds.empty() && backgrounds.size() != bands.size())
      throw std::invalid_argument("ModelSet::render_bands: " + std::to_string(backgrounds.size()) +
                                  " backgrounds for " + std::to_string(bands.size()) + " bands");
    struct Item { std::size_t index; BandSource src; std::vector<float> bg; };
    std::vector<Item> items;
    for (std::size_t i = 0; i < bands.size(); ++i) {
      const BandSource* s = source(bands[i]);
      if (!s) throw std::invalid_argument("ModelSet: no model renders band '" + bands[i] + "'");
      std::vector<float> bg = backgrounds.empty() ? std::vector<float>{} : backgrounds[i];
      if (bg.empty()) bg.assign(std::size_t(s->channels), 0.0f);
      else if (bg.size() == 1) bg.assign(std::size_t(s->channels), bg[0]);
      else if (bg.size() != std::size_t(s->channels))
        throw std::invalid_argument("ModelSet: band '" + bands[i] + "' has " + std::to_string(s->channels) +
                                    " channel(s) but " + std::to_string(bg.size()) + " background values");
      items.push_back({i, *s, std::move(bg)});
    }
    std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
      return a.src.model != b.src.model ? a.src.model < b.src.model : a.src.first_channel < b.src.first_channel;
    });
    std::vector<Image<float>> out(bands.size());
    for (std::size_t i = 0; i < items.size();) {
      // A run of bands in adjacent channels of one model renders in one pass.
      std::size_t j = i + 1;
      int end = items[i].src.first_channel + items[i].src.channels;
      while (j < items.size() && items[j].src.model == items[i].src.model && items[j].src.first_channel == end) {
        end += items[j].src.channels;
        ++j;
      }
      const LoadedModel& m = *models_[items[i].src.model];
      RenderSettings<float> rs;
      rs.band_first = items[i].src.first_channel;
      rs.band_count = end - rs.band_first;
      rs.sh_degree = sh_degree < 0 ? -1 : std::min(sh_degree, m.sh_degree());
      for (std::size_t k = i; k < j; ++k) rs.background.insert(rs.background.end(), items[k].bg.begin(), items[k].bg.end());
      const Image<float> img = renderers_[items[i].src.model](cam, rs);
      for (std::size_t k = i; k < j; ++k)
        out[items[k].index] = j - i == 1 ? img
                                         : channel_slice(img, items[k].src.first_channel - rs.band_first,
                                                         items[k].src.channels);
      i = j;
    }
    return out;
  }

 private:
  void claim(const std::string& band, BandSource src, const LoadedModel& m) {
    auto [it, inserted] = named_.emplace(band, src);
    if (!inserted)
      io::fail(m.path, "comment msgs_bands",
               io::cat("band ", band, " is also rendered by ", models_[it->second.model]->path.string(),
                       " (one model per band)"));
  }

  void add_bands(const LoadedModel& m, std::size_t index) {
    const auto& names = m.info.band_names;
    const std::vector<std::string> joint = io::joint_channel_names();
    const io::BandInfo& rgb = *io::find_band("D");
    if (names.empty()) {
      if (m.channels() == 1) {
        if (wildcard_)
          io::fail(m.path, "comment msgs_bands",
                   io::cat("two single-band models without band names (also ", models_[wildcard_->model]->path.string(),
                           "): cannot tell which band each renders"));
        wildcard_ = BandSource{index, 0, 1};
      } else if (m.channels() == rgb.channels) {
        claim(rgb.id, BandSource{index, 0, rgb.channels}, m);
      } else {  // the standard Joint layout
        for (const auto& b : io::standard_bands()) claim(b.id, BandSource{index, b.first_channel_in_joint, b.channels}, m);
      }
      return;
    }
    bool any = false;
    for (const auto& b : io::standard_bands()) {
      // A band's channel names are its slice of the Joint names: D_R D_G D_B, or MS_NIR.
      const auto first = joint.begin() + b.first_channel_in_joint;
      const std::vector<std::string> want(first, first + b.channels);
      for (std::size_t c = 0; c + want.size() <= names.size(); ++c)
        if (std::equal(want.begin(), want.end(), names.begin() + std::ptrdiff_t(c))) {
          claim(b.id, BandSource{index, int(c), b.channels}, m);
          any = true;
          break;
        }
    }
    if (!any) {
      std::string got, known;
      for (const auto& n : names) got += (got.empty() ? "" : " ") + n;
      for (const auto& n : joint) known += (known.empty() ? "" : " ") + n;
      io::fail(m.path, "comment msgs_bands", io::cat("channel names '", got, "' match no known band (expected ", known, ")"));
    }
  }

  std::vector<std::shared_ptr<const LoadedModel>> models_;
  std::vector<ChannelRenderer> renderers_;
  std::map<std::string, BandSource> named_;
  std::optional<BandSource> wildcard_;
};

}  // namespace msgs
