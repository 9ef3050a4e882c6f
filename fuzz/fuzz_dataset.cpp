// fuzz/fuzz_dataset.cpp
// libFuzzer target for the dataset loader: transforms.json and train_split.json parsing through
// io::load_dataset on a scratch dataset whose image files exist (empty) and whose point cloud is valid.
//
// Input: the transforms.json text, optionally followed by a NUL byte and the train_split.json
// text (no NUL: the dataset has no split file).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "fuzz_common.hpp"
#include "msgs/io/dataset.hpp"
#include "msgs/io/ply.hpp"

namespace {

/// A dataset folder with every band's first two images (empty files: the loader only checks that
/// they exist) and a two-point sparse_pc.ply.
const std::filesystem::path& dataset_root() {
  static const std::filesystem::path root = [] {
    namespace fs = std::filesystem;
    const fs::path r = msgs::fuzz::scratch_dir() / "dataset";
    fs::create_directories(r / "images");
    for (const char* band : {"D", "MS_G", "MS_R", "MS_RE", "MS_NIR"})
      for (const char* idx : {"00001", "00002"})
        msgs::fuzz::put_file(r / "images" / (std::string(band) + "_" + idx + ".png"), "", 0);
    msgs::io::PointCloud pc;
    pc.xyz = {0.f, 0.f, 0.f, 1.f, 2.f, 3.f};
    pc.rgb = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f};
    msgs::io::write_point_cloud(r / "sparse_pc.ply", pc);
    return r;
  }();
  return root;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace msgs;
  namespace fs = std::filesystem;
  const fs::path& root = dataset_root();
  const auto* begin = reinterpret_cast<const char*>(data);
  const auto* end = begin + size;
  const auto* nul = std::find(begin, end, '\0');
  fuzz::put_file(root / "transforms.json", begin, std::size_t(nul - begin));
  std::error_code ec;
  if (nul != end) fuzz::put_file(root / "train_split.json", nul + 1, std::size_t(end - nul - 1));
  else fs::remove(root / "train_split.json", ec);

  fuzz::expect_io_error_only("load_dataset", [&] { (void)io::load_dataset(root); });
  // A band filter takes the other split path (entries of filtered-out bands must still match).
  io::LoadOptions opt;
  opt.bands = {"D", "MS_NIR"};
  opt.orient_and_center = false;
  fuzz::expect_io_error_only("load_dataset(bands)", [&] { (void)io::load_dataset(root, opt); });
  return 0;
}
