#include "viewer_client/render/passes/depth_readback.h"

#include <algorithm>
#include <limits>

#include <Eigen/LU>

namespace ave::viewer::internal {

absl::StatusOr<std::vector<float>> ReadLinearDepth(const View& view, const DepthSources& d) {
  const Viewport& v = view.viewport;
  if (d.width == 0 || v.x < 0 || v.y < 0 || v.width <= 0 || v.height <= 0 || v.x + v.width > d.width ||
      v.y + v.height > d.height) {
    return absl::FailedPreconditionError("ReadLinearDepth: the view's viewport is not inside the last Render's framebuffer");
  }
  FramebufferGuard guard;
  std::vector<float> window_depth(static_cast<size_t>(v.width) * v.height);
  std::vector<uint8_t> color(static_cast<size_t>(v.width) * v.height * 4);
  // A view drawn from its cache in the last frame: the cached G-buffer, and the working one in the
  // rectangles drawn exactly over it.
  std::vector<std::pair<GLuint, Viewport>> sources = {{d.working.fbo, v}};
  for (const ViewCache& cache : d.cache.entries()) {
    if (!cache.valid || cache.last_frame != d.frames || cache.viewport.x != v.x || cache.viewport.y != v.y ||
        cache.viewport.width != v.width || cache.viewport.height != v.height) {
      continue;
    }
    sources = {{d.cache.gbuffer().fbo, v}};
    for (const Viewport& r : cache.patches) sources.emplace_back(d.working.fbo, r);
  }
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glPixelStorei(GL_PACK_ROW_LENGTH, v.width);
  for (const auto& [fbo, r] : sources) {
    const size_t offset = static_cast<size_t>(r.y - v.y) * v.width + (r.x - v.x);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    glReadPixels(r.x, r.y, r.width, r.height, GL_DEPTH_COMPONENT, GL_FLOAT, window_depth.data() + offset);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(r.x, r.y, r.width, r.height, GL_RGBA, GL_UNSIGNED_BYTE, color.data() + 4 * offset);
  }
  glPixelStorei(GL_PACK_ROW_LENGTH, 0);
  // A view drawn at reduced resolution: its working G-buffer part, scaled up as the resolve did.
  for (const auto& [shown, drawn] : d.reduced_views) {
    if (shown.x != v.x || shown.y != v.y || shown.width != v.width || shown.height != v.height) continue;
    std::vector<float> small_depth(static_cast<size_t>(drawn.width) * drawn.height);
    std::vector<uint8_t> small_color(small_depth.size() * 4);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, d.working.fbo);
    glReadPixels(drawn.x, drawn.y, drawn.width, drawn.height, GL_DEPTH_COMPONENT, GL_FLOAT, small_depth.data());
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(drawn.x, drawn.y, drawn.width, drawn.height, GL_RGBA, GL_UNSIGNED_BYTE, small_color.data());
    for (int row = 0; row < v.height; ++row) {
      const int src_row = std::min(drawn.height - 1, static_cast<int>((row + 0.5) * drawn.height / v.height));
      for (int col = 0; col < v.width; ++col) {
        const int src_col = std::min(drawn.width - 1, static_cast<int>((col + 0.5) * drawn.width / v.width));
        const size_t src = static_cast<size_t>(src_row) * drawn.width + src_col;
        const size_t dst = static_cast<size_t>(row) * v.width + col;
        window_depth[dst] = small_depth[src];
        std::copy_n(&small_color[4 * src], 4, &color[4 * dst]);
      }
    }
  }
  if (absl::Status s = CheckGl("ReadLinearDepth"); !s.ok()) return s;
  const Eigen::Matrix4d eye_from_clip = view.projection.inverse();
  std::vector<float> depth(window_depth.size());
  for (int row = 0; row < v.height; ++row) {
    const int gl_row = v.height - 1 - row;
    for (int col = 0; col < v.width; ++col) {
      const size_t src = static_cast<size_t>(gl_row) * v.width + col;
      float& out = depth[static_cast<size_t>(row) * v.width + col];
      if (color[src * 4 + 3] != 255) {  // nothing or sky
        out = std::numeric_limits<float>::infinity();
        continue;
      }
      const Eigen::Vector4d ndc(2 * (col + 0.5) / v.width - 1, 2 * (gl_row + 0.5) / v.height - 1,
                                2.0 * window_depth[src] - 1, 1);
      const Eigen::Vector4d eye = eye_from_clip * ndc;
      out = static_cast<float>(-eye.z() / eye.w());
    }
  }
  return depth;
}

}  // namespace ave::viewer::internal
