#pragma once
// Test and benchmark support for the buildings work (not linked into the model store): a
// simulated airborne survey of a synthetic site read back into a PointCloud, a HeightGrid
// gridded from it with the bare earth taken from the site's analytic terrain (so building tests do
// not depend on the ground filter), and scoring of extracted buildings against the site's truth.
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/buildings/buildings.h"
#include "model_store/scene/campus.h"

namespace ave::model::testing {

struct Survey {
  PointCloud cloud;  // origin = the site's origin; classification and point_source_id as simulated
  HeightGrid grid;   // statistics, cell_class (kGround within 0.5 m of the truth DTM) and truth DTM
};

// Writes the simulated airborne survey of `site` (altitude 400 m, +-20 deg swath) as LAS 1.4.
absl::Status WriteSurveyLas(const scene::SyntheticCampus& site, double spacing_m, uint64_t seed, const std::string& path);

// Simulates the airborne LiDAR over `site` (altitude 400 m, +-20 deg swath, `spacing_m`) into a
// temporary LAS file, reads it back and grids it at `resolution_m`.
absl::StatusOr<Survey> SurveySite(const scene::SyntheticCampus& site, double spacing_m, double resolution_m, uint64_t seed);

// Grids a cloud; dtm from `site.TerrainHeight` (shifted to the cloud's origin).
HeightGrid GridWithTruthGround(const PointCloud& cloud, const scene::SyntheticCampus& site, double resolution_m);

struct BuildingScore {
  int truth = 0, detected = 0;
  int true_positive_detections = 0;  // detections whose main part's centre lies on a true building
  int found = 0;                     // true buildings with at least one detection
  int split = 0;                     // extra detections of an already found building
  int roof_correct = 0;              // found buildings whose main part's roof type matches
  double precision = 0, recall = 0, roof_accuracy = 0;
  // Main-part parameter errors over found buildings (sizes compared sorted; yaw modulo 90 deg
  // for four-fold symmetric parts, 180 deg otherwise; round parts carry no yaw).
  double center_err_m_mean = 0, size_err_m_mean = 0, eave_err_m_mean = 0, roof_height_err_m_mean = 0, yaw_err_deg_mean = 0;
  double center_err_m_max = 0, size_err_m_max = 0, eave_err_m_max = 0, roof_height_err_m_max = 0, yaw_err_deg_max = 0;
  Eigen::Vector2d center_bias_m = Eigen::Vector2d::Zero();  // mean signed centre offset (detected - true)
  std::vector<std::string> mistakes;  // one line per missed building or wrong roof
};
RoofType TruthRoof(scene::PrimitiveKind kind);
BuildingScore ScoreBuildings(const scene::SyntheticCampus& site, const Eigen::Vector3d& cloud_origin,
                             const std::vector<BuildingRecord>& detected);

}  // namespace ave::model::testing
