#pragma once
// The rotating multi-beam LiDAR's vocabulary (i4D §3.1, §3.2; issue 16), shared by the sources
// (`sensor_agent/lidar/`: simulator, Velodyne pcap, live UDP), the people tracker
// (`sensor_agent/lidar_track/`) and the agent's streaming of LiDAR tracks. Eigen only.
//
// Sensor frame: origin at the sensor's optical centre, z along the spin axis (up when mounted
// level), Velodyne's azimuth convention: clockwise from +y seen from above, so a return at range r,
// elevation e, azimuth a is
//   x = r cos(e) sin(a),  y = r cos(e) cos(a),  z = r sin(e)   (plus per-laser offsets, real data).
// `world_from_sensor` places it in the site's local ENU frame (metres, relative to the static
// model's double origin); a sensor may be tilted, so nothing downstream assumes z_sensor = up.
#include <cstdint>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "model_store/geometry/rigid3.h"

namespace ave::lidar {

struct SweepPoint {
  Eigen::Vector3f p_in_sensor = Eigen::Vector3f::Zero();  // metres
  float range_m = 0;       // measured distance; returns at 0 or beyond the sensor's maximum are dropped by sources
  float intensity = 0;     // reflectivity 0-255
  float azimuth_rad = 0;   // [0, 2π), Velodyne convention (see above)
  uint16_t ring = 0;       // row of the range image: 0 = the highest beam, rings-1 = the lowest
  uint8_t return_index = 0;  // 0 = strongest (or the only) return, 1 = the other of a dual-return pair
  uint32_t truth_label = 0;  // simulator only (sim_camera.h id scheme); 0 = unknown
};

// One revolution, cut at the azimuth wrap.
struct LidarSweep {
  int64_t t_ns = 0;  // time of the first firing; sensor clock (scenario time for the simulator)
  int rings = 0;     // range-image rows
  // Elevation of each ring (radians, ring order: descending), so a range image can be laid out
  // without knowing the sensor model.
  std::vector<float> ring_elevation_rad;
  std::vector<SweepPoint> points;
  // Where the sensor stands, when the source knows it (simulator; a registered sensor).
  std::optional<Rigid3d> world_from_sensor;
  // Simulator truth: the ground contact of every person in range, (label, p_in_world).
  std::vector<std::pair<uint32_t, Eigen::Vector3d>> truth_feet_in_world;
};

// One tracked person's foot position on the ground (i4D §3.2): what the LiDAR agent streams.
struct FootTrack {
  uint32_t id = 0;  // stable per sensor session
  Eigen::Vector2d xy_m = Eigen::Vector2d::Zero();        // ground frame (see frame below), metres
  Eigen::Vector2d velocity_mps = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Identity();  // of xy_m
  int age_frames = 0;       // frames since birth
  int missed_frames = 0;    // consecutive frames without a measurement (0 = measured this sweep)
  bool confirmed = false;   // survived the birth test; only confirmed tracks are streamed
};

// The trackers' ground frame: z along the ground plane's normal, origin below the sensor, x/y in
// the plane; `world_from_ground` places it in the site (identity-like when the sensor is level and
// registered at the site origin).
struct FootTracks {
  int64_t t_ns = 0;
  Rigid3d world_from_ground;
  std::vector<FootTrack> tracks;
  // Per point of the sweep these came from (same order): the id of the person it belongs to, 0 for
  // background or unassigned foreground (i4D §3.2, back-projection from the foot blob). Empty when
  // the tracker did not label points.
  std::vector<uint32_t> point_track_id;
};

// What turns sweeps into tracks, online (one call per sweep, in order). The agent's LiDAR mode and
// the streamer take one of these, so they do not depend on the tracker's implementation.
using SweepTracker = std::function<absl::StatusOr<FootTracks>(const LidarSweep&)>;

}  // namespace ave::lidar
