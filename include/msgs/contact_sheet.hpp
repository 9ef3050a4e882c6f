// include/msgs/contact_sheet.hpp
// Comparing pictures: error maps on the sequential colour scale and contact sheets, a grid of
// images (ground truth | render | error per row) in one picture.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "colormap.hpp"
#include "detail/image_checks.hpp"
#include "image.hpp"

namespace msgs {

/// Default full-scale value of error maps: a mean absolute error of 0.25 shows as white.
inline constexpr float default_error_scale = 0.25f;

/// Per-pixel mean over channels of |render - reference|, shown on the sequential scale from 0
/// (black) to `scale` (white), [H, W, 3]. The images must have the same shape.
inline Image<float> error_map(const Image<float>& render, const Image<float>& reference,
                              float scale = default_error_scale) {
  detail::check_same_size(render, reference, "error_map", "render", "reference");
  if (render.channels != reference.channels || render.channels < 1)
    throw std::invalid_argument("error_map: render has " + std::to_string(render.channels) + " channels, reference " +
                                std::to_string(reference.channels));
  if (!(scale > 0) || !std::isfinite(scale)) throw std::invalid_argument("error_map: scale must be finite and > 0");
  Image<float> err(render.width, render.height, 1);
  const std::size_t C = std::size_t(render.channels);
  for (std::size_t p = 0; p < render.pixels(); ++p) {
    double s = 0;
    for (std::size_t c = 0; c < C; ++c) s += std::abs(double(render.data[p * C + c]) - double(reference.data[p * C + c]));
    err.data[p] = float(s / double(C));
  }
  return colourize(err, Colormap::sequential, 0.0f, scale);
}

/// Where the cells of a contact sheet go. Column c spans [col_x[c], col_x[c] + col_w[c]), row r
/// spans [row_y[r], row_y[r] + row_h[r]); `gap` pixels around and between cells.
struct SheetLayout {
  int width = 0, height = 0;
  std::vector<int> col_x, col_w;  // [columns]
  std::vector<int> row_y, row_h;  // [rows]
};

/// Rows of cells, each an image (1 or 3 channels) or nullptr for an empty cell.
using SheetCells = std::vector<std::vector<const Image<float>*>>;

/// Layout of a contact sheet: a column is as wide as its widest image, a row as tall as its
/// tallest, so bands of different resolutions line up in a grid.
inline SheetLayout contact_sheet_layout(const SheetCells& rows, int gap) {
  if (rows.empty()) throw std::invalid_argument("contact_sheet: no rows");
  if (gap < 0) throw std::invalid_argument("contact_sheet: gap must be >= 0");
  std::size_t cols = 0;
  for (const auto& r : rows) cols = std::max(cols, r.size());
  SheetLayout L;
  L.col_w.assign(cols, 0);
  L.row_h.assign(rows.size(), 0);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (std::size_t c = 0; c < rows[r].size(); ++c)
      if (const Image<float>* im = rows[r][c]) {
        L.col_w[c] = std::max(L.col_w[c], im->width);
        L.row_h[r] = std::max(L.row_h[r], im->height);
      }
  int x = gap, y = gap;
  for (int w : L.col_w) { L.col_x.push_back(x); x += w + gap; }
  for (int h : L.row_h) { L.row_y.push_back(y); y += h + gap; }
  L.width = std::max(1, x);
  L.height = std::max(1, y);
  return L;
}

/// Compose `rows` into one RGB image [height, width, 3] (see contact_sheet_layout); each image
/// sits at the top-left of its cell, grey images are replicated to RGB, the rest is `fill`.
inline Image<float> contact_sheet(const SheetCells& rows, int gap = 4, float fill = 1.0f) {
  const SheetLayout L = contact_sheet_layout(rows, gap);
  Image<float> out(L.width, L.height, 3, fill);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      const Image<float>* im = rows[r][c];
      if (!im) continue;
      const Image<float> rgb = to_rgb(*im);
      for (int y = 0; y < rgb.height; ++y)
        for (int x = 0; x < rgb.width; ++x)
          for (int k = 0; k < 3; ++k) out.at(L.col_x[c] + x, L.row_y[r] + y, k) = rgb.at(x, y, k);
    }
  return out;
}

}  // namespace msgs
