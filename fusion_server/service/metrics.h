#pragma once
// Server metrics in the Prometheus text exposition format (version 0.0.4), served over a tiny
// HTTP/1.0 responder on its own thread (issue 8). Counters and histograms are lock-free atomics;
// rendering takes a consistent-enough snapshot (each value read once).
#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace ave {

// Cumulative histogram over fixed upper bounds in seconds (+Inf implicit).
class LatencyHistogram {
 public:
  static constexpr std::array<double, 14> kBounds = {0.001, 0.0025, 0.005, 0.01, 0.02, 0.035, 0.05,
                                                     0.075, 0.1,    0.15,  0.25,  0.5,  1.0,   2.5};
  void Observe(double seconds);
  // Appends "# TYPE name histogram" and its _bucket/_sum/_count lines.
  void Render(const std::string& name, const std::string& help, std::string& out) const;
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }

 private:
  std::array<std::atomic<uint64_t>, kBounds.size() + 1> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_us_{0};
};

struct ServerMetrics {
  std::atomic<uint64_t> frames_in{0};          // accepted sensor frames with a JPEG
  std::atomic<uint64_t> metadata_frames_in{0};  // replayed metadata-only frames
  std::atomic<uint64_t> bytes_in{0};
  std::atomic<uint64_t> frames_rejected{0};
  std::atomic<uint64_t> lidar_sweeps_in{0};  // accepted rotating-LiDAR sweeps (issue 16)
  std::atomic<uint64_t> frames_out{0};      // JPEGs written to viewers
  std::atomic<uint64_t> bytes_out{0};
  std::atomic<uint64_t> viewer_drops{0};    // frames skipped for a slow viewer (latest-frame semantics)
  std::atomic<uint64_t> updates_out{0};
  std::atomic<uint64_t> auth_failures{0};       // calls refused: bad or missing token, or outside the role
  std::atomic<uint64_t> auth_rate_limited{0};   // calls refused unread: their peer failed too often (issue 14)
  std::atomic<uint64_t> insecure_plaintext_warnings{0};
  std::atomic<int64_t> sensors_connected{0};
  std::atomic<int64_t> viewers_connected{0};
  std::atomic<int64_t> viewer_queue_depth{0};  // frames pending in viewers' (one-per-camera) slots
  std::atomic<int64_t> saturated{0};           // 1 while the flow hint is lowered
  std::atomic<int64_t> insecure_plaintext{0};  // 1 when serving plaintext off loopback (--insecure-plaintext)
  std::atomic<int64_t> auth_tracked_peers{0};  // peers with failed authentications in the limiter's table
  LatencyHistogram capture_to_ingest_s;  // skew-corrected capture -> accepted by the server
  LatencyHistogram ingest_to_send_s;     // accepted -> written to a viewer
  LatencyHistogram capture_to_send_s;    // skew-corrected capture -> written to a viewer
  // Appends further families (the recorder's ave_record_*, issue 18); set before serving.
  std::function<void(std::string&)> render_extra;

  std::string RenderPrometheus() const;
};

// Serves GET /metrics (and GET /healthz) as HTTP/1.0, one connection at a time.
class MetricsHttpServer {
 public:
  // `address` "host:port" (port 0 = any free port). `render` is called per request.
  static absl::StatusOr<std::unique_ptr<MetricsHttpServer>> Start(const std::string& address,
                                                                  std::function<std::string()> render);
  ~MetricsHttpServer();
  int port() const { return port_; }

 private:
  MetricsHttpServer(int fd, int port, std::function<std::string()> render);
  void Loop();
  int fd_;
  int port_;
  std::function<std::string()> render_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace ave
