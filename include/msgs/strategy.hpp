// include/msgs/strategy.hpp
// The paper's training strategies (Separate, Split, Joint) and modifiers (SpecDelay, ExtADC,
// MSAD, SIG) as compile-time policies: `Joint<SpecDelay, MSAD>` is Joint-Optimized. Each policy
// configures the run plan and may hook the step before the backward pass; a run-time name such as
// "joint+specdelay+msad" maps to the same types.
#pragma once

#include <algorithm>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "adam.hpp"
#include "densify.hpp"
#include "schedule.hpp"

namespace msgs {

/// The three strategies of the paper (Sec. 3.2).
enum class StrategyKind { Separate, Split, Joint };

inline const char* to_string(StrategyKind k) {
  switch (k) {
    case StrategyKind::Separate: return "separate";
    case StrategyKind::Split: return "split";
    case StrategyKind::Joint: return "joint";
  }
  return "?";
}

/// Everything a strategy and its modifiers decide about a run, resolved before training. All
/// iteration counts are the reference ones multiplied by the schedule scale.
struct TrainPlan {
  StrategyKind kind = StrategyKind::Joint;
  ScheduleScale scale{};
  /// Steps of one optimisation: Separate 30k per band; Split 30k for RGB then 30k more per band
  /// (the band model's step counter continues from 30k to 60k); Joint 120k.
  int stage_steps = 120000;
  TrainSchedule schedule{};       ///< SH growth, colour-only warm-up, resolution schedule
  DensifyConfig densify{};        ///< adaptive density control
  int spectral_start = 0;         ///< SpecDelay: spectral bands are sampled from this step on
  int spectral_geometry_start = 0;///< SpecDelay: spectral steps update geometry from this step on
  bool sig = false;               ///< SIG: spectral steps never update geometry or opacity
  std::string name;               ///< canonical run-time name

  /// Total optimisation steps over all models of the run (Split: 30k + 4 x 30k = 150k).
  long long total_steps(int spectral_bands) const {
    switch (kind) {
      case StrategyKind::Separate: return (long long)stage_steps * (1 + spectral_bands);
      case StrategyKind::Split: return (long long)stage_steps * (1 + spectral_bands);
      case StrategyKind::Joint: return stage_steps;
    }
    return stage_steps;
  }
};

/// What a hook sees and may change in one training step, before the backward pass.
struct StepContext {
  long long step = 0;
  int band = 0;            ///< index of the rendered band in the trainer's band list
  bool spectral = false;   ///< the rendered band is a narrow band (not the RGB camera)
  AdamMask mask{};         ///< which parameter groups this step updates
  bool observe_density = true;  ///< feed this step's screen-space gradients to densification
};

/// Base of the modifier policies: every hook defaults to doing nothing.
struct Modifier {
  static void configure(TrainPlan&) {}
  /// May the trainer sample a band of this kind at `step`?
  static bool band_enabled(const TrainPlan&, long long /*step*/, bool /*spectral*/) { return true; }
  /// Adjust the step (masks, statistics) before the backward pass.
  static void pre_backward(const TrainPlan&, StepContext&) {}
};

/// Freeze means, scales and rotations (and opacity when `opacity`) for this step.
inline void freeze_geometry(AdamMask& m, bool opacity) {
  m.means = m.scales = m.quats = false;
  if (opacity) m.opacities = false;
}

/// Smallest refinement interval a scaled schedule may use. Statistics averaged over fewer views are
/// single-view noise: at scale 0.005 the interval would round to 1 step and the Gaussian count
/// grows every step (150k on a 96x72 image in minutes). The opacity reset keeps its 30x ratio.
inline constexpr int kMinRefineEvery = 5;

/// Earliest step a scaled schedule may start densifying at. The reference starts at step 500,
/// when the colour warm-up has fitted the colours; scaling that to 13 steps (scale 0.025) starts
/// densifying a model that still has its random initial colours, whose gradients exceed the
/// threshold nearly everywhere, so every refinement duplicates or splits almost every Gaussian:
/// a single-band Separate model on the `small` scene went 6k -> 118k -> 2.7M Gaussians in 50 steps.
/// The optimiser's learning rates do not scale, so the warm-up it needs does not either. Measured on
/// `small` at scale 0.025 (PSNR / Gaussians): Separate G 29.3 dB / 96k with a start of 100 steps,
/// 29.9 / 56k with 250; Joint 19.5 / 24k and 22.7 / 24k; Joint-Optimized 28.0 / 102k and 27.7 / 91k
/// (27.0 / 90k with the scaled 13). Full-length schedules (scale >= 0.5) are not affected.
inline constexpr int kMinRefineStart = 250;

/// Apply kMinRefineEvery and kMinRefineStart to a scaled density-control schedule.
inline void floor_refine_schedule(DensifyConfig& d) {
  if (d.refine_every < kMinRefineEvery) d.refine_every = kMinRefineEvery;
  if (d.reset_every > 0 && d.reset_every < 30 * d.refine_every) d.reset_every = 30 * d.refine_every;
  if (d.refine_start < kMinRefineStart) d.refine_start = kMinRefineStart;
}

/// SpecDelay: RGB only for the first 30k steps; densification (statistics, refinement and opacity
/// resets) paused for steps 29001..32001; spectral colours then warm up for 2k steps with geometry
/// frozen (paper Sec. 3.2.4 and 4.3). The window is the reference command's `29000 32001` (start
/// exclusive, end inclusive), so its end is the scaled 32000 plus one step.
struct SpecDelay : Modifier {
  static constexpr std::string_view name = "specdelay";
  static void configure(TrainPlan& p) {
    p.spectral_start = p.scale(30000);
    p.spectral_geometry_start = p.scale(32000);
    p.densify.pause_begin = p.scale(29000);
    p.densify.pause_end = p.scale(32000) + 1;
  }
  static bool band_enabled(const TrainPlan& p, long long step, bool spectral) {
    return !spectral || step >= p.spectral_start;
  }
  static void pre_backward(const TrainPlan& p, StepContext& c) {
    if (c.spectral && c.step < p.spectral_geometry_start) freeze_geometry(c.mask, true);
  }
};

/// ExtADC: densify until 60k (45k of a Split band model's 60k steps).
struct ExtADC : Modifier {
  static constexpr std::string_view name = "extadc";
  static void configure(TrainPlan& p) {
    p.densify.refine_stop = p.scale(p.kind == StrategyKind::Split ? 45000 : 60000);
  }
};

/// MSAD: per-band accumulators of the absolute screen-space gradient, densify where the maximum
/// over bands exceeds 0.0008, refine every 300 steps, always until 60k.
struct MSAD : Modifier {
  static constexpr std::string_view name = "msad";
  static void configure(TrainPlan& p) {
    const DensifyConfig m = DensifyConfig::msad().scaled(p.scale);
    DensifyConfig& d = p.densify;
    d.per_band = true;
    d.absgrad = m.absgrad;
    d.grow_grad2d = m.grow_grad2d;
    d.refine_every = m.refine_every;
    d.reset_every = m.reset_every;
    d.refine_stop = p.scale(60000);
    floor_refine_schedule(d);
  }
};

/// SIG: only RGB steps update means, scales, rotations and opacities; spectral steps update
/// colour. Densification statistics still accumulate from spectral steps.
struct SIG : Modifier {
  static constexpr std::string_view name = "sig";
  static void configure(TrainPlan& p) { p.sig = true; }
  static void pre_backward(const TrainPlan&, StepContext& c) {
    if (c.spectral) freeze_geometry(c.mask, true);
  }
};

/// Which adaptive density control the modifiers start from.
enum class DensifyPreset {
  MultiSpectral,  ///< the multi-spectral implementation (nerfstudio splatfacto), the default
  Gsplat,         ///< gsplat's DefaultStrategy / original 3DGS: 0.0002 on the plain gradient, prune < 0.005
};

/// Densification of the baseline. MultiSpectral (nerfstudio splatfacto, on which the paper builds):
/// one accumulator of the absolute gradient, threshold 0.0008, refine every 100 steps until 15k,
/// opacity reset every 3000 steps to 0.2, prune opacity < 0.1. Gsplat: DensifyConfig::gsplat_default().
inline DensifyConfig baseline_densify(const ScheduleScale& s, DensifyPreset preset = DensifyPreset::MultiSpectral) {
  DensifyConfig c = preset == DensifyPreset::Gsplat ? DensifyConfig::gsplat_default() : DensifyConfig::msad();
  if (preset == DensifyPreset::MultiSpectral) {
    c.per_band = false;
    c.refine_every = 100;
    c.reset_every = 3000;
    c.refine_stop = 15000;
  }
  c = c.scaled(s);
  floor_refine_schedule(c);
  return c;
}

/// "msgs" / "multispectral" or "gsplat" / "3dgs".
inline DensifyPreset parse_densify_preset(std::string_view name) {
  if (name == "msgs" || name == "multispectral" || name == "splatfacto") return DensifyPreset::MultiSpectral;
  if (name == "gsplat" || name == "3dgs") return DensifyPreset::Gsplat;
  throw std::invalid_argument("unknown densification preset '" + std::string(name) + "'; valid: msgs, gsplat");
}

namespace detail {
template <class T, class... Ts>
inline constexpr bool contains_v = (std::is_same_v<T, Ts> || ...);

/// Fold the modifiers' hooks; the colour-only warm-up of the first 500 steps is common to all.
template <class... Mods>
struct ModifierSet {
  static void configure([[maybe_unused]] TrainPlan& p) { (Mods::configure(p), ...); }
  static bool band_enabled([[maybe_unused]] const TrainPlan& p, [[maybe_unused]] long long step,
                           [[maybe_unused]] bool spectral) {
    return (Mods::band_enabled(p, step, spectral) && ...);
  }
  static void pre_backward(const TrainPlan& p, StepContext& c) {
    if (p.schedule.geometry_frozen(c.step)) freeze_geometry(c.mask, false);
    (Mods::pre_backward(p, c), ...);
  }
  static std::string suffix() {
    std::string s;
    ((s += "+", s += std::string(Mods::name)), ...);
    return s;
  }
};
}  // namespace detail

/// Hooks of a strategy as plain function pointers, so the trainer is not a template on the
/// strategy (one trainer instantiation per model type serves every configuration).
struct StrategyHooks {
  bool (*band_enabled)(const TrainPlan&, long long, bool) = nullptr;
  void (*pre_backward)(const TrainPlan&, StepContext&) = nullptr;
};

/// Common part of the three strategies.
template <StrategyKind Kind, int StageSteps, class... Mods>
struct StrategyBase {
  using modifiers = detail::ModifierSet<Mods...>;
  static constexpr StrategyKind kind = Kind;
  static std::string name() { return std::string(to_string(Kind)) + modifiers::suffix(); }
  static TrainPlan plan(const ScheduleScale& scale = {}, DensifyPreset preset = DensifyPreset::MultiSpectral) {
    TrainPlan p;
    p.kind = Kind;
    p.scale = scale;
    p.stage_steps = scale(StageSteps);
    TrainSchedule sched;
    sched.total_steps = Kind == StrategyKind::Split ? 2 * StageSteps : StageSteps;
    p.schedule = sched.scaled(scale);
    p.densify = baseline_densify(scale, preset);
    p.name = name();
    modifiers::configure(p);
    return p;
  }
  static StrategyHooks hooks() { return {&modifiers::band_enabled, &modifiers::pre_backward}; }
};

/// Separate: one model per band (`<3>` for RGB, `<1>` per narrow band), 30k steps each.
template <class... Mods>
struct Separate : StrategyBase<StrategyKind::Separate, 30000, Mods...> {
  static_assert(sizeof...(Mods) == 0, "Separate takes no modifiers");
};

/// Split: RGB model for 30k steps, then its geometry copied into one model per band with fresh
/// colour, every parameter optimised with ADC for 30k more.
template <class... Mods>
struct Split : StrategyBase<StrategyKind::Split, 30000, Mods...> {
  static_assert(((std::is_same_v<Mods, ExtADC>) && ...), "Split takes only the ExtADC modifier");
};

/// Joint: one `<7>` model, 120k steps, one band rendered per step.
template <class... Mods>
struct Joint : StrategyBase<StrategyKind::Joint, 120000, Mods...> {
  static_assert(!(detail::contains_v<ExtADC, Mods...> && detail::contains_v<MSAD, Mods...>),
                "MSAD always densifies until 60k: combining it with ExtADC is contradictory");
};

/// Joint + SpecDelay + MSAD, the paper's best configuration.
using JointOptimized = Joint<SpecDelay, MSAD>;

/// A strategy resolved from its run-time name.
struct StrategySpec {
  TrainPlan plan;
  StrategyHooks hooks;
};

namespace detail {
/// Calls f(Strategy{}) for each of the 15 configurations of the paper's ablation table.
template <class F>
void for_each_strategy(F&& f) {
  f(Separate<>{});
  f(Split<>{});
  f(Split<ExtADC>{});
  f(Joint<SIG>{});
  f(Joint<SIG, ExtADC>{});
  f(Joint<SIG, MSAD>{});
  f(Joint<SIG, SpecDelay>{});
  f(Joint<SIG, SpecDelay, ExtADC>{});
  f(Joint<SIG, SpecDelay, MSAD>{});
  f(Joint<>{});
  f(Joint<ExtADC>{});
  f(Joint<MSAD>{});
  f(Joint<SpecDelay>{});
  f(Joint<SpecDelay, ExtADC>{});
  f(Joint<SpecDelay, MSAD>{});
}

/// "joint+msad+specdelay" -> "joint+specdelay+msad": modifiers in the paper's order.
inline std::string canonical_strategy_name(std::string_view name) {
  std::string lower(name);
  for (char& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (lower == "joint-optimized" || lower == "joint_optimized" || lower == "jointoptimized") return "joint+specdelay+msad";
  // getline drops an empty last field, so "joint+" would read as "joint": keep it invalid.
  if (!lower.empty() && lower.back() == '+') return lower;
  std::vector<std::string> parts;
  std::stringstream ss(lower);
  for (std::string part; std::getline(ss, part, '+');) parts.push_back(part);
  if (parts.empty()) return lower;
  static const std::vector<std::string> order = {"sig", "specdelay", "extadc", "msad"};
  std::vector<std::string> mods(parts.begin() + 1, parts.end());
  for (const auto& m : mods)
    if (std::count(mods.begin(), mods.end(), m) > 1) return lower;  // repeated modifier: not valid
  std::stable_sort(mods.begin(), mods.end(), [&](const std::string& a, const std::string& b) {
    auto ia = std::find(order.begin(), order.end(), a), ib = std::find(order.begin(), order.end(), b);
    return ia < ib;
  });
  std::string out = parts[0];
  for (const auto& m : mods) out += "+" + m;
  return out;
}
}  // namespace detail

/// The run-time names of the 15 configurations of the paper's ablation table.
inline std::vector<std::string> strategy_names() {
  std::vector<std::string> names;
  detail::for_each_strategy([&](auto s) { names.push_back(decltype(s)::name()); });
  return names;
}

/// Resolve a run-time name ("separate", "split+extadc", "joint+specdelay+msad", "joint-optimized",
/// modifiers in any order). Throws std::invalid_argument listing the valid names otherwise.
inline StrategySpec parse_strategy(std::string_view name, const ScheduleScale& scale = {},
                                   DensifyPreset preset = DensifyPreset::MultiSpectral) {
  const std::string canon = detail::canonical_strategy_name(name);
  StrategySpec spec;
  bool found = false;
  detail::for_each_strategy([&](auto s) {
    using T = decltype(s);
    if (!found && T::name() == canon) {
      spec.plan = T::plan(scale, preset);
      spec.hooks = T::hooks();
      found = true;
    }
  });
  if (!found) {
    std::string list;
    for (const auto& n : strategy_names()) list += (list.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown or contradictory strategy '" + std::string(name) + "'; valid: " + list +
                                " (and joint-optimized = joint+specdelay+msad)");
  }
  return spec;
}

}  // namespace msgs
