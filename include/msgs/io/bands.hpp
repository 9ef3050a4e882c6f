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

/// The wavelengths a camera band may have and still fill a standard narrow band's slot: green
/// 490-600 nm, red 600-700, red edge 690-760, near infra-red 760-1000. Wide enough for the filters
/// of the usual multispectral cameras (MicaSense red 668, red edge 717, NIR 842; DJI 560, 650, 730,
/// 860; Parrot Sequoia 550, 660, 735, 790) and narrow enough to keep blue, a second green or a
/// thermal band out. {0, 0} for the RGB camera, which has no single wavelength.
struct BandWindow {
  double lo_nm = 0, hi_nm = 0;
};
inline BandWindow band_window(std::string_view id) {
  if (id == "MS_G") return {490.0, 600.0};
  if (id == "MS_R") return {600.0, 700.0};
  if (id == "MS_RE") return {690.0, 760.0};
  if (id == "MS_NIR") return {760.0, 1000.0};
  return {};
}

/// Whether a camera band centred at `nm` can fill slot `id` (always true for the RGB camera and
/// for ids without a window).
inline bool wavelength_fits_band(std::string_view id, double nm) {
  const BandWindow w = band_window(id);
  return w.hi_nm == 0 || (nm >= w.lo_nm && nm <= w.hi_nm);
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
