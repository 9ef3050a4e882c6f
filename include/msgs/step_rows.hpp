// include/msgs/step_rows.hpp
// Which rows of the gradients a training step fills and reads: the dense reference step and the
// sparse one, both at the cost of what the view saw wherever the result allows it.
#pragma once

#include <cstdint>
#include <vector>

#include "adam.hpp"
#include "rasterize.hpp"

namespace msgs {

/// The rows of one step. `seen` is the rasteriser's visible() list of this step's forward.
///
/// Dense step (the reference, torch's Adam): every Gaussian moves, an unseen one with a zero
/// gradient. The backward writes the seen rows only (GradientFill::visible) and Adam takes every
/// other row as zero without reading it (AdamRows::zero_elsewhere): the same bits as zeroing the
/// whole buffer, without the pass. On a step with the scale regulariser, which gives every
/// Gaussian a gradient, the whole buffer is filled (GradientFill::dense) and read.
///
/// Sparse step: gradients, regulariser and Adam for the seen rows only (AdamRows::only).
struct StepRows {
  GradientFill fill = GradientFill::dense;
  /// Adam's row list and the gradient rows the step reads (nullptr: every row).
  const std::vector<std::uint32_t>* rows = nullptr;
  AdamRows adam = AdamRows::only;
  const std::vector<std::uint32_t>* reg_rows = nullptr;  ///< scale_reg's rows (nullptr: every row)

  static StepRows of(bool sparse, bool regularised, const std::vector<std::uint32_t>& seen) {
    StepRows r;
    if (sparse) return {GradientFill::visible, &seen, AdamRows::only, &seen};
    if (regularised) return r;  // whole buffer, every row
    return {GradientFill::visible, &seen, AdamRows::zero_elsewhere, nullptr};
  }
};

}  // namespace msgs
