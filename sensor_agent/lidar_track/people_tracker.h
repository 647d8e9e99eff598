#pragma once
// LiDAR people detection and tracking, online (i4D §3.1 + §3.2; issue 16; docs/LIDAR.md): one
// call per sweep, in order, returning the foot tracks and the person id of every point.
//
//   sweep -> range image -> MoG + dynamic MRF -> 3D point classification      (foreground.h)
//         -> ground lattice, closing, components with area limits, centres     (foot_blobs.h)
//         -> Kalman tracks, optimal assignment, births and deaths              (foot_tracker.h)
//         -> per-point ids by vertical back-projection from the foot blobs
//         -> background learning, frozen under confirmed people (tracker feedback)
//
// The ground is the plane given in the options (e.g. the environment module's RANSAC plane, in
// the sensor frame), else fitted once by RANSAC to the first sweep. Everything runs in the ground
// frame, so a tilted sensor works; `world_from_ground` in the output places it in the site
// (double precision: a sensor 1e6 m from the origin is fine).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar_track/foot_blobs.h"
#include "sensor_agent/lidar_track/foot_tracker.h"
#include "sensor_agent/lidar_track/foreground.h"

namespace ave::lidar_track {

struct LidarPeopleTrackerOptions {
  ForegroundOptions foreground;
  BlobOptions blobs;
  FootTrackerOptions tracker;
  // Ground plane n . p + d = 0 in the sensor frame (n, d); absent: RANSAC on the first sweep.
  std::optional<Eigen::Vector4d> ground_plane_in_sensor;
  double ground_tolerance_m = 0.15;
  double ground_max_tilt_deg = 20;
  // Tracker feedback: the background is not learned under confirmed people (false: plain MoG
  // learning everywhere; a standing person then melts into the background).
  bool freeze_background_under_tracks = true;
  double freeze_radius_m = 0.5;  // around each confirmed track (ground distance)
  // Split blobs that hold two confirmed tracks' predictions (foot_blobs.h).
  bool split_merged_blobs = true;
  std::string Check() const;
};

// CPU seconds of the last sweep per stage (thread time).
struct StageTimes {
  double foreground_s = 0, blobs_s = 0, tracking_s = 0, learn_s = 0;
  double Total() const { return foreground_s + blobs_s + tracking_s + learn_s; }
};

class LidarPeopleTracker {
 public:
  explicit LidarPeopleTracker(LidarPeopleTrackerOptions options = {});

  absl::StatusOr<lidar::FootTracks> Process(const lidar::LidarSweep& sweep);
  // The same chain after the foreground step, with a foreground from elsewhere (per point, 1 =
  // foreground): peers in ave-bench feed the same detector and tracker this way.
  absl::StatusOr<lidar::FootTracks> ProcessWithForeground(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& foreground);

  // The last sweep's per-point foreground (after the 3D step).
  const std::vector<uint8_t>& last_foreground() const { return foreground_; }
  const StageTimes& last_times() const { return times_; }
  const std::optional<GroundFrame>& ground() const { return ground_; }
  const RangeForeground& segmenter() const { return segmenter_; }

 private:
  absl::Status EnsureGround(const lidar::LidarSweep& sweep);
  absl::StatusOr<lidar::FootTracks> Track(const lidar::LidarSweep& sweep);
  std::vector<uint8_t> FrozenPoints(const lidar::LidarSweep& sweep, const lidar::FootTracks& tracks) const;

  LidarPeopleTrackerOptions options_;
  RangeForeground segmenter_;
  FootTracker tracker_;
  std::optional<GroundFrame> ground_;
  std::vector<uint8_t> foreground_;
  StageTimes times_;
};

// An online tracker behind the SweepTracker seam (lidar_types.h); the tracker lives in the closure.
lidar::SweepTracker MakeSweepTracker(LidarPeopleTrackerOptions options = {});


}  // namespace ave::lidar_track
