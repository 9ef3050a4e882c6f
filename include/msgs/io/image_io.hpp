// include/msgs/io/image_io.hpp
// Reading and writing images as Image<float> in [0, 1]: 8-bit JPEG/PNG, 16-bit PNG, 8/16-bit TIFF,
// float32 .npy; box-filter downscaling for the images_2/4/8 resolutions.
#pragma once

#include <png.h>
#include <stb/stb_image.h>
#include <stb/stb_image_write.h>
#include <tiffio.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "msgs/image.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"

namespace msgs::io {

namespace detail {

inline std::string lower_extension(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  for (char& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return e;
}

/// Quantise a [0, 1] value to 0..maxv, clamping and rounding; NaN is an error rather than a silent 0.
inline std::uint32_t quantise(float v, std::uint32_t maxv, const std::filesystem::path& p, std::size_t index) {
  if (std::isnan(v)) fail(p, cat("pixel value ", std::to_string(index), " is NaN; refusing to write"));
  const float c = std::clamp(v, 0.0f, 1.0f);
  return static_cast<std::uint32_t>(std::lround(double(c) * double(maxv)));
}

inline void check_writable_image(const std::filesystem::path& p, const Image<float>& img) {
  if (img.width < 1 || img.height < 1) fail(p, "cannot write an empty image");
  if (img.channels < 1 || img.channels > 4)
    fail(p, cat("cannot write ", std::to_string(img.channels), " channels (need 1 to 4)"));
  if (img.data.size() != img.pixels() * static_cast<std::size_t>(img.channels))
    fail(p, "image buffer size does not match width x height x channels");
}

/// Refuse a header that claims far more pixel data than the file could hold, before anything is
/// allocated: `raw_bytes` (what the decoder would produce) may exceed the file size by at most
/// `max_ratio` (the codec's best compression), plus 16 MiB so that small flat images always pass.
/// Without this a 60-byte file claiming 1e6 x 1e6 pixels asks for terabytes. Doubles: no overflow.
inline void check_plausible_size(const std::filesystem::path& p, const char* format, std::uint64_t width,
                                 std::uint64_t height, int channels, double raw_bytes, std::size_t file_size,
                                 double max_ratio) {
  if (width < 1 || height < 1) fail(p, cat(format, " has an empty image"));
  if (width > 2147483647u || height > 2147483647u)
    fail(p, cat(format, " claims ", width, "x", height, " pixels (more than 2^31 - 1 in one dimension)"));
  if (raw_bytes > max_ratio * double(file_size) + 16.0 * 1024 * 1024)
    fail(p, cat(format, " header claims ", width, "x", height, "x", channels, " samples but the file has only ",
                file_size, " bytes (corrupt header?)"));
}

// ---- libpng plumbing. libpng reports errors by longjmp; the functions that call setjmp keep no
// non-trivial locals alive across it (C++ forbids skipping their destructors), so every buffer
// lives in the caller.

struct PngError {
  char msg[256] = "unknown libpng error";
};
struct PngMemReader {
  const unsigned char* data;
  std::size_t size;
  std::size_t pos;
};

inline void png_error_fn(png_structp png, png_const_charp msg) {
  auto* e = static_cast<PngError*>(png_get_error_ptr(png));
  std::snprintf(e->msg, sizeof e->msg, "%s", msg);
  png_longjmp(png, 1);
}
inline void png_warning_fn(png_structp, png_const_charp) {}
inline void png_read_mem(png_structp png, png_bytep out, png_size_t n) {
  auto* m = static_cast<PngMemReader*>(png_get_io_ptr(png));
  if (m->size - m->pos < n) png_error(png, "file is truncated");
  std::memcpy(out, m->data + m->pos, n);
  m->pos += n;
}

/// Decode a PNG held in memory. Returns false with `err.msg` set on failure. Samples come back
/// 8-bit, or 16-bit big-endian when `depth` is 16; palettes and low bit depths are expanded.
inline bool png_decode(const unsigned char* data, std::size_t size, std::vector<unsigned char>& pixels,
                       std::vector<png_bytep>& rows, png_uint_32& w, png_uint_32& h, int& channels, int& depth,
                       PngError& err) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &err, png_error_fn, png_warning_fn);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    return false;
  }
  PngMemReader mem{data, size, 0};
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_set_read_fn(png, &mem, png_read_mem);
  png_read_info(png, info);
  // Deflate expands at most 1032:1; each stored row has a filter byte. Checked here, before the
  // buffers are sized, since libpng's own limit (1e6 x 1e6 pixels) allows terabytes.
  if (double(png_get_image_height(png, info)) * (double(png_get_rowbytes(png, info)) + 2.0) >
      1032.0 * double(size) + 16.0 * 1024 * 1024) {
    std::snprintf(err.msg, sizeof err.msg, "header claims %lux%lu pixels but the file has only %zu bytes",
                  static_cast<unsigned long>(png_get_image_width(png, info)),
                  static_cast<unsigned long>(png_get_image_height(png, info)), size);
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  const int color_type = png_get_color_type(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color_type == PNG_COLOR_TYPE_GRAY && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png);
  png_read_update_info(png, info);
  w = png_get_image_width(png, info);
  h = png_get_image_height(png, info);
  channels = png_get_channels(png, info);
  depth = png_get_bit_depth(png, info);
  const std::size_t rowbytes = png_get_rowbytes(png, info);
  pixels.resize(rowbytes * h);
  rows.resize(h);
  for (png_uint_32 y = 0; y < h; ++y) rows[y] = pixels.data() + y * rowbytes;
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

/// Encode rows (8-bit, or 16-bit big-endian) as a PNG into an open FILE. Returns false on error.
inline bool png_encode(std::FILE* f, std::vector<png_bytep>& rows, png_uint_32 w, png_uint_32 h, int channels,
                       int depth, PngError& err) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &err, png_error_fn, png_warning_fn);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_init_io(png, f);
  const int color_type = channels == 1   ? PNG_COLOR_TYPE_GRAY
                         : channels == 2 ? PNG_COLOR_TYPE_GRAY_ALPHA
                         : channels == 3 ? PNG_COLOR_TYPE_RGB
                                         : PNG_COLOR_TYPE_RGBA;
  png_set_IHDR(png, info, w, h, depth, color_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

inline Image<float> read_png(const std::filesystem::path& p, const std::vector<unsigned char>& bytes) {
  std::vector<unsigned char> pixels;
  std::vector<png_bytep> rows;
  png_uint_32 w = 0, h = 0;
  int channels = 0, depth = 0;
  PngError err;
  if (!png_decode(bytes.data(), bytes.size(), pixels, rows, w, h, channels, depth, err))
    fail(p, cat("cannot decode PNG: ", err.msg));
  if (depth != 8 && depth != 16) fail(p, cat("unsupported PNG bit depth ", std::to_string(depth)));
  Image<float> img(static_cast<int>(w), static_cast<int>(h), channels);
  const std::size_t n = img.size();
  if (depth == 8) {
    for (std::size_t i = 0; i < n; ++i) img.data[i] = float(pixels[i]) / 255.0f;
  } else {
    for (std::size_t i = 0; i < n; ++i)
      img.data[i] = float((unsigned(pixels[2 * i]) << 8) | unsigned(pixels[2 * i + 1])) / 65535.0f;
  }
  return img;
}

inline void write_png(const std::filesystem::path& p, const Image<float>& img, int depth) {
  check_writable_image(p, img);
  const std::uint32_t maxv = depth == 16 ? 65535u : 255u;
  const std::size_t bps = depth == 16 ? 2 : 1;
  const std::size_t rowbytes = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.channels) * bps;
  std::vector<unsigned char> pixels(rowbytes * static_cast<std::size_t>(img.height));
  for (std::size_t i = 0; i < img.size(); ++i) {
    const std::uint32_t q = quantise(img.data[i], maxv, p, i);
    if (depth == 16) {
      pixels[2 * i] = static_cast<unsigned char>(q >> 8);
      pixels[2 * i + 1] = static_cast<unsigned char>(q & 0xff);
    } else {
      pixels[i] = static_cast<unsigned char>(q);
    }
  }
  std::vector<png_bytep> rows(static_cast<std::size_t>(img.height));
  for (std::size_t y = 0; y < rows.size(); ++y) rows[y] = pixels.data() + y * rowbytes;
  AtomicFile out(p);
  std::FILE* f = std::fopen(out.temp().c_str(), "wb");
  if (!f) fail(p, "cannot open for writing (directory missing or not writable?)");
  PngError err;
  const bool ok = png_encode(f, rows, static_cast<png_uint_32>(img.width), static_cast<png_uint_32>(img.height),
                             img.channels, depth, err);
  const bool closed = std::fclose(f) == 0;
  if (!ok) fail(p, cat("cannot encode PNG: ", err.msg));
  if (!closed) fail(p, "write error (disk full?)");
  out.commit();
}

// ---- libtiff plumbing: errors are captured per file through TIFFOpenOptions (libtiff >= 4.5),
// so nothing global is touched.

struct TiffError {
  char msg[512] = "";
};
inline int tiff_error_handler(TIFF*, void* user, const char* module, const char* fmt, va_list ap) {
  auto* e = static_cast<TiffError*>(user);
  char buf[400];
  std::vsnprintf(buf, sizeof buf, fmt, ap);
  if (e->msg[0] == '\0') std::snprintf(e->msg, sizeof e->msg, "%s%s%s", module ? module : "", module ? ": " : "", buf);
  return 1;
}
inline int tiff_warning_handler(TIFF*, void*, const char*, const char*, va_list) { return 1; }

/// Owns a TIFF handle and its captured error text.
class TiffFile {
 public:
  TiffFile(const std::filesystem::path& p, const char* mode) : path_(p) {
    TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetErrorHandlerExtR(opts, tiff_error_handler, &err_);
    TIFFOpenOptionsSetWarningHandlerExtR(opts, tiff_warning_handler, nullptr);
    tif_ = TIFFOpenExt(p.c_str(), mode, opts);
    TIFFOpenOptionsFree(opts);
  }
  TiffFile(const TiffFile&) = delete;
  TiffFile& operator=(const TiffFile&) = delete;
  ~TiffFile() { close(); }
  TIFF* get() const { return tif_; }
  bool close() {
    if (!tif_) return true;
    TIFFClose(tif_);  // flushes pending writes; errors land in err_
    tif_ = nullptr;
    return err_.msg[0] == '\0';
  }
  std::string error() const { return err_.msg[0] ? std::string(err_.msg) : std::string("libtiff error"); }

 private:
  std::filesystem::path path_;
  TiffError err_;
  TIFF* tif_ = nullptr;
};

inline Image<float> read_tiff(const std::filesystem::path& p, std::size_t file_size) {
  TiffFile tf(p, "r");
  TIFF* tif = tf.get();
  if (!tif) fail(p, cat("cannot open TIFF: ", tf.error()));
  std::uint32_t w = 0, h = 0;
  std::uint16_t bits = 1, spp = 1, fmt = SAMPLEFORMAT_UINT, planar = PLANARCONFIG_CONTIG, photo = PHOTOMETRIC_MINISBLACK;
  if (!TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &w) || !TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &h))
    fail(p, "TIFF has no image size");
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &spp);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &fmt);
  TIFFGetFieldDefaulted(tif, TIFFTAG_PLANARCONFIG, &planar);
  TIFFGetField(tif, TIFFTAG_PHOTOMETRIC, &photo);
  const bool is_float = fmt == SAMPLEFORMAT_IEEEFP;
  if (!((fmt == SAMPLEFORMAT_UINT && (bits == 8 || bits == 16)) || (is_float && bits == 32)))
    fail(p, cat("unsupported TIFF sample format: ", bits, "-bit ",
                is_float ? "float" : fmt == SAMPLEFORMAT_INT ? "signed int" : "unsigned int",
                " (need 8/16-bit unsigned or 32-bit float)"));
  if (spp < 1 || spp > 4) fail(p, cat("unsupported TIFF samples per pixel ", std::to_string(spp), " (need 1 to 4)"));
  if (photo == PHOTOMETRIC_PALETTE) fail(p, "palette TIFF images are not supported");
  // YCbCr samples are not colours, and subsampled chroma makes a row shorter than width x samples.
  if (photo == PHOTOMETRIC_YCBCR) fail(p, "YCbCr TIFF images are not supported (save the image as RGB)");
  if (w == 0 || h == 0) fail(p, "TIFF has an empty image");
  // LZW, Deflate, ZSTD or LZMA strips may compress well, but not beyond ~4096:1.
  check_plausible_size(p, "TIFF", w, h, spp, double(w) * double(h) * double(spp) * double(bits / 8), file_size,
                       4096.0);
  if (TIFFIsTiled(tif) && planar != PLANARCONFIG_CONTIG) fail(p, "tiled TIFF with separate planes is not supported");

  Image<float> img(static_cast<int>(w), static_cast<int>(h), spp);
  const float scale = bits == 8 ? 1.0f / 255.0f : bits == 16 ? 1.0f / 65535.0f : 1.0f;
  auto sample = [&](const unsigned char* buf, std::size_t idx) -> float {
    if (bits == 8) return float(buf[idx]) * scale;
    if (bits == 16) {
      std::uint16_t v;
      std::memcpy(&v, buf + 2 * idx, 2);  // libtiff returns native byte order
      return float(v) * scale;
    }
    float v;
    std::memcpy(&v, buf + 4 * idx, 4);
    return v;
  };
  const bool invert = photo == PHOTOMETRIC_MINISWHITE;
  auto store = [&](std::uint32_t x, std::uint32_t y, int c, float v) {
    if (!std::isfinite(v))
      fail(p, cat("TIFF sample at (", std::to_string(x), ", ", std::to_string(y),
                  ") is NaN or infinite; msgs needs a finite value in every pixel (fill masked or no-data pixels, "
                  "e.g. with 0, before training)"));
    img.at(static_cast<int>(x), static_cast<int>(y), c) = invert && !is_float ? 1.0f - v : v;
  };

  if (TIFFIsTiled(tif)) {
    std::uint32_t tw = 0, th = 0;
    TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw);
    TIFFGetField(tif, TIFFTAG_TILELENGTH, &th);
    if (tw == 0 || th == 0) fail(p, "TIFF tile size is zero");
    const tmsize_t tile_bytes = TIFFTileSize(tif);
    if (tile_bytes <= 0 || double(tile_bytes) < double(tw) * double(th) * double(spp) * double(bits / 8))
      fail(p, cat("TIFF tiles hold fewer bytes than ", std::to_string(tw), "x", std::to_string(th), " pixels of ",
                  std::to_string(spp), " samples"));
    // The tile size comes from tags of its own: a tile far larger than the image (which the size
    // check above bounds) would be allocated before a byte of it is read. A tile is decoded from
    // the file, so the same compression bound applies to it.
    check_plausible_size(p, "TIFF tile", tw, th, spp, double(tile_bytes), file_size, 4096.0);
    std::vector<unsigned char> tile(static_cast<std::size_t>(tile_bytes));
    for (std::uint32_t ty = 0; ty < h; ty += th)
      for (std::uint32_t tx = 0; tx < w; tx += tw) {
        if (TIFFReadTile(tif, tile.data(), tx, ty, 0, 0) < 0)
          fail(p, cat("cannot read TIFF tile (truncated?): ", tf.error()));
        for (std::uint32_t y = ty; y < std::min(h, ty + th); ++y)
          for (std::uint32_t x = tx; x < std::min(w, tx + tw); ++x)
            for (int c = 0; c < spp; ++c)
              store(x, y, c, sample(tile.data(), (std::size_t(y - ty) * tw + (x - tx)) * spp + std::size_t(c)));
      }
    return img;
  }
  const int planes = planar == PLANARCONFIG_SEPARATE ? spp : 1;
  const tmsize_t line_bytes = TIFFScanlineSize(tif);
  if (line_bytes <= 0 || double(line_bytes) < double(w) * double(spp / planes) * double(bits / 8))
    fail(p, cat("TIFF rows hold fewer bytes than ", std::to_string(w), " pixels of ", std::to_string(spp / planes),
                " samples"));
  std::vector<unsigned char> line(static_cast<std::size_t>(line_bytes));
  for (int plane = 0; plane < planes; ++plane)
    for (std::uint32_t y = 0; y < h; ++y) {
      if (TIFFReadScanline(tif, line.data(), y, static_cast<std::uint16_t>(plane)) < 0)
        fail(p, cat("cannot read TIFF row ", std::to_string(y), " (truncated?): ", tf.error()));
      for (std::uint32_t x = 0; x < w; ++x) {
        if (planes == 1)
          for (int c = 0; c < spp; ++c) store(x, y, c, sample(line.data(), std::size_t(x) * spp + std::size_t(c)));
        else
          store(x, y, plane, sample(line.data(), x));
      }
    }
  return img;
}

/// stb's JPEG decoder pads a truncated stream with zeros instead of failing, so look for the
/// end-of-image marker after the last start-of-scan marker ourselves.
inline bool jpeg_looks_complete(const std::vector<unsigned char>& b) {
  std::size_t last_sos = 0;
  bool have_sos = false;
  for (std::size_t i = 0; i + 1 < b.size(); ++i)
    if (b[i] == 0xFF && b[i + 1] == 0xDA) { last_sos = i; have_sos = true; }
  if (!have_sos) return false;
  for (std::size_t i = b.size() - 1; i > last_sos; --i)
    if (b[i - 1] == 0xFF && b[i] == 0xD9) return true;
  return false;
}

inline Image<float> read_stb(const std::filesystem::path& p, const std::vector<unsigned char>& bytes) {
  if (bytes.size() > static_cast<std::size_t>(INT32_MAX)) fail(p, "file too large");
  const bool is_jpeg = bytes.size() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF;
  if (is_jpeg && !jpeg_looks_complete(bytes)) fail(p, "JPEG is truncated (no end-of-image marker)");
  int w = 0, h = 0, n = 0;
  // stb pads truncated BMP/TGA data instead of failing, so bound the claimed size first (JPEG,
  // RLE and LZW formats compress well below 1024:1 for real images).
  if (stbi_info_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &n))
    check_plausible_size(p, "image", std::uint64_t(std::max(w, 0)), std::uint64_t(std::max(h, 0)), n,
                         double(w) * double(h) * double(n), bytes.size(), 1024.0);
  unsigned char* px = stbi_load_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &n, 0);
  if (!px) {
    const char* why = stbi_failure_reason();
    fail(p, cat("cannot decode image: ", (why ? why : "unknown format")));
  }
  Image<float> img(w, h, n);
  for (std::size_t i = 0; i < img.size(); ++i) img.data[i] = float(px[i]) / 255.0f;
  stbi_image_free(px);
  return img;
}

}  // namespace detail

/// Read an image as floats in [0, 1]: 8-bit values / 255, 16-bit values / 65535, 32-bit float TIFF
/// as stored. PNG (8/16-bit, via libpng), TIFF (8/16-bit unsigned, 32-bit float, via libtiff) and
/// JPEG/BMP/TGA (8-bit, via stb). The format is sniffed from the content, not the extension.
/// Channels are kept as stored (1 grey, 2 grey+alpha, 3 RGB, 4 RGBA); palettes become RGB(A).
/// Throws IoError naming the file for a missing, truncated or unsupported file.
inline Image<float> read_image(const std::filesystem::path& p) {
  const std::vector<unsigned char> bytes = read_bytes(p);
  if (bytes.size() < 8) fail(p, cat("file is too short to be an image (", std::to_string(bytes.size()), " bytes)"));
  static constexpr unsigned char png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (std::memcmp(bytes.data(), png_sig, 8) == 0) return detail::read_png(p, bytes);
  const bool tiff = (bytes[0] == 'I' && bytes[1] == 'I' && (bytes[2] == 42 || bytes[2] == 43) && bytes[3] == 0) ||
                    (bytes[0] == 'M' && bytes[1] == 'M' && bytes[2] == 0 && (bytes[3] == 42 || bytes[3] == 43));
  if (tiff) return detail::read_tiff(p, bytes.size());
  return detail::read_stb(p, bytes);
}

/// Write an 8-bit PNG (1 to 4 channels): values clamped to [0, 1], scaled by 255 and rounded.
/// Atomic; NaN pixels are an error.
inline void write_png8(const std::filesystem::path& p, const Image<float>& img) { detail::write_png(p, img, 8); }

/// Write a 16-bit PNG (1 to 4 channels): values clamped to [0, 1], scaled by 65535 and rounded.
inline void write_png16(const std::filesystem::path& p, const Image<float>& img) { detail::write_png(p, img, 16); }

/// Write a 16-bit unsigned TIFF (1 to 4 channels, deflate-compressed when libtiff has zlib),
/// same quantisation as write_png16. Atomic.
inline void write_tiff16(const std::filesystem::path& p, const Image<float>& img) {
  detail::check_writable_image(p, img);
  const auto w = static_cast<std::uint32_t>(img.width), h = static_cast<std::uint32_t>(img.height);
  const auto spp = static_cast<std::uint16_t>(img.channels);
  std::vector<std::uint16_t> line(static_cast<std::size_t>(w) * spp);
  AtomicFile out(p);
  {
    detail::TiffFile tf(out.temp(), "w");
    TIFF* tif = tf.get();
    if (!tif) fail(p, cat("cannot open for writing: ", tf.error()));
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, w);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, h);
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, std::uint16_t(16));
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, spp);
    TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, std::uint16_t(SAMPLEFORMAT_UINT));
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, std::uint16_t(PLANARCONFIG_CONTIG));
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, std::uint16_t(spp >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK));
    if (spp == 2 || spp == 4) {
      std::uint16_t extra[1] = {EXTRASAMPLE_UNASSALPHA};
      TIFFSetField(tif, TIFFTAG_EXTRASAMPLES, std::uint16_t(1), extra);
    }
    if (TIFFIsCODECConfigured(COMPRESSION_ADOBE_DEFLATE))
      TIFFSetField(tif, TIFFTAG_COMPRESSION, std::uint16_t(COMPRESSION_ADOBE_DEFLATE));
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, TIFFDefaultStripSize(tif, 0));
    for (std::uint32_t y = 0; y < h; ++y) {
      const std::size_t base = std::size_t(y) * line.size();
      for (std::size_t i = 0; i < line.size(); ++i)
        line[i] = static_cast<std::uint16_t>(detail::quantise(img.data[base + i], 65535u, p, base + i));
      if (TIFFWriteScanline(tif, line.data(), y, 0) < 0) fail(p, cat("cannot write TIFF row: ", tf.error()));
    }
    if (!tf.close()) fail(p, cat("cannot finish TIFF: ", tf.error()));
  }
  out.commit();
}

/// Write a float32 little-endian NumPy .npy file of shape [H, W, C] (values as they are, no clamping).
inline void write_npy(const std::filesystem::path& p, const Image<float>& img) {
  if (img.data.size() != img.pixels() * static_cast<std::size_t>(img.channels))
    fail(p, "image buffer size does not match width x height x channels");
  std::string header = cat("{'descr': '<f4', 'fortran_order': False, 'shape': (", img.height, ", ", img.width, ", ",
                           img.channels, "), }");
  // Format 1.0: magic (6) + version (2) + header length (2) + header, padded with spaces so the data
  // starts on a 64-byte boundary, header ending in '\n'.
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  std::string bytes = "\x93NUMPY";
  bytes.push_back('\x01');
  bytes.push_back('\x00');
  bytes.push_back(static_cast<char>(header.size() & 0xff));
  bytes.push_back(static_cast<char>((header.size() >> 8) & 0xff));
  bytes += header;
  const std::size_t off = bytes.size();
  bytes.resize(off + img.data.size() * 4);
  for (std::size_t i = 0; i < img.data.size(); ++i) {
    std::uint32_t u;
    std::memcpy(&u, &img.data[i], 4);
    for (int b = 0; b < 4; ++b) bytes[off + 4 * i + std::size_t(b)] = static_cast<char>((u >> (8 * b)) & 0xff);
  }
  write_bytes_atomic(p, bytes.data(), bytes.size());
}

/// Read a float32 little-endian .npy of shape [H, W, C] or [H, W] (the files write_npy makes).
inline Image<float> read_npy(const std::filesystem::path& p) {
  const auto b = read_bytes(p);
  if (b.size() < 10 || std::memcmp(b.data(), "\x93NUMPY", 6) != 0) fail(p, "not a .npy file (bad magic)");
  if (b[6] != 1) fail(p, cat("unsupported .npy version ", std::to_string(int(b[6])), " (need 1)"));
  const std::size_t hlen = std::size_t(b[8]) | (std::size_t(b[9]) << 8);
  if (b.size() < 10 + hlen) fail(p, "file is truncated (header)");
  const std::string header(b.begin() + 10, b.begin() + 10 + static_cast<std::ptrdiff_t>(hlen));
  if (header.find("'descr': '<f4'") == std::string::npos) fail(p, "descr", "need '<f4' (float32 little-endian)");
  if (header.find("'fortran_order': False") == std::string::npos) fail(p, "fortran_order", "need False");
  const auto s0 = header.find("'shape': ("), s1 = header.find(')', s0);
  if (s0 == std::string::npos || s1 == std::string::npos) fail(p, "shape", "missing");
  std::vector<long> dims;
  for (std::size_t i = s0 + 10; i < s1;) {
    char* end = nullptr;
    const long v = std::strtol(header.c_str() + i, &end, 10);
    if (end == header.c_str() + i) break;
    dims.push_back(v);
    i = static_cast<std::size_t>(end - header.c_str());
    while (i < s1 && (header[i] == ',' || header[i] == ' ')) ++i;
  }
  if (dims.size() == 2) dims.push_back(1);
  if (dims.size() != 3 || dims[0] < 1 || dims[1] < 1 || dims[2] < 1) fail(p, "shape", "need (H, W, C) or (H, W)");
  // Compare with the data present before allocating (doubles: a shape like (1e18, 1e18) must not wrap).
  const std::size_t data_bytes = b.size() - 10 - hlen;
  if (double(dims[0]) * double(dims[1]) * double(dims[2]) * 4.0 != double(data_bytes) || dims[0] > INT32_MAX ||
      dims[1] > INT32_MAX || dims[2] > INT32_MAX)
    fail(p, cat("data size ", std::to_string(data_bytes), " bytes does not match the shape (truncated?)"));
  Image<float> img(static_cast<int>(dims[1]), static_cast<int>(dims[0]), static_cast<int>(dims[2]));
  const unsigned char* d = b.data() + 10 + hlen;
  for (std::size_t i = 0; i < img.size(); ++i) {
    const std::uint32_t u = std::uint32_t(d[4 * i]) | (std::uint32_t(d[4 * i + 1]) << 8) |
                            (std::uint32_t(d[4 * i + 2]) << 16) | (std::uint32_t(d[4 * i + 3]) << 24);
    std::memcpy(&img.data[i], &u, 4);
  }
  return img;
}

namespace detail {
inline void append_jpeg_bytes(void* ctx, void* data, int size) {
  auto* out = static_cast<std::vector<unsigned char>*>(ctx);
  out->insert(out->end(), static_cast<unsigned char*>(data), static_cast<unsigned char*>(data) + size);
}
}  // namespace detail

/// Write an 8-bit JPEG of a grey or RGB image at `quality` (1..100): values clamped to [0, 1].
/// Atomic; NaN pixels are an error.
inline void write_jpeg(const std::filesystem::path& p, const Image<float>& img, int quality = 95) {
  detail::check_writable_image(p, img);
  if (img.channels != 1 && img.channels != 3) fail(p, cat("a JPEG holds 1 or 3 channels, not ", img.channels));
  std::vector<unsigned char> px(img.data.size());
  for (std::size_t i = 0; i < px.size(); ++i) {
    if (std::isnan(img.data[i])) fail(p, cat("pixel value ", i, " is NaN"));
    px[i] = static_cast<unsigned char>(std::lround(std::clamp(img.data[i], 0.0f, 1.0f) * 255.0f));
  }
  std::vector<unsigned char> jpg;
  if (!stbi_write_jpg_to_func(detail::append_jpeg_bytes, &jpg, img.width, img.height, img.channels, px.data(),
                              std::clamp(quality, 1, 100)) ||
      jpg.empty())
    fail(p, "JPEG encoding failed");
  write_bytes_atomic(p, jpg.data(), jpg.size());
}

/// Write by extension: .png -> 8-bit PNG, .tif/.tiff -> 16-bit TIFF, .npy -> float32.
inline void write_image(const std::filesystem::path& p, const Image<float>& img) {
  const std::string e = detail::lower_extension(p);
  if (e == ".png") return write_png8(p, img);
  if (e == ".tif" || e == ".tiff") return write_tiff16(p, img);
  if (e == ".npy") return write_npy(p, img);
  fail(p, cat("unknown image extension '", e, "' (need .png, .tif, .tiff or .npy)"));
}

/// Shrink by an integer factor with a box filter. The output is ceil(W / f) x ceil(H / f), matching
/// Camera::downscaled; edge blocks average only the pixels that exist. factor <= 1 returns a copy.
inline Image<float> downscale(const Image<float>& img, int factor) {
  if (factor <= 1) return img;
  const int ow = (img.width + factor - 1) / factor, oh = (img.height + factor - 1) / factor;
  const int C = img.channels;
  Image<float> out(ow, oh, C);
  std::vector<double> acc(static_cast<std::size_t>(C));
  for (int oy = 0; oy < oh; ++oy)
    for (int ox = 0; ox < ow; ++ox) {
      std::fill(acc.begin(), acc.end(), 0.0);
      const int y1 = std::min(img.height, (oy + 1) * factor), x1 = std::min(img.width, (ox + 1) * factor);
      int count = 0;
      for (int y = oy * factor; y < y1; ++y)
        for (int x = ox * factor; x < x1; ++x, ++count)
          for (int c = 0; c < C; ++c) acc[std::size_t(c)] += img.at(x, y, c);
      for (int c = 0; c < C; ++c) out.at(ox, oy, c) = float(acc[std::size_t(c)] / count);
    }
  return out;
}

}  // namespace msgs::io
