// examples/export_index.hpp
// The spectral indices of `msgs view` (view_api.hpp: formula, bands, colour-scale range) as
// msgs::IndexSpec for `msgs export --index`, so both show an index the same way.
#pragma once

#include <string>

#include <msgs/export.hpp>

#include "view_api.hpp"

namespace msgs::cli {

/// "ndvi", "ndre", "gndvi", "ndwi", "savi" -> the viewer's definition; ExportError otherwise.
inline IndexSpec export_index(const std::string& id) {
  for (const view::IndexInfo& info : view::indices()) {
    if (id != info.id) continue;
    IndexSpec spec;
    spec.name = info.label;
    spec.band_a = info.a;
    spec.band_b = info.b;
    const view::Index idx = info.index;
    spec.value = [idx](float a, float b) { return view::index_value(idx, a, b); };
    spec.lo = view::index_lo;
    spec.hi = view::index_hi;
    return spec;
  }
  std::string known;
  for (const view::IndexInfo& info : view::indices()) known += (known.empty() ? "" : ", ") + std::string(info.id);
  throw ExportError("unknown index '" + id + "' (expected one of: " + known + ")");
}

}  // namespace msgs::cli
