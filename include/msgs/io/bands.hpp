// include/msgs/io/bands.hpp
// The band table of the multi-spectral dataset (REFERENCE.md §1): band ids, channel counts, where
// each band sits in a Joint model's 7 channels, and nominal wavelengths.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace msgs::io {

/// One band of the capture rig.
struct BandInfo {
  std::string id;               ///< `mm_channel` value in transforms.json, e.g. "D", "MS_NIR"
  int channels;                 ///< colour channels of the band (3 for D, 1 for the narrow bands)
  int first_channel_in_joint;   ///< first channel index in a Joint (7-channel) model
  double centre_nm;             ///< nominal centre wavelength in nm (0 for the broadband RGB camera)
  double half_width_nm;         ///< half of the pass-band width in nm (0 for the RGB camera)
};

/// The five standard bands: D (RGB, Joint channels 0..2), then MS_G = 3, MS_R = 4, MS_RE = 5, MS_NIR = 6.
inline const std::vector<BandInfo>& standard_bands() {
  static const std::vector<BandInfo> bands = {
      {"D", 3, 0, 0.0, 0.0},
      {"MS_G", 1, 3, 560.0, 16.0},
      {"MS_R", 1, 4, 650.0, 16.0},
      {"MS_RE", 1, 5, 730.0, 16.0},
      {"MS_NIR", 1, 6, 860.0, 26.0},
  };
  return bands;
}

/// Total channels of a Joint model holding every standard band.
inline int joint_channels() {
  int n = 0;
  for (const auto& b : standard_bands()) n += b.channels;
  return n;
}

/// The standard band with this id, or nullptr.
inline const BandInfo* find_band(std::string_view id) {
  for (const auto& b : standard_bands())
    if (b.id == id) return &b;
  return nullptr;
}

/// Names of the individual channels of a Joint model, for PLY headers and reports:
/// D_R D_G D_B MS_G MS_R MS_RE MS_NIR.
inline std::vector<std::string> joint_channel_names() {
  std::vector<std::string> names;
  for (const auto& b : standard_bands()) {
    if (b.channels == 3) {
      for (const char* c : {"_R", "_G", "_B"}) names.push_back(b.id + c);
    } else {
      for (int c = 0; c < b.channels; ++c) names.push_back(b.channels == 1 ? b.id : b.id + "_" + std::to_string(c));
    }
  }
  return names;
}

}  // namespace msgs::io
