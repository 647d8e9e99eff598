#pragma once
// Test and benchmark support for the terrain work (issue 4): a built DTM and per-point classes
// scored against a synthetic site's analytic truth. Not linked into ave-model.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "model_store/scene/campus.h"
#include "model_store/terrain/grid.h"

namespace ave::model::testing {

struct TerrainScore {
  double rmse_all_m = 0, rmse_open_m = 0, rmse_under_buildings_m = 0;  // DTM vs site.TerrainHeight
  size_t cells = 0;                                                     // cells scored
  double ground_accuracy = 0;  // fraction of points whose ground / non-ground verdict matches truth
};

// DTM error at every cell centre lying inside the site at least 1 m from its edge (`cloud_origin`:
// the grid's frame; the site's frame is at site.origin), split by whether a building covers the
// cell; ground accuracy compares LAS class 2 in `point_class` with class 2 in `truth_class`.
TerrainScore ScoreTerrain(const HeightGrid& grid, const scene::SyntheticCampus& site, const Eigen::Vector3d& cloud_origin,
                          const std::vector<uint8_t>& point_class, const std::vector<uint8_t>& truth_class);

}  // namespace ave::model::testing
