#pragma once
// Internal to ave_render: Renderer::ReadLinearDepth. The depth of a view as the last Render drew
// it comes from the working G-buffer, or from its view cache (and the working G-buffer in the
// rectangles drawn exactly over it), or from the reduced part of the working G-buffer a moving
// view was drawn into (scaled up as the resolve did).
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "viewer_client/render/passes/gbuffer_pass.h"
#include "viewer_client/render/passes/view_cache.h"

namespace ave::viewer::internal {

// Where the last Render left each view's depth.
struct DepthSources {
  int width = 0, height = 0;  // the targets (0: no Render yet)
  uint64_t frames = 0;        // RenderStats::frames
  const GbufferTargets& working;
  const ViewCachePass& cache;
  // Views drawn at reduced resolution: (viewport, the part of the working G-buffer drawn into).
  const std::vector<std::pair<Viewport, Viewport>>& reduced_views;
};

absl::StatusOr<std::vector<float>> ReadLinearDepth(const View& view, const DepthSources& sources);

}  // namespace ave::viewer::internal
