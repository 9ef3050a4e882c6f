// bench/synth_pose_error.cpp
// How far the poses of an imported synthetic flight are from the scene's cameras: `msgs synth --raw`
// writes the raw folder, `msgs import` poses it with COLMAP (and the rig), and this compares each
// frame of the resulting transforms.json with the camera the scene rendered it from, after the
// least-squares similarity that takes the import's frame onto the scene's (msgs/synth/pose_error.hpp).
// Positions in metres (the scene's unit) and in capture spacings, rotations in degrees. The
// similarity is fitted on the frames of COLMAP's main model; frames carried over from a model of
// the rest and frames the rig placed are measured against it and counted apart. The README's
// import accuracy numbers come from it:
//
//   msgs synth --preset small --raw dji --captures 48 --width 320 --out flight48
//   msgs import --images flight48 --out flight48_ds --matching gps
//   ./build/bench/synth_pose_error flight48_ds --preset small --captures 48 [--seed 1]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <msgs/io/file.hpp>
#include <msgs/synth.hpp>
#include <msgs/synth/pose_error.hpp>

namespace {

struct Errors {
  std::vector<double> metres, degrees;
  void print(const char* what, double spacing) {
    if (metres.empty()) return;
    auto sorted = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v;
    };
    const auto m = sorted(metres), d = sorted(degrees);
    std::printf("%s (%zu): position median %.4f m (%.3f spacings), max %.4f m (%.3f); rotation median %.3f, max %.3f deg\n",
                what, m.size(), m[m.size() / 2], m[m.size() / 2] / spacing, m.back(), m.back() / spacing, d[d.size() / 2],
                d.back());
  }
};

int run(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: synth_pose_error DATASET [--preset small] [--captures N] [--seed S]\n");
    return 2;
  }
  std::string preset_name = "small";
  int captures = 0;
  std::uint64_t seed = 1;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--preset") preset_name = v;
    else if (k == "--captures") captures = std::stoi(v);
    else if (k == "--seed") seed = std::stoull(v);
    else throw std::invalid_argument("unknown option " + k);
  }
  msgs::synth::SynthPreset preset = msgs::synth::synth_preset(preset_name);
  if (captures > 0) preset.captures = captures;  // as `msgs synth --raw --captures` (the poses do not depend on the size)
  const msgs::synth::SynthScene scene = msgs::synth::make_scene(preset, seed);

  const std::string path = std::string(argv[1]) + "/transforms.json";
  const msgs::synth::PoseErrors pe =
      msgs::synth::frame_pose_errors(nlohmann::json::parse(msgs::io::read_text(path)), scene, path);
  enum Kind { kMain, kCarried, kRig };
  Errors errors[3];
  for (const auto& f : pe.frames) {
    Errors& e = errors[f.pose.rfind("rig", 0) == 0 ? kRig : f.pose == "colmap" ? kMain : kCarried];
    e.metres.push_back(f.metres);
    e.degrees.push_back(f.degrees);
  }
  const double spacing = pe.capture_spacing;
  std::printf("%s: %zu frames; capture spacing (median nearest neighbour) %.3f m\n", path.c_str(), pe.frames.size(), spacing);
  errors[kMain].print("registered in COLMAP's main model", spacing);
  errors[kCarried].print("carried over from a model of the rest", spacing);
  errors[kRig].print("placed by the rig", spacing);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "synth_pose_error: %s\n", e.what());
    return 1;
  }
}
