// tests/test_image_io.cpp
// Tests for include/msgs/io/image_io.hpp: PNG 8/16-bit, TIFF (8/16-bit, float, tiled, compressed, planes),
// .npy round trips, bad files, downscale.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <random>

#include <stb/stb_image_write.h>

#include "msgs/io/image_io.hpp"
#include "scratch.hpp"

namespace test_image_io {
namespace fs = std::filesystem;
using msgs::Image;
using namespace msgs::io;

namespace {

fs::path scratch(const std::string& sub) { return msgs::testing::fresh_scratch_dir("test_image_io/" + sub); }

Image<float> random_image(int w, int h, int c, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Image<float> img(w, h, c);
  for (auto& v : img.data) v = u(rng);
  return img;
}

void truncate_file(const fs::path& p, double keep) {
  const auto size = fs::file_size(p);
  fs::resize_file(p, static_cast<std::uintmax_t>(double(size) * keep));
}

bool only_file_in(const fs::path& dir) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir)) { (void)e; ++n; }
  return n == 1;
}

}  // namespace

TEST_CASE("8-bit PNG round trip quantises to 1/255 for 1, 3 and 4 channels") {
  const auto dir = scratch("png8");
  for (int c : {1, 3, 4}) {
    const auto img = random_image(13, 7, c, 10u + unsigned(c));
    const auto p = dir / cat("a", c, ".png");
    write_png8(p, img);
    const auto back = read_image(p);
    REQUIRE(back.width == 13);
    REQUIRE(back.height == 7);
    REQUIRE(back.channels == c);
    for (std::size_t i = 0; i < img.size(); ++i)
      CHECK(back.data[i] == doctest::Approx(std::round(double(img.data[i]) * 255.0) / 255.0).epsilon(1e-6));
  }
}

TEST_CASE("16-bit PNG keeps 16 bits") {
  const auto dir = scratch("png16");
  const auto img = random_image(9, 11, 1, 3);
  const auto p = dir / "a.png";
  write_png16(p, img);
  const auto back = read_image(p);
  REQUIRE(back.channels == 1);
  double max_err = 0;
  for (std::size_t i = 0; i < img.size(); ++i) max_err = std::max(max_err, double(std::abs(back.data[i] - img.data[i])));
  CHECK(max_err <= 0.5 / 65535.0 + 1e-7);
  CHECK(max_err > 0);  // it is quantised, not bit-exact floats
}

TEST_CASE("16-bit TIFF round trip, 1 and 3 channels") {
  const auto dir = scratch("tiff16");
  for (int c : {1, 3, 4}) {
    const auto img = random_image(17, 5, c, 7u + unsigned(c));
    const auto p = dir / cat("a", c, ".tif");
    write_tiff16(p, img);
    const auto back = read_image(p);
    REQUIRE(back.width == 17);
    REQUIRE(back.height == 5);
    REQUIRE(back.channels == c);
    for (std::size_t i = 0; i < img.size(); ++i)
      CHECK(back.data[i] == doctest::Approx(std::round(double(img.data[i]) * 65535.0) / 65535.0).epsilon(1e-7));
  }
}

/// Opens `p` for writing with libtiff itself, with these tags set (nullptr if it cannot be).
static TIFF* open_tiff(const fs::path& p, unsigned w, unsigned h, int bits, int samples, int format, int planar,
                       int compression, int photometric) {
  TIFF* tif = TIFFOpen(p.c_str(), "w");
  if (!tif) return nullptr;
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, w);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, h);
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, bits);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, samples);
  TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, format);
  TIFFSetField(tif, TIFFTAG_PLANARCONFIG, planar);
  TIFFSetField(tif, TIFFTAG_COMPRESSION, compression);
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, photometric);
  return tif;
}

/// A 4x2 8-bit contiguous uncompressed TIFF.
static TIFF* open_tiff_8bit(const fs::path& p, int samples, int photometric) {
  return open_tiff(p, 4, 2, 8, samples, SAMPLEFORMAT_UINT, PLANARCONFIG_CONTIG, COMPRESSION_NONE, photometric);
}

TEST_CASE("8-bit TIFF written with libtiff directly reads as value / 255") {
  const auto dir = scratch("tiff8");
  const auto p = dir / "a.tif";
  TIFF* tif = open_tiff_8bit(p, 1, PHOTOMETRIC_MINISBLACK);
  REQUIRE(tif);
  unsigned char rows[2][4] = {{0, 51, 102, 255}, {1, 2, 3, 4}};
  for (unsigned y = 0; y < 2; ++y) REQUIRE(TIFFWriteScanline(tif, rows[y], y, 0) >= 0);
  TIFFClose(tif);
  const auto img = read_image(p);
  REQUIRE(img.channels == 1);
  CHECK(img.at(1, 0, 0) == doctest::Approx(0.2f));
  CHECK(img.at(3, 0, 0) == doctest::Approx(1.0f));
  CHECK(img.at(3, 1, 0) == doctest::Approx(4.0f / 255.0f));
}

/// The value of sample c of pixel (x, y) in the layout tests below: distinct everywhere.
static unsigned tiff_test_value(unsigned x, unsigned y, unsigned c) { return (x * 7u + y * 13u + c * 61u) % 251u; }

// Reflectance maps from photogrammetry tools and GeoTIFF exports come tiled, compressed, in
// 32-bit float or with separate planes; cameras write 16-bit strips. Every layout the reader
// accepts is read back value for value.
TEST_CASE("TIFF layouts: tiled, compressed, float, separate planes and min-is-white read exactly") {
  const auto dir = scratch("tiff_layouts");
  SUBCASE("tiled 8-bit RGB, deflate, edge tiles cut by the image") {
    const unsigned w = 21, h = 18, tw = 16, th = 16;
    const auto p = dir / "tiled.tif";
    TIFF* tif = open_tiff(p, w, h, 8, 3, SAMPLEFORMAT_UINT, PLANARCONFIG_CONTIG, COMPRESSION_ADOBE_DEFLATE, PHOTOMETRIC_RGB);
    REQUIRE(tif);
    TIFFSetField(tif, TIFFTAG_TILEWIDTH, tw);
    TIFFSetField(tif, TIFFTAG_TILELENGTH, th);
    std::vector<unsigned char> tile(tw * th * 3);
    for (unsigned ty = 0; ty < h; ty += th)
      for (unsigned tx = 0; tx < w; tx += tw) {
        for (unsigned y = 0; y < th; ++y)
          for (unsigned x = 0; x < tw; ++x)
            for (unsigned c = 0; c < 3; ++c)
              tile[(y * tw + x) * 3 + c] = static_cast<unsigned char>(tiff_test_value(tx + x, ty + y, c));
        REQUIRE(TIFFWriteTile(tif, tile.data(), tx, ty, 0, 0) >= 0);
      }
    TIFFClose(tif);
    const auto img = read_image(p);
    REQUIRE(img.width == int(w));
    REQUIRE(img.height == int(h));
    REQUIRE(img.channels == 3);
    for (unsigned y = 0; y < h; ++y)
      for (unsigned x = 0; x < w; ++x)
        for (unsigned c = 0; c < 3; ++c) REQUIRE(img.at(int(x), int(y), int(c)) == float(tiff_test_value(x, y, c)) * (1.0f / 255.0f));
  }
  SUBCASE("32-bit float, LZW strips of 3 rows: values as stored, negatives included") {
    const unsigned w = 7, h = 5;
    const auto p = dir / "float.tif";
    TIFF* tif = open_tiff(p, w, h, 32, 1, SAMPLEFORMAT_IEEEFP, PLANARCONFIG_CONTIG, COMPRESSION_LZW, PHOTOMETRIC_MINISBLACK);
    REQUIRE(tif);
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, 3u);
    std::vector<float> row(w);
    for (unsigned y = 0; y < h; ++y) {
      for (unsigned x = 0; x < w; ++x) row[x] = float(tiff_test_value(x, y, 0)) / 100.0f - 0.5f;
      REQUIRE(TIFFWriteScanline(tif, row.data(), y, 0) >= 0);
    }
    TIFFClose(tif);
    const auto img = read_image(p);
    REQUIRE(img.channels == 1);
    for (unsigned y = 0; y < h; ++y)
      for (unsigned x = 0; x < w; ++x) REQUIRE(img.at(int(x), int(y), 0) == float(tiff_test_value(x, y, 0)) / 100.0f - 0.5f);
  }
  SUBCASE("32-bit float with a NaN (a masked pixel) or an infinity: an error naming the pixel") {
    const unsigned w = 5, h = 3;
    for (const float bad : {std::nanf(""), -std::numeric_limits<float>::infinity()}) {
      const auto p = dir / "masked.tif";
      TIFF* tif = open_tiff(p, w, h, 32, 1, SAMPLEFORMAT_IEEEFP, PLANARCONFIG_CONTIG, COMPRESSION_NONE, PHOTOMETRIC_MINISBLACK);
      REQUIRE(tif);
      std::vector<float> row(w, 0.25f);
      for (unsigned y = 0; y < h; ++y) {
        row[3] = y == 1 ? bad : 0.25f;
        REQUIRE(TIFFWriteScanline(tif, row.data(), y, 0) >= 0);
      }
      TIFFClose(tif);
      std::string msg;
      try {
        (void)read_image(p);
      } catch (const msgs::io::IoError& e) {
        msg = e.what();
      }
      INFO(msg);
      CHECK(msg.find(p.string()) != std::string::npos);
      CHECK(msg.find("(3, 1) is NaN or infinite") != std::string::npos);
      CHECK(msg.find("fill masked or no-data pixels") != std::string::npos);
    }
  }
  SUBCASE("16-bit, four separate planes") {
    const unsigned w = 6, h = 4;
    const auto p = dir / "planes.tif";
    TIFF* tif = open_tiff(p, w, h, 16, 4, SAMPLEFORMAT_UINT, PLANARCONFIG_SEPARATE, COMPRESSION_NONE, PHOTOMETRIC_MINISBLACK);
    REQUIRE(tif);
    const std::uint16_t extra = EXTRASAMPLE_UNSPECIFIED;
    const std::uint16_t extras[3] = {extra, extra, extra};
    TIFFSetField(tif, TIFFTAG_EXTRASAMPLES, 3, extras);
    std::vector<std::uint16_t> row(w);
    for (unsigned c = 0; c < 4; ++c)
      for (unsigned y = 0; y < h; ++y) {
        for (unsigned x = 0; x < w; ++x) row[x] = static_cast<std::uint16_t>(tiff_test_value(x, y, c) * 257u);
        REQUIRE(TIFFWriteScanline(tif, row.data(), y, static_cast<std::uint16_t>(c)) >= 0);
      }
    TIFFClose(tif);
    const auto img = read_image(p);
    REQUIRE(img.channels == 4);
    for (unsigned y = 0; y < h; ++y)
      for (unsigned x = 0; x < w; ++x)
        for (unsigned c = 0; c < 4; ++c)
          REQUIRE(img.at(int(x), int(y), int(c)) == float(tiff_test_value(x, y, c) * 257u) * (1.0f / 65535.0f));
  }
  SUBCASE("8-bit min-is-white reads as 1 - value / 255") {
    const unsigned w = 4, h = 2;
    const auto p = dir / "white.tif";
    TIFF* tif = open_tiff(p, w, h, 8, 1, SAMPLEFORMAT_UINT, PLANARCONFIG_CONTIG, COMPRESSION_NONE, PHOTOMETRIC_MINISWHITE);
    REQUIRE(tif);
    std::vector<unsigned char> row(w);
    for (unsigned y = 0; y < h; ++y) {
      for (unsigned x = 0; x < w; ++x) row[x] = static_cast<unsigned char>(tiff_test_value(x, y, 0));
      REQUIRE(TIFFWriteScanline(tif, row.data(), y, 0) >= 0);
    }
    TIFFClose(tif);
    const auto img = read_image(p);
    for (unsigned y = 0; y < h; ++y)
      for (unsigned x = 0; x < w; ++x)
        REQUIRE(img.at(int(x), int(y), 0) == 1.0f - float(tiff_test_value(x, y, 0)) * (1.0f / 255.0f));
  }
}

TEST_CASE("a YCbCr TIFF is refused with a clear error, not read past its rows") {
  // Found by fuzz_image: 16-bit YCbCr with the default 2x2 chroma subsampling, whose rows are
  // shorter than width x samples.
  const auto dir = scratch("tiff_ycbcr");
  const auto p = dir / "a.tif";
  TIFF* tif = open_tiff_8bit(p, 3, PHOTOMETRIC_YCBCR);
  REQUIRE(tif);
  std::vector<unsigned char> row(64, 128);
  for (unsigned y = 0; y < 2; ++y) TIFFWriteScanline(tif, row.data(), y, 0);
  TIFFClose(tif);
  try {
    (void)read_image(p);
    FAIL("a YCbCr TIFF was read");
  } catch (const std::exception& e) {
    const std::string what = e.what();
    CHECK(what.find("a.tif") != std::string::npos);
    CHECK(what.find("YCbCr") != std::string::npos);
  }
}

TEST_CASE("npy round trip is exact and has the NumPy header") {
  const auto dir = scratch("npy");
  auto img = random_image(5, 3, 2, 1);
  img.data[0] = -3.5f;  // npy stores values as they are
  const auto p = dir / "a.npy";
  write_npy(p, img);
  const auto bytes = read_bytes(p);
  const std::string head(bytes.begin(), bytes.begin() + 128);
  CHECK(head.find("'shape': (3, 5, 2)") != std::string::npos);
  const std::size_t hlen = std::size_t(bytes[8]) | (std::size_t(bytes[9]) << 8);
  CHECK((10 + hlen) % 64 == 0);
  CHECK(bytes.size() == 10 + hlen + img.size() * 4);
  const auto back = read_npy(p);
  CHECK(back.width == 5);
  CHECK(back.height == 3);
  CHECK(back.data == img.data);
}

TEST_CASE("writers replace the target atomically and leave no temporary behind") {
  const auto dir = scratch("atomic");
  const auto p = dir / "a.png";
  write_png8(p, random_image(4, 4, 3, 2));
  write_png8(p, random_image(6, 6, 3, 3));
  CHECK(read_image(p).width == 6);
  CHECK(only_file_in(dir));
  // A failing write leaves the old file untouched.
  Image<float> bad(2, 2, 1);
  bad.data[1] = std::nanf("");
  CHECK_THROWS_AS(write_png8(p, bad), IoError);
  CHECK(read_image(p).width == 6);
  CHECK(only_file_in(dir));
  CHECK_THROWS_AS(write_png8(dir / "missing_dir" / "x.png", bad), IoError);
}

TEST_CASE("writers clamp to [0, 1]") {
  const auto dir = scratch("clamp");
  Image<float> img(2, 1, 1);
  img.data = {-0.5f, 7.0f};
  write_png8(dir / "a.png", img);
  const auto back = read_image(dir / "a.png");
  CHECK(back.data[0] == 0.0f);
  CHECK(back.data[1] == 1.0f);
}

TEST_CASE("bad image files are refused with the file name in the message") {
  const auto dir = scratch("bad");
  auto expect_error = [](const fs::path& p, const std::string& needle) {
    try {
      (void)read_image(p);
      FAIL("no exception for " << p);
    } catch (const IoError& e) {
      const std::string msg = e.what();
      CHECK(msg.find(p.filename().string()) != std::string::npos);
      CHECK_MESSAGE(msg.find(needle) != std::string::npos, msg);
    }
  };
  expect_error(dir / "missing.png", "does not exist");

  write_png16(dir / "t.png", random_image(64, 64, 3, 5));
  truncate_file(dir / "t.png", 0.5);
  expect_error(dir / "t.png", "truncated");

  write_tiff16(dir / "t.tif", random_image(64, 64, 1, 5));
  truncate_file(dir / "t.tif", 0.3);
  expect_error(dir / "t.tif", "t.tif");

  {
    std::ofstream f(dir / "junk.jpg", std::ios::binary);
    f << "this is not an image at all";
  }
  expect_error(dir / "junk.jpg", "cannot decode");

  // 32-bit unsigned TIFF: unsupported bit depth.
  TIFF* tif = TIFFOpen((dir / "u32.tif").c_str(), "w");
  REQUIRE(tif);
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, 2u);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, 1u);
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 32);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
  std::uint32_t row[2] = {1, 2};
  REQUIRE(TIFFWriteScanline(tif, row, 0, 0) >= 0);
  TIFFClose(tif);
  expect_error(dir / "u32.tif", "32-bit");
}

TEST_CASE("downscale: box filter with ceil size") {
  Image<float> img(5, 3, 1);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x) img.at(x, y, 0) = float(y * 5 + x);
  const auto d = downscale(img, 2);
  REQUIRE(d.width == 3);
  REQUIRE(d.height == 2);
  CHECK(d.at(0, 0, 0) == doctest::Approx((0 + 1 + 5 + 6) / 4.0));
  CHECK(d.at(2, 0, 0) == doctest::Approx((4 + 9) / 2.0));
  CHECK(d.at(1, 1, 0) == doctest::Approx((12 + 13) / 2.0));
  CHECK(d.at(2, 1, 0) == doctest::Approx(14.0));
  CHECK(downscale(img, 1).data == img.data);
}

TEST_CASE("8-bit JPEG via stb: values / 255, truncation detected") {
  const auto dir = scratch("jpeg");
  const int w = 32, h = 24;
  std::vector<unsigned char> px(static_cast<std::size_t>(w * h * 3));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) px[std::size_t((y * w + x) * 3 + c)] = static_cast<unsigned char>(40 + 60 * c + 2 * x);
  const auto p = dir / "a.jpg";
  REQUIRE(stbi_write_jpg(p.c_str(), w, h, 3, px.data(), 95) != 0);
  const auto img = read_image(p);
  REQUIRE(img.width == w);
  REQUIRE(img.channels == 3);
  double max_err = 0;
  for (std::size_t i = 0; i < img.size(); ++i) max_err = std::max(max_err, std::abs(img.data[i] * 255.0 - px[i]));
  CHECK(max_err < 12);  // lossy, but the same image
  truncate_file(p, 0.7);
  try {
    (void)read_image(p);
    FAIL("truncated JPEG accepted");
  } catch (const IoError& e) {
    CHECK(std::string(e.what()).find("truncated") != std::string::npos);
  }
}

TEST_CASE("16-bit PNG with 3 channels and 8-bit grey+alpha keep their channels") {
  const auto dir = scratch("channels");
  const auto rgb = random_image(3, 2, 3, 21);
  write_png16(dir / "rgb.png", rgb);
  CHECK(read_image(dir / "rgb.png").channels == 3);
  const auto ga = random_image(3, 2, 2, 22);
  write_png8(dir / "ga.png", ga);
  const auto back = read_image(dir / "ga.png");
  CHECK(back.channels == 2);
  CHECK(back.data[1] == doctest::Approx(std::round(double(ga.data[1]) * 255.0) / 255.0));
}

}  // namespace test_image_io
