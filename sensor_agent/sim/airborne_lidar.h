#pragma once
// Simulated airborne LiDAR survey of the campus (MISSION part A input): parallel flight lines
// along the local x axis (east) at `altitude_m` above the origin, a line scanner sweeping across
// track by ±`swath_half_angle_deg`, written as LAS 1.4 point data record format 6.
//
// File layout (docs/SIMULATOR_FORMATS.md): uncompressed LAS 1.4, 375-byte header, no VLRs,
// 30-byte records; coordinates in world (campus.origin + local) with scale 0.001 m and the
// origin rounded to whole metres as offset; classification 2 ground, 6 building, 5 high
// vegetation, 1 other (movers, static objects); building index + 1 in point_source_id
// (0 = not a building; this replaces the usual flight-line id) and the flight line in user_data;
// intensity by material (when named); GPS time = seconds since the survey start. One return per
// pulse (return 1 of 1).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/scene/campus.h"
#include "sensor_agent/sim/effects.h"

namespace ave::sim {

struct AirborneLidarSpec {
  double altitude_m = 400;           // above the campus origin, > 0
  double swath_half_angle_deg = 20;  // in (0, 60)
  double point_spacing_m = 0.5;      // along and across track on flat ground, > 0.05
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// LAS classification codes (ASPRS LAS 1.4 table 17).
inline constexpr uint8_t kLasUnclassified = 1;
inline constexpr uint8_t kLasGround = 2;
inline constexpr uint8_t kLasHighVegetation = 5;
inline constexpr uint8_t kLasBuilding = 6;

// Effects honoured: lidar_range_noise (sigma_m), lidar_missing_returns (probability),
// lidar_intensity_by_material (else constant intensity 25700). Deterministic for a seed. Nothing
// is written when the spec is unusable. Movers are frozen at the start time of each flight line.
absl::Status SimulateAirborneLidar(const scene::SyntheticCampus& campus, const AirborneLidarSpec& spec, const EffectSet& effects,
                                   uint64_t seed, const std::string& las_path);

// A minimal LAS 1.4 / format 6 reader for tests and tools (the full reader belongs to
// model_store). Returns the points in world coordinates.
struct LasPoint6 {
  Eigen::Vector3d p_world;
  uint16_t intensity = 0;
  uint8_t return_number = 0, number_of_returns = 0;
  uint8_t classification = 0;
  double scan_angle_deg = 0;  // stored in 0.006° units; negative = left of the aircraft
  uint8_t user_data = 0;
  uint16_t point_source_id = 0;
  double gps_time = 0;
};
struct LasFile {
  uint8_t version_major = 0, version_minor = 0;
  uint16_t header_size = 0;
  uint32_t offset_to_points = 0;
  uint8_t point_format = 0;
  uint16_t record_length = 0;
  uint64_t point_count = 0;
  std::array<uint64_t, 15> points_by_return{};
  Eigen::Vector3d scale = Eigen::Vector3d::Zero(), offset = Eigen::Vector3d::Zero();
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  std::vector<LasPoint6> points;
};
absl::StatusOr<LasFile> ReadLas6(const std::string& path);

}  // namespace ave::sim
