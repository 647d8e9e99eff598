#pragma once
// Internal to ave_render: the cameras the renderer projects. Live layer i holds projector i's
// frame (VideoLayers) and shadow map (ShadowMaps); a camera that turns away leaves a retained
// snapshot (texture retention, renderer.h). Pose jitter below still_pose_tolerance_px keeps the
// old pose; a pose with NaNs keeps the camera's last good state and marks it stale.
#include <array>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class VideoLayers;

// Retained snapshots fainter than this are not drawn (one 8-bit step).
inline constexpr double kMinFade = 1.0 / 256;

// What live layer i holds.
struct LiveSlot {
  std::string camera_id;
  uint64_t image_serial = 0;
  bool has_image = false;
  double image_time_s = 0;
  ShadowSlot shadow;
  std::optional<Eigen::Matrix4d> anchor_view;  // pose at the last snapshot (or the first pose)
};

// A camera's last imagery at a pose it has left (texture retention, issue 7).
struct RetainedSnapshot {
  bool in_use = false;
  std::string camera_id;
  Projector projector;  // image_rgba empty
  double capture_time_s = 0;
  uint64_t order = 0;  // larger: newer
  ShadowSlot shadow;
};

class CameraSet {
 public:
  // `options` and `clock` must outlive the set (Renderer::Impl owns all three).
  CameraSet(const RendererOptions& options, const Clock& clock);

  // Renderer::SetProjectors after validation: poses (jitter kept out, NaNs marked stale),
  // snapshots of cameras that turned away, frames uploaded into `video`.
  absl::Status Set(const std::vector<Projector>& projectors, VideoLayers& video, RenderStats& stats);

  // The live layer is drawn: enabled, with a frame.
  bool LiveActive(size_t i) const { return projectors_[i].enabled && slots_[i].has_image; }
  bool RetainedActive(const RetainedSnapshot& r) const { return r.in_use && Fade(r.capture_time_s) >= kMinFade; }
  // 0.5^(age / half-life) of imagery captured at capture_time_s; 0 with retention off.
  double Fade(double capture_time_s) const;

  // The live and retained projector passes of a frame, with their frustum volumes (cut at the
  // scene's bounds and what each shadow map saw) appended to `volumes`, 36 vertices each.
  std::vector<ProjectorPass> Passes(const Bounds& scene, std::vector<LineVertex>& volumes) const;

  const std::vector<Projector>& projectors() const { return projectors_; }
  const std::vector<std::array<Eigen::Vector3d, 16>>& frustums() const { return frustums_; }
  std::array<LiveSlot, kMaxProjectors>& slots() { return slots_; }
  const std::array<LiveSlot, kMaxProjectors>& slots() const { return slots_; }
  std::vector<RetainedSnapshot>& retained() { return retained_; }
  const std::vector<RetainedSnapshot>& retained() const { return retained_; }
  std::vector<std::string> Stale() const { return {stale_.begin(), stale_.end()}; }

 private:
  // Keeps live layer `layer` (frame and the pose it was taken at) as a retained snapshot.
  absl::Status Snapshot(const Projector& old, const LiveSlot& slot, int layer, VideoLayers& video,
                        RenderStats& stats);

  const RendererOptions& options_;
  const Clock& clock_;
  std::vector<Projector> projectors_;  // image_rgba cleared: only valid during Set
  std::vector<std::array<Eigen::Vector3d, 16>> frustums_;
  std::array<LiveSlot, kMaxProjectors> slots_;
  std::vector<RetainedSnapshot> retained_;
  uint64_t snapshot_counter_ = 0;
  std::set<std::string> stale_;
};

}  // namespace ave::viewer::internal
