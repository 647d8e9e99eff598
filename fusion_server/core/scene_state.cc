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

uint64_t SceneState::StreamOpened(const std::string& id, const PinholeIntrinsics& intrinsics) {
  std::lock_guard lock(mu_);
  const uint64_t session = ++sessions_;
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return session;
  it->second.stream_intrinsics = intrinsics;
  ++it->second.open_streams;
  BumpLocked();
  return session;
}

uint64_t SceneState::StreamOpened(const std::string& id) {
  std::lock_guard lock(mu_);
  const uint64_t session = ++sessions_;
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return session;
  ++it->second.open_streams;
  BumpLocked();
  return session;
}

void SceneState::StreamClosed(const std::string& id) {
  std::lock_guard lock(mu_);
  auto it = cameras_.find(id);
  if (it == cameras_.end()) return;
  it->second.open_streams = std::max(0, it->second.open_streams - 1);
  BumpLocked();
}

namespace {

// The box's axis-aligned extent (x0, y0, x1, y1) from its corners.
std::array<double, 4> BoxExtent(const v1::DetectedBox& box) {
  std::array<double, 4> b = {1e300, 1e300, -1e300, -1e300};
  for (const v1::Point2& c : box.corners()) {
    b = {std::min<double>(b[0], c.x()), std::min<double>(b[1], c.y()), std::max<double>(b[2], c.x()),
         std::max<double>(b[3], c.y())};
  }
  return b;
}

// Places every box of `frame` (no lock held: the terrain is immutable).
std::vector<ObjectObservation> PlaceFrameBoxes(const TerrainModel& terrain, const PinholeIntrinsics& k,
                                               const Rigid3d& mounting_pose, const v1::SensorFrame& frame,
                                               const std::string& id, uint64_t session, int64_t t_ns) {
  const Rigid3d pose = frame.has_pose() ? FromProto(frame.pose()) : mounting_pose;
  Eigen::Matrix<double, 6, 6> covariance;
  const bool has_covariance = frame.has_pose() && frame.pose().covariance_size() == 36;
  if (has_covariance) {
    for (int i = 0; i < 36; ++i) covariance(i / 6, i % 6) = frame.pose().covariance(i);
  }
  std::vector<ObjectObservation> placed;
  for (const v1::DetectedBox& box : frame.boxes()) {
    if (auto p = PlaceBox(terrain, k, pose, has_covariance ? &covariance : nullptr, BoxExtent(box))) {
      placed.push_back({id, box.track_id(), t_ns, *p, session});
    }
  }
  return placed;
}

// Object time on the server clock (see SetStaticModel).
int64_t ObjectTimeNs(const v1::SensorFrame& frame, int64_t received_ns) {
  if (frame.clock_offset_ns() == 0) return received_ns;
  return std::min(frame.capture_time_ns() + frame.clock_offset_ns(), received_ns);
}

}  // namespace

absl::Status SceneState::AcceptFrame(const std::string& id, std::shared_ptr<const v1::SensorFrame> frame,
                                     int64_t received_ns, uint64_t session) {
  const int64_t t_ns = ObjectTimeNs(*frame, received_ns);
  std::shared_ptr<const TerrainModel> terrain;
  std::vector<ObjectObservation> placed;
  if (!frame->metadata_only()) {
    PinholeIntrinsics k;
    Rigid3d mounting_pose;
    {
      std::lock_guard lock(mu_);
      auto it = cameras_.find(id);
      if (it == cameras_.end()) return absl::NotFoundError(absl::StrCat("camera '", id, "' is not registered"));
      terrain = terrain_;
      k = it->second.stream_intrinsics.value_or(it->second.entry.intrinsics);
      mounting_pose = it->second.entry.mounting_pose;
    }
    if (terrain && frame->boxes_size() > 0) {
      placed = PlaceFrameBoxes(*terrain, k, mounting_pose, *frame, id, session, t_ns);
    }
  }
  {
    std::lock_guard lock(mu_);
    auto it = cameras_.find(id);
    if (it == cameras_.end()) return absl::NotFoundError(absl::StrCat("camera '", id, "' is not registered"));
    if (it->second.entry.kind != SensorKind::kCamera) {
      return absl::FailedPreconditionError(absl::StrCat("sensor '", id, "' is registered as a rotating LiDAR, not a camera"));
    }
    if (frame->metadata_only()) {
      ++it->second.metadata;
      return absl::OkStatus();
    }
    ++it->second.accepted;
    it->second.latest = frame;
    it->second.latest_received_ns = received_ns;
    for (const ObjectObservation& observation : placed) ObserveLocked(observation);
    if (terrain) ExpireObjectsLocked(t_ns);
    BumpLocked();
  }
  if (frame_observer_) frame_observer_(id, frame, received_ns, t_ns);
  return absl::OkStatus();
}

void SceneState::ExpireObjectsLocked(int64_t t_ns) {
  // Expiry and merging look at every object: at most ten times a second of object time.
  constexpr int64_t kExpireEveryNs = 100'000'000;
  if (t_ns - objects_expired_ns_ >= kExpireEveryNs || t_ns < objects_expired_ns_ - 10 * kExpireEveryNs) {
    objects_.Expire(t_ns);
    objects_expired_ns_ = t_ns;
    std::vector<uint64_t> live;
    for (const FusedObject* o : objects_.Live(t_ns)) live.push_back(o->id);
    avatars_.Retain(live);
  }
}

void SceneState::ObserveLocked(const ObjectObservation& observation) {
  const uint64_t id = objects_.Observe(observation);
  // Every object's avatar pose follows it (its kind may settle on person later); only persons'
  // poses go out (BuildUpdate).
  if (const FusedObject* o = objects_.Find(id)) avatars_.Update(id, o->position.head<2>(), observation.t_ns, o->heading_rad);
}

void SceneState::SetAvatarSequences(std::vector<AvatarSequenceInfo> sequences) {
  std::lock_guard lock(mu_);
  avatars_.SetSequences(std::move(sequences));
  BumpLocked();
}

namespace {

// A LiDAR foot track as an object observation (issue 16): the track's ground position and
// covariance as they came, the height from the terrain below when the server has one.
ObjectObservation LidarObservation(const TerrainModel* terrain, const v1::FootTrack& track, const std::string& id,
                                   uint64_t session, int64_t t_ns, const Eigen::Vector3d& sensor_in_world) {
  ObjectObservation obs;
  obs.camera_id = id;
  obs.track_id = track.track_id();
  obs.t_ns = t_ns;
  obs.session = session;
  obs.size_measured = false;
  Placement& z = obs.placement;
  z.position = Eigen::Vector3d(track.position().x(), track.position().y(), track.position().z());
  if (terrain) {
    constexpr double kAboveM = 50;
    if (auto hit = terrain->Raycast(z.position + Eigen::Vector3d(0, 0, kAboveM), -Eigen::Vector3d::UnitZ(), 2 * kAboveM)) {
      z.position.z() = hit->point.z();
    }
  }
  z.covariance_xy << track.covariance(0), track.covariance(1), track.covariance(1), track.covariance(2);
  z.covariance_xy.diagonal() = z.covariance_xy.diagonal().cwiseMax(1e-4);  // validated PSD; floored like placements
  z.size_m = Eigen::Vector3d(kLidarPersonSizeM[0], kLidarPersonSizeM[1], kLidarPersonSizeM[2]);
  z.range_m = (z.position - sensor_in_world).head<2>().norm();
  z.kind = ObjectKind::kPerson;
  z.shape = ObjectShape::kBillboard;
  return obs;
}

int64_t SweepTimeNs(const v1::LidarSweepFrame& sweep, int64_t received_ns) {
  if (sweep.clock_offset_ns() == 0) return received_ns;
  return std::min(sweep.capture_time_ns() + sweep.clock_offset_ns(), received_ns);
}

}  // namespace

absl::Status SceneState::AcceptLidarSweep(const std::string& id, std::shared_ptr<const v1::LidarSweepFrame> sweep,
                                          int64_t received_ns, uint64_t session) {
  const int64_t t_ns = SweepTimeNs(*sweep, received_ns);
  std::shared_ptr<const TerrainModel> terrain;
  Rigid3d world_from_sensor;
  const auto check = [&](const Live* live) -> absl::Status {
    if (!live) return absl::NotFoundError(absl::StrCat("lidar '", id, "' is not registered"));
    if (live->entry.kind != SensorKind::kRotatingLidar) {
      return absl::FailedPreconditionError(absl::StrCat("sensor '", id, "' is registered as a camera, not a rotating LiDAR"));
    }
    return absl::OkStatus();
  };
  {
    std::lock_guard lock(mu_);
    auto it = cameras_.find(id);
    if (absl::Status s = check(it == cameras_.end() ? nullptr : &it->second); !s.ok()) return s;
    terrain = terrain_;
    world_from_sensor = it->second.entry.mounting_pose;
  }
  if (sweep->has_world_from_sensor()) world_from_sensor = FromProto(sweep->world_from_sensor());
  // Terrain heights on the caller's thread, before the lock (the terrain is immutable).
  std::vector<ObjectObservation> observations;
  observations.reserve(sweep->tracks_size());
  for (const v1::FootTrack& track : sweep->tracks()) {
    observations.push_back(LidarObservation(terrain.get(), track, id, session, t_ns, world_from_sensor.translation));
  }
  {
    std::lock_guard lock(mu_);
    auto it = cameras_.find(id);
    if (absl::Status s = check(it == cameras_.end() ? nullptr : &it->second); !s.ok()) return s;
    Live& live = it->second;
    ++live.accepted;
    live.latest_sweep = sweep;
    live.latest_received_ns = received_ns;
    live.sweep_session = session;
    for (const ObjectObservation& observation : observations) ObserveLocked(observation);
    ExpireObjectsLocked(t_ns);
    BumpLocked();
  }
  if (sweep_observer_) sweep_observer_(id, sweep, received_ns, t_ns);
  return absl::OkStatus();
}

void SceneState::SetStaticModel(const TriangleMesh& mesh) { SetTerrain(std::make_shared<const TerrainModel>(mesh)); }

void SceneState::SetTerrain(std::shared_ptr<const TerrainModel> terrain) {
  std::lock_guard lock(mu_);
  terrain_ = std::move(terrain);
}

std::shared_ptr<const TerrainModel> SceneState::terrain() const {
  std::lock_guard lock(mu_);
  return terrain_;
}

void SceneState::SetObservers(FrameObserver frames, SweepObserver sweeps) {
  frame_observer_ = std::move(frames);
  sweep_observer_ = std::move(sweeps);
}

size_t SceneState::ObjectCount() const {
  std::lock_guard lock(mu_);
  return objects_.size();
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
  v1::SceneUpdate update;
  BuildUpdate(camera_ids, include_jpeg, now_ns, cursor, update);
  return update;
}

void SceneState::BuildUpdate(const std::vector<std::string>& camera_ids, bool include_jpeg, int64_t now_ns,
                             ViewerCursor& cursor, v1::SceneUpdate& update) const {
  update.Clear();
  // Boxes and JPEGs (~50 KB each) are copied into the update after the lock is released: the
  // frames are immutable and held by shared_ptr. (camera, frame, whether its JPEG goes out)
  struct Copy {
    v1::CameraState* cam;
    std::shared_ptr<const v1::SensorFrame> frame;
    bool jpeg;
  };
  std::vector<Copy> copies;
  struct LidarCopy {
    v1::LidarState* lidar;
    std::shared_ptr<const v1::LidarSweepFrame> sweep;
    bool points;
  };
  std::vector<LidarCopy> lidar_copies;
  std::unique_lock lock(mu_);
  update.set_server_time_ns(now_ns);
  cursor.last_sent.clear();
  cursor.last_skipped = 0;
  cursor.last_selected = 0;
  auto wanted = [&](const std::string& id) {
    return camera_ids.empty() || std::find(camera_ids.begin(), camera_ids.end(), id) != camera_ids.end();
  };
  std::set<std::string> present;
  for (const auto& [id, live] : cameras_) {
    if (!live.entry.enabled || !wanted(id)) continue;
    present.insert(id);
    if (live.entry.kind == SensorKind::kRotatingLidar) {
      v1::LidarState* lidar = update.add_lidars();
      lidar->set_sensor_id(id);
      lidar->set_name(live.entry.name);
      *lidar->mutable_pose() = live.latest_sweep && live.latest_sweep->has_world_from_sensor()
                                   ? live.latest_sweep->world_from_sensor()
                                   : ToProto(live.entry.mounting_pose);
      lidar->set_status(StatusLocked(live, now_ns));
      if (!live.latest_sweep) continue;
      const v1::LidarSweepFrame& sweep = *live.latest_sweep;
      lidar->set_sweep_capture_time_ns(sweep.capture_time_ns());
      lidar->set_sweep_capture_server_time_ns(sweep.capture_time_ns() + sweep.clock_offset_ns());
      lidar->set_sweep_sequence(sweep.sequence());
      for (const v1::FootTrack& track : sweep.tracks()) {
        lidar->add_track_object_ids(objects_.TiedObject(id, live.sweep_session, track.track_id()));
      }
      uint64_t& sent = cursor.sent_sequence[id];
      const bool send_points =
          cursor.include_lidar_points && sweep.sequence() != sent && sweep.foreground().count() > 0;
      if (send_points) sent = sweep.sequence();
      lidar_copies.push_back({lidar, live.latest_sweep, send_points});
      continue;
    }
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
    cam->set_status(StatusLocked(live, now_ns));
    const bool in_view =
        cursor.views.empty() ||
        AnyIntersects(CameraVolume(k, FromProto(cam->pose()), options_.near_m, options_.far_m, cursor.selection_floor_z),
                      cursor.views);
    cursor.last_selected += in_view;
    if (live.latest && !in_view) cursor.sent_accepted[id] = live.accepted;  // out of view: not skipped
    if (live.latest) {
      const int64_t capture_server_ns = live.latest->capture_time_ns() + live.latest->clock_offset_ns();
      cam->set_frame_capture_time_ns(live.latest->capture_time_ns());
      cam->set_frame_capture_server_time_ns(capture_server_ns);
      cam->set_frame_sequence(live.latest->sequence());
      uint64_t& sent = cursor.sent_sequence[id];
      const bool send_jpeg = include_jpeg && in_view && live.latest->sequence() != sent && !live.latest->jpeg().empty();
      copies.push_back({cam, live.latest, send_jpeg});
      if (send_jpeg) {
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
  for (const FusedObject* o : objects_.Live(now_ns)) {
    if (!std::any_of(o->cameras.begin(), o->cameras.end(), [&](const auto& c) { return wanted(c.first); })) continue;
    v1::DynamicObject* out = update.add_objects();
    out->set_object_id(o->id);
    out->mutable_position()->set_x(o->position.x());
    out->mutable_position()->set_y(o->position.y());
    out->mutable_position()->set_z(o->position.z());
    out->mutable_size()->set_x(o->size_m.x());
    out->mutable_size()->set_y(o->size_m.y());
    out->mutable_size()->set_z(o->size_m.z());
    out->set_heading_rad(static_cast<float>(o->heading_rad));
    out->set_source_camera_id(o->newest_camera);
    out->set_model(static_cast<v1::ObjectModel>(o->shape));
    out->add_position_covariance(static_cast<float>(o->covariance_xy(0, 0)));
    out->add_position_covariance(static_cast<float>(o->covariance_xy(0, 1)));
    out->add_position_covariance(static_cast<float>(o->covariance_xy(1, 1)));
    for (const Eigen::Vector3d& p : o->path) {
      v1::Vec3* q = out->add_path();
      q->set_x(p.x()), q->set_y(p.y()), q->set_z(p.z());
    }
    for (const auto& c : o->cameras) out->add_camera_ids(c.first);
    out->set_last_seen_ns(o->last_seen_ns);
    out->set_kind(static_cast<uint32_t>(o->kind));
    const AvatarPose* avatar = o->kind == ObjectKind::kPerson ? avatars_.Find(o->id) : nullptr;
    if (avatar && !avatar->sequence.empty()) {
      out->set_avatar_sequence(avatar->sequence);
      out->set_avatar_sequence_version(static_cast<uint64_t>(avatar->sequence_version));
      out->set_avatar_phase_cycles(static_cast<float>(avatar->phase_cycles));
      out->set_avatar_heading_rad(static_cast<float>(avatar->heading_rad));
      out->set_avatar_placement(avatar->placement);
    }
  }
  lock.unlock();
  for (const Copy& c : copies) {
    *c.cam->mutable_boxes() = c.frame->boxes();
    if (c.jpeg) c.cam->set_jpeg(c.frame->jpeg());
  }
  for (const LidarCopy& c : lidar_copies) {
    *c.lidar->mutable_tracks() = c.sweep->tracks();
    if (c.points) *c.lidar->mutable_foreground() = c.sweep->foreground();
  }
}

v1::CameraStatus SceneState::StatusLocked(const Live& live, int64_t now_ns) const {
  const bool any = live.latest || live.latest_sweep;
  const int64_t age_ns = any ? now_ns - live.latest_received_ns : INT64_MAX;
  const int64_t live_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(options_.live_window).count();
  const int64_t stale_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(options_.stale_window).count();
  if (any && age_ns <= live_ns) return v1::CAMERA_STATUS_LIVE;
  if (live.open_streams > 0 || age_ns <= stale_ns) return v1::CAMERA_STATUS_STALE;
  return v1::CAMERA_STATUS_LOST;
}

}  // namespace ave
