// include/msgs/detail/freetype_text.hpp
// The FreeType implementation of TextRenderer (text.hpp includes it where MSGS_HAVE_FREETYPE is
// defined): hinted, anti-aliased greyscale glyphs of one TrueType/OpenType face, no kerning or
// shaping (labels are short Latin text and numbers). Include text.hpp, not this file: it needs
// TextRenderer and decode_utf8 from there.
#pragma once

#include <ft2build.h>
#include FT_FREETYPE_H

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "../image.hpp"

namespace msgs::detail {

class FreeTypeText final : public TextRenderer {
 public:
  /// The face in `path`; nullptr with the reason in `*why` when it does not load.
  static std::unique_ptr<TextRenderer> open(const std::string& path, std::string* why) {
    FT_Library lib = nullptr;
    if (FT_Init_FreeType(&lib) != 0) {
      if (why) *why = "FreeType did not initialise";
      return nullptr;
    }
    FT_Face face = nullptr;
    if (FT_New_Face(lib, path.c_str(), 0, &face) != 0) {
      FT_Done_FreeType(lib);
      if (why) *why = "cannot load the font file " + path;
      return nullptr;
    }
    if (!FT_IS_SCALABLE(face)) {
      FT_Done_Face(face);
      FT_Done_FreeType(lib);
      if (why) *why = path + " is not a scalable (TrueType/OpenType) font";
      return nullptr;
    }
    return std::unique_ptr<TextRenderer>(new FreeTypeText(lib, face, path));
  }

  FreeTypeText(const FreeTypeText&) = delete;
  FreeTypeText& operator=(const FreeTypeText&) = delete;
  ~FreeTypeText() override {
    FT_Done_Face(face_);
    FT_Done_FreeType(lib_);
  }

  Image<float> render(std::string_view utf8, int px) const override {
    check_px(px);
    std::lock_guard<std::mutex> lock(mutex_);  // one FT_Face serves every thread
    const auto [asc, desc] = size_to(px);
    const int H = asc + desc;
    struct Placed {
      int x = 0, y = 0, w = 0, h = 0;  // top-left relative to the line's origin (pen 0, top row 0)
      std::vector<unsigned char> cov;  // [h, w] 0..255
    };
    std::vector<Placed> glyphs;
    int pen = 0, min_x = 0, max_x = 0;
    for (char32_t cp : decode_utf8(utf8)) {
      if (cp < 0x20 || (cp >= 0x7F && cp < 0xA0)) continue;  // control characters: nothing to draw
      // A code point the face lacks maps to glyph 0, the font's "missing" box.
      const FT_UInt index = FT_Get_Char_Index(face_, FT_ULong(cp));
      if (FT_Load_Glyph(face_, index, FT_LOAD_DEFAULT) != 0) continue;
      const FT_GlyphSlot g = face_->glyph;
      if (g->format != FT_GLYPH_FORMAT_BITMAP && FT_Render_Glyph(g, FT_RENDER_MODE_NORMAL) != 0) continue;
      const FT_Bitmap& bm = g->bitmap;
      Placed p;
      p.x = pen + g->bitmap_left;
      p.y = asc - g->bitmap_top;
      p.w = int(bm.width);
      p.h = int(bm.rows);
      if (p.w > 0 && p.h > 0 && (bm.pixel_mode == FT_PIXEL_MODE_GRAY || bm.pixel_mode == FT_PIXEL_MODE_MONO)) {
        p.cov.resize(std::size_t(p.w) * std::size_t(p.h));
        for (int r = 0; r < p.h; ++r) {
          // A negative pitch stores rows bottom-up; rows are addressed from the buffer's start.
          const unsigned char* row = bm.pitch >= 0 ? bm.buffer + std::ptrdiff_t(r) * bm.pitch
                                                   : bm.buffer + std::ptrdiff_t(p.h - 1 - r) * (-bm.pitch);
          for (int c = 0; c < p.w; ++c) {
            const unsigned v = bm.pixel_mode == FT_PIXEL_MODE_GRAY
                                   ? (bm.num_grays == 256 ? row[c] : unsigned(row[c]) * 255u / unsigned(bm.num_grays - 1))
                                   : ((row[c >> 3] >> (7 - (c & 7))) & 1u) * 255u;
            p.cov[std::size_t(r) * std::size_t(p.w) + std::size_t(c)] = static_cast<unsigned char>(v);
          }
        }
        min_x = std::min(min_x, p.x);
        max_x = std::max(max_x, p.x + p.w);
        glyphs.push_back(std::move(p));
      }
      pen += int((g->advance.x + 32) >> 6);
    }
    max_x = std::max(max_x, pen);
    Image<float> out(max_x - min_x, H, 1, 0.0f);
    for (const Placed& p : glyphs)
      for (int r = 0; r < p.h; ++r) {
        const int y = p.y + r;
        if (y < 0 || y >= H) continue;  // beyond the font's ascent / descent (rare accents)
        for (int c = 0; c < p.w; ++c) {
          const float v = float(p.cov[std::size_t(r) * std::size_t(p.w) + std::size_t(c)]) / 255.0f;
          float& o = out.at(p.x - min_x + c, y, 0);
          o = std::max(o, v);  // overlapping glyphs: the darker ink
        }
      }
    return out;
  }

  int line_height(int px) const override {
    check_px(px);
    std::lock_guard<std::mutex> lock(mutex_);
    const auto [asc, desc] = size_to(px);
    return asc + desc;
  }

  int ascent(int px) const override {
    check_px(px);
    std::lock_guard<std::mutex> lock(mutex_);
    return size_to(px).first;
  }

  std::string describe() const override { return "FreeType, " + path_; }

 private:
  FreeTypeText(FT_Library lib, FT_Face face, std::string path) : lib_(lib), face_(face), path_(std::move(path)) {}

  /// Set the face to `px` pixels per em; returns (ascent, descent) in whole pixels, both >= 0.
  std::pair<int, int> size_to(int px) const {
    if (px != px_) {
      FT_Set_Pixel_Sizes(face_, 0, FT_UInt(px));
      px_ = px;
    }
    const FT_Size_Metrics& m = face_->size->metrics;  // 26.6 fixed point
    const int asc = int((m.ascender + 63) >> 6), desc = int((-m.descender + 63) >> 6);
    return {std::max(asc, 1), std::max(desc, 0)};
  }

  FT_Library lib_;
  FT_Face face_;
  std::string path_;
  mutable int px_ = 0;
  mutable std::mutex mutex_;
};

}  // namespace msgs::detail
