#pragma once
// The agent's uplink: takes frames from a FrameSource, JPEG-encodes them, and streams them with
// their pose to the fusion server. Survives server restarts: on a broken stream it reconnects with
// jittered exponential backoff and carries on with the newest frame (latest-frame semantics).
// During an outage it keeps capturing and buffers each frame's pose and boxes (bounded, spilled to
// disk when long) and replays them, oldest first, as metadata-only frames once it is back (issue 8).
// It estimates the offset between its clock and the server's from ack round trips and sends it
// with every frame, so the server places captures on its own clock.
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "ave/net/tls.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/source/frame_source.h"

namespace ave {

// One tracked object in a frame: four corners clockwise from the top-left (pixels, origin at the
// top-left pixel's corner), its stable track id and a score in [0, 1] (wire: ave.v1.DetectedBox).
struct FrameBox {
  uint32_t track_id = 0;
  std::array<std::array<float, 2>, 4> corners{};
  float score = 0;
};

struct AgentOptions {
  std::string server = "127.0.0.1:50051";
  std::string camera_id;
  std::string token;  // sensor bearer token
  std::string software_version = "ave-agent/0.1";
  double fps = 10;            // frames per second sent (the server's hint may lower it)
  // Paced (non-live) sources keep a fixed frame schedule through a frame that ran late by up to
  // this much (the next frames go out sooner: the camera's rate holds on average, issue 19);
  // later than that, the schedule restarts. 0: every late frame restarts it (before issue 19).
  std::chrono::milliseconds pace_max_lag{250};
  int jpeg_quality = 80;      // 1..100 (the server's hint may override it)
  int64_t max_frames = 0;     // stop after this many frames sent (0 = no limit)
  double duration_s = 0;      // stop after this long (0 = no limit)
  std::chrono::milliseconds backoff_initial{200};
  // Kept at 2 s so that an agent is back within ~2.5 s of the server's return (issue 8: 5 s).
  std::chrono::milliseconds backoff_max{2000};
  // A source that fails to deliver (a network camera down, a read error) is retried after
  // `source_retry_initial`, doubling to `source_retry_max` while it stays down, and logged at each
  // doubling and then once every `source_log_every` (not at every attempt).
  std::chrono::milliseconds source_retry_initial{200};
  std::chrono::milliseconds source_retry_max{5000};
  std::chrono::milliseconds source_log_every{30000};
  // A link that silently stops carrying data (a blocked route, a dead Wi-Fi) is detected by HTTP/2
  // keepalive pings: unanswered for `keepalive` after `keepalive` of silence = the link is dead,
  // the stream fails and the agent reconnects. Also bounds a connection attempt that hangs.
  std::chrono::milliseconds keepalive{1500};
  net::TlsClientOptions tls;  // TLS (and mutual TLS) to the server; empty ca_file = plaintext
  // Metadata kept across outages: records in memory, then spilled to `spill_path` (empty: a file
  // in the temp directory named after the camera; "-" = no spill).
  size_t metadata_in_memory = 4096;
  std::string spill_path;
  size_t metadata_max_spilled = 1'000'000;
  // The sensor's clock (ns); capture stamps from the source are taken to be on it.
  std::function<int64_t()> clock;
  std::optional<Rigid3d> mounting_pose;  // used when the source knows no pose of its own
  // Set: runs on every captured frame (the agent's detection and tracking, issue 6); the boxes it
  // returns travel with that frame (and with its buffered metadata during an outage).
  std::function<std::vector<FrameBox>(const CapturedFrame&)> detector;

  std::string Check() const;  // empty when usable, else names the field
};

struct AgentStats {
  int64_t frames_captured = 0;
  int64_t frames_sent = 0;
  int64_t frames_acked = 0;
  int64_t connects = 0;
  int64_t bytes_sent = 0;
  int64_t metadata_buffered = 0;  // records buffered during outages
  int64_t metadata_replayed = 0;  // records replayed after reconnecting
  int64_t metadata_dropped = 0;   // records lost to the buffer bound
  int64_t clock_offset_ns = 0;    // current estimate of server clock - sensor clock
  int64_t clock_rtt_ns = 0;       // round trip of the sample it came from
  float hint_fps = 0;             // last flow hint
  // The highest SensorAck.recorded_sequence (issue 18): that frame is on the server's disk and
  // indexed; a server crash cannot lose it. 0: none yet, or the server does not record.
  uint64_t recorded_sequence = 0;
  int64_t source_errors = 0;      // reads the source failed (each retry counts)
  int64_t source_outages = 0;     // runs of failed reads ended by a frame or still going
  double source_down_s = 0;       // time spent in the runs that ended
  int64_t source_drop_outs = 0;   // a network source's own count (at the end of Run)
  int64_t source_reconnects = 0;
  std::string last_error;
};

// Server-minus-sensor clock offset from ack round trips: for a frame sent at local t0, acked with
// server time ts and received at t1, offset = ts - (t0 + t1) / 2 with error at most (t1 - t0) / 2.
// Keeps the sample with the smallest round trip among the last `window` (an NTP-like filter).
class ClockOffsetEstimator {
 public:
  explicit ClockOffsetEstimator(size_t window = 64) : window_(window) {}
  void Sent(uint64_t sequence, int64_t local_ns);
  // Returns false when the sequence's send time is unknown (too old).
  bool Acked(uint64_t sequence, int64_t server_ns, int64_t local_ns);
  bool known() const { return known_; }
  int64_t offset_ns() const { return offset_ns_; }
  int64_t rtt_ns() const { return rtt_ns_; }

 private:
  static constexpr size_t kRing = 1024;
  std::array<std::pair<uint64_t, int64_t>, kRing> sent_{};
  size_t window_;
  std::vector<std::pair<int64_t, int64_t>> samples_;  // (rtt, offset), newest last
  bool known_ = false;
  int64_t offset_ns_ = 0;
  int64_t rtt_ns_ = 0;
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
