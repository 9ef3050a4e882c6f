// include/msgs/io/frame_json.hpp
// Writing a camera into a frame of transforms.json, as `msgs synth` and `msgs import` both do: the
// numbers in the shortest form that reads back as the same float, so the files stay readable and
// load_dataset recovers the exact camera.
#pragma once

#include <cstdio>
#include <cstdlib>

#include <nlohmann/json.hpp>

#include "msgs/camera.hpp"

namespace msgs::io {

/// Float to the shortest double that reads back as the same float: the JSON shows 0.300000012
/// rather than 0.30000001192092896, and never "-0.0".
inline double json_float(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", double(v));
  const double d = std::strtod(buf, nullptr);
  return d == 0.0 ? 0.0 : d;
}

/// A frame's intrinsics: "fl_x", "fl_y", "cx", "cy", "w" and "h", in that order.
inline void write_intrinsics_json(nlohmann::ordered_json& frame, const Camera<float>& cam) {
  frame["fl_x"] = json_float(cam.fx);
  frame["fl_y"] = json_float(cam.fy);
  frame["cx"] = json_float(cam.cx);
  frame["cy"] = json_float(cam.cy);
  frame["w"] = cam.width;
  frame["h"] = cam.height;
}

/// A frame's "transform_matrix": the camera's pose as an OpenGL camera-to-world matrix, row by row.
inline nlohmann::ordered_json transform_matrix_json(const Camera<float>& cam) {
  const Eigen::Matrix4f m = cam.opengl_c2w();
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  for (int r = 0; r < 4; ++r) {
    nlohmann::ordered_json row = nlohmann::ordered_json::array();
    for (int c = 0; c < 4; ++c) row.push_back(json_float(m(r, c)));
    rows.push_back(row);
  }
  return rows;
}

}  // namespace msgs::io
