#include "viewer_client/render/passes/cameras.h"

#include <algorithm>
#include <cmath>

#include <Eigen/LU>

#include "viewer_client/render/passes/video_layers.h"

namespace ave::viewer::internal {

CameraSet::CameraSet(const RendererOptions& options, const Clock& clock) : options_(options), clock_(clock) {
  retained_.resize(static_cast<size_t>(options.max_retained));
}

double CameraSet::Fade(double capture_time_s) const {
  const double half_life = options_.display.retention_half_life_s;
  if (half_life <= 0) return 0;
  return std::pow(0.5, std::max(0.0, clock_.Now() - capture_time_s) / half_life);
}

absl::Status CameraSet::Set(const std::vector<Projector>& projectors, VideoLayers& video, RenderStats& stats) {
  std::vector<Projector> previous = std::move(projectors_);
  projectors_.clear();
  frustums_.clear();
  const double turn_cos = std::cos(options_.retention_turn_deg * M_PI / 180);
  for (size_t i = 0; i < projectors.size(); ++i) {
    const Projector* old = i < previous.size() ? &previous[i] : nullptr;
    LiveSlot& slot = slots_[i];
    if (slot.camera_id != projectors[i].camera_id) {
      slot = LiveSlot();
      slot.camera_id = projectors[i].camera_id;
      old = nullptr;
    }
    Projector p = projectors[i];
    if (!MatricesFinite(p)) {
      // A pose with NaNs: the frame is ignored; the camera keeps its last good state, marked stale.
      stale_.insert(p.camera_id);
      if (old != nullptr) {
        p = *old;
      } else {
        p.view = p.projection = Eigen::Matrix4d::Identity();
        p.position.setZero();
        p.enabled = false;
      }
      p.image_rgba = {};
    } else {
      stale_.erase(p.camera_id);
      if (old != nullptr && MatricesFinite(*old) &&
          ReprojectionShiftPx(*old, p, options_.frustum_depth_m, options_.video_layer_width,
                              options_.video_layer_height) < options_.still_pose_tolerance_px) {
        // Jitter of a still camera: keep the pose its shadow map and the view caches were made with.
        p.view = old->view;
        p.projection = old->projection;
        p.position = old->position;
        p.near_m = old->near_m;
        p.far_m = old->far_m;
      }
      if (slot.has_image && old != nullptr && slot.anchor_view) {
        const Eigen::Matrix3d r_new = p.view.topLeftCorner<3, 3>(), r_anchor = slot.anchor_view->topLeftCorner<3, 3>();
        const Eigen::Vector3d c_new = -r_new.transpose() * p.view.topRightCorner<3, 1>();
        const Eigen::Vector3d c_anchor = -r_anchor.transpose() * slot.anchor_view->topRightCorner<3, 1>();
        const double axis_cos = r_new.row(2).dot(r_anchor.row(2));
        if (axis_cos < turn_cos || (c_new - c_anchor).norm() > options_.retention_move_m) {
          if (absl::Status s = Snapshot(*old, slot, static_cast<int>(i), video, stats); !s.ok()) return s;
          slot.anchor_view = p.view;
        }
      }
      if (!slot.anchor_view) slot.anchor_view = p.view;
    }
    if (p.enabled && !p.image_rgba.empty() && (!slot.has_image || slot.image_serial != p.image_serial)) {
      if (absl::Status s = video.Upload(static_cast<int>(i), p); !s.ok()) {
        return absl::InternalError("SetProjectors: camera '" + p.camera_id + "': " + std::string(s.message()));
      }
      slot.has_image = true;
      slot.image_serial = p.image_serial;
      slot.image_time_s = clock_.Now();
      ++stats.video_uploads;
    }
    frustums_.push_back(FrustumSegments(p, options_.frustum_depth_m));
    p.image_rgba = {};
    projectors_.push_back(std::move(p));
  }
  for (size_t i = projectors.size(); i < slots_.size(); ++i) slots_[i] = LiveSlot();
  return CheckGl("SetProjectors");
}

absl::Status CameraSet::Snapshot(const Projector& old, const LiveSlot& slot, int layer, VideoLayers& video,
                                 RenderStats& stats) {
  if (options_.max_retained <= 0 || options_.display.retention_half_life_s <= 0) return absl::OkStatus();
  int same_camera = 0, pick = -1;
  for (const RetainedSnapshot& r : retained_) same_camera += r.in_use && r.camera_id == old.camera_id;
  auto older = [&](int a, int b) { return b < 0 || retained_[a].order < retained_[b].order; };
  for (int k = 0; k < static_cast<int>(retained_.size()); ++k) {
    const RetainedSnapshot& r = retained_[k];
    if (same_camera >= options_.max_retained_per_camera) {
      if (r.in_use && r.camera_id == old.camera_id && older(k, pick)) pick = k;
    } else if (!r.in_use) {
      pick = k;
      break;
    } else if (older(k, pick)) {
      pick = k;
    }
  }
  if (pick < 0) return absl::OkStatus();
  if (absl::Status s = video.KeepAsRetained(layer, pick); !s.ok()) return s;
  RetainedSnapshot& r = retained_[pick];
  r.in_use = true;
  r.camera_id = old.camera_id;
  r.projector = old;
  r.capture_time_s = slot.image_time_s;
  r.order = ++snapshot_counter_;
  r.shadow = ShadowSlot();
  ++stats.retained_snapshots;
  return CheckGl("retained snapshot");
}

std::vector<ProjectorPass> CameraSet::Passes(const Bounds& scene, std::vector<LineVertex>& volumes) const {
  std::vector<ProjectorPass> passes;
  for (size_t i = 0; i < projectors_.size(); ++i) {
    if (!LiveActive(i)) continue;
    ProjectorPass pass{&projectors_[i], static_cast<int>(i), false, 1.0f, {}};
    AppendFrustumVolume(projectors_[i], scene, slots_[i].shadow, volumes, pass.corners);
    passes.push_back(pass);
  }
  if (options_.display.retention_half_life_s > 0) {
    for (size_t k = 0; k < retained_.size(); ++k) {
      const RetainedSnapshot& r = retained_[k];
      if (!RetainedActive(r)) continue;
      ProjectorPass pass{&r.projector, static_cast<int>(k), true, static_cast<float>(Fade(r.capture_time_s)), {}};
      AppendFrustumVolume(r.projector, scene, r.shadow, volumes, pass.corners);
      passes.push_back(pass);
    }
  }
  return passes;
}

}  // namespace ave::viewer::internal
