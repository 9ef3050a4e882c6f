// tests/test_ply.cpp
// Tests for include/msgs/io/ply.hpp: 3DGS model round trips for 1, 3 and 7 channels, the
// channel-major f_rest layout checked byte by byte, inspection, RGB export, point clouds, bad files.
#include <doctest/doctest.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "msgs/io/ply.hpp"
#include "scratch.hpp"

namespace test_ply {
namespace fs = std::filesystem;
using msgs::testing::io_error_of;
using namespace msgs;
using namespace msgs::io;

namespace {

fs::path scratch(const std::string& sub) { return msgs::testing::fresh_scratch_dir("test_ply/" + sub); }

template <class G>
GaussianModel<G, float> random_model(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  GaussianModel<G, float> m(n);
  for (auto* v : {&m.means, &m.log_scales, &m.quats, &m.opacity_logits, &m.sh})
    for (auto& x : *v) x = g(rng);
  return m;
}

template <class G>
void check_equal(const GaussianModel<G, float>& a, const GaussianModel<G, float>& b) {
  CHECK(a.means == b.means);
  CHECK(a.log_scales == b.log_scales);
  CHECK(a.quats == b.quats);
  CHECK(a.opacity_logits == b.opacity_logits);
  CHECK(a.sh == b.sh);
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

}  // namespace

TEST_CASE_TEMPLATE("PLY round trip is bit exact", G, Gaussian<1, 3>, Gaussian<3, 3>, Gaussian<7, 3>, Gaussian<3, 0>,
                   Gaussian<7, 0>) {
  const auto dir = scratch("roundtrip");
  const auto m = random_model<G>(37, 1234u + unsigned(G::bands * 10 + G::sh_degree));
  std::vector<std::string> names;
  for (int c = 0; c < G::bands; ++c) names.push_back(cat("band", c));
  const auto p = dir / "m.ply";
  write_ply(p, m, names);
  std::vector<std::string> back_names;
  const auto back = read_ply<G>(p, &back_names);
  REQUIRE(back.size() == m.size());
  check_equal(m, back);
  CHECK(back_names == names);
  const PlyInfo info = inspect_ply(p);
  CHECK(info.gaussian);
  CHECK(info.vertices == 37);
  CHECK(info.channels == G::bands);
  CHECK(info.sh_degree == G::sh_degree);
  CHECK(info.band_names == names);
  // File size: header + N * (6 + C K + 8) floats.
  const auto size = fs::file_size(p);
  CHECK(size > 37u * (14u + unsigned(G::sh_floats)) * 4u);
}

TEST_CASE("PLY byte layout matches the 3DGS convention (independent decoder)") {
  using G = Gaussian<3, 1>;  // K = 4: f_rest has 9 entries
  GaussianModel<G, float> m(2);
  for (std::size_t i = 0; i < 2; ++i) {
    for (int k = 0; k < G::sh_coeffs; ++k)
      for (int c = 0; c < 3; ++c) m.sh_at(i, k, c) = float(100 * int(i) + 10 * k + c);
    m.means[3 * i] = 1.5f; m.means[3 * i + 1] = -2.0f; m.means[3 * i + 2] = 3.0f;
    m.opacity_logits[i] = -0.25f;
    m.log_scales[3 * i] = -1; m.log_scales[3 * i + 1] = -2; m.log_scales[3 * i + 2] = -3;
    m.quats[4 * i] = 0.5f; m.quats[4 * i + 1] = 0.1f; m.quats[4 * i + 2] = 0.2f; m.quats[4 * i + 3] = 0.3f;
  }
  const auto dir = scratch("layout");
  write_ply(dir / "m.ply", m);
  const auto bytes = read_bytes(dir / "m.ply");
  const std::string text(bytes.begin(), bytes.end());
  const auto hend = text.find("end_header\n") + 11;
  // Collect property names in order.
  std::vector<std::string> props;
  std::istringstream hs(text.substr(0, hend));
  for (std::string line; std::getline(hs, line);)
    if (line.rfind("property float ", 0) == 0) props.push_back(line.substr(15));
  const std::vector<std::string> expect = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
                                           "f_rest_0", "f_rest_1", "f_rest_2", "f_rest_3", "f_rest_4", "f_rest_5",
                                           "f_rest_6", "f_rest_7", "f_rest_8", "opacity", "scale_0", "scale_1",
                                           "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"};
  REQUIRE(props == expect);
  REQUIRE(bytes.size() == hend + 2 * props.size() * 4);
  auto value = [&](std::size_t i, std::size_t prop) {
    float v;
    std::memcpy(&v, bytes.data() + hend + (i * props.size() + prop) * 4, 4);
    return v;
  };
  for (std::size_t i = 0; i < 2; ++i) {
    CHECK(value(i, 0) == 1.5f);
    CHECK(value(i, 3) == 0.0f);  // normals
    for (int c = 0; c < 3; ++c) CHECK(value(i, 6 + std::size_t(c)) == float(100 * int(i) + c));
    // channel c, coefficient k >= 1 at f_rest_{c (K-1) + k - 1}
    for (int c = 0; c < 3; ++c)
      for (int k = 1; k < 4; ++k) CHECK(value(i, 9 + std::size_t(c * 3 + k - 1)) == float(100 * int(i) + 10 * k + c));
    CHECK(value(i, 18) == -0.25f);
    CHECK(value(i, 21) == -3.0f);
    CHECK(value(i, 22) == 0.5f);  // w first
    CHECK(value(i, 25) == 0.3f);
  }
}

TEST_CASE("lower SH degree in the file is zero-padded; higher degree and other channel counts are refused") {
  const auto dir = scratch("degree");
  const auto m0 = random_model<Gaussian<3, 0>>(5, 7);
  write_ply(dir / "d0.ply", m0);
  const auto m3 = read_ply<Gaussian<3, 3>>(dir / "d0.ply");
  REQUIRE(m3.size() == 5);
  for (std::size_t i = 0; i < 5; ++i)
    for (int c = 0; c < 3; ++c) {
      CHECK(m3.sh_at(i, 0, c) == m0.sh_at(i, 0, c));
      for (int k = 1; k < 16; ++k) CHECK(m3.sh_at(i, k, c) == 0.0f);
    }
  CHECK(m3.means == m0.means);
  CHECK(m3.quats == m0.quats);

  write_ply(dir / "d3.ply", random_model<Gaussian<3, 3>>(4, 8));
  CHECK(io_error_of([&] { (void)read_ply<Gaussian<3, 1>>(dir / "d3.ply"); }).find("SH degree 3") != std::string::npos);
  const auto msg = io_error_of([&] { (void)read_ply<Gaussian<7, 3>>(dir / "d3.ply"); });
  CHECK(msg.find("d3.ply") != std::string::npos);
  CHECK(msg.find("f_dc") != std::string::npos);
  CHECK(msg.find("3 colour channels") != std::string::npos);
}

TEST_CASE("RGB export of a Joint model is a plain 3-channel file") {
  const auto dir = scratch("rgb");
  const auto joint = random_model<Gaussian<7, 3>>(6, 99);
  write_ply_rgb(dir / "rgb.ply", joint);
  const auto info = inspect_ply(dir / "rgb.ply");
  CHECK(info.channels == 3);
  CHECK(info.band_names == std::vector<std::string>{"D_R", "D_G", "D_B"});
  const auto rgb = read_ply<Gaussian<3, 3>>(dir / "rgb.ply");
  for (std::size_t i = 0; i < 6; ++i)
    for (int k = 0; k < 16; ++k)
      for (int c = 0; c < 3; ++c) CHECK(rgb.sh_at(i, k, c) == joint.sh_at(i, k, c));
  CHECK(rgb.means == joint.means);
  const auto nir = slice_channels<6, 1>(joint);
  for (int k = 0; k < 16; ++k) CHECK(nir.sh_at(3, k, 0) == joint.sh_at(3, k, 6));
}

TEST_CASE("writer refuses bad band names and non-finite parameters, leaving no file") {
  const auto dir = scratch("badwrite");
  auto m = random_model<Gaussian<1, 0>>(3, 1);
  CHECK(io_error_of([&] { write_ply(dir / "a.ply", m, {"a", "b"}); }).find("band_names") != std::string::npos);
  CHECK(io_error_of([&] { write_ply(dir / "a.ply", m, {"has space"}); }).find("whitespace") != std::string::npos);
  m.log_scales[4] = std::numeric_limits<float>::infinity();
  CHECK(io_error_of([&] { write_ply(dir / "a.ply", m); }).find("scale") != std::string::npos);
  CHECK(fs::is_empty(dir));
}

TEST_CASE("point clouds: ASCII and binary, with and without colour") {
  const auto dir = scratch("pc");
  write_text(dir / "a.ply",
             "ply\r\nformat ascii 1.0\r\ncomment hello\r\nelement vertex 2\r\nproperty float x\r\nproperty float y\r\n"
             "property float z\r\nproperty uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\nend_header\r\n"
             "1 2 3 255 0 51\r\n-1.5 0.25 1e2 0 255 102\r\n");
  const auto a = read_point_cloud(dir / "a.ply");
  REQUIRE(a.size() == 2);
  CHECK(a.xyz == std::vector<float>{1, 2, 3, -1.5f, 0.25f, 100});
  REQUIRE(a.has_colour());
  CHECK(a.rgb[0] == 1.0f);
  CHECK(a.rgb[2] == doctest::Approx(0.2f));
  CHECK(a.rgb[5] == doctest::Approx(0.4f));

  write_text(dir / "b.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0.5 0.5 0.5\n3 0 0 0\n");
  const auto b = read_point_cloud(dir / "b.ply");
  CHECK(b.size() == 1);
  CHECK_FALSE(b.has_colour());

  PointCloud pc;
  pc.xyz = {0, 1, 2, 3, 4, 5, 6, 7, 8};
  pc.rgb = {0, 0.5f, 1, 1, 1, 1, 0.2f, 0.4f, 0.6f};
  write_point_cloud(dir / "c.ply", pc);
  const auto c = read_point_cloud(dir / "c.ply");
  CHECK(c.xyz == pc.xyz);
  for (std::size_t i = 0; i < 9; ++i) CHECK(c.rgb[i] == doctest::Approx(pc.rgb[i]).epsilon(0.003));
  const auto info = inspect_ply(dir / "c.ply");
  CHECK_FALSE(info.gaussian);
  CHECK(info.vertices == 3);
}

TEST_CASE("binary PLY: an element without properties holds no bytes, however many entries it declares") {
  // Found by fuzz_ply: such an element's entries took a pass of the chunked reader per 4096, so a
  // count of 1e15 never finished.
  const auto dir = scratch("empty_element");
  const float v[3] = {1.0f, 2.0f, 3.0f};
  std::string data(sizeof v, '\0');
  std::memcpy(data.data(), v, sizeof v);
  write_text(dir / "a.ply",
             "ply\nformat binary_little_endian 1.0\nelement marker 1000000000000000\nelement vertex 1\n"
             "property float x\nproperty float y\nproperty float z\nend_header\n" + data);
  const auto a = read_point_cloud(dir / "a.ply");
  CHECK(a.xyz == std::vector<float>{1, 2, 3});
}

TEST_CASE("bad PLY: truncated binary model") {
  const auto dir = scratch("trunc");
  write_ply(dir / "m.ply", random_model<Gaussian<3, 1>>(10, 3));
  fs::resize_file(dir / "m.ply", fs::file_size(dir / "m.ply") - 7);
  const auto msg = io_error_of([&] { (void)read_ply<Gaussian<3, 1>>(dir / "m.ply"); });
  CHECK(msg.find("m.ply") != std::string::npos);
  CHECK(msg.find("truncated") != std::string::npos);
  CHECK(msg.find("entry 9") != std::string::npos);
}

TEST_CASE("bad PLY: header count smaller than the data (wrong counts)") {
  const auto dir = scratch("count");
  write_text(dir / "a.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2 3\n4 5 6\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "a.ply"); }).find("after the declared elements") !=
        std::string::npos);
  write_text(dir / "b.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2 3\n4 5 6\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "b.ply"); }).find("truncated") != std::string::npos);
  write_text(dir / "c.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "c.ply"); }).find("field 'z'") != std::string::npos);
}

TEST_CASE("bad PLY: unsupported property types") {
  const auto dir = scratch("types");
  write_text(dir / "a.ply",
             "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty half x\nproperty float y\n"
             "property float z\nend_header\n");
  const auto msg = io_error_of([&] { (void)read_point_cloud(dir / "a.ply"); });
  CHECK(msg.find("field 'x'") != std::string::npos);
  CHECK(msg.find("half") != std::string::npos);
  write_text(dir / "b.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
             "property list uchar float extra\nend_header\n1 2 3 1 4\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "b.ply"); }).find("field 'extra'") != std::string::npos);
  write_text(dir / "c.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "c.ply"); }).find("binary_middle_endian") != std::string::npos);
}

TEST_CASE("bad PLY: NaN values are refused with the field name") {
  const auto dir = scratch("nan");
  write_text(dir / "a.ply",
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2 3\n4 nan 6\n");
  const auto msg = io_error_of([&] { (void)read_point_cloud(dir / "a.ply"); });
  CHECK(msg.find("field 'y'") != std::string::npos);
  CHECK(msg.find("vertex 1") != std::string::npos);
  // Binary model with a NaN opacity, patched into a valid file.
  write_ply(dir / "m.ply", random_model<Gaussian<1, 0>>(2, 5));
  auto bytes = read_bytes(dir / "m.ply");
  const std::string text(bytes.begin(), bytes.end());
  const std::size_t hend = text.find("end_header\n") + 11;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // properties: x y z nx ny nz f_dc_0 opacity ... -> opacity is index 7, vertex 1 starts at 15 floats
  std::memcpy(bytes.data() + hend + (15 + 7) * 4, &nan, 4);
  write_bytes_atomic(dir / "m.ply", bytes.data(), bytes.size());
  const auto msg2 = io_error_of([&] { (void)read_ply<Gaussian<1, 0>>(dir / "m.ply"); });
  CHECK(msg2.find("field 'opacity'") != std::string::npos);
  CHECK(msg2.find("vertex 1") != std::string::npos);
}

TEST_CASE("bad PLY: missing file, not a PLY, missing properties, gaps in f_rest") {
  const auto dir = scratch("misc");
  CHECK(io_error_of([&] { (void)inspect_ply(dir / "none.ply"); }).find("does not exist") != std::string::npos);
  write_text(dir / "x.ply", "PNG\n");
  CHECK(io_error_of([&] { (void)inspect_ply(dir / "x.ply"); }).find("not a PLY") != std::string::npos);
  write_text(dir / "y.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
  CHECK(io_error_of([&] { (void)read_point_cloud(dir / "y.ply"); }).find("field 'z'") != std::string::npos);
  write_text(dir / "z.ply",
             "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float f_dc_0\n"
             "property float f_rest_0\nproperty float f_rest_2\nproperty float opacity\nend_header\n");
  CHECK(io_error_of([&] { (void)inspect_ply(dir / "z.ply"); }).find("f_rest_") != std::string::npos);
  write_text(dir / "h.ply", "ply\nformat ascii 1.0\nelement vertex 1\n");
  CHECK(io_error_of([&] { (void)inspect_ply(dir / "h.ply"); }).find("end_header") != std::string::npos);
}

}  // namespace test_ply
