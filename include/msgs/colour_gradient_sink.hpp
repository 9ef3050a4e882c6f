// include/msgs/colour_gradient_sink.hpp
// The hand-over of colour gradients from the rasteriser's backward to whoever consumes them row by
// row (Adam::ColourStep), so that neither header needs the other.
#pragma once

#include <cstddef>
#include <cstdint>

namespace msgs {

/// Takes the colour (SH) gradients of the visible Gaussians from Rasterizer::backward in place of
/// Gradients::model.sh, a vector of Gaussians at a time, as soon as they are known: an optimiser
/// that updates each row right there (Adam::ColourStep) never stores the gradient and reads it
/// back. The rows are those Gradients::model.sh would have held, zeros above the active degree.
template <class S>
class ColourGradientSink {
 public:
  virtual ~ColourGradientSink() = default;
  /// For each lane l < n whose bit in `skip` is clear: `rows + l * stride` holds the gradient of
  /// the coefficients of channel `channel` of Gaussian ids[l]. Called from the backward's threads
  /// at once, each Gaussian once per rendered channel; lanes of one call are distinct Gaussians.
  virtual void consume(const std::uint32_t* ids, int n, std::uint32_t skip, int channel, const S* rows,
                       std::size_t stride) = 0;
  /// Called with each vector of Gaussians before their gradients are computed: a chance to fetch
  /// what `consume` will read for channels [first, first + count) of ids[0 .. n).
  virtual void prefetch(const std::uint32_t* /*ids*/, int /*n*/, int /*first*/, int /*count*/) const {}
};

}  // namespace msgs
