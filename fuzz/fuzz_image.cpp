// fuzz/fuzz_image.cpp
// libFuzzer target for the image readers: read_image (PNG via libpng, TIFF via libtiff, JPEG and
// others via stb, sniffed from the content) and read_npy.
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "fuzz_common.hpp"
#include "msgs/io/image_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace msgs;
  const auto p = fuzz::scratch_dir() / "input.img";
  fuzz::put_file(p, data, size);
  if (size >= 6 && std::memcmp(data, "\x93NUMPY", 6) == 0)
    fuzz::expect_io_error_only("read_npy", [&] { (void)io::read_npy(p); });
  else
    fuzz::expect_io_error_only("read_image", [&] {
      const Image<float> img = io::read_image(p);
      // The box filter walks the decoded buffer with the decoded sizes: a cheap consistency check.
      (void)io::downscale(img, 2);
    });
  return 0;
}
