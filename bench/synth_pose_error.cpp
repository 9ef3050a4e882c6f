// bench/synth_pose_error.cpp
// How far the poses of an imported synthetic flight are from the scene's cameras: `msgs synth --raw`
// writes the raw folder, `msgs import` poses it with COLMAP (and the rig), and this compares each
// frame of the resulting transforms.json with the camera the scene rendered it from, after the
// least-squares similarity (msgs/io/similarity.hpp) that takes the import's frame onto the scene's.
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
#include <msgs/io/rig_poses.hpp>
#include <msgs/io/similarity.hpp>
#include <msgs/synth.hpp>

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
  const nlohmann::json tf = nlohmann::json::parse(msgs::io::read_text(path));
  std::vector<Eigen::Vector3d> got, want;
  std::vector<Eigen::Matrix3d> got_R, want_R;
  enum Kind { kMain, kCarried, kRig };
  std::vector<Kind> kind;
  for (const auto& f : tf.at("frames")) {
    // The capture's number ends its key ("0001", "IMG_0001"), counted from 1 as synth numbers them.
    const std::string key = f.at("capture").get<std::string>();
    const std::size_t digits = key.find_last_not_of("0123456789") + 1;  // npos + 1 == 0: all digits
    if (digits == key.size()) throw std::invalid_argument(path + ": capture '" + key + "' has no number at its end");
    const std::size_t capture = std::size_t(std::stoul(key.substr(digits))) - 1;
    if (capture >= scene.captures.size())
      throw std::invalid_argument(path + ": capture " + f.at("capture").get<std::string>() + " beyond the scene's " +
                                  std::to_string(scene.captures.size()) + " (--captures as given to msgs synth)");
    const msgs::synth::Band band = msgs::synth::band_from_name(f.at("mm_channel").get<std::string>());
    Eigen::Matrix4f c2w;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) c2w(r, c) = f.at("transform_matrix")[std::size_t(r)][std::size_t(c)].get<float>();
    const auto cam = msgs::Camera<float>::from_opengl_c2w(c2w);
    const msgs::Camera<float>& truth = scene.captures[capture].cameras[std::size_t(band)];
    got.push_back(cam.position().cast<double>());
    want.push_back(truth.position().cast<double>());
    got_R.push_back(cam.R.cast<double>());
    want_R.push_back(truth.R.cast<double>());
    const std::string pose = f.value("pose", std::string("colmap"));
    kind.push_back(pose.rfind("rig", 0) == 0 ? kRig : pose == "colmap" ? kMain : kCarried);
  }
  // The similarity from the frames of COLMAP's main model; the others are measured against it.
  std::vector<Eigen::Vector3d> reg_got, reg_want;
  for (std::size_t i = 0; i < got.size(); ++i)
    if (kind[i] == kMain) {
      reg_got.push_back(got[i]);
      reg_want.push_back(want[i]);
    }
  const msgs::io::Similarity sim = msgs::io::fit_similarity(reg_got, reg_want);
  std::vector<double> gaps;  // each capture's distance to the nearest other
  for (std::size_t a = 0; a < scene.captures.size(); ++a) {
    double d = 1e300;
    for (std::size_t b = 0; b < scene.captures.size(); ++b)
      if (a != b) d = std::min(d, double((scene.captures[a].rig_position - scene.captures[b].rig_position).norm()));
    gaps.push_back(d);
  }
  std::sort(gaps.begin(), gaps.end());
  const double spacing = gaps[gaps.size() / 2];
  Errors errors[3];
  for (std::size_t i = 0; i < got.size(); ++i) {
    Errors& e = errors[kind[i]];
    e.metres.push_back((sim(got[i]) - want[i]).norm());
    e.degrees.push_back(msgs::io::detail::rotation_angle_deg(got_R[i] * sim.R.transpose(), want_R[i]));
  }
  std::printf("%s: %zu frames; capture spacing (median nearest neighbour) %.3f m\n", path.c_str(), got.size(), spacing);
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
