// examples/render_dispatch.hpp
// The renderer factory of `msgs render` and `msgs eval`: the Rasterizers of each channel count
// are compiled in their own translation unit (cmd_render_c<C>.cpp), which keeps the 2-core build lean.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

#include <msgs/render_util.hpp>

namespace msgs::cli {

ChannelRenderer make_renderer_c1(std::shared_ptr<const LoadedModel> m);  // cmd_render_c1.cpp
ChannelRenderer make_renderer_c3(std::shared_ptr<const LoadedModel> m);  // cmd_render_c3.cpp
ChannelRenderer make_renderer_c7(std::shared_ptr<const LoadedModel> m);  // cmd_render_c7.cpp

/// Renderer for any model load_model accepts (1, 3 or 7 channels, SH degree 0..3).
inline ChannelRenderer make_any_renderer(std::shared_ptr<const LoadedModel> m) {
  switch (m->channels()) {
    case 1: return make_renderer_c1(std::move(m));
    case 3: return make_renderer_c3(std::move(m));
    case 7: return make_renderer_c7(std::move(m));
    default:
      throw std::invalid_argument(m->path.string() + ": cannot render " + std::to_string(m->channels()) + " channels");
  }
}

}  // namespace msgs::cli
