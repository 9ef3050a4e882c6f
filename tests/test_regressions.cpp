// tests/test_regressions.cpp
// Inputs found by fuzzing (fuzz/) or written to reproduce its findings, kept as bytes: each must
// fail fast with an io::IoError naming the file, not crash, hang or allocate gigabytes.
#include <doctest/doctest.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "msgs/io/image_io.hpp"
#include "msgs/io/ply.hpp"
#include "scratch.hpp"

namespace test_regressions {
namespace fs = std::filesystem;
using namespace msgs;

namespace {

fs::path scratch(const std::string& sub) { return msgs::testing::fresh_scratch_dir("test_regressions/" + sub); }

fs::path put(const fs::path& dir, const std::string& name, const std::string& bytes) {
  const fs::path p = dir / name;
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return p;
}

std::string bytes(std::initializer_list<unsigned> v) {
  std::string s;
  for (unsigned b : v) s.push_back(static_cast<char>(b));
  return s;
}

/// Run `f`, which must throw io::IoError whose message names `p` and contains `needle`, within a
/// second (the unfixed readers allocated for ~30 s, or threw std::bad_alloc, on these inputs).
template <class F>
void expect_fast_io_error(const fs::path& p, const std::string& needle, F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string msg;
  try {
    f();
    FAIL("accepted: " << p);
  } catch (const io::IoError& e) {
    msg = e.what();
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  INFO(msg);
  CHECK(msg.find(p.string()) != std::string::npos);
  CHECK(msg.find(needle) != std::string::npos);
  CHECK(s < 1.0);
}

// ---- PNG chunks with real CRCs (libpng rejects a bad IHDR CRC before reading the size).
std::uint32_t crc32(const std::string& s) {
  std::uint32_t c = 0xffffffffu;
  for (unsigned char b : s) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}
void put_be32(std::string& s, std::uint32_t v) {
  for (int b = 3; b >= 0; --b) s.push_back(static_cast<char>((v >> (8 * b)) & 0xff));
}
std::string png_chunk(const std::string& type, const std::string& data) {
  std::string s;
  put_be32(s, static_cast<std::uint32_t>(data.size()));
  const std::string body = type + data;
  s += body;
  put_be32(s, crc32(body));
  return s;
}

}  // namespace

TEST_CASE("PLY: a header claiming 1e12 vertices fails before allocating") {
  const auto dir = scratch("ply_count");
  // Binary: 3 floats per vertex, 12 bytes of data for 1e12 claimed vertices.
  const auto bin = put(dir, "binary.ply",
                       "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\n"
                       "property float y\nproperty float z\nend_header\n" + std::string(12, '\0'));
  expect_fast_io_error(bin, "declares 1000000000000 entries", [&] { (void)io::read_point_cloud(bin); });
  // 1e8 vertices used to allocate 1.2 GB, zero it, then report truncation after ~30 s under ASan.
  const auto mid = put(dir, "mid.ply",
                       "ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\n"
                       "property float y\nproperty float z\nend_header\n");
  expect_fast_io_error(mid, "declares 100000000 entries", [&] { (void)io::read_point_cloud(mid); });
  // ASCII, and a second element whose count overflows count * row size.
  const auto asc = put(dir, "ascii.ply",
                       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 18446744073709551615\nproperty list uchar int idx\n"
                       "end_header\n0 0 0\n");
  expect_fast_io_error(asc, "declares 18446744073709551615 entries", [&] { (void)io::read_point_cloud(asc); });
  // Gaussian model reader: same check, through read_ply.
  std::string model = "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n";
  for (const char* n : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                        "rot_0", "rot_1", "rot_2", "rot_3"})
    model += std::string("property float ") + n + "\n";
  const auto gm = put(dir, "model.ply", model + "end_header\n");
  expect_fast_io_error(gm, "declares 4000000000 entries", [&] { (void)io::read_ply<Gaussian<3, 3>>(gm); });
  // inspect_ply reads the header only and reports the count as it is.
  CHECK(io::inspect_ply(gm).vertices == 4000000000u);
}

TEST_CASE("PLY (fuzz_ply out-of-memory): data on the end_header line, no newline after it") {
  const auto dir = scratch("ply_end_header");
  // As found: 315,460,194 vertices of 11 bytes declared (with leading zeros), and the data on the
  // end_header line itself. getline read that line to the end of the file, the stream could then
  // not tell its position, the size check was skipped and gigabytes of columns were allocated.
  const std::string head = "ply\nformat binary_little_endian 1.0\ncomment written by msgs\nelement vertex " +
                           std::string(72, '0') +
                           "315460194\nproperty float x\nproperty int16 y\nproperty float z\nproperty uchar red\n";
  const std::string data = bytes({0x00, 0x00, 0x00, 0x00, 0x1a, 0x33, 0x4d, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00,
                                  0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00});
  const auto found = put(dir, "found.ply", head + "end_header\t" + data);
  expect_fast_io_error(found, "'end_header' must stand alone", [&] { (void)io::read_point_cloud(found); });
  expect_fast_io_error(found, "'end_header' must stand alone", [&] { (void)io::inspect_ply(found); });
  // The file ends on the end_header line: no data at all, whatever the header declares.
  const auto bare = put(dir, "bare.ply", head + "end_header");
  expect_fast_io_error(bare, "declares 315460194 entries", [&] { (void)io::read_point_cloud(bare); });
  // Trailing blanks and a CR on that line are still a plain end of header.
  const auto crlf = put(dir, "crlf.ply",
                        "ply\r\nformat binary_little_endian 1.0\r\nelement vertex 1\r\nproperty float x\r\n"
                        "property float y\r\nproperty float z\r\nend_header \t\r\n" + std::string(12, '\0'));
  CHECK(io::read_point_cloud(crlf).size() == 1);
}

TEST_CASE("PLY: list lengths that are NaN, fractional or 1e30 are refused before the size_t cast") {
  const auto dir = scratch("ply_list");
  const std::string head =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list float int idx\nend_header\n";
  const std::string xyz(12, '\0');
  // float32 little-endian list counts: 1e30, NaN, 2.5.
  const std::array<std::string, 3> counts = {bytes({0xca, 0xf2, 0x49, 0x71}), bytes({0x00, 0x00, 0xc0, 0x7f}),
                                             bytes({0x00, 0x00, 0x20, 0x40})};
  for (std::size_t i = 0; i < counts.size(); ++i) {
    const auto p = put(dir, "list" + std::to_string(i) + ".ply", head + xyz + counts[i] + std::string(16, '\0'));
    expect_fast_io_error(p, "bad list length", [&] { (void)io::read_point_cloud(p); });
  }
  // ASCII: a list claiming 1e300 entries.
  const auto asc = put(dir, "ascii.ply",
                       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 1\nproperty list uchar int idx\nend_header\n0 0 0\n1e300 1 2\n");
  expect_fast_io_error(asc, "bad list length", [&] { (void)io::read_point_cloud(asc); });
}

TEST_CASE("PLY: valid files still read after the size checks (no trailing newline, lists)") {
  const auto dir = scratch("ply_ok");
  const auto p = put(dir, "ok.ply",
                     "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 1\nproperty list uchar int idx\nend_header\n1 2 3\n4 5 6\n2 0 1");
  const auto pc = io::read_point_cloud(p);
  REQUIRE(pc.size() == 2);
  CHECK(pc.xyz[5] == 6.0f);
}

TEST_CASE("BMP (fuzz_image timeout): 54 bytes claiming 1024 x 66M pixels") {
  // libFuzzer artifact: stb accepts the header and pads the missing data, so the reader used to
  // allocate and convert ~200 M floats.
  const std::string bmp = bytes({0x42, 0x4d, 0x4e, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x36, 0x00, 0x00, 0x00,
                                 0x28, 0x00, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x01, 0xfc, 0x00, 0x00, 0x01, 0x00,
                                 0x18, 0x00, 0x00, 0x00, 0x00, 0x00, 0xff, 0xff, 0x5f, 0x40, 0x00, 0x05, 0x34, 0x27,
                                 0x2c, 0x20, 0x27, 0x72, 0x74, 0x72, 0x61, 0x6e, 0x23, 0x1c, 0x15, 0x39});
  const auto dir = scratch("bmp");
  const auto p = put(dir, "huge.bmp", bmp);
  expect_fast_io_error(p, "header claims", [&] { (void)io::read_image(p); });
}

TEST_CASE("PNG: an IHDR claiming 1e6 x 1e6 RGBA pixels fails before the row buffers") {
  std::string ihdr;
  put_be32(ihdr, 1000000);
  put_be32(ihdr, 1000000);
  ihdr += bytes({8, 6, 0, 0, 0});  // 8-bit RGBA, deflate, no filter method, not interlaced
  const std::string png = bytes({0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}) + png_chunk("IHDR", ihdr) +
                          png_chunk("IDAT", bytes({0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01})) +
                          png_chunk("IEND", "");
  const auto dir = scratch("png");
  const auto p = put(dir, "huge.png", png);
  expect_fast_io_error(p, "header claims 1000000x1000000", [&] { (void)io::read_image(p); });
}

TEST_CASE("TIFF: a header claiming 100000 x 100000 16-bit pixels fails before allocating") {
  // Little-endian TIFF, one IFD of 8 entries, one 2-byte strip.
  std::string t = bytes({'I', 'I', 42, 0, 8, 0, 0, 0});
  auto le16 = [&](unsigned v) { t += bytes({v & 0xff, (v >> 8) & 0xff}); };
  auto le32 = [&](unsigned v) { t += bytes({v & 0xff, (v >> 8) & 0xff, (v >> 16) & 0xff, (v >> 24) & 0xff}); };
  auto entry = [&](unsigned tag, unsigned type, unsigned value) {
    le16(tag);
    le16(type);
    le32(1);
    if (type == 3) { le16(value); le16(0); } else { le32(value); }
  };
  const unsigned n_entries = 8, data_offset = 8 + 2 + 12 * n_entries + 4;
  le16(n_entries);
  entry(256, 4, 100000);       // ImageWidth
  entry(257, 4, 100000);       // ImageLength
  entry(258, 3, 16);           // BitsPerSample
  entry(259, 3, 1);            // Compression: none
  entry(262, 3, 1);            // Photometric: min-is-black
  entry(273, 4, data_offset);  // StripOffsets
  entry(278, 4, 100000);       // RowsPerStrip
  entry(279, 4, 2);            // StripByteCounts
  le32(0);                     // no next IFD
  t += bytes({0, 0});
  const auto dir = scratch("tiff");
  const auto p = put(dir, "huge.tif", t);
  expect_fast_io_error(p, "header claims 100000x100000", [&] { (void)io::read_image(p); });
}

TEST_CASE("TIFF (fuzz_image out-of-memory): 196 bytes with tiles of 7.4 GB") {
  // A small tiled image whose tile tags claim a tile of 7,369,621,504 bytes: the reader allocated
  // the tile buffer before reading a byte of it.
  const std::string t = bytes({
      0x49, 0x49, 0x2a, 0x00, 0x38, 0x00, 0x00, 0x00, 0x82, 0x9c, 0x63, 0x60, 0x60, 0x10, 0x60, 0x50, 0x60, 0x30,
      0x60, 0x70, 0x60, 0x08, 0x60, 0x48, 0x60, 0x28, 0x60, 0xca, 0xf8, 0xdf, 0xff, 0x7f, 0xfe, 0x01, 0x0a, 0x00,
      0x0d, 0xff, 0x3f, 0xff, 0xff, 0xfe, 0xff, 0xf7, 0xff, 0xfd, 0x33, 0xa0, 0xa8, 0x00, 0x00, 0x91, 0x07, 0x11,
      0xc1, 0x00, 0x0b, 0x00, 0x00, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x00, 0x00, 0x00, 0x01, 0x01,
      0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x46, 0x00, 0x00, 0x00, 0x02, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00,
      0x10, 0x00, 0x00, 0x00, 0x03, 0x00, 0x00, 0x00, 0x0f, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, 0x16, 0x01,
      0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0xe0, 0xff, 0x01, 0x11, 0x01, 0x04, 0x00, 0x01, 0x00, 0x00, 0x00,
      0x01, 0x00, 0x00, 0x00, 0x16, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0xaa, 0x02, 0x00, 0x00, 0x17, 0x01,
      0x04, 0x00, 0x01, 0x00, 0x2f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x16, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00,
      0x02, 0x00, 0x00, 0xfd, 0x42, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x02, 0xfb, 0xff, 0xff, 0xbc, 0xfe,
      0xfc, 0xff, 0xfe, 0x00, 0x00, 0x00, 0x12, 0x00, 0x00, 0x5d, 0x33, 0x27, 0x00, 0x00, 0x00, 0x00});
  REQUIRE(t.size() == 196);
  const auto dir = scratch("tiff_tile");
  const auto p = put(dir, "huge_tile.tif", t);
  expect_fast_io_error(p, "TIFF tile header claims", [&] { (void)io::read_image(p); });
}

TEST_CASE("npy: a shape of 1e5 x 1e5 x 3 with no data fails before allocating") {
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (100000, 100000, 3), }";
  header.append(64 - (10 + header.size() + 1) % 64, ' ');
  header.push_back('\n');
  const std::string npy = std::string("\x93NUMPY\x01\x00", 8) +
                          bytes({unsigned(header.size() & 0xff), unsigned(header.size() >> 8)}) + header;
  const auto dir = scratch("npy");
  const auto p = put(dir, "huge.npy", npy);
  expect_fast_io_error(p, "does not match the shape", [&] { (void)io::read_npy(p); });
  // A shape whose element count wraps around 2^64 must not match a small data size either.
  std::string wrap = "{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 1), }";
  wrap.append(64 - (10 + wrap.size() + 1) % 64, ' ');
  wrap.push_back('\n');
  const auto q = put(dir, "wrap.npy", std::string("\x93NUMPY\x01\x00", 8) +
                                          bytes({unsigned(wrap.size() & 0xff), unsigned(wrap.size() >> 8)}) + wrap);
  expect_fast_io_error(q, "does not match the shape", [&] { (void)io::read_npy(q); });
}

}  // namespace test_regressions
