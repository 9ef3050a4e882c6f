// include/msgs/export.hpp
// What of a multi-spectral model goes into a file that ordinary 3DGS viewers open (three colour
// channels): one band, the colour-infrared composite, or a spectral index, as a 3-channel model.
//
//   band       a 3-channel band (D) as it is; a 1-channel band copied into all three channels,
//              DC and every SH coefficient, so each channel renders exactly as the band does.
//   cir        NIR, R, G as red, green, blue: a channel selection, exact, since colour is linear
//              in the SH coefficients of its own channel. Needs the three bands on the same
//              Gaussians, i.e. one Joint model; per-band models (Separate, Split) have different
//              Gaussians for each band and are refused (export the bands one by one instead).
//   index      the index of the two bands' view-independent DC colours (max(0, C0 dc + 0.5)) per
//              Gaussian, through the diverging colour scale the viewer uses, as an SH-degree-0
//              model. An approximation: `msgs view` and `msgs render` compute indices per pixel
//              from rendered bands, where many Gaussians blend; a ratio of blends is not a blend
//              of ratios, and view-dependent colour is left out.
//
// Gaussians that the rasteriser would never draw (a non-finite value in the exported channels or
// the geometry, a quaternion shorter than kMinQuatNorm) are dropped, and log-scales beyond the
// rasteriser's clamp (+-50) are clamped to it, so an export renders in msgs as its source did
// and no viewer is handed a NaN. write_export writes the result as .ply, .splat or .spz.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "msgs/gaussian.hpp"
#include "msgs/io/bands.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/image_io.hpp"
#include "msgs/io/ply.hpp"
#include "msgs/io/splat_formats.hpp"
#include "msgs/project.hpp"
#include "msgs/render_util.hpp"
#include "msgs/sh.hpp"

namespace msgs {

/// A 3-channel model of any SH degree: what ordinary viewers open.
using RgbModel = std::variant<ModelOf<3, 0>, ModelOf<3, 1>, ModelOf<3, 2>, ModelOf<3, 3>>;

/// A spectral index for a per-Gaussian export: `value(a, b)` of the colours of the formula's two
/// bands, shown on Colormap::diverging with `lo` at the low end and `hi` at the high end. The
/// definitions live with the viewer (examples/view_api.hpp); the export takes them as data.
struct IndexSpec {
  std::string name;                          ///< for messages and summaries, e.g. "NDVI"
  std::string band_a, band_b;                ///< the formula's bands, e.g. MS_NIR and MS_R
  std::function<float(float, float)> value;  ///< must be total: finite for any input
  float lo = -1.0f, hi = 1.0f;               ///< colour scale range
};

/// What to export.
struct ExportSelection {
  enum Kind { band, cir, index } kind = band;
  std::string band_id;  ///< kind == band: D, MS_G, MS_R, MS_RE or MS_NIR
  IndexSpec idx;        ///< kind == index
};

/// A band, composite or index of a model as a 3-channel model, and where it came from.
struct ExportedModel {
  RgbModel model;
  std::vector<std::string> channel_names;  ///< `msgs_bands` names of the 3 channels; empty for an index
  std::filesystem::path source;            ///< the model file the channels came from
  std::string what;                        ///< "band MS_NIR", "CIR (MS_NIR, MS_R, MS_G)", "NDVI (per Gaussian)"
  std::size_t dropped = 0;                 ///< Gaussians left out: non-finite values or zero quaternion
  std::size_t clamped = 0;                 ///< Gaussians whose log-scales were clamped to +-kLogScaleClamp
  std::size_t size() const {
    return std::visit([](const auto& m) { return m.size(); }, model);
  }
  int sh_degree() const { return int(model.index()); }
};

/// A problem with what was asked for (a band the model lacks, CIR of per-band models): the
/// message says what the model has and the way out.
struct ExportError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

/// File formats write_export writes.
enum class ExportFormat { ply, splat, spz };

/// The format named by a file's extension (.ply, .splat, .spz; any case); throws ExportError otherwise.
inline ExportFormat export_format_from_path(const std::filesystem::path& p) {
  const std::string ext = io::detail::lower_extension(p);
  if (ext == ".ply") return ExportFormat::ply;
  if (ext == ".splat") return ExportFormat::splat;
  if (ext == ".spz") return ExportFormat::spz;
  throw ExportError(p.string() + ": cannot tell the format from the extension '" + ext +
                    "' (expected .ply, .splat or .spz; or name the format explicitly)");
}

/// "ply" | "splat" | "spz" -> ExportFormat; throws ExportError otherwise.
inline ExportFormat parse_export_format(std::string_view s) {
  if (s == "ply") return ExportFormat::ply;
  if (s == "splat") return ExportFormat::splat;
  if (s == "spz") return ExportFormat::spz;
  throw ExportError("unknown export format '" + std::string(s) + "' (expected ply, splat or spz)");
}

namespace detail {

/// Out channel c = channel pick[c] of `m`, every SH coefficient and the geometry copied.
template <class G>
ModelOf<3, G::sh_degree> pick_channels(const GaussianModel<G, float>& m, const std::array<int, 3>& pick) {
  ModelOf<3, G::sh_degree> o(m.size());
  o.means = m.means;
  o.log_scales = m.log_scales;
  o.quats = m.quats;
  o.opacity_logits = m.opacity_logits;
  // Band planes: a channel is one contiguous run of N rows (the planes' capacities may differ).
  const std::size_t values = m.size() * std::size_t(G::sh_coeffs);
  for (int c = 0; c < 3; ++c)
    if (values > 0) std::copy_n(m.sh_row(0, pick[std::size_t(c)]), values, o.sh_row(0, c));
  return o;
}

/// DC-only colour of channel c of Gaussian i, as the renderer forms it: max(0, C0 dc + 0.5).
template <class G>
float dc_colour(const GaussianModel<G, float>& m, std::size_t i, int c) {
  return float(std::max(0.0, sh::C0 * double(m.sh_at(i, 0, c)) + 0.5));
}

/// The SH DC coefficient whose colour is `colour`: (colour - 0.5) / C0.
inline float dc_for_colour(float colour) { return float((double(colour) - 0.5) / sh::C0); }

/// Per-Gaussian index colours of channels a and b of `m`, degree 0. A Gaussian whose a or b DC
/// is not finite gets a NaN colour, so that sanitize_for_export drops it (the rasteriser would
/// not draw it in either band).
template <class G>
ModelOf<3, 0> index_colours(const GaussianModel<G, float>& m, int a, int b, const IndexSpec& spec) {
  ModelOf<3, 0> o(m.size());
  o.means = m.means;
  o.log_scales = m.log_scales;
  o.quats = m.quats;
  o.opacity_logits = m.opacity_logits;
  const float span = spec.hi - spec.lo;
  for (std::size_t i = 0; i < m.size(); ++i) {
    std::array<float, 3> rgb;
    if (!std::isfinite(m.sh_at(i, 0, a)) || !std::isfinite(m.sh_at(i, 0, b))) {
      rgb.fill(std::numeric_limits<float>::quiet_NaN());
    } else {
      const float v = spec.value(dc_colour(m, i, a), dc_colour(m, i, b));
      rgb = colour_at(Colormap::diverging, (v - spec.lo) / span);
    }
    for (int c = 0; c < 3; ++c) {
      const float v = rgb[std::size_t(c)];
      o.sh_at(i, 0, c) = std::isfinite(v) ? dc_for_colour(v) : v;
    }
  }
  return o;
}

}  // namespace detail

/// Drop the Gaussians the rasteriser never draws (a non-finite value anywhere in `m`, a
/// quaternion shorter than kMinQuatNorm) and clamp log-scales to +-kLogScaleClamp, as the
/// rasteriser does. Order is kept. Returns {dropped, clamped} counts of Gaussians.
template <int D>
std::pair<std::size_t, std::size_t> sanitize_for_export(ModelOf<3, D>& m) {
  using PC = ProjectConstants;
  constexpr int K = Gaussian<3, D>::sh_coeffs;
  const std::size_t n = m.size(), plane = m.sh_plane_stride();
  std::vector<std::size_t> keep;
  keep.reserve(n);
  std::size_t clamped = 0;
  for (std::size_t i = 0; i < n; ++i) {
    bool ok = std::isfinite(m.opacity_logits[i]);
    double q2 = 0;
    for (int d = 0; d < 3; ++d)
      ok = ok && std::isfinite(m.means[3 * i + std::size_t(d)]) && std::isfinite(m.log_scales[3 * i + std::size_t(d)]);
    for (int d = 0; d < 4; ++d) {
      const double q = m.quats[4 * i + std::size_t(d)];
      ok = ok && std::isfinite(q);
      q2 += q * q;
    }
    ok = ok && std::sqrt(q2) >= PC::kMinQuatNorm;
    for (int c = 0; c < 3 && ok; ++c)
      for (int k = 0; k < K; ++k) ok = ok && std::isfinite(m.sh_at(i, k, c));
    if (!ok) continue;
    keep.push_back(i);
    bool any = false;
    for (int d = 0; d < 3; ++d) {
      float& s = m.log_scales[3 * i + std::size_t(d)];
      const float cl = float(std::clamp(double(s), -PC::kLogScaleClamp, PC::kLogScaleClamp));
      any = any || cl != s;
      s = cl;
    }
    clamped += any ? 1 : 0;
  }
  if (keep.size() == n) return {0, clamped};
  // Compact in place (keep is increasing, so every row moves down or stays).
  std::vector<float> sh(3 * keep.size() * std::size_t(K));
  for (std::size_t j = 0; j < keep.size(); ++j) {
    const std::size_t i = keep[j];
    for (int d = 0; d < 3; ++d) m.means[3 * j + std::size_t(d)] = m.means[3 * i + std::size_t(d)];
    for (int d = 0; d < 3; ++d) m.log_scales[3 * j + std::size_t(d)] = m.log_scales[3 * i + std::size_t(d)];
    for (int d = 0; d < 4; ++d) m.quats[4 * j + std::size_t(d)] = m.quats[4 * i + std::size_t(d)];
    m.opacity_logits[j] = m.opacity_logits[i];
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < K; ++k)
        sh[std::size_t(c) * keep.size() * std::size_t(K) + j * std::size_t(K) + std::size_t(k)] =
            m.sh[std::size_t(c) * plane + i * std::size_t(K) + std::size_t(k)];
  }
  const std::size_t dropped = n - keep.size();
  m.means.resize(3 * keep.size());
  m.log_scales.resize(3 * keep.size());
  m.quats.resize(4 * keep.size());
  m.opacity_logits.resize(keep.size());
  m.sh = std::move(sh);
  m.check_consistent();
  return {dropped, clamped};
}

namespace detail {

/// "D, MS_G, MS_NIR": the standard bands some model of `models` renders.
inline std::string bands_present(const ModelSet& models) {
  std::string s;
  for (const auto& b : io::standard_bands())
    if (models.renders(b.id)) s += (s.empty() ? "" : ", ") + b.id;
  return s.empty() ? "none" : s;
}

/// The model file, or the folder of the per-band files, for messages.
inline std::string where(const ModelSet& models) {
  const auto& ms = models.models();
  if (ms.size() == 1) return ms.front()->path.string();
  return ms.front()->path.parent_path().string() + " (" + std::to_string(ms.size()) + " model_*.ply files)";
}

/// The source of `band` for a composite: a model that names it, or an ExportError saying why not.
inline const BandSource& composite_source(const ModelSet& models, const std::string& band, const std::string& what) {
  const BandSource* s = models.named_source(band);
  if (!s)
    throw ExportError(where(models) + ": " + what + " needs band " + band +
                      ", which the model does not name (bands present: " +
                      bands_present(models) + "); export a band it has with --band");
  return *s;
}

/// One model holds every band of a composite, or an ExportError explaining why it must.
using NamedSources = std::vector<std::pair<std::string, const BandSource*>>;

inline void require_one_model(const ModelSet& models, const NamedSources& srcs, const std::string& what) {
  for (const auto& [band, s] : srcs) {
    if (s->model == srcs.front().second->model) continue;
    throw ExportError(what + " combines colours per Gaussian, so its bands must live on the same Gaussians (one Joint "
                      "model), but " + srcs.front().first + " comes from " +
                      models.models()[srcs.front().second->model]->path.string() + " and " + band + " from " +
                      models.models()[s->model]->path.string() +
                      ": per-band models (Separate, Split) have different Gaussians for each band. Export the bands "
                      "one by one (--band " + srcs.front().first + ", --band " + band +
                      ", ...), or look at the composite in `msgs view`, which combines rendered bands per pixel");
  }
}

template <class F>
auto visit_loaded(const LoadedModel& m, F&& f) {
  return std::visit(std::forward<F>(f), m.model);
}

}  // namespace detail

/// A ModelSet for reading only (its renderers refuse to render): load_model and the band rules of
/// ModelSet without compiling a Rasterizer. `ply_or_dir` as ModelSet::load.
inline ModelSet load_models_for_export(const std::filesystem::path& ply_or_dir) {
  return ModelSet::load(ply_or_dir, [](std::shared_ptr<const LoadedModel>) -> ChannelRenderer {
    return [](const Camera<float>&, const RenderSettings<float>&) -> Image<float> {
      throw std::logic_error("load_models_for_export: this ModelSet does not render");
    };
  });
}

/// The selected band, composite or index of `models` as a 3-channel model, sanitised (see the top
/// of this file). Throws ExportError when the models cannot provide it, with the bands present
/// and the way out.
inline ExportedModel select_export(const ModelSet& models, const ExportSelection& sel) {
  ExportedModel out;
  if (sel.kind == ExportSelection::band) {
    const io::BandInfo* info = io::find_band(sel.band_id);
    if (!info) {
      std::string known;
      for (const auto& b : io::standard_bands()) known += (known.empty() ? "" : ", ") + b.id;
      throw ExportError("unknown band '" + sel.band_id + "' (band ids: " + known + ")");
    }
    const BandSource* s = models.source(sel.band_id);
    if (!s)
      throw ExportError(detail::where(models) + ": the model has no band " + sel.band_id +
                        " (bands present: " + detail::bands_present(models) +
                        "); export one of those with --band");
    const LoadedModel& m = *models.models()[s->model];
    const int f = s->first_channel;
    const std::array<int, 3> pick =
        s->channels == 3 ? std::array<int, 3>{f, f + 1, f + 2} : std::array<int, 3>{f, f, f};
    out.model = detail::visit_loaded(m, [&](const auto& g) -> RgbModel { return detail::pick_channels(g, pick); });
    out.source = m.path;
    out.what = "band " + sel.band_id;
    if (s->channels == 3) {
      const std::vector<std::string> joint = io::joint_channel_names();
      out.channel_names.assign(joint.begin() + info->first_channel_in_joint,
                               joint.begin() + info->first_channel_in_joint + 3);
    } else {
      out.channel_names.assign(3, sel.band_id);
    }
  } else if (sel.kind == ExportSelection::cir) {
    const std::string what = "colour infrared (NIR, R, G as red, green, blue)";
    const std::vector<std::string> bands = {"MS_NIR", "MS_R", "MS_G"};
    detail::NamedSources srcs;
    for (const auto& b : bands) srcs.emplace_back(b, &detail::composite_source(models, b, what));
    detail::require_one_model(models, srcs, what);
    const LoadedModel& m = *models.models()[srcs[0].second->model];
    const std::array<int, 3> pick = {srcs[0].second->first_channel, srcs[1].second->first_channel,
                                     srcs[2].second->first_channel};
    out.model = detail::visit_loaded(m, [&](const auto& g) -> RgbModel { return detail::pick_channels(g, pick); });
    out.source = m.path;
    out.what = "CIR (MS_NIR, MS_R, MS_G)";
    out.channel_names = bands;
  } else {
    const IndexSpec& spec = sel.idx;
    if (!spec.value || !(std::isfinite(spec.lo) && std::isfinite(spec.hi) && spec.hi > spec.lo))
      throw ExportError("index " + spec.name + ": needs a value function and a finite range lo < hi");
    const std::string what = spec.name + " (per Gaussian)";
    detail::NamedSources srcs;
    for (const auto& b : {spec.band_a, spec.band_b}) srcs.emplace_back(b, &detail::composite_source(models, b, what));
    detail::require_one_model(models, srcs, what);
    const LoadedModel& m = *models.models()[srcs[0].second->model];
    const int a = srcs[0].second->first_channel, b = srcs[1].second->first_channel;
    out.model =
        detail::visit_loaded(m, [&](const auto& g) -> RgbModel { return detail::index_colours(g, a, b, spec); });
    out.source = m.path;
    out.what = what;
  }
  std::tie(out.dropped, out.clamped) = std::visit([](auto& g) { return sanitize_for_export(g); }, out.model);
  return out;
}

/// Write `e` to `p` in format `fmt` (PLY with the channel names in its `msgs_bands` comment),
/// atomically. `spz` applies to ExportFormat::spz only.
inline void write_export(const std::filesystem::path& p, const ExportedModel& e, ExportFormat fmt,
                         const io::SpzOptions& spz = {}) {
  std::visit(
      [&](const auto& m) {
        switch (fmt) {
          case ExportFormat::ply: io::write_ply(p, m, e.channel_names); break;
          case ExportFormat::splat: io::write_splat(p, m); break;
          case ExportFormat::spz: io::write_spz(p, m, spz); break;
        }
      },
      e.model);
}

}  // namespace msgs
