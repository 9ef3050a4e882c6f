// include/msgs/io/panel_list.hpp
// The list of calibration-panel pictures a user gives `msgs import --panels FILE`, for cameras that
// do not mark their panel pictures (DJI, Parrot, MicaSense firmware that could not read the panel):
// which images show the panel, where its reflecting area lies in each, and its reflectance.
//
//   {
//     "albedo": 0.49,                        (optional: for every picture without its own)
//     "pictures": [
//       {"file": "DJI_0021_MS_G.TIF",         (relative to --images)
//        "area": [[412, 300], [380, 301], [381, 333], [413, 332]],   (corners, x and y in pixels)
//        "albedo": 0.5},                      (optional)
//       ...
//     ]
//   }
//
// The corners go once around a convex area, in either direction, in the image as stored. A picture
// that shows several panels (a grey panel and a dark tarp side by side, for an empirical line) is
// listed once for each, with its area and albedo.
#pragma once

#include <cmath>
#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "msgs/io/calibration_panel.hpp"
#include "msgs/io/error.hpp"
#include "msgs/io/file.hpp"

namespace msgs::io {

/// One listed picture of a calibration panel.
struct PanelPicture {
  std::filesystem::path file;  ///< relative to the images folder, normalised
  PanelArea area{};
  std::optional<double> albedo;  ///< its own, else the list's (nullopt: neither)
};

/// Parse a panel list (`text`, read from `file`, which errors name). IoError naming the field for
/// anything that is not as above.
inline std::vector<PanelPicture> parse_panel_list(std::string_view text, const std::filesystem::path& file) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    fail(file, cat("invalid JSON: ", e.what()));
  }
  const auto albedo_of = [&](const nlohmann::json& v, const std::string& field) {
    if (!v.is_number() || !(v.get<double>() > 0.0 && v.get<double>() <= 1.0))
      fail(file, field, "expected the panel's reflectance, a number in (0, 1]");
    return v.get<double>();
  };
  if (!j.is_object() || !j.contains("pictures") || !j["pictures"].is_array() || j["pictures"].empty())
    fail(file, "pictures", "expected a non-empty list of {\"file\", \"area\"} objects (see msgs import --help)");
  std::optional<double> common;
  if (j.contains("albedo")) common = albedo_of(j["albedo"], "albedo");
  std::vector<PanelPicture> out;
  std::set<std::pair<std::string, PanelArea>> seen;  // (file, area)
  for (std::size_t i = 0; i < j["pictures"].size(); ++i) {
    const nlohmann::json& e = j["pictures"][i];
    const std::string at = cat("pictures[", i, "]");
    if (!e.is_object()) fail(file, at, "expected an object with \"file\" and \"area\"");
    if (!e.contains("file") || !e["file"].is_string() || e["file"].get<std::string>().empty())
      fail(file, at + ".file", "expected the picture's path relative to --images");
    PanelPicture p;
    p.file = std::filesystem::path(e["file"].get<std::string>()).lexically_normal();
    const std::string name = p.file.generic_string();
    if (p.file.is_absolute() || p.file.has_root_name() || name == ".." || name.rfind("../", 0) == 0)
      fail(file, at + ".file", cat("'", name.substr(0, 200), "' is not a path inside --images (give it relative to it)"));
    const nlohmann::json* a = e.contains("area") ? &e["area"] : nullptr;
    bool ok = a && a->is_array() && a->size() == 4;
    for (std::size_t k = 0; ok && k < 4; ++k) {
      const nlohmann::json& c = (*a)[k];
      ok = c.is_array() && c.size() == 2 && c[0].is_number() && c[1].is_number() &&
           std::isfinite(c[0].get<double>()) && std::isfinite(c[1].get<double>());
      if (ok) p.area[k] = {c[0].get<double>(), c[1].get<double>()};
    }
    if (!ok) fail(file, at + ".area", "expected four [x, y] corners of the panel's reflecting area, in pixels");
    if (!convex_quad(p.area))
      fail(file, at + ".area", "the four corners do not go once around a convex area (list them in order around it)");
    if (!seen.insert({name, p.area}).second)
      fail(file, at + ".file", cat("'", name.substr(0, 200), "' is listed twice with the same area"));
    p.albedo = e.contains("albedo") ? std::optional<double>(albedo_of(e["albedo"], at + ".albedo")) : common;
    out.push_back(std::move(p));
  }
  return out;
}

/// parse_panel_list of the file `file`.
inline std::vector<PanelPicture> read_panel_list(const std::filesystem::path& file) {
  return parse_panel_list(read_text(file), file);
}

}  // namespace msgs::io
