#pragma once
// Per-laser calibration of Velodyne rotating multi-beam sensors (HDL-64E S2/S3, HDL-32E, VLP-16),
// from the two formats in the field or the built-in defaults of each model (issue 16).
//
// Geometry (HDL-64E S3 manual, appendix; the ROS velodyne driver does the same, in its own axes):
// with a = azimuth − rot_correction, e = vert_correction, d = raw·distance_resolution + dist_correction,
//   xy = d cos(e) − vert_offset sin(e)
//   x  = xy sin(a) − horiz_offset cos(a),   y = xy cos(a) + horiz_offset sin(a),
//   z  = d sin(e) + vert_offset cos(e)
// in the sensor frame of lidar_types.h (Velodyne's own: azimuth clockwise from +y).
// Not applied: the HDL-64E two-point near-range correction (dist_correction_x/_y, focal
// distance/slope); the files' values for them are ignored.
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace ave::lidar {

enum class VelodyneModel { kUnknown, kHdl64e, kHdl32e, kVlp16 };

const char* VelodyneModelName(VelodyneModel model);
int VelodyneLaserCount(VelodyneModel model);

struct LaserCalibration {
  double vert_correction_rad = 0;    // elevation of the beam
  double rot_correction_rad = 0;     // subtracted from the block azimuth
  double dist_correction_m = 0;      // added to the measured distance
  double vert_offset_m = 0;          // beam origin above/below the optical centre
  double horiz_offset_m = 0;         // beam origin sideways
};

struct VelodyneCalibration {
  VelodyneModel model = VelodyneModel::kUnknown;  // kUnknown: a file that does not say (any model with as many lasers)
  std::vector<LaserCalibration> lasers;           // indexed by laser id
  double distance_resolution_m = 0.002;
  std::string source;  // "built-in VLP-16", the file path, ...
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Published vertical angles for VLP-16 and HDL-32E; for HDL-64E (whose angles differ per unit and
// come with its db.xml) the layout the simulator writes (sensor_agent/sim/rotating_lidar.cc:
// 64 lasers, laser id = ring, elevation 2.0° − id·26.8°/63, no offsets).
VelodyneCalibration DefaultVelodyneCalibration(VelodyneModel model);

// The simulator's HDL-64E-style layout for any ring count and field of view (its pcap carries
// lasers 0..rings-1, id = ring, linearly spaced elevations).
VelodyneCalibration SimulatorVelodyneCalibration(int rings, double fov_up_deg, double fov_down_deg);

// Velodyne's db.xml (boost serialization; points_/item/px with id_, rotCorrection_ and
// vertCorrection_ in degrees, distCorrection_, vertOffsetCorrection_, horizOffsetCorrection_ and
// distLSB_ in centimetres). Errors name the file, the item and the field.
absl::StatusOr<VelodyneCalibration> ReadVelodyneDbXml(const std::string& path);
absl::StatusOr<VelodyneCalibration> ParseVelodyneDbXml(const std::string& text, const std::string& name);

// The ROS velodyne_pointcloud YAML (lasers: [{laser_id, vert_correction, rot_correction,
// dist_correction, vert_offset_correction, horiz_offset_correction}], num_lasers,
// distance_resolution; radians and metres).
absl::StatusOr<VelodyneCalibration> ReadVelodyneYaml(const std::string& path);
absl::StatusOr<VelodyneCalibration> ParseVelodyneYaml(const std::string& text, const std::string& name);

// By extension: .xml -> db.xml, .yaml/.yml -> YAML.
absl::StatusOr<VelodyneCalibration> ReadVelodyneCalibration(const std::string& path);

}  // namespace ave::lidar
