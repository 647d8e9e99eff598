#pragma once
// The whole static-model pipeline of `ave-model build` (MISSION part A, AVE §4-§4.1), shared by the
// command line and `ave-bench model`: point cloud -> height grid -> ground filter + DTM ->
// buildings (when this build has the buildings library) -> one assembled mesh (terrain + buildings)
// under the cloud's double origin, plus the per-point LAS classes.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/buildings/buildings.h"
#include "model_store/geometry/mesh.h"
#include "model_store/lidar/point_cloud.h"
#include "model_store/lidar/point_cloud_io.h"
#include "model_store/terrain/mesh_export.h"
#include "model_store/terrain/terrain.h"

namespace ave::model {

struct StaticModelOptions {
  double resolution_m = 0.5;
  GroundFilterOptions ground;
  BuildingOptions buildings;
  TessellateOptions tessellate;
  bool extract_buildings = true;  // ignored (no buildings) when the library is not built in
  // Buildings are segmented on a grid at least this coarse: the terrain resolution doubled until
  // at most half of the cells are empty (cells finer than the point spacing leave roofs full of
  // holes); 0 = always the terrain grid.
  bool adapt_building_grid = true;
  std::string Check() const;      // empty when usable, else the first bad field
};

struct StaticModel {
  TerrainResult terrain;                  // grid, DTM, per-point ground classes
  std::vector<uint8_t> point_class;       // final LAS codes: 2 ground, 6 building, 5 vegetation, 1 other
  std::vector<BuildingRecord> buildings;  // empty without the buildings library
  TriangleMesh mesh;                      // terrain, then every building (triangle_object = index)
  size_t terrain_triangles = 0;
  double building_grid_m = 0;             // resolution the buildings were segmented at
  double grid_seconds = 0, filter_seconds = 0, buildings_seconds = 0, mesh_seconds = 0;
};

// `progress(fraction, stage)` is called between stages when set.
absl::StatusOr<StaticModel> BuildStaticModel(const PointCloud& cloud, const StaticModelOptions& options,
                                             const std::function<void(double, const std::string&)>& progress = {});

// `ave-model classify` (issue 14): reads `input` (.las, .ply, .pcd), builds the static model and
// writes its per-point classes to `out_path` with WriteClassifiedCloud, so a LAS input comes back
// with only its classification changed. Errors name the input or the output.
struct ClassifiedFile {
  PointCloud cloud;
  StaticModel model;
  std::string written;  // one line: how the output was written
};
absl::StatusOr<ClassifiedFile> ClassifyPointCloudFile(const std::string& input, const std::string& out_path,
                                                      const CloudReadOptions& read, const StaticModelOptions& options,
                                                      const std::function<void(double, const std::string&)>& progress = {});

// Counts per LAS class as one JSON object, e.g. {"1":10,"2":900,"6":90}.
std::string ClassCountsJson(const std::vector<uint8_t>& point_class);

}  // namespace ave::model
