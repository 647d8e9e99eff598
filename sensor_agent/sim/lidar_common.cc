#include "sensor_agent/sim/lidar_common.h"

#include <fstream>
#include <sstream>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::sim::internal {

absl::StatusOr<std::string> ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError("cannot open " + path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}


uint64_t MixSeed(uint64_t seed, uint64_t stream, uint64_t index) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1) + 0xBF58476D1CE4E5B9ull * (index + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

namespace {

uint32_t StaticLabel(SurfaceMaterial material, int32_t object) {
  switch (material) {
    case SurfaceMaterial::kTerrain:
    case SurfaceMaterial::kRoad:
      return kGroundId;
    case SurfaceMaterial::kVegetation:
      return kLidarVegetationId;
    case SurfaceMaterial::kWall:
    case SurfaceMaterial::kRoof:
      return object >= 0 ? kBuildingIdBase + static_cast<uint32_t>(object) : kLidarStaticObjectId;
    case SurfaceMaterial::kObject:
      return kLidarStaticObjectId;
  }
  return kLidarStaticObjectId;
}

}  // namespace

LabelledMesh BuildStaticLidarMesh(const scene::SyntheticCampus& campus, double terrain_resolution_m) {
  LabelledMesh out;
  out.mesh = scene::BuildStaticMesh(campus, terrain_resolution_m);
  const size_t n = out.mesh.TriangleCount();
  out.label.resize(n);
  for (size_t t = 0; t < n; ++t) {
    const SurfaceMaterial m = t < out.mesh.triangle_material.size() ? out.mesh.triangle_material[t] : SurfaceMaterial::kObject;
    const int32_t object = t < out.mesh.triangle_object.size() ? out.mesh.triangle_object[t] : -1;
    out.label[t] = StaticLabel(m, object);
  }
  out.bvh = MeshBvh(out.mesh);
  return out;
}

LabelledMesh BuildMoverLidarMesh(const scene::SyntheticCampus& campus, double t_s) {
  LabelledMesh out;
  out.mesh.origin = campus.origin;
  const Eigen::Vector3f none(0.5f, 0.5f, 0.5f);
  for (const scene::Mover& mover : campus.movers) {
    const scene::MoverState state = scene::MoverAt(campus, mover, t_s);
    if (!state.position_m.allFinite() || !std::isfinite(state.heading_rad)) continue;
    const size_t first = out.mesh.TriangleCount();
    const double width = mover.size_m.x(), length = mover.size_m.y(), height = mover.size_m.z();
    const Eigen::Vector3d forward(std::cos(state.heading_rad), std::sin(state.heading_rad), 0);
    auto box = [&](const Eigen::Vector3d& base, const Eigen::Vector3d& extent) {
      scene::AppendBox(out.mesh, base, state.heading_rad, extent, none, none, -1, SurfaceMaterial::kObject, SurfaceMaterial::kObject);
    };
    // Same shapes as sim_camera.cc's AppendMover.
    if (mover.kind == scene::MoverKind::kPerson) {
      const double body = 0.86 * height;
      box(state.position_m, Eigen::Vector3d(length, width, body));
      box(state.position_m + Eigen::Vector3d(0, 0, body), Eigen::Vector3d(0.22, 0.20, height - body));
    } else {
      const double chassis = 0.55 * height;
      box(state.position_m, Eigen::Vector3d(length, width, chassis));
      box(state.position_m + Eigen::Vector3d(0, 0, chassis) - 0.05 * length * forward,
          Eigen::Vector3d(0.55 * length, 0.9 * width, height - chassis));
    }
    out.label.resize(out.mesh.TriangleCount(), kMoverIdBase + mover.id);
    (void)first;
  }
  out.bvh = MeshBvh(out.mesh);
  return out;
}

std::optional<LidarHit> CastLidarRay(const LabelledMesh* static_mesh, const LabelledMesh* movers, const Eigen::Vector3d& origin,
                                     const Eigen::Vector3d& d, double max_distance_m) {
  std::optional<RayHit> best;
  const LabelledMesh* owner = nullptr;
  for (const LabelledMesh* m : {static_mesh, movers}) {
    if (m == nullptr || m->bvh.TriangleCount() == 0) continue;
    const double limit = best ? best->distance_m : max_distance_m;
    if (auto hit = m->bvh.Raycast(origin, d, 1e-4, limit); hit && (!best || hit->distance_m < best->distance_m)) {
      best = hit;
      owner = m;
    }
  }
  if (!best) return std::nullopt;
  const TriangleMesh& mesh = owner->mesh;
  const size_t t = best->triangle;
  const Eigen::Vector3d p0 = mesh.positions[mesh.indices[3 * t]].cast<double>();
  const Eigen::Vector3d p1 = mesh.positions[mesh.indices[3 * t + 1]].cast<double>();
  const Eigen::Vector3d p2 = mesh.positions[mesh.indices[3 * t + 2]].cast<double>();
  Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
  n = n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d(-d);
  if (n.dot(d) > 0) n = -n;
  LidarHit hit;
  hit.distance_m = best->distance_m;
  hit.label = owner->label[t];
  hit.material = t < mesh.triangle_material.size() ? mesh.triangle_material[t] : SurfaceMaterial::kObject;
  hit.normal = n;
  return hit;
}

double MaterialReflectivity(SurfaceMaterial material, uint32_t label) {
  if (label >= kMoverIdBase) return 70;  // clothing, car paint: mid reflectivity
  switch (material) {
    case SurfaceMaterial::kTerrain:
      return 55;  // grass
    case SurfaceMaterial::kRoad:
      return 18;  // asphalt
    case SurfaceMaterial::kWall:
      return 140;  // concrete, render
    case SurfaceMaterial::kRoof:
      return 95;
    case SurfaceMaterial::kObject:
      return 110;
    case SurfaceMaterial::kVegetation:
      return 35;  // leaves are dark at 905 nm's competitors; low as the i4D vegetation filter expects
  }
  return 60;
}

void PutU8(std::string& out, uint8_t v) { out.push_back(static_cast<char>(v)); }
void PutU16(std::string& out, uint16_t v) {
  for (int i = 0; i < 2; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void PutU32(std::string& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void PutU64(std::string& out, uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void PutI32(std::string& out, int32_t v) { PutU32(out, static_cast<uint32_t>(v)); }
void PutF32(std::string& out, float v) {
  uint32_t u;
  std::memcpy(&u, &v, 4);
  PutU32(out, u);
}
void PutF64(std::string& out, double v) {
  uint64_t u;
  std::memcpy(&u, &v, 8);
  PutU64(out, u);
}
uint16_t GetU16(const char* p) {
  return static_cast<uint16_t>(static_cast<uint8_t>(p[0]) | (static_cast<uint8_t>(p[1]) << 8));
}
uint32_t GetU32(const char* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}
uint64_t GetU64(const char* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}
float GetF32(const char* p) {
  const uint32_t u = GetU32(p);
  float v;
  std::memcpy(&v, &u, 4);
  return v;
}
double GetF64(const char* p) {
  const uint64_t u = GetU64(p);
  double v;
  std::memcpy(&v, &u, 8);
  return v;
}

std::string MakeDirs(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return "cannot create directory " + dir + ": " + ec.message();
  return {};
}

}  // namespace ave::sim::internal
