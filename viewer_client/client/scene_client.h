#pragma once
// The viewer's link to the fusion server: fetches the static model once and keeps a subscription
// to the projection-ready scene state, decoding each camera's newest JPEG as it arrives.
// Reconnects with backoff if the server goes away.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "model_store/avatar/avatar_sequence.h"
#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"
#include "viewer_client/client/decoded_image.h"
#include "viewer_client/client/lidar_points.h"

namespace grpc {
class Channel;
}
namespace ave::v1 {
class LidarState;
}

namespace ave::viewer {

enum class CameraLiveness { kUnknown, kLive, kStale, kLost };

struct CameraView {
  std::string id;
  std::string name;
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();        // GL eye from world (server-computed)
  Eigen::Matrix4d projection = Eigen::Matrix4d::Identity();  // GL projection (server-computed)
  double near_m = 0.5, far_m = 600;
  CameraLiveness status = CameraLiveness::kUnknown;
  int64_t frame_capture_time_ns = 0;
  uint64_t frame_sequence = 0;
  std::shared_ptr<const DecodedImage> image;  // newest decoded frame, may be null
  uint64_t image_serial = 0;                  // changes whenever `image` does
  uint64_t jpegs_received = 0;                // frames received for this camera (data selection counts)
  uint64_t jpeg_bytes_received = 0;
  std::vector<int64_t> recent_frame_times_ns;  // capture times of the last frames received (time line)
  int server_index = 0;                        // which --server it came from
};

// A moving object the server tracks (proto DynamicObject), in the static model's local frame.
struct ObjectView {
  uint64_t id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // ground contact
  Eigen::Vector3d size = Eigen::Vector3d::Zero();      // width, length, height (m)
  double heading_rad = 0;
  int model = 0;  // proto ObjectModel
  uint32_t kind = 0;
  std::vector<Eigen::Vector3d> path;  // oldest first
  std::string source_camera_id;
  std::vector<std::string> sensor_ids;  // every camera or LiDAR observing it (DynamicObject.camera_ids)
  // A person's avatar (issue 17): empty sequence when the server holds none.
  std::string avatar_sequence;
  uint64_t avatar_version = 0;
  double avatar_phase_cycles = 0;
  double avatar_heading_rad = 0;
};

// A registered rotating LiDAR (issue 16; wire LidarState): not a camera, nothing to project. The
// people it tracks arrive as objects (person-sized billboards unless a camera measured them); its
// newest sweep's foreground points, when subscribed to, for a point-cloud layer.
struct LidarView {
  std::string id;
  std::string name;
  Rigid3d world_from_sensor;
  CameraLiveness status = CameraLiveness::kUnknown;
  int64_t sweep_capture_time_ns = 0;
  uint64_t sweep_sequence = 0;
  std::vector<LidarTrackView> tracks;             // the newest sweep's
  std::shared_ptr<const LidarPointCloud> points;  // the newest sweep's points received; null: none yet
  uint64_t points_serial = 0;                     // changes whenever `points` does
  uint64_t points_received = 0;                   // point clouds received for this LiDAR
  int server_index = 0;
};

// Data selection (issue 7): the frusta of the viewer's views, GL clip from the model's local frame.
struct SelectionViews {
  std::vector<Eigen::Matrix4d> clip_from_local;
  // World coordinates of the local frame's zero. Unset: the static model this client fetched (or
  // the server's own local frame before any fetch). A viewer of several servers draws in the
  // first one's frame and says so here.
  std::optional<Eigen::Vector3d> origin;
};

// Whether two sets of view frusta differ enough to ask the server again: a different count, or a
// frustum corner (clamped at `depth_m`) that moved by more than `fraction` of its frustum's size.
bool ViewsDifferALot(const SelectionViews& a, const SelectionViews& b, double fraction = 0.1, double depth_m = 300);

struct SubscribeOptions {
  std::vector<std::string> camera_ids;  // empty = all
  float max_rate_hz = 30;
  bool include_jpeg = true;
  uint32_t max_jpeg_width = 0;  // hint to the server, 0 = any
  // Rotating LiDARs' foreground points (issue 16); their tracks and status come regardless.
  bool include_lidar_points = true;
  // Data selection: re-subscribe with new views at most this often (SetViews).
  std::chrono::milliseconds reselect_interval{500};
  // The image size the renderer resamples frames to (its video layer; 0 = keep full size): a
  // frame at least twice as large is decoded at 1/2, 1/4 or 1/8 scale by the JPEG decoder, never
  // below this size.
  int decode_width = 0, decode_height = 0;
  // Replay (issue 18): when replay_to_ns > replay_from_ns, the client consumes SceneService.Replay
  // of that recorded interval (server clock, ns since the Unix epoch) at replay_rate instead of the
  // live subscription; everything downstream (snapshots, objects, LiDARs) is the same. A change
  // of views re-requests from the recorded time reached. The client stops when the replay ends.
  int64_t replay_from_ns = 0, replay_to_ns = 0;
  float replay_rate = 1;
  bool replay() const { return replay_to_ns > replay_from_ns; }
};

// What the server has recorded (issue 18, SceneService.RecordedSpans): the panel's time line.
struct RecordedCameraSpans {
  std::string camera_id;
  std::vector<std::pair<int64_t, int64_t>> intervals_ns;  // [first, last] capture time, oldest first
  uint64_t frames = 0;
};
struct RecordedSpans {
  std::vector<RecordedCameraSpans> cameras;
  int64_t server_time_ns = 0;  // the server clock when it answered
};

// Where a seek on the time line goes (a pure function of the spans, so it is tested without a
// window). Seeking at or after now - live_margin_ns is live. Inside a recorded interval (of any
// camera) the replay starts there; in a gap or before the first recording, at the next recorded
// instant; after the last one recorded, live. A replay runs to now_ns.
struct ReplaySeek {
  bool live = true;
  int64_t from_ns = 0, to_ns = 0;
};
ReplaySeek PlanSeek(int64_t seek_ns, int64_t now_ns, const RecordedSpans& spans, int64_t live_margin_ns = 1'000'000'000);

// The JPEG scale divisor (1, 2, 4 or 8) that keeps a frame_width x frame_height frame at least
// need_width x need_height; 1 when either need is 0 or the frame size is unknown.
int JpegReduction(int frame_width, int frame_height, int need_width, int need_height);

// DecodeJpeg, DecodeJpegFrame: decoded_image.h.

class SceneClient {
 public:
  SceneClient(std::shared_ptr<grpc::Channel> channel, std::string viewer_token, std::string viewer_id);
  ~SceneClient();

  // The newest static model (all chunks merged), with its version.
  absl::StatusOr<TriangleMesh> FetchStaticModel(uint64_t* version = nullptr);
  // An avatar sequence by name (issue 17), fetched whole (its chunks) and decoded; `version`
  // receives the store's version of it. Errors name the sequence.
  absl::StatusOr<avatar::AvatarSequence> FetchAvatarSequence(const std::string& name, uint64_t* version = nullptr);

  // Each camera's recorded intervals (all cameras when `camera_ids` is empty); the server must
  // record. Segments closer than 2 s are one interval.
  absl::StatusOr<RecordedSpans> FetchRecordedSpans(const std::vector<std::string>& camera_ids = {});

  // Starts the subscription thread; Stop() ends it.
  void Start(const SubscribeOptions& options);
  void Stop();

  // The cameras as last received. Frames are decoded here, not on arrival, and only each camera's
  // newest: a frame superseded before anyone asked for it is never decoded (issue 7 performance).
  std::vector<CameraView> Snapshot() const;
  std::vector<ObjectView> Objects() const;
  // The rotating LiDARs as last received (issue 16), by id.
  std::vector<LidarView> Lidars() const;
  uint64_t updates_received() const { return updates_.load(); }
  uint64_t jpeg_bytes_received() const { return jpeg_bytes_.load(); }
  uint64_t subscriptions() const { return subscriptions_.load(); }  // Subscribe calls made (re-subscribes count)
  uint64_t jpegs_decoded() const { return jpegs_decoded_.load(); }

  // Data selection: the views the viewer draws now, in the local frame of the static model (its
  // origin goes with them once FetchStaticModel ran; before, the server's own local frame). The
  // first call before Start() sets the initial subscription's views (none: every camera's
  // frames). Later calls re-subscribe when the views
  // differ a lot from the subscribed ones and reselect_interval has passed since the last
  // subscription; call every frame, a change held back by the rate limit goes out on a later call.
  void SetViews(const SelectionViews& views);
  // Whether the subscription asks for the LiDARs' points (the viewer's point layer is on);
  // starts as SubscribeOptions::include_lidar_points. A change re-subscribes at once; turned off,
  // every LiDAR's points are dropped (null) when the new subscription starts.
  void SetIncludeLidarPoints(bool include);
  // The views the current subscription carries.
  SelectionViews subscribed_views() const;
  // The origin of the static model fetched (the local frame the views are in).
  Eigen::Vector3d model_origin() const;
  std::string last_error() const;
  // Replay: whether it ended (its last update came, or the server refused it: last_error() says
  // why), and the recorded time the newest update showed.
  bool replay_ended() const { return replay_ended_.load(); }
  int64_t replay_time_ns() const { return replay_time_ns_.load(); }

  // Waits until `ready(snapshot)` holds or the timeout passes; returns whether it held.
  bool WaitUntil(const std::function<bool(const std::vector<CameraView>&)>& ready, std::chrono::milliseconds timeout);

 private:
  void Loop(SubscribeOptions options);
  void UpdateLidarLocked(const v1::LidarState& lidar, bool with_points);

  std::shared_ptr<grpc::Channel> channel_;
  std::string token_;
  std::string viewer_id_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  // The newest undecoded JPEG of a camera and the scale to decode it at.
  struct PendingJpeg {
    std::shared_ptr<const std::string> bytes;
    uint64_t frame_sequence = 0;
    int reduction = 1;
  };
  // Mutable: Snapshot() decodes pending frames into the cameras it returns.
  mutable std::map<std::string, CameraView> cameras_;
  mutable std::map<std::string, PendingJpeg> pending_;
  mutable std::atomic<uint64_t> jpegs_decoded_{0};
  std::vector<ObjectView> objects_;
  std::map<std::string, LidarView> lidars_;
  SelectionViews wanted_views_, subscribed_views_;
  std::chrono::steady_clock::time_point last_subscribe_{};
  bool resubscribe_ = false;  // the current subscription was cancelled to change views or points
  bool include_points_ = true;  // wanted; the current subscription's is in Loop's options
  Eigen::Vector3d model_origin_ = Eigen::Vector3d::Zero();
  std::chrono::milliseconds reselect_interval_{500};
  std::atomic<uint64_t> jpeg_bytes_{0};
  std::atomic<uint64_t> subscriptions_{0};
  std::string last_error_;
  std::atomic<uint64_t> updates_{0};
  std::atomic<bool> stop_{false};
  std::atomic<bool> replay_ended_{false};
  std::atomic<int64_t> replay_time_ns_{0};
  std::shared_ptr<void> context_;  // the live grpc::ClientContext, so Stop() can cancel it
  std::thread thread_;
  mutable uint64_t next_serial_ = 1;
};

}  // namespace ave::viewer
