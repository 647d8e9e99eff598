#pragma once
// The built-in synthetic campus: analytic sloped terrain with roads, box buildings, three fixed
// cameras and a few people and cars on closed paths. It is the bundled demo site and the ground
// truth every test measures against; the scenario-file simulator (issue 3) grows out of it.
//
// Everything here is in the campus's local frame (east, north, up; metres) whose zero lies at
// `origin` in world (UTM-like) coordinates.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"

namespace ave::scene {

struct BoxBuilding {
  std::string id;
  Eigen::Vector2d center_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d size_m = Eigen::Vector2d::Ones();  // extent along the building's own x, y
  double yaw_rad = 0;                                // building x axis from east, counter-clockwise
  double height_m = 10;                              // roof above the highest ground at the footprint
};

// A camera carried along a path (e.g. a backpack camera): it walks the polyline at constant speed
// at `height_m` above the terrain, looking ahead along the path and `pitch_deg` below horizontal.
struct CameraPath {
  std::vector<Eigen::Vector2d> waypoints_m;  // open polyline, walked back and forth (ping-pong)
  double speed_mps = 1.4;
  double height_m = 1.7;
  double pitch_deg = 10;
};

struct CameraSpec {
  std::string id;
  std::string name;
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;  // local frame; the pose at t = 0 for a moving camera
  std::optional<CameraPath> path;  // set: a moving camera
};

enum class MoverKind : uint8_t { kPerson = 0, kCar = 1 };

struct Mover {
  uint32_t id = 0;
  MoverKind kind = MoverKind::kPerson;
  std::vector<Eigen::Vector2d> loop_m;  // closed polyline, walked at constant speed
  double speed_mps = 1.4;
  double start_offset_m = 0;                            // arc length at t = 0
  Eigen::Vector3d size_m = Eigen::Vector3d(0.6, 0.4, 1.8);  // width, length, height
  Eigen::Vector3f color = Eigen::Vector3f(0.8f, 0.2f, 0.2f);
};

struct MoverState {
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  // ground contact (bottom centre)
  double heading_rad = 0;                                // direction of travel from east, CCW
};

struct SyntheticCampus {
  std::string name = "campus";
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates of the local zero
  double half_extent_m = 120;                        // terrain covers [-e, e] x [-e, e]
  double road_half_width_m = 4;
  std::vector<BoxBuilding> buildings;
  std::vector<CameraSpec> cameras;
  std::vector<Mover> movers;

  // Analytic terrain (gentle hills plus a tilt), metres above the origin.
  double TerrainHeight(double x_m, double y_m) const;
  Eigen::Vector3d TerrainNormal(double x_m, double y_m) const;
  // Roads: the two axes of the local frame.
  bool IsRoad(double x_m, double y_m) const;
  // Footprint test: index of the building covering (x, y), or -1.
  int BuildingAt(double x_m, double y_m) const;
  // Bottom and top of a building's box (the bottom sits below the lowest ground of its footprint).
  double BuildingBase(const BoxBuilding& b) const;
  double BuildingTop(const BoxBuilding& b) const;

  const CameraSpec* FindCamera(const std::string& id) const;
};

// The bundled demo campus (deterministic).
SyntheticCampus BuiltinCampus();

// Static model: terrain grid at `grid_resolution_m` plus every building box, coloured with the
// model's own neutral colours, material and building index per triangle.
TriangleMesh BuildStaticMesh(const SyntheticCampus& campus, double grid_resolution_m = 2.0);

// Where a mover is at time t (seconds since the scenario start); t may be negative.
MoverState MoverAt(const SyntheticCampus& campus, const Mover& mover, double t_s);

// A camera's true pose at time t: its mounting pose, or its place on its path.
Rigid3d CameraPoseAt(const SyntheticCampus& campus, const CameraSpec& camera, double t_s);

// Corners of a box footprint (counter-clockwise), local frame.
std::vector<Eigen::Vector2d> FootprintCorners(const BoxBuilding& b);

// Appends an oriented box to a mesh: bottom centre at `base`, box x axis at `yaw_rad` from east,
// `extent` = (size along box x, size along box y, height),
// with flat per-face normals.
void AppendBox(TriangleMesh& mesh, const Eigen::Vector3d& base, double yaw_rad, const Eigen::Vector3d& extent,
               const Eigen::Vector3f& wall_color, const Eigen::Vector3f& roof_color, int32_t object,
               SurfaceMaterial wall_material, SurfaceMaterial roof_material);

}  // namespace ave::scene
