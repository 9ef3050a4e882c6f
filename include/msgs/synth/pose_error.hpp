// include/msgs/synth/pose_error.hpp
// How far the poses of an import of a synthetic flight (`msgs synth --raw`, then `msgs import`)
// are from the cameras the scene rendered each image from. COLMAP's frame is the scene's up to a
// similarity, fitted (msgs/io/similarity.hpp) to the camera centres of the frames of COLMAP's main
// model ("pose": "colmap" in transforms.json); every frame is measured after it, so frames
// carried over from a model of the rest and frames the rig placed are held to the same frame.
// Used by bench/synth_pose_error and by the import tests.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../io/rig_poses.hpp"
#include "../io/similarity.hpp"
#include "scene.hpp"
#include "spectra.hpp"

namespace msgs::synth {

/// One frame of transforms.json against the truth.
struct FramePoseError {
  std::string source, band, pose;  ///< as transforms.json has them ("pose": "colmap" when absent)
  double metres = 0;               ///< camera centre from the scene's, in the scene's unit
  double degrees = 0;              ///< rotation from the scene's
};

/// Every frame's error, in frame order, and the scene's capture spacing (the median distance
/// from a capture to its nearest other one).
struct PoseErrors {
  std::vector<FramePoseError> frames;
  double capture_spacing = 0;
};

/// The errors of the frames of `transforms` (a parsed transforms.json; `where` names it in
/// errors) against `scene`, the scene the raw folder was rendered from. A frame's capture is the
/// number that ends its "capture" key, counted from 1 as `msgs synth` numbers them.
/// std::invalid_argument for a capture key without a number or beyond the scene's captures, and
/// when fewer than 3 frames come from COLMAP's main model (no similarity to fit).
inline PoseErrors frame_pose_errors(const nlohmann::json& transforms, const SynthScene& scene, const std::string& where) {
  PoseErrors out;
  std::vector<Eigen::Vector3d> got, want, main_got, main_want;
  std::vector<Eigen::Matrix3d> got_R, want_R;
  for (const auto& f : transforms.at("frames")) {
    const std::string key = f.at("capture").get<std::string>();
    const std::size_t digits = key.find_last_not_of("0123456789") + 1;  // npos + 1 == 0: all digits
    if (digits == key.size()) throw std::invalid_argument(where + ": capture '" + key + "' has no number at its end");
    const std::size_t capture = std::size_t(std::stoul(key.substr(digits))) - 1;
    if (capture >= scene.captures.size())
      throw std::invalid_argument(where + ": capture " + key + " beyond the scene's " +
                                  std::to_string(scene.captures.size()) + " (--captures as given to msgs synth)");
    const std::string band = f.at("mm_channel").get<std::string>();
    Eigen::Matrix4f c2w;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) c2w(r, c) = f.at("transform_matrix")[std::size_t(r)][std::size_t(c)].get<float>();
    const auto cam = Camera<float>::from_opengl_c2w(c2w);
    const Camera<float>& truth = scene.captures[capture].cameras[std::size_t(band_from_name(band))];
    out.frames.push_back({f.value("source", std::string()), band, f.value("pose", std::string("colmap")), 0.0, 0.0});
    got.push_back(cam.position().cast<double>());
    want.push_back(truth.position().cast<double>());
    got_R.push_back(cam.R.cast<double>());
    want_R.push_back(truth.R.cast<double>());
    if (out.frames.back().pose == "colmap") {
      main_got.push_back(got.back());
      main_want.push_back(want.back());
    }
  }
  const io::Similarity sim = io::fit_similarity(main_got, main_want);  // COLMAP world -> scene world
  std::vector<Eigen::Vector3d> positions;
  for (const auto& c : scene.captures) positions.push_back(c.rig_position.cast<double>());
  out.capture_spacing = io::detail::median_nearest_distance(positions);
  for (std::size_t i = 0; i < out.frames.size(); ++i) {
    out.frames[i].metres = (sim(got[i]) - want[i]).norm();
    out.frames[i].degrees = io::detail::rotation_angle_deg(got_R[i] * sim.R.transpose(), want_R[i]);
  }
  return out;
}

}  // namespace msgs::synth
