// examples/cmd_render_c1.cpp
// Rasterizers for 1-channel models (SH degree 0..3), used by `msgs render` and `msgs eval`.
#include "render_dispatch.hpp"

namespace msgs::cli {
ChannelRenderer make_renderer_c1(std::shared_ptr<const LoadedModel> m) { return make_channel_renderer<1>(std::move(m)); }
}  // namespace msgs::cli
