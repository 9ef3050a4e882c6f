// examples/cmd_render_c7.cpp
// Rasterizers for 7-channel models (SH degree 0..3), used by `msgs render` and `msgs eval`.
#include "render_dispatch.hpp"

namespace msgs::cli {
ChannelRenderer make_renderer_c7(std::shared_ptr<const LoadedModel> m) { return make_channel_renderer<7>(std::move(m)); }
}  // namespace msgs::cli
