// tests/test_train_parity.cpp
// The reference-parity switches seen through Trainer<G> on the synthetic `tiny` scene: clamped
// renders before the loss, the reshuffle of each band's images on every pass, the evaluation SSIM
// window; the anytime evaluation (a curve that leaves training bit-identical and survives a resume)
// and the fast preset's narrow-band colour start.
#include <doctest/doctest.h>

#include "fixtures.hpp"
#include "shared_trainers.hpp"  // Trainer<G>, compiled once for the tests that drive it

#include <msgs/presets.hpp>
#include <msgs/run.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

namespace test_train_parity {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

using G = Gaussian<7, 0>;  // one trainer type for the file
using Model = GaussianModel<G, float>;

const io::Dataset& tiny() { return msgs::testing::tiny_scene("train_parity", 5); }

Model initial_model() {
  RunConfig cfg;
  return detail::initial_model<G>(tiny(), cfg);
}

Trainer<G> make_trainer(const std::string& strategy, double scale, TrainOptions opt, Model m = initial_model()) {
  const StrategySpec s = parse_strategy(strategy, ScheduleScale{scale});
  return Trainer<G>(tiny(), detail::run_bands(tiny(), {}), std::move(m), s.plan, s.hooks, std::move(opt));
}

bool same_model(const Model& a, const Model& b) {
  return a.means == b.means && a.log_scales == b.log_scales && a.quats == b.quats &&
         a.opacity_logits == b.opacity_logits && a.sh == b.sh;
}

}  // namespace

TEST_CASE("clamp01 and its backward: the gradient is 0 exactly where the render left [0, 1]") {
  Image<float> img(3, 1, 1), out, grad(3, 1, 1);
  img.data = {-0.5f, 0.25f, 1.5f};
  clamp01(img, out);
  CHECK(out.data == std::vector<float>{0.0f, 0.25f, 1.0f});
  grad.data = {1.0f, 2.0f, 3.0f};
  clamp01_backward(img, grad);
  CHECK(grad.data == std::vector<float>{0.0f, 2.0f, 0.0f});
}

TEST_CASE("clamped renders: identical training while renders stay in [0, 1], different once they saturate") {
  TrainOptions on, off;
  off.clamp_render = false;
  // Initial colours are 0.5 + C0 [0, 1) < 1 and backgrounds < 1: every render is inside [0, 1].
  Trainer<G> a = make_trainer("joint", 0.05, on), b = make_trainer("joint", 0.05, off);
  a.train(0, 10);
  b.train(0, 10);
  CHECK(same_model(a.model(), b.model()));
  // Saturate: every colour about 3.3.
  Model hot = initial_model();
  for (float& v : hot.sh) v = 10.0f;
  Trainer<G> c = make_trainer("joint", 0.05, on, hot), d = make_trainer("joint", 0.05, off, hot);
  c.train(0, 10);
  d.train(0, 10);
  CHECK_FALSE(c.model().sh == d.model().sh);
}

TEST_CASE("shuffle every pass: the first pass equals shuffle-once, later passes differ") {
  TrainOptions every, once;
  once.shuffle = Shuffle::once;
  std::size_t shortest = SIZE_MAX;
  for (const auto& b : detail::run_bands(tiny(), {})) shortest = std::min(shortest, b.train_frames.size());
  const long long first_pass = 5 * (long long)shortest;  // every band's first pass is identical
  Trainer<G> a = make_trainer("joint", 0.05, every), b = make_trainer("joint", 0.05, once);
  a.train(0, first_pass);
  b.train(0, first_pass);
  CHECK(same_model(a.model(), b.model()));
  a.train(first_pass, first_pass + 5 * 40);
  b.train(first_pass, first_pass + 5 * 40);
  CHECK_FALSE(same_model(a.model(), b.model()));
}

TEST_CASE("evaluation SSIM follows TrainOptions::eval_ssim") {
  TrainOptions valid, same;
  same.eval_ssim = SsimBorder::same;
  Trainer<G> a = make_trainer("joint", 0.05, valid), b = make_trainer("joint", 0.05, same);
  const auto ma = a.evaluate(), mb = b.evaluate();
  REQUIRE(ma.size() == mb.size());
  CHECK(ma[0].psnr == mb[0].psnr);  // PSNR does not depend on it
  CHECK(ma[0].ssim != mb[0].ssim);
}

TEST_CASE("anytime evaluation: points at the requested steps, training bit-identical, the curve survives a resume") {
  TrainOptions plain, curved;
  curved.curve.every_steps = 10;
  curved.curve.images = 2;
  Trainer<G> a = make_trainer("joint", 0.05, plain), b = make_trainer("joint", 0.05, curved);
  a.train(0, 30);
  b.train(0, 30);
  CHECK(same_model(a.model(), b.model()));
  CHECK(a.curve().empty());
  REQUIRE(b.curve().size() == 3);
  b.finish_curve(30);  // run_experiment's point at the model's last step
  b.finish_curve(30);  // once
  REQUIRE(b.curve().size() == 4);
  const std::vector<long long> steps = {0, 10, 20, 30};
  for (std::size_t i = 0; i < 4; ++i) {
    const CurvePoint& p = b.curve()[i];
    CHECK(p.step == steps[i]);
    REQUIRE(p.bands.size() == 5);
    for (double v : p.psnr) CHECK(std::isfinite(v));
    for (double v : p.ssim) CHECK(std::isfinite(v));
    if (i > 0) CHECK(p.seconds >= b.curve()[i - 1].seconds);
  }
  CHECK(b.curve().back().seconds <= b.clock());
  CHECK(b.curve().back().psnr[0] > b.curve().front().psnr[0]);  // RGB improves over 30 steps

  // Resume: stop at 15 with a checkpoint, continue in a fresh trainer from it.
  const fs::path dir = msgs::testing::scratch_dir("train_parity") / "resume";
  fs::remove_all(dir);
  fs::create_directories(dir);
  TrainOptions ck = curved;
  ck.checkpoint_path = dir / "joint.ckpt";
  Trainer<G> c = make_trainer("joint", 0.05, ck);
  c.train(0, 15);
  const double clock15 = c.clock();
  TrainOptions no_curve = plain;  // resumed without the anytime evaluation: the curve file is ignored
  no_curve.checkpoint_path = ck.checkpoint_path;
  Trainer<G> e = make_trainer("joint", 0.05, no_curve);
  CHECK(e.restore(load_checkpoint<G>(ck.checkpoint_path)) == 15);
  CHECK(e.curve().empty());
  Trainer<G> d = make_trainer("joint", 0.05, ck);
  const long long next = d.restore(load_checkpoint<G>(ck.checkpoint_path));
  CHECK(next == 15);
  CHECK(d.clock() == doctest::Approx(clock15));
  REQUIRE(d.curve().size() == 2);  // steps 0 and 10
  d.train(next, 30);
  d.finish_curve(30);
  CHECK(same_model(d.model(), b.model()));
  REQUIRE(d.curve().size() == 4);
  CHECK(d.curve()[2].step == 20);
  CHECK(d.curve()[3].step == 30);
  CHECK(d.curve()[3].psnr == b.curve()[3].psnr);  // same model, same images
}

TEST_CASE("fast preset: narrow bands join SpecDelay's run with the geometry band's texture at their own brightness") {
  TrainOptions opt;
  opt.spectral_colour_init = true;
  Trainer<G> tr = make_trainer("joint+specdelay", 0.05, opt);
  const long long start = tr.plan().spectral_start;
  REQUIRE(start == 1500);
  const Model before = tr.model();
  tr.train(start, start + 1);  // the init, then a step (step 1500 renders band 0: RGB)
  const Model& after = tr.model();
  const std::vector<float> lum = dc_luminance(before, 0, 3);
  ImageCache images(tiny());
  const auto bands = detail::run_bands(tiny(), {});
  const int factor = tr.plan().schedule.downscale(start);
  const double geo_mean = mean_luminance(images, bands[0], factor);
  for (std::size_t b = 1; b < bands.size(); ++b) {
    CAPTURE(bands[b].id);
    const double k = mean_luminance(images, bands[b], factor) / geo_mean;
    const int c = bands[b].first_channel;
    double max_err = 0;
    for (std::size_t i = 0; i < after.size(); ++i) {
      const double colour = sh::C0 * double(after.sh_at(i, 0, c)) + 0.5;
      max_err = std::max(max_err, std::abs(colour - k * double(lum[i])));
    }
    CHECK(max_err < 1e-5);
  }
  // Without the option the narrow bands keep their random start.
  Trainer<G> ref = make_trainer("joint+specdelay", 0.05, TrainOptions{});
  ref.train(start, start + 1);
  for (int c = 3; c < 7; ++c)
    for (std::size_t i = 0; i < 10; ++i) CHECK(ref.model().sh_at(i, 0, c) == before.sh_at(i, 0, c));
}

TEST_CASE("presets: reference is TrainOptions{}, fast names and applies its departures") {
  TrainOptions t;
  t.clamp_render = false;
  t.sparse = true;
  apply_preset(Preset::reference, t, 0.025);
  const TrainOptions ref;
  CHECK(t.clamp_render);
  CHECK(t.shuffle == Shuffle::every_pass);
  CHECK(t.loss.ssim_border == SsimBorder::valid);
  CHECK(t.eval_ssim == SsimBorder::valid);
  CHECK_FALSE(t.sparse);
  CHECK(t.adam.lr_sh_dc == ref.adam.lr_sh_dc);
  CHECK(preset_departures(Preset::reference, 0.025).empty());

  apply_preset(Preset::fast, t, 0.025);
  CHECK(t.adam.lr_sh_dc == doctest::Approx(0.01));
  CHECK_FALSE(t.sparse);  // sparse Adam trains worse at CPU schedules (README): not a fast-preset choice
  CHECK(t.spectral_colour_init);
  CHECK(t.clamp_render);  // the parity switches stay the reference's
  CHECK(preset_departures(Preset::fast, 0.025).size() == 2);
  CHECK(fast_lr_sh_dc(0.4) == 0.0025);  // exactly the reference's rate from scale 0.4 on
  CHECK(fast_lr_sh_dc(1.0) == 0.0025);
  // There colour-lr is no departure: the fast preset is the reference plus spectral-init.
  CHECK(preset_departures(Preset::fast, 0.4).size() == 1);
  CHECK(preset_departures(Preset::fast, 1.0).front().name == "spectral-init");
  CHECK(preset_departures(Preset::fast, 0.39).size() == 2);
  {
    TrainOptions at_full;
    apply_preset(Preset::fast, at_full, 1.0);
    CHECK(at_full.adam.lr_sh_dc == TrainOptions{}.adam.lr_sh_dc);
  }
  CHECK(fast_lr_sh_dc(1e-4) == doctest::Approx(0.025));  // at most 10x
  CHECK(parse_preset("fast") == Preset::fast);
  CHECK_THROWS_AS(parse_preset("quick"), std::invalid_argument);
  CHECK_THROWS_AS(fast_lr_sh_dc(0.0), std::invalid_argument);
}

}  // namespace test_train_parity
