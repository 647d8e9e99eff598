#include "model_store/scene/campus.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ave::scene {
namespace {

const Eigen::Vector3f kTerrainColor(0.56f, 0.60f, 0.50f);
const Eigen::Vector3f kRoadColor(0.47f, 0.47f, 0.46f);
const Eigen::Vector3f kWallColor(0.78f, 0.76f, 0.72f);
const Eigen::Vector3f kRoofColor(0.62f, 0.58f, 0.55f);

Eigen::Vector2d ToBuildingFrame(const BoxBuilding& b, double x, double y) {
  const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
  const double dx = x - b.center_m.x(), dy = y - b.center_m.y();
  return {c * dx + s * dy, -s * dx + c * dy};
}

CameraSpec MakeCamera(const SyntheticCampus& campus, std::string id, std::string name, Eigen::Vector2d eye_xy,
                      double mast_m, Eigen::Vector2d target_xy) {
  CameraSpec cam;
  cam.id = std::move(id);
  cam.name = std::move(name);
  cam.intrinsics = PinholeIntrinsics::FromFov(640, 480, 70);
  const Eigen::Vector3d eye(eye_xy.x(), eye_xy.y(), campus.TerrainHeight(eye_xy.x(), eye_xy.y()) + mast_m);
  const Eigen::Vector3d target(target_xy.x(), target_xy.y(), campus.TerrainHeight(target_xy.x(), target_xy.y()));
  cam.world_from_camera = LookAt(eye, target);
  return cam;
}

}  // namespace

double SyntheticCampus::TerrainHeight(double x, double y) const {
  return 1.2 * std::sin(x / 35.0) * std::cos(y / 50.0) + 0.015 * x + 0.01 * y;
}

Eigen::Vector3d SyntheticCampus::TerrainNormal(double x, double y) const {
  const double dhdx = 1.2 / 35.0 * std::cos(x / 35.0) * std::cos(y / 50.0) + 0.015;
  const double dhdy = -1.2 / 50.0 * std::sin(x / 35.0) * std::sin(y / 50.0) + 0.01;
  return Eigen::Vector3d(-dhdx, -dhdy, 1.0).normalized();
}

bool SyntheticCampus::IsRoad(double x, double y) const {
  return std::abs(x) <= road_half_width_m || std::abs(y) <= road_half_width_m;
}

int SyntheticCampus::BuildingAt(double x, double y) const {
  for (size_t i = 0; i < buildings.size(); ++i) {
    const Eigen::Vector2d p = ToBuildingFrame(buildings[i], x, y);
    if (std::abs(p.x()) <= 0.5 * buildings[i].size_m.x() && std::abs(p.y()) <= 0.5 * buildings[i].size_m.y()) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

std::vector<Eigen::Vector2d> FootprintCorners(const BoxBuilding& b) {
  const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
  const Eigen::Vector2d ax(c, s), ay(-s, c);
  const double hx = 0.5 * b.size_m.x(), hy = 0.5 * b.size_m.y();
  return {b.center_m - hx * ax - hy * ay, b.center_m + hx * ax - hy * ay, b.center_m + hx * ax + hy * ay,
          b.center_m - hx * ax + hy * ay};
}

double SyntheticCampus::BuildingBase(const BoxBuilding& b) const {
  double lowest = TerrainHeight(b.center_m.x(), b.center_m.y());
  for (const auto& c : FootprintCorners(b)) lowest = std::min(lowest, TerrainHeight(c.x(), c.y()));
  return lowest - 0.5;  // sunk in so no gap shows on slopes
}

double SyntheticCampus::BuildingTop(const BoxBuilding& b) const {
  double highest = TerrainHeight(b.center_m.x(), b.center_m.y());
  for (const auto& c : FootprintCorners(b)) highest = std::max(highest, TerrainHeight(c.x(), c.y()));
  return highest + b.height_m;
}

const CameraSpec* SyntheticCampus::FindCamera(const std::string& id) const {
  for (const auto& c : cameras)
    if (c.id == id) return &c;
  return nullptr;
}

SyntheticCampus BuiltinCampus() {
  SyntheticCampus campus;
  campus.name = "campus";
  campus.origin = Eigen::Vector3d(384500.0, 3768200.0, 85.0);  // UTM zone 11N-like magnitudes
  campus.half_extent_m = 120;

  // Twelve buildings in the four quadrants between the roads (id, centre, size, yaw, height).
  campus.buildings = {
      {"hall-a", {-30, -28}, {22, 14}, 0.0, 12},   {"hall-b", {-62, -30}, {16, 26}, 0.0, 18},
      {"library", {28, -30}, {26, 18}, 0.15, 15},  {"lab", {62, -40}, {14, 14}, 0.0, 24},
      {"gym", {30, 30}, {30, 20}, 0.0, 9},         {"tower", {70, 35}, {10, 10}, 0.3, 36},
      {"dorm-1", {-28, 32}, {12, 30}, 0.0, 14},    {"dorm-2", {-55, 35}, {12, 30}, 0.0, 14},
      {"cafe", {-28, 70}, {16, 10}, 0.0, 6},       {"annex", {30, 75}, {20, 12}, -0.2, 10},
      {"depot", {-80, -75}, {24, 16}, 0.0, 8},     {"admin", {75, -80}, {18, 18}, 0.4, 20},
  };

  campus.cameras = {
      MakeCamera(campus, "cam1", "Plaza south-west", {-12, -62}, 16, {4, -12}),
      MakeCamera(campus, "cam2", "Gym east", {62, 8}, 18, {20, 4}),
      MakeCamera(campus, "cam3", "Dorms north", {-10, 58}, 17, {-12, 12}),
  };

  // People walk along the roads' edges; cars drive on them. Loops are closed polylines.
  auto person = [](uint32_t id, std::vector<Eigen::Vector2d> loop, double offset, Eigen::Vector3f color) {
    Mover m;
    m.id = id;
    m.kind = MoverKind::kPerson;
    m.loop_m = std::move(loop);
    m.speed_mps = 1.4;
    m.start_offset_m = offset;
    m.size_m = {0.6, 0.4, 1.8};
    m.color = color;
    return m;
  };
  auto car = [](uint32_t id, std::vector<Eigen::Vector2d> loop, double offset, Eigen::Vector3f color) {
    Mover m;
    m.id = id;
    m.kind = MoverKind::kCar;
    m.loop_m = std::move(loop);
    m.speed_mps = 6.0;
    m.start_offset_m = offset;
    m.size_m = {1.8, 4.5, 1.5};
    m.color = color;
    return m;
  };
  campus.movers = {
      person(1, {{-6, -60}, {-6, 50}}, 10, {0.85f, 0.15f, 0.15f}),
      person(2, {{6, -55}, {6, 40}}, 40, {0.15f, 0.25f, 0.85f}),
      person(3, {{-50, -6}, {50, -6}}, 5, {0.95f, 0.75f, 0.10f}),
      person(4, {{-45, 6}, {55, 6}}, 60, {0.60f, 0.15f, 0.70f}),
      person(5, {{-20, -10}, {-8, -20}, {-20, -45}, {-40, -15}}, 0, {0.10f, 0.70f, 0.65f}),
      car(101, {{-2, -100}, {-2, 100}}, 30, {0.90f, 0.90f, 0.95f}),
      car(102, {{-100, 2}, {100, 2}}, 120, {0.20f, 0.20f, 0.22f}),
  };
  return campus;
}

void AppendBox(TriangleMesh& mesh, const Eigen::Vector3d& base, double yaw_rad, const Eigen::Vector3d& extent,
               const Eigen::Vector3f& wall_color, const Eigen::Vector3f& roof_color, int32_t object,
               SurfaceMaterial wall_material, SurfaceMaterial roof_material) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Eigen::Vector3d ax(c, s, 0), ay(-s, c, 0), az(0, 0, 1);
  const double hx = 0.5 * extent.x(), hy = 0.5 * extent.y(), h = extent.z();
  auto corner = [&](double sx, double sy, double sz) -> Eigen::Vector3f {
    return (base + sx * hx * ax + sy * hy * ay + sz * h * az).cast<float>();
  };
  auto quad = [&](Eigen::Vector3f a, Eigen::Vector3f b, Eigen::Vector3f cc, Eigen::Vector3f d, const Eigen::Vector3f& color,
                  SurfaceMaterial material) {
    const Eigen::Vector3f n = (b - a).cross(cc - a).normalized();
    const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
    for (const auto& p : {a, b, cc, d}) {
      mesh.positions.push_back(p);
      mesh.normals.push_back(n);
      mesh.colors.push_back(color);
    }
    mesh.indices.insert(mesh.indices.end(), {first, first + 1, first + 2, first, first + 2, first + 3});
    for (int i = 0; i < 2; ++i) {
      mesh.triangle_material.push_back(material);
      mesh.triangle_object.push_back(object);
    }
  };
  // Walls (outward, counter-clockwise seen from outside), then the roof.
  quad(corner(-1, -1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(-1, -1, 1), wall_color, wall_material);
  quad(corner(1, -1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, -1, 1), wall_color, wall_material);
  quad(corner(1, 1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(1, 1, 1), wall_color, wall_material);
  quad(corner(-1, 1, 0), corner(-1, -1, 0), corner(-1, -1, 1), corner(-1, 1, 1), wall_color, wall_material);
  quad(corner(-1, -1, 1), corner(1, -1, 1), corner(1, 1, 1), corner(-1, 1, 1), roof_color, roof_material);
}

TriangleMesh BuildStaticMesh(const SyntheticCampus& campus, double grid_resolution_m) {
  TriangleMesh mesh;
  mesh.origin = campus.origin;
  const double e = campus.half_extent_m;
  const int n = std::max(2, static_cast<int>(std::ceil(2 * e / grid_resolution_m)) + 1);
  const double step = 2 * e / (n - 1);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double x = -e + i * step, y = -e + j * step;
      mesh.positions.emplace_back(x, y, campus.TerrainHeight(x, y));
      mesh.normals.push_back(campus.TerrainNormal(x, y).cast<float>());
      mesh.colors.push_back(campus.IsRoad(x, y) ? kRoadColor : kTerrainColor);
    }
  }
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      mesh.indices.insert(mesh.indices.end(), {a, b, c, a, c, d});
      const double cx = -e + (i + 0.5) * step, cy = -e + (j + 0.5) * step;
      const SurfaceMaterial m = campus.IsRoad(cx, cy) ? SurfaceMaterial::kRoad : SurfaceMaterial::kTerrain;
      for (int k = 0; k < 2; ++k) {
        mesh.triangle_material.push_back(m);
        mesh.triangle_object.push_back(-1);
      }
    }
  }
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    const BoxBuilding& b = campus.buildings[i];
    const double base = campus.BuildingBase(b);
    AppendBox(mesh, Eigen::Vector3d(b.center_m.x(), b.center_m.y(), base), b.yaw_rad,
              Eigen::Vector3d(b.size_m.x(), b.size_m.y(), campus.BuildingTop(b) - base), kWallColor, kRoofColor,
              static_cast<int32_t>(i), SurfaceMaterial::kWall, SurfaceMaterial::kRoof);
  }
  return mesh;
}

MoverState MoverAt(const SyntheticCampus& campus, const Mover& mover, double t_s) {
  MoverState state;
  const size_t n = mover.loop_m.size();
  if (n == 0) return state;
  if (n == 1) {
    state.position_m = {mover.loop_m[0].x(), mover.loop_m[0].y(), campus.TerrainHeight(mover.loop_m[0].x(), mover.loop_m[0].y())};
    return state;
  }
  double perimeter = 0;
  for (size_t i = 0; i < n; ++i) perimeter += (mover.loop_m[(i + 1) % n] - mover.loop_m[i]).norm();
  if (!(perimeter > 0)) return state;
  double s = std::fmod(mover.start_offset_m + mover.speed_mps * t_s, perimeter);
  if (s < 0) s += perimeter;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d a = mover.loop_m[i], b = mover.loop_m[(i + 1) % n];
    const double len = (b - a).norm();
    if (s <= len || i + 1 == n) {
      const Eigen::Vector2d dir = len > 0 ? Eigen::Vector2d((b - a) / len) : Eigen::Vector2d::UnitX();
      const Eigen::Vector2d p = a + std::min(s, len) * dir;
      state.position_m = {p.x(), p.y(), campus.TerrainHeight(p.x(), p.y())};
      state.heading_rad = std::atan2(dir.y(), dir.x());
      return state;
    }
    s -= len;
  }
  return state;
}

Rigid3d CameraPoseAt(const SyntheticCampus& campus, const CameraSpec& camera, double t_s) {
  if (!camera.path || camera.path->waypoints_m.size() < 2) return camera.world_from_camera;
  const CameraPath& path = *camera.path;
  double length = 0;
  for (size_t i = 0; i + 1 < path.waypoints_m.size(); ++i) length += (path.waypoints_m[i + 1] - path.waypoints_m[i]).norm();
  if (!(length > 0)) return camera.world_from_camera;
  // Ping-pong along the polyline: s in [0, 2 length) folds back onto [0, length].
  double s = std::fmod(path.speed_mps * t_s, 2 * length);
  if (s < 0) s += 2 * length;
  const bool returning = s > length;
  if (returning) s = 2 * length - s;
  Eigen::Vector2d p = path.waypoints_m.back(), dir = Eigen::Vector2d::UnitX();
  for (size_t i = 0; i + 1 < path.waypoints_m.size(); ++i) {
    const Eigen::Vector2d a = path.waypoints_m[i], b = path.waypoints_m[i + 1];
    const double len = (b - a).norm();
    if (s <= len || i + 2 == path.waypoints_m.size()) {
      dir = len > 0 ? Eigen::Vector2d((b - a) / len) : Eigen::Vector2d::UnitX();
      p = a + std::min(s, len) * dir;
      break;
    }
    s -= len;
  }
  if (returning) dir = -dir;
  const Eigen::Vector3d eye(p.x(), p.y(), campus.TerrainHeight(p.x(), p.y()) + path.height_m);
  const double pitch = path.pitch_deg * M_PI / 180;
  const Eigen::Vector3d forward(std::cos(pitch) * dir.x(), std::cos(pitch) * dir.y(), -std::sin(pitch));
  return LookAt(eye, eye + forward);
}

}  // namespace ave::scene
