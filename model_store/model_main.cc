// ave-model: the static scene model from airborne LiDAR (issue 4; MISSION part A, AVE §4-§4.1).
//   ave-model build --input survey.las [--resolution 0.5] [--db ave.db] [--mesh m.gltf] [--exr dtm.exr]
//   ave-model classify --input survey.las --out classified.las   (only the classification changes)
//   ave-model export --db ave.db --out model.glb|model.ply|model.obj|dtm.exr
//   ave-model fit ...   (semi-automatic building fit, from the buildings library when built in)
// Every parameter is in metres: the input's unit comes from its CRS (LAS WKT / GeoTIFF VLR) or
// --units, and the unit used is printed.
#include <openssl/evp.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <optional>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <sstream>

#include "model_store/common/cli.h"
#include "model_store/db/store.h"
#include "model_store/lidar/point_cloud_io.h"
#include "model_store/lidar/read_file.h"
#include "model_store/pipeline/static_model.h"
#include "model_store/buildings/fit_command.h"

namespace {

using ave::model::PointCloud;

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int Fail(const std::string& what) {
  std::cerr << "ave-model: " << what << "\n";
  return 1;
}

// --units: a name or metres per unit.
std::optional<double> ParseUnits(const std::string& text) {
  static const std::map<std::string, double> kNames = {{"m", 1.0},      {"metre", 1.0},      {"meter", 1.0},
                                                       {"ft", 0.3048},  {"foot", 0.3048},    {"feet", 0.3048},
                                                       {"us-ft", 1200.0 / 3937.0}, {"us-survey-foot", 1200.0 / 3937.0}};
  if (auto it = kNames.find(text); it != kNames.end()) return it->second;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end && *end == '\0' && std::isfinite(v) && v > 0) return v;
  return std::nullopt;
}

struct InputFlags {
  std::string input, units;
  double resolution_m = 0.5;
  ave::model::StaticModelOptions options;
  bool quiet = false;

  void Add(CLI::App* sub) {
    sub->add_option("--input", input, "point cloud: .las (1.2-1.4), .ply or .pcd")->required();
    sub->add_option("--resolution", resolution_m, "grid resolution in metres")->check(ave::cli::Range(0.05, 100.0));
    sub->add_option("--units", units, "override the input's linear unit: m, ft, us-ft or metres per unit");
    sub->add_option("--max-window", options.ground.max_window_m, "ground filter: largest opening window (m)");
    sub->add_option("--slope", options.ground.slope, "ground filter: terrain slope allowed (m/m)");
    sub->add_option("--ground-threshold", options.ground.point_threshold_m, "a point this close above the DTM is ground (m)");
    sub->add_option("--flat-tolerance", options.tessellate.flat_tolerance_m, "tessellation: merge blocks flat within this (m)");
    sub->add_flag("--quiet", quiet, "no progress bar");
  }

  absl::StatusOr<PointCloud> Read() const {
    ave::model::CloudReadOptions read;
    if (!units.empty()) {
      read.unit_to_metres = ParseUnits(units);
      if (!read.unit_to_metres) return absl::InvalidArgumentError("--units '" + units + "': use m, ft, us-ft or metres per unit");
    }
    absl::StatusOr<PointCloud> cloud = ave::model::ReadPointCloud(input, read);
    if (cloud.ok()) {
      std::cerr << "ave-model: " << input << ": " << cloud->size() << " points, unit " << cloud->unit_name << " ("
                << cloud->unit_to_metres << " m)";
      if (cloud->rejected_non_finite) std::cerr << ", " << cloud->rejected_non_finite << " rejected (NaN/inf or out of range)";
      std::cerr << "\n";
    }
    return cloud;
  }
};

// A one-line progress bar on stderr.
std::function<void(double, const std::string&)> ProgressBar(bool quiet) {
  if (quiet) return {};
  if (!::isatty(2)) {  // a log file: one line per stage
    return [](double fraction, const std::string& stage) { std::cerr << "ave-model: " << static_cast<int>(fraction * 100) << "% " << stage << "\n"; };
  }
  return [](double fraction, const std::string& stage) {
    const int filled = static_cast<int>(fraction * 30 + 0.5);
    std::cerr << "\r[" << std::string(filled, '#') << std::string(30 - filled, '-') << "] " << static_cast<int>(fraction * 100)
              << "% " << stage << "          " << (fraction >= 1 ? "\n" : "") << std::flush;
  };
}

std::string Sha256Hex(const std::string& bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (EVP_Digest(bytes.data(), bytes.size(), digest, &length, EVP_sha256(), nullptr) != 1) return std::string(64, '0');
  static const char* kHex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < length; ++i) {
    out += kHex[digest[i] >> 4];
    out += kHex[digest[i] & 15];
  }
  return out;
}

// The height grid cut into tiles of at most `tile` cells a side, each an OpenEXR image.
absl::StatusOr<std::vector<ave::store::TerrainTileRecord>> EncodeTiles(const ave::model::HeightGrid& grid, int tile) {
  std::vector<ave::store::TerrainTileRecord> tiles;
  const std::string tmp = (std::filesystem::temp_directory_path() / ("ave-model-tile-" + std::to_string(::getpid()) + ".exr")).string();
  for (int r0 = 0; r0 < grid.rows; r0 += tile) {
    for (int c0 = 0; c0 < grid.cols; c0 += tile) {
      ave::model::HeightGrid part;
      part.origin = grid.origin;
      part.resolution_m = grid.resolution_m;
      part.cols = std::min(tile, grid.cols - c0);
      part.rows = std::min(tile, grid.rows - r0);
      part.min_xy = grid.min_xy + Eigen::Vector2d(c0, r0) * grid.resolution_m;
      for (int r = 0; r < part.rows; ++r) {
        for (int c = 0; c < part.cols; ++c) {
          part.dtm.push_back(grid.dtm[grid.Index(c0 + c, r0 + r)]);
          part.zmax.push_back(grid.zmax[grid.Index(c0 + c, r0 + r)]);
        }
      }
      if (absl::Status s = ave::model::WriteHeightExr(part, tmp); !s.ok()) return s;
      absl::StatusOr<std::string> bytes = ave::model::ReadWholeFile(tmp);
      if (!bytes.ok()) return bytes.status();
      tiles.push_back({c0 / tile, r0 / tile, part.min_xy.x(), part.min_xy.y(), part.resolution_m, part.cols, part.rows, "exr",
                       std::move(*bytes)});
    }
  }
  std::filesystem::remove(tmp);
  return tiles;
}

std::string Fmt(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

// The input read and the pipeline run with the command's options.
struct Built {
  ave::model::StaticModelOptions options;
  PointCloud cloud;
  ave::model::StaticModel model;
};
absl::StatusOr<Built> ReadAndBuild(const InputFlags& in, const std::function<void(double, const std::string&)>& progress) {
  Built built;
  built.options = in.options;
  built.options.resolution_m = in.resolution_m;
  if (std::string why = built.options.Check(); !why.empty()) return absl::InvalidArgumentError("bad option: " + why);
  absl::StatusOr<PointCloud> cloud = in.Read();
  if (!cloud.ok()) return cloud.status();
  built.cloud = std::move(*cloud);
  absl::StatusOr<ave::model::StaticModel> model = ave::model::BuildStaticModel(built.cloud, built.options, progress);
  if (!model.ok()) return absl::Status(model.status().code(), in.input + ": " + std::string(model.status().message()));
  built.model = std::move(*model);
  return built;
}

int RunBuild(const InputFlags& in, const std::string& db_path, const std::string& name_flag, const std::vector<std::string>& meshes,
             const std::string& exr_path, const std::string& classified_path) {
  const auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<Built> built = ReadAndBuild(in, ProgressBar(in.quiet));
  if (!built.ok()) return Fail(std::string(built.status().message()));
  const PointCloud* cloud = &built->cloud;
  const ave::model::StaticModel* model = &built->model;
  const ave::model::StaticModelOptions& options = built->options;
  for (const std::string& path : meshes) {
    if (absl::Status s = ave::model::WriteMesh(model->mesh, path); !s.ok()) return Fail(std::string(s.message()));
  }
  if (!exr_path.empty()) {
    if (absl::Status s = ave::model::WriteHeightExr(model->terrain.grid, exr_path); !s.ok()) return Fail(std::string(s.message()));
  }
  if (!classified_path.empty()) {
    absl::StatusOr<std::string> written = ave::model::WriteClassifiedCloud(*cloud, model->point_class, classified_path);
    if (!written.ok()) return Fail(std::string(written.status().message()));
    std::cerr << "ave-model: " << *written << "\n";
  }
  const std::string parameters = "{\"resolution_m\":" + Fmt(options.resolution_m) + ",\"max_window_m\":" + Fmt(options.ground.max_window_m) +
                                 ",\"slope\":" + Fmt(options.ground.slope) + ",\"ground_threshold_m\":" + Fmt(options.ground.point_threshold_m) +
                                 ",\"flat_tolerance_m\":" + Fmt(options.tessellate.flat_tolerance_m) + ",\"unit_to_metres\":" +
                                 Fmt(cloud->unit_to_metres) + "}";
  std::string summary = "{\"points\":" + std::to_string(cloud->size()) + ",\"rejected\":" + std::to_string(cloud->rejected_non_finite) +
                        ",\"unit\":\"" + cloud->unit_name + "\",\"grid\":[" + std::to_string(model->terrain.grid.cols) + "," +
                        std::to_string(model->terrain.grid.rows) + "],\"ground_cells\":" + std::to_string(model->terrain.ground_cells) +
                        ",\"buildings\":" + std::to_string(model->buildings.size()) + ",\"triangles\":" +
                        std::to_string(model->mesh.TriangleCount()) + ",\"terrain_triangles\":" + std::to_string(model->terrain_triangles) +
                        ",\"classes\":" + ave::model::ClassCountsJson(model->point_class) + ",\"seconds\":{\"grid\":" +
                        Fmt(model->grid_seconds) + ",\"ground\":" + Fmt(model->filter_seconds) + ",\"buildings\":" +
                        Fmt(model->buildings_seconds) + ",\"mesh\":" + Fmt(model->mesh_seconds) + "}";
  if (!db_path.empty()) {
    absl::StatusOr<std::unique_ptr<ave::store::Store>> store = ave::store::Store::Open(db_path);
    if (!store.ok()) return Fail(std::string(store.status().message()));
    const std::string name = name_flag.empty() ? std::filesystem::path(in.input).stem().string() : name_flag;
    absl::StatusOr<int64_t> version = (*store)->PutStaticModel("lidar:" + name, model->mesh);
    if (!version.ok()) return Fail(std::string(version.status().message()));
    absl::StatusOr<std::vector<ave::store::TerrainTileRecord>> tiles = EncodeTiles(model->terrain.grid, 512);
    if (!tiles.ok()) return Fail(std::string(tiles.status().message()));
    std::vector<ave::store::StoredBuilding> buildings;
    for (const auto& b : model->buildings) buildings.push_back(ave::model::ToStoredBuilding(b));
    absl::StatusOr<std::string> bytes = ave::model::ReadWholeFile(in.input);
    if (!bytes.ok()) return Fail(std::string(bytes.status().message()));
    ave::store::SceneRecord scene;
    scene.name = name;
    scene.origin = cloud->origin;
    scene.input_path = std::filesystem::absolute(in.input).string();
    scene.input_sha256 = Sha256Hex(*bytes);
    scene.parameters_json = parameters;
    scene.summary_json = summary + "}";
    scene.static_model_version = *version;
    absl::StatusOr<int64_t> id = (*store)->PutScene(scene, *tiles, buildings);
    if (!id.ok()) return Fail(std::string(id.status().message()));
    summary += ",\"db\":\"" + db_path + "\",\"scene_id\":" + std::to_string(*id) + ",\"static_model_version\":" + std::to_string(*version);
  }
  std::cout << summary << ",\"total_seconds\":" << Fmt(Seconds(t0)) << "}" << std::endl;
  return 0;
}

int RunClassify(const InputFlags& in, const std::string& out) {
  const auto t0 = std::chrono::steady_clock::now();
  ave::model::CloudReadOptions read;
  if (!in.units.empty()) {
    read.unit_to_metres = ParseUnits(in.units);
    if (!read.unit_to_metres) return Fail("--units '" + in.units + "': use m, ft, us-ft or metres per unit");
  }
  ave::model::StaticModelOptions options = in.options;
  options.resolution_m = in.resolution_m;
  absl::StatusOr<ave::model::ClassifiedFile> done = ave::model::ClassifyPointCloudFile(in.input, out, read, options);
  if (!done.ok()) return Fail(std::string(done.status().message()));
  const PointCloud& cloud = done->cloud;
  std::cerr << "ave-model: " << in.input << ": " << cloud.size() << " points, unit " << cloud.unit_name << " (" << cloud.unit_to_metres
            << " m)\nave-model: " << done->written << "\n";
  std::cout << "{\"points\":" << cloud.size() << ",\"rejected\":" << cloud.rejected_non_finite
            << ",\"classes\":" << ave::model::ClassCountsJson(done->model.point_class) << ",\"seconds\":" << Fmt(Seconds(t0)) << "}"
            << std::endl;
  return 0;
}

int RunExport(const std::string& db_path, const std::string& out) {
  // Opening creates a missing store: a mistyped --db would leave an empty file behind.
  if (!std::filesystem::is_regular_file(db_path)) return Fail(db_path + ": no such model store (--db)");
  absl::StatusOr<std::unique_ptr<ave::store::Store>> store = ave::store::Store::Open(db_path);
  if (!store.ok()) return Fail(std::string(store.status().message()));
  if (out.size() > 4 && out.substr(out.size() - 4) == ".exr") {
    absl::StatusOr<std::vector<ave::store::SceneRecord>> scenes = (*store)->ListScenes();
    if (!scenes.ok()) return Fail(std::string(scenes.status().message()));
    if (scenes->empty()) return Fail(db_path + ": no LiDAR scene stored (run ave-model build --db first)");
    absl::StatusOr<std::vector<ave::store::TerrainTileRecord>> tiles = (*store)->GetTerrainTiles(scenes->back().id);
    if (!tiles.ok()) return Fail(std::string(tiles.status().message()));
    if (tiles->size() != 1) return Fail(db_path + ": scene " + std::to_string(scenes->back().id) + " has " + std::to_string(tiles->size()) + " terrain tiles; writing the first");
    if (absl::Status s = ave::model::WriteWholeFile(out, tiles->front().data); !s.ok()) return Fail(std::string(s.message()));
    return 0;
  }
  absl::StatusOr<std::optional<ave::store::StaticModelRecord>> latest = (*store)->LatestStaticModel();
  if (!latest.ok()) return Fail(std::string(latest.status().message()));
  if (!*latest) return Fail(db_path + ": no static model stored");
  if (absl::Status s = ave::model::WriteMesh((*latest)->mesh, out); !s.ok()) return Fail(std::string(s.message()));
  std::cout << "{\"version\":" << (*latest)->version << ",\"name\":\"" << (*latest)->name << "\",\"triangles\":" << (*latest)->mesh.TriangleCount()
            << ",\"out\":\"" << out << "\"}" << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ave-model: the static scene model from airborne LiDAR (terrain, buildings, store)"};
  app.require_subcommand(1);

  InputFlags build_in, classify_in;
  std::string db, name, exr, classified, classify_out, export_db, export_out;
  std::vector<std::string> meshes;
  CLI::App* build = app.add_subcommand("build", "grid, classify, fill, tessellate, fit buildings; store and export");
  build_in.Add(build);
  build->add_option("--db", db, "model store (SQLite) to put the mesh, terrain tiles, buildings and provenance in");
  build->add_option("--name", name, "scene name (default: the input's file stem)");
  build->add_option("--mesh", meshes, "write the assembled mesh (.ply, .obj, .gltf, .glb); repeatable")->check(ave::cli::WritableFile());
  build->add_option("--exr", exr, "write the height grid (DTM + DSM) as OpenEXR")->check(ave::cli::WritableFile());
  build->add_option("--classified", classified, "also write the classified points (.las: a LAS input keeps every byte but the classes)")->check(ave::cli::WritableFile());

  CLI::App* classify = app.add_subcommand("classify", "write the points with computed LAS classes and print a JSON summary");
  classify_in.Add(classify);
  classify->add_option("--out", classify_out,
                       "output .las: a LAS input is given back with only its classification changed (version, format, scale, "
                       "offset, unit, VLRs and every other byte kept); PLY/PCD become LAS 1.4 format 6 in metres")
      ->required()
      ->check(ave::cli::WritableFile());

  CLI::App* exp = app.add_subcommand("export", "write the store's newest static model (mesh) or terrain (EXR)");
  exp->add_option("--db", export_db, "model store")->required();
  exp->add_option("--out", export_out, ".ply, .obj, .gltf, .glb (mesh) or .exr (terrain)")->required()->check(ave::cli::WritableFile());

  // The buildings library adds `fit` (semi-automatic primitive fit); its callback runs during
  // parsing and exits non-zero itself on failure.
  ave::model::AddFitCommand(app);

  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-model")) return *exit_code;
  if (build->parsed()) return RunBuild(build_in, db, name, meshes, exr, classified);
  if (classify->parsed()) return RunClassify(classify_in, classify_out);
  if (exp->parsed()) return RunExport(export_db, export_out);
  if (app.got_subcommand("fit")) return 0;
  return 2;
}
