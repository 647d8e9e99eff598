#pragma once
// Test and benchmark support for the i4D environment (not linked into the model store): rotating
// LiDAR frames of a scenario's first sensor with per-point truth in `classification`, and the
// accuracy of a reconstruction against the site (wall lines, vegetation removal).
#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/environment/environment.h"
#include "model_store/scene/campus.h"

namespace ave::model::testing {

// Truth codes carried in PointCloud::classification (LAS-like).
inline constexpr uint8_t kEnvTruthMover = 0;
inline constexpr uint8_t kEnvTruthObject = 1;
inline constexpr uint8_t kEnvTruthGround = 2;
inline constexpr uint8_t kEnvTruthVegetation = 5;
inline constexpr uint8_t kEnvTruthBuilding = 6;

struct LidarFrames {
  scene::SyntheticCampus site;
  std::vector<PointCloud> frames;  // in the site's local frame, origin = site.origin
  Eigen::Vector3d sensor_m = Eigen::Vector3d::Zero();
};
// `frames` rotations of the scenario's first rotating LiDAR, every `step_s` seconds from t = 0,
// with the scenario's effects.
absl::StatusOr<LidarFrames> SimulateLidarFrames(const std::string& scenario, int frames, double step_s);

struct EnvironmentScore {
  int background_points = 0;
  int vegetation_points = 0, vegetation_removed = 0;   // truth vegetation, and how much was labelled so
  int other_points = 0, other_removed = 0;             // truth non-vegetation labelled vegetation
  int mover_points = 0;                                // movers left in the background
  double vegetation_removal_rate = 0, false_removal_rate = 0;  // over the accumulated background
  // Over everything the sensor saw: vegetation voxels (options.voxel_m) hit in any frame, and the
  // share of them absent from the final model (dropped as non-background or labelled vegetation).
  int vegetation_observed_voxels = 0;
  double overall_vegetation_removal_rate = 0;
  // Fitted plane normal vs the least-squares plane through the background points whose truth is
  // ground (what a perfect ground classifier would fit).
  double ground_angle_deg = 0;
  Eigen::Vector3d reference_ground_normal = Eigen::Vector3d::UnitZ();
  int walls = 0, walls_matched = 0, faces_found = 0;   // detected; within 10 deg and 1 m of a true face; distinct faces
  double position_err_m_mean = 0, position_err_m_max = 0;  // endpoint distance to the true face line
  double angle_err_deg_mean = 0, angle_err_deg_max = 0;
  double top_err_m_mean = 0;                           // wall top vs the true eaves
};
EnvironmentScore ScoreEnvironment(const LidarFrames& truth, const EnvironmentModel& model, double voxel_m = 0.2);

}  // namespace ave::model::testing
