// The GL-free parts of renderer.h: options, shading formula, viewport layout, camera-locked views.
#include <algorithm>
#include <cmath>

#include "viewer_client/render/renderer.h"

namespace ave::viewer {

std::string RendererOptions::Check() const {
  if (video_layer_width < 16 || video_layer_width > 4096) return "video_layer_width must be in 16..4096";
  if (video_layer_height < 16 || video_layer_height > 4096) return "video_layer_height must be in 16..4096";
  if (shadow_map_size < 64 || shadow_map_size > 8192) return "shadow_map_size must be in 64..8192";
  if (!sun_direction.allFinite() || sun_direction.norm() < 1e-6f) return "sun_direction must be finite and non-zero";
  if (!std::isfinite(ambient) || ambient < 0 || ambient > 1) return "ambient must be in [0, 1]";
  if (!std::isfinite(diffuse) || diffuse < 0 || diffuse > 1) return "diffuse must be in [0, 1]";
  if (!std::isfinite(frustum_depth_m) || frustum_depth_m <= 0) return "frustum_depth_m must be finite and > 0";
  if (max_retained < 0 || max_retained > 256) return "max_retained must be in 0..256";
  if (max_retained_per_camera < 1) return "max_retained_per_camera must be >= 1";
  if (!std::isfinite(retention_turn_deg) || retention_turn_deg <= 0) return "retention_turn_deg must be finite and > 0";
  if (!std::isfinite(retention_move_m) || retention_move_m <= 0) return "retention_move_m must be finite and > 0";
  if (!std::isfinite(sky_radius_m) || sky_radius_m < 0) return "sky_radius_m must be finite and >= 0";
  if (!(moving_view_scale >= 1 && moving_view_scale <= kMaxMovingViewScale)) return "moving_view_scale must be in 1..4";
  if (moving_view_cameras < 1) return "moving_view_cameras must be >= 1";
  if (view_cache_entries < 1 || view_cache_entries > kMaxViewCacheEntries) {
    return "view_cache_entries must be in 1.." + std::to_string(kMaxViewCacheEntries);
  }
  if (!std::isfinite(still_pose_tolerance_px) || still_pose_tolerance_px < 0 || still_pose_tolerance_px > 10) {
    return "still_pose_tolerance_px must be in [0, 10]";
  }
  if (const std::string why = display.Check(); !why.empty()) return "display." + why;
  return {};
}

std::string DisplayOptions::Check() const {
  if (!std::isfinite(seam_feather) || seam_feather < 0 || seam_feather > 1) return "seam_feather must be in [0, 1]";
  if (std::isnan(retention_half_life_s)) return "retention_half_life_s must not be NaN";
  return {};
}

Eigen::Vector3f ShadedModelColor(const RendererOptions& options, const Eigen::Vector3f& color,
                                 const Eigen::Vector3f& normal) {
  const float lambert = std::max(normal.normalized().dot(options.sun_direction.normalized()), 0.0f);
  return color * (options.ambient + options.diffuse * lambert);
}

std::array<Viewport, 4> QuadLayout(int width, int height) {
  const int left_w = width / 2, right_w = width - left_w;
  const int bottom_h = height / 2, top_h = height - bottom_h;
  return {Viewport{0, bottom_h, left_w, top_h}, Viewport{left_w, bottom_h, right_w, top_h},
          Viewport{0, 0, left_w, bottom_h}, Viewport{left_w, 0, right_w, bottom_h}};
}

View ViewLockedToProjector(const Projector& projector, const Viewport& viewport) {
  View view;
  view.viewport = viewport;
  view.view = projector.view;
  view.projection = projector.projection;
  view.draw_frustums = false;
  view.highlight_camera_id = projector.camera_id;
  if (projector.image_width > 0 && projector.image_height > 0 && viewport.width > 0 && viewport.height > 0) {
    const double image_aspect = static_cast<double>(projector.image_width) / projector.image_height;
    const double viewport_aspect = static_cast<double>(viewport.width) / viewport.height;
    // Scaling a row of the projection scales that NDC axis about the centre: the image's [-1, 1]
    // rectangle shrinks to the part of the viewport with the image's aspect.
    if (viewport_aspect > image_aspect) {
      view.projection.row(0) *= image_aspect / viewport_aspect;
    } else {
      view.projection.row(1) *= viewport_aspect / image_aspect;
    }
  }
  return view;
}

}  // namespace ave::viewer
