// include/msgs/io/load_scene.hpp
// One entry point for every dataset a user may point msgs at: the nerfstudio multi-spectral
// layout (transforms.json) or a COLMAP scene (images/ + sparse/0 or sparse/, text or binary).
// detect_scene() says which it found; load_scene() loads it with the right reader.
#pragma once

#include <cctype>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>

#include "msgs/io/colmap.hpp"
#include "msgs/io/dataset.hpp"
#include "msgs/io/error.hpp"

namespace msgs::io {

/// The two dataset layouts msgs reads.
enum class SceneLayout { nerfstudio, colmap };

/// What detect_scene() found under a dataset root.
struct SceneInfo {
  SceneLayout layout = SceneLayout::nerfstudio;
  std::filesystem::path model_dir;  ///< COLMAP: the folder holding cameras/images/points3D
  bool binary = false;              ///< COLMAP: .bin files (else .txt)

  /// "nerfstudio layout (transforms.json)" or "COLMAP scene (sparse/0, binary)".
  std::string describe(const std::filesystem::path& root) const {
    if (layout == SceneLayout::nerfstudio) return "nerfstudio layout (transforms.json)";
    return cat("COLMAP scene (", model_dir.lexically_relative(root).generic_string(), ", ", binary ? "binary" : "text",
               ")");
  }
};

/// Which layout `root` holds: transforms.json wins; else a COLMAP model in sparse/0 or sparse/
/// (cameras and images, .bin or .txt). IoError naming both expectations when neither is there.
inline SceneInfo detect_scene(const std::filesystem::path& root) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(root, ec)) fail(root, "dataset folder does not exist");
  SceneInfo info;
  if (fs::is_regular_file(root / "transforms.json", ec)) return info;
  for (const fs::path& dir : {root / "sparse" / "0", root / "sparse"}) {
    for (const char* ext : {".bin", ".txt"}) {
      if (fs::is_regular_file(dir / cat("cameras", ext), ec) && fs::is_regular_file(dir / cat("images", ext), ec)) {
        info.layout = SceneLayout::colmap;
        info.model_dir = dir;
        info.binary = std::string(ext) == ".bin";
        return info;
      }
    }
  }
  fail(root, "not a dataset msgs can read: expected transforms.json (nerfstudio multi-spectral layout) or a COLMAP "
             "model (sparse/0/ or sparse/ with cameras and images, .bin or .txt) next to images/; "
             "`msgs import` turns a folder of camera images into a dataset");
}

/// "images_4" -> 4; nullopt for any other name.
inline std::optional<int> downscale_folder_factor(const std::string& name) {
  const std::string n = std::filesystem::path(name).lexically_normal().generic_string();
  if (n.rfind("images_", 0) != 0 || n.size() == 7 || n.size() > 10) return std::nullopt;
  int f = 0;
  for (std::size_t i = 7; i < n.size(); ++i) {
    if (!std::isdigit(static_cast<unsigned char>(n[i]))) return std::nullopt;
    f = 10 * f + (n[i] - '0');
  }
  return f >= 1 ? std::optional<int>(f) : std::nullopt;
}

/// Load the dataset at `root` in whichever layout detect_scene() finds.
///
/// `image_dir` picks the image folder ("images" by default). "images_<f>" next to a full-size
/// "images/" means resolution divisor f (the prepared copies are used, as for opt.downscale); for
/// a COLMAP scene any other folder holds resized copies whose size sets the intrinsics. The
/// nerfstudio layout names its images in transforms.json, so there only "images_<f>" is accepted.
/// `info`, when given, receives what was detected.
inline Dataset load_scene(const std::filesystem::path& root, LoadOptions opt = {}, const std::string& image_dir = "images",
                          SceneInfo* info = nullptr) {
  namespace fs = std::filesystem;
  const SceneInfo found = detect_scene(root);
  if (info) *info = found;
  std::string dir = image_dir.empty() ? std::string("images") : image_dir;
  std::error_code ec;
  if (const auto f = downscale_folder_factor(dir); f && fs::is_directory(root / "images", ec)) {
    if (!fs::is_directory(root / dir, ec))
      fail(root / dir, cat("image folder does not exist (--images ", dir, " asks for images downscaled by ", *f, ")"));
    opt.downscale = *f;
    dir = "images";
  }
  if (found.layout == SceneLayout::nerfstudio) {
    if (dir != "images")
      fail(root / "transforms.json", cat("image folder '", image_dir, "': a nerfstudio layout names its images in "
                                         "transforms.json; only images_<f> (a downscaled copy next to images/) can be chosen"));
    return load_dataset(root, opt);
  }
  if (!fs::is_directory(root / dir, ec)) fail(root / dir, "image folder of the COLMAP scene does not exist");
  return load_colmap_dataset(root, opt, dir);
}

}  // namespace msgs::io
