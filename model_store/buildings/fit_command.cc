#include "model_store/buildings/fit_command.h"

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "model_store/common/cli.h"
#include "model_store/lidar/point_cloud_io.h"
#include "model_store/terrain/terrain.h"

namespace ave::model {

absl::StatusOr<std::vector<Eigen::Vector2d>> ParseFootprint(const std::string& text) {
  std::vector<Eigen::Vector2d> out;
  int index = 0;
  for (const absl::string_view vertex : absl::StrSplit(text, ';', absl::SkipWhitespace())) {
    std::stringstream ss{std::string(vertex)};
    double x, y;
    char comma = 0;
    if (!(ss >> x >> comma >> y) || comma != ',' || !(ss >> std::ws).eof() || !std::isfinite(x) || !std::isfinite(y))
      return absl::InvalidArgumentError(absl::StrFormat("vertex %d '%s' is not x,y", index, vertex));
    out.emplace_back(x, y);
    ++index;
  }
  if (out.empty()) return absl::InvalidArgumentError("no vertices");
  return out;
}

absl::StatusOr<PrimitiveType> ParsePrimitiveType(const std::string& name) {
  for (const PrimitiveType t : {PrimitiveType::kBox, PrimitiveType::kWedge, PrimitiveType::kCylinder, PrimitiveType::kSphere,
                                PrimitiveType::kPolyhedron})
    if (name == PrimitiveTypeName(t)) return t;
  return absl::InvalidArgumentError("--type '" + name + "': use box, wedge, cylinder, sphere or polyhedron");
}

absl::StatusOr<RoofType> ParseRoofType(const std::string& name) {
  for (const RoofType t : {RoofType::kFlat, RoofType::kShed, RoofType::kGable, RoofType::kHip, RoofType::kDome, RoofType::kCylinder})
    if (name == RoofTypeName(t)) return t;
  return absl::InvalidArgumentError("--roof '" + name + "': use flat, shed, gable, hip, dome or cylinder");
}

store::StoredBuilding ToStoredBuilding(const BuildingRecord& b) {
  store::StoredBuilding out;
  out.building_id = b.id;
  out.roof = RoofTypeName(b.roof);
  out.footprint_m = b.footprint_m;
  out.area_m2 = b.area_m2;
  out.point_count = b.point_count;
  for (const BuildingPrimitive& p : b.parts)
    out.parts.push_back({PrimitiveTypeName(p.type), RoofTypeName(p.roof), p.center_m, p.size_m, p.yaw_rad, p.base_z_m, p.eave_height_m,
                         p.roof_height_m, p.polygon_m, p.rms_m, p.point_count});
  return out;
}

std::string BuildingJson(const BuildingRecord& record, const Eigen::Vector3d& origin) {
  nlohmann::json parts = nlohmann::json::array();
  for (const BuildingPrimitive& p : record.parts) {
    nlohmann::json j = {{"type", PrimitiveTypeName(p.type)},
                        {"roof", RoofTypeName(p.roof)},
                        {"center_m", {p.center_m.x(), p.center_m.y()}},
                        {"center_world_m", {p.center_m.x() + origin.x(), p.center_m.y() + origin.y()}},
                        {"size_m", {p.size_m.x(), p.size_m.y()}},
                        {"yaw_deg", p.yaw_rad * 180 / M_PI},
                        {"base_z_world_m", p.base_z_m + origin.z()},
                        {"eave_height_m", p.eave_height_m},
                        {"roof_height_m", p.roof_height_m},
                        {"rms_m", p.rms_m},
                        {"points", p.point_count}};
    if (!p.polygon_m.empty()) {
      nlohmann::json poly = nlohmann::json::array();
      for (const auto& v : p.polygon_m) poly.push_back({v.x(), v.y()});
      j["polygon_m"] = poly;
    }
    parts.push_back(j);
  }
  nlohmann::json footprint = nlohmann::json::array();
  for (const auto& v : record.footprint_m) footprint.push_back({v.x(), v.y()});
  const nlohmann::json j = {{"roof", RoofTypeName(record.roof)}, {"area_m2", record.area_m2}, {"points", record.point_count},
                            {"footprint_m", footprint},          {"parts", parts}};
  return j.dump();
}

int RunFit(const FitCommandOptions& o, std::ostream& out, std::ostream& err) {
  auto fail = [&](const std::string& what) {
    err << "ave-model fit: " << what << "\n";
    return 1;
  };
  if (o.footprint.empty() == o.click.empty()) return fail("give exactly one of --footprint and --click");
  const absl::StatusOr<PrimitiveType> type = ParsePrimitiveType(o.type);
  if (!type.ok()) return fail(std::string(type.status().message()));
  RoofType roof = *type == PrimitiveType::kSphere ? RoofType::kDome : RoofType::kFlat;
  if (!o.roof.empty()) {
    const absl::StatusOr<RoofType> r = ParseRoofType(o.roof);
    if (!r.ok()) return fail(std::string(r.status().message()));
    roof = *r;
  } else if (*type == PrimitiveType::kWedge) {
    roof = RoofType::kDome;  // not a wedge roof: FitBuilding then chooses shed or gable
  }
  absl::StatusOr<std::vector<Eigen::Vector2d>> shape = ParseFootprint(o.footprint.empty() ? o.click : o.footprint);
  if (!shape.ok()) return fail((o.footprint.empty() ? "--click: " : "--footprint: ") + std::string(shape.status().message()));
  if (!o.click.empty() && shape->size() != 1) return fail("--click takes one x,y");
  const auto t0 = std::chrono::steady_clock::now();
  CloudReadOptions read;
  read.unit_to_metres = o.units;
  const absl::StatusOr<PointCloud> cloud = ReadPointCloud(o.input, read);
  if (!cloud.ok()) return fail(std::string(cloud.status().message()));
  err << "ave-model fit: " << o.input << ": " << cloud->size() << " points, unit " << cloud->unit_name << "\n";
  const absl::StatusOr<TerrainResult> terrain = BuildTerrain(*cloud, o.resolution_m, GroundFilterOptions{});
  if (!terrain.ok()) return fail(o.input + ": terrain: " + std::string(terrain.status().message()));
  if (!o.local)
    for (auto& v : *shape) v -= cloud->origin.head<2>();
  const absl::StatusOr<BuildingRecord> rec = FitBuilding(*cloud, terrain->grid, *shape, *type, roof);
  if (!rec.ok()) return fail(o.input + ": " + std::string(rec.status().message()));
  out << BuildingJson(*rec, cloud->origin) << "\n";
  if (!o.db.empty()) {
    absl::StatusOr<std::unique_ptr<store::Store>> db = store::Store::Open(o.db);
    if (!db.ok()) return fail("--db " + o.db + ": " + std::string(db.status().message()));
    store::SceneRecord scene;
    scene.name = "fit:" + std::filesystem::path(o.input).stem().string();
    scene.origin = cloud->origin;
    scene.input_path = std::filesystem::absolute(o.input).string();
    scene.parameters_json = nlohmann::json{{"command", "fit"}, {"type", o.type}, {"roof", o.roof}, {"footprint", o.footprint},
                                           {"click", o.click}, {"resolution_m", o.resolution_m}, {"local", o.local}}
                                .dump();
    scene.summary_json = nlohmann::json{{"buildings", 1}, {"rms_m", rec->parts.front().rms_m}}.dump();
    const absl::StatusOr<int64_t> id = (*db)->PutScene(scene, {}, {ToStoredBuilding(*rec)});
    if (!id.ok()) return fail("--db " + o.db + ": " + std::string(id.status().message()));
    err << "ave-model fit: stored as scene " << *id << " in " << o.db << "\n";
  }
  err << absl::StrFormat("ave-model fit: %.2f s\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return 0;
}

void AddFitCommand(CLI::App& app) {
  auto options = std::make_shared<FitCommandOptions>();
  CLI::App* fit = app.add_subcommand("fit", "semi-automatic building fit: one primitive to a footprint or click point");
  fit->add_option("--input", options->input, "point cloud (.las, .ply, .pcd)")->required();
  fit->add_option("--footprint", options->footprint, "footprint polygon x,y;x,y;x,y[;...] (metres)");
  fit->add_option("--click", options->click, "a point x,y on the building's roof (metres)");
  fit->add_option("--type", options->type, "box, wedge, cylinder, sphere or polyhedron")->required();
  fit->add_option("--roof", options->roof, "roof for wedge/polyhedron: flat, shed, gable, hip");
  fit->add_option("--resolution", options->resolution_m, "grid resolution (m)")->check(ave::cli::PositiveNumber());
  fit->add_flag("--local", options->local, "coordinates are relative to the cloud's origin, not world");
  fit->add_option("--units", options->units, "metres per file unit (overrides the file's CRS)")->check(ave::cli::PositiveNumber());
  fit->add_option("--db", options->db, "model store (SQLite) to add the building to");
  // Runs when parsing succeeds; a failure ends the process with its exit code (1), success
  // returns to ave-model's main, which exits 0.
  fit->callback([options] {
    if (const int code = RunFit(*options, std::cout, std::cerr); code != 0) std::exit(code);
  });
}

}  // namespace ave::model
