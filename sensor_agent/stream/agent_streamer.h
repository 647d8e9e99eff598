#pragma once
// The agent's uplink: takes frames from a FrameSource, JPEG-encodes them, and streams them with
// their pose to the fusion server. Survives server restarts: on a broken stream it reconnects with
// jittered exponential backoff and carries on with the newest frame (latest-frame semantics; the
// bounded metadata buffer across outages arrives with issue 8).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/source/frame_source.h"

namespace ave {

struct AgentOptions {
  std::string server = "127.0.0.1:50051";
  std::string camera_id;
  std::string token;  // sensor bearer token
  std::string software_version = "ave-agent/0.1";
  double fps = 10;            // frames per second sent (the server's hint may lower it)
  int jpeg_quality = 80;      // 1..100 (the server's hint may override it)
  int64_t max_frames = 0;     // stop after this many frames sent (0 = no limit)
  double duration_s = 0;      // stop after this long (0 = no limit)
  std::chrono::milliseconds backoff_initial{200};
  std::chrono::milliseconds backoff_max{5000};
  std::optional<Rigid3d> mounting_pose;  // used when the source knows no pose of its own

  std::string Check() const;  // empty when usable, else names the field
};

struct AgentStats {
  int64_t frames_captured = 0;
  int64_t frames_sent = 0;
  int64_t frames_acked = 0;
  int64_t connects = 0;
  int64_t bytes_sent = 0;
  std::string last_error;
};

class AgentStreamer {
 public:
  AgentStreamer(AgentOptions options, std::unique_ptr<FrameSource> source);

  // Streams until `stop` becomes true, the source ends, max_frames or duration_s is reached, or
  // the server refuses this sensor for good (bad token: Unauthenticated / PermissionDenied).
  absl::Status Run(const std::atomic<bool>& stop);

  AgentStats stats() const;

 private:
  AgentOptions options_;
  std::unique_ptr<FrameSource> source_;
  mutable std::mutex stats_mu_;
  AgentStats stats_;
};

}  // namespace ave
