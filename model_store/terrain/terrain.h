#pragma once
// Bare-earth terrain from an airborne point cloud (MISSION part A, AVE §4.1: "resample to a
// regular grid ... classify ground ... fill holes"): gridding with per-cell statistics, a
// progressive morphological ground filter (Zhang et al., IEEE TGRS 41(4), 2003) whose height
// threshold grows with the window times the terrain slope, per-point ground labels, and a DTM whose
// holes are filled from ground cells only, so buildings never leak into the terrain.
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/lidar/point_cloud.h"
#include "model_store/terrain/grid.h"

namespace ave::model {

// Grids `cloud` at `resolution_m` (> 0): zmin, zmax, zmean, znearest (the point closest to the
// cell centre in xy) and count per cell; cell_class and dtm are left empty. InvalidArgument for a
// bad resolution, an empty cloud or a grid above `max_cells`.
absl::StatusOr<HeightGrid> BuildHeightGrid(const PointCloud& cloud, double resolution_m, size_t max_cells = 400'000'000);

struct GroundFilterOptions {
  double max_window_m = 40;        // largest opening window: wider than the widest building
  double slope = 0.3;              // terrain slope the threshold allows (m per m)
  double initial_threshold_m = 0.3;  // height threshold for the first (3-cell) window
  double max_threshold_m = 3.0;    // threshold cap (steep terrain vs. low buildings)
  double point_threshold_m = 0.25;  // a point within this of the DTM is ground
  int fill_iterations = 60;        // Gauss-Seidel relaxation steps after the push-pull hole fill
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Fills grid.cell_class (kEmpty / kGround / kObject) and grid.dtm from the grid's zmin surface:
// the progressive morphological filter, then hole filling from ground cells. Returns the number of
// ground cells; InvalidArgument when options are bad; FailedPrecondition when no cell is ground
// (a cloud with no ground at all) — the grid then has cell_class set and dtm all NaN.
absl::StatusOr<size_t> ClassifyGroundCells(HeightGrid& grid, const GroundFilterOptions& options);

// Per-point LAS class from the DTM: 2 (ground) within point_threshold_m above or any depth below
// the bilinear DTM, else 1 (unclassified). Then refines grid.dtm to the mean height of each cell's
// ground points (zmin is biased low on slopes and by noise) and re-fills the holes.
std::vector<uint8_t> ClassifyGroundPoints(const PointCloud& cloud, HeightGrid& grid, const GroundFilterOptions& options);

// Bilinear DTM height at local (x, y) through cell centres, clamped at the border; NaN outside.
float DtmAt(const HeightGrid& grid, double x, double y);

// Grey-scale opening (erosion then dilation) with a (2 * half_window + 1)^2 square window, in
// place; +inf marks empty cells, which never pull the erosion and stay +inf where no data lies
// within the window. Van Herk / Gil-Werman: cost independent of the window size.
void MorphologicalOpening(std::vector<float>& values, int cols, int rows, int half_window);

// Fills the NaN cells of `values` (cols x rows) from the finite ones: push-pull pyramid, then
// `iterations` Gauss-Seidel steps of the Laplace equation on the filled cells only.
void FillHoles(std::vector<float>& values, int cols, int rows, int iterations);

// Everything above in one call, as `ave-model build` and `classify` use it.
struct TerrainResult {
  HeightGrid grid;
  std::vector<uint8_t> point_class;  // LAS codes: 2 ground, 1 unclassified
  size_t ground_cells = 0;
  double grid_seconds = 0, filter_seconds = 0;
};
absl::StatusOr<TerrainResult> BuildTerrain(const PointCloud& cloud, double resolution_m, const GroundFilterOptions& options);

}  // namespace ave::model
