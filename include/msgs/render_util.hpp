// include/msgs/render_util.hpp
// Rendering trained models over a dataset and looking at the result, in one include. Each
// concern has its own header; this one includes them all (and what it always included), so code
// written against render_util.hpp keeps compiling.
//
// Layers, bottom up:
//   pictures    spectral_index.hpp  normalized_difference / ndvi / ndre, cir_composite
//               colormap.hpp        Colormap, colour_at, colourize, legend_bar, legend_strip,
//                                   with_legend, to_rgb
//               text.hpp            TextRenderer, draw_text, default_text (FreeType where built with it)
//               contact_sheet.hpp   error_map, contact_sheet_layout, contact_sheet (optionally labelled)
//   models      model_set.hpp       load_model (inspect_ply -> Gaussian<C, D>), LoadedModel,
//                                   make_typed_renderer / make_channel_renderer, ModelSet
//   datasets    render_dataset.hpp  capture_key / group_captures, band_background, OutputStage,
//                                   render_dataset (every frame, plus per-capture composites)
//               evaluate.hpp        evaluate_models (PSNR / SSIM per band, contact sheets)
#pragma once

#include "camera.hpp"
#include "colormap.hpp"
#include "contact_sheet.hpp"
#include "evaluate.hpp"
#include "gaussian.hpp"
#include "image.hpp"
#include "io/bands.hpp"
#include "io/dataset.hpp"
#include "io/error.hpp"
#include "io/image_io.hpp"
#include "io/ply.hpp"
#include "loss.hpp"
#include "model_set.hpp"
#include "rasterize.hpp"
#include "render_dataset.hpp"
#include "schedule.hpp"
#include "spectral_index.hpp"
#include "text.hpp"
#include "train.hpp"
