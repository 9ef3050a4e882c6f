// include/msgs/detail/image_checks.hpp
// Argument checks shared by the picture functions (spectral indices, colour scales, error maps):
// single channel, equal sizes, finite values; each throws std::invalid_argument naming the caller.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

#include "../image.hpp"

namespace msgs {

namespace detail {

inline void check_single_channel(const Image<float>& img, const char* who, const char* name) {
  if (img.channels != 1 || img.data.size() != img.pixels())
    throw std::invalid_argument(std::string(who) + ": " + name + " must be a single-channel image, got " +
                                std::to_string(img.channels) + " channels");
}

inline void check_same_size(const Image<float>& a, const Image<float>& b, const char* who, const char* na,
                            const char* nb) {
  if (a.width != b.width || a.height != b.height)
    throw std::invalid_argument(std::string(who) + ": " + na + " is " + std::to_string(a.width) + "x" +
                                std::to_string(a.height) + " but " + nb + " is " + std::to_string(b.width) + "x" +
                                std::to_string(b.height));
}

inline void check_finite_image(const Image<float>& img, const char* who, const char* name) {
  for (std::size_t i = 0; i < img.data.size(); ++i)
    if (!std::isfinite(img.data[i]))
      throw std::invalid_argument(std::string(who) + ": " + name + " has a non-finite value at element " +
                                  std::to_string(i));
}

}  // namespace detail

}  // namespace msgs
