// fuzz/fuzz_colmap.cpp
// libFuzzer target for the COLMAP sparse-model readers (io::read_colmap): cameras, images and
// points3D, text or binary, including the camera-model and pose checks.
//
// Input: one byte choosing the format ('b' binary, anything else text), then the cameras file,
// the images file and the points3D file separated by kSeparator (a missing part: no such file,
// which points3D may be and the others may not).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string_view>
#include <system_error>

#include "fuzz_common.hpp"
#include "msgs/io/colmap.hpp"

namespace {
constexpr std::string_view kSeparator = "\n#@@next-file@@#\n";
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace msgs;
  namespace fs = std::filesystem;
  if (size == 0) return 0;
  const fs::path dir = fuzz::scratch_dir() / "colmap";
  std::error_code ec;
  fs::remove_all(dir, ec);
  fs::create_directories(dir);
  const bool binary = data[0] == 'b';
  const std::string_view in(reinterpret_cast<const char*>(data) + 1, size - 1);
  std::size_t pos = 0;
  for (const char* stem : {"cameras", "images", "points3D"}) {
    if (pos > in.size()) break;
    const std::size_t next = in.find(kSeparator, pos);
    const std::string_view part = in.substr(pos, next == std::string_view::npos ? std::string_view::npos : next - pos);
    fuzz::put_file(dir / (std::string(stem) + (binary ? ".bin" : ".txt")), part.data(), part.size());
    pos = next == std::string_view::npos ? in.size() + 1 : next + kSeparator.size();
  }
  fuzz::expect_io_error_only("read_colmap", [&] { (void)io::read_colmap(dir); });
  return 0;
}
