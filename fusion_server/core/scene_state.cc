#include "fusion_server/core/scene_state.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "fusion_server/core/convert.h"

namespace ave {

SceneState::SceneState(SceneStateOptions options) : options_(options) {}

void SceneState::BumpLocked() {
  ++version_;
  changed_.notify_all();
}

void SceneState::UpsertCamera(const CameraEntry& camera) {
  std::lock_guard lock(mu_);
  cameras_[camera.id].entry = camera;
  BumpLocked();
}

bool SceneState::RemoveCamera(const std::string& id) {
  std::lock_guard lock(mu_);
  const bool erased = cameras_.erase(id) > 0;
  if (erased) BumpLocked();
  return erased;
}

std::optional<CameraEntry> SceneState::FindCamera(const std::string& id) const {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return std::nullopt;
  return it->second.entry;
}

std::vector<std::string> SceneState::CameraIds() const {
  std::lock_guard lock(mu_);
  std::vector<std::string> ids;
  for (const auto& [id, live] : cameras_) ids.push_back(id);
  return ids;
}

void SceneState::StreamOpened(const std::string& id, const PinholeIntrinsics& intrinsics) {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return;
  it->second.stream_intrinsics = intrinsics;
  ++it->second.open_streams;
  BumpLocked();
}

void SceneState::StreamClosed(const std::string& id) {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return;
  it->second.open_streams = std::max(0, it->second.open_streams - 1);
  BumpLocked();
}

absl::Status SceneState::AcceptFrame(const std::string& id, std::shared_ptr<const v1::SensorFrame> frame,
                                     int64_t received_ns) {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return absl::NotFoundError(absl::StrCat("camera '", id, "' is not registered"));
  if (frame->metadata_only()) {
    ++it->second.metadata;
    return absl::OkStatus();
  }
  ++it->second.accepted;
  it->second.latest = std::move(frame);
  it->second.latest_received_ns = received_ns;
  BumpLocked();
  return absl::OkStatus();
}

uint64_t SceneState::AcceptedCount(const std::string& id) const {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  return it == cameras_.end() ? 0 : it->second.accepted;
}

uint64_t SceneState::MetadataCount(const std::string& id) const {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  return it == cameras_.end() ? 0 : it->second.metadata;
}

int SceneState::OpenStreams(const std::string& id) const {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  return it == cameras_.end() ? 0 : it->second.open_streams;
}

std::shared_ptr<const v1::SensorFrame> SceneState::LatestFrame(const std::string& id) const {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  return it == cameras_.end() ? nullptr : it->second.latest;
}

uint64_t SceneState::version() const {
  std::lock_guard lock(mu_);
  return version_;
}

bool SceneState::WaitForChange(uint64_t seen, std::chrono::milliseconds timeout) const {
  std::unique_lock lock(mu_);
  return changed_.wait_for(lock, timeout, [&] { return version_ != seen || shut_down_; }) && !shut_down_;
}

void SceneState::Shutdown() {
  std::lock_guard lock(mu_);
  shut_down_ = true;
  BumpLocked();
}

bool SceneState::shut_down() const {
  std::lock_guard lock(mu_);
  return shut_down_;
}

v1::SceneUpdate SceneState::BuildUpdate(const std::vector<std::string>& camera_ids, bool include_jpeg, int64_t now_ns,
                                        ViewerCursor& cursor) const {
  std::lock_guard lock(mu_);
  v1::SceneUpdate update;
  update.set_server_time_ns(now_ns);
  cursor.last_sent.clear();
  cursor.last_skipped = 0;
  auto wanted = [&](const std::string& id) {
    return camera_ids.empty() || std::find(camera_ids.begin(), camera_ids.end(), id) != camera_ids.end();
  };
  std::set<std::string> present;
  for (const auto& [id, live] : cameras_) {
    if (!live.entry.enabled || !wanted(id)) continue;
    present.insert(id);
    v1::CameraState* cam = update.add_cameras();
    cam->set_camera_id(id);
    cam->set_name(live.entry.name);
    const PinholeIntrinsics k = live.stream_intrinsics.value_or(live.entry.intrinsics);
    *cam->mutable_intrinsics() = ToProto(k);
    // The frame's own pose when it carries one (a moving camera), else the mounting pose.
    v1::Pose pose = live.latest && live.latest->has_pose() ? live.latest->pose() : ToProto(live.entry.mounting_pose);
    SetMatrix(GlViewFromWorld(FromProto(pose)), cam->mutable_view_matrix());
    SetMatrix(GlProjection(k, options_.near_m, options_.far_m), cam->mutable_projection_matrix());
    *cam->mutable_pose() = std::move(pose);
    cam->set_near_m(static_cast<float>(options_.near_m));
    cam->set_far_m(static_cast<float>(options_.far_m));
    const int64_t age_ns = live.latest ? now_ns - live.latest_received_ns : INT64_MAX;
    const int64_t live_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(options_.live_window).count();
    const int64_t stale_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(options_.stale_window).count();
    if (live.latest && age_ns <= live_ns) {
      cam->set_status(v1::CAMERA_STATUS_LIVE);
    } else if (live.open_streams > 0 || age_ns <= stale_ns) {
      cam->set_status(v1::CAMERA_STATUS_STALE);
    } else {
      cam->set_status(v1::CAMERA_STATUS_LOST);
    }
    if (live.latest) {
      const int64_t capture_server_ns = live.latest->capture_time_ns() + live.latest->clock_offset_ns();
      cam->set_frame_capture_time_ns(live.latest->capture_time_ns());
      cam->set_frame_capture_server_time_ns(capture_server_ns);
      cam->set_frame_sequence(live.latest->sequence());
      *cam->mutable_boxes() = live.latest->boxes();
      uint64_t& sent = cursor.sent_sequence[id];
      if (include_jpeg && live.latest->sequence() != sent && !live.latest->jpeg().empty()) {
        cam->set_jpeg(live.latest->jpeg());
        sent = live.latest->sequence();
        auto [slot, first] = cursor.sent_accepted.try_emplace(id, live.accepted);
        // Frames that arrived after the previous send and were replaced before this one.
        if (!first && live.accepted > slot->second + 1) {
          const uint64_t skipped = live.accepted - slot->second - 1;
          cursor.skipped[id] += skipped;
          cursor.last_skipped += skipped;
        }
        slot->second = live.accepted;
        cursor.last_sent.emplace_back(live.latest_received_ns, capture_server_ns);
      }
      cam->set_frames_skipped(cursor.skipped[id]);
    }
  }
  for (const std::string& id : cursor.known_cameras) {
    if (!present.count(id)) {
      update.add_removed_camera_ids(id);
      cursor.sent_sequence.erase(id);
      cursor.sent_accepted.erase(id);
      cursor.skipped.erase(id);
    }
  }
  cursor.known_cameras = std::move(present);
  return update;
}

}  // namespace ave
