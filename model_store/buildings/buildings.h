#pragma once
// Buildings from airborne LiDAR (MISSION part A, AVE §4.1): footprints segmented from non-ground
// cells high above the bare earth, roof type classified, primitives fitted by least squares and
// assembled into multi-primitive buildings; plus the semi-automatic fit of one primitive to a
// user-given footprint or click point.
//
// Owned by the buildings work (issue 4); the terrain pipeline (ave-model build) calls
// ExtractBuildings after gridding and ground classification. Extend, but keep these signatures.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include "absl/status/statusor.h"

#include "model_store/geometry/mesh.h"
#include "model_store/lidar/point_cloud.h"
#include "model_store/terrain/grid.h"

namespace ave::model {

enum class RoofType : uint8_t { kFlat = 0, kShed = 1, kGable = 2, kHip = 3, kDome = 4, kCylinder = 5 };
enum class PrimitiveType : uint8_t { kBox = 0, kWedge = 1, kCylinder = 2, kSphere = 3, kPolyhedron = 4 };
const char* RoofTypeName(RoofType type);
const char* PrimitiveTypeName(PrimitiveType type);

// One fitted primitive, in the cloud's local frame.
struct BuildingPrimitive {
  PrimitiveType type = PrimitiveType::kBox;
  RoofType roof = RoofType::kFlat;
  Eigen::Vector2d center_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d size_m = Eigen::Vector2d::Ones();  // along the primitive's own x, y (diameters when round)
  double yaw_rad = 0;            // primitive x axis from east, counter-clockwise
  double base_z_m = 0;           // local height of the ground under it
  double eave_height_m = 0;      // walls' top above base_z_m
  double roof_height_m = 0;      // roof rise above the eaves
  std::vector<Eigen::Vector2d> polygon_m;  // kPolyhedron: footprint polygon (counter-clockwise)
  double rms_m = 0;              // least-squares residual of the roof points
  uint32_t point_count = 0;
};

struct BuildingRecord {
  uint32_t id = 0;
  std::vector<Eigen::Vector2d> footprint_m;  // outline polygon, counter-clockwise, local
  RoofType roof = RoofType::kFlat;           // of the main (largest) primitive
  std::vector<BuildingPrimitive> parts;      // main part first
  uint32_t point_count = 0;
  double area_m2 = 0;
};

struct BuildingOptions {
  double min_height_m = 2.5;   // above the DTM for a cell to count as a building candidate
  double min_area_m2 = 12;     // smaller blobs are dropped (kiosks, cars)
  // Vegetation: the median over a blob's interior of the rms residual of a plane through each 3x3
  // block of highest points, blocks of ~0.5 m (scaled to 0.5 m for coarser grids). Roofs are planes
  // or gentle curves (campus: <= 0.04); tree crowns are lumpy or, small as they are, strongly
  // curved (simulated smooth crowns: >= 0.045). A small blob with no interior block is vegetation.
  double max_roughness_m = 0.06;             // any blob above this is vegetation
  double small_blob_area_m2 = 80;            // blobs smaller than this ...
  double small_blob_max_roughness_m = 0.03;  // ... are vegetation above this
  double max_multi_return_fraction = 0.3;  // blobs with more multi-return pulses are vegetation
  // Multi-primitive assembly: roof regions split at height steps above part_step_m; regions
  // smaller than min_part_area_m2, or that one primitive fits with a neighbour to within
  // part_merge_rms_m, are merged.
  double part_step_m = 1.0;
  double min_part_area_m2 = 8;
  double part_merge_rms_m = 0.3;
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Segments, classifies and fits every building. Needs the grid's statistics and its DTM
// (candidates are cells whose highest point stands min_height_m above it; cell_class is not used,
// see buildings.cc); an empty result without them. `point_class_out`, when non-null, holds LAS
// codes per point as the terrain filter computed them (2 ground, 1 unclassified; reset to 1 when
// its size differs from the cloud's): points of buildings above half min_height_m are set to 6,
// of vegetation blobs to 5.
std::vector<BuildingRecord> ExtractBuildings(const PointCloud& cloud, const HeightGrid& grid,
                                             const BuildingOptions& options,
                                             std::vector<uint8_t>* point_class_out);

// Semi-automatic mode: fit one primitive of the given type to the points inside `footprint_m`
// (local polygon; with a DTM only the cells standing min_height_m above it count, so the polygon
// may be rough), or, for one point (a click), to the blob of such cells grown from its cell.
// `roof` picks the roof of a wedge (shed / gable; otherwise the better fit) or polyhedron (flat:
// the polygon extruded; else on its rectangle); box, cylinder and sphere ignore it. Errors name
// the cause: too few points, collinear or coincident points or vertices, a click off any building.
absl::StatusOr<BuildingRecord> FitBuilding(const PointCloud& cloud, const HeightGrid& grid,
                                           const std::vector<Eigen::Vector2d>& footprint_m, PrimitiveType type,
                                           RoofType roof);

// Closed triangle mesh of a building (walls kWall, roofs and bottom kRoof; triangle_object =
// `object`), appended in the cloud's local frame: the mesh's origin should be the cloud's origin.
void AppendBuildingMesh(const BuildingRecord& building, int32_t object, TriangleMesh& mesh);

}  // namespace ave::model
