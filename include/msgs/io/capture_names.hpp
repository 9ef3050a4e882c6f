// include/msgs/io/capture_names.hpp
// Recognising multi-band captures from file names: which files belong to one capture (one trigger
// of the multi-lens camera) and which band each file holds, for the naming schemes of MicaSense
// RedEdge/Altum, DJI Mavic 3M, DJI P4 Multispectral and Parrot Sequoia, or for explicit user
// patterns ("IMG_*_2.tif=MS_G").
// Pure string work (no file access), so odd names of any kind give a clear answer, never a crash.
#pragma once

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "msgs/io/bands.hpp"
#include "msgs/io/error.hpp"

namespace msgs::io {

/// What a file name says about an image.
struct NameMatch {
  std::string capture;      ///< capture key within its folder: all bands of one capture share it
  std::string band;         ///< msgs band id (D, MS_G, MS_R, MS_RE, MS_NIR); empty when msgs has no slot
  std::string camera_band;  ///< the camera's own name of the band ("Blue", "GRE", "MS_NIR", "band 6")
};

/// One explicit pattern: a file-name glob (`*` any run, `?` one character, case-insensitive) and
/// the band its files hold. What the wildcards match is the capture key, so every pattern of a
/// set must leave the capture number (and only that) to the wildcards.
struct BandPattern {
  std::string pattern;
  std::string band;  ///< msgs band id, or empty for "skip these files"
};

/// The built-in camera naming schemes.
inline const std::vector<std::string>& known_cameras() {
  static const std::vector<std::string> c = {"micasense", "dji", "p4m", "sequoia"};
  return c;
}

/// Human-readable form of a camera's naming scheme, for reports and errors.
inline std::string camera_pattern_text(std::string_view camera) {
  if (camera == "micasense")
    return "MicaSense RedEdge/Altum: IMG_<nnnn>_<1..10>.tif (1 Blue, 2 Green, 3 Red, 4 NIR, 5 RedEdge)";
  if (camera == "dji")
    return "DJI Mavic 3M: DJI_<yyyymmddhhmmss>_<nnnn>_<D|MS_G|MS_R|MS_RE|MS_NIR>.JPG/.TIF";
  if (camera == "p4m")
    return "DJI P4 Multispectral: DJI_<nnn><0..5>.JPG/.TIF (0 RGB, 1 Blue, 2 Green, 3 Red, 4 RedEdge, 5 NIR)";
  if (camera == "sequoia")
    return "Parrot Sequoia: IMG_<yymmdd>_<hhmmss>_<nnnn>_<GRE|RED|REG|NIR|RGB>.TIF/.JPG";
  return std::string(camera);
}

namespace detail {

inline char lower_ascii(char c) { return static_cast<char>(std::tolower(static_cast<unsigned char>(c))); }

inline bool iequal(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (lower_ascii(a[i]) != lower_ascii(b[i])) return false;
  return true;
}

inline bool all_digits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  return true;
}

/// Split "a_b_c" on '_'.
inline std::vector<std::string_view> split_underscore(std::string_view s) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= s.size(); ++i)
    if (i == s.size() || s[i] == '_') {
      out.push_back(s.substr(start, i - start));
      start = i + 1;
    }
  return out;
}

/// Stem and lower-case extension of a file name ("IMG_0001_1.TIF" -> "IMG_0001_1", ".tif").
inline void stem_ext(std::string_view name, std::string_view& stem, std::string& ext) {
  const std::size_t dot = name.rfind('.');
  stem = dot == std::string_view::npos ? name : name.substr(0, dot);
  ext.clear();
  if (dot != std::string_view::npos)
    for (char c : name.substr(dot)) ext.push_back(lower_ascii(c));
}

inline bool is_tiff_ext(const std::string& e) { return e == ".tif" || e == ".tiff"; }
inline bool is_jpeg_ext(const std::string& e) { return e == ".jpg" || e == ".jpeg"; }

inline std::optional<NameMatch> match_micasense(std::string_view name) {
  std::string_view stem;
  std::string ext;
  stem_ext(name, stem, ext);
  if (!is_tiff_ext(ext)) return std::nullopt;
  const auto parts = split_underscore(stem);
  if (parts.size() != 3 || !iequal(parts[0], "IMG") || parts[1].size() < 4 || !all_digits(parts[1]) ||
      parts[2].size() > 2 || !all_digits(parts[2]))
    return std::nullopt;
  const int band = std::stoi(std::string(parts[2]));
  if (band < 1 || band > 10) return std::nullopt;
  NameMatch m;
  m.capture = cat("IMG_", parts[1]);
  // RedEdge / RedEdge-M / Altum band order. Bands 6..10 are Altum's thermal (6) or the second
  // camera of a RedEdge-MX Dual (444, 531, 650, 705, 740 nm): which one the name cannot tell, and
  // msgs has no slot for either (two greens in one capture would collide).
  static const char* names[] = {"Blue", "Green", "Red", "NIR", "RedEdge"};
  static const char* ids[] = {"", "MS_G", "MS_R", "MS_NIR", "MS_RE"};
  if (band <= 5) {
    m.camera_band = names[band - 1];
    m.band = ids[band - 1];
  } else {
    m.camera_band = cat("band ", band, " (Altum thermal or RedEdge-MX Dual second camera)");
  }
  return m;
}

inline std::optional<NameMatch> match_dji(std::string_view name) {
  std::string_view stem;
  std::string ext;
  stem_ext(name, stem, ext);
  if (!is_tiff_ext(ext) && !is_jpeg_ext(ext)) return std::nullopt;
  const auto parts = split_underscore(stem);
  if (parts.size() < 4 || !iequal(parts[0], "DJI") || parts[1].size() != 14 || !all_digits(parts[1]) ||
      parts[2].size() != 4 || !all_digits(parts[2]))
    return std::nullopt;
  std::string suffix;
  for (std::size_t i = 3; i < parts.size(); ++i) suffix += cat(i > 3 ? "_" : "", std::string(parts[i]));
  for (char& c : suffix) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  NameMatch m;
  m.capture = std::string(parts[2]);
  m.camera_band = suffix;
  if (suffix == "D") m.band = "D";
  else if (suffix == "MS_G" || suffix == "MS_R" || suffix == "MS_RE" || suffix == "MS_NIR") m.band = suffix;
  else if (suffix == "T" || suffix == "W" || suffix == "Z") m.camera_band = cat(suffix, suffix == "T" ? " (thermal)" : " (wide/zoom RGB of another drone)");
  else return std::nullopt;
  return m;
}

/// DJI P4 Multispectral: one capture is six files numbered in a run of ten, DJI_0010.JPG (RGB),
/// DJI_0011.TIF (blue) .. DJI_0015.TIF (NIR), the next DJI_0020.JPG ..: the last digit is the band.
inline std::optional<NameMatch> match_dji_p4m(std::string_view name) {
  std::string_view stem;
  std::string ext;
  stem_ext(name, stem, ext);
  const bool tiff = is_tiff_ext(ext);
  if (!tiff && !is_jpeg_ext(ext)) return std::nullopt;
  const auto parts = split_underscore(stem);
  if (parts.size() != 2 || !iequal(parts[0], "DJI") || parts[1].size() != 4 || !all_digits(parts[1]))
    return std::nullopt;
  const int band = parts[1][3] - '0';
  if (band > 5 || (band == 0) == tiff) return std::nullopt;  // the RGB image is the JPEG, the others TIFFs
  static const char* names[] = {"RGB", "Blue", "Green", "Red", "RedEdge", "NIR"};
  static const char* ids[] = {"D", "", "MS_G", "MS_R", "MS_RE", "MS_NIR"};
  NameMatch m;
  m.capture = cat("DJI_", std::string(parts[1].substr(0, 3)));
  m.camera_band = names[band];
  m.band = ids[band];
  return m;
}

inline std::optional<NameMatch> match_sequoia(std::string_view name) {
  std::string_view stem;
  std::string ext;
  stem_ext(name, stem, ext);
  if (!is_tiff_ext(ext) && !is_jpeg_ext(ext)) return std::nullopt;
  const auto parts = split_underscore(stem);
  if (parts.size() != 5 || !iequal(parts[0], "IMG") || parts[1].size() != 6 || !all_digits(parts[1]) ||
      parts[2].size() != 6 || !all_digits(parts[2]) || parts[3].size() != 4 || !all_digits(parts[3]))
    return std::nullopt;
  static const std::pair<const char*, const char*> bands[] = {
      {"GRE", "MS_G"}, {"RED", "MS_R"}, {"REG", "MS_RE"}, {"NIR", "MS_NIR"}, {"RGB", "D"}};
  for (const auto& [suffix, id] : bands)
    if (iequal(parts[4], suffix)) {
      NameMatch m;
      m.capture = std::string(parts[3]);
      m.camera_band = suffix;
      m.band = id;
      return m;
    }
  return std::nullopt;
}

}  // namespace detail

/// Match a file name (no folder) against a built-in camera's naming scheme ("micasense", "dji",
/// "sequoia"); nullopt when it does not follow the scheme. Throws std::invalid_argument for an
/// unknown camera name.
inline std::optional<NameMatch> match_camera_name(std::string_view camera, std::string_view file_name) {
  if (camera == "micasense") return detail::match_micasense(file_name);
  if (camera == "dji") return detail::match_dji(file_name);
  if (camera == "p4m") return detail::match_dji_p4m(file_name);
  if (camera == "sequoia") return detail::match_sequoia(file_name);
  throw std::invalid_argument(cat("unknown camera '", std::string(camera), "' (expected auto, micasense, dji, p4m or sequoia)"));
}

/// Case-insensitive glob match of `name` against `pattern` (`*` any run of characters, `?` one).
/// On success `groups` (when given) receives what each wildcard matched, every `*` taking as few
/// characters as it can. Linear-memory dynamic programming: no exponential backtracking on
/// patterns like "*a*a*a*b". Names over 4096 or patterns over 512 characters never match.
inline bool glob_match(std::string_view pattern, std::string_view name, std::vector<std::string>* groups = nullptr) {
  if (pattern.size() > 512 || name.size() > 4096) return false;
  const std::size_t m = pattern.size(), n = name.size();
  // ok[i][j]: pattern[i..] matches name[j..]; filled backwards, (m + 1) x (n + 1) bits.
  std::vector<std::vector<char>> ok(m + 1, std::vector<char>(n + 1, 0));
  ok[m][n] = 1;
  for (std::size_t ii = m; ii-- > 0;) {
    for (std::size_t jj = n + 1; jj-- > 0;) {
      const char pc = pattern[ii];
      if (pc == '*') ok[ii][jj] = ok[ii + 1][jj] || (jj < n && ok[ii][jj + 1]);
      else if (jj < n && (pc == '?' || detail::lower_ascii(pc) == detail::lower_ascii(name[jj])))
        ok[ii][jj] = ok[ii + 1][jj + 1];
    }
  }
  if (!ok[0][0]) return false;
  if (groups) {
    groups->clear();
    std::size_t j = 0;
    for (std::size_t i = 0; i < m; ++i) {
      if (pattern[i] == '*') {
        std::size_t k = j;
        while (!ok[i + 1][k]) ++k;  // shortest extent that still lets the rest match
        groups->emplace_back(name.substr(j, k - j));
        j = k;
      } else {
        if (pattern[i] == '?') groups->emplace_back(name.substr(j, 1));
        ++j;
      }
    }
  }
  return true;
}

/// Parse "PATTERN=ID,PATTERN=ID,..." (ID a msgs band id, or "skip" / "-" to ignore those files).
/// Throws std::invalid_argument saying which entry is wrong and what was expected.
inline std::vector<BandPattern> parse_band_patterns(std::string_view spec) {
  std::vector<BandPattern> out;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= spec.size(); ++i) {
    if (i < spec.size() && spec[i] != ',') continue;
    const std::string entry(spec.substr(start, i - start));
    start = i + 1;
    if (entry.empty()) continue;
    const std::size_t eq = entry.rfind('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == entry.size())
      throw std::invalid_argument(cat("--bands entry '", entry, "' is not PATTERN=ID (e.g. IMG_*_2.tif=MS_G)"));
    BandPattern p{entry.substr(0, eq), entry.substr(eq + 1)};
    if (p.pattern.find_first_of("*?") == std::string::npos)
      throw std::invalid_argument(cat("--bands pattern '", p.pattern,
                                      "' has no * or ?: the wildcards must match the capture number"));
    if (p.pattern.find_first_of("/\\") != std::string::npos)
      throw std::invalid_argument(cat("--bands pattern '", p.pattern, "' contains a folder separator (patterns match file names only)"));
    if (p.band == "skip" || p.band == "-") {
      p.band.clear();
    } else if (!find_band(p.band)) {
      std::string known;
      for (const auto& b : standard_bands()) known += cat(known.empty() ? "" : ", ", b.id);
      throw std::invalid_argument(cat("--bands entry '", entry, "': unknown band '", p.band, "' (expected ", known, ", or skip)"));
    }
    out.push_back(std::move(p));
  }
  if (out.empty()) throw std::invalid_argument("--bands is empty (expected PATTERN=ID,...)");
  return out;
}

/// Match a file name against explicit patterns; the first matching pattern wins.
inline std::optional<NameMatch> match_patterns(const std::vector<BandPattern>& patterns, std::string_view file_name) {
  std::vector<std::string> groups;
  for (const auto& p : patterns) {
    if (!glob_match(p.pattern, file_name, &groups)) continue;
    NameMatch m;
    for (std::size_t g = 0; g < groups.size(); ++g) m.capture += cat(g ? "|" : "", groups[g]);
    m.band = p.band;
    m.camera_band = p.band.empty() ? cat("pattern ", p.pattern) : p.band;
    return m;
  }
  return std::nullopt;
}

/// The files of one capture.
struct CaptureFiles {
  std::string key;                                     ///< folder + capture key ("flight1/IMG_0001")
  std::map<std::string, std::filesystem::path> bands;  ///< msgs band id -> file (relative to the scan root)
};

/// The result of scanning a folder's file names.
struct CaptureScan {
  std::string camera;                   ///< micasense | dji | p4m | sequoia | patterns
  std::vector<CaptureFiles> captures;   ///< sorted by key
  /// Files of bands msgs has no slot for, by the camera's band name.
  std::map<std::string, std::vector<std::filesystem::path>> skipped;
  std::vector<std::filesystem::path> unmatched;  ///< files no pattern recognised
  std::vector<std::string> patterns_tried;       ///< human-readable, for reports and errors

  /// Number of images per msgs band.
  std::map<std::string, int> band_counts() const {
    std::map<std::string, int> n;
    for (const auto& c : captures)
      for (const auto& [b, f] : c.bands) n[b] += 1;
    return n;
  }
};

/// Group `files` (paths relative to `root`, as found by a directory scan) into captures.
/// `camera`: "auto" (the built-in scheme that recognises most files), "micasense", "dji", "p4m",
/// "sequoia"; ignored when `patterns` is not empty. Throws IoError (naming `root`) when nothing is
/// recognised, saying which patterns were tried, and when two files claim the same band of the same
/// capture; std::invalid_argument for an unknown camera name.
inline CaptureScan scan_capture_names(const std::filesystem::path& root, const std::vector<std::filesystem::path>& files,
                                      std::string_view camera, const std::vector<BandPattern>& patterns = {}) {
  CaptureScan scan;
  std::vector<std::string> candidates;
  if (!patterns.empty()) {
    scan.camera = "patterns";
    for (const auto& p : patterns) scan.patterns_tried.push_back(cat(p.pattern, "=", p.band.empty() ? "skip" : p.band));
  } else if (camera == "auto") {
    candidates = known_cameras();
  } else {
    (void)match_camera_name(camera, "");  // validates the name
    candidates = {std::string(camera)};
  }
  if (patterns.empty()) {
    std::size_t best = 0;
    for (const auto& c : candidates) {
      scan.patterns_tried.push_back(camera_pattern_text(c));
      std::size_t hits = 0;
      for (const auto& f : files) hits += match_camera_name(c, f.filename().string()).has_value();
      if (hits > best) {
        best = hits;
        scan.camera = c;
      }
    }
  }
  auto match = [&](const std::filesystem::path& f) -> std::optional<NameMatch> {
    if (!patterns.empty()) return match_patterns(patterns, f.filename().string());
    if (scan.camera.empty()) return std::nullopt;
    return match_camera_name(scan.camera, f.filename().string());
  };
  std::map<std::string, CaptureFiles> by_key;
  for (const auto& f : files) {
    const auto m = match(f);
    if (!m) {
      scan.unmatched.push_back(f);
      continue;
    }
    if (m->band.empty()) {
      scan.skipped[m->camera_band].push_back(f);
      continue;
    }
    const std::string folder = f.parent_path().generic_string();
    const std::string key = folder.empty() ? m->capture : cat(folder, "/", m->capture);
    CaptureFiles& c = by_key[key];
    c.key = key;
    const auto [it, fresh] = c.bands.emplace(m->band, f);
    if (!fresh)
      fail(root, cat("two files for band ", m->band, " of capture '", key, "': '", it->second.generic_string(), "' and '",
                     f.generic_string(), "' (images of several flights in one folder? put each flight in its own sub-folder)"));
  }
  for (auto& [k, c] : by_key) scan.captures.push_back(std::move(c));
  if (scan.captures.empty()) {
    std::string tried, seen;
    for (const auto& t : scan.patterns_tried) tried += cat("\n  ", t);
    for (std::size_t i = 0; i < files.size() && i < 5; ++i) seen += cat(i ? ", " : "", files[i].generic_string());
    if (files.size() > 5) seen += cat(", ... (", files.size(), " files)");
    std::string skipped;
    for (const auto& [b, fs] : scan.skipped) skipped += cat(skipped.empty() ? "" : ", ", b, " (", fs.size(), " files)");
    fail(root, cat("no multi-band capture recognised among ", files.size(), " files",
                   files.empty() ? std::string() : cat(" (", seen, ")"),
                   skipped.empty() ? std::string() : cat("; only bands without a msgs slot: ", skipped),
                   "; file-name patterns tried:", tried,
                   "\n  give explicit patterns with --bands PATTERN=ID,... (e.g. --bands 'IMG_*_2.tif=MS_G,IMG_*_3.tif=MS_R')"));
  }
  return scan;
}

}  // namespace msgs::io
