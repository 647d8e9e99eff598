#pragma once
// The viewer's link to the fusion server: fetches the static model once and keeps a subscription
// to the projection-ready scene state, decoding each camera's newest JPEG as it arrives.
// Reconnects with backoff if the server goes away.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"

namespace grpc {
class Channel;
}

namespace ave::viewer {

enum class CameraLiveness { kUnknown, kLive, kStale, kLost };

struct DecodedImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgba;  // top row first
};

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
};

struct SubscribeOptions {
  std::vector<std::string> camera_ids;  // empty = all
  float max_rate_hz = 30;
  bool include_jpeg = true;
};

class SceneClient {
 public:
  SceneClient(std::shared_ptr<grpc::Channel> channel, std::string viewer_token, std::string viewer_id);
  ~SceneClient();

  // The newest static model (all chunks merged), with its version.
  absl::StatusOr<TriangleMesh> FetchStaticModel(uint64_t* version = nullptr);

  // Starts the subscription thread; Stop() ends it.
  void Start(const SubscribeOptions& options);
  void Stop();

  std::vector<CameraView> Snapshot() const;
  uint64_t updates_received() const { return updates_.load(); }
  std::string last_error() const;

  // Waits until `ready(snapshot)` holds or the timeout passes; returns whether it held.
  bool WaitUntil(const std::function<bool(const std::vector<CameraView>&)>& ready, std::chrono::milliseconds timeout);

 private:
  void Loop(SubscribeOptions options);

  std::shared_ptr<grpc::Channel> channel_;
  std::string token_;
  std::string viewer_id_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  std::map<std::string, CameraView> cameras_;
  std::string last_error_;
  std::atomic<uint64_t> updates_{0};
  std::atomic<bool> stop_{false};
  std::shared_ptr<void> context_;  // the live grpc::ClientContext, so Stop() can cancel it
  std::thread thread_;
  uint64_t next_serial_ = 1;
};

}  // namespace ave::viewer
