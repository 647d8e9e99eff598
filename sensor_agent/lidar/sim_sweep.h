#pragma once
// The simulator's rotating-LiDAR frame as a LidarSweep (issue 16): ring = range-image row,
// elevations from the spec, per-point truth labels, the truth feet in the world (the scenario's
// local frame). One conversion for the `sim:` source, the tracker's benchmark and the tests.
#include <optional>
#include <vector>

#include "model_store/geometry/rigid3.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/sim/rotating_lidar.h"

namespace ave::lidar {

// Elevation of each ring, radians, ring 0 (the top beam) first, as the simulator fires them.
std::vector<float> RingElevationsRad(const sim::RotatingLidarSpec& spec);

// `world_from_sensor` absent: the spec's position with the sensor's axes parallel to the site's
// ENU axes (the simulator's sensor frame). t_ns is the frame's scenario time.
LidarSweep SweepFromSimFrame(const sim::LidarFrame& frame, const sim::RotatingLidarSpec& spec,
                             const std::optional<Rigid3d>& world_from_sensor = std::nullopt);

}  // namespace ave::lidar
