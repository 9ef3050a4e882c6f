// bench/soak.cpp
// Soak run: every strategy on the `medium` synthetic scene for its whole (scaled) schedule, checking
// every parameter and every used gradient for NaN/Inf at every step, with peak memory and Gaussian
// counts over time written as CSV. Not a test (minutes per strategy); run it by hand:
//
//   soak [--scale 0.01] [--preset medium] [--data DIR] [--csv soak.csv] [--every 10]
//        [--strategies joint,split,...] [--seed 0] [--no-eval]
//
// Gradients are checked through Adam's moments: m += (1 - b1)(g - m), v = b2 v + (1 - b2) g^2 stay
// finite exactly as long as every gradient that reached the optimiser was finite, and the trainer
// does not hand its gradient buffers out (see the proposal in the report: a post-backward hook).
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <msgs/run.hpp>
#include <msgs/synth.hpp>
#include <msgs/large_page_new.hpp>  // as the msgs tool: large arrays in large pages (one inclusion per program)

namespace fs = std::filesystem;
using namespace msgs;

namespace {

/// A value of /proc/self/status in MiB ("VmRSS", "VmHWM"); -1 when unavailable.
double proc_status_mib(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string prefix = std::string(key) + ":";
  while (std::getline(in, line))
    if (line.rfind(prefix, 0) == 0) return std::atof(line.c_str() + prefix.size()) / 1024.0;  // kB
  return -1.0;
}

/// Peak RSS since the last reset_peak() (VmHWM), falling back to getrusage (peak of the process).
double peak_rss_mib() {
  const double hwm = proc_status_mib("VmHWM");
  if (hwm >= 0) return hwm;
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_maxrss) / 1024.0;
}

/// Reset VmHWM to the current RSS (Linux >= 4.0, "5" > /proc/self/clear_refs); false when refused.
bool reset_peak() {
  std::ofstream f("/proc/self/clear_refs");
  f << "5";
  f.flush();
  return bool(f);
}

struct Args {
  double scale = 0.01;
  std::string preset = "medium";
  fs::path data;
  fs::path csv = "soak.csv";
  int every = 10;
  std::vector<std::string> strategies;
  std::uint64_t seed = 0;
  bool eval = true;
};

std::vector<std::string> split_commas(const std::string& s) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == ',') { if (!cur.empty()) out.push_back(cur); cur.clear(); }
    else cur += c;
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(k + " needs a value");
      return argv[++i];
    };
    if (k == "--scale") a.scale = std::stod(value());
    else if (k == "--preset") a.preset = value();
    else if (k == "--data") a.data = value();
    else if (k == "--csv") a.csv = value();
    else if (k == "--every") a.every = std::max(1, std::stoi(value()));
    else if (k == "--strategies") a.strategies = split_commas(value());
    else if (k == "--seed") a.seed = std::stoull(value());
    else if (k == "--no-eval") a.eval = false;
    else if (k == "--help" || k == "-h") {
      std::puts("soak [--scale F] [--preset medium] [--data DIR] [--csv FILE] [--every N] [--strategies a,b] "
                "[--seed S] [--no-eval]");
      std::exit(0);
    } else {
      throw std::invalid_argument("unknown argument '" + k + "'");
    }
  }
  if (a.strategies.empty()) a.strategies = strategy_names();
  return a;
}

/// Throws when any value of a model-shaped buffer is NaN or Inf.
template <class G>
void check_finite_model(const GaussianModel<G, float>& m, const char* what, long long step, const std::string& key) {
  auto check = [&](const std::vector<float>& v, const char* group) {
    for (std::size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i]))
        throw std::runtime_error(key + ": non-finite " + what + " (" + group + "[" + std::to_string(i) + "] = " +
                                 std::to_string(v[i]) + ") after step " + std::to_string(step));
  };
  check(m.means, "means");
  check(m.log_scales, "log_scales");
  check(m.quats, "quats");
  check(m.opacity_logits, "opacity_logits");
  check(m.sh, "sh");
}

struct Soak {
  Args args;
  std::ofstream csv;
  std::string strategy;
  double t0 = 0;
};

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// detail::train_model, one step at a time with the finiteness checks and the CSV rows.
template <class G>
GaussianModel<G, float> soak_model(Soak& s, const io::Dataset& ds, std::vector<TrainBand> bands,
                                   GaussianModel<G, float> model, const StrategySpec& spec, long long begin,
                                   long long end, const std::string& key, std::int64_t adam_iteration) {
  TrainOptions opt;
  opt.seed = s.args.seed;
  opt.check_finite = true;  // parameters, after every step (throws)
  opt.progress_every = 1;
  TrainProgress last;
  opt.on_progress = [&](const TrainProgress& p) { last = p; };
  Trainer<G> tr(ds, std::move(bands), std::move(model), spec.plan, spec.hooks, opt);
  tr.adam().iteration = adam_iteration;
  for (long long step = begin; step < end; ++step) {
    tr.train(step, step + 1);
    check_finite_model(tr.adam().exp_avg, "gradient (first moment)", step, key);
    check_finite_model(tr.adam().exp_avg_sq, "gradient (second moment)", step, key);
    if ((step - begin) % s.args.every == 0 || step + 1 == end)
      s.csv << s.strategy << ',' << key << ',' << step + 1 << ',' << tr.model().size() << ','
            << proc_status_mib("VmRSS") << ',' << peak_rss_mib() << ',' << last.loss << ',' << now_s() - s.t0
            << '\n';
  }
  s.csv.flush();
  if (s.args.eval)
    for (const auto& m : tr.evaluate())
      std::printf("    %-8s %-6s PSNR %6.2f  SSIM %.3f\n", key.c_str(), m.band.c_str(), BandMetrics::mean(m.psnr),
                  BandMetrics::mean(m.ssim));
  std::printf("    %-8s %zu Gaussians after steps [%lld, %lld)\n", key.c_str(), tr.model().size(), begin, end);
  return std::move(tr.model());
}

/// run_experiment's wiring of Separate / Split / Joint (run.hpp), through soak_model.
void soak_strategy(Soak& s, const io::Dataset& ds) {
  constexpr int D = 3;
  using G7 = Gaussian<7, D>;
  using G3 = Gaussian<3, D>;
  using G1 = Gaussian<1, D>;
  const StrategySpec spec = parse_strategy(s.strategy, ScheduleScale{s.args.scale});
  RunConfig cfg;
  cfg.init.seed = std::uint32_t(s.args.seed);
  const std::vector<TrainBand> bands = detail::run_bands(ds, {});
  const long long stage = spec.plan.stage_steps;
  switch (spec.plan.kind) {
    case StrategyKind::Joint:
      soak_model<G7>(s, ds, bands, detail::initial_model<G7>(ds, cfg), spec, 0, stage, "joint", 0);
      break;
    case StrategyKind::Separate:
      for (TrainBand b : bands) {
        b.first_channel = 0;
        if (b.channels == 3) soak_model<G3>(s, ds, {b}, detail::initial_model<G3>(ds, cfg), spec, 0, stage, b.id, 0);
        else soak_model<G1>(s, ds, {b}, detail::initial_model<G1>(ds, cfg), spec, 0, stage, b.id, 0);
      }
      break;
    case StrategyKind::Split: {
      TrainBand rgb;
      for (const auto& b : bands)
        if (b.id == "D") rgb = b;
      rgb.first_channel = 0;
      const auto rgb_model = soak_model<G3>(s, ds, {rgb}, detail::initial_model<G3>(ds, cfg), spec, 0, stage, "D", 0);
      for (std::size_t i = 0; i < bands.size(); ++i) {
        TrainBand b = bands[i];
        if (b.id == "D") continue;
        b.first_channel = 0;
        GaussianModel<G1, float> m;
        detail::copy_geometry(rgb_model, m);
        detail::fresh_colour(m, cfg.init.seed + 1u + std::uint32_t(i));
        soak_model<G1>(s, ds, {b}, std::move(m), spec, stage, 2 * stage, b.id, stage);
      }
      break;
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Soak s;
    s.args = parse(argc, argv);
    fs::path data = s.args.data;
    if (data.empty()) data = fs::temp_directory_path() / ("msgs_soak_" + s.args.preset);
    if (!fs::exists(data / "transforms.json")) {
      synth::SynthOptions so;
      so.preset = s.args.preset;
      so.overwrite = true;
      const auto sum = write_synthetic_dataset(data, so);
      std::printf("synthetic '%s' scene written to %s in %.1f s\n", so.preset.c_str(), data.c_str(), sum.seconds);
    }
    const io::Dataset ds = io::load_dataset(data);
    s.csv.open(s.args.csv);
    if (!s.csv) throw std::runtime_error("cannot write " + s.args.csv.string());
    s.csv << "strategy,model,step,gaussians,rss_mib,peak_rss_mib,loss,seconds\n";
    std::printf("%-26s %8s %10s %12s %s\n", "strategy", "seconds", "steps/s", "peak MiB", "result");
    int failures = 0;
    for (const auto& name : s.args.strategies) {
      s.strategy = name;
      const bool per_strategy_peak = reset_peak();
      s.t0 = now_s();
      std::printf("%s (scale %g)\n", name.c_str(), s.args.scale);
      std::string result = "ok";
      try {
        soak_strategy(s, ds);
      } catch (const std::exception& e) {
        result = std::string("FAILED: ") + e.what();
        ++failures;
      }
      const double secs = now_s() - s.t0;
      const StrategySpec spec = parse_strategy(name, ScheduleScale{s.args.scale});
      const double steps = double(spec.plan.total_steps(int(ds.bands().size()) - 1));
      std::printf("%-26s %8.1f %10.1f %12.1f%s %s\n", name.c_str(), secs, steps / secs, peak_rss_mib(),
                  per_strategy_peak ? "" : "*", result.c_str());
      std::fflush(stdout);
    }
    std::printf("CSV: %s%s\n", s.args.csv.c_str(), failures ? "" : "; every strategy finite at every step");
    return failures ? 1 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "soak: %s\n", e.what());
    return 2;
  }
}
