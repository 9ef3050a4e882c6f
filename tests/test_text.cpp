// tests/test_text.cpp
// Tests of text.hpp: ink only inside the line box, determinism, empty strings, UTF-8 (valid,
// malformed, glyphs the font lacks), tiny and huge sizes, drawing into an image. Includes
// text.hpp alone, so it also checks that the header compiles on its own. The FreeType cases skip
// themselves in a build without FreeType or without the font.
#include <doctest/doctest.h>

#include <msgs/text.hpp>

#include <string>
#include <vector>

namespace test_text {
using msgs::Image;

namespace {

/// Smallest box holding every pixel with coverage > 0: {x0, y0, x1, y1} (exclusive ends), or
/// all -1 when there is no ink.
std::array<int, 4> ink_box(const Image<float>& img) {
  std::array<int, 4> b{-1, -1, -1, -1};
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      if (img.at(x, y, 0) > 0.0f) {
        if (b[0] < 0) b = {x, y, x + 1, y + 1};
        b = {std::min(b[0], x), std::min(b[1], y), std::max(b[2], x + 1), std::max(b[3], y + 1)};
      }
  return b;
}

bool in_unit_range(const Image<float>& img) {
  for (float v : img.data)
    if (!(v >= 0.0f && v <= 1.0f)) return false;
  return true;
}

}  // namespace

TEST_CASE("decode_utf8: code points, malformed bytes become U+FFFD") {
  using V = std::vector<char32_t>;
  CHECK(msgs::decode_utf8("") == V{});
  CHECK(msgs::decode_utf8("aZ") == V{U'a', U'Z'});
  CHECK(msgs::decode_utf8("\xC3\xA9") == V{0xE9});                     // é
  CHECK(msgs::decode_utf8("\xE2\x82\xAC") == V{0x20AC});               // €
  CHECK(msgs::decode_utf8("\xF0\x9F\x8C\xBF") == V{0x1F33F});          // 🌿
  CHECK(msgs::decode_utf8("\xC3") == V{0xFFFD});                       // truncated
  CHECK(msgs::decode_utf8("\xFF" "a") == V{0xFFFD, U'a'});             // not a lead byte
  CHECK(msgs::decode_utf8("\xC0\xAF") == V{0xFFFD, 0xFFFD});           // overlong '/'
  CHECK(msgs::decode_utf8("\xED\xA0\x80") == V{0xFFFD, 0xFFFD, 0xFFFD});  // a surrogate
}

TEST_CASE("font_path: $MSGS_FONT overrides DejaVu Sans") {
  ::unsetenv(msgs::font_env_var);
  CHECK(msgs::font_path() == msgs::default_font_path);
  ::setenv(msgs::font_env_var, "/some/font.ttf", 1);
  CHECK(msgs::font_path() == "/some/font.ttf");
  ::setenv(msgs::font_env_var, "", 1);
  CHECK(msgs::font_path() == msgs::default_font_path);
  ::unsetenv(msgs::font_env_var);
}

TEST_CASE("make_text_renderer: a missing or non-font file gives nullptr and a reason") {
  std::string why;
  CHECK(msgs::make_text_renderer("/nonexistent/font.ttf", &why) == nullptr);
  CHECK(!why.empty());
  why.clear();
  CHECK(msgs::make_text_renderer("/etc/hostname", &why) == nullptr);
  CHECK(!why.empty());
}

TEST_CASE("FreeType text: ink inside the line box, deterministic, any input") {
  std::string why;
  const auto text = msgs::make_text_renderer(msgs::default_font_path, &why);
  if (!text) {
    MESSAGE("skipped: " << why);
    return;
  }
  const int px = 16;
  const int H = text->line_height(px), asc = text->ascent(px);
  CHECK(H > px);  // ascent + descent of DejaVu Sans: about 1.17 em
  CHECK(asc > 0);
  CHECK(asc < H);

  SUBCASE("a label: line height, ink in the box, anti-aliased") {
    const Image<float> a = text->render("NDVI (MS_NIR)", px);
    CHECK(a.channels == 1);
    CHECK(a.height == H);
    CHECK(a.width == msgs::text_width(*text, "NDVI (MS_NIR)", px));
    CHECK(a.width > 5 * px);
    CHECK(a.width < 13 * px);
    CHECK(in_unit_range(a));
    const auto b = ink_box(a);
    REQUIRE(b[0] >= 0);
    // Capitals reach from the cap height to the baseline: ink starts in the top part of the box
    // and its bottom is at the baseline or below (the parentheses descend).
    CHECK(b[1] < asc - px / 2);
    CHECK(b[3] >= asc);
    CHECK(b[2] <= a.width);
    bool grey = false;  // some pixel partly covered: anti-aliased, not a bitmap font
    for (float v : a.data) grey = grey || (v > 0.05f && v < 0.95f);
    CHECK(grey);
    // Nothing below the descent of "NDVI" alone: capitals sit on the baseline.
    const Image<float> caps = text->render("NDVI", px);
    CHECK(ink_box(caps)[3] <= asc + 1);
  }

  SUBCASE("deterministic: the same call, the same bits; a longer text is wider") {
    const Image<float> a = text->render("ground truth", px), b = text->render("ground truth", px);
    CHECK(a.data == b.data);
    (void)text->render("something else", 40);  // another size in between
    CHECK(text->render("ground truth", px).data == a.data);
    CHECK(text->render("ground truth | render", px).width > a.width);
  }

  SUBCASE("empty string: no width, no ink") {
    const Image<float> e = text->render("", px);
    CHECK(e.width == 0);
    CHECK(e.height == H);
    CHECK(msgs::text_width(*text, "", px) == 0);
    Image<float> img(10, 10, 3, 0.5f);
    CHECK(msgs::draw_text(img, *text, "", px, 0, 0, {0.0f, 0.0f, 0.0f}) == 0);
    for (float v : img.data) CHECK(v == 0.5f);
    // Spaces advance the pen but leave no ink.
    const Image<float> s = text->render("   ", px);
    CHECK(s.width > 0);
    CHECK(ink_box(s)[0] == -1);
  }

  SUBCASE("UTF-8, glyphs the font lacks, malformed bytes, control characters") {
    for (const char* s : {"Ünïcödé λ 860 nm", "\xF0\x9F\x8C\xBF \xE4\xB8\xAD", "\xFF\xFE\xC3", "a\tb\nc\x7f"}) {
      CAPTURE(s);
      const Image<float> a = text->render(s, px);
      CHECK(a.height == H);
      CHECK(a.width > 0);
      CHECK(in_unit_range(a));
    }
    CHECK(ink_box(text->render("é", px))[0] >= 0);
  }

  SUBCASE("tiny and huge sizes; sizes out of range are refused") {
    const Image<float> t = text->render("NDVI", 1);
    CHECK(t.height == text->line_height(1));
    CHECK(in_unit_range(t));
    const Image<float> h = text->render("Wg", 400);
    CHECK(h.height == text->line_height(400));
    CHECK(h.height > 400);
    const auto b = ink_box(h);
    REQUIRE(b[0] >= 0);
    CHECK(b[3] - b[1] > 300);  // W's cap height plus g's descender
    CHECK_THROWS_AS((void)text->render("a", 0), std::invalid_argument);
    CHECK_THROWS_AS((void)text->render("a", -3), std::invalid_argument);
    CHECK_THROWS_AS((void)text->render("a", msgs::TextRenderer::max_px + 1), std::invalid_argument);
  }

  SUBCASE("draw_text: blends the ink inside the box at (x, y) and nowhere else, clips at edges") {
    const Image<float> cov = text->render("RGB", px);
    Image<float> img(80, 40, 3, 1.0f);
    const int x = 7, y = 5;
    CHECK(msgs::draw_text(img, *text, "RGB", px, x, y, {0.0f, 0.25f, 0.5f}) == cov.width);
    for (int yy = 0; yy < img.height; ++yy)
      for (int xx = 0; xx < img.width; ++xx) {
        const bool inside = xx >= x && xx < x + cov.width && yy >= y && yy < y + cov.height;
        const float a = inside ? cov.at(xx - x, yy - y, 0) : 0.0f;
        CHECK(img.at(xx, yy, 0) == doctest::Approx(1.0f - a));
        CHECK(img.at(xx, yy, 1) == doctest::Approx(1.0f - 0.75f * a));
      }
    Image<float> grey(20, 10, 1, 0.0f);  // grey images take ink[0]; drawing past the edges is clipped
    (void)msgs::draw_text(grey, *text, "RGB", px, -5, -3, {1.0f, 0.0f, 0.0f});
    (void)msgs::draw_text(grey, *text, "RGB", px, 15, 6, {1.0f, 0.0f, 0.0f});
    CHECK(ink_box(grey)[0] >= 0);
    CHECK(in_unit_range(grey));
  }
}

TEST_CASE("default_text: the shared renderer, made once") {
  const msgs::TextRenderer* a = msgs::default_text();
  CHECK(msgs::default_text() == a);
#if defined(MSGS_HAVE_FREETYPE)
  if (a) CHECK(a->describe().find("FreeType") != std::string::npos);
#else
  CHECK(a == nullptr);
#endif
}

}  // namespace test_text
