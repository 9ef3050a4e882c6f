// fuzz/fuzz_ply.cpp
// libFuzzer target for the PLY readers: inspect_ply, read_point_cloud and read_ply<Gaussian<3, 3>>.
#include <cstddef>
#include <cstdint>

#include "fuzz_common.hpp"
#include "msgs/io/ply.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace msgs;
  const auto p = fuzz::scratch_dir() / "input.ply";
  fuzz::put_file(p, data, size);
  fuzz::expect_io_error_only("inspect_ply", [&] { (void)io::inspect_ply(p); });
  fuzz::expect_io_error_only("read_point_cloud", [&] { (void)io::read_point_cloud(p); });
  fuzz::expect_io_error_only("read_ply<3,3>", [&] { (void)io::read_ply<Gaussian<3, 3>>(p); });
  return 0;
}
