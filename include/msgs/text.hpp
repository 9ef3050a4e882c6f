// include/msgs/text.hpp
// Text in pictures (labels of contact sheets, legend values): an interface that turns a line of
// UTF-8 text into anti-aliased greyscale coverage, drawing that coverage into an image, and the
// renderer msgs' pictures use by default.
//
// The library itself does not need FreeType. Where MSGS_HAVE_FREETYPE is defined (CMake: link
// `msgs::freetype`, which also links FreeType), default_text() draws with FreeType and a TrueType
// font: $MSGS_FONT, or DejaVu Sans (Debian fonts-dejavu-core). Without it, or when the font does
// not load, default_text() is nullptr, says so once on stderr, and pictures are written without
// their words (the same pictures as before labels existed). Define the macro for every
// translation unit of a program or for none: default_text() differs between the two.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "image.hpp"

namespace msgs {

/// Turns one line of text into coverage.
class TextRenderer {
 public:
  virtual ~TextRenderer() = default;

  /// Smallest and largest size accepted, in pixels per em.
  static constexpr int min_px = 1, max_px = 1024;

  /// `utf8` (one line; invalid bytes and control characters are drawn as the font's replacement
  /// glyph or left out) at `px` pixels per em, as coverage [line_height(px), W, 1] in [0, 1]
  /// (1 = full ink). Row 0 is the line's top, the baseline is row ascent(px); W spans the pen
  /// advance and every glyph's ink, so all ink lies inside the image. An empty string gives W = 0.
  /// std::invalid_argument for px outside [min_px, max_px]. Deterministic: the same call gives
  /// the same bits.
  virtual Image<float> render(std::string_view utf8, int px) const = 0;
  /// Height of every render(…, px) result: ascent + descent of the font, in pixels.
  virtual int line_height(int px) const = 0;
  /// Rows from the top of a line to its baseline.
  virtual int ascent(int px) const = 0;
  /// What draws the text, for messages ("FreeType, /usr/share/.../DejaVuSans.ttf").
  virtual std::string describe() const = 0;

 protected:
  static void check_px(int px) {
    if (px < min_px || px > max_px)
      throw std::invalid_argument("TextRenderer: size " + std::to_string(px) + " px is outside [" +
                                  std::to_string(min_px) + ", " + std::to_string(max_px) + "]");
  }
};

/// Width in pixels of `utf8` rendered at `px` (0 for an empty string).
inline int text_width(const TextRenderer& text, std::string_view utf8, int px) {
  return utf8.empty() ? 0 : text.render(utf8, px).width;
}

/// Draw `utf8` at `px` with the top-left corner of its line box at (x, y): every channel c of
/// `img` becomes img * (1 - a) + ink[c] * a, a the coverage (grey images take ink[0]). Clipped
/// to the image. Returns the width drawn over (text_width).
inline int draw_text(Image<float>& img, const TextRenderer& text, std::string_view utf8, int px, int x, int y,
                     const std::array<float, 3>& ink) {
  if (utf8.empty()) return 0;
  const Image<float> cov = text.render(utf8, px);  // [line_height, W, 1]
  for (int r = 0; r < cov.height; ++r) {
    const int iy = y + r;
    if (iy < 0 || iy >= img.height) continue;
    for (int c = 0; c < cov.width; ++c) {
      const int ix = x + c;
      if (ix < 0 || ix >= img.width) continue;
      const float a = cov.at(c, r, 0);
      if (a <= 0.0f) continue;
      for (int k = 0; k < img.channels; ++k) {
        float& v = img.at(ix, iy, k);
        v = v * (1.0f - a) + ink[img.channels == 3 ? std::size_t(k) : 0] * a;
      }
    }
  }
  return cov.width;
}

/// Unicode code points of UTF-8 text; malformed sequences become U+FFFD (one per bad byte).
inline std::vector<char32_t> decode_utf8(std::string_view s) {
  std::vector<char32_t> out;
  std::size_t i = 0;
  while (i < s.size()) {
    const auto b0 = static_cast<unsigned char>(s[i]);
    int len = b0 < 0x80 ? 1 : (b0 >> 5) == 0x6 ? 2 : (b0 >> 4) == 0xE ? 3 : (b0 >> 3) == 0x1E ? 4 : 0;
    char32_t cp = len == 1 ? b0 : len == 2 ? (b0 & 0x1F) : len == 3 ? (b0 & 0x0F) : (b0 & 0x07);
    bool ok = len > 0 && i + std::size_t(len) <= s.size();
    for (int k = 1; ok && k < len; ++k) {
      const auto b = static_cast<unsigned char>(s[i + std::size_t(k)]);
      ok = (b & 0xC0) == 0x80;
      cp = (cp << 6) | (b & 0x3F);
    }
    // Overlong forms, surrogates and values past U+10FFFF are malformed too.
    static constexpr char32_t min_of_len[5] = {0, 0, 0x80, 0x800, 0x10000};
    ok = ok && cp >= min_of_len[len] && cp <= 0x10FFFF && !(cp >= 0xD800 && cp <= 0xDFFF);
    if (ok) {
      out.push_back(cp);
      i += std::size_t(len);
    } else {
      out.push_back(0xFFFD);
      ++i;
    }
  }
  return out;
}

/// Environment variable naming the TrueType/OpenType font file of pictures.
inline constexpr const char* font_env_var = "MSGS_FONT";
/// The font used when $MSGS_FONT is unset: DejaVu Sans from Debian's fonts-dejavu-core.
inline constexpr const char* default_font_path = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// The font file pictures use: $MSGS_FONT when set and not empty, else default_font_path.
inline std::string font_path() {
  const char* env = std::getenv(font_env_var);
  return env && *env ? std::string(env) : std::string(default_font_path);
}

}  // namespace msgs

#if defined(MSGS_HAVE_FREETYPE)
#include "detail/freetype_text.hpp"
#endif

namespace msgs {

/// A text renderer for the font file `path`; nullptr, with the reason in `*why` when given, if
/// msgs is built without FreeType or the file does not load as a font.
inline std::unique_ptr<TextRenderer> make_text_renderer(const std::string& path, std::string* why = nullptr) {
#if defined(MSGS_HAVE_FREETYPE)
  return detail::FreeTypeText::open(path, why);
#else
  if (why) *why = "msgs was built without FreeType (MSGS_HAVE_FREETYPE); install libfreetype-dev and rebuild";
  (void)path;
  return nullptr;
#endif
}

/// The text renderer of msgs' pictures: make_text_renderer(font_path()), made once, on first
/// use, and shared (thread-safe). nullptr when it cannot be made; the first call then prints one
/// warning on stderr saying why, and pictures are written without labels.
inline const TextRenderer* default_text() {
  static const std::unique_ptr<TextRenderer> text = [] {
    std::string why;
    std::unique_ptr<TextRenderer> t = make_text_renderer(font_path(), &why);
    if (!t)
      std::fprintf(stderr, "msgs: warning: pictures are written without labels: %s (set %s to a .ttf file)\n",
                   why.c_str(), font_env_var);
    return t;
  }();
  return text.get();
}

}  // namespace msgs
