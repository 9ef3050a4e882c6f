// tests/test_study.cpp
// Tests of study.hpp (run lists, Pareto front, rank correlation) and of the tool side in
// examples/study_report.hpp (CSV / Markdown / gnuplot writers, job lines against a real shell,
// aggregation of result.json files), and two tiny real runs.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <msgs/run.hpp>
#include <msgs/study.hpp>

#include "run_experiment_sh0.hpp"  // run_experiment<0>, compiled once for the tests that run it

#include "../examples/study_convergence.hpp"  // the tool side: curves of the convergence study
#include "../examples/study_report.hpp"       // the tool side: summaries, tables, job files
#include <msgs/synth.hpp>

#include "../examples/report.hpp"  // the result.json writer of `msgs train`, which collect must read
#include "../examples/train_options.hpp"  // the preset and the switches `msgs train` takes

namespace test_study {
using namespace msgs;
using namespace msgs::study;
namespace fs = std::filesystem;

namespace {

fs::path scratch_dir(const std::string& name) {
  const char* env = std::getenv("MSGS_TEST_TMP");
  fs::path d = (env ? fs::path(env) : fs::temp_directory_path() / "msgs_test") / "study" / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// CSV line -> fields (RFC 4180 quoting), written independently of the writer.
std::vector<std::string> parse_csv_line(const std::string& line) {
  std::vector<std::string> f(1);
  bool q = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (q) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') { f.back() += '"'; ++i; }
      else if (c == '"') q = false;
      else f.back() += c;
    } else if (c == '"') q = true;
    else if (c == ',') f.emplace_back();
    else f.back() += c;
  }
  return f;
}

std::vector<std::string> lines_of(const std::string& s) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == '\n') { out.push_back(cur); cur.clear(); }
    else cur += c;
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

/// A result.json body in the format of examples/report.hpp for given per-band PSNR / SSIM.
nlohmann::json fake_result(const std::string& strategy, double scale, int deg,
                           const std::vector<std::pair<std::string, double>>& psnr, double seconds, std::size_t n) {
  RunResult r;
  r.strategy = strategy;
  r.plan = parse_strategy(strategy, ScheduleScale{scale}).plan;
  for (const auto& [band, p] : psnr) {
    BandMetrics m;
    m.band = band;
    m.psnr = {p - 1, p + 1};  // mean p
    m.ssim = {p / 100, p / 100};
    r.metrics.push_back(m);
  }
  r.gaussians = {{"joint", n}};
  r.seconds = seconds;
  r.steps = 123;
  nlohmann::json j = cli::result_json(r);
  j["sh_degree"] = deg;
  j["seed"] = 0;
  return j;
}

void write_json(const fs::path& p, const nlohmann::json& j) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << j.dump(2);
}

}  // namespace

TEST_CASE("ablation: the paper's 15 configurations, in the table's order, one run each") {
  const auto runs = ablation_runs({0.01, 0, 7});
  REQUIRE(runs.size() == 15);
  const auto names = strategy_names();
  std::set<std::string> ids;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    CHECK(runs[i].strategy == names[i]);
    CHECK(runs[i].strategy == paper_ablation()[i].key);  // the hard-coded table lines up row for row
    CHECK(runs[i].bands.empty());
    CHECK(runs[i].scale == 0.01);
    CHECK(runs[i].sh_degree == 0);
    CHECK(runs[i].seed == 7);
    REQUIRE(runs[i].labels.size() == 1);
    CHECK(runs[i].labels[0].knob == "strategy");
    ids.insert(runs[i].id);
  }
  CHECK(ids.size() == 15);
  CHECK(paper_ablation().back().psnr[0] == doctest::Approx(24.99));
}

TEST_CASE("crosstalk: 16 subsets, RGB in every one, each combination of the four narrow bands once") {
  const auto subsets = crosstalk_subsets();
  REQUIRE(subsets.size() == 16);
  std::set<unsigned> masks;
  std::vector<int> by_size(6, 0);
  const std::vector<std::string> ms = {"MS_G", "MS_R", "MS_RE", "MS_NIR"};
  for (std::size_t i = 0; i < subsets.size(); ++i) {
    const auto& s = subsets[i];
    REQUIRE(!s.empty());
    CHECK(s[0] == "D");
    CHECK(std::count(s.begin(), s.end(), "D") == 1);
    unsigned mask = 0;
    for (std::size_t k = 1; k < s.size(); ++k) {
      const auto it = std::find(ms.begin(), ms.end(), s[k]);
      REQUIRE(it != ms.end());
      mask |= 1u << (it - ms.begin());
    }
    masks.insert(mask);
    ++by_size[s.size()];
    // Row order of the paper's table.
    CHECK(study::detail::bands_label(s) == paper_crosstalk()[i].key);
  }
  CHECK(masks.size() == 16);
  CHECK(by_size == std::vector<int>{0, 1, 4, 6, 4, 1});

  const auto runs = crosstalk_runs({0.005, 0, 0});
  REQUIRE(runs.size() == 16);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    CHECK(runs[i].strategy == "joint+specdelay+msad");
    // Every band is stored as "all" (empty); otherwise the list is the subset, D first.
    if (i + 1 < runs.size()) CHECK(runs[i].bands == subsets[i]);
    else CHECK(runs[i].bands.empty());
  }
  // The paper's cross-talk "All" is the mean of the listed bands.
  CHECK(paper_crosstalk()[1].psnr[0] == doctest::Approx((21.16 + 24.33) / 2));
}

TEST_CASE("cost: one run per distinct configuration, the shared baseline labelled under every knob") {
  const auto runs = cost_runs({0.02, 2, 0});
  std::set<std::string> ids;
  for (const auto& r : runs) ids.insert(r.id);
  CHECK(ids.size() == runs.size());
  // 1 baseline + 3 SH degrees + 3 scales + 3 strategies (separate, split, joint) + 4 modifier sets
  // (sig, specdelay, extadc, msad; "none" is joint) + 4 band counts.
  CHECK(runs.size() == 18);
  const auto base = std::find_if(runs.begin(), runs.end(), [](const StudyRun& r) {
    return r.strategy == "joint+specdelay+msad" && r.scale == 0.02 && r.sh_degree == 2 && r.bands.empty();
  });
  REQUIRE(base != runs.end());
  std::set<std::string> knobs;
  for (const auto& l : base->labels) knobs.insert(l.knob);
  CHECK(knobs == std::set<std::string>{"sh_degree", "scale", "strategy", "modifiers", "bands"});
  const auto joint = std::find_if(runs.begin(), runs.end(), [](const StudyRun& r) { return r.strategy == "joint"; });
  REQUIRE(joint != runs.end());
  CHECK(joint->labels.size() == 2);  // strategy "joint" and modifiers "none"
  std::vector<double> scales;
  for (const auto& r : runs)
    for (const auto& l : r.labels)
      if (l.knob == "scale") scales.push_back(r.scale);
  std::sort(scales.begin(), scales.end());
  CHECK(scales == std::vector<double>{0.005, 0.01, 0.02, 0.04});
}

TEST_CASE("pareto_front: known points, duplicates, NaN, and an independent sweep on random points") {
  //                         0    1    2    3    4    5     6    7
  const std::vector<double> c = {1, 2, 3, 4, 2, NAN, 5, 1};
  const std::vector<double> q = {10, 12, 11, 15, 9, 20, 15, 10};
  // 2 is beaten by 1 (cheaper, better); 4 by 1; 5 is NaN; 6 by 3 (same quality, cheaper);
  // 0 and 7 are the same point: neither strictly beats the other.
  CHECK(pareto_front(c, q) == std::vector<std::size_t>{0, 7, 1, 3});
  CHECK(pareto_front({}, {}).empty());
  CHECK_THROWS_AS(pareto_front({1, 2}, {1}), std::invalid_argument);

  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<double> cc(40), qq(40);
    for (std::size_t i = 0; i < 40; ++i) { cc[i] = u(rng); qq[i] = u(rng); }
    // Reference: sweep by increasing cost; a point is on the front when it beats every cheaper one.
    std::vector<std::size_t> order(40);
    for (std::size_t i = 0; i < 40; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return cc[a] < cc[b]; });
    std::vector<std::size_t> ref;
    double best = -1;
    for (std::size_t i : order)
      if (qq[i] > best) { ref.push_back(i); best = qq[i]; }
    CHECK(pareto_front(cc, qq) == ref);
  }
}

TEST_CASE("spearman: monotone, reversed, ties by hand, NaN pairs skipped, too few points") {
  CHECK(spearman({1, 2, 3, 4}, {10, 20, 30, 1000}) == doctest::Approx(1.0));
  CHECK(spearman({1, 2, 3, 4}, {4, 3, 2, 1}) == doctest::Approx(-1.0));
  // ranks x 1..5, y 1 2 3.5 5 3.5: sum dxdy = 8, sum dx^2 = 10, sum dy^2 = 9.5.
  CHECK(spearman({1, 2, 3, 4, 5}, {5, 6, 7, 8, 7}) == doctest::Approx(8 / std::sqrt(95.0)));
  CHECK(spearman({1, 2, NAN, 3, 4}, {1, 2, 0, 3, 4}) == doctest::Approx(1.0));
  CHECK(std::isnan(spearman({1, 2}, {1, 2})));
  CHECK(std::isnan(spearman({1, 1, 1}, {1, 2, 3})));
}

TEST_CASE("CSV, Markdown and gnuplot writers: shape, quoting, missing values, Pareto flags") {
  std::vector<RunSummary> rows(3);
  rows[0].run = {"a", "joint", 0.01, 0, {}, 0, {{"strategy", "joint"}, {"modifiers", "none"}}};
  rows[0].found = true;
  rows[0].psnr = {20, 21, 19, 22, 18, NAN};
  rows[0].ssim = {0.5, 0.6, 0.4, 0.5, 0.5, 0.5};
  rows[0].seconds = 10;
  rows[0].gaussians = 1000;
  rows[1].run = {"b", "separate", 0.01, 0, {"D", "MS_G"}, 0, {{"odd,knob", "say \"hi\""}}};
  rows[1].found = true;
  rows[1].psnr = {18, 18, 18, NAN, NAN, NAN};
  rows[1].seconds = 20;  // slower and worse: not on the front
  rows[2].run = {"c", "split", 0.01, 0, {}, 0, {{"strategy", "split"}}};
  rows[2].error = "no result.json (run not finished)";

  const auto csv = lines_of(summary_csv(rows));
  REQUIRE(csv.size() == 1 + 4);  // header + 2 labels of a + 1 of b + 1 of c
  const auto header = parse_csv_line(csv[0]);
  CHECK(header.size() == 26);
  auto col = [&](const std::string& name) {
    return std::size_t(std::find(header.begin(), header.end(), name) - header.begin());
  };
  for (std::size_t i = 1; i < csv.size(); ++i) CHECK(parse_csv_line(csv[i]).size() == header.size());
  const auto a1 = parse_csv_line(csv[1]), a2 = parse_csv_line(csv[2]), b = parse_csv_line(csv[3]), c = parse_csv_line(csv[4]);
  CHECK(a1[col("knob")] == "strategy");
  CHECK(a2[col("knob")] == "modifiers");
  CHECK(std::stod(a1[col("psnr_RGB")]) == 21.0);
  CHECK(a1[col("pareto_All")] == "1");
  CHECK(b[col("knob")] == "odd,knob");
  CHECK(b[col("value")] == "say \"hi\"");
  CHECK(b[col("bands")] == "RGB+G");
  CHECK(b[col("psnr_R")].empty());
  CHECK(b[col("pareto_All")] == "0");
  CHECK(c[col("status")] == "no result.json (run not finished)");
  CHECK(c[col("seconds")].empty());

  // Every Markdown table line has as many cells as the header.
  for (StudyKind k : {StudyKind::Cost, StudyKind::Ablation, StudyKind::Crosstalk}) {
    const auto md = lines_of(summary_markdown(k, rows));
    REQUIRE(md.size() > 3);
    const auto bars = [](const std::string& s) { return std::count(s.begin(), s.end(), '|'); };
    for (const auto& l : md)
      if (!l.empty() && l[0] == '|') CHECK(bars(l) == bars(md[0]));
  }
  const std::string gp = gnuplot_script(rows, "cost");
  CHECK(gp.find("set output \"cost_All.png\"") != std::string::npos);
  CHECK(gp.find("set output \"cost_R.png\"") != std::string::npos);
  CHECK(gp.find("set output \"cost_NIR.png\"") == std::string::npos);  // no run has NIR
  CHECK(gp.find("say 'hi'") != std::string::npos);                  // quotes cannot end a gnuplot string
  CHECK(gp.find("using 1:2:8 with labels") != std::string::npos);   // label column after seconds + 6 PSNRs
  // The script runs when gnuplot is installed (scripts/setup.sh installs gnuplot-nox).
  if (std::system("command -v gnuplot >/dev/null 2>&1") == 0) {
    const fs::path dir = scratch_dir("gnuplot");
    std::ofstream(dir / "cost.gp") << gp;
    CHECK(std::system(("cd " + dir.string() + " && gnuplot cost.gp 2>gnuplot.err").c_str()) == 0);
    std::stringstream err;
    err << std::ifstream(dir / "gnuplot.err").rdbuf();
    // Warnings about a knob with no point in a band are expected here; errors are not.
    CHECK(err.str().find("rror") == std::string::npos);
    CHECK(fs::exists(dir / "cost_All.png"));
    CHECK(fs::exists(dir / "cost_RGB.png"));
  }
}

TEST_CASE("ablation Markdown: measured rows beside the paper's, and the rank correlation") {
  std::vector<RunSummary> rows;
  for (const auto& r : ablation_runs({0.01, 0, 0})) {
    RunSummary s;
    s.run = r;
    s.found = true;
    const PaperRow* p = paper_row(StudyKind::Ablation, r);
    REQUIRE(p != nullptr);
    for (std::size_t c = 0; c < metric_columns; ++c) { s.psnr[c] = p->psnr[c] - 5; s.ssim[c] = p->ssim[c]; }
    s.seconds = 1;
    rows.push_back(s);
  }
  const std::string md = summary_markdown(StudyKind::Ablation, rows);
  std::size_t measured = 0, paper = 0;
  for (const auto& l : lines_of(md)) {
    measured += l.find("| measured |") != std::string::npos;
    paper += l.find("| paper |") != std::string::npos;
  }
  CHECK(measured == 15);
  CHECK(paper == 15);
  CHECK(md.find("| 24.99 |") != std::string::npos);
  CHECK(md.find("measured against paper: 1.00") != std::string::npos);  // same ranking, shifted by 5 dB
}

TEST_CASE("job lines: a POSIX shell splits them into the arguments, and they parse back to the run") {
  const fs::path data = "/data/my scene's \"files\"", out = "/out/study $HOME";
  for (const auto& r : cost_runs({0.01, 1, 3})) {
    const std::string line = job_line(r, "/opt/msgs/bin/msgs", data, out);
    const ParsedJob j = parse_job_line(line);
    CHECK(j.run.id == r.id);
    CHECK(j.run.strategy == r.strategy);
    CHECK(j.run.scale == r.scale);  // %.17g round-trips exactly
    CHECK(j.run.sh_degree == r.sh_degree);
    CHECK(j.run.bands == r.bands);
    CHECK(j.run.seed == 3);
    CHECK(j.data == data);
    CHECK(j.out == out / "runs" / r.id);
  }
  // Independent reference: /bin/sh splits the line the same way.
  const StudyRun r = crosstalk_runs({0.01, 0, 0})[3];
  const std::string line = job_line(r, "/opt/msgs", data, out);
  const std::string cmd = "set -- " + line + "; for a in \"$@\"; do printf '%s\\n' \"$a\"; done";
  const fs::path script = scratch_dir("shell") / "split.sh";
  std::ofstream(script) << cmd << "\n";
  FILE* p = popen(("sh " + script.string()).c_str(), "r");
  REQUIRE(p != nullptr);
  std::string got;
  char buf[256];
  while (std::fgets(buf, sizeof buf, p)) got += buf;
  pclose(p);
  std::vector<std::string> expected = {"/opt/msgs"};
  for (const auto& w : train_arguments(r, data, out)) expected.push_back(w);
  CHECK(lines_of(got) == expected);
  CHECK(split_shell_words(line) == expected);
  CHECK_THROWS_AS(parse_job_line("msgs train --data 'x"), std::invalid_argument);
  CHECK_THROWS_AS(parse_job_line("msgs train --data x --out y --strategy joint+bogus"), std::invalid_argument);
  CHECK_THROWS_AS(parse_job_line("msgs render --data x"), std::invalid_argument);
  // The options every run shares (msgs study --images, --eval-every, --geometry-band,
  // --num-downscales) come back as they went in.
  const std::vector<std::string> shared = {"--images", "images_2", "--num-downscales", "0"};
  CHECK(parse_job_line(job_line(r, "/opt/msgs", data, out, shared)).data_args == shared);
}

TEST_CASE("convergence: strategies x presets with the anytime evaluation, carried through job lines") {
  StudyOptions o;
  o.scale = 0.02;
  o.presets = {"reference", "fast"};
  o.curve_seconds = 7.5;
  const std::vector<StudyRun> runs = convergence_runs(o);
  REQUIRE(runs.size() == 8);
  std::set<std::string> ids;
  for (const auto& r : runs) {
    ids.insert(r.id);
    CHECK(r.curve_seconds == 7.5);
    CHECK(r.id.ends_with("_fast") == (r.preset == "fast"));
    const ParsedJob j = parse_job_line(job_line(r, "/opt/msgs", "/data", "/out"));
    CHECK(j.run.preset == r.preset);
    CHECK(j.run.curve_seconds == 7.5);
    CHECK(j.run.id == r.id);
  }
  CHECK(ids.size() == 8);
  CHECK(runs[3].labels[0].value == "joint-optimized (reference)");
  o.presets = {"quick"};
  CHECK_THROWS_AS(convergence_runs(o), std::invalid_argument);
  o.presets = {"reference"};
  o.curve_seconds = 0;
  CHECK_THROWS_AS(convergence_runs(o), std::invalid_argument);
}

TEST_CASE("convergence report: a finished run keeps its final value, and the crossing is found") {
  // A rises 10 -> 20 dB over 10 s; B reaches 16 dB at 5 s and stops: A overtakes it at 6 s.
  msgs::cli::RunCurves a, b;
  a.id = a.label = "slow";
  b.id = b.label = "quick";
  a.series["All"] = {{0, 10, 0.1}, {10, 20, 0.2}};
  b.series["All"] = {{0, 15, 0.1}, {5, 16, 0.2}};
  a.final_seconds = 10;
  b.final_seconds = 5;
  const std::string md = msgs::cli::convergence_markdown({a, b});
  CHECK(md.find("| slow | quick | +4.00 dB at 10 s | 6: slow |") != std::string::npos);
  const std::string csv = msgs::cli::convergence_csv({a, b});
  CHECK(csv.find("quick,quick,All,5.000,16.0000,0.20000") != std::string::npos);
  const std::string gp = msgs::cli::convergence_gnuplot({a, b}, "t");
  CHECK(gp.find("curves_All.png") != std::string::npos);
  CHECK(gp.find("curves_RGB.png") == std::string::npos);  // no RGB series
}

TEST_CASE("collect: manifest runs read from result.json, missing ones reported; without a manifest too") {
  const fs::path dir = scratch_dir("collect");
  const auto runs = crosstalk_runs({0.01, 0, 0});
  const std::vector<StudyRun> two = {runs[0], runs[15]};  // RGB only, all bands
  std::ofstream(dir / "study.json") << manifest_json(StudyKind::Crosstalk, {0.01, 0, 0}, "/data", two).dump();
  write_json(dir / "runs" / two[0].id / "result.json",
             fake_result("joint+specdelay+msad", 0.01, 0, {{"D", 20}}, 5.5, 100));
  // Second run missing at first.
  StudyKind kind = StudyKind::Runs;
  auto rows = collect(dir, &kind);
  CHECK(kind == StudyKind::Crosstalk);
  REQUIRE(rows.size() == 2);
  CHECK(rows[0].found);
  CHECK(rows[0].psnr[1] == doctest::Approx(20));
  CHECK(rows[0].psnr[0] == doctest::Approx(20));
  CHECK(rows[0].ssim[1] == doctest::Approx(0.2));
  CHECK(std::isnan(rows[0].psnr[2]));
  CHECK(rows[0].seconds == doctest::Approx(5.5));
  CHECK(rows[0].gaussians == 100);
  CHECK(rows[0].steps == 123);
  CHECK(rows[0].run.labels == std::vector<Label>{{"subset", "RGB"}});
  CHECK(!rows[1].found);
  CHECK(rows[1].error.find("no result.json") != std::string::npos);

  write_json(dir / "runs" / two[1].id / "result.json",
             fake_result("joint+specdelay+msad", 0.01, 0,
                         {{"D", 20}, {"MS_G", 22}, {"MS_R", 24}, {"MS_RE", 26}, {"MS_NIR", 28}}, 9, 200));
  rows = collect(dir);
  REQUIRE(rows[1].found);
  CHECK(rows[1].psnr[0] == doctest::Approx(24));  // each band weighs the same
  CHECK(paper_row(StudyKind::Crosstalk, rows[1].run)->psnr[1] == doctest::Approx(21.29));

  // Without study.json: every runs/*/result.json, configuration read from the file.
  fs::remove(dir / "study.json");
  rows = collect(dir, &kind);
  CHECK(kind == StudyKind::Runs);
  REQUIRE(rows.size() == 2);
  for (const auto& r : rows) {
    CHECK(r.found);
    CHECK(r.run.strategy == "joint+specdelay+msad");
    CHECK(r.run.scale == doctest::Approx(0.01));
    REQUIRE(r.run.labels.size() == 1);
    CHECK(r.run.labels[0].value == r.run.id);
  }
  const auto rgb_only = std::find_if(rows.begin(), rows.end(), [&](const RunSummary& s) { return s.run.id == two[0].id; });
  REQUIRE(rgb_only != rows.end());
  CHECK(rgb_only->run.bands == std::vector<std::string>{"D"});

  // A malformed result.json is reported with the file and field, not thrown.
  write_json(dir / "runs" / "broken" / "result.json", nlohmann::json{{"metrics", 3}});
  rows = collect(dir);
  const auto broken = std::find_if(rows.begin(), rows.end(), [](const RunSummary& s) { return s.run.id == "broken"; });
  REQUIRE(broken != rows.end());
  CHECK(!broken->found);
  CHECK(broken->error.find("metrics") != std::string::npos);
  CHECK(broken->error.find("result.json") != std::string::npos);

  // A malformed manifest throws, naming the file and field.
  std::ofstream(dir / "study.json") << R"({"study": "cost", "runs": [{"strategy": "joint"}]})";
  CHECK_THROWS_WITH_AS(collect(dir), doctest::Contains("runs[0].id"), io::IoError);
}

TEST_CASE("end to end: two tiny cross-talk runs trained, written as `msgs train` does, collected") {
  const fs::path dir = scratch_dir("e2e");
  synth::SynthOptions so;
  so.preset = "tiny";
  so.seed = 1;
  so.overwrite = true;
  write_synthetic_dataset(dir / "data", so);
  const io::Dataset ds = io::load_dataset(dir / "data");
  const auto all = crosstalk_runs({0.001, 0, 0});  // 120 Joint steps: seconds, not minutes
  const std::vector<StudyRun> runs = {all[0], all[4]};  // RGB; RGB + NIR
  std::ofstream(dir / "study.json") << manifest_json(StudyKind::Crosstalk, {0.001, 0, 0}, dir / "data", runs).dump();
  for (const auto& r : runs) {
    RunConfig cfg;
    cfg.strategy = r.strategy;
    cfg.scale = r.scale;
    cfg.bands = r.bands;
    const fs::path rd = dir / "runs" / r.id;
    fs::create_directories(rd);
    const RunResult res = run_experiment<0>(ds, cfg, rd);
    nlohmann::json j = cli::result_json(res);
    j["sh_degree"] = 0;
    j["seed"] = 0;
    io::write_text_atomic(rd / "result.json", j.dump(2));
  }
  const auto rows = collect(dir);
  REQUIRE(rows.size() == 2);
  for (const auto& s : rows) {
    REQUIRE(s.found);
    CHECK(std::isfinite(s.psnr[1]));
    CHECK(s.psnr[1] > 5);
    CHECK(s.gaussians > 0);
    CHECK(s.seconds > 0);
    CHECK(fs::exists(dir / "runs" / s.run.id / "model_joint.ply"));
  }
  CHECK(std::isnan(rows[0].psnr[5]));
  CHECK(std::isfinite(rows[1].psnr[5]));
  CHECK(rows[1].psnr[0] == doctest::Approx((rows[1].psnr[1] + rows[1].psnr[5]) / 2));
  const auto csv = lines_of(summary_csv(rows));
  CHECK(csv.size() == 3);
}

TEST_CASE("train options: each departure of the fast preset can be switched on its own") {
  const auto config_of = [](const std::vector<std::string>& argv) {
    RunConfig cfg;
    cfg.scale = 0.2;
    cli::apply_train_options(cli::Args(argv, cli::train_option_values(), cli::train_option_flags()), cfg);
    return cfg;
  };
  const RunConfig ref = config_of({});
  CHECK_FALSE(ref.train.spectral_colour_init);
  CHECK(ref.train.adam.lr_sh_dc == doctest::Approx(0.0025));
  const RunConfig fast = config_of({"--preset", "fast"});
  CHECK(fast.train.spectral_colour_init);
  CHECK(fast.train.adam.lr_sh_dc == doctest::Approx(fast_lr_sh_dc(0.2)));
  CHECK(fast.train.adam.lr_sh_dc > 0.0035);
  // The fast preset less one departure: spectral-init alone, then colour-lr alone.
  const RunConfig init_only = config_of({"--preset", "fast", "--lr-sh-dc", "0.0025"});
  CHECK(init_only.train.spectral_colour_init);
  CHECK(init_only.train.adam.lr_sh_dc == doctest::Approx(0.0025));
  const RunConfig lr_only = config_of({"--preset", "fast", "--spectral-init", "off"});
  CHECK_FALSE(lr_only.train.spectral_colour_init);
  CHECK(lr_only.train.adam.lr_sh_dc == doctest::Approx(fast.train.adam.lr_sh_dc));
  CHECK(config_of({"--spectral-init", "on"}).train.spectral_colour_init);
  CHECK_THROWS_AS(config_of({"--spectral-init", "yes"}), cli::UsageError);
}

}  // namespace test_study
