// include/msgs/presets.hpp
// Training presets. `reference` follows the multi-spectral reference implementation in every detail
// msgs knows of (REFERENCE §9: clamped renders before the loss, valid-window SSIM, a reshuffle of
// each band's images on every pass, the reference's pause window); it is what TrainOptions{} holds.
// `fast` is for CPU budgets: the reference plus named departures, each of which the convergence
// study measures against the reference.
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "adam.hpp"
#include "schedule.hpp"

namespace msgs {

enum class Preset { reference, fast };

inline const char* to_string(Preset p) { return p == Preset::fast ? "fast" : "reference"; }

/// "reference" or "fast"; std::invalid_argument otherwise.
inline Preset parse_preset(std::string_view s) {
  if (s == "reference") return Preset::reference;
  if (s == "fast") return Preset::fast;
  throw std::invalid_argument("unknown preset '" + std::string(s) + "'; valid: reference, fast");
}

/// One way a preset departs from the reference, for reports.
struct PresetDeparture {
  std::string name;  ///< short id, as the convergence study labels it
  std::string what;  ///< one sentence
};

/// Learning rate of the SH DC (base colour) coefficients in the fast preset: the reference's 0.0025
/// times sqrt(0.4 / scale), between 1x and 10x. A shortened schedule gives colours fewer steps to
/// travel the same distance; at scale 0.025 this is 0.01, where a fixed 0.01 lifted Joint-Optimized on
/// `small` from 27.7 to 32.2 dB; from scale 0.4 on it is the reference's rate.
inline double fast_lr_sh_dc(double scale) {
  ScheduleScale{scale}.validate();
  return AdamConfig{}.lr_sh_dc * std::clamp(std::sqrt(0.4 / scale), 1.0, 10.0);
}

/// The departures of `p` from the reference at schedule scale `scale` (empty for the reference).
/// colour-lr is listed only where it changes the rate (below scale 0.4): from 0.4 on the fast
/// preset differs from the reference by spectral-init alone, so its Separate and plain Joint runs
/// (which have no narrow band joining trained geometry) are the reference's, bit for bit.
inline std::vector<PresetDeparture> preset_departures(Preset p, double scale) {
  if (p == Preset::reference) return {};
  std::vector<PresetDeparture> out;
  if (const double lr = fast_lr_sh_dc(scale); lr != AdamConfig{}.lr_sh_dc)
    out.push_back({"colour-lr", "SH DC learning rate " + std::to_string(lr) +
                                    " (reference 0.0025): 0.0025 sqrt(0.4 / scale), between 1x and 10x"});
  out.push_back({"spectral-init", "narrow bands start from the geometry band's luminance at their own brightness, "
                                  "not from random colours (SpecDelay's Joint and Split's band models)"});
  return out;
}

/// Set the options `p` decides in `t` (a TrainOptions, train.hpp), for a run at schedule scale
/// `scale`. Call it on fresh options, then apply any explicit user choice on top.
template <class Options>
void apply_preset(Preset p, Options& t, double scale) {
  const Options ref{};
  t.loss.ssim_border = ref.loss.ssim_border;
  t.clamp_render = ref.clamp_render;
  t.shuffle = ref.shuffle;
  t.eval_ssim = ref.eval_ssim;
  t.adam.lr_sh_dc = ref.adam.lr_sh_dc;
  t.sparse = ref.sparse;
  t.spectral_colour_init = ref.spectral_colour_init;
  if (p == Preset::fast) {
    t.adam.lr_sh_dc = fast_lr_sh_dc(scale);
    t.spectral_colour_init = true;
  }
}

}  // namespace msgs
