#pragma once
// The synthetic site every simulator and test measures against: terrain (analytic hills or a
// gridded height field), roads, buildings made of primitives (box, gable, shed, hip, cylinder,
// dome; one or several parts), trees, static objects, fixed and moving cameras, and people and
// cars on closed paths. Scenario files (scene_file.h, docs/SCENARIOS.md) describe one; the bundled
// demo campus is the `campus` scenario (BuiltinCampus).
//
// Everything here is in the site's local frame (east, north, up; metres) whose zero lies at
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

// The primitive shapes buildings are made of (MISSION part A: the roof types the model store
// classifies). Walls rise to the eaves; the roof adds `roof_height_m` above them.
enum class PrimitiveKind : uint8_t {
  kBox = 0,       // flat roof at the eaves
  kGable = 1,     // a wedge: ridge along the part's x axis, triangular gable ends (walls)
  kShed = 2,      // mono-pitch: eaves on the -y side, high edge on the +y side
  kHip = 3,       // ridge along the longer axis, all four sides slope (a pyramid when square)
  kCylinder = 4,  // elliptic footprint (size_m = diameters), flat round roof
  kDome = 5,      // cylinder walls under a half-spheroid of rise roof_height_m
};
const char* PrimitiveName(PrimitiveKind kind);

// One primitive of a building.
struct BuildingPart {
  PrimitiveKind kind = PrimitiveKind::kBox;
  Eigen::Vector2d center_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d size_m = Eigen::Vector2d::Ones();  // extent along the part's own x, y
  double yaw_rad = 0;                                // part x axis from east, counter-clockwise
  double height_m = 10;       // eaves above the highest ground under the whole building
  double roof_height_m = 0;   // roof rise above the eaves (0 for box and cylinder)
};

// A building: its main part (the fields inherited from BuildingPart, kept under their old names
// so `b.center_m`, `b.height_m` read as before) plus any further parts of a multi-primitive
// building. All parts share one base and one ground reference and one building index.
struct BoxBuilding : BuildingPart {
  std::string id;
  std::vector<BuildingPart> extra_parts;

  // Main part first, then the extra parts.
  std::vector<BuildingPart> Parts() const;
};
using Building = BoxBuilding;

// A tree: a trunk (cylinder) under a crown (sphere), both SurfaceMaterial::kVegetation.
struct Tree {
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();
  double trunk_height_m = 3;    // ground to the crown's bottom
  double trunk_radius_m = 0.2;
  double crown_radius_m = 2.5;  // the crown's centre is trunk_height_m + crown_radius_m above ground
};

// A static object (bench, kiosk, bin, low wall): a box or an upright cylinder standing on the
// ground, SurfaceMaterial::kObject, in its own colour.
struct StaticObject {
  std::string id;
  enum class Shape : uint8_t { kBox = 0, kCylinder = 1 } shape = Shape::kBox;
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();
  Eigen::Vector3d size_m = Eigen::Vector3d::Ones();  // along its x, y; height
  double yaw_rad = 0;
  Eigen::Vector3f color = Eigen::Vector3f(0.45f, 0.40f, 0.35f);
};

// A road: a polyline of centre points with a half width; painted asphalt with kerbs and lines.
struct Road {
  std::vector<Eigen::Vector2d> points_m;
  double half_width_m = 4;
};

// Where a point lies on the road network (RoadAt).
struct RoadPoint {
  double across_m = 0;      // distance from the nearest road's centre line
  double along_m = 0;       // arc length along that road from its first point
  double half_width_m = 0;  // of that road
  bool crossing = false;    // covered by more than one road (junction: no markings)
};

// The ground: analytic hills plus a tilt, or a height grid (bilinear between samples, clamped
// at its border).
struct Terrain {
  enum class Kind : uint8_t { kAnalytic = 0, kGrid = 1 } kind = Kind::kAnalytic;
  // h = amplitude sin(x / length_x) cos(y / length_y) + tilt_x x + tilt_y y (metres).
  double amplitude_m = 1.2;
  double length_x_m = 35;
  double length_y_m = 50;
  double tilt_x = 0.015;  // slope along x (m per m)
  double tilt_y = 0.01;
  // Grid: heights[row * cols + col] at (grid_origin + (col, row) * spacing).
  Eigen::Vector2d grid_origin_m = Eigen::Vector2d::Zero();
  double grid_spacing_m = 1;
  int grid_cols = 0, grid_rows = 0;
  std::vector<double> heights_m;
};

// A camera carried along a path (e.g. a backpack camera): it walks the polyline at constant speed
// at `height_m` above the terrain, looking ahead along the path and `pitch_deg` below horizontal.
struct CameraPath {
  std::vector<Eigen::Vector2d> waypoints_m;  // open polyline, walked back and forth (ping-pong)
  double speed_mps = 1.4;
  double height_m = 1.7;
  double pitch_deg = 10;
  // The carrier turns its heading at this mean rate where the path bends and at its ends (a walker
  // takes about a second for a street corner, two to turn back), the turn centred on the bend and
  // smooth (smoothstep: the rate peaks at 1.5 times this mid-turn); the position stays on the
  // polyline. The start of the first walk is not a turn.
  double turn_rate_deg_s = 90;
};

struct CameraSpec {
  std::string id;
  std::string name;
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;  // local frame; the pose at t = 0 for a moving camera
  std::optional<CameraPath> path;  // set: a moving camera
  double fps = 15;                 // frames per second the simulator produces by default
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
  Terrain terrain;
  std::vector<Road> roads;
  std::vector<BoxBuilding> buildings;
  std::vector<Tree> trees;
  std::vector<StaticObject> objects;
  std::vector<CameraSpec> cameras;
  std::vector<Mover> movers;

  // Terrain height (metres above the origin) and unit normal.
  double TerrainHeight(double x_m, double y_m) const;
  Eigen::Vector3d TerrainNormal(double x_m, double y_m) const;
  // Road network queries.
  bool IsRoad(double x_m, double y_m) const;
  std::optional<RoadPoint> RoadAt(double x_m, double y_m) const;
  // Footprint test: index of the building covering (x, y) with any of its parts, or -1.
  int BuildingAt(double x_m, double y_m) const;
  // Bottom of a building (sunk 0.5 m below the lowest ground under any part, so no gap shows on
  // slopes), its ground reference (the highest ground under any part: eaves are measured from
  // it) and its top (the highest roof point).
  double BuildingBase(const BoxBuilding& b) const;
  double BuildingGround(const BoxBuilding& b) const;
  double BuildingTop(const BoxBuilding& b) const;
  // The analytic roof height of building b at (x, y): the highest roof of the parts covering the
  // point, or nullopt outside its footprint. The static mesh has its roofs exactly there (up to
  // the tessellation of round parts, see BuildStaticMesh).
  std::optional<double> RoofHeightAt(const BoxBuilding& b, double x_m, double y_m) const;

  const CameraSpec* FindCamera(const std::string& id) const;
};

// The bundled demo campus: the `campus` scenario's site (model_store/scene/scenarios/campus.yaml)
// with its fixed cameras only (the registry imports these; moving cameras come from the scenario
// through the simulator). Deterministic; parsed once per process.
SyntheticCampus BuiltinCampus();
// The `campus` scenario's moving cameras (the backpack walker), which BuiltinCampus leaves out;
// world_from_camera is the pose at t = 0. `ave-admin import-campus --moving` registers them.
std::vector<CameraSpec> BuiltinCampusMovingCameras();

// Static model: terrain grid at `grid_resolution_m` plus every building part, tree and static
// object, coloured with the model's own neutral colours. Per triangle: material (walls kWall,
// roofs kRoof, trees kVegetation, static objects kObject, ground kTerrain / kRoad) and object
// (building index for walls and roofs, -1 otherwise). Round parts use 48 segments; dome roofs 12
// rings.
TriangleMesh BuildStaticMesh(const SyntheticCampus& campus, double grid_resolution_m = 2.0);

// Appends one tree (trunk, then crown) to a mesh as kVegetation with object -1. Returns the index
// of the crown's first vertex (crown vertices run to the end of mesh.positions), so a renderer can
// sway the crown (waving vegetation).
size_t AppendTree(TriangleMesh& mesh, const SyntheticCampus& campus, const Tree& tree);

// Where a mover is at time t (seconds since the scenario start); t may be negative.
MoverState MoverAt(const SyntheticCampus& campus, const Mover& mover, double t_s);

// A camera's true pose at time t: its mounting pose, or its place on its path.
Rigid3d CameraPoseAt(const SyntheticCampus& campus, const CameraSpec& camera, double t_s);

// Corners of a part's rectangular footprint (counter-clockwise), local frame.
std::vector<Eigen::Vector2d> FootprintCorners(const BuildingPart& b);

// True when (x, y) lies inside a part's footprint (rectangle, or ellipse for round parts).
bool PartCovers(const BuildingPart& part, double x_m, double y_m);

// Appends an oriented box to a mesh: bottom centre at `base`, box x axis at `yaw_rad` from east,
// `extent` = (size along box x, size along box y, height),
// with flat per-face normals.
void AppendBox(TriangleMesh& mesh, const Eigen::Vector3d& base, double yaw_rad, const Eigen::Vector3d& extent,
               const Eigen::Vector3f& wall_color, const Eigen::Vector3f& roof_color, int32_t object,
               SurfaceMaterial wall_material, SurfaceMaterial roof_material);

}  // namespace ave::scene
