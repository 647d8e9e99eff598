#pragma once
// The fusion server: gRPC services for sensors, viewers and administrators over one SceneState
// and one SQLite model store. Start() binds (port 0 picks a free port), loads the camera registry
// and the static model from the store, and serves until Shutdown().
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "ave/net/tls.h"
#include "fusion_server/core/auth_limiter.h"
#include "fusion_server/core/flow.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/core/validation.h"

namespace ave {

struct ServerOptions {
  std::string listen_address = "127.0.0.1:50051";  // host:port; port 0 = any free port
  std::string store_path = "ave.db";               // SQLite file (":memory:" for tests)
  // Bootstrap bearer tokens per role (MISSION part G; empty = none). Sensors send theirs in the
  // hello; viewers and administrators in "authorization: Bearer <token>" metadata. They are kept
  // hashed like the tokens an administrator issues (stored hashed in the model store); the
  // bootstrap sensor token is a fleet token that may stream as any registered camera, issued
  // sensor tokens are bound to one camera.
  std::string sensor_token;
  std::string viewer_token;
  std::string admin_token;
  // Transport: TLS when tls.cert_file is set; mutual TLS when tls.client_ca_file is set too.
  // Plaintext on a non-loopback listen address is refused unless tls.insecure_plaintext is set
  // (--insecure-plaintext); then a warning is logged at start and every plaintext_warning_period,
  // and the metric ave_insecure_plaintext is 1 (issue 14).
  net::TlsServerOptions tls;
  std::chrono::milliseconds plaintext_warning_period{60'000};
  bool sensor_requires_client_cert = false;  // sensors must present a verified client certificate
  // Failed authentications per peer address (issue 14): beyond auth_limit.max_failures in a window
  // the peer's calls are refused (RESOURCE_EXHAUSTED) until the window ends.
  AuthLimiterOptions auth_limit;
  std::function<int64_t()> auth_clock_ns;  // the limiter's clock in ns (tests inject one); empty = steady clock
  // Prometheus text metrics over HTTP ("host:port", port 0 = any); empty = off.
  std::string metrics_listen;
  FlowOptions flow;  // server-wide budgets; max_fps/jpeg_quality come from the two hints below
  FrameLimits frame_limits;
  int max_message_bytes = 16 << 20;  // gRPC hard cap; frame_limits.max_jpeg_bytes is the clear-error limit
  float max_fps_hint = 30;           // flow-control hint sent to sensors (0 = none)
  uint32_t jpeg_quality_hint = 0;    // 0 = keep the sensor's
  float default_viewer_rate_hz = 30;
  float max_viewer_rate_hz = 60;
  bool seed_campus = true;     // store the built-in campus as the static model when the store has none
  double campus_grid_m = 2.0;  // its terrain grid resolution
  SceneStateOptions scene;
  // Recording (issue 18): when record_dir is set, every accepted frame is recorded there (segment
  // files) with its index in the store file (which must then be a file, not ":memory:").
  std::string record_dir;
  std::chrono::seconds record_retention{0};  // delete recordings older than this; 0 = keep
  int64_t record_max_bytes = 0;              // recording budget in bytes; 0 = the disk's size
  // Write + sync + commit period of the recorder (--record-sync-ms): a crash may lose the frames
  // received in the last period plus one flush; acknowledged frames are never lost.
  std::chrono::milliseconds record_sync_period{500};
  bool record_sync_per_file = false;  // --record-sync fdatasync: one fdatasync per segment, not one syncfs
  bool record_direct_io = true;       // segment batches written with O_DIRECT (--record-buffered-io: off)

  // Empty when usable, else names the bad field.
  std::string Check() const;
};

class FusionServer {
 public:
  static absl::StatusOr<std::unique_ptr<FusionServer>> Start(const ServerOptions& options);
  ~FusionServer();

  int port() const;
  int metrics_port() const;  // 0 when metrics are off
  std::string RenderMetrics() const;
  SceneState& state();
  // Blocks until every frame accepted before the call is recorded and indexed (no-op when not recording).
  void DrainRecorder();
  uint64_t static_model_version() const;

  // Stops accepting calls, wakes every subscriber and ends open streams after `grace`.
  void Shutdown(std::chrono::milliseconds grace = std::chrono::milliseconds(2000));
  // Blocks until the server has shut down.
  void Wait();

  struct Impl;

 private:
  explicit FusionServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave
