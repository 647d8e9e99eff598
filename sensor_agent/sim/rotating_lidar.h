#pragma once
// Simulated rotating multi-beam LiDAR (i4D §3.1: HDL-64E-like, 64 rings, 10-15 Hz) standing in the
// campus, with per-point truth labels and the true foot points of the people around it.
//
// Sensor frame: origin at `position_m` (campus local frame, metres), axes parallel to the local
// ENU axes (x east, y north, z up). Ring r fires at elevation
//   fov_up_deg - r (fov_up_deg - fov_down_deg) / (rings - 1)   (ring 0 is the top beam),
// azimuth step c at azimuth 2π c / azimuth_steps. Azimuth follows Velodyne's convention, in the
// native frames and in the pcap alike: clockwise from the sensor's +y (north), so
//   x = r cos(elev) sin(az),  y = r cos(elev) cos(az),  z = r sin(elev).
// A frame is a snapshot: every ray of the frame at t_s (movers do not move within a sweep).
//
// Labels use the simulated camera's object-id scheme (sim_camera.h): kGroundId, kBuildingIdBase +
// building index, kMoverIdBase + Mover::id, plus the LiDAR-only classes below.
//
// Effects, each only when named: lidar_range_noise (sigma_m), lidar_ring_pattern (per-ring range
// bias and intensity gain), lidar_missing_returns (dropout probability; grazing returns lost),
// lidar_intensity_by_material (else intensity 100 for every return), waving_vegetation (tree
// points sway with time). Without lidar_missing_returns, every ray that hits within max_range_m
// returns. Files: docs/SIMULATOR_FORMATS.md.
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/scene/campus.h"
#include "sensor_agent/sim/effects.h"

namespace ave::sim {

// Labels of LiDAR points that sim_camera.h's id scheme has no id for (values below
// kBuildingIdBase that the camera scheme does not use).
inline constexpr uint32_t kLidarVegetationId = 2;    // trees, bushes (SurfaceMaterial::kVegetation)
inline constexpr uint32_t kLidarStaticObjectId = 3;  // other static objects (SurfaceMaterial::kObject, no building)

struct RotatingLidarSpec {
  std::string id;
  Eigen::Vector3d position_m = Eigen::Vector3d(0, 0, 2);  // sensor origin, campus local frame
  double rate_hz = 10;         // rotations per second, (0, 50]
  int rings = 64;              // [1, 64] (the pcap packs 32 lasers per block, two block ids)
  double fov_up_deg = 2.0;     // elevation of ring 0
  double fov_down_deg = -24.8; // elevation of the last ring, < fov_up_deg, >= -89
  int azimuth_steps = 1024;    // firings per rotation, [16, 36000]
  double max_range_m = 120;    // (0, 130]: the pcap's 2 mm distance unit tops out at 131 m
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

struct LidarPoint {
  Eigen::Vector3f p_local = Eigen::Vector3f::Zero();  // sensor frame (see above), metres
  float range_m = 0;        // measured distance from the sensor origin
  float intensity = 0;      // reflectivity, 0-255 (the pcap stores it rounded)
  uint16_t ring = 0;
  float azimuth_rad = 0;    // Velodyne convention, [0, 2π)
  uint32_t label = 0;       // object id, see above
};

struct LidarFrame {
  int64_t t_ns = 0;                  // since the scenario start
  std::vector<LidarPoint> points;    // ordered by azimuth step, then ring
  // True ground contact of every person within max_range_m: (kMoverIdBase + Mover::id, local frame).
  std::vector<std::pair<uint32_t, Eigen::Vector3d>> pedestrian_feet;
};

// One rotation at t_s. Deterministic for (campus, spec, effects, seed, t_s). An unusable spec gives
// an empty frame. Builds the static BVH on every call; WriteRotatingLidar builds it once.
LidarFrame SimulateRotatingLidarFrame(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec, const EffectSet& effects,
                                      uint64_t seed, double t_s);

// One sensor's frames on demand, the static BVH built once (for sources that generate sweeps as
// they are asked for). `enu_from_sensor` tilts the sensor (the spec's sensor is level): rays are
// cast along enu_from_sensor * d, points stay in the (tilted) sensor frame; it must be a rotation.
// `campus` must outlive the simulator. Frame() of an unusable spec is empty.
class RotatingLidarSimulator {
 public:
  RotatingLidarSimulator(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec, const EffectSet& effects,
                         uint64_t seed, const Eigen::Matrix3d& enu_from_sensor = Eigen::Matrix3d::Identity());
  ~RotatingLidarSimulator();
  LidarFrame Frame(double t_s) const;
  const RotatingLidarSpec& spec() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// floor(duration_s * rate_hz) frames (at least one) into `out_dir`: frame_NNNNNN.bin (native,
// labelled), frames.csv, pedestrians.csv (truth) and velodyne.pcap (HDL-64E-style packets).
absl::Status WriteRotatingLidar(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec, const EffectSet& effects,
                                uint64_t seed, double duration_s, const std::string& out_dir);

// Reads one native frame file back (the format WriteRotatingLidar writes; pedestrian_feet stay empty).
absl::StatusOr<LidarFrame> ReadRotatingLidarFrame(const std::string& path);

}  // namespace ave::sim
