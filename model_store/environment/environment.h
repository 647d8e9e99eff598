#pragma once
// i4D static environment from a ground rotating LiDAR (MISSION part A, i4D §3.3): accumulate the
// background points of many frames, fit the ground plane by RANSAC, remove vegetation (irregular
// neighbourhoods that also reflect weakly), find wall lines by a Hough transform of the remaining
// points projected on the ground, and mesh each wall.
//
// Wall meshes: each merged Hough segment is refitted by least squares to its points and extruded
// from the ground plane to the measured wall top (the 98th percentile of its points' heights).
// The paper applies Ball-Pivoting to the points of each line instead; we do not, because a
// rotating LiDAR samples a wall in rings that are tens of centimetres to metres apart at 10-30 m,
// so a pivoting ball small enough to keep corners either leaves the wall full of holes or, when
// large, bridges across doorways and trees; a wall is a plane by construction of the Hough step,
// so the extruded quad is watertight, exact to the fitted line, and costs nothing
// (docs/ARCHITECTURE.md, model_store/environment).
//
// Everything is in one local frame (x east, y north, z up, metres) under a double origin.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include "absl/status/statusor.h"

#include "model_store/geometry/mesh.h"
#include "model_store/lidar/point_cloud.h"

namespace ave::model {

struct EnvironmentOptions {
  // Background accumulation: a voxel is background when points fall in it in at least
  // `background_fraction` of the frames (people passing occupy a voxel for a few frames only).
  double voxel_m = 0.2;
  double background_fraction = 0.5;
  // RANSAC ground plane: inlier distance, iterations, and the largest tilt a ground may have.
  double ground_tolerance_m = 0.2;
  int ransac_iterations = 300;
  double max_ground_tilt_deg = 15;
  uint64_t seed = 1;
  // Vegetation (i4D: "distance and irregularity of its neighbours" plus low intensity): a point
  // that reflects weakly (intensity below `vegetation_intensity`) and whose neighbourhood within
  // `vegetation_radius_m` is irregular (surface variation above `vegetation_irregularity`) or
  // sparse (fewer than `min_neighbours` neighbours: leaves) or a thin upright line (trunks), or any point three times
  // as irregular whatever its intensity. Weak returns alone are not enough: walls seen at grazing
  // incidence reflect weakly too, but they are dense and planar.
  double vegetation_radius_m = 0.5;
  double vegetation_irregularity = 0.04;
  double vegetation_intensity = 60;
  int min_neighbours = 10;
  // Walls: points at least `wall_min_height_m` above the ground, rasterised at `hough_cell_m`;
  // Hough segments shorter than `min_wall_length_m` are dropped; collinear pieces merged.
  double wall_min_height_m = 1.5;
  double hough_cell_m = 0.1;
  int hough_votes = 30;
  double min_wall_length_m = 2.0;
  double max_wall_gap_m = 1.0;
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// n . p + d = 0 with n unit and pointing up.
struct GroundPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0;
  int inliers = 0;
  double rms_m = 0;
  double HeightAbove(const Eigen::Vector3d& p) const { return normal.dot(p) + d; }
};

// The least-squares plane through all points (smallest principal axis, normal turned up; rms_m
// is the rms distance to it): no outlier rejection (the RANSAC stage's peer in ave-bench).
GroundPlane FitPlaneLeastSquares(const std::vector<Eigen::Vector3f>& points);

// RANSAC over `points` (3-point samples; collinear or coincident samples are skipped), then a
// least-squares refit to the inliers. FailedPrecondition, with the reason, when every sample is
// degenerate (all points collinear or coincident) or no plane within the tilt limit has 3 inliers.
absl::StatusOr<GroundPlane> FitGroundPlaneRansac(const std::vector<Eigen::Vector3f>& points, const EnvironmentOptions& options);

// One point per background voxel (mean position, mean intensity, and the most frequent
// classification when the frames carry one). Frames must share the cloud origin of the first.
PointCloud AccumulateBackground(const std::vector<PointCloud>& frames, const EnvironmentOptions& options);

// Each point's neighbourhood within vegetation_radius_m: how many other points, and the surface
// variation lambda_min / (lambda_0 + lambda_1 + lambda_2) of their covariance (0 on a plane, 1/3
// for isotropic scatter; 0 with fewer than 3 neighbours).
struct NeighbourStats {
  float irregularity = 0;
  int neighbours = 0;
  bool upright_linear = false;  // the neighbourhood is a thin vertical line (trunk, pole)
};
std::vector<NeighbourStats> PointNeighbourhoods(const PointCloud& cloud, const EnvironmentOptions& options);

enum class EnvClass : uint8_t { kOther = 0, kGround = 1, kVegetation = 2 };
std::vector<EnvClass> ClassifyEnvironment(const PointCloud& background, const GroundPlane& ground, const EnvironmentOptions& options);

struct WallSegment {
  Eigen::Vector2d a_m = Eigen::Vector2d::Zero(), b_m = Eigen::Vector2d::Zero();  // on the ground projection
  double bottom_z_m = 0, top_z_m = 0;  // ground under the segment's middle; measured top
  int support = 0;                    // points within the wall's band
  double rms_m = 0;                   // of those points about the fitted line
};
// The Hough transform's input: points of class kOther at least wall_min_height_m above the
// ground, projected on it and rasterised at hough_cell_m (255 where two or more points stack,
// dilated by a pixel). Pixel (col, row) covers min_xy + (col - 1, row - 1) * cell_m.
struct OccupancyImage {
  int width = 0, height = 0;
  double cell_m = 0.1;
  Eigen::Vector2d min_xy = Eigen::Vector2d::Zero();
  std::vector<uint8_t> pixels;        // row-major, 0 or 255; empty when too few points
  std::vector<Eigen::Vector3d> points;  // the wall candidates: x, y, height above ground
  size_t PixelIndex(const Eigen::Vector2d& xy) const {
    return static_cast<size_t>((xy.y() - min_xy.y()) / cell_m + 1) * width + static_cast<size_t>((xy.x() - min_xy.x()) / cell_m + 1);
  }
};
OccupancyImage RasteriseWallPoints(const PointCloud& background, const std::vector<EnvClass>& classes, const GroundPlane& ground,
                                   const EnvironmentOptions& options);

std::vector<WallSegment> DetectWalls(const PointCloud& background, const std::vector<EnvClass>& classes, const GroundPlane& ground,
                                     const EnvironmentOptions& options);

// Two-sided quads (kWall) per wall, in the cloud's local frame; object = -1.
void AppendWallMeshes(const std::vector<WallSegment>& walls, TriangleMesh& mesh);

struct EnvironmentModel {
  PointCloud background;
  GroundPlane ground;
  std::vector<EnvClass> classes;
  std::vector<WallSegment> walls;
  TriangleMesh mesh;  // walls
  // Seconds per stage.
  double accumulate_s = 0, ransac_s = 0, vegetation_s = 0, hough_s = 0, mesh_s = 0;
};
absl::StatusOr<EnvironmentModel> ReconstructEnvironment(const std::vector<PointCloud>& frames, const EnvironmentOptions& options);

}  // namespace ave::model
