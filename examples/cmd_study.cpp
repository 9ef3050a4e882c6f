// examples/cmd_study.cpp
// `msgs study`: the paper's ablation and cross-talk tables and an accuracy-against-time sweep,
// run here in parallel or written as job files for a cluster, then collected into tables and plots.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <msgs/io/file.hpp>
#include "study_report.hpp"

#include "study_convergence.hpp"

#include "commands.hpp"
#include "data_options.hpp"
#include "experiment.hpp"
#include "memory_guard.hpp"
#include "render_dispatch.hpp"
#include "report.hpp"
#include "run_sheets.hpp"

namespace cmd_study {  // this file's own names: the tool's files compile in unity groups
namespace {

namespace fs = std::filesystem;
namespace st = msgs::study;

constexpr const char* kUsage =
    "usage: msgs study ablation|crosstalk|cost|convergence --data DIR --out DIR [--scale F] [--jobs N]\n"
    "                  [--sh-degree D] [--seed S] [--resume] [--job-file PATH] [--msgs PATH] [--no-plot]\n"
    "                  [--images NAME] [--eval-every N] [--geometry-band ID] [--num-downscales N]\n"
    "                  convergence: [--strategies LIST] [--presets LIST] [--eval-every-seconds T]\n"
    "       msgs study collect --out DIR [--no-plot]\n"
    "\n"
    "Studies over many training runs (every run is `msgs train` with one configuration):\n"
    "  ablation   the 15 configurations of the paper's ablation table\n"
    "  crosstalk  Joint-Optimized on RGB plus each of the 16 subsets of G, R, RE, NIR\n"
    "  cost       accuracy against time per quality knob around Joint-Optimized at scale F:\n"
    "             SH degree 0..3, scale F/4..2F, strategy, Joint modifiers, band count 1..5\n"
    "  convergence  quality against training time: each strategy of --strategies with each preset\n"
    "             of --presets at scale F, evaluated every T seconds of training; writes\n"
    "             convergence.md (final table, where each pair of All curves crosses),\n"
    "             convergence.csv and curves_<band>.png (PSNR against training seconds)\n"
    "  collect    rebuild the tables of DIR from DIR/study.json and DIR/runs/*/result.json\n"
    "\n"
    "Writes into DIR: study.json (the run list), runs/<id>/ (result.json, metrics.md, model PLYs,\n"
    "sheets/sheet_<n>.png: contact sheets of the first 3 eval captures, as `msgs train`),\n"
    "summary.csv, summary.md, summary.json, <study>.gp and <study>_<band>.png (PSNR against wall\n"
    "time, Pareto front marked; needs gnuplot, else run `gnuplot <study>.gp` in DIR later).\n"
    "\n"
    MSGS_DATA_OPTIONS_USAGE
    "  --geometry-band ID  geometry band of every run (see `msgs train --help`; default D)\n"
    "  --num-downscales N  resolution schedule of every run (see `msgs train --help`; default 2)\n"
    "  --scale F       schedule scale of the runs (default 0.01: a 1200-step Joint run)\n"
    "  --jobs N        runs at a time, as threads of this process; with N > 1 each run gets\n"
    "                  max(1, cores / N) OpenMP threads (default 1: one run on every core)\n"
    "  --sh-degree D   spherical-harmonics degree 0..3 (default 3; the cost study varies it)\n"
    "  --seed S        seed of every run (default 0)\n"
    "  --resume        keep runs whose result.json exists and was not interrupted\n"
    "  --job-file PATH write one `msgs train` command line per run to PATH instead of running, plus\n"
    "                  PATH's stem + _slurm.sh (a Slurm array script); then `msgs study collect`\n"
    "  --msgs PATH     msgs executable named in the job file (default: this executable)\n"
    "  --no-plot       do not call gnuplot (the .gp script is still written)\n"
    "  --strategies L  convergence: comma-separated strategies (default separate,split,joint,joint-optimized)\n"
    "  --presets L     convergence: comma-separated presets, reference and/or fast (default reference)\n"
    "  --eval-every-seconds T  convergence: anytime evaluation period in training seconds (default 10)\n";

std::atomic<bool> g_stop{false};
void on_sigint(int) { g_stop.store(true); }

/// This executable, for job files; "msgs" when /proc is not there.
fs::path self_executable() {
  std::error_code ec;
  fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path("msgs") : p;
}

bool have_gnuplot() { return std::system("command -v gnuplot >/dev/null 2>&1") == 0; }

int omp_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

/// Tables, JSON and the plot script of the study in `out`; gnuplot is run when present.
int write_summaries(const fs::path& out, bool plot) {
  st::StudyKind kind = st::StudyKind::Runs;
  const std::vector<st::RunSummary> rows = st::collect(out, &kind);
  if (rows.empty()) throw msgs::io::IoError(out.string() + ": no study.json and no runs/*/result.json to collect");
  const std::string md = st::summary_markdown(kind, rows);
  msgs::io::write_text_atomic(out / "summary.csv", st::summary_csv(rows));
  msgs::io::write_text_atomic(out / "summary.md", "# msgs study " + std::string(st::to_string(kind)) + "\n\n" + md);
  msgs::io::write_text_atomic(out / "summary.json", st::summary_json(kind, rows).dump(2) + "\n");
  const std::string prefix = st::to_string(kind);
  msgs::io::write_text_atomic(out / (prefix + ".gp"), st::gnuplot_script(rows, prefix, "msgs study " + prefix));
  std::printf("%s\n", md.c_str());
  std::size_t missing = 0;
  for (const auto& r : rows)
    if (!r.found) { ++missing; std::printf("missing: %s (%s)\n", r.run.id.c_str(), r.error.c_str()); }
  std::printf("wrote %s/summary.{csv,md,json} and %s.gp\n", out.string().c_str(), prefix.c_str());
  std::vector<std::string> scripts = {prefix};
  if (kind == st::StudyKind::Convergence) {
    (void)msgs::cli::write_convergence_report(out, rows);
    std::printf("%s", msgs::io::read_text(out / "convergence.md").c_str());
    std::printf("wrote %s/convergence.{md,csv,gp}\n", out.string().c_str());
    scripts.push_back("convergence");
  }
  if (plot) {
    if (have_gnuplot()) {
      for (const auto& sc : scripts) {
        const std::string cmd = "cd " + msgs::study::detail::shell_quote(out.string()) + " && gnuplot " +
                                msgs::study::detail::shell_quote(sc + ".gp");
        if (std::system(cmd.c_str()) != 0) std::fprintf(stderr, "msgs study: gnuplot failed on %s.gp\n", sc.c_str());
      }
      std::printf("plots: %s/%s_<All|RGB|G|R|RE|NIR>.png%s\n", out.string().c_str(), prefix.c_str(),
                  kind == st::StudyKind::Convergence ? " and curves_<All|RGB|...>.png" : "");
    } else {
      std::printf("gnuplot not found (Debian: apt-get install gnuplot-nox); plot later with: cd %s && gnuplot %s.gp\n",
                  out.string().c_str(), prefix.c_str());
    }
  }
  return missing ? 1 : 0;
}

/// jobs file + Slurm array script; returns the number of lines.
void write_job_files(const fs::path& job_file, const std::vector<st::StudyRun>& runs, const fs::path& exe,
                     const fs::path& data, const std::vector<std::string>& data_args, const fs::path& out,
                     st::StudyKind kind) {
  std::string lines;
  for (const auto& r : runs) lines += st::job_line(r, exe, data, out, data_args) + "\n";
  msgs::io::write_text_atomic(job_file, lines);
  const fs::path jobs_abs = fs::absolute(job_file);
  const fs::path slurm = job_file.parent_path() / (job_file.stem().string() + "_slurm.sh");
  fs::create_directories(out / "logs");
  std::string s;
  s += "#!/bin/bash\n";
  s += "# Slurm array for `msgs study " + std::string(st::to_string(kind)) + "`: task i runs line i of " + jobs_abs.string() + ".\n";
  s += "# Submit: sbatch " + slurm.filename().string() + "    Then: msgs study collect --out " + out.string() + "\n";
  s += "#SBATCH --job-name=msgs-" + std::string(st::to_string(kind)) + "\n";
  s += "#SBATCH --array=1-" + std::to_string(runs.size()) + "\n";
  s += "#SBATCH --cpus-per-task=8\n";
  s += "#SBATCH --output=" + (fs::absolute(out) / "logs" / "%A_%a.log").string() + "\n";
  s += "set -euo pipefail\n";
  s += "export OMP_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}\n";
  s += "line=$(sed -n \"${SLURM_ARRAY_TASK_ID}p\" " + st::detail::shell_quote(jobs_abs.string()) + ")\n";
  s += "eval \"$line\"\n";
  msgs::io::write_text_atomic(slurm, s);
  fs::permissions(slurm, fs::perms::owner_exec | fs::perms::group_exec, fs::perm_options::add);
  std::printf("wrote %zu job lines to %s and the Slurm array script %s\n", runs.size(), job_file.string().c_str(),
              slurm.string().c_str());
  std::printf("run them with GNU parallel:  OMP_NUM_THREADS=1 parallel -j <N> < %s\n", job_file.string().c_str());
  std::printf("or on Slurm:                 sbatch %s\n", slurm.string().c_str());
  std::printf("then:                        msgs study collect --out %s\n", out.string().c_str());
}

/// What one worker writes as a run's result.json: the `msgs train` fields plus the study's labels.
void write_run_result(const fs::path& dir, const msgs::RunResult& res, const st::StudyRun& r, const fs::path& data,
                      const msgs::io::Dataset& ds, int threads) {
  nlohmann::json j = msgs::cli::result_json(res);
  j["data"] = data.string();
  j["sh_degree"] = r.sh_degree;
  j["seed"] = r.seed;
  j["transform"] = std::vector<float>(ds.transform.data(), ds.transform.data() + 16);
  j["threads"] = threads;
  j["study_id"] = r.id;
  j["preset"] = r.preset;
  nlohmann::json labels = nlohmann::json::array();
  for (const auto& l : r.labels) labels.push_back({{"knob", l.knob}, {"value", l.value}});
  j["labels"] = labels;
  msgs::io::write_text_atomic(dir / "metrics.md", "# " + res.strategy + "\n\n" + msgs::cli::metrics_markdown(res.metrics));
  if (!res.curve.empty()) msgs::io::write_text_atomic(dir / "curve.csv", msgs::cli::curve_csv(res));
  msgs::io::write_text_atomic(dir / "result.json", j.dump(2) + "\n");  // last: its presence marks the run done
}

/// Is <dir>/result.json a finished, uninterrupted run?
bool finished(const fs::path& dir) {
  const st::RunSummary s = st::read_summary(dir, {});
  return s.found && !s.interrupted;
}

int run_study(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(argv, {"data", "images", "eval-every", "geometry-band", "out", "scale", "jobs", "sh-degree", "seed",
                              "job-file", "msgs", "strategies", "presets", "eval-every-seconds",
                              "num-downscales"},
                             {"help", "resume", "no-plot", "quiet"});
  if (args.flag("help") || args.positional().empty()) { std::fputs(kUsage, stdout); return args.flag("help") ? 0 : 2; }
  if (args.positional().size() > 1) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[1] + "'");
  const std::string what = args.positional()[0];
  const fs::path out = args.require("out");
  const bool plot = !args.flag("no-plot");
  if (what == "collect") return write_summaries(out, plot);

  st::StudyKind kind;
  try {
    kind = st::parse_study_kind(what);
  } catch (const std::invalid_argument&) {
    throw msgs::cli::UsageError("unknown study '" + what + "' (ablation, crosstalk, cost, convergence or collect)");
  }
  if (kind == st::StudyKind::Runs) throw msgs::cli::UsageError("'runs' is not a study to run; use collect");
  st::StudyOptions opt;
  opt.scale = args.number("scale", 0.01);
  if (!(opt.scale > 0) || !std::isfinite(opt.scale)) throw msgs::cli::UsageError("--scale must be > 0");
  const long deg = args.integer("sh-degree", 3);
  if (deg < 0 || deg > 3) throw msgs::cli::UsageError("--sh-degree must be 0..3");
  opt.sh_degree = int(deg);
  const long seed = args.integer("seed", 0);
  if (seed < 0) throw msgs::cli::UsageError("--seed must be >= 0");
  opt.seed = std::uint64_t(seed);
  if (kind != st::StudyKind::Convergence)
    for (const char* k : {"strategies", "presets", "eval-every-seconds"})
      if (args.has(k)) throw msgs::cli::UsageError(std::string("--") + k + " belongs to the convergence study");
  if (args.has("strategies")) opt.strategies = msgs::cli::split_list(args.get("strategies"));
  if (args.has("presets")) opt.presets = msgs::cli::split_list(args.get("presets"));
  opt.curve_seconds = args.number("eval-every-seconds", opt.curve_seconds);
  const long jobs = args.integer("jobs", 1);
  if (jobs < 1) throw msgs::cli::UsageError("--jobs must be >= 1");
  const fs::path data = fs::absolute(args.require("data"));
  std::vector<std::string> data_args;  // passed on to every run (job lines included)
  for (const char* k : {"images", "eval-every", "geometry-band", "num-downscales"})
    if (args.has(k)) { data_args.push_back(std::string("--") + k); data_args.push_back(args.get(k)); }
  const long num_downscales = args.integer("num-downscales", -1);
  if (args.has("num-downscales") && (num_downscales < 0 || num_downscales > 8))
    throw msgs::cli::UsageError("--num-downscales must be 0..8 (0 = full resolution from the first step)");
  const std::string geometry_band = args.get("geometry-band", "D");

  std::vector<st::StudyRun> runs;
  try {
    runs = st::study_runs(kind, opt);
  } catch (const std::invalid_argument& e) {
    throw msgs::cli::UsageError(e.what());
  }
  fs::create_directories(out);
  msgs::io::write_text_atomic(out / "study.json", st::manifest_json(kind, opt, data, runs).dump(2) + "\n");

  if (args.has("job-file")) {
    const fs::path exe = args.has("msgs") ? fs::path(args.get("msgs")) : self_executable();
    write_job_files(args.get("job-file"), runs, exe, data, data_args, fs::absolute(out), kind);
    return 0;
  }

  const msgs::io::Dataset ds = msgs::cli::load_data(args, msgs::io::LoadOptions{}, "study");
  // Threads, not processes: the dataset is loaded once and shared read-only, failures are
  // collected here, and one Ctrl-C handler stops everything. OpenMP's thread count (nthreads-var)
  // is an ICV of each host thread: a std::thread starts from the initial value (OMP_NUM_THREADS or
  // all cores), so each worker sets its own; setting it once in main would not reach the workers.
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const int threads_per_run = jobs > 1 ? std::max(1, int(hw / unsigned(jobs))) : 0;  // 0: leave as is
  const bool quiet = args.flag("quiet") || jobs > 1;
  const bool resume = args.flag("resume");
  std::printf("msgs study %s: %zu runs on %s, scale %g, SH degree %d, %ld at a time%s\n", st::to_string(kind),
              runs.size(), data.string().c_str(), opt.scale, opt.sh_degree, jobs,
              threads_per_run ? (", " + std::to_string(threads_per_run) + " OpenMP thread(s) each").c_str() : "");
  std::fflush(stdout);

  std::signal(SIGINT, on_sigint);
  std::mutex print_mutex;
  std::atomic<std::size_t> next{0}, done{0};
  std::vector<std::string> errors(runs.size());
  const auto t0 = std::chrono::steady_clock::now();
  auto worker = [&] {
#ifdef _OPENMP
    if (threads_per_run > 0) omp_set_num_threads(threads_per_run);
#endif
    while (!g_stop.load()) {
      const std::size_t i = next.fetch_add(1);
      if (i >= runs.size()) break;
      const st::StudyRun& r = runs[i];
      const fs::path dir = out / "runs" / r.id;
      std::string line;
      if (resume && finished(dir)) {
        line = "kept (--resume)";
      } else {
        try {
          fs::create_directories(dir);
          msgs::RunConfig cfg;
          cfg.strategy = r.strategy;
          cfg.scale = r.scale;
          cfg.bands = r.bands;
          cfg.geometry_band = geometry_band;
          cfg.num_downscales = int(num_downscales);
          // Runaway densification ends the run with an error, not the machine's memory (the
          // runs at a time share it).
          cfg.stop_gaussians = msgs::cli::default_stop_gaussians(r.strategy, r.bands.empty() ? ds.bands() : r.bands,
                                                                 r.sh_degree, int(jobs));
          msgs::apply_preset(msgs::parse_preset(r.preset), cfg.train, r.scale);
          cfg.train.curve.every_seconds = r.curve_seconds;
          cfg.train.seed = r.seed;
          cfg.init.seed = std::uint32_t(r.seed);
          cfg.train.stop = &g_stop;
          if (!quiet) cfg.train.on_progress = [&](const msgs::TrainProgress& p) { msgs::cli::print_progress(p); };
          const msgs::RunResult res = msgs::cli::run_experiment_any(r.sh_degree, ds, cfg, dir);
          write_run_result(dir, res, r, data, ds, omp_threads());
          std::string sheet_note;
          try {  // after result.json, as `msgs train` does; a failure here does not fail the run
            (void)msgs::cli::write_run_sheets(ds, res, dir, msgs::cli::default_run_sheets, msgs::cli::make_any_renderer);
          } catch (const std::exception& e) {
            sheet_note = std::string("  (contact sheets not written: ") + e.what() + ")";
          }
          char buf[160];
          std::snprintf(buf, sizeof buf, "All %.2f dB  RGB %.2f dB  %.1f s  %zu Gaussians%s",
                        msgs::cli::all_bands_mean(res.metrics, true),
                        res.metrics.empty() ? std::nan("") : msgs::BandMetrics::mean(res.metrics[0].psnr), res.seconds,
                        [&] { std::size_t n = 0; for (const auto& [k, v] : res.gaussians) n += v; return n; }(),
                        res.interrupted ? "  (interrupted)" : "");
          line = buf + sheet_note;
        } catch (const std::exception& e) {
          errors[i] = e.what();
          line = std::string("FAILED: ") + e.what();
        }
      }
      const std::lock_guard<std::mutex> lock(print_mutex);
      std::printf("[%zu/%zu] %s: %s\n", ++done, runs.size(), r.id.c_str(), line.c_str());
      std::fflush(stdout);
    }
  };
  std::vector<std::thread> pool;
  for (long k = 1; k < jobs; ++k) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  std::signal(SIGINT, SIG_DFL);
  std::printf("study time %.1f s\n\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

  const int rc = write_summaries(out, plot);
  const std::size_t failed = std::size_t(std::count_if(errors.begin(), errors.end(), [](const std::string& e) { return !e.empty(); }));
  if (g_stop.load()) { std::printf("interrupted: rerun with --resume to finish the remaining runs\n"); return 130; }
  if (failed) { std::printf("%zu run(s) failed\n", failed); return 1; }
  return rc;
}

}  // namespace
}  // namespace cmd_study

MSGS_COMMAND("study", "Ablation, cross-talk and accuracy-vs-time studies over many runs; job files; collect", cmd_study::run_study);
