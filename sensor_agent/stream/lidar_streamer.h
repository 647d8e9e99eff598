#pragma once
// The LiDAR agent's uplink (issue 16, i4D §3.2): takes sweeps from a source callback, runs the
// people tracker on every one of them (in order, online), and streams each sweep's confirmed foot
// tracks — in the world frame — and optionally its labelled foreground points to the fusion server
// on SensorService.Stream (hello kind SENSOR_KIND_ROTATING_LIDAR). Reconnects with jittered
// exponential backoff like the camera path (AgentStreamer) and estimates the server-minus-sensor
// clock offset from ack round trips. During an outage the tracker keeps running (its ids stay
// stable) but the sweeps are not buffered: a person's position of seconds ago is of no use to the
// live scene, unlike a camera's pose history.
//
// Frames: the tracker reports tracks in its ground frame with `FootTracks::world_from_ground`;
// the streamer applies it (positions, velocities, covariances) so the wire carries world
// coordinates. Before calling the tracker, a sweep whose source knows no `world_from_sensor` gets
// the registered one from the options, so a tracker that composes world_from_ground from it sees
// the sensor where the site has it.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "ave/net/tls.h"
#include "ave/v1/ave.pb.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/lidar/lidar_types.h"

namespace ave {

// The next sweep, blocking until it is there; OutOfRange when the source has ended (a file's end),
// any other error is logged and the source asked again after a short pause.
using SweepSource = std::function<absl::StatusOr<lidar::LidarSweep>()>;

struct LidarStreamOptions {
  std::string server = "127.0.0.1:50051";
  std::string sensor_id;  // the LiDAR's registered id
  std::string token;      // sensor bearer token (an issued token must be bound to sensor_id)
  std::string software_version = "ave-agent/0.1";
  net::TlsClientOptions tls;
  std::chrono::milliseconds backoff_initial{200};
  std::chrono::milliseconds backoff_max{2000};
  std::chrono::milliseconds keepalive{1500};  // as AgentOptions::keepalive
  int64_t max_sweeps = 0;  // stop after this many sweeps sent (0 = no limit)
  double duration_s = 0;   // stop after this long (0 = no limit)
  // Sources that are not live (a pcap replay, the simulator) deliver sweeps as fast as asked: send
  // at most this many per second (their spin rate). 0 = as they come.
  double pace_hz = 0;
  // The sensor's clock (ns); default the system clock.
  std::function<int64_t()> clock;
  // Set when the source's LidarSweep::t_ns is not on `clock` (the simulator's scenario time, a pcap
  // file's capture time): each sweep is stamped with clock() when it arrives.
  bool stamp_on_arrival = false;
  // The registered world_from_sensor, given to sweeps whose source knows none.
  std::optional<Rigid3d> world_from_sensor;
  // Foreground points labelled with a streamed track go with each sweep (8 bytes each), at most
  // max_points of them, decimated uniformly over the sweep above that (the server's limit is
  // FrameLimits::max_lidar_points). A 64-beam sensor sees ~6,800 points on 12 people in the
  // courtyard (55 kB a sweep, 550 kB/s at 10 Hz; docs/BENCHMARKS.md): the default keeps ~2,000.
  bool send_points = true;
  uint32_t max_points = 2048;

  std::string Check() const;  // empty when usable, else names the field
};

struct LidarStreamStats {
  int64_t sweeps_read = 0;
  int64_t sweeps_sent = 0;
  int64_t sweeps_acked = 0;
  int64_t sweeps_dropped = 0;  // tracked while the link was down (not sent)
  int64_t tracks_sent = 0;
  int64_t points_sent = 0;
  int64_t points_dropped = 0;  // beyond ±327.67 m, beyond max_points, or of an unconfirmed track
  int64_t tracker_errors = 0;
  int64_t connects = 0;
  int64_t clock_offset_ns = 0;
  std::string last_error;
};

// One sweep and what the tracker made of it as the wire message (sequence and clock offset left
// 0): confirmed tracks in the world frame, and — when send_points — the points whose
// point_track_id names a confirmed track, quantised to int16 cm in the sensor frame with label
// k = index of that track + 1, every stride-th of them when there are more than max_points.
// Pure; `points_dropped` (may be null) counts points left out.
v1::LidarSweepFrame SweepToWire(const lidar::LidarSweep& sweep, const lidar::FootTracks& tracks, bool send_points,
                                uint32_t max_points, int64_t* points_dropped = nullptr);

class LidarStreamer {
 public:
  LidarStreamer(LidarStreamOptions options, SweepSource source, lidar::SweepTracker tracker);

  // Streams until `stop` becomes true, the source ends, max_sweeps or duration_s is reached, or the
  // server refuses this sensor's token for good (Unauthenticated, PermissionDenied: that status).
  // Anything else (not registered yet, disabled, registered as a camera, server away) is retried
  // with backoff, as the camera path does: an administrator may fix the registry.
  absl::Status Run(const std::atomic<bool>& stop);
  LidarStreamStats stats() const;

 private:
  LidarStreamOptions options_;
  SweepSource source_;
  lidar::SweepTracker tracker_;
  mutable std::mutex stats_mu_;
  LidarStreamStats stats_;
};

// The library call the agent's LiDAR mode makes: LidarStreamer(options, source, tracker).Run(stop).
absl::Status StreamLidar(const LidarStreamOptions& options, SweepSource source, lidar::SweepTracker tracker,
                         const std::atomic<bool>& stop, LidarStreamStats* stats = nullptr);

}  // namespace ave
