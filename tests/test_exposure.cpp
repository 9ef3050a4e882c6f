// tests/test_exposure.cpp
// Exposure compensation (exposure.hpp): the affine map's gradients against central differences in
// double, its Adam step and guards, the least-squares colour correction of evaluation, the trainer
// with the option off (no exposure state anywhere) and on (checkpoints resume bit for bit), and an
// end-to-end run on a scene whose training images were darkened by known factors: the learned
// gains follow the factors and fit the training images better than a run without them.
#include <doctest/doctest.h>

#include "fixtures.hpp"
#include "shared_trainers.hpp"  // Trainer<G>, compiled once for the tests that drive it
#include "../examples/report.hpp"  // result.json / metrics.md of `msgs train`

#include <msgs/checkpoint.hpp>
#include <msgs/exposure.hpp>
#include <msgs/io/image_io.hpp>
#include <msgs/run.hpp>
#include <msgs/synth.hpp>

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace test_exposure {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

using G = Gaussian<7, 1>;  // one model type for the whole file (compile time)

Image<double> random_image(int w, int h, int c, std::uint32_t seed, double lo = 0.0, double hi = 1.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  Image<double> img(w, h, c);
  for (double& v : img.data) v = u(rng);
  return img;
}

/// L = 0.5 sum_p (out_p - t_p)^2 with out = exposure_forward(in, a, b): a non-linear loss of the
/// corrected image, so the test exercises d_out that depends on the parameters.
double loss_of(const Image<double>& in, const std::vector<double>& a, const std::vector<double>& b, const Image<double>& t) {
  Image<double> out;
  exposure_forward<double>(in, a, b, out);
  double l = 0;
  for (std::size_t i = 0; i < out.size(); ++i) l += 0.5 * (out.data[i] - t.data[i]) * (out.data[i] - t.data[i]);
  return l;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

fs::path scratch() { return msgs::testing::scratch_dir("exposure"); }

const io::Dataset& tiny() { return msgs::testing::tiny_scene("exposure", 3); }

Trainer<G> make_trainer(TrainOptions opt) {
  // As test_checkpoint: refinement, an opacity reset and SpecDelay all fall in the first 240 steps.
  const StrategySpec s = parse_strategy("joint+specdelay+msad", ScheduleScale{0.004});
  RunConfig cfg;
  return Trainer<G>(tiny(), detail::run_bands(tiny(), {}), detail::initial_model<G>(tiny(), cfg), s.plan, s.hooks, opt);
}

}  // namespace

TEST_CASE("exposure backward matches central differences in double (image, log-gain and offset gradients)") {
  for (const int C : {1, 3}) {
    CAPTURE(C);
    const Image<double> in = random_image(5, 4, C, 11u + std::uint32_t(C));
    const Image<double> target = random_image(5, 4, C, 23u + std::uint32_t(C), -0.5, 1.5);
    const auto n = static_cast<std::size_t>(C);
    std::vector<double> a(n), b(n);
    for (int c = 0; c < C; ++c) { a[std::size_t(c)] = -0.4 + 0.35 * c; b[std::size_t(c)] = 0.1 - 0.08 * c; }

    Image<double> out, d_out, d_in;
    exposure_forward<double>(in, a, b, out);
    d_out = out;
    for (std::size_t i = 0; i < out.size(); ++i) d_out.data[i] = out.data[i] - target.data[i];
    std::vector<double> da(n), db(n);
    exposure_backward<double>(in, a, d_out, d_in, da, db);

    const double h = 1e-6;
    for (int c = 0; c < C; ++c) {
      auto ap = a, am = a, bp = b, bm = b;
      ap[std::size_t(c)] += h; am[std::size_t(c)] -= h;
      bp[std::size_t(c)] += h; bm[std::size_t(c)] -= h;
      const double fa = (loss_of(in, ap, b, target) - loss_of(in, am, b, target)) / (2 * h);
      const double fb = (loss_of(in, a, bp, target) - loss_of(in, a, bm, target)) / (2 * h);
      CHECK(da[std::size_t(c)] == doctest::Approx(fa).epsilon(1e-7));
      CHECK(db[std::size_t(c)] == doctest::Approx(fb).epsilon(1e-7));
    }
    for (std::size_t i = 0; i < in.size(); ++i) {
      Image<double> ip = in, im = in;
      ip.data[i] += h; im.data[i] -= h;
      const double fd = (loss_of(ip, a, b, target) - loss_of(im, a, b, target)) / (2 * h);
      CHECK(d_in.data[i] == doctest::Approx(fd).epsilon(1e-7));
    }
    // In place (d_in aliasing d_out, as the trainer calls it) gives the same bits.
    Image<double> inplace = d_out;
    std::vector<double> da2(n), db2(n);
    exposure_backward<double>(in, a, inplace, inplace, da2, db2);
    CHECK(inplace.data == d_in.data);
    CHECK(da2 == da);
    CHECK(db2 == db);
  }
}

TEST_CASE("exposure: shapes are checked, gradients stay finite for huge finite inputs") {
  Image<float> img(3, 2, 3, 0.5f), out;
  const std::vector<float> a3(3, 0.0f), a1(1, 0.0f);
  CHECK_THROWS_AS(exposure_forward<float>(img, a1, a1, out), std::invalid_argument);
  Image<float> d(3, 2, 2), din;
  std::vector<double> g3(3), o3(3);
  CHECK_THROWS_AS(exposure_backward<float>(img, a3, d, din, g3, o3), std::invalid_argument);

  const float big = std::numeric_limits<float>::max();
  Image<float> huge(3, 2, 3, big), dhuge(3, 2, 3, -big);
  const std::vector<float> a_max(3, 4.0f);
  exposure_backward<float>(huge, a_max, dhuge, din, g3, o3);
  for (float v : din.data) CHECK(std::isfinite(v));
  for (double v : g3) CHECK(std::isfinite(v));
  for (double v : o3) CHECK(std::isfinite(v));
}

TEST_CASE("exposure Adam: only the stepped image changes, gains stay positive and bounded, NaN never enters") {
  ExposureConfig cfg;
  cfg.lr = 0.1;
  Exposure e(6, {{4, 3}, {1, 1}}, cfg);
  REQUIRE(e.size() == 2);
  CHECK(e.has(1));
  CHECK(e.has(4));
  CHECK_FALSE(e.has(0));
  CHECK_THROWS_AS((void)e.log_gain(0), std::out_of_range);
  CHECK_THROWS_AS(Exposure(3, {{5, 1}}, cfg), std::invalid_argument);
  CHECK_THROWS_AS(Exposure(6, {{1, 1}, {1, 3}}, cfg), std::invalid_argument);
  ExposureConfig bad;
  bad.lr = std::nan("");
  CHECK_THROWS_AS(Exposure(6, {{1, 1}}, bad), std::invalid_argument);

  // A positive gradient lowers the parameter by lr on the first step (Adam's first step is the sign).
  const std::vector<double> g1{2.0}, o1{-3.0};
  e.adam_step(1, g1, o1);
  CHECK(e.log_gain(1)[0] == doctest::Approx(-0.1));
  CHECK(e.offset(1)[0] == doctest::Approx(0.1));
  for (float v : e.log_gain(4)) CHECK(v == 0.0f);  // untouched
  CHECK(e.state().steps == std::vector<std::int64_t>{1, 0});

  // A non-finite gradient leaves the state as it was.
  const ExposureState before = e.state();
  const std::vector<double> nan3{std::nan(""), 0.0, 0.0}, zero3{0, 0, 0};
  e.adam_step(4, nan3, zero3);
  CHECK(e.state().steps == before.steps);
  CHECK(same_bits(e.state().log_gain, before.log_gain));
  CHECK(same_bits(e.state().m_log_gain, before.m_log_gain));

  // However hard it is pushed, the log-gain stays within +-max_log_gain (gain in (0, inf)) and the
  // moments stay finite, even for gradients far beyond float range.
  const std::vector<double> push{1e300, -1e300, 1e300};
  for (int i = 0; i < 200; ++i) e.adam_step(4, push, push);
  for (float v : e.log_gain(4)) {
    CHECK(std::isfinite(v));
    CHECK(std::abs(v) <= cfg.max_log_gain);
    CHECK(std::exp(v) > 0.0f);
  }
  for (float v : e.offset(4)) CHECK(std::abs(v) <= cfg.max_offset);
  CHECK_NOTHROW(e.state().validate("test"));
  CHECK(e.log_gain(4)[0] == -cfg.max_log_gain);
  CHECK(e.log_gain(4)[1] == cfg.max_log_gain);

  // A gauge group keeps its mean log-gain and offset at 0: a step on one image is projected, the
  // others move by minus its share. Frame 3 is in no group and moves alone.
  Exposure p(4, {{0, 1}, {2, 1}, {3, 1}}, cfg);
  p.add_gauge_group({0, 2});
  p.adam_step(0, g1, o1);  // frame 0 by (-0.1, +0.1), then recentred
  CHECK(p.log_gain(0)[0] == doctest::Approx(-0.05));
  CHECK(p.log_gain(2)[0] == doctest::Approx(0.05));
  CHECK(p.offset(0)[0] == doctest::Approx(0.05));
  CHECK(p.offset(2)[0] == doctest::Approx(-0.05));
  p.adam_step(3, g1, o1);
  CHECK(p.log_gain(3)[0] == doctest::Approx(-0.1));
  CHECK_THROWS_AS(p.add_gauge_group({2, 3}), std::invalid_argument);  // 2 is already in a group
  CHECK_THROWS_AS(p.add_gauge_group({1}), std::out_of_range);         // no parameters for frame 1
  Exposure mixed(2, {{0, 1}, {1, 3}}, cfg);
  CHECK_THROWS_AS(mixed.add_gauge_group({0, 1}), std::invalid_argument);
}

TEST_CASE("colour correction: the least-squares affine recovers a known one; flat renders fall back to the mean") {
  const Image<double> r = random_image(7, 5, 3, 5u, 0.1, 0.8);
  Image<double> gt = r;
  const double ga[3] = {0.6, 1.2, 0.9}, ob[3] = {0.05, -0.1, 0.02};
  for (std::size_t p = 0; p < r.pixels(); ++p)
    for (std::size_t c = 0; c < 3; ++c) gt.data[p * 3 + c] = ga[c] * r.data[p * 3 + c] + ob[c];
  const AffineFit fit = fit_affine(r, gt);
  for (std::size_t c = 0; c < 3; ++c) {
    CHECK(fit.gain[c] == doctest::Approx(ga[c]).epsilon(1e-12));
    CHECK(fit.offset[c] == doctest::Approx(ob[c]).epsilon(1e-12));
  }
  const Image<double> cc = colour_correct(r, gt);
  for (std::size_t i = 0; i < cc.size(); ++i) CHECK(cc.data[i] == doctest::Approx(std::clamp(gt.data[i], 0.0, 1.0)).epsilon(1e-12));

  // A constant render: gain 0, the offset is the ground truth's mean (no division by zero).
  const Image<double> flat(7, 5, 1, 0.3);
  const Image<double> g1 = random_image(7, 5, 1, 9u);
  const AffineFit f1 = fit_affine(flat, g1);
  double mean = 0;
  for (double v : g1.data) mean += v;
  mean /= double(g1.size());
  CHECK(f1.gain[0] == 0.0);
  CHECK(f1.offset[0] == doctest::Approx(mean));
  CHECK_THROWS_AS(fit_affine(flat, r), std::invalid_argument);
}

TEST_CASE("exposure off (the default) leaves no exposure state; its learning rate then changes nothing") {
  TrainOptions off;
  off.lr_exposure = 0.5;  // ignored while exposure is off
  Trainer<G> a = make_trainer({});
  Trainer<G> b = make_trainer(off);
  CHECK(a.exposure() == nullptr);
  CHECK(a.exposure_report().empty());
  a.train(0, 40);
  b.train(0, 40);
  const TrainState<G> sa = a.state(40), sb = b.state(40);
  CHECK(sa.exposure.empty());
  CHECK(same_bits(sa.model.means, sb.model.means));
  CHECK(same_bits(sa.model.sh, sb.model.sh));
  CHECK(same_bits(sa.exp_avg_sq.sh, sb.exp_avg_sq.sh));
  for (const BandMetrics& m : a.evaluate()) {
    CHECK(m.psnr_cc.empty());
    CHECK(m.ssim_cc.empty());
  }
  // Its checkpoint is the format without the optional section, and loads with an empty state.
  const fs::path p = scratch() / "off.ckpt";
  save_checkpoint(p, sa);
  CHECK(load_checkpoint<G>(p).exposure.empty());
  // Such a checkpoint cannot be resumed with exposure on (it would not be the same run), and vice versa.
  TrainOptions on;
  on.exposure = true;
  Trainer<G> c = make_trainer(on);
  CHECK_THROWS_WITH_AS(c.restore(load_checkpoint<G>(p)), doctest::Contains("exposure"), std::runtime_error);
}

TEST_CASE("with exposure on, a resumed run equals the uninterrupted run bit for bit, exposure state included") {
  constexpr long long kEnd = 240, kStop = 131;
  TrainOptions base;
  base.exposure = true;
  base.lr_exposure = 0.01;
  Trainer<G> straight = make_trainer(base);
  REQUIRE(straight.train(0, kEnd) == kEnd);
  const TrainState<G> want = straight.state(kEnd);
  REQUIRE_FALSE(want.exposure.empty());
  CHECK(want.exposure.frames.size() == 45);  // 9 training images in each of 5 bands
  // Some gains moved (the images seen), every one finite and positive.
  bool moved = false;
  for (float a : want.exposure.log_gain) {
    CHECK(std::isfinite(a));
    moved |= a != 0.0f;
  }
  CHECK(moved);

  const fs::path ckpt = scratch() / "exposure.ckpt";
  fs::remove(ckpt);
  std::atomic<bool> stop{false};
  TrainOptions opt = base;
  opt.checkpoint_path = ckpt;
  opt.stop = &stop;
  opt.progress_every = 1;
  opt.on_progress = [&](const TrainProgress& p) { if (p.step >= kStop) stop.store(true); };
  Trainer<G> first = make_trainer(opt);
  REQUIRE(first.train(0, kEnd) == kStop);
  REQUIRE(fs::exists(ckpt));

  Trainer<G> second = make_trainer(base);
  const long long at = second.restore(load_checkpoint<G>(ckpt));
  CHECK(at == kStop);
  REQUIRE(second.train(at, kEnd) == kEnd);
  const TrainState<G> got = second.state(kEnd);
  CHECK(same_bits(got.model.means, want.model.means));
  CHECK(same_bits(got.model.sh, want.model.sh));
  CHECK(same_bits(got.exp_avg.sh, want.exp_avg.sh));
  CHECK(same_bits(got.model.opacity_logits, want.model.opacity_logits));
  CHECK(got.exposure.frames == want.exposure.frames);
  CHECK(got.exposure.steps == want.exposure.steps);
  CHECK(same_bits(got.exposure.log_gain, want.exposure.log_gain));
  CHECK(same_bits(got.exposure.offset, want.exposure.offset));
  CHECK(same_bits(got.exposure.m_log_gain, want.exposure.m_log_gain));
  CHECK(same_bits(got.exposure.v_log_gain, want.exposure.v_log_gain));
  CHECK(same_bits(got.exposure.m_offset, want.exposure.m_offset));
  CHECK(same_bits(got.exposure.v_offset, want.exposure.v_offset));

  // The checkpoint refuses to resume without exposure, and a truncated exposure section.
  Trainer<G> plain = make_trainer({});
  CHECK_THROWS_AS(plain.restore(load_checkpoint<G>(ckpt)), std::runtime_error);
  auto bytes = io::read_bytes(ckpt);
  const fs::path cut = scratch() / "cut.ckpt";
  io::write_text_atomic(cut, std::string(bytes.begin(), bytes.end() - 5));
  CHECK_THROWS_WITH_AS(load_checkpoint<G>(cut), doctest::Contains("truncated"), std::runtime_error);
  bytes.push_back(0);
  io::write_text_atomic(cut, std::string(bytes.begin(), bytes.end()));
  CHECK_THROWS_WITH_AS(load_checkpoint<G>(cut), doctest::Contains("trailing"), std::runtime_error);
}

TEST_CASE("end to end: on training images darkened by known factors the learned gains follow them") {
  // The tiny scene with the RGB band's training images multiplied by known factors (the eval
  // image keeps factor 1); the downscaled copies are removed so the loader box-filters the
  // modified full-resolution images.
  const fs::path root = scratch() / "tiny_gain";
  SynthOptions so;
  so.preset = "tiny";
  so.seed = 5;
  so.overwrite = true;
  write_synthetic_dataset(root, so);
  io::LoadOptions lo;
  lo.bands = {"D"};
  const io::Dataset ds0 = io::load_dataset(root, lo);
  const std::vector<std::size_t> train = ds0.frames_of("D", io::Split::train);
  REQUIRE(train.size() == 9);
  std::vector<double> factor;
  for (std::size_t i = 0; i < train.size(); ++i) {
    // 0.5 .. 1.0 shuffled over the images, divided by their geometric mean (0.732): the images
    // are darker and brighter than the model's radiometry, which the gauge holds at their mean.
    const double k = (0.5 + 0.0625 * double((i * 5) % 9)) / 0.7321;
    factor.push_back(k);
    const io::Frame& f = ds0.frames[train[i]];
    Image<float> img = io::read_image(root / f.file_path);
    for (float& v : img.data) v = float(double(v) * k);
    io::write_png16(root / f.file_path, img);
    fs::remove(root / "images_2" / fs::path(f.file_path).filename());
  }
  const io::Dataset ds = io::load_dataset(root, lo);

  // The settings of test_train's convergence run (no resolution schedule, a growth threshold
  // suited to 96x72 images), RGB only, 150 steps. Measured: training-view PSNR 21.9 dB without
  // exposure, 24.0 dB with it; learned against true centred log-gains correlate 0.93, the worst
  // image is 0.16 off.
  StrategySpec spec = parse_strategy("joint", ScheduleScale{0.005});
  spec.plan.schedule.num_downscales = 0;
  spec.plan.densify.grow_grad2d = 0.005;
  const long long steps = spec.plan.stage_steps;
  RunConfig rc;
  auto run = [&](bool exposure) {
    TrainOptions opt;
    opt.exposure = exposure;
    opt.lr_exposure = 0.1;  // 150 steps, about 17 per image: a short run needs a large rate
    opt.check_finite = true;
    Trainer<G> tr(ds, detail::run_bands(ds, {"D"}), detail::initial_model<G>(ds, rc), spec.plan, spec.hooks, opt);
    REQUIRE(tr.train(0, steps) == steps);
    // Fit to the training images as the loss sees them: with the learned correction when on.
    Rasterizer<G, float, kTrainRaster> raster;
    double psnr_sum = 0;
    for (std::size_t f : train) {
      RenderSettings<float> rs;
      rs.band_first = 0;
      rs.band_count = 3;
      rs.background = eval_background<float>(3);
      Image<float> render = raster.forward(tr.model(), io::frame_camera(ds, ds.frames[f], 1), rs);
      if (exposure) {
        Image<float> c;
        tr.exposure()->forward(f, render, c);
        render = std::move(c);
      }
      psnr_sum += psnr(render, io::load_frame_image(ds, ds.frames[f], 1));
    }
    std::vector<double> log_gain;  // channel mean per image
    if (exposure)  // the gauge: the band's mean log-gain and offset are 0 per channel
      for (int c = 0; c < 3; ++c) {
        double sa = 0, sb = 0;
        for (std::size_t f : train) { sa += tr.exposure()->log_gain(f)[std::size_t(c)]; sb += tr.exposure()->offset(f)[std::size_t(c)]; }
        CHECK(std::abs(sa) < 1e-5);
        CHECK(std::abs(sb) < 1e-5);
      }
    if (exposure)
      for (std::size_t f : train) {
        double s = 0;
        for (float a : tr.exposure()->log_gain(f)) s += double(a);
        log_gain.push_back(s / 3.0);
      }
    return std::make_pair(psnr_sum / double(train.size()), log_gain);
  };
  // Plain variables, not structured bindings: CAPTURE's lambda cannot name a binding under Clang 14.
  const auto off = run(false), on = run(true);
  const double psnr_off = off.first, psnr_on = on.first;
  const auto& none = off.second;
  const auto& log_gain = on.second;
  CAPTURE(psnr_off);
  CAPTURE(psnr_on);
  CHECK(none.empty());
  CHECK(psnr_on > psnr_off + 1.5);

  // Gains are defined up to a common scale: compare log-gains and log-factors about their means.
  REQUIRE(log_gain.size() == factor.size());
  double mg = 0, mk = 0;
  for (std::size_t i = 0; i < factor.size(); ++i) { mg += log_gain[i]; mk += std::log(factor[i]); }
  mg /= double(factor.size());
  mk /= double(factor.size());
  double sgk = 0, sgg = 0, skk = 0, worst = 0;
  for (std::size_t i = 0; i < factor.size(); ++i) {
    const double g = log_gain[i] - mg, k = std::log(factor[i]) - mk;
    sgk += g * k; sgg += g * g; skk += k * k;
    worst = std::max(worst, std::abs(g - k));
  }
  const double corr = sgk / std::sqrt(sgg * skk);
  std::string table;
  for (std::size_t i = 0; i < factor.size(); ++i) {
    table.append(1, ' ').append(std::to_string(std::log(factor[i]) - mk));
    table.append(1, '/').append(std::to_string(log_gain[i] - mg));
  }
  INFO("centred log factor / learned log gain:", table);
  CAPTURE(corr);
  CAPTURE(worst);
  CHECK(corr > 0.9);
  CHECK(worst < 0.25);  // each image's gain relative to the others within ~25 % of the truth
}

TEST_CASE("result.json: \"exposure\" always, corrected metrics and learned gains only for exposure runs") {
  RunResult r;
  r.metrics.push_back(BandMetrics{"D", {20.0, 22.0}, {0.8, 0.9}});
  const nlohmann::json off = cli::result_json(r);
  CHECK(off["exposure"] == false);
  CHECK_FALSE(off.contains("exposure_correction"));
  CHECK_FALSE(off["metrics"]["D"].contains("psnr_cc_mean"));
  CHECK_FALSE(off["metrics"]["All"].contains("psnr_cc_mean"));
  CHECK(cli::metrics_markdown(r.metrics).find("colour-corrected") == std::string::npos);

  r.exposure = true;
  r.metrics[0].psnr_cc = {24.0, 26.0};
  r.metrics[0].ssim_cc = {0.85, 0.95};
  BandExposure e;
  e.band = "D";
  e.channels = 3;
  e.files = {"images/D_1.png", "images/D_2.png"};
  e.gain = {{0.5, 1.0, 1.5}, {2.0, 0.25, 1.0}};
  e.offset = {{0.0, 0.1, -0.1}, {0.2, 0.0, 0.0}};
  r.exposure_params.emplace_back("joint", e);
  const nlohmann::json on = cli::result_json(r);
  CHECK(on["exposure"] == true);
  CHECK(on["metrics"]["D"]["psnr_cc_mean"].get<double>() == doctest::Approx(25.0));
  CHECK(on["metrics"]["D"]["psnr_mean"].get<double>() == doctest::Approx(21.0));  // the plain render, as before
  CHECK(on["metrics"]["All"]["psnr_cc_mean"].get<double>() == doctest::Approx(25.0));
  const nlohmann::json& x = on["exposure_correction"][0];
  CHECK(x["model"] == "joint");
  CHECK(x["band"] == "D");
  CHECK(x["images"] == 2);
  CHECK(x["gain"][0]["min"].get<double>() == 0.5);
  CHECK(x["gain"][0]["max"].get<double>() == 2.0);
  CHECK(x["gain"][1]["mean"].get<double>() == doctest::Approx(0.625));
  CHECK(x["offset"][2]["min"].get<double>() == -0.1);
  CHECK(x["frames"][1]["file_path"] == "images/D_2.png");
  CHECK(cli::metrics_markdown(r.metrics).find("PSNR (colour-corrected) | 25.00") != std::string::npos);
}

}  // namespace test_exposure
