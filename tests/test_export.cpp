// tests/test_export.cpp
// Tests of export.hpp and io/splat_formats.hpp: a band exported as 3 channels renders every channel
// as the band, CIR maps NIR, R, G to red, green, blue, per-Gaussian index colours against a hand
// computation, .splat and .spz read back by small readers written here, and the hard cases
// (non-finite values, zero quaternions, huge log-scales, empty models, missing bands, per-band
// models for composites, unwritable outputs), through the library and through `msgs export`.
// Rasterizers: Gaussian<7, 1> (the source) and Gaussian<3, 1> (the export) only.
#include <doctest/doctest.h>
#include <sys/wait.h>
#include <zlib.h>

#include <msgs/export.hpp>
#include <msgs/rasterize.hpp>

#include "../examples/export_index.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace test_export {
namespace fs = std::filesystem;
using msgs::Image;

namespace {

using G7 = msgs::Gaussian<7, 1>;
using G3 = msgs::Gaussian<3, 1>;
using G1 = msgs::Gaussian<1, 1>;

fs::path scratch_dir(const std::string& sub) {
  const char* env = std::getenv("MSGS_TEST_TMP");
  fs::path d = env ? fs::path(env) : fs::temp_directory_path() / "msgs_test";
  d /= "export";
  d /= sub;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// n Gaussians in front of camera() with random geometry, opacities and SH in [-0.6, 0.6]; every
/// position distinct (the readers below match records by position).
template <class G>
msgs::GaussianModel<G, float> random_model(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  msgs::GaussianModel<G, float> m(n);
  for (std::size_t i = 0; i < n; ++i) {
    m.means[3 * i + 0] = 0.8f * u(rng) + 1e-4f * float(i);
    m.means[3 * i + 1] = 0.6f * u(rng);
    m.means[3 * i + 2] = 3.0f + u(rng);
    for (int d = 0; d < 3; ++d) m.log_scales[3 * i + std::size_t(d)] = -2.6f + 0.6f * u(rng);
    for (int d = 0; d < 4; ++d) m.quats[4 * i + std::size_t(d)] = u(rng) + (d == 0 ? 1.5f : 0.0f);
    m.opacity_logits[i] = 2.0f * u(rng);
    for (int c = 0; c < G::bands; ++c)
      for (int k = 0; k < G::sh_coeffs; ++k) m.sh_at(i, k, c) = 0.6f * u(rng);
  }
  return m;
}

msgs::Camera<float> camera() {
  msgs::Camera<float> c;
  c.width = 48;
  c.height = 36;
  c.fx = c.fy = 40;
  c.cx = 24;
  c.cy = 18;
  return c;
}

template <class G>
Image<float> render(const msgs::GaussianModel<G, float>& m, int first, int count) {
  msgs::Rasterizer<G, float> raster;
  msgs::RenderSettings<float> rs;
  rs.band_first = first;
  rs.band_count = count;
  return raster.forward(m, camera(), rs);
}

double max_abs_diff(const Image<float>& a, const Image<float>& b) {
  REQUIRE(a.data.size() == b.data.size());
  double d = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) d = std::max(d, std::abs(double(a.data[i]) - double(b.data[i])));
  return d;
}

/// A ModelSet of one in-memory model, as load_models_for_export builds it from a file.
template <class G>
msgs::ModelSet set_of(const msgs::GaussianModel<G, float>& m, const fs::path& dir, const std::string& name,
                      const std::vector<std::string>& bands) {
  msgs::io::write_ply(dir / name, m, bands);
  return msgs::load_models_for_export(dir / name);
}

msgs::ExportSelection band(const std::string& id) {
  msgs::ExportSelection s;
  s.kind = msgs::ExportSelection::band;
  s.band_id = id;
  return s;
}

float dc_of(float colour) { return float((double(colour) - 0.5) / msgs::sh::C0); }
double colour_of(float dc) { return msgs::sh::C0 * double(dc) + 0.5; }

double sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

std::array<double, 4> unit(const float* q) {
  const double n = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
  return {q[0] / n, q[1] / n, q[2] / n, q[3] / n};
}

std::vector<unsigned char> read_all(const fs::path& p) { return msgs::io::read_bytes(p); }

float f32_at(const unsigned char* b) {
  float v;
  std::memcpy(&v, b, 4);
  return v;
}
std::uint32_t u32_at(const unsigned char* b) {
  return std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8 | std::uint32_t(b[2]) << 16 | std::uint32_t(b[3]) << 24;
}

/// gunzip with zlib (gzip wrapper required).
std::vector<unsigned char> gunzip(const std::vector<unsigned char>& in) {
  REQUIRE(in.size() >= 2);
  CHECK(in[0] == 0x1f);  // gzip magic
  CHECK(in[1] == 0x8b);
  z_stream zs{};
  REQUIRE(inflateInit2(&zs, 16 + MAX_WBITS) == Z_OK);
  zs.next_in = const_cast<Bytef*>(in.data());
  zs.avail_in = uInt(in.size());
  std::vector<unsigned char> out, buf(1 << 16);
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    zs.next_out = buf.data();
    zs.avail_out = uInt(buf.size());
    rc = inflate(&zs, Z_NO_FLUSH);
    REQUIRE((rc == Z_OK || rc == Z_STREAM_END));
    out.insert(out.end(), buf.data(), buf.data() + (buf.size() - zs.avail_out));
  }
  inflateEnd(&zs);
  return out;
}

/// One Gaussian as a .splat or .spz reader sees it.
struct Decoded {
  float pos[3];
  double log_scale[3];
  double rgb[3];  // colour for .splat, DC coefficient for .spz
  double alpha;
  std::array<double, 4> q;  // w, x, y, z
  std::vector<double> sh;   // .spz: coefficient-major, channel inner
};

std::vector<Decoded> read_splat(const fs::path& p) {
  const auto b = read_all(p);
  REQUIRE(b.size() % 32 == 0);
  std::vector<Decoded> out(b.size() / 32);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const unsigned char* r = b.data() + 32 * i;
    Decoded& d = out[i];
    for (int k = 0; k < 3; ++k) d.pos[k] = f32_at(r + 4 * k);
    for (int k = 0; k < 3; ++k) d.log_scale[k] = std::log(double(f32_at(r + 12 + 4 * k)));
    for (int k = 0; k < 3; ++k) d.rgb[k] = r[24 + k] / 255.0;
    d.alpha = r[27] / 255.0;
    for (int k = 0; k < 4; ++k) d.q[std::size_t(k)] = (r[28 + k] - 128.0) / 128.0;
  }
  return out;
}

struct SpzFile {
  std::uint32_t magic, version, n;
  int degree, frac, flags, reserved;
  std::vector<Decoded> g;
};

SpzFile read_spz(const fs::path& p) {
  const std::vector<unsigned char> b = gunzip(read_all(p));
  REQUIRE(b.size() >= 16);
  SpzFile f;
  f.magic = u32_at(b.data());
  f.version = u32_at(b.data() + 4);
  f.n = u32_at(b.data() + 8);
  f.degree = b[12];
  f.frac = b[13];
  f.flags = b[14];
  f.reserved = b[15];
  const std::size_t n = f.n, dim = std::size_t((f.degree + 1) * (f.degree + 1) - 1);
  const std::size_t rot = f.version >= 3 ? 4 : 3;
  REQUIRE(b.size() == 16 + n * (9 + 1 + 3 + 3 + rot + 3 * dim));
  const unsigned char* pos = b.data() + 16;
  const unsigned char* alpha = pos + 9 * n;
  const unsigned char* col = alpha + n;
  const unsigned char* scale = col + 3 * n;
  const unsigned char* rots = scale + 3 * n;
  const unsigned char* sh = rots + rot * n;
  f.g.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    Decoded& d = f.g[i];
    for (int k = 0; k < 3; ++k) {
      const unsigned char* q = pos + 9 * i + 3 * std::size_t(k);
      std::int32_t v = std::int32_t(q[0] | q[1] << 8 | q[2] << 16);
      if (v & 0x800000) v -= 0x1000000;  // sign extension of 24 bits
      d.pos[k] = float(std::ldexp(double(v), -f.frac));
      d.rgb[k] = (col[3 * i + std::size_t(k)] / 255.0 - 0.5) / 0.15;
      d.log_scale[k] = scale[3 * i + std::size_t(k)] / 16.0 - 10.0;
    }
    d.alpha = alpha[i] / 255.0;
    double xyzw[4];
    if (f.version >= 3) {
      std::uint32_t comp = u32_at(rots + 4 * i);
      const unsigned largest = comp >> 30;
      double ss = 0;
      for (int k = 3; k >= 0; --k) {
        if (unsigned(k) == largest) continue;
        const double mag = double(comp & 511u), v = std::sqrt(0.5) * mag / 511.0;
        xyzw[k] = ((comp >> 9) & 1u) ? -v : v;
        ss += v * v;
        comp >>= 10;
      }
      xyzw[largest] = std::sqrt(std::max(0.0, 1.0 - ss));
    } else {
      double ss = 0;
      for (int k = 0; k < 3; ++k) {
        xyzw[k] = rots[3 * i + std::size_t(k)] / 127.5 - 1.0;
        ss += xyzw[k] * xyzw[k];
      }
      xyzw[3] = std::sqrt(std::max(0.0, 1.0 - ss));
    }
    d.q = {xyzw[3], xyzw[0], xyzw[1], xyzw[2]};
    for (std::size_t k = 0; k < 3 * dim; ++k) d.sh.push_back((sh[3 * dim * i + k] - 128.0) / 128.0);
  }
  return f;
}

/// |<a, b>| of two unit quaternions: 1 when they are the same rotation.
double same_rotation(const std::array<double, 4>& a, const std::array<double, 4>& b) {
  return std::abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
}

/// Index of the Gaussian of `m` at exactly `pos` (positions are distinct).
template <class G>
std::size_t find_by_position(const msgs::GaussianModel<G, float>& m, const float* pos, float tol = 0.0f) {
  for (std::size_t i = 0; i < m.size(); ++i)
    if (std::abs(m.means[3 * i] - pos[0]) <= tol && std::abs(m.means[3 * i + 1] - pos[1]) <= tol &&
        std::abs(m.means[3 * i + 2] - pos[2]) <= tol)
      return i;
  FAIL("no Gaussian at the decoded position");
  return 0;
}

}  // namespace

TEST_CASE("a band exported as 3 channels renders every channel exactly as the band") {
  const fs::path dir = scratch_dir("band");
  using namespace msgs;
  const auto joint = random_model<G7>(300, 1);
  const ModelSet set = set_of(joint, dir, "model_joint.ply", io::joint_channel_names());

  for (const char* id : {"MS_NIR", "MS_G"}) {
    CAPTURE(id);
    const ExportedModel e = select_export(set, band(id));
    CHECK(e.size() == joint.size());
    CHECK(e.sh_degree() == 1);
    CHECK(e.dropped == 0);
    CHECK(e.channel_names == std::vector<std::string>(3, id));
    write_export(dir / "band.ply", e, ExportFormat::ply);
    // Back through msgs' own PLY reader as a plain 3-channel model.
    const io::PlyInfo info = io::inspect_ply(dir / "band.ply");
    CHECK(info.channels == 3);
    CHECK(info.sh_degree == 1);
    const auto back = io::read_ply<G3>(dir / "band.ply");
    const int ch = io::find_band(id)->first_channel_in_joint;
    const Image<float> want = render(joint, ch, 1);
    double max_diff = 0;
    for (int c = 0; c < 3; ++c) max_diff = std::max(max_diff, max_abs_diff(render(back, c, 1), want));
    CHECK(max_diff == 0.0);  // the same coefficients, the same Gaussians: the same bits
    const Image<float> all = render(back, 0, 3);
    for (std::size_t p = 0; p < want.pixels(); ++p)
      for (int c = 0; c < 3; ++c) CHECK(all.data[3 * p + std::size_t(c)] == want.data[p]);
    // Read back as msgs reads models, the file renders the band it came from.
    const ModelSet again = load_models_for_export(dir / "band.ply");
    REQUIRE(again.named_source(id));
    CHECK(again.named_source(id)->channels == 1);
  }

  // D as it is: its three channels, D_R D_G D_B.
  const ExportedModel d = select_export(set, band("D"));
  CHECK(d.channel_names == std::vector<std::string>{"D_R", "D_G", "D_B"});
  write_export(dir / "d.ply", d, ExportFormat::ply);
  CHECK(max_abs_diff(render(io::read_ply<G3>(dir / "d.ply"), 0, 3), render(joint, 0, 3)) == 0.0);
  CHECK(load_models_for_export(dir / "d.ply").named_source("D"));
}

TEST_CASE("a single-band model (Separate) exports its band; an unnamed one serves any single band") {
  const fs::path dir = scratch_dir("separate_band");
  using namespace msgs;
  const auto nir = random_model<G1>(50, 2);
  io::write_ply(dir / "model_MS_NIR.ply", nir, {"MS_NIR"});
  io::write_ply(dir / "model_D.ply", random_model<msgs::Gaussian<3, 1>>(40, 3), {"D_R", "D_G", "D_B"});
  const ModelSet set = load_models_for_export(dir);
  const ExportedModel e = select_export(set, band("MS_NIR"));
  REQUIRE(std::holds_alternative<ModelOf<3, 1>>(e.model));
  const auto& m = std::get<ModelOf<3, 1>>(e.model);
  CHECK(e.source == dir / "model_MS_NIR.ply");
  for (std::size_t i = 0; i < nir.size(); ++i)
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < G1::sh_coeffs; ++k) CHECK(m.sh_at(i, k, c) == nir.sh_at(i, k, 0));
  CHECK(m.means == nir.means);
  CHECK(m.quats == nir.quats);

  io::write_ply(dir / "unnamed.ply", nir);
  const ExportedModel u = select_export(load_models_for_export(dir / "unnamed.ply"), band("MS_RE"));
  CHECK(u.size() == nir.size());
  CHECK(u.channel_names == std::vector<std::string>(3, "MS_RE"));
}

TEST_CASE("CIR maps NIR, R, G to red, green, blue; per-band models are refused with the way out") {
  const fs::path dir = scratch_dir("cir");
  using namespace msgs;
  const auto joint = random_model<G7>(200, 4);
  const ModelSet set = set_of(joint, dir, "model_joint.ply", io::joint_channel_names());
  ExportSelection cir;
  cir.kind = ExportSelection::cir;
  const ExportedModel e = select_export(set, cir);
  CHECK(e.channel_names == std::vector<std::string>{"MS_NIR", "MS_R", "MS_G"});
  const auto& m = std::get<ModelOf<3, 1>>(e.model);
  for (std::size_t i = 0; i < joint.size(); ++i)
    for (int k = 0; k < G7::sh_coeffs; ++k) {
      CHECK(m.sh_at(i, k, 0) == joint.sh_at(i, k, 6));
      CHECK(m.sh_at(i, k, 1) == joint.sh_at(i, k, 4));
      CHECK(m.sh_at(i, k, 2) == joint.sh_at(i, k, 3));
    }
  write_export(dir / "cir.ply", e, ExportFormat::ply);
  const auto back = io::read_ply<G3>(dir / "cir.ply");
  const Image<float> got = render(back, 0, 3);
  const Image<float> nir = render(joint, 6, 1), red = render(joint, 4, 1), green = render(joint, 3, 1);
  CHECK(max_abs_diff(got, cir_composite(nir, red, green)) == 0.0);
  // msgs reads the file back as the three bands it holds.
  const ModelSet again = load_models_for_export(dir / "cir.ply");
  CHECK(again.named_source("MS_NIR")->first_channel == 0);
  CHECK(again.named_source("MS_G")->first_channel == 2);

  // A Separate run: NIR, R and G live on different Gaussians.
  const fs::path sep = dir / "separate";
  fs::create_directories(sep);
  for (const char* b : {"MS_G", "MS_R", "MS_NIR"}) io::write_ply(sep / (std::string("model_") + b + ".ply"), random_model<G1>(10, 5), {b});
  const ModelSet per_band = load_models_for_export(sep);
  try {
    (void)select_export(per_band, cir);
    FAIL("CIR of per-band models accepted");
  } catch (const ExportError& err) {
    const std::string msg = err.what();
    CHECK(msg.find("same Gaussians") != std::string::npos);
    CHECK(msg.find("Separate") != std::string::npos);
    CHECK(msg.find("--band") != std::string::npos);
    CHECK(msg.find("model_MS_NIR.ply") != std::string::npos);
  }
  ExportSelection ndvi;
  ndvi.kind = ExportSelection::index;
  ndvi.idx = cli::export_index("ndvi");
  CHECK_THROWS_AS((void)select_export(per_band, ndvi), ExportError);
  // CIR of a model without R names the band and the bands present.
  io::write_ply(dir / "rgb.ply", random_model<msgs::Gaussian<3, 1>>(5, 6), {"D_R", "D_G", "D_B"});
  try {
    (void)select_export(load_models_for_export(dir / "rgb.ply"), cir);
    FAIL("CIR of an RGB model accepted");
  } catch (const ExportError& err) {
    CHECK(std::string(err.what()).find("MS_NIR") != std::string::npos);
    CHECK(std::string(err.what()).find("bands present: D") != std::string::npos);
  }
}

TEST_CASE("index colours per Gaussian against a hand computation") {
  const fs::path dir = scratch_dir("index");
  using namespace msgs;
  // RdYlGn stops, from ColorBrewer's table: -1 -> stop 0, 0 -> stop 5, 0.6 -> stop 8, 1 -> stop 10.
  const std::array<double, 3> red_end = {165 / 255.0, 0, 38 / 255.0}, middle = {1, 1, 191 / 255.0},
                              stop8 = {102 / 255.0, 189 / 255.0, 99 / 255.0}, green_end = {0, 104 / 255.0, 55 / 255.0};
  struct Case { float g, r, re, nir; std::array<double, 3> ndvi, ndwi; };
  // ndvi = (nir - r) / (nir + r); ndwi = (g - nir) / (g + nir)
  const std::vector<Case> cases = {
      {0.2f, 0.2f, 0.3f, 0.8f, stop8, stop8},       // ndvi 0.6; ndwi -0.6 checked below by formula
      {0.5f, 0.5f, 0.5f, 0.5f, middle, middle},     // 0, 0
      {0.5f, 0.0f, 0.1f, 0.5f, green_end, middle},  // ndvi 1
      {0.0f, 0.7f, 0.1f, 0.0f, red_end, middle},    // ndvi -1; ndwi 0/0 -> 0
  };
  GaussianModel<G7, float> m = random_model<G7>(cases.size() + 1, 7);
  for (std::size_t i = 0; i < cases.size(); ++i) {
    m.sh_at(i, 0, 3) = dc_of(cases[i].g);
    m.sh_at(i, 0, 4) = dc_of(cases[i].r);
    m.sh_at(i, 0, 5) = dc_of(cases[i].re);
    m.sh_at(i, 0, 6) = dc_of(cases[i].nir);
  }
  // The last Gaussian: R far below zero, clamped at 0 as the renderer clamps: NDVI 1.
  m.sh_at(cases.size(), 0, 4) = -10.0f;
  m.sh_at(cases.size(), 0, 6) = dc_of(0.4f);
  const ModelSet set = set_of(m, dir, "model_joint.ply", io::joint_channel_names());

  ExportSelection sel;
  sel.kind = ExportSelection::index;
  sel.idx = cli::export_index("ndvi");
  CHECK(sel.idx.band_a == "MS_NIR");
  CHECK(sel.idx.band_b == "MS_R");
  const ExportedModel e = select_export(set, sel);
  CHECK(e.sh_degree() == 0);
  CHECK(e.channel_names.empty());
  write_export(dir / "ndvi.ply", e, ExportFormat::ply);
  const auto back = io::read_ply<msgs::Gaussian<3, 0>>(dir / "ndvi.ply");
  REQUIRE(back.size() == m.size());
  CHECK(io::inspect_ply(dir / "ndvi.ply").sh_degree == 0);  // no f_rest: zero view dependence
  for (std::size_t i = 0; i <= cases.size(); ++i) {
    CAPTURE(i);
    const auto& want = i < cases.size() ? cases[i].ndvi : green_end;
    for (int c = 0; c < 3; ++c) CHECK(colour_of(back.sh_at(i, 0, c)) == doctest::Approx(want[std::size_t(c)]).epsilon(1e-5));
  }
  CHECK(back.means == m.means);
  CHECK(back.opacity_logits == m.opacity_logits);

  // NDWI of the first Gaussian: (0.2 - 0.8) / (0.2 + 0.8) = -0.6 -> t = 0.2 -> stop 2 (244, 109, 67).
  sel.idx = cli::export_index("ndwi");
  const ExportedModel ndwi = select_export(set, sel);
  const auto& w = std::get<ModelOf<3, 0>>(ndwi.model);
  CHECK(colour_of(w.sh_at(0, 0, 0)) == doctest::Approx(244 / 255.0).epsilon(1e-5));
  CHECK(colour_of(w.sh_at(0, 0, 1)) == doctest::Approx(109 / 255.0).epsilon(1e-5));
  CHECK(colour_of(w.sh_at(0, 0, 2)) == doctest::Approx(67 / 255.0).epsilon(1e-5));
  CHECK(colour_of(w.sh_at(3, 0, 1)) == doctest::Approx(1.0).epsilon(1e-5));  // 0/0 -> 0 -> middle

  // SAVI of the first Gaussian: 1.5 (0.8 - 0.2) / (0.8 + 0.2 + 0.5) = 0.6 -> stop 8.
  sel.idx = cli::export_index("savi");
  const ExportedModel savi = select_export(set, sel);
  const auto& s = std::get<ModelOf<3, 0>>(savi.model);
  for (int c = 0; c < 3; ++c) CHECK(colour_of(s.sh_at(0, 0, c)) == doctest::Approx(stop8[std::size_t(c)]).epsilon(1e-5));
  CHECK_THROWS_AS((void)cli::export_index("evi"), ExportError);
}

TEST_CASE(".splat: 32 bytes per Gaussian, sorted by size times opacity, within the format's quantisation") {
  const fs::path dir = scratch_dir("splat");
  using namespace msgs;
  auto m = random_model<G3>(150, 8);
  m.sh_at(0, 0, 0) = 20.0f;   // colour far above 1: clamped to 255
  m.sh_at(1, 0, 1) = -20.0f;  // below 0: clamped to 0
  m.quats[4 * 2 + 0] = -0.9f;  // w < 0 is kept as it is (.splat stores all four)
  io::write_splat(dir / "m.splat", m);
  const auto rec = read_splat(dir / "m.splat");
  REQUIRE(rec.size() == m.size());
  double prev_key = std::numeric_limits<double>::infinity();
  std::vector<bool> seen(m.size(), false);
  for (const Decoded& d : rec) {
    const std::size_t i = find_by_position(m, d.pos);
    CHECK_FALSE(seen[i]);
    seen[i] = true;
    double key = 0;
    for (int k = 0; k < 3; ++k) {
      CHECK(d.log_scale[k] == doctest::Approx(m.log_scales[3 * i + std::size_t(k)]).epsilon(1e-6));
      key += m.log_scales[3 * i + std::size_t(k)];
      const double c = std::clamp(colour_of(m.sh_at(i, 0, k)), 0.0, 1.0);
      CHECK(std::abs(d.rgb[k] - c) <= 0.5 / 255 + 1e-9);
    }
    key += std::log(sigmoid(m.opacity_logits[i]));
    CHECK(key <= prev_key + 1e-9);  // descending exp(sum log-scales) sigmoid(opacity)
    prev_key = key;
    CHECK(std::abs(d.alpha - sigmoid(m.opacity_logits[i])) <= 0.5 / 255 + 1e-9);
    const auto q = unit(&m.quats[4 * i]);
    for (int k = 0; k < 4; ++k) CHECK(std::abs(d.q[std::size_t(k)] - q[std::size_t(k)]) <= 0.5 / 128 + 1e-9);
  }
  CHECK(std::all_of(seen.begin(), seen.end(), [](bool b) { return b; }));
  for (const Decoded& d : rec) {  // out-of-range colours clamp to the byte range
    const std::size_t i = find_by_position(m, d.pos);
    if (i == 0) CHECK(d.rgb[0] == 1.0);
    if (i == 1) CHECK(d.rgb[1] == 0.0);
  }
  CHECK(fs::file_size(dir / "m.splat") == 150 * io::splat_record_bytes);
}

TEST_CASE(".spz v3 and v2: gzip, header, arrays within the format's quantisation") {
  const fs::path dir = scratch_dir("spz");
  using namespace msgs;
  auto m = random_model<G3>(120, 9);
  m.quats[4 * 3 + 0] = -1.2f;  // w the largest and negative: q and -q are the same rotation
  m.means[3 * 4] = -1.75f;     // negative coordinates: 24-bit two's complement
  for (int version : {3, 2}) {
    CAPTURE(version);
    io::SpzOptions opt;
    opt.version = version;
    io::write_spz(dir / "m.spz", m, opt);
    const SpzFile f = read_spz(dir / "m.spz");
    CHECK(f.magic == 0x5053474eu);
    CHECK(f.version == std::uint32_t(version));
    CHECK(f.n == m.size());
    CHECK(f.degree == 1);
    CHECK(f.frac == 12);
    CHECK(f.flags == 0);
    CHECK(f.reserved == 0);
    for (std::size_t i = 0; i < m.size(); ++i) {
      const Decoded& d = f.g[i];  // .spz keeps the model's order
      for (int k = 0; k < 3; ++k) {
        CHECK(std::abs(d.pos[k] - m.means[3 * i + std::size_t(k)]) <= 0.5 / 4096 + 1e-6);
        CHECK(std::abs(d.log_scale[k] - m.log_scales[3 * i + std::size_t(k)]) <= 1.0 / 32 + 1e-9);
        CHECK(std::abs(d.rgb[k] - m.sh_at(i, 0, k)) <= 0.5 / 255 / 0.15 + 1e-6);
      }
      CHECK(std::abs(d.alpha - sigmoid(m.opacity_logits[i])) <= 0.5 / 255 + 1e-9);
      // v3: 9-bit magnitudes of components up to sqrt(1/2); v2: 8 bits of x, y, z and w rebuilt.
      CHECK(same_rotation(d.q, unit(&m.quats[4 * i])) >= (version == 3 ? 1 - 1e-5 : 1 - 2e-3));
      // SH: degree 1 in buckets of 8 (5 bits), channel inner: (k, c) at 3 (k - 1) + c.
      REQUIRE(d.sh.size() == 9);
      for (int k = 1; k < 4; ++k)
        for (int c = 0; c < 3; ++c)
          CHECK(std::abs(d.sh[std::size_t(3 * (k - 1) + c)] - m.sh_at(i, k, c)) <= 4.5 / 128 + 1e-9);
    }
  }
  // A large scene gives up fractional bits instead of wrapping around.
  m.means[0] = 5000.0f;
  io::write_spz(dir / "far.spz", m);
  const SpzFile far = read_spz(dir / "far.spz");
  CHECK(far.frac == 10);  // 5000 * 2^10 < 2^23 <= 5000 * 2^11
  CHECK(far.g[0].pos[0] == doctest::Approx(5000.0).epsilon(1e-6));
  m.means[0] = 1e7f;
  CHECK_THROWS_AS(io::write_spz(dir / "too_far.spz", m), io::IoError);
  CHECK_FALSE(fs::exists(dir / "too_far.spz"));
}

TEST_CASE("hard cases: non-finite values, zero quaternions, huge log-scales, empty models, unwritable files") {
  const fs::path dir = scratch_dir("hard");
  using namespace msgs;
  auto joint = random_model<G7>(20, 10);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  joint.means[3 * 1 + 2] = nan;            // dropped
  joint.sh_at(2, 2, 6) = inf;              // NIR SH rest: dropped from a NIR export, kept in D
  for (int d = 0; d < 4; ++d) joint.quats[4 * 3 + std::size_t(d)] = 0.0f;  // dropped
  joint.log_scales[3 * 4] = 200.0f;        // clamped to 50
  joint.log_scales[3 * 5 + 1] = -1e30f;    // clamped to -50
  joint.opacity_logits[6] = -inf;          // dropped
  // A PLY cannot hold these values (the writer refuses them): the library path is in memory.
  std::vector<LoadedModel> loaded(1);
  loaded[0].path = dir / "memory.ply";
  loaded[0].info.channels = 7;
  loaded[0].info.sh_degree = 1;
  loaded[0].info.gaussian = true;
  loaded[0].info.band_names = io::joint_channel_names();
  loaded[0].model = joint;
  const ModelSet set = ModelSet::from_models(std::move(loaded), [](std::shared_ptr<const LoadedModel>) {
    return ChannelRenderer{};
  });
  const ExportedModel nir = select_export(set, band("MS_NIR"));
  CHECK(nir.dropped == 4);
  CHECK(nir.clamped == 2);
  CHECK(nir.size() == 16);
  const ExportedModel d = select_export(set, band("D"));
  CHECK(d.dropped == 3);
  const auto& dm = std::get<ModelOf<3, 1>>(d.model);
  for (float s : dm.log_scales) CHECK(std::abs(s) <= 50.0f);
  // The drops keep the rest in order: renders match the source (which the rasteriser culls the same way).
  auto finite_joint = joint;
  CHECK(max_abs_diff(render(dm, 0, 3), render(finite_joint, 0, 3)) == 0.0);
  for (ExportFormat f : {ExportFormat::ply, ExportFormat::splat, ExportFormat::spz}) write_export(dir / "x.out", nir, f);
  // Every float of the .splat is finite.
  write_export(dir / "nir.splat", nir, ExportFormat::splat);
  for (const Decoded& r : read_splat(dir / "nir.splat"))
    for (int k = 0; k < 3; ++k) {
      CHECK(std::isfinite(r.pos[k]));
      CHECK(std::isfinite(r.log_scale[k]));
    }
  // The index of a Gaussian whose band colour is not finite is dropped, not a NaN colour.
  joint.sh_at(7, 0, 4) = nan;
  std::vector<LoadedModel> l2(1);
  l2[0].path = dir / "memory2.ply";
  l2[0].info = set.models()[0]->info;
  l2[0].model = joint;
  const ModelSet set2 = ModelSet::from_models(std::move(l2), [](std::shared_ptr<const LoadedModel>) { return ChannelRenderer{}; });
  ExportSelection ndvi;
  ndvi.kind = ExportSelection::index;
  ndvi.idx = cli::export_index("ndvi");
  const ExportedModel idx = select_export(set2, ndvi);
  CHECK(idx.dropped == 4);  // NaN position, zero quaternion, -inf opacity, NaN R colour
  for (float v : std::get<ModelOf<3, 0>>(idx.model).sh) CHECK(std::isfinite(v));

  // The writers refuse what they cannot draw, naming file, field and Gaussian.
  auto bad = random_model<G3>(3, 11);
  bad.quats[4] = bad.quats[5] = bad.quats[6] = bad.quats[7] = 0.0f;
  try {
    io::write_splat(dir / "bad.splat", bad);
    FAIL("zero quaternion written");
  } catch (const io::IoError& e) {
    CHECK(std::string(e.what()).find("bad.splat") != std::string::npos);
    CHECK(std::string(e.what()).find("'rot'") != std::string::npos);
    CHECK(std::string(e.what()).find("Gaussian 1") != std::string::npos);
  }
  CHECK_FALSE(fs::exists(dir / "bad.splat"));

  // Empty models write empty but valid files.
  const GaussianModel<G3, float> empty;
  io::write_splat(dir / "empty.splat", empty);
  CHECK(fs::file_size(dir / "empty.splat") == 0);
  io::write_spz(dir / "empty.spz", empty);
  CHECK(read_spz(dir / "empty.spz").n == 0);
  io::write_ply(dir / "empty.ply", empty);
  CHECK(io::read_ply<G3>(dir / "empty.ply").size() == 0);

  // A band the model lacks: the bands present and the way out.
  io::write_ply(dir / "model_MS_NIR.ply", random_model<G1>(5, 12), {"MS_NIR"});
  io::write_ply(dir / "model_D.ply", random_model<G3>(5, 13), {"D_R", "D_G", "D_B"});
  try {
    (void)select_export(load_models_for_export(dir), band("MS_RE"));
    FAIL("missing band accepted");
  } catch (const ExportError& e) {
    CHECK(std::string(e.what()).find("MS_RE") != std::string::npos);
    CHECK(std::string(e.what()).find("bands present: D, MS_NIR") != std::string::npos);
  }
  CHECK_THROWS_AS((void)select_export(load_models_for_export(dir), band("NIR")), ExportError);

  // An output that cannot be written: an IoError naming it, and nothing left behind.
  const fs::path missing = dir / "no_such_folder" / "x.splat";
  try {
    write_export(missing, nir, ExportFormat::splat);
    FAIL("wrote into a missing folder");
  } catch (const io::IoError& e) {
    CHECK(std::string(e.what()).find("x.splat") != std::string::npos);
  }
  CHECK_FALSE(fs::exists(dir / "no_such_folder"));
  CHECK(export_format_from_path("a/b.SPZ") == ExportFormat::spz);
  CHECK_THROWS_AS((void)export_format_from_path("a/b.obj"), ExportError);
}

#ifdef MSGS_BIN
namespace {
/// Run `msgs <args>`; returns the exit status and leaves stderr in `err`.
int run_msgs(const std::string& args, const fs::path& dir, std::string& err) {
  const fs::path log = dir / "stderr.txt";
  const std::string cmd = std::string(MSGS_BIN) + " " + args + " > " + (dir / "stdout.txt").string() + " 2> " + log.string();
  const int rc = std::system(cmd.c_str());
  err = msgs::io::read_text(log);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}
}  // namespace

TEST_CASE("msgs export: files from a run directory, and non-zero exits that say why") {
  const fs::path dir = scratch_dir("cli");
  using namespace msgs;
  const fs::path run = dir / "run";
  fs::create_directories(run);
  io::write_ply(run / "model_joint.ply", random_model<G7>(30, 14), io::joint_channel_names());
  std::string err;
  for (const char* out : {"nir.ply", "cir.splat", "ndvi.spz"}) {
    const std::string what = std::string(out) == "nir.ply" ? "--band MS_NIR"
                             : std::string(out) == "cir.splat" ? "--composite cir" : "--index ndvi";
    CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / out).string() + " " + what, dir, err) == 0);
    CHECK(fs::is_regular_file(dir / out));
  }
  CHECK(read_splat(dir / "cir.splat").size() == 30);
  CHECK(read_spz(dir / "ndvi.spz").n == 30);
  CHECK(read_spz(dir / "ndvi.spz").degree == 0);

  // Per-band run: CIR refused with the way out; a band it lacks named with the bands present.
  const fs::path sep = dir / "sep";
  fs::create_directories(sep);
  for (const char* b : {"MS_G", "MS_R", "MS_NIR"}) io::write_ply(sep / (std::string("model_") + b + ".ply"), random_model<G1>(10, 15), {b});
  CHECK(run_msgs("export --model " + sep.string() + " --out " + (dir / "c.ply").string() + " --composite cir", dir, err) == 1);
  CHECK(err.find("--band") != std::string::npos);
  CHECK(run_msgs("export --model " + sep.string() + " --out " + (dir / "d.ply").string() + " --band D", dir, err) == 1);
  CHECK(err.find("bands present: MS_G, MS_R, MS_NIR") != std::string::npos);
  // Empty model, missing output folder, unknown extension, two selections.
  io::write_ply(dir / "empty.ply", GaussianModel<G3, float>{}, {"D_R", "D_G", "D_B"});
  CHECK(run_msgs("export --model " + (dir / "empty.ply").string() + " --out " + (dir / "e.splat").string() + " --band D", dir, err) == 1);
  CHECK(err.find("no Gaussian to export") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "e.splat"));
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "nope" / "x.ply").string() + " --band D", dir, err) == 1);
  CHECK(err.find("does not exist") != std::string::npos);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "x.obj").string() + " --band D", dir, err) == 2);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "x.ply").string() + " --band D --index ndvi", dir, err) == 2);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "x.ply").string() + " --index evi", dir, err) == 2);
  CHECK(err.find("ndvi") != std::string::npos);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "x.ply").string() + " --band D --format splat", dir, err) == 2);
  CHECK(err.find("extension") != std::string::npos);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (dir / "x.bin").string() + " --band D --format splat", dir, err) == 0);
  CHECK(fs::file_size(dir / "x.bin") == 30 * io::splat_record_bytes);
  // The source model is never overwritten, and no model_*.ply is added to the run folder.
  const auto before = fs::file_size(run / "model_joint.ply");
  CHECK(run_msgs("export --model " + (run / "model_joint.ply").string() + " --out " + (run / "model_joint.ply").string() + " --band D", dir, err) == 1);
  CHECK(err.find("is the model being exported") != std::string::npos);
  CHECK(run_msgs("export --model " + run.string() + " --out " + (run / "model_nir.ply").string() + " --band MS_NIR", dir, err) == 1);
  CHECK_FALSE(fs::exists(run / "model_nir.ply"));
  CHECK(fs::file_size(run / "model_joint.ply") == before);
}
#endif

}  // namespace test_export
