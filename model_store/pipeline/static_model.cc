#include "model_store/pipeline/static_model.h"

#include <array>
#include <chrono>
#include <cmath>

#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double EmptyFraction(const HeightGrid& grid) {
  size_t empty = 0;
  for (uint32_t c : grid.count) empty += c == 0;
  return grid.count.empty() ? 1.0 : static_cast<double>(empty) / grid.count.size();
}

}  // namespace

std::string StaticModelOptions::Check() const {
  if (!std::isfinite(resolution_m) || resolution_m < 0.05 || resolution_m > 100) return "resolution_m must be in [0.05, 100]";
  if (std::string why = ground.Check(); !why.empty()) return "ground." + why;
  if (std::string why = tessellate.Check(); !why.empty()) return "tessellate." + why;
  return {};
}

absl::StatusOr<StaticModel> BuildStaticModel(const PointCloud& cloud, const StaticModelOptions& options,
                                             const std::function<void(double, const std::string&)>& progress) {
  if (std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("static model: " + why);
  auto report = [&](double f, const std::string& stage) {
    if (progress) progress(f, stage);
  };
  StaticModel model;
  report(0.05, "gridding + ground filter");
  absl::StatusOr<TerrainResult> terrain = BuildTerrain(cloud, options.resolution_m, options.ground);
  if (!terrain.ok()) return terrain.status();
  model.terrain = std::move(*terrain);
  model.grid_seconds = model.terrain.grid_seconds;
  model.filter_seconds = model.terrain.filter_seconds;
  model.point_class = model.terrain.point_class;

  auto t0 = std::chrono::steady_clock::now();
  if (options.extract_buildings) {
    report(0.45, "buildings");
    model.building_grid_m = options.resolution_m;
    const HeightGrid* grid = &model.terrain.grid;
    TerrainResult coarse;
    for (int doubling = 0; options.adapt_building_grid && doubling < 4 && EmptyFraction(*grid) > 0.5; ++doubling) {
      absl::StatusOr<TerrainResult> next = BuildTerrain(cloud, model.building_grid_m * 2, options.ground);
      if (!next.ok()) break;
      coarse = std::move(*next);
      grid = &coarse.grid;
      model.building_grid_m *= 2;
    }
    model.buildings = ExtractBuildings(cloud, *grid, options.buildings, &model.point_class);
  }
  model.buildings_seconds = SecondsSince(t0);

  report(0.75, "tessellation");
  t0 = std::chrono::steady_clock::now();
  model.mesh = TessellateDtm(model.terrain.grid, options.tessellate);
  model.terrain_triangles = model.mesh.TriangleCount();
  for (size_t i = 0; i < model.buildings.size(); ++i) AppendBuildingMesh(model.buildings[i], static_cast<int32_t>(i), model.mesh);
  model.mesh_seconds = SecondsSince(t0);
  report(1.0, "done");
  return model;
}

absl::StatusOr<ClassifiedFile> ClassifyPointCloudFile(const std::string& input, const std::string& out_path,
                                                      const CloudReadOptions& read, const StaticModelOptions& options,
                                                      const std::function<void(double, const std::string&)>& progress) {
  if (std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("bad option: " + why);
  if (LowerExtension(out_path) != "las") {  // before the work, not after
    return absl::InvalidArgumentError(out_path + ": classified points are written as LAS; name the output *.las");
  }
  ClassifiedFile result;
  absl::StatusOr<PointCloud> cloud = ReadPointCloud(input, read);
  if (!cloud.ok()) return cloud.status();
  result.cloud = std::move(*cloud);
  absl::StatusOr<StaticModel> model = BuildStaticModel(result.cloud, options, progress);
  if (!model.ok()) return absl::Status(model.status().code(), input + ": " + std::string(model.status().message()));
  result.model = std::move(*model);
  absl::StatusOr<std::string> written = WriteClassifiedCloud(result.cloud, result.model.point_class, out_path);
  if (!written.ok()) return written.status();
  result.written = std::move(*written);
  return result;
}

std::string ClassCountsJson(const std::vector<uint8_t>& point_class) {
  std::array<uint64_t, 256> counts{};
  for (uint8_t c : point_class) ++counts[c];
  std::string out = "{";
  for (int c = 0; c < 256; ++c) {
    if (!counts[c]) continue;
    if (out.size() > 1) out += ',';
    out += "\"" + std::to_string(c) + "\":" + std::to_string(counts[c]);
  }
  return out + "}";
}

}  // namespace ave::model
