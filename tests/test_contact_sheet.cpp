// tests/test_contact_sheet.cpp
// Tests of the labelled contact sheet (contact_sheet.hpp) and of legend strips (colormap.hpp):
// where the row labels, column titles and legends go, that words never cover a cell, and that
// without a text renderer the sheet is the unlabelled one. A block "font" (every character a
// filled box) makes the geometry exact and independent of FreeType. Includes contact_sheet.hpp
// alone, so it also checks that the header compiles on its own.
#include <doctest/doctest.h>

#include <msgs/contact_sheet.hpp>

#include <string>
#include <vector>

namespace test_contact_sheet {
using msgs::Image;

namespace {

/// Every character a box `px / 2` wide and `px` tall, from row 1 of a line px + 2 tall.
class BlockText final : public msgs::TextRenderer {
 public:
  Image<float> render(std::string_view s, int px) const override {
    check_px(px);
    const int cw = std::max(1, px / 2);
    Image<float> out(int(s.size()) * cw, line_height(px), 1, 0.0f);
    for (int x = 0; x < out.width; ++x)
      for (int y = 1; y <= px; ++y) out.at(x, y, 0) = (x % cw == cw - 1) ? 0.0f : 1.0f;  // a gap between boxes
    return out;
  }
  int line_height(int px) const override { return px + 2; }
  int ascent(int px) const override { return px + 1; }
  std::string describe() const override { return "blocks"; }
};

/// True when any pixel of the rectangle [x0, x1) x [y0, y1) has channel 0 equal to v.
bool any_equal(const Image<float>& img, int x0, int y0, int x1, int y1, float v) {
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      if (img.at(x, y, 0) == v) return true;
  return false;
}

}  // namespace

TEST_CASE("label_px: 1/40 of the cell width, at least 12, at most 200") {
  CHECK(msgs::label_px(64) == msgs::min_label_px);
  CHECK(msgs::label_px(96) == 12);
  CHECK(msgs::label_px(800) == 20);
  CHECK(msgs::label_px(1800) == 45);
  CHECK(msgs::label_px(100000) == 200);
}

TEST_CASE("labelled contact sheet: labels' column, heading lines and legend strips where documented") {
  const BlockText text;
  // Two rows of a 3-column grid: 100x40 cells, grey 0.5 (row 0) and 0.8 (row 1).
  const Image<float> a(100, 40, 1, 0.5f), b(100, 40, 3, 0.8f);
  const msgs::SheetCells rows = {{&a, &a, &a}, {&b, &b, &b}};
  msgs::SheetLabels labels;
  labels.rows = {"RGB (D)", "NDVI"};
  labels.headings = {{0, {"ground truth", "render", "error"}}, {1, {"GT", "render", "difference"}}};
  labels.legends = {{0, 2, msgs::Colormap::sequential, 0.0f, 0.25f}, {1, 0, msgs::Colormap::diverging, -1.0f, 1.0f}};
  const int gap = 4;
  const msgs::SheetLayout L = msgs::contact_sheet_layout(rows, gap, labels, &text);
  const int px = msgs::label_px(100);
  REQUIRE(L.text_px == px);
  CHECK(L.line_h == px + 2);
  CHECK(L.legend_h == msgs::legend_metrics(px, &text).height());
  CHECK(L.label_x == gap);
  CHECK(L.label_w == 7 * (px / 2));  // "RGB (D)": the widest label
  // Columns move right by the labels' column and a gap; rows down by the lines above them.
  const int x0 = gap + L.label_w + gap;
  CHECK(L.col_x == std::vector<int>{x0, x0 + 104, x0 + 208});
  CHECK(L.heading_y == std::vector<int>{gap, gap + L.line_h + gap + 40 + gap + L.legend_h + gap});
  CHECK(L.row_y[0] == gap + L.line_h + gap);
  CHECK(L.legend_y[0] == L.row_y[0] + 40 + gap);
  CHECK(L.row_y[1] == L.heading_y[1] + L.line_h + gap);
  CHECK(L.legend_y[1] == L.row_y[1] + 40 + gap);
  CHECK(L.width == x0 + 3 * 100 + 3 * gap);
  CHECK(L.height == L.legend_y[1] + L.legend_h + gap);

  const float fill = 0.35f;
  const Image<float> s = msgs::contact_sheet(rows, labels, gap, fill, &text);
  REQUIRE(s.width == L.width);
  REQUIRE(s.height == L.height);
  // Cells are untouched by words.
  for (std::size_t r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c)
      for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 100; ++x) REQUIRE(s.at(L.col_x[std::size_t(c)] + x, L.row_y[r] + y, 1) == (r ? 0.8f : 0.5f));
  // Row labels: white ink (on a dark fill) in the labels' column, centred on the row, nowhere else there.
  for (std::size_t r = 0; r < 2; ++r) {
    const int ty = L.row_y[r] + (40 - L.line_h) / 2;
    const int w = int(labels.rows[r].size()) * (px / 2);
    CHECK(any_equal(s, L.label_x, ty, L.label_x + w, ty + L.line_h, 1.0f));
    CHECK_FALSE(any_equal(s, L.label_x, L.row_y[r], L.label_x + L.label_w, ty, 1.0f));                  // above
    CHECK_FALSE(any_equal(s, L.label_x, ty + L.line_h, L.label_x + L.label_w, L.row_y[r] + 40, 1.0f));  // below
    CHECK_FALSE(any_equal(s, L.label_x + w, ty, x0, ty + L.line_h, 1.0f));                               // right
  }
  // Column titles: centred over their column, on the heading line. "render" is 6 blocks wide.
  const int rw = 6 * (px / 2), rx = L.col_x[1] + (100 - rw) / 2;
  CHECK(any_equal(s, rx, L.heading_y[0], rx + rw, L.heading_y[0] + L.line_h, 1.0f));
  CHECK_FALSE(any_equal(s, L.col_x[1], L.heading_y[0], rx, L.heading_y[0] + L.line_h, 1.0f));
  CHECK_FALSE(any_equal(s, rx + rw, L.heading_y[0], L.col_x[2], L.heading_y[0] + L.line_h, 1.0f));
  CHECK(any_equal(s, L.col_x[0], L.heading_y[1], L.col_x[0] + 100, L.heading_y[1] + L.line_h, 1.0f));  // "GT"
  CHECK(any_equal(s, L.col_x[0], L.heading_y[0], L.col_x[0] + 100, L.heading_y[0] + L.line_h, 1.0f));
  // Legends: the strip sits below its row in its column; the bar's end colours at the ends.
  const msgs::LegendMetrics m = msgs::legend_metrics(px, &text);
  const int bar_y = L.legend_y[0] + m.pad;
  CHECK(s.at(L.col_x[2] + m.pad, bar_y, 0) == 0.0f);  // hot scale starts black
  CHECK(s.at(L.col_x[2] + 100 - m.pad - 1, bar_y, 1) == 1.0f);  // ... ends white
  CHECK(s.at(L.col_x[0] + 50, bar_y, 0) == fill);  // no legend under column 0 of row 0
  const auto red = msgs::colour_at(msgs::Colormap::diverging, 0.0f);
  CHECK(s.at(L.col_x[0] + m.pad, L.legend_y[1] + m.pad, 0) == red[0]);
  // The values ("-1", "0", "1") below the diverging bar in white.
  const int vy = L.legend_y[1] + m.pad + m.bar_h + m.pad;
  CHECK(any_equal(s, L.col_x[0], vy, L.col_x[0] + 100, vy + L.line_h, 1.0f));
}

TEST_CASE("labelled contact sheet without a text renderer: the unlabelled sheet") {
  const Image<float> a(20, 10, 3, 0.25f);
  const msgs::SheetCells rows = {{&a, &a}, {nullptr, &a}};
  msgs::SheetLabels labels;
  labels.rows = {"one", "two"};
  labels.headings = {{0, {"x", "y"}}};
  labels.legends = {{1, 1, msgs::Colormap::sequential, 0.0f, 1.0f}};
  const msgs::SheetLayout L = msgs::contact_sheet_layout(rows, 3, labels, nullptr);
  const msgs::SheetLayout U = msgs::contact_sheet_layout(rows, 3);
  CHECK(L.width == U.width);
  CHECK(L.height == U.height);
  CHECK(L.col_x == U.col_x);
  CHECK(L.row_y == U.row_y);
  CHECK(L.heading_y == std::vector<int>{-1, -1});
  CHECK(msgs::contact_sheet(rows, labels, 3, 0.5f, nullptr).data == msgs::contact_sheet(rows, 3, 0.5f).data);
  // No labels at all: the same as the unlabelled layout too.
  const BlockText text;
  const msgs::SheetLayout E = msgs::contact_sheet_layout(rows, 3, msgs::SheetLabels{}, &text);
  CHECK(E.width == U.width);
  CHECK(E.height == U.height);
  // Labels that point outside the grid are refused.
  msgs::SheetLabels bad;
  bad.legends = {{0, 5, msgs::Colormap::sequential, 0.0f, 1.0f}};
  CHECK_THROWS_AS((void)msgs::contact_sheet_layout(rows, 3, bad, &text), std::invalid_argument);
  bad.legends.clear();
  bad.headings = {{2, {"x"}}};
  CHECK_THROWS_AS((void)msgs::contact_sheet_layout(rows, 3, bad, &text), std::invalid_argument);
}

TEST_CASE("legend_strip and with_legend: bar, ticks and values; values left out when too narrow") {
  const BlockText text;
  const int px = 12;
  const msgs::LegendMetrics m = msgs::legend_metrics(px, &text);
  const Image<float> s = msgs::legend_strip(120, msgs::Colormap::diverging, -1.0f, 1.0f, &text, px);
  CHECK(s.width == 120);
  CHECK(s.height == m.height());
  const int ty = m.pad + m.bar_h + m.pad;  // top of the values' line
  CHECK(any_equal(s, 0, ty, 120, ty + m.text_h, 0.0f));   // black values
  CHECK_FALSE(any_equal(s, 0, 0, 120, m.pad, 0.0f));     // nothing above the bar
  // Too narrow for "-1", "0" and "1" side by side: no values, bar and ticks stay.
  const Image<float> n = msgs::legend_strip(12, msgs::Colormap::diverging, -1.0f, 1.0f, &text, px);
  CHECK_FALSE(any_equal(n, 0, ty, 12, ty + m.text_h, 0.0f));
  CHECK(any_equal(n, 0, m.pad + m.bar_h, 12, ty, 0.0f));  // ticks
  // Without text the strip has no value line.
  CHECK(msgs::legend_strip(120, msgs::Colormap::diverging, -1.0f, 1.0f, nullptr, px).height ==
        m.pad + m.bar_h + m.pad);

  const Image<float> rgb(200, 90, 3, 0.25f);
  const Image<float> lg = msgs::with_legend(rgb, msgs::Colormap::sequential, 0.0f, 0.5f, &text);
  CHECK(lg.width == 200);
  CHECK(lg.height == 90 + msgs::legend_metrics(msgs::label_px(200), &text).height());
  CHECK(lg.at(100, 45, 0) == 0.25f);
}

TEST_CASE("labelled contact sheet with the real font, where there is one") {
  const msgs::TextRenderer* text = msgs::default_text();
  if (!text) {
    MESSAGE("skipped: no text renderer");
    return;
  }
  const Image<float> a(64, 48, 1, 0.5f);
  const msgs::SheetCells rows = {{&a, &a, &a}};
  msgs::SheetLabels labels;
  labels.rows = {"red edge (MS_RE)"};
  labels.headings = {{0, {"ground truth", "render", "error"}}};
  labels.legends = {{0, 2, msgs::Colormap::sequential, 0.0f, 0.25f}};
  const msgs::SheetLayout L = msgs::contact_sheet_layout(rows, 4, labels, text);
  CHECK(L.text_px == msgs::min_label_px);
  CHECK(L.label_w == msgs::text_width(*text, "red edge (MS_RE)", msgs::min_label_px));
  const Image<float> s = msgs::contact_sheet(rows, labels, 4, 0.35f, text);
  CHECK(s.data == msgs::contact_sheet(rows, labels, 4, 0.35f, text).data);  // deterministic
  bool ink = false;  // anti-aliased white words on the grey fill, in the heading line
  for (int y = L.heading_y[0]; y < L.heading_y[0] + L.line_h; ++y)
    for (int x = 0; x < s.width; ++x) ink = ink || s.at(x, y, 0) > 0.9f;
  CHECK(ink);
}

}  // namespace test_contact_sheet
