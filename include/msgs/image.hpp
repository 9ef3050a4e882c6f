// include/msgs/image.hpp
// Image<S>: a dense height x width x channels buffer, the currency between the renderer, the
// losses, the data loaders and the writers.
#pragma once

#include <cstddef>
#include <vector>

namespace msgs {

/// Row-major interleaved image: `data[(y * width + x) * channels + c]`. Values are linear
/// reflectance or display values in [0, 1] by convention; nothing here enforces it.
template <class S = float>
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<S> data;  ///< [H, W, C]

  Image() = default;
  Image(int w, int h, int c, S fill = S(0))
      : width(w), height(h), channels(c),
        data(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c), fill) {}

  std::size_t pixels() const { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
  std::size_t size() const { return data.size(); }
  bool empty() const { return data.empty(); }

  S& at(int x, int y, int c) {
    return data[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x)) *
                    static_cast<std::size_t>(channels) + static_cast<std::size_t>(c)];
  }
  const S& at(int x, int y, int c) const {
    return data[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x)) *
                    static_cast<std::size_t>(channels) + static_cast<std::size_t>(c)];
  }

  /// Resize and fill with `fill` (keeps the allocation when it is large enough).
  void reset(int w, int h, int c, S fill = S(0)) {
    width = w; height = h; channels = c;
    data.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c), fill);
  }
  /// Set the shape without clearing: for a producer that writes every element (elements kept
  /// from the old shape are stale, new ones zero).
  void reshape(int w, int h, int c) {
    width = w; height = h; channels = c;
    data.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c));
  }
};

}  // namespace msgs
