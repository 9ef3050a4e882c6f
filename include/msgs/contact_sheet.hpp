// include/msgs/contact_sheet.hpp
// Comparing pictures: error maps on the sequential colour scale and contact sheets, a grid of
// images (ground truth | render | error per row) in one picture, optionally with words: row
// labels, column titles and legends with their values (text.hpp).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "colormap.hpp"
#include "detail/image_checks.hpp"
#include "image.hpp"
#include "text.hpp"

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
/// The labelled layout adds the words' places (all 0 / empty / -1 without labels).
struct SheetLayout {
  int width = 0, height = 0;
  std::vector<int> col_x, col_w;  // [columns]
  std::vector<int> row_y, row_h;  // [rows]
  int text_px = 0;                ///< size of the words, pixels per em
  int line_h = 0;                 ///< height of a line of words (TextRenderer::line_height)
  int legend_h = 0;               ///< height of a legend strip (legend_metrics)
  int label_x = 0, label_w = 0;   ///< row labels: columns [label_x, label_x + label_w)
  std::vector<int> heading_y;     ///< [rows] top of the column titles' line above row r; -1 = none
  std::vector<int> legend_y;      ///< [rows] top of the legend strips below row r; -1 = none
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


/// The words of a contact sheet; every part is optional.
struct SheetLabels {
  /// Column titles on a line of their own above row `row`, one per column ("" = none).
  struct Heading {
    std::size_t row = 0;
    std::vector<std::string> titles;
  };
  /// A colour scale with its values (legend_strip) below row `row`, as wide as column `column`.
  struct Legend {
    std::size_t row = 0, column = 0;
    Colormap cm = Colormap::sequential;
    float lo = 0.0f, hi = 1.0f;
  };
  std::vector<std::string> rows;  ///< [rows] label left of each row, vertically centred ("" = none)
  std::vector<Heading> headings;
  std::vector<Legend> legends;
};

/// Layout of a labelled contact sheet, from the top: `gap`; per row r, when a heading names r,
/// its line (heading_y[r], line_h tall) and `gap`; the row (row_y[r]) and `gap`; when legends
/// name r, their strip (legend_y[r], legend_h tall) and `gap`. From the left: `gap`, the row
/// labels' column (label_x, label_w wide) and `gap` when any row has a label, then the cells'
/// columns as in the unlabelled layout. Words are text_px pixels per em: label_px of the widest
/// column. Without `text` (nullptr) the labels take no room: the unlabelled layout.
inline SheetLayout contact_sheet_layout(const SheetCells& rows, int gap, const SheetLabels& labels,
                                        const TextRenderer* text) {
  SheetLayout L = contact_sheet_layout(rows, gap);
  L.heading_y.assign(rows.size(), -1);
  L.legend_y.assign(rows.size(), -1);
  if (!text) return L;
  for (const auto& h : labels.headings)
    if (h.row >= rows.size()) throw std::invalid_argument("contact_sheet: a heading above row " + std::to_string(h.row) + " of " + std::to_string(rows.size()));
  for (const auto& l : labels.legends)
    if (l.row >= rows.size() || l.column >= L.col_w.size())
      throw std::invalid_argument("contact_sheet: a legend below cell (" + std::to_string(l.row) + ", " +
                                  std::to_string(l.column) + ") outside the grid");
  L.text_px = label_px(*std::max_element(L.col_w.begin(), L.col_w.end()));
  L.line_h = text->line_height(L.text_px);
  L.legend_h = legend_metrics(L.text_px, text).height();
  for (std::size_t r = 0; r < rows.size() && r < labels.rows.size(); ++r)
    L.label_w = std::max(L.label_w, text_width(*text, labels.rows[r], L.text_px));
  L.label_x = gap;
  const int shift = L.label_w > 0 ? L.label_w + gap : 0;
  for (int& x : L.col_x) x += shift;
  L.width += shift;
  int y = gap;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    for (const auto& h : labels.headings)
      if (h.row == r && L.heading_y[r] < 0) {
        L.heading_y[r] = y;
        y += L.line_h + gap;
      }
    L.row_y[r] = y;
    y += L.row_h[r] + gap;
    for (const auto& l : labels.legends)
      if (l.row == r && L.legend_y[r] < 0) {
        L.legend_y[r] = y;
        y += L.legend_h + gap;
      }
  }
  L.height = std::max(1, y);
  return L;
}

/// A contact sheet with words (see the labelled contact_sheet_layout): row labels, column titles
/// centred over their columns (smaller, down to 3/4 of text_px, when a title is wider than its
/// column) and legends. Words are white on a dark `fill` (< 0.5), black on a light one; legends
/// sit on `fill` too. `text` nullptr: the unlabelled sheet.
inline Image<float> contact_sheet(const SheetCells& rows, const SheetLabels& labels, int gap = 4, float fill = 1.0f,
                                  const TextRenderer* text = default_text()) {
  const SheetLayout L = contact_sheet_layout(rows, gap, labels, text);
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
  if (!text) return out;
  const float ink = fill < 0.5f ? 1.0f : 0.0f;
  const std::array<float, 3> colour{ink, ink, ink};
  for (std::size_t r = 0; r < rows.size() && r < labels.rows.size(); ++r)
    (void)draw_text(out, *text, labels.rows[r], L.text_px, L.label_x, L.row_y[r] + (L.row_h[r] - L.line_h) / 2, colour);
  for (const auto& h : labels.headings)
    for (std::size_t c = 0; c < h.titles.size() && c < L.col_w.size(); ++c) {
      int px = L.text_px, w = text_width(*text, h.titles[c], px);
      while (w > L.col_w[c] && px > (L.text_px * 3) / 4) w = text_width(*text, h.titles[c], --px);
      // A smaller title sits on the line's baseline, as the others do.
      const int y = L.heading_y[h.row] + text->ascent(L.text_px) - text->ascent(px);
      (void)draw_text(out, *text, h.titles[c], px, L.col_x[c] + (L.col_w[c] - w) / 2, y, colour);
    }
  for (const auto& l : labels.legends) {
    const Image<float> strip = legend_strip(L.col_w[l.column], l.cm, l.lo, l.hi, text, L.text_px, fill, ink);
    for (int y = 0; y < strip.height; ++y)
      for (int x = 0; x < strip.width; ++x)
        for (int k = 0; k < 3; ++k) out.at(L.col_x[l.column] + x, L.legend_y[l.row] + y, k) = strip.at(x, y, k);
  }
  return out;
}

/// Compose `rows` into one RGB image [height, width, 3] (see contact_sheet_layout); each image
/// sits at the top-left of its cell, grey images are replicated to RGB, the rest is `fill`.
inline Image<float> contact_sheet(const SheetCells& rows, int gap = 4, float fill = 1.0f) {
  return contact_sheet(rows, SheetLabels{}, gap, fill, nullptr);  // without text: the grid alone
}

}  // namespace msgs
