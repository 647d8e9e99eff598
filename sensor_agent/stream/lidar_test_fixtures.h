#pragma once
// Test-only fixtures for the LiDAR streaming path (issue 16): the simulator's rotating-LiDAR frames
// as LidarSweep, and a "tracker" that reads the simulator's truth feet. The truth tracker is a
// test fixture standing in for sensor_agent/lidar_track/'s LidarPeopleTracker so that the wire,
// the server's fusion and the viewers can be tested before it exists; it must never be used by a
// product program (it needs the simulator's truth, which real sensors do not have).
#include <cstdint>
#include <map>
#include <memory>
#include <utility>

#include <Eigen/Core>

#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar/sim_sweep.h"
#include "sensor_agent/sim/rotating_lidar.h"

namespace ave::fixtures {

// One simulated frame as a sweep: points in the sensor frame with their truth labels, the ring
// elevations, world_from_sensor (the simulator's sensor axes are the site's ENU axes), truth feet.
// t_ns is the frame's scenario time; callers that stream it restamp it on their clock.
inline lidar::LidarSweep SweepFromSim(const sim::LidarFrame& frame, const sim::RotatingLidarSpec& spec) {
  return lidar::SweepFromSimFrame(frame, spec);
}

// Tracks straight from the simulator's truth (TEST FIXTURE, see above): one confirmed track per
// person in range, id = the person's truth label, position = the true foot point (world frame:
// world_from_ground is the identity), velocity from the previous sweep, covariance sigma_m^2 I;
// every point whose truth label is a tracked person is labelled with that person's id.
inline lidar::SweepTracker TruthFootTracker(double sigma_m = 0.05) {
  auto previous = std::make_shared<std::map<uint32_t, std::pair<int64_t, Eigen::Vector2d>>>();
  return [previous, sigma_m](const lidar::LidarSweep& sweep) -> absl::StatusOr<lidar::FootTracks> {
    lidar::FootTracks out;
    out.t_ns = sweep.t_ns;
    std::map<uint32_t, std::pair<int64_t, Eigen::Vector2d>> now;
    for (const auto& [label, foot] : sweep.truth_feet_in_world) {
      lidar::FootTrack t;
      t.id = label;
      t.xy_m = foot.head<2>();
      t.covariance_m2 = Eigen::Matrix2d::Identity() * sigma_m * sigma_m;
      t.confirmed = true;
      if (auto it = previous->find(label); it != previous->end() && sweep.t_ns > it->second.first) {
        t.velocity_mps = (t.xy_m - it->second.second) / ((sweep.t_ns - it->second.first) * 1e-9);
      }
      now[label] = {sweep.t_ns, t.xy_m};
      out.tracks.push_back(t);
    }
    *previous = std::move(now);
    out.point_track_id.reserve(sweep.points.size());
    for (const lidar::SweepPoint& p : sweep.points) out.point_track_id.push_back(previous->count(p.truth_label) ? p.truth_label : 0);
    return out;
  };
}

}  // namespace ave::fixtures
