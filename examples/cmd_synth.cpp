// examples/cmd_synth.cpp
// `msgs synth`: generate a ray-traced synthetic multi-spectral dataset in the public layout.
#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <msgs/synth.hpp>
#include <msgs/synth/raw.hpp>

#include "commands.hpp"

namespace cmd_synth {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs synth --preset tiny|small|medium --out DIR [--seed S] [--force]\n"
    "       msgs synth --raw micasense|dji|p4m|sequoia --out DIR [--preset P] [--captures N] [--width W]\n"
    "                  [--light-variation V] [--dls-bias B] [--panel-captures N] [--panel-before]\n"
    "                  [--light-drift D] [--dls1] [--heading-bias H] [--dark-panel]\n"
    "                  [--path-reflectance P] [--seed S] [--force]\n"
    "\n"
    "Ray-trace a procedural outdoor scene (lawn, soil, trees, solar panels, pond, painted pad) seen\n"
    "by a 5-camera drone rig (RGB + G, R, RE, NIR) and write it in the public multi-spectral dataset\n"
    "layout: transforms.json, train_split.json, images/, images_2/ (images_4/), sparse_pc.ply.\n"
    "\n"
    "  --preset P   tiny (tests, ~1 s), small (demo), medium (studies); default tiny\n"
    "  --out DIR    output directory (must not exist unless --force)\n"
    "  --seed S     scene and flight seed (default 1); the same seed gives identical files\n"
    "  --force      replace an existing DIR once the new dataset is complete\n"
    "\n"
    "With --raw CAMERA, write instead a folder of raw captures as that camera would (input for\n"
    "`msgs import`): its file names (MicaSense IMG_0001_1.tif..._5.tif, DJI Mavic 3M\n"
    "DJI_<datetime>_0001_MS_G.TIF ... _D.JPG, DJI P4 Multispectral DJI_0010.JPG, DJI_0011.TIF ...\n"
    "DJI_0015.TIF, Parrot Sequoia IMG_<date>_<time>_0001_GRE.TIF ... _RGB.JPG),\n"
    "16-bit TIFFs with per-capture exposure time and ISO, black level and vignetting in the digital\n"
    "numbers, and the camera's metadata tags as XMP (band, wavelength, black level, exposure, ISO/gain,\n"
    "vignetting polynomial and centre, focal length and focal-plane resolution; MicaSense files\n"
    "also the radiance calibration and the DLS 2 light sensor's irradiance, DJI sets the sunlight\n"
    "sensor's readings and SensorGainAdjustment, Sequoia sets the sunshine sensor's readings).\n"
    "  --captures N number of captures (default: the preset's)\n"
    "  --width W    multispectral image width in pixels (height 3/4 of it, RGB 1.5x; default: the preset's)\n"
    "  --light-variation V  the sunlight of each capture varies by up to +-V (0 to 0.9; default 0),\n"
    "               as under passing clouds (`msgs import --radiometry reflectance`, sun-sensor or\n"
    "               panel+dls divides it out)\n"
    "  --dls-bias B the light sensor (MicaSense, DJI, Sequoia) reads (1 + B) x the sunlight (-0.5 to 1; default 0): a\n"
    "               sensor error that `msgs import --radiometry panel+dls` takes out with the panel\n"
    "  --panel-captures N  N captures of a calibration panel after the flight's (default 0), for\n"
    "               `msgs import --radiometry panel`: MicaSense files are marked as the camera marks\n"
    "               them (CalibrationPicture, Albedo, ReflectArea); for DJI and Sequoia sets, which\n"
    "               carry no such tags, DIR/panels.json lists them for `msgs import --panels`.\n"
    "               The flight's captures are 2 s apart, the panel's a minute after the last\n"
    "  --panel-before  one more capture of the panel, 5 minutes before the flight (numbered 0)\n"
    "  --light-drift D  the sunlight grows linearly in time by D from the first capture to the last (-0.5 to\n"
    "               1; default 0), as the sun climbs: panels before and after the flight follow it\n"
    "  --dls1       MicaSense files as a RedEdge-M with the first light sensor writes them: its\n"
    "               tilted reading (DLS:SpectralIrradiance) and attitude (DLS:Yaw/Pitch/Roll) under a\n"
    "               clear sky, the drone pitched 8 degrees forward on flight lines that turn back\n"
    "               at every capture, and no HorizontalIrradiance (`msgs import` levels the reading)\n"
    "  --heading-bias H  the light sensor (MicaSense, DJI) reads 1 + H cos(yaw - 20 deg) x the sunlight\n"
    "               (-0.5 to 0.5; default 0), as a sensor that sits off the drone's centre or is shaded\n"
    "               by its body does: flight lines that turn back make it alternate; `msgs import`\n"
    "               reports it and --light-sensor-heading correct divides it out\n"
    "  --dark-panel every second panel capture after the flight shows a dark panel (reflectance about\n"
    "               0.1, the grey one's about 0.5): panels of two reflectances, from which `msgs\n"
    "               import --radiometry panel` fits an empirical line (needs --panel-captures 2 or more)\n"
    "  --path-reflectance P  haze: every band of every capture sees P more reflectance (0 to 0.2;\n"
    "               default 0), light in proportion to the sunlight, which the line's offset takes out\n";

int run_raw(const msgs::cli::Args& args) {
  msgs::synth::RawOptions opt;
  opt.camera = args.get("raw");
  opt.preset = args.get("preset", "tiny");
  const long seed = args.integer("seed", 1), captures = args.integer("captures", 0), width = args.integer("width", 0);
  if (seed < 0) throw msgs::cli::UsageError("option --seed expects a non-negative integer");
  opt.seed = static_cast<std::uint64_t>(seed);
  opt.captures = static_cast<int>(std::clamp(captures, -1L, 1000000L));
  opt.width = static_cast<int>(std::clamp(width, -1L, 1000000L));
  // Ranges checked by write_synthetic_raw.
  opt.light_variation = args.number("light-variation", 0.0);
  opt.dls_bias = args.number("dls-bias", 0.0);
  opt.panel_captures = static_cast<int>(std::clamp(args.integer("panel-captures", 0), -1L, 1000000L));
  opt.panel_before = args.flag("panel-before");
  opt.light_drift = args.number("light-drift", 0.0);
  opt.dls1 = args.flag("dls1");
  opt.heading_bias = args.number("heading-bias", 0.0);
  opt.dark_panel = args.flag("dark-panel");
  opt.path_reflectance = args.number("path-reflectance", 0.0);
  opt.overwrite = args.flag("force");
  const std::string out = args.require("out");
  msgs::synth::RawSummary s;
  try {
    s = msgs::synth::write_synthetic_raw(out, opt);
  } catch (const std::invalid_argument& e) {
    throw msgs::cli::UsageError(e.what());
  }
  std::printf("synthetic raw %s captures (preset %s, seed %llu) written to %s\n", s.camera.c_str(), opt.preset.c_str(),
              static_cast<unsigned long long>(opt.seed), s.out.string().c_str());
  std::printf("  captures: %d%s, files: %d\n", s.captures,
              s.panel_captures ? msgs::io::cat(" and ", s.panel_captures, " of a calibration panel",
                                               s.camera == "micasense" ? "" : " (listed in panels.json)")
                                     .c_str()
                               : "",
              s.files);
  std::printf("  multispectral %d x %d (16-bit TIFF)", s.ms_width, s.ms_height);
  if (s.camera != "micasense") std::printf(", RGB %d x %d (JPEG)", s.rgb_width, s.rgb_height);
  std::printf("\n  exposure 1/%.0f .. 1/%.0f s, ISO %d .. %d\n", 1.0 / s.min_exposure_s, 1.0 / s.max_exposure_s, s.min_iso,
              s.max_iso);
  std::printf("  time: %.2f s\n", s.seconds);
  return 0;
}

int run_synth(const std::vector<std::string>& argv) {
  const msgs::cli::Args args(
      argv,
      {"preset", "out", "seed", "raw", "captures", "width", "light-variation", "dls-bias", "panel-captures", "light-drift",
       "heading-bias", "path-reflectance"},
      {"force", "help", "panel-before", "dls1", "dark-panel"});
  if (args.flag("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!args.positional().empty()) throw msgs::cli::UsageError("unexpected argument '" + args.positional()[0] + "'");
  if (args.has("raw")) return run_raw(args);
  for (const char* o :
       {"captures", "width", "light-variation", "dls-bias", "panel-captures", "light-drift", "heading-bias",
        "path-reflectance"})
    if (args.has(o)) throw msgs::cli::UsageError(std::string("--") + o + " needs --raw");
  for (const char* f : {"panel-before", "dls1", "dark-panel"})
    if (args.flag(f)) throw msgs::cli::UsageError(std::string("--") + f + " needs --raw");
  msgs::synth::SynthOptions opt;
  opt.preset = args.get("preset", "tiny");
  try {
    (void)msgs::synth::synth_preset(opt.preset);
  } catch (const std::invalid_argument& e) {
    throw msgs::cli::UsageError(e.what());
  }
  const long seed = args.integer("seed", 1);
  if (seed < 0) throw msgs::cli::UsageError("option --seed expects a non-negative integer");
  opt.seed = static_cast<std::uint64_t>(seed);
  opt.overwrite = args.flag("force");
  const std::string out = args.require("out");

  const auto s = msgs::write_synthetic_dataset(out, opt);
  std::printf("synthetic dataset '%s' (seed %llu) written to %s\n", s.preset.c_str(),
              static_cast<unsigned long long>(s.seed), s.out.string().c_str());
  std::printf("  captures: %d (%d train, %d eval)\n", s.captures, s.train_captures, s.eval_captures);
  for (msgs::synth::Band b : msgs::synth::all_bands) {
    const auto i = static_cast<std::size_t>(b);
    std::printf("  %-7s %3d frames  %4d x %-4d  %s\n", std::string(msgs::synth::band_name(b)).c_str(),
                s.frames_per_band[i], s.width[i], s.height[i], b == msgs::synth::Band::D ? "8-bit" : "16-bit");
  }
  std::string ds;
  for (int f : s.downscales) ds += " images_" + std::to_string(f);
  std::printf("  downscaled:%s\n", ds.c_str());
  std::printf("  sparse_pc.ply: %zu points (%zu outliers)\n", s.points, s.outliers);
  std::printf("  time: %.2f s\n", s.seconds);
  return 0;
}

}  // namespace
}  // namespace cmd_synth

MSGS_COMMAND("synth", "Generate a ray-traced synthetic multi-spectral dataset", cmd_synth::run_synth);
