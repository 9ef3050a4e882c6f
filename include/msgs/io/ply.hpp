// include/msgs/io/ply.hpp
// PLY files: Gaussian models in the standard 3DGS binary layout for any channel count (with the
// band names in a header comment), runtime inspection for CLI dispatch, and sparse point clouds.
//
// Model layout (binary little-endian, one float32 per property, in this order):
//   x y z nx ny nz f_dc_0 .. f_dc_{C-1} f_rest_0 .. f_rest_{C(K-1)-1} opacity scale_0..2 rot_0..3
// C colour channels, K = (degree + 1)^2 SH coefficients per channel. f_rest is channel-major:
// channel c, coefficient k >= 1 sits at f_rest_{c (K-1) + k - 1}. Opacity is a logit, scales are
// logs, rot is a w x y z quaternion. A C = 3 file is exactly what ordinary 3DGS viewers expect.
// The per-channel names go into a header comment `comment msgs_bands <name> ...` (one name per
// channel), which other readers ignore.
#pragma once

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "msgs/gaussian.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"

namespace msgs::io {

/// A sparse point cloud (e.g. sparse_pc.ply or COLMAP points3D).
struct PointCloud {
  std::vector<float> xyz;  ///< [N, 3] positions
  std::vector<float> rgb;  ///< [N, 3] colours in [0, 1]; empty when the file has none
  std::size_t size() const { return xyz.size() / 3; }
  bool has_colour() const { return !rgb.empty(); }
};

/// What a PLY file holds, read from its header alone.
struct PlyInfo {
  std::size_t vertices = 0;             ///< number of vertices (Gaussians or points)
  bool gaussian = false;                ///< true when it has the 3DGS model properties
  int channels = 0;                     ///< colour channels (f_dc count); 0 when not a model
  int sh_degree = -1;                   ///< SH degree; -1 when not a model
  std::vector<std::string> band_names;  ///< per-channel names from `comment msgs_bands`, may be empty
};

namespace detail {

enum class PlyType { i8, u8, i16, u16, i32, u32, f32, f64 };
enum class PlyFormat { ascii, binary_le, binary_be };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::f32;
  bool is_list = false;
  PlyType count_type = PlyType::u8;  // lists only
};
struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> props;
};
struct PlyHeader {
  PlyFormat format = PlyFormat::binary_le;
  std::vector<std::string> comments;
  std::vector<PlyElement> elements;
};

inline bool parse_ply_type(std::string_view s, PlyType& t) {
  struct Entry { std::string_view a, b; PlyType t; };
  static constexpr Entry table[] = {{"char", "int8", PlyType::i8},     {"uchar", "uint8", PlyType::u8},
                                    {"short", "int16", PlyType::i16},  {"ushort", "uint16", PlyType::u16},
                                    {"int", "int32", PlyType::i32},    {"uint", "uint32", PlyType::u32},
                                    {"float", "float32", PlyType::f32}, {"double", "float64", PlyType::f64}};
  for (const auto& e : table)
    if (s == e.a || s == e.b) { t = e.t; return true; }
  return false;
}

inline std::size_t ply_type_size(PlyType t) {
  switch (t) {
    case PlyType::i8: case PlyType::u8: return 1;
    case PlyType::i16: case PlyType::u16: return 2;
    case PlyType::i32: case PlyType::u32: case PlyType::f32: return 4;
    case PlyType::f64: return 8;
  }
  return 0;
}

/// Decode one binary value; `swap` when the file's byte order differs from the machine's.
inline double ply_decode(const unsigned char* src, PlyType t, bool swap) {
  unsigned char b[8];
  const std::size_t n = ply_type_size(t);
  for (std::size_t i = 0; i < n; ++i) b[i] = swap ? src[n - 1 - i] : src[i];
  switch (t) {
    case PlyType::i8: { std::int8_t v; std::memcpy(&v, b, 1); return v; }
    case PlyType::u8: return b[0];
    case PlyType::i16: { std::int16_t v; std::memcpy(&v, b, 2); return v; }
    case PlyType::u16: { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
    case PlyType::i32: { std::int32_t v; std::memcpy(&v, b, 4); return v; }
    case PlyType::u32: { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
    case PlyType::f32: { float v; std::memcpy(&v, b, 4); return v; }
    case PlyType::f64: { double v; std::memcpy(&v, b, 8); return v; }
  }
  return 0;
}

inline std::vector<std::string> split_ws(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream ss(line);
  for (std::string tok; ss >> tok;) out.push_back(tok);
  return out;
}

/// Parse the header and leave `in` at the first data byte.
inline PlyHeader read_ply_header(std::istream& in, const std::filesystem::path& p) {
  PlyHeader h;
  std::string line;
  auto next = [&]() -> bool {
    if (!std::getline(in, line)) return false;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  if (!next() || line != "ply") fail(p, "not a PLY file (first line must be 'ply')");
  bool have_format = false;
  for (int lineno = 2;; ++lineno) {
    if (!next()) fail(p, "header is truncated (no end_header)");
    const auto tok = split_ws(line);
    if (tok.empty()) continue;
    const std::string where = cat("header line ", lineno);
    if (tok[0] == "end_header") {
      // The data starts after this line's newline: anything else on the line would be read as
      // part of the header and the data would start too late (or, with no newline, never).
      if (tok.size() != 1) fail(p, where, "'end_header' must stand alone on its line; the data starts on the next");
      break;
    }
    if (tok[0] == "comment" || tok[0] == "obj_info") {
      h.comments.push_back(line.size() > tok[0].size() + 1 ? line.substr(tok[0].size() + 1) : std::string());
    } else if (tok[0] == "format") {
      if (tok.size() < 2) fail(p, where, "format line needs a format name");
      if (tok[1] == "ascii") h.format = PlyFormat::ascii;
      else if (tok[1] == "binary_little_endian") h.format = PlyFormat::binary_le;
      else if (tok[1] == "binary_big_endian") h.format = PlyFormat::binary_be;
      else fail(p, where, cat("unknown format '", tok[1], "'"));
      have_format = true;
    } else if (tok[0] == "element") {
      if (tok.size() != 3) fail(p, where, "element line must be 'element <name> <count>'");
      PlyElement e;
      e.name = tok[1];
      const auto r = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), e.count);
      if (r.ec != std::errc() || r.ptr != tok[2].data() + tok[2].size())
        fail(p, cat("element ", tok[1]), cat("bad count '", tok[2], "'"));
      h.elements.push_back(std::move(e));
    } else if (tok[0] == "property") {
      if (h.elements.empty()) fail(p, where, "property before any element");
      PlyProperty prop;
      if (tok.size() == 5 && tok[1] == "list") {
        prop.is_list = true;
        prop.name = tok[4];
        if (!parse_ply_type(tok[2], prop.count_type) || !parse_ply_type(tok[3], prop.type))
          fail(p, prop.name, cat("unsupported list property types '", tok[2], " ", tok[3], "'"));
      } else if (tok.size() == 3) {
        prop.name = tok[2];
        if (!parse_ply_type(tok[1], prop.type)) fail(p, prop.name, cat("unsupported property type '", tok[1], "'"));
      } else {
        fail(p, where, cat("malformed property line '", line, "'"));
      }
      h.elements.back().props.push_back(std::move(prop));
    } else {
      fail(p, where, cat("unknown header keyword '", tok[0], "'"));
    }
  }
  if (!have_format) fail(p, "header has no format line");
  // A file that ends on the end_header line has no data; clear the end-of-file state so the
  // size checks see 0 bytes left rather than a stream that cannot tell.
  if (in.eof()) in.clear();
  return h;
}

inline const PlyElement* find_element(const PlyHeader& h, std::string_view name) {
  for (const auto& e : h.elements)
    if (e.name == name) return &e;
  return nullptr;
}

inline int find_property(const PlyElement& e, std::string_view name) {
  for (std::size_t i = 0; i < e.props.size(); ++i)
    if (e.props[i].name == name) return static_cast<int>(i);
  return -1;
}

/// Bytes from the current position of `in` to its end (the stream is left where it was);
/// SIZE_MAX when the stream cannot tell (then no size check is possible).
inline std::size_t remaining_bytes(std::istream& in) {
  const std::streampos here = in.tellg();
  if (here < 0) return SIZE_MAX;
  in.seekg(0, std::ios::end);
  const std::streampos last = in.tellg();
  in.seekg(here);
  if (last < here || !in) {
    in.clear();
    in.seekg(here);
    return SIZE_MAX;
  }
  return static_cast<std::size_t>(last - here);
}

/// Stream over the data section. Reads the "vertex" element into [N, names.size()] floats
/// (the properties named, in that order), skips the other elements, and refuses truncated
/// files, trailing data, list properties in the vertex element and non-finite values.
/// `types` (optional) receives the stored type of each requested property.
inline std::vector<float> read_vertex_columns(std::istream& in, const PlyHeader& h, const std::filesystem::path& p,
                                              const std::vector<std::string>& names,
                                              std::vector<PlyType>* types = nullptr) {
  const PlyElement* vert = find_element(h, "vertex");
  if (!vert) fail(p, "no 'vertex' element");
  std::vector<int> col_of_prop(vert->props.size(), -1);
  if (types) types->clear();
  for (std::size_t j = 0; j < names.size(); ++j) {
    const int k = find_property(*vert, names[j]);
    if (k < 0) fail(p, names[j], "missing vertex property");
    col_of_prop[static_cast<std::size_t>(k)] = static_cast<int>(j);
    if (types) types->push_back(vert->props[static_cast<std::size_t>(k)].type);
  }
  for (const auto& prop : vert->props)
    if (prop.is_list) fail(p, prop.name, "list properties are not supported in the vertex element");

  // The counts come from the header: check them against the bytes actually present before
  // allocating, so a tiny file claiming 1e12 vertices fails at once instead of asking for terabytes.
  const std::size_t avail = remaining_bytes(in);
  // An ASCII file may lack the newline after its last entry.
  const std::size_t budget = avail == SIZE_MAX ? avail : avail + (h.format == PlyFormat::ascii ? 1 : 0);
  std::size_t need = 0;
  for (const auto& e : h.elements) {
    // The fewest bytes one entry can take: binary, its fixed-size values (and list counts);
    // ASCII, one character and a newline (finer errors, such as a missing value, come below).
    std::size_t min_row = h.format == PlyFormat::ascii ? 2 : 0;
    if (h.format != PlyFormat::ascii)
      for (const auto& pr : e.props) min_row += ply_type_size(pr.is_list ? pr.count_type : pr.type);
    if (min_row == 0 || e.count == 0) continue;
    if (e.count > (budget - need) / min_row)
      fail(p, cat("truncated: element '", e.name, "' declares ", e.count, " entries, data ends in entry ",
                  (budget - need) / min_row, " (", avail, " bytes of data)"));
    need += e.count * min_row;
  }

  const std::size_t ncol = names.size();
  std::vector<float> out(vert->count * ncol);
  auto store = [&](std::size_t row, std::size_t prop, double v) {
    const int c = col_of_prop[prop];
    if (c < 0) return;
    if (!std::isfinite(v))
      fail(p, names[static_cast<std::size_t>(c)], cat("value of vertex ", row, " is not finite"));
    out[row * ncol + static_cast<std::size_t>(c)] = static_cast<float>(v);
  };

  if (h.format == PlyFormat::ascii) {
    std::string line;
    for (const auto& e : h.elements) {
      for (std::size_t row = 0; row < e.count; ++row) {
        do {
          if (!std::getline(in, line))
            fail(p, cat("truncated: element '", e.name, "' declares ", e.count, " entries, data ends at ", row));
        } while (line.find_first_not_of(" \t\r") == std::string::npos);
        const char* s = line.data();
        const char* end = s + line.size();
        std::size_t prop = 0;
        auto next_value = [&](const std::string& field) -> double {
          while (s < end && (*s == ' ' || *s == '\t' || *s == '\r')) ++s;
          if (s == end) fail(p, field, cat("line for ", e.name, " ", row, " has too few values"));
          double v = 0;
          const auto r = std::from_chars(s, end, v);
          if (r.ec != std::errc() || (r.ptr < end && *r.ptr != ' ' && *r.ptr != '\t' && *r.ptr != '\r'))
            fail(p, field, cat("cannot parse a number in ", e.name, " ", row));
          s = r.ptr;
          return v;
        };
        for (; prop < e.props.size(); ++prop) {
          const auto& pr = e.props[prop];
          if (pr.is_list) {
            const double n = next_value(pr.name);
            // Each value needs a character of the line, which also keeps the cast below in range.
            if (!(n >= 0) || n != std::floor(n) || n > double(end - s))
              fail(p, pr.name, cat("bad list length in ", e.name, " ", row));
            for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) (void)next_value(pr.name);
          } else {
            const double v = next_value(pr.name);
            if (&e == vert) store(row, prop, v);
          }
        }
        while (s < end && (*s == ' ' || *s == '\t' || *s == '\r')) ++s;
        if (s != end) fail(p, cat("element '", e.name, "' entry ", row, " has more values than properties"));
      }
    }
    while (std::getline(in, line))
      if (line.find_first_not_of(" \t\r") != std::string::npos) fail(p, "data continues after the declared elements");
    return out;
  }

  const bool swap = (h.format == PlyFormat::binary_le) != (std::endian::native == std::endian::little);
  for (const auto& e : h.elements) {
    bool fixed = true;
    std::size_t stride = 0;
    for (const auto& pr : e.props) {
      fixed = fixed && !pr.is_list;
      stride += ply_type_size(pr.type);
    }
    if (fixed && stride == 0) continue;  // no properties: its entries hold no bytes, however many
    if (fixed) {
      // Whole rows in chunks: the common case, and the only one for Gaussian models.
      constexpr std::size_t chunk_rows = 4096;
      std::vector<unsigned char> buf(stride * chunk_rows);
      for (std::size_t row0 = 0; row0 < e.count; row0 += chunk_rows) {
        const std::size_t rows = std::min(chunk_rows, e.count - row0);
        in.read(reinterpret_cast<char*>(buf.data()), static_cast<std::streamsize>(rows * stride));
        const auto got = static_cast<std::size_t>(in.gcount());
        if (got != rows * stride)
          fail(p, cat("truncated: element '", e.name, "' declares ", e.count, " entries, data ends in entry ",
                      row0 + got / std::max<std::size_t>(stride, 1)));
        if (&e != vert) continue;
        for (std::size_t r = 0; r < rows; ++r) {
          const unsigned char* src = buf.data() + r * stride;
          for (std::size_t prop = 0; prop < e.props.size(); ++prop) {
            if (col_of_prop[prop] >= 0) store(row0 + r, prop, ply_decode(src, e.props[prop].type, swap));
            src += ply_type_size(e.props[prop].type);
          }
        }
      }
    } else {
      // Elements with lists (faces) are skipped value by value.
      unsigned char b[8];
      for (std::size_t row = 0; row < e.count; ++row)
        for (const auto& pr : e.props) {
          const std::size_t cs = ply_type_size(pr.is_list ? pr.count_type : pr.type);
          if (!in.read(reinterpret_cast<char*>(b), static_cast<std::streamsize>(cs)))
            fail(p, cat("truncated: element '", e.name, "' declares ", e.count, " entries, data ends in entry ", row));
          if (!pr.is_list) continue;
          const double n = ply_decode(b, pr.count_type, swap);
          // A float count type can hold NaN, fractions or 1e300: refuse them before the cast.
          if (!(n >= 0) || n != std::floor(n) || n >= double(avail))
            fail(p, pr.name, cat("bad list length in ", e.name, " ", row));
          in.ignore(static_cast<std::streamsize>(static_cast<std::size_t>(n) * ply_type_size(pr.type)));
          if (!in) fail(p, cat("truncated: element '", e.name, "' entry ", row));
        }
    }
  }
  if (in.peek() != std::char_traits<char>::eof()) fail(p, "data continues after the declared elements (wrong counts?)");
  return out;
}

inline std::ifstream open_ply(const std::filesystem::path& p) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(p, ec)) fail(p, "file does not exist or is not a regular file");
  std::ifstream in(p, std::ios::binary);
  if (!in) fail(p, "cannot open for reading");
  return in;
}

/// Parse `comment msgs_bands a b c` into {a, b, c}; empty when absent.
inline std::vector<std::string> band_names_from_comments(const PlyHeader& h) {
  for (const auto& c : h.comments) {
    auto tok = split_ws(c);
    if (!tok.empty() && tok[0] == "msgs_bands") return {tok.begin() + 1, tok.end()};
  }
  return {};
}

/// Count a contiguous run prefix_0, prefix_1, ... and refuse gaps.
inline int count_indexed(const PlyElement& e, const std::string& prefix, const std::filesystem::path& p) {
  int n = 0, max_index = -1;
  for (const auto& pr : e.props) {
    if (pr.name.rfind(prefix, 0) != 0) continue;
    int idx = -1;
    const char* b = pr.name.data() + prefix.size();
    const char* end = pr.name.data() + pr.name.size();
    const auto r = std::from_chars(b, end, idx);
    if (r.ec != std::errc() || r.ptr != end || idx < 0) continue;
    ++n;
    max_index = std::max(max_index, idx);
  }
  if (max_index + 1 != n) fail(p, prefix + "*", cat("indices are not contiguous from 0 (", n, " found, max ", max_index, ")"));
  return n;
}

inline PlyInfo info_from_header(const PlyHeader& h, const std::filesystem::path& p) {
  PlyInfo info;
  const PlyElement* vert = find_element(h, "vertex");
  if (!vert) fail(p, "no 'vertex' element");
  info.vertices = vert->count;
  info.band_names = band_names_from_comments(h);
  const int dc = count_indexed(*vert, "f_dc_", p);
  if (dc == 0 || find_property(*vert, "opacity") < 0) return info;
  const int rest = count_indexed(*vert, "f_rest_", p);
  if (rest % dc != 0) fail(p, "f_rest_*", cat(rest, " coefficients are not a multiple of ", dc, " channels"));
  const int k = rest / dc + 1;
  int deg = 0;
  while (sh_coeffs_for_degree(deg) < k) ++deg;
  if (sh_coeffs_for_degree(deg) != k || deg > 3)
    fail(p, "f_rest_*", cat(k, " SH coefficients per channel is not (degree + 1)^2 for a degree 0..3"));
  info.gaussian = true;
  info.channels = dc;
  info.sh_degree = deg;
  if (!info.band_names.empty() && static_cast<int>(info.band_names.size()) != dc)
    fail(p, "comment msgs_bands", cat("names ", info.band_names.size(), " bands but the file has ", dc, " channels"));
  return info;
}

inline void put_f32_le(std::string& out, float v) {
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  for (int b = 0; b < 4; ++b) out.push_back(static_cast<char>((u >> (8 * b)) & 0xff));
}

}  // namespace detail

/// Read the header of a PLY file and report what it holds (no data is read). Throws IoError for a
/// malformed header or inconsistent model properties.
inline PlyInfo inspect_ply(const std::filesystem::path& p) {
  auto in = detail::open_ply(p);
  return detail::info_from_header(detail::read_ply_header(in, p), p);
}

/// Write a Gaussian model in the standard 3DGS binary PLY layout (see the top of this file),
/// atomically. `band_names` gives one name per channel (no whitespace) and goes into the
/// `comment msgs_bands` line; empty means no names. Non-finite parameters are refused.
template <class G>
void write_ply(const std::filesystem::path& p, const GaussianModel<G, float>& m,
               const std::vector<std::string>& band_names = {}) {
  m.check_consistent();
  constexpr int C = G::bands, K = G::sh_coeffs;
  if (!band_names.empty() && static_cast<int>(band_names.size()) != C)
    fail(p, "band_names", cat("got ", band_names.size(), " names for ", C, " channels"));
  for (const auto& n : band_names)
    if (n.empty() || n.find_first_of(" \t\r\n") != std::string::npos)
      fail(p, "band_names", cat("name '", n, "' is empty or contains whitespace"));

  std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by msgs\n";
  if (!band_names.empty()) {
    out += "comment msgs_bands";
    for (const auto& n : band_names) out += cat(" ", n);
    out += "\n";
  }
  out += cat("element vertex ", m.size(), "\n");
  for (const char* n : {"x", "y", "z", "nx", "ny", "nz"}) out += cat("property float ", n, "\n");
  for (int c = 0; c < C; ++c) out += cat("property float f_dc_", c, "\n");
  for (int i = 0; i < C * (K - 1); ++i) out += cat("property float f_rest_", i, "\n");
  out += "property float opacity\n";
  for (int i = 0; i < 3; ++i) out += cat("property float scale_", i, "\n");
  for (int i = 0; i < 4; ++i) out += cat("property float rot_", i, "\n");
  out += "end_header\n";

  constexpr std::size_t per_vertex = 6 + C * K + 1 + 3 + 4;
  const std::size_t header_size = out.size();
  out.reserve(header_size + m.size() * per_vertex * 4);
  auto put = [&](float v, std::size_t i, const char* field) {
    if (!std::isfinite(v)) fail(p, field, cat("Gaussian ", i, " has a non-finite value; refusing to write"));
    detail::put_f32_le(out, v);
  };
  for (std::size_t i = 0; i < m.size(); ++i) {
    for (int d = 0; d < 3; ++d) put(m.means[3 * i + std::size_t(d)], i, "x/y/z");
    for (int d = 0; d < 3; ++d) detail::put_f32_le(out, 0.0f);
    for (int c = 0; c < C; ++c) put(m.sh_at(i, 0, c), i, "f_dc");
    for (int c = 0; c < C; ++c)
      for (int k = 1; k < K; ++k) put(m.sh_at(i, k, c), i, "f_rest");
    put(m.opacity_logits[i], i, "opacity");
    for (int d = 0; d < 3; ++d) put(m.log_scales[3 * i + std::size_t(d)], i, "scale");
    for (int d = 0; d < 4; ++d) put(m.quats[4 * i + std::size_t(d)], i, "rot");
  }
  write_bytes_atomic(p, out.data(), out.size());
}

/// Read a Gaussian model written in the 3DGS PLY layout (by msgs or any 3DGS trainer). The file's
/// channel count must equal G::bands. A file with a lower SH degree than G is accepted and its
/// missing coefficients are zero (a degree-0 model grows into a degree-3 one); a higher degree is
/// refused, since dropping coefficients would silently change the colours. `band_names` receives
/// the per-channel names from the header comment (empty when there are none).
template <class G>
GaussianModel<G, float> read_ply(const std::filesystem::path& p, std::vector<std::string>* band_names = nullptr) {
  auto in = detail::open_ply(p);
  const detail::PlyHeader h = detail::read_ply_header(in, p);
  const PlyInfo info = detail::info_from_header(h, p);
  if (!info.gaussian) fail(p, "not a Gaussian model (no f_dc_* / opacity properties)");
  constexpr int C = G::bands, K = G::sh_coeffs;
  if (info.channels != C)
    fail(p, "f_dc_*", cat("file has ", info.channels, " colour channels, the model type needs ", C));
  if (info.sh_degree > G::sh_degree)
    fail(p, "f_rest_*", cat("file has SH degree ", info.sh_degree, ", the model type only ", G::sh_degree,
                            " (refusing to drop coefficients)"));
  const int kf = sh_coeffs_for_degree(info.sh_degree);

  std::vector<std::string> names = {"x", "y", "z"};
  for (int c = 0; c < C; ++c) names.push_back(cat("f_dc_", c));
  for (int i = 0; i < C * (kf - 1); ++i) names.push_back(cat("f_rest_", i));
  names.push_back("opacity");
  for (int i = 0; i < 3; ++i) names.push_back(cat("scale_", i));
  for (int i = 0; i < 4; ++i) names.push_back(cat("rot_", i));
  for (const auto& pr : detail::find_element(h, "vertex")->props)
    if (pr.type != detail::PlyType::f32 && pr.type != detail::PlyType::f64 &&
        std::find(names.begin(), names.end(), pr.name) != names.end())
      fail(p, pr.name, "model properties must be float or double");
  const std::vector<float> cols = detail::read_vertex_columns(in, h, p, names);

  const std::size_t n = info.vertices, nc = names.size();
  GaussianModel<G, float> m(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* r = cols.data() + i * nc;
    for (int d = 0; d < 3; ++d) m.means[3 * i + std::size_t(d)] = r[d];
    const float* dc = r + 3;
    const float* rest = dc + C;
    for (int c = 0; c < C; ++c) {
      m.sh_at(i, 0, c) = dc[c];
      for (int k = 1; k < K; ++k) m.sh_at(i, k, c) = k < kf ? rest[c * (kf - 1) + k - 1] : 0.0f;
    }
    const float* tail = rest + C * (kf - 1);
    m.opacity_logits[i] = tail[0];
    for (int d = 0; d < 3; ++d) m.log_scales[3 * i + std::size_t(d)] = tail[1 + d];
    for (int d = 0; d < 4; ++d) m.quats[4 * i + std::size_t(d)] = tail[4 + d];
  }
  if (band_names) *band_names = info.band_names;
  return m;
}

/// Channels [First, First + Count) of a model as a model of their own, same geometry and SH
/// degree. `slice_channels<0, 3>(joint)` is the RGB part of a Joint model.
template <int First, int Count, class G>
GaussianModel<Gaussian<Count, G::sh_degree>, float> slice_channels(const GaussianModel<G, float>& m) {
  static_assert(First >= 0 && Count >= 1 && First + Count <= G::bands, "channel range outside the model");
  using Out = Gaussian<Count, G::sh_degree>;
  GaussianModel<Out, float> o;
  o.means = m.means;
  o.log_scales = m.log_scales;
  o.quats = m.quats;
  o.opacity_logits = m.opacity_logits;
  // Band planes: the channels are one contiguous run of planes.
  const std::size_t stride = m.sh_plane_stride();
  o.sh.assign(m.sh.begin() + static_cast<std::ptrdiff_t>(First * stride),
              m.sh.begin() + static_cast<std::ptrdiff_t>((First + Count) * stride));
  return o;
}

/// Write only the first three channels (the RGB camera of a Joint model) as a plain 3-channel
/// 3DGS file that any viewer opens.
template <class G>
void write_ply_rgb(const std::filesystem::path& p, const GaussianModel<G, float>& m,
                   const std::vector<std::string>& band_names = {"D_R", "D_G", "D_B"}) {
  static_assert(G::bands >= 3, "write_ply_rgb needs a model with at least three channels");
  write_ply(p, slice_channels<0, 3>(m), band_names);
}

/// Read a sparse point cloud PLY (ASCII or binary): `x y z` and, when present, `red green blue`
/// (uchar values are divided by 255, ushort by 65535, float/double taken as [0, 1]). Refuses
/// truncated files, wrong element counts, list or unknown property types and non-finite values.
inline PointCloud read_point_cloud(const std::filesystem::path& p) {
  auto in = detail::open_ply(p);
  const detail::PlyHeader h = detail::read_ply_header(in, p);
  const detail::PlyElement* vert = detail::find_element(h, "vertex");
  if (!vert) fail(p, "no 'vertex' element");
  const bool colour = detail::find_property(*vert, "red") >= 0 && detail::find_property(*vert, "green") >= 0 &&
                      detail::find_property(*vert, "blue") >= 0;
  std::vector<std::string> names = {"x", "y", "z"};
  if (colour) names.insert(names.end(), {"red", "green", "blue"});
  std::vector<detail::PlyType> types;
  const std::vector<float> cols = detail::read_vertex_columns(in, h, p, names, &types);
  PointCloud pc;
  const std::size_t n = vert->count, nc = names.size();
  pc.xyz.resize(3 * n);
  if (colour) pc.rgb.resize(3 * n);
  float colour_scale[3] = {1, 1, 1};
  if (colour)
    for (int c = 0; c < 3; ++c) {
      const auto t = types[3 + std::size_t(c)];
      if (t == detail::PlyType::u8) colour_scale[c] = 1.0f / 255.0f;
      else if (t == detail::PlyType::u16) colour_scale[c] = 1.0f / 65535.0f;
      else if (t != detail::PlyType::f32 && t != detail::PlyType::f64)
        fail(p, names[3 + std::size_t(c)], "colour must be uchar, ushort, float or double");
    }
  for (std::size_t i = 0; i < n; ++i) {
    for (int d = 0; d < 3; ++d) pc.xyz[3 * i + std::size_t(d)] = cols[i * nc + std::size_t(d)];
    if (colour)
      for (int c = 0; c < 3; ++c)
        pc.rgb[3 * i + std::size_t(c)] = std::clamp(cols[i * nc + 3 + std::size_t(c)] * colour_scale[c], 0.0f, 1.0f);
  }
  return pc;
}

/// Write a point cloud as binary little-endian PLY (x y z float, red green blue uchar when the
/// cloud has colour), atomically. For tests, the synthetic generator and COLMAP conversion.
inline void write_point_cloud(const std::filesystem::path& p, const PointCloud& pc) {
  if (pc.xyz.size() % 3 != 0) fail(p, "xyz", "size is not a multiple of 3");
  if (pc.has_colour() && pc.rgb.size() != pc.xyz.size()) fail(p, "rgb", "size does not match xyz");
  std::string out = cat("ply\nformat binary_little_endian 1.0\ncomment written by msgs\nelement vertex ", pc.size(),
                        "\nproperty float x\nproperty float y\nproperty float z\n");
  if (pc.has_colour()) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "end_header\n";
  for (std::size_t i = 0; i < pc.size(); ++i) {
    for (int d = 0; d < 3; ++d) {
      const float v = pc.xyz[3 * i + std::size_t(d)];
      if (!std::isfinite(v)) fail(p, "xyz", cat("point ", i, " is not finite"));
      detail::put_f32_le(out, v);
    }
    if (pc.has_colour())
      for (int c = 0; c < 3; ++c) {
        const float v = std::clamp(pc.rgb[3 * i + std::size_t(c)], 0.0f, 1.0f);
        out.push_back(static_cast<char>(static_cast<unsigned char>(std::lround(std::isnan(v) ? 0.0f : v * 255.0f))));
      }
  }
  write_bytes_atomic(p, out.data(), out.size());
}

}  // namespace msgs::io
