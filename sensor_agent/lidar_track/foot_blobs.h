#pragma once
// Pedestrian detection on the ground (i4D §3.2): the foreground points are projected on a regular
// lattice fitted to the ground plane, closed by morphology, split into connected components, and
// the components whose area lies between a lower and an upper limit become foot candidates at their
// centre. The centre weights each point by its height above the ground: the torso and head (steady,
// densely sampled) pull more than swinging legs and feet, which a rotating LiDAR samples sparsely
// and which the 3D step partly returns to the ground's background.
//
// A blob that holds the predicted positions of two or more confirmed tracks (shoulder-to-shoulder
// walkers merged by the closing) is split between them, each point to its nearest prediction; the
// paper leaves this to sequence-level post-processing, doing it here keeps both identities online.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar_track {

// The trackers' ground frame (lidar_types.h FootTracks): z along the plane's normal, origin under
// the sensor, x along the sensor's x projected on the plane.
struct GroundFrame {
  Rigid3d ground_from_sensor;
  Eigen::Vector3d normal_in_sensor = Eigen::Vector3d::UnitZ();  // unit, towards the sensor side
  double d = 0;                                                  // normal . p + d = 0 in the sensor frame
};
// From a plane n . p + d = 0 in the sensor frame; the normal is turned towards the sensor (d > 0).
// InvalidArgument when n is not finite or zero, or the plane runs through the sensor (|d| < 1 cm).
absl::StatusOr<GroundFrame> GroundFrameFromPlane(const Eigen::Vector3d& normal_in_sensor, double d);

// Ground plane by RANSAC (model_store/environment) over the sweep's usable points below the sensor
// (z_sensor < 0, or all when fewer than 100), excluding points with exclude[i] != 0.
// FailedPrecondition when no plane is found.
absl::StatusOr<GroundFrame> FitGroundFrame(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& exclude,
                                           double tolerance_m = 0.15, double max_tilt_deg = 20);

struct BlobOptions {
  double cell_m = 0.1;            // lattice pitch
  double half_extent_m = 50;      // lattice covers [-e, e]^2 around the sensor's foot
  double min_height_m = 0.25;     // foreground points between these heights above the ground are projected
  double max_height_m = 2.3;      // (tree crowns and roofs above, ground clutter below)
  int closing_radius_cells = 1;   // morphological closing, square (2r+1)^2 structuring element
  double min_area_m2 = 0.015;     // after the closing (a far person seen from one side is a thin arc)
  double max_area_m2 = 2.5;
  double min_top_m = 0.9;         // a blob whose highest point is lower is no person
  int min_points = 6;
  // Back-projection: points up to this height above a blob's cells get its label.
  double label_max_height_m = 2.5;
  double label_min_height_m = 0.03;
  double surface_offset_m = 0.12;     // centre pushed away from the sensor: only the near side is sampled
  double split_hint_radius_m = 0.25;  // a predicted position this close to a blob's cell is inside it
  std::string Check() const;
};

struct FootBlob {
  Eigen::Vector2d xy_m = Eigen::Vector2d::Zero();  // ground frame
  double area_m2 = 0;
  double top_m = 0;     // highest point above the ground
  int points = 0;
  int split_hint = -1;  // index of the prediction it was split for, -1 when not split
};

struct BlobDetection {
  std::vector<FootBlob> blobs;
  std::vector<int32_t> blob_of_point;  // per sweep point: blob index, -1 none (back-projection)
};

// `foreground`: per point, 1 = foreground. `split_hints`: predicted ground positions of confirmed
// tracks. Points must be in the sensor frame of `ground`.
BlobDetection DetectFootBlobs(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& foreground, const GroundFrame& ground,
                              const std::vector<Eigen::Vector2d>& split_hints, const BlobOptions& options);

}  // namespace ave::lidar_track
