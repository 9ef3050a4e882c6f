// tests/test_strategy.cpp
// Tests of the strategy policies: run-time names, the plan each one resolves to (every iteration
// count scaled), and the hooks (band enabling, Adam masks) as pure functions of the step.
#include <doctest/doctest.h>

#include <msgs/strategy.hpp>

#include <algorithm>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace test_strategy {
using namespace msgs;

namespace {

/// The 15 configurations of the paper's ablation table, written out independently of the header.
const std::vector<std::string> kExpectedNames = {
    "separate",
    "split",
    "split+extadc",
    "joint+sig",
    "joint+sig+extadc",
    "joint+sig+msad",
    "joint+sig+specdelay",
    "joint+sig+specdelay+extadc",
    "joint+sig+specdelay+msad",
    "joint",
    "joint+extadc",
    "joint+msad",
    "joint+specdelay",
    "joint+specdelay+extadc",
    "joint+specdelay+msad",
};

std::string error_of(const std::string& name) {
  try {
    (void)parse_strategy(name);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

/// The mask a strategy's hook leaves for one step of a band with channels [first, first + count).
AdamMask mask_at(const StrategySpec& s, long long step, bool spectral, int first = 0, int count = 3) {
  StepContext c;
  c.step = step;
  c.spectral = spectral;
  c.mask = AdamMask::band(first, count);
  s.hooks.pre_backward(s.plan, c);
  CHECK(c.mask.sh);  // no hook ever freezes colour
  CHECK(c.mask.sh_first == first);
  CHECK(c.mask.sh_count == count);
  CHECK(c.observe_density);  // SIG: statistics still accumulate from spectral steps
  return c.mask;
}

bool geometry_on(const AdamMask& m) { return m.means && m.scales && m.quats; }
bool geometry_off(const AdamMask& m) { return !m.means && !m.scales && !m.quats; }

}  // namespace

TEST_CASE("strategy_names lists the 15 configurations, each resolving to itself") {
  const std::vector<std::string> names = strategy_names();
  CHECK(names == kExpectedNames);
  CHECK(std::set<std::string>(names.begin(), names.end()).size() == 15);
  for (const auto& n : names) {
    CAPTURE(n);
    const StrategySpec s = parse_strategy(n);
    CHECK(s.plan.name == n);
    CHECK(bool(s.hooks.band_enabled));
    CHECK(bool(s.hooks.pre_backward));
    const StrategyKind want = n.rfind("separate", 0) == 0 ? StrategyKind::Separate
                              : n.rfind("split", 0) == 0  ? StrategyKind::Split
                                                          : StrategyKind::Joint;
    CHECK(s.plan.kind == want);
    CHECK(s.plan.sig == (n.find("+sig") != std::string::npos));  // reported with the run
  }
}

TEST_CASE("modifier order and case do not matter; joint-optimized is joint+specdelay+msad") {
  CHECK(parse_strategy("joint+msad+specdelay").plan.name == "joint+specdelay+msad");
  CHECK(parse_strategy("joint+extadc+specdelay+sig").plan.name == "joint+sig+specdelay+extadc");
  CHECK(parse_strategy("joint+msad+sig+specdelay").plan.name == "joint+sig+specdelay+msad");
  CHECK(parse_strategy("JOINT+MSAD").plan.name == "joint+msad");
  CHECK(parse_strategy("Split+ExtADC").plan.name == "split+extadc");
  for (const char* alias : {"joint-optimized", "Joint-Optimized", "joint_optimized"}) {
    CAPTURE(alias);
    CHECK(parse_strategy(alias).plan.name == "joint+specdelay+msad");
  }
  CHECK(JointOptimized::name() == "joint+specdelay+msad");
  // The type and the run-time name give the same plan.
  const TrainPlan a = JointOptimized::plan(ScheduleScale{0.05});
  const TrainPlan b = parse_strategy("joint+msad+specdelay", ScheduleScale{0.05}).plan;
  CHECK(a.stage_steps == b.stage_steps);
  CHECK(a.spectral_start == b.spectral_start);
  CHECK(a.densify.refine_every == b.densify.refine_every);
  CHECK(a.densify.per_band == b.densify.per_band);
}

TEST_CASE("unknown, contradictory and repeated names are refused with the list of valid names") {
  for (const char* bad : {"joint+foo", "foo", "", "joint+extadc+msad", "joint+msad+extadc", "split+sig", "split+msad",
                          "split+specdelay", "separate+msad", "separate+extadc", "joint+sig+sig",
                          "joint+msad+msad", "split+extadc+extadc", "joint++sig", "joint-optimized+sig", " joint"}) {
    CAPTURE(bad);
    const std::string msg = error_of(bad);
    REQUIRE_FALSE(msg.empty());
    const std::string quoted = std::string("'").append(bad).append("'");
    CHECK(msg.find(quoted) != std::string::npos);  // names the offending input
    for (const auto& n : kExpectedNames) CHECK(msg.find(n) != std::string::npos);
  }
}

TEST_CASE("a trailing '+' is not a valid name") {
  CHECK_FALSE(error_of("joint+").empty());
  CHECK_FALSE(error_of("split+").empty());
}

TEST_CASE("plans at scale 1 carry the paper's counts") {
  const TrainPlan joint = parse_strategy("joint").plan;
  CHECK(joint.kind == StrategyKind::Joint);
  CHECK(joint.stage_steps == 120000);
  CHECK(joint.schedule.total_steps == 120000);
  CHECK(joint.schedule.warmup_steps == 500);
  CHECK(joint.schedule.sh_degree_every == 5000);
  CHECK(joint.schedule.resolution_every == 3000);
  CHECK(joint.total_steps(4) == 120000);
  // Baseline density control: one accumulator, every 100 until 15k, reset every 3000.
  CHECK_FALSE(joint.densify.per_band);
  CHECK(joint.densify.absgrad);
  CHECK(joint.densify.grow_grad2d == doctest::Approx(0.0008));
  CHECK(joint.densify.refine_every == 100);
  CHECK(joint.densify.refine_stop == 15000);
  CHECK(joint.densify.reset_every == 3000);
  CHECK(joint.densify.refine_start == 500);
  CHECK(joint.densify.pause_begin == joint.densify.pause_end);  // no pause
  CHECK(joint.spectral_start == 0);

  const TrainPlan sep = parse_strategy("separate").plan;
  CHECK(sep.stage_steps == 30000);
  CHECK(sep.schedule.total_steps == 30000);
  CHECK(sep.total_steps(4) == 150000);

  const TrainPlan split = parse_strategy("split").plan;
  CHECK(split.stage_steps == 30000);
  CHECK(split.schedule.total_steps == 60000);  // the band models continue the RGB model's counter
  CHECK(split.total_steps(4) == 150000);
  CHECK(split.densify.refine_stop == 15000);
  CHECK(parse_strategy("split+extadc").plan.densify.refine_stop == 45000);
  CHECK(parse_strategy("joint+extadc").plan.densify.refine_stop == 60000);

  const TrainPlan opt = parse_strategy("joint-optimized").plan;
  CHECK(opt.densify.per_band);
  CHECK(opt.densify.refine_every == 300);
  CHECK(opt.densify.reset_every == 9000);
  CHECK(opt.densify.refine_stop == 60000);
  CHECK(opt.spectral_start == 30000);
  CHECK(opt.spectral_geometry_start == 32000);
  CHECK(opt.densify.pause_begin == 29000);
  CHECK(opt.densify.pause_end == 32001);  // the reference's 29000 32001: steps 29001..32001
}

TEST_CASE("the schedule scale reaches every count of every plan") {
  const ScheduleScale s{0.05};
  const TrainPlan joint = parse_strategy("joint", s).plan;
  CHECK(joint.stage_steps == 6000);
  CHECK(joint.schedule.total_steps == 6000);
  CHECK(joint.schedule.warmup_steps == 25);
  CHECK(joint.schedule.sh_degree_every == 250);
  CHECK(joint.schedule.resolution_every == 150);
  CHECK(joint.densify.refine_every == 5);
  CHECK(joint.densify.refine_start == kMinRefineStart);  // 25 scaled, floored to 250
  CHECK(joint.densify.refine_stop == 750);
  CHECK(joint.densify.reset_every == 150);
  CHECK(joint.densify.screen_stop == 200);
  CHECK(joint.densify.images_scale == doctest::Approx(0.05));

  const TrainPlan msad = parse_strategy("joint+msad", s).plan;
  CHECK(msad.densify.per_band);
  CHECK(msad.densify.refine_every == 15);
  CHECK(msad.densify.reset_every == 450);  // 30 x refine_every
  CHECK(msad.densify.refine_stop == 3000);
  CHECK(msad.densify.refine_start == kMinRefineStart);
  CHECK(msad.densify.screen_stop == 200);

  const TrainPlan sd = parse_strategy("joint+specdelay", s).plan;
  CHECK(sd.spectral_start == 1500);
  CHECK(sd.spectral_geometry_start == 1600);
  CHECK(sd.densify.pause_begin == 1450);
  CHECK(sd.densify.pause_end == 1601);
  CHECK(sd.densify.refine_stop == 750);  // SpecDelay alone keeps the baseline stop

  CHECK(parse_strategy("joint+extadc", s).plan.densify.refine_stop == 3000);
  CHECK(parse_strategy("joint+sig+specdelay+extadc", s).plan.densify.refine_stop == 3000);
  CHECK(parse_strategy("joint+sig+specdelay+extadc", s).plan.spectral_start == 1500);

  const TrainPlan split = parse_strategy("split+extadc", s).plan;
  CHECK(split.stage_steps == 1500);
  CHECK(split.schedule.total_steps == 3000);
  CHECK(split.densify.refine_stop == 2250);
  CHECK(split.total_steps(4) == 7500);
  const TrainPlan sep = parse_strategy("separate", s).plan;
  CHECK(sep.stage_steps == 1500);
  CHECK(sep.total_steps(2) == 4500);

  // Every one of the 15 plans is valid for density control at a very small scale.
  for (const auto& n : strategy_names()) {
    CAPTURE(n);
    const TrainPlan p = parse_strategy(n, ScheduleScale{0.002}).plan;
    CHECK_NOTHROW(p.densify.validate());
    CHECK(p.stage_steps >= 1);
    CHECK(p.schedule.warmup_steps == 1);
    CHECK(p.densify.refine_every >= 1);
  }
}

TEST_CASE("colour-only warm-up: geometry frozen for the first (scaled) 500 steps, opacity not") {
  for (const auto& n : strategy_names()) {
    CAPTURE(n);
    const StrategySpec s = parse_strategy(n, ScheduleScale{0.1});  // warm-up 50 steps
    for (long long step : {0LL, 1LL, 49LL}) {
      const AdamMask m = mask_at(s, step, false);
      CHECK(geometry_off(m));
      CHECK(m.opacities);
    }
    const AdamMask m = mask_at(s, 50, false);
    CHECK(geometry_on(m));
    CHECK(m.opacities);
  }
}

TEST_CASE("SIG: spectral steps update colour only, RGB steps everything") {
  for (const char* n : {"joint+sig", "joint+sig+msad", "joint+sig+specdelay+msad"}) {
    CAPTURE(n);
    const StrategySpec s = parse_strategy(n, ScheduleScale{0.01});
    for (long long step : {10LL, 400LL, 1199LL, 100000LL}) {
      const AdamMask spec = mask_at(s, step, true, 4, 1);
      CHECK(geometry_off(spec));
      CHECK_FALSE(spec.opacities);
      const AdamMask rgb = mask_at(s, step, false, 0, 3);
      CHECK(geometry_on(rgb));
      CHECK(rgb.opacities);
    }
  }
  // Without SIG spectral steps after warm-up and after SpecDelay's window update everything.
  const StrategySpec j = parse_strategy("joint", ScheduleScale{0.01});
  CHECK(geometry_on(mask_at(j, 10, true, 4, 1)));
  CHECK(mask_at(j, 10, true, 4, 1).opacities);
}

TEST_CASE("SpecDelay: spectral bands disabled before spectral_start, colour-only until spectral_geometry_start") {
  const StrategySpec s = parse_strategy("joint+specdelay+msad", ScheduleScale{0.05});
  REQUIRE(s.plan.spectral_start == 1500);
  REQUIRE(s.plan.spectral_geometry_start == 1600);
  for (long long step : {0LL, 100LL, 1499LL}) {
    CHECK(s.hooks.band_enabled(s.plan, step, false));
    CHECK_FALSE(s.hooks.band_enabled(s.plan, step, true));
  }
  for (long long step : {1500LL, 1600LL, 6000LL}) {
    CHECK(s.hooks.band_enabled(s.plan, step, false));
    CHECK(s.hooks.band_enabled(s.plan, step, true));
  }
  for (long long step : {1500LL, 1550LL, 1599LL}) {
    const AdamMask m = mask_at(s, step, true, 6, 1);
    CHECK(geometry_off(m));
    CHECK_FALSE(m.opacities);
    const AdamMask rgb = mask_at(s, step, false);
    CHECK(geometry_on(rgb));
    CHECK(rgb.opacities);
  }
  const AdamMask after = mask_at(s, 1600, true, 6, 1);
  CHECK(geometry_on(after));
  CHECK(after.opacities);

  // Without SpecDelay every band is enabled from step 0.
  const StrategySpec j = parse_strategy("joint+msad", ScheduleScale{0.05});
  CHECK(j.hooks.band_enabled(j.plan, 0, true));
}

TEST_CASE("the gsplat/3DGS densification preset is the base the modifiers change") {
  const TrainPlan g = parse_strategy("joint", ScheduleScale{}, DensifyPreset::Gsplat).plan;
  CHECK(g.densify.grow_grad2d == doctest::Approx(0.0002));
  CHECK_FALSE(g.densify.absgrad);
  CHECK_FALSE(g.densify.per_band);
  CHECK(g.densify.prune_opacity == doctest::Approx(0.005));
  CHECK(g.densify.reset_opacity == doctest::Approx(0.01));
  CHECK(g.densify.refine_every == 100);
  CHECK(g.densify.reset_every == 3000);
  CHECK(g.densify.refine_stop == 15000);
  const TrainPlan m = parse_strategy("joint+msad", ScheduleScale{}, DensifyPreset::Gsplat).plan;
  CHECK(m.densify.per_band);
  CHECK(m.densify.absgrad);
  CHECK(m.densify.grow_grad2d == doctest::Approx(0.0008));
  CHECK(m.densify.refine_stop == 60000);
  CHECK(parse_strategy("joint+extadc", ScheduleScale{}, DensifyPreset::Gsplat).plan.densify.refine_stop == 60000);
  // The default stays the multi-spectral implementation's.
  CHECK(parse_strategy("joint").plan.densify.grow_grad2d == doctest::Approx(0.0008));
  CHECK(parse_densify_preset("gsplat") == DensifyPreset::Gsplat);
  CHECK(parse_densify_preset("msgs") == DensifyPreset::MultiSpectral);
  CHECK_THROWS_AS(parse_densify_preset("fast"), std::invalid_argument);
}

}  // namespace test_strategy
