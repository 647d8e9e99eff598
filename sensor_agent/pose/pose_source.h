#pragma once
// The agent's --pose-mode (issue 5): wraps a simulated frame source so that each frame carries the
// fused pose (GPS + inertial, optionally + vision) and its 6x6 covariance instead of the
// simulator's true pose. The camera's GPS and inertial streams come from a recorded log (world
// coordinates, docs/POSE.md) or are simulated with the scenario's effects.
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "sensor_agent/pose/pose_inputs.h"
#include "sensor_agent/pose/vision.h"
#include "sensor_agent/source/frame_source.h"

namespace ave::pose {

struct PoseSourceOptions {
  PoseMode mode = PoseMode::kTruth;
  std::string log_dir;      // DIR with gps.csv and imu.csv; empty: simulate the camera's streams
  double simulate_s = 900;  // seconds of GPS / inertial data simulated when there is no log
  // The carried camera's height above the ground (VisionOptions::carrier_height_m); < 0: the sim
  // camera's own when it walks a path (the backpack's 1.7 m), else none.
  double carrier_height_m = -1;
  PoseFilterOptions filter;
  VisionOptions vision;
};

// `sim_spec` is the spec `inner` was opened from ("sim:SCENARIO#CAMERA"): the scenario gives the
// site origin, the static model (vision) and the GPS / inertial carrier. Mode truth returns
// `inner` unchanged. Errors name the spec or the log file.
absl::StatusOr<std::unique_ptr<FrameSource>> WithFusedPose(std::unique_ptr<FrameSource> inner, const std::string& sim_spec,
                                                           const PoseSourceOptions& options);

}  // namespace ave::pose
