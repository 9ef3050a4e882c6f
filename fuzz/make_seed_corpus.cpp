// fuzz/make_seed_corpus.cpp
// Writes the seed corpus of the fuzz targets (fuzz/corpus/<target>/) from msgs' own writers, so
// the seeds are valid files a fuzzer mutates from. Run once after a format change: make_seed_corpus <dir>.
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "msgs/io/image_io.hpp"
#include "msgs/io/ply.hpp"

namespace fs = std::filesystem;
using namespace msgs;

namespace {

/// A TIFF written with libtiff in a layout msgs' own writer does not produce (tiles, float
/// samples, separate planes, compression), so that the fuzzer starts from every branch of the
/// reader. `tile` 0 writes strips of 2 rows.
void write_tiff_layout(const fs::path& p, unsigned w, unsigned h, int bits, int samples, int format, int planar,
                       int compression, unsigned tile) {
  TIFF* tif = TIFFOpen(p.c_str(), "w");
  if (!tif) {
    std::fprintf(stderr, "cannot write %s\n", p.c_str());
    std::exit(1);
  }
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, w);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, h);
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, bits);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, samples);
  TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, format);
  TIFFSetField(tif, TIFFTAG_PLANARCONFIG, planar);
  TIFFSetField(tif, TIFFTAG_COMPRESSION, compression);
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, samples == 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK);
  const unsigned bytes = unsigned(bits / 8), per_pixel = planar == PLANARCONFIG_CONTIG ? unsigned(samples) : 1u;
  std::vector<unsigned char> buf(std::size_t(std::max(w, tile)) * std::max(tile, 1u) * per_pixel * bytes);
  for (std::size_t i = 0; i < buf.size(); ++i) buf[i] = static_cast<unsigned char>(i * 29 % 251);
  if (tile > 0) {
    TIFFSetField(tif, TIFFTAG_TILEWIDTH, tile);
    TIFFSetField(tif, TIFFTAG_TILELENGTH, tile);
    for (unsigned ty = 0; ty < h; ty += tile)
      for (unsigned tx = 0; tx < w; tx += tile) TIFFWriteTile(tif, buf.data(), tx, ty, 0, 0);
  } else {
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, 2u);
    for (int s = 0; s < (planar == PLANARCONFIG_CONTIG ? 1 : samples); ++s)
      for (unsigned y = 0; y < h; ++y) TIFFWriteScanline(tif, buf.data(), y, static_cast<std::uint16_t>(s));
  }
  TIFFClose(tif);
}

Image<float> ramp(int w, int h, int c) {
  Image<float> img(w, h, c);
  for (std::size_t i = 0; i < img.size(); ++i) img.data[i] = float(i % 17) / 16.0f;
  return img;
}

template <class G>
GaussianModel<G, float> tiny_model(std::size_t n) {
  GaussianModel<G, float> m(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int d = 0; d < 3; ++d) m.means[3 * i + std::size_t(d)] = float(i) + 0.5f * float(d);
    for (int d = 0; d < 3; ++d) m.log_scales[3 * i + std::size_t(d)] = -2.0f;
    m.quats[4 * i] = 1.0f;
    m.opacity_logits[i] = 0.3f;
    for (int k = 0; k < G::sh_coeffs; ++k)
      for (int c = 0; c < G::bands; ++c) m.sh_at(i, k, c) = 0.01f * float(k + c);
  }
  return m;
}

void text(const fs::path& p, const std::string& s) { io::write_text_atomic(p, s); }

const char* frames_json = R"({
  "camera_model": "OPENCV", "fl_x": 50, "fl_y": 50, "cx": 16, "cy": 12, "w": 32, "h": 24,
  "k1": 0.01, "k2": -0.002,
  "frames": [
    {"file_path": "images/D_00001.png", "mm_channel": "D",
     "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,3],[0,0,0,1]]},
    {"file_path": "images/D_00002.png", "mm_channel": "D",
     "transform_matrix": [[0,-1,0,1],[1,0,0,0],[0,0,1,3],[0,0,0,1]]},
    {"file_path": "images/MS_NIR_00001.png", "mm_channel": "MS_NIR", "fl_x": 40, "fl_y": 40,
     "cx": 10, "cy": 8, "w": 20, "h": 16, "camera_model": "OPENCV_FISHEYE", "k3": 0.001, "k4": 0.0,
     "transform_matrix": [[1,0,0,0.1],[0,1,0,0],[0,0,1,3]]},
    {"file_path": "./images/MS_G_00002.png", "mm_channel": "MS_G", "camera_model": "PINHOLE",
     "k1": 0, "k2": 0, "transform_matrix": [[1,0,0,0.2],[0,1,0,0],[0,0,1,3],[0,0,0,1]]}
  ],
  "ply_file_path": "sparse_pc.ply"
})";

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seed_corpus <corpus dir>\n");
    return 2;
  }
  const fs::path out = argv[1];
  for (const char* t : {"ply", "image", "dataset", "colmap"}) fs::create_directories(out / t);

  // PLY: models of two SH degrees, point clouds binary / ASCII (with a face list) / big-endian.
  io::write_ply<Gaussian<3, 1>>(out / "ply" / "model_c3_deg1.ply", tiny_model<Gaussian<3, 1>>(2), {"D_R", "D_G", "D_B"});
  io::write_ply<Gaussian<3, 3>>(out / "ply" / "model_c3_deg3.ply", tiny_model<Gaussian<3, 3>>(1));
  io::PointCloud pc;
  pc.xyz = {0, 0, 0, 1, 2, 3, -1, 0.5f, 2};
  pc.rgb = {0.1f, 0.2f, 0.3f, 1, 0, 0.5f, 0, 0, 0};
  io::write_point_cloud(out / "ply" / "points_binary.ply", pc);
  text(out / "ply" / "points_ascii.ply",
       "ply\nformat ascii 1.0\ncomment ascii with a face list\nelement vertex 3\nproperty float x\n"
       "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
       "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n3 0 1 2\n");
  {
    std::string s = "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
                    "property double z\nproperty ushort red\nproperty ushort green\nproperty ushort blue\n"
                    "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    auto put_be = [&](const void* v, int n) {
      for (int b = n - 1; b >= 0; --b) s.push_back(static_cast<const char*>(v)[b]);
    };
    for (int i = 0; i < 2; ++i) {
      for (int d = 0; d < 3; ++d) { const double v = 0.25 * (i + d); put_be(&v, 8); }
      for (int c = 0; c < 3; ++c) { const std::uint16_t v = std::uint16_t(1000 * (c + 1)); put_be(&v, 2); }
    }
    s.push_back(2);
    for (int k = 0; k < 2; ++k) { const std::int32_t v = k; put_be(&v, 4); }
    text(out / "ply" / "points_big_endian.ply", s);
  }

  // Images: PNG 8/16-bit, TIFF (16-bit strips; tiled, float, separate planes, compressed), JPEG,
  // BMP, npy.
  io::write_png8(out / "image" / "grey8.png", ramp(5, 3, 1));
  io::write_png16(out / "image" / "rgba16.png", ramp(4, 3, 4));
  io::write_tiff16(out / "image" / "grey16.tif", ramp(6, 4, 1));
  io::write_tiff16(out / "image" / "rgb16.tif", ramp(3, 2, 3));
  io::write_npy(out / "image" / "rgb.npy", ramp(3, 2, 3));
  write_tiff_layout(out / "image" / "tiled8_deflate.tif", 20, 18, 8, 3, SAMPLEFORMAT_UINT, PLANARCONFIG_CONTIG,
                    COMPRESSION_ADOBE_DEFLATE, 16);
  write_tiff_layout(out / "image" / "float32_lzw.tif", 5, 4, 32, 1, SAMPLEFORMAT_IEEEFP, PLANARCONFIG_CONTIG,
                    COMPRESSION_LZW, 0);
  write_tiff_layout(out / "image" / "planes16.tif", 4, 3, 16, 2, SAMPLEFORMAT_UINT, PLANARCONFIG_SEPARATE,
                    COMPRESSION_NONE, 0);
  {
    std::vector<unsigned char> px(16 * 8 * 3);
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<unsigned char>(i * 7);
    stbi_write_jpg((out / "image" / "rgb.jpg").c_str(), 16, 8, 3, px.data(), 80);
    stbi_write_bmp((out / "image" / "rgb.bmp").c_str(), 4, 2, 3, px.data());
  }

  // Datasets: transforms.json [NUL train_split.json]; the published splits have trailing commas.
  text(out / "dataset" / "no_split.json", frames_json);
  std::string with_split = frames_json;
  with_split.push_back('\0');
  with_split += R"({"train": ["images/D_00001.png", "D_00002.png", "images/MS_NIR_00001.png",], "eval": ["images/MS_G_00002.png",],})";
  text(out / "dataset" / "split_trailing_commas.json", with_split);
  std::string val_split = frames_json;
  val_split.push_back('\0');
  val_split += R"({"train": ["images/D_00001.png"], "val": ["./images/D_00002.png"], "test": []})";
  text(out / "dataset" / "split_val.json", val_split);

  // COLMAP models: 't' + cameras.txt, images.txt, points3D.txt; 'b' + the same in binary.
  const std::string sep = "\n#@@next-file@@#\n";
  text(out / "colmap" / "text.model",
       "t# Camera list\n1 PINHOLE 40 30 35 36 20 15\n2 SIMPLE_RADIAL 40 30 33 19.5 15.5 -0.05\n"
       "3 OPENCV 40 30 30 31 20 15 -0.1 0.01 0.001 -0.002\n4 OPENCV_FISHEYE 40 30 30 31 20 15 0.01 0 0 0\n"
       "5 FULL_OPENCV 40 30 30 31 20 15 -0.1 0.01 0.001 -0.002 0.001 0 0 0\n6 RADIAL 40 30 30 20 15 0.01 0.001\n" +
       sep + "# Image list\n7 0.7071 0 0 0.7071 0.5 -1 2 1 b.png\n1.0 2.0 5 10.5 3.5 -1\n3 1 0 0 0 0 0 4 2 a.png\n\n"
       "9 0.9 0.1 -0.3 0.2 1 2 3 3 c d.png\n\n" +
       sep + "# 3D point list\n5 -1 2 -3 1 2 3 0.5 7 0\n6 0.1 0.2 0.3 255 0 10 1.25\n");
  {
    std::string b = "b";
    auto put = [&](const auto& v) { b.append(reinterpret_cast<const char*>(&v), sizeof v); };
    put(std::uint64_t(2));
    put(std::int32_t(1)); put(std::int32_t(1)); put(std::uint64_t(40)); put(std::uint64_t(30));
    for (double v : {35.0, 36.0, 20.0, 15.0}) put(v);
    put(std::int32_t(2)); put(std::int32_t(4)); put(std::uint64_t(40)); put(std::uint64_t(30));
    for (double v : {30.0, 31.0, 20.0, 15.0, -0.1, 0.01, 0.001, -0.002}) put(v);
    b += sep;
    put(std::uint64_t(2));
    for (int i = 0; i < 2; ++i) {
      put(std::int32_t(3 + i));
      for (double v : {1.0, 0.0, 0.0, 0.0, 0.5 * i, 0.0, 4.0}) put(v);
      put(std::int32_t(1 + i));
      b += i ? "b.png" : "a.png";
      b.push_back('\0');
      put(std::uint64_t(1));
      put(2.5); put(3.5); put(std::int64_t(5));
    }
    b += sep;
    put(std::uint64_t(1));
    put(std::uint64_t(5));
    for (double v : {-1.0, 2.0, -3.0}) put(v);
    for (std::uint8_t c : {1, 2, 3}) put(c);
    put(0.5);
    put(std::uint64_t(1)); put(std::int32_t(3)); put(std::int32_t(0));
    text(out / "colmap" / "binary.model", b);
  }
  return 0;
}
