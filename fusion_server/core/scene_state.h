#pragma once
// The server's live scene: the camera registry plus the latest frame of every camera, and the
// projection-ready view of it that each viewer receives. Pure (no gRPC); thread-safe.
//
// Latest-frame semantics: a camera keeps only its newest accepted frame; a viewer that falls behind
// simply receives the newest frame when it next asks, never a queue of old ones.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "fusion_server/core/avatar_assign.h"
#include "fusion_server/core/objects.h"
#include "fusion_server/core/placement.h"
#include "fusion_server/core/view_select.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"
#include "ave/v1/ave.pb.h"

namespace ave {

// What a registered sensor is (wire: ave.v1.SensorKind).
enum class SensorKind : uint8_t { kCamera = 0, kRotatingLidar = 1 };

// A registered sensor. A rotating LiDAR (issue 16) has no intrinsics; its mounting_pose is
// world_from_sensor.
struct CameraEntry {
  std::string id;
  std::string name;
  PinholeIntrinsics intrinsics;
  Rigid3d mounting_pose;  // world_from_camera, local frame
  std::string source_url;
  bool enabled = true;
  SensorKind kind = SensorKind::kCamera;
};

// LiDAR foot tracks (issue 16) fuse as persons of this size (width, length, height; metres) until
// a camera measures one: a track is a ground position only.
inline constexpr double kLidarPersonSizeM[3] = {0.6, 0.6, 1.75};

struct SceneStateOptions {
  double near_m = 0.5;                          // GL projection near plane handed to viewers
  double far_m = 600;                           // and far plane
  std::chrono::milliseconds live_window{2000};  // a frame this recent: LIVE
  std::chrono::milliseconds stale_window{30000};
};

// What one subscriber has been sent so far (sequence per camera), so that JPEGs go out once.
// Each viewer has in effect a one-slot queue per camera: a newer frame replaces an unsent one, and
// the replaced frames are counted as skipped for this viewer only.
struct ViewerCursor {
  std::map<std::string, uint64_t> sent_sequence;
  std::map<std::string, uint64_t> sent_accepted;  // the camera's accepted-frame count at the last send
  std::map<std::string, uint64_t> skipped;        // frames skipped per camera, cumulative
  std::set<std::string> known_cameras;
  // Filled by BuildUpdate for the JPEGs it put in the update: (received_ns, capture on the server clock).
  std::vector<std::pair<int64_t, int64_t>> last_sent;
  uint64_t last_skipped = 0;  // frames skipped by the last BuildUpdate
  // Data selection (issue 7, view_select.h): when `views` is non-empty, a camera's JPEG goes out
  // only while its viewing volume, cut at selection_floor_z (local frame), intersects one of them;
  // poses and status go out for every camera. Frames that arrive while a camera is out of view are
  // not counted as skipped. last_selected: cameras whose frames the last BuildUpdate could send.
  std::vector<ConvexVolume> views;
  double selection_floor_z = -std::numeric_limits<double>::infinity();
  size_t last_selected = 0;
  // Rotating LiDARs (issue 16): send each sweep's foreground points (once, like JPEGs: the
  // sequence sent goes to sent_sequence under the LiDAR's id).
  bool include_lidar_points = false;
};

class SceneState {
 public:
  explicit SceneState(SceneStateOptions options = {});

  void UpsertCamera(const CameraEntry& camera);
  bool RemoveCamera(const std::string& id);
  std::optional<CameraEntry> FindCamera(const std::string& id) const;
  std::vector<std::string> CameraIds() const;

  // A sensor stream opened (with the intrinsics it announced) or closed. StreamOpened returns the
  // stream's session number (unique in this server's life, > 0) to pass to AcceptFrame.
  uint64_t StreamOpened(const std::string& id, const PinholeIntrinsics& intrinsics);
  // A sensor without intrinsics (a rotating LiDAR) opened a stream.
  uint64_t StreamOpened(const std::string& id);
  void StreamClosed(const std::string& id);

  // Keeps `frame` as the camera's latest. NotFound when the camera is not (or no longer) registered.
  // A metadata-only frame (replayed after an outage) is counted but does not replace the latest
  // image. The frame's clock_offset_ns, when set, places its capture time on the server clock.
  // Its boxes are placed on the terrain on the caller's thread before the state's lock is taken;
  // `session` keeps the track ids of different stream sessions of one camera apart.
  absl::Status AcceptFrame(const std::string& id, std::shared_ptr<const v1::SensorFrame> frame, int64_t received_ns,
                           uint64_t session = 0);

  // Keeps a rotating LiDAR's sweep (issue 16) as its latest and fuses its foot tracks into the
  // objects (ground positions with covariance; heights from the static model's terrain when there
  // is one, else the track's own z). NotFound when the sensor is not registered, FailedPrecondition
  // when it is registered as a camera. Object time as for AcceptFrame.
  absl::Status AcceptLidarSweep(const std::string& id, std::shared_ptr<const v1::LidarSweepFrame> sweep,
                                int64_t received_ns, uint64_t session = 0);

  // Frames with a JPEG accepted for a camera since it was registered (0 for an unknown camera);
  // for a LiDAR, sweeps accepted.
  uint64_t AcceptedCount(const std::string& id) const;
  uint64_t MetadataCount(const std::string& id) const;
  int OpenStreams(const std::string& id) const;

  // The latest accepted frame of a camera, if any.
  std::shared_ptr<const v1::SensorFrame> LatestFrame(const std::string& id) const;

  // Moving objects (issue 6): with a static model set, the boxes of every accepted frame are placed
  // on its terrain (placement.h) and fused across cameras (objects.h); BuildUpdate sends the live
  // objects seen by the requested cameras. Without one, boxes are forwarded but not placed.
  // Object time is the capture time on the server clock when the frame carries the agent's clock
  // offset (never later than its receipt), else the server's receipt time: an agent that has not
  // yet measured its offset cannot make objects expire early or linger.
  void SetStaticModel(const TriangleMesh& mesh);
  // The same ground shared with another state (a replay's, issue 18) without rebuilding it.
  void SetTerrain(std::shared_ptr<const TerrainModel> terrain);
  std::shared_ptr<const TerrainModel> terrain() const;
  size_t ObjectCount() const;
  // Avatars (issue 17): the stored sequences people get (avatar_assign.h). Each person object in
  // an update then carries its avatar's sequence, phase, smoothed heading and placement count.
  void SetAvatarSequences(std::vector<AvatarSequenceInfo> sequences);

  // Called after every accepted frame with a JPEG / sweep, on the accepting thread and outside the
  // state's lock, with its capture time on the server clock (the object time above): the recorder
  // (issue 18) hangs here. Set before any frame arrives; an observer must not block.
  using FrameObserver = std::function<void(const std::string& id, const std::shared_ptr<const v1::SensorFrame>& frame,
                                           int64_t received_ns, int64_t capture_server_ns)>;
  using SweepObserver = std::function<void(const std::string& id, const std::shared_ptr<const v1::LidarSweepFrame>& sweep,
                                           int64_t received_ns, int64_t capture_server_ns)>;
  void SetObservers(FrameObserver frames, SweepObserver sweeps);

  // Monotonic counter bumped by every change; WaitForChange returns true when it moved past `seen`.
  uint64_t version() const;
  bool WaitForChange(uint64_t seen, std::chrono::milliseconds timeout) const;
  // Wakes every waiter for good (server shutdown).
  void Shutdown();
  bool shut_down() const;

  // The update for one viewer: every enabled camera in `camera_ids` (all when empty) with its
  // matrices and status, its JPEG only when newer than what the cursor says was sent, and the ids
  // of cameras the viewer knew that are gone. Advances the cursor.
  v1::SceneUpdate BuildUpdate(const std::vector<std::string>& camera_ids, bool include_jpeg, int64_t now_ns,
                              ViewerCursor& cursor) const;
  // The same, filled into `update` (which may live on a protobuf arena); the state's lock is not held
  // while JPEGs and boxes are copied into it.
  void BuildUpdate(const std::vector<std::string>& camera_ids, bool include_jpeg, int64_t now_ns, ViewerCursor& cursor,
                   v1::SceneUpdate& update) const;

 private:
  struct Live {
    CameraEntry entry;
    std::optional<PinholeIntrinsics> stream_intrinsics;
    int open_streams = 0;
    std::shared_ptr<const v1::SensorFrame> latest;
    int64_t latest_received_ns = 0;
    uint64_t accepted = 0;
    uint64_t metadata = 0;
    // Rotating LiDARs: the newest sweep and its stream session (its tracks' ties to objects).
    std::shared_ptr<const v1::LidarSweepFrame> latest_sweep;
    uint64_t sweep_session = 0;
  };
  void BumpLocked();
  // ObjectFusion::Expire at most ten times a second of object time.
  void ExpireObjectsLocked(int64_t t_ns);
  // ObjectFusion::Observe, then the object's avatar pose.
  void ObserveLocked(const ObjectObservation& observation);
  v1::CameraStatus StatusLocked(const Live& live, int64_t now_ns) const;

  SceneStateOptions options_;
  mutable std::mutex mu_;
  mutable std::condition_variable changed_;
  std::map<std::string, Live> cameras_;
  std::shared_ptr<const TerrainModel> terrain_;
  ObjectFusion objects_;
  AvatarAssigner avatars_;
  int64_t objects_expired_ns_ = 0;  // object time of the last ObjectFusion::Expire (run <= 10 Hz)
  uint64_t sessions_ = 0;
  FrameObserver frame_observer_;
  SweepObserver sweep_observer_;
  uint64_t version_ = 1;
  bool shut_down_ = false;
};

}  // namespace ave
