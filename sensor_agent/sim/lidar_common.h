#pragma once
// Shared by the two simulated LiDARs (internal to ave_sim): the campus as labelled triangles
// behind a BVH, the movers at time t as a second small BVH, deterministic random streams, the
// material reflectivity table and little-endian binary writing.
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/bvh.h"
#include "model_store/geometry/mesh.h"
#include "model_store/scene/campus.h"

#include "absl/status/statusor.h"

namespace ave::sim::internal {

// The whole file as bytes; NotFound naming the path when it cannot be opened.
absl::StatusOr<std::string> ReadWholeFile(const std::string& path);


// SplitMix64 finaliser: decorrelates (seed, stream, index) into an RNG seed.
uint64_t MixSeed(uint64_t seed, uint64_t stream, uint64_t index);

// Triangles with their truth label (sim_camera.h id scheme plus rotating_lidar.h's extra classes)
// and material, behind a BVH.
struct LabelledMesh {
  TriangleMesh mesh;
  MeshBvh bvh;
  std::vector<uint32_t> label;  // per triangle
};

// Terrain facets at 0.5 m stay within ~0.2 mm of the analytic hills: both LiDARs' points lie on
// the surface.
inline constexpr double kLidarTerrainResolution_m = 0.5;

// The static campus (terrain at `terrain_resolution_m`, buildings, vegetation, static objects).
LabelledMesh BuildStaticLidarMesh(const scene::SyntheticCampus& campus, double terrain_resolution_m);
// Movers at t_s as boxes, matching the simulated camera's shapes (a person is a body and a head,
// a car a chassis and a cabin). Only movers whose position is finite are added.
LabelledMesh BuildMoverLidarMesh(const scene::SyntheticCampus& campus, double t_s);

struct LidarHit {
  double distance_m = 0;
  uint32_t label = 0;
  SurfaceMaterial material = SurfaceMaterial::kTerrain;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, facing the ray origin
};

// Nearest hit in the static and the mover meshes (either may be null), in (1e-4, max_distance_m].
std::optional<LidarHit> CastLidarRay(const LabelledMesh* static_mesh, const LabelledMesh* movers, const Eigen::Vector3d& origin,
                                     const Eigen::Vector3d& unit_direction, double max_distance_m);

// Reflectivity (0-255) of a material at normal incidence, used by lidar_intensity_by_material;
// people and cars (label is a mover id) have their own values.
double MaterialReflectivity(SurfaceMaterial material, uint32_t label);

// Little-endian appenders for binary files.
void PutU8(std::string& out, uint8_t v);
void PutU16(std::string& out, uint16_t v);
void PutU32(std::string& out, uint32_t v);
void PutU64(std::string& out, uint64_t v);
void PutI32(std::string& out, int32_t v);
void PutF32(std::string& out, float v);
void PutF64(std::string& out, double v);
uint16_t GetU16(const char* p);
uint32_t GetU32(const char* p);
uint64_t GetU64(const char* p);
float GetF32(const char* p);
double GetF64(const char* p);

// Creates `dir` (and parents); an error names the directory.
std::string MakeDirs(const std::string& dir);

}  // namespace ave::sim::internal
