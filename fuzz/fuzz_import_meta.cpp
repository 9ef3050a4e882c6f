// fuzz/fuzz_import_meta.cpp
// libFuzzer target for the pure parts of `msgs import`: exiv2 output parsing
// (io::parse_capture_meta with GPS positions and the pairs formed from them, the light sensor's
// heading check on a flight made of the capture, a calibration panel's
// area read from a small picture, io::split_exiv2_output), the --panels list (io::parse_panel_list,
// fed the same text), --bands pattern parsing and file-name
// recognition (io::parse_band_patterns, io::scan_capture_names with every camera scheme).
//
// Input: exiv2 text, then optionally a NUL byte, a --bands spec line and file names one per line.
// Acceptable outcomes: success, io::IoError, and std::invalid_argument from parse_band_patterns
// (a usage error). Anything else aborts.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "msgs/io/calibration_panel.hpp"
#include "msgs/io/capture_meta.hpp"
#include "msgs/io/capture_names.hpp"
#include "msgs/io/light_sensor_heading.hpp"
#include "msgs/io/match_pairs.hpp"
#include "msgs/io/panel_list.hpp"
#include "msgs/io/radiometry.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace msgs;
  const auto* begin = reinterpret_cast<const char*>(data);
  const auto* end = begin + size;
  const auto* nul = std::find(begin, end, '\0');
  const std::string text(begin, nul);
  std::vector<std::string> lines;
  if (nul != end) {
    std::string cur;
    for (const char* p = nul + 1; p != end; ++p) {
      if (*p == '\n') { lines.push_back(cur); cur.clear(); } else cur.push_back(*p);
    }
    lines.push_back(cur);
  }

  fuzz::expect_io_error_only("parse_capture_meta", [&] {
    const io::CaptureMeta m = io::parse_capture_meta(text, "fuzz.tif");
    // A light sensor's reading, levelled for the sun or not, is a positive finite irradiance.
    if (m.irradiance && !(std::isfinite(*m.irradiance) && *m.irradiance > 0)) {
      std::fprintf(stderr, "parse_capture_meta: a light-sensor irradiance that is not positive and finite\n");
      std::abort();
    }
    // A heading that was read lies in [0, 360); with the reading and the time, a flight of such
    // captures on alternate lines fits to a finite effect, or to a reason why not.
    if (m.heading_deg && !(*m.heading_deg >= 0.0 && *m.heading_deg < 360.0)) {
      std::fprintf(stderr, "parse_capture_meta: a heading outside [0, 360)\n");
      std::abort();
    }
    if (m.heading_deg && m.irradiance && m.time_s) {
      std::vector<double> reading, time_s, heading;
      for (int i = 0; i < 8; ++i) {
        reading.push_back(*m.irradiance * (i % 2 ? 0.9 : 1.1));
        time_s.push_back(*m.time_s + 2.0 * i);
        heading.push_back(*m.heading_deg + (i % 2 ? 180.0 : 0.0));
      }
      const io::HeadingFit fit = io::fit_heading_bias(reading, time_s, heading);
      if (fit.problem.empty() && !(std::isfinite(fit.ratio) && fit.ratio >= 1.0 && fit.heading_factor.size() == 8)) {
        std::fprintf(stderr, "fit_heading_bias: a fit without a finite ratio of at least 1\n");
        std::abort();
      }
    }
    // The plan and the per-frame parameters must also be safe to form (and to check).
    const io::BandPlan plan = io::plan_band({m, m}, {"a.tif", "b.tif"});
    io::FrameRadiometry r = io::frame_radiometry(m, plan.steps, 65535.0, 8, 6);
    io::check_radiometry(r, 8, 6, "fuzz.tif");
    (void)io::relative_radiance(1000.0, 3.0, 2.0, r);
    // And the plans for reflectance and for the light sensor's band ratios (DJI's sunlight sensor,
    // MicaSense's DLS 2), where nothing is missing.
    for (const io::Calibration c : {io::Calibration::sun_sensor, io::Calibration::sun_sensor_relative}) {
      const io::BandPlan p = io::plan_band({m, m}, {"a.tif", "b.tif"}, c);
      if (!p.missing.empty()) continue;
      io::FrameRadiometry q = io::frame_radiometry(m, p.steps, 65535.0, 8, 6);
      q.scale = c == io::Calibration::sun_sensor ? io::reflectance_scale(q) : io::light_sensor_scale(q);
      io::check_radiometry(q, 8, 6, "fuzz.tif");
      (void)io::relative_radiance(1000.0, 3.0, 2.0, q);
    }
    // A panel's area, however odd its corners, reads as a finite mean or an IoError.
    if (m.panel_area) {
      const io::BandPlan pp = io::plan_band({m}, {"p.tif"}, io::Calibration::panel);
      io::FrameRadiometry pr = io::frame_radiometry(m, pp.steps, 65535.0, 24, 18);
      msgs::Image<float> img(24, 18, 1);
      for (std::size_t i = 0; i < img.data.size(); ++i) img.data[i] = float(i % 7) / 8.0f + 0.1f;
      const io::PanelReading reading = io::read_panel(img, pr, *m.panel_area, "p.tif");
      if (!std::isfinite(reading.mean) || !(reading.mean > 0) || reading.pixels < io::kMinPanelPixels) {
        std::fprintf(stderr, "read_panel: a reading that is not a positive mean of enough pixels\n");
        std::abort();
      }
    }
    // A position that was read is a finite place on the Earth, and pairs can be formed from it.
    if (m.gps) {
      const auto local = io::local_metres(*m.gps, 0.0, 0.0);
      for (double v : local)
        if (!std::isfinite(v)) {
          std::fprintf(stderr, "parse_capture_meta: a GPS position that is not finite\n");
          std::abort();
        }
      const std::vector<io::PairImage> images = {{0, "D"}, {1, "D"}};
      (void)io::neighbour_pairs(images, {local, io::local_metres(*m.gps, 1.0, 1.0)}, 1);
    }
  });
  fuzz::expect_io_error_only("parse_panel_list", [&] {
    std::vector<io::PanelResponse> responses;  // the listed panels as an empirical line's points
    for (const io::PanelPicture& p : io::parse_panel_list(text, "panels.json")) {
      if (!io::convex_quad(p.area) || (p.albedo && !(*p.albedo > 0 && *p.albedo <= 1)) || p.file.is_absolute()) {
        std::fprintf(stderr, "parse_panel_list: a picture that should have been refused\n");
        std::abort();
      }
      // A positive response and a time from the corners, however large or odd.
      responses.push_back({1e-3 + std::abs(std::fmod(p.area[0][0], 1e6)), p.albedo.value_or(0.5),
                           std::fmod(p.area[0][1], 1e5)});
    }
    // The line's offset is finite and leaves every panel light, or there is none (offset 0).
    const io::PanelLine line = io::panel_line(responses);
    bool bad = !std::isfinite(line.offset) || (!line.fitted() && line.offset != 0.0);
    for (const io::PanelResponse& r : responses) bad = bad || !(r.albedo + line.offset > 0);
    if (bad || std::abs(line.offset) > io::kMaxPanelLineOffset) {
      std::fprintf(stderr, "panel_line: an offset that is not finite, leaves a panel no light, or lacks a reason\n");
      std::abort();
    }
  });
  std::vector<std::string> names(lines.begin() + (lines.empty() ? 0 : 1), lines.end());
  fuzz::expect_io_error_only("split_exiv2_output", [&] {
    const auto per = io::split_exiv2_output(text, names);
    for (std::size_t i = 0; i < per.size(); ++i) (void)io::parse_capture_meta(per[i], "f");
  });

  std::vector<io::BandPattern> patterns;
  if (!lines.empty()) {
    try {
      patterns = io::parse_band_patterns(lines[0]);
    } catch (const std::invalid_argument&) {
    }
  }
  std::vector<std::filesystem::path> files(names.begin(), names.end());
  for (const char* cam : {"auto", "micasense", "dji", "p4m", "sequoia"})
    fuzz::expect_io_error_only("scan_capture_names", [&] { (void)io::scan_capture_names("/fuzz", files, cam); });
  if (!patterns.empty())
    fuzz::expect_io_error_only("scan_capture_names(patterns)",
                               [&] { (void)io::scan_capture_names("/fuzz", files, "auto", patterns); });
  return 0;
}
