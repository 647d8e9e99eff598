#pragma once
// 3D placement of a tracked box (seed AVE §6.1, issue 6): the bottom-middle of the box is taken to
// be the object's ground contact; the ray through it (undistorted through the lens model) from the
// camera pose is intersected with the static model's terrain (a BVH over its terrain and road
// triangles, not a flat plane). The ground-plane uncertainty comes from the pose covariance and a
// pixel error by sigma points (each a ray cast); the object's size from the box and the distance.
//
// Frames: "world" is the static model's local frame (the frame of mesh positions and of camera
// poses on the server). Boxes use the wire's pixel convention: the origin at the top-left pixel's
// corner, so the bottom edge of a box is at y = last row + 1.
#include <array>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"

namespace ave {

// What the viewer draws for an object (wire: ave.v1.ObjectModel).
enum class ObjectShape : uint8_t { kBillboard = 1, kCuboid = 2, kCylinder = 3 };
enum class ObjectKind : uint8_t { kUnknown = 0, kPerson = 1, kCar = 2 };

// The ground of a static model: its terrain and road triangles in a BVH, plus its building walls
// and roofs in a second BVH, which hide the ground behind them.
class TerrainModel {
 public:
  // Keeps the kTerrain and kRoad triangles of `mesh` as ground and its kWall and kRoof triangles
  // as occluders (trees and objects are neither).
  explicit TerrainModel(const TriangleMesh& mesh);
  // Nearest ground hit along a ray (world/local frame); the hit point and the triangle's unit
  // normal (facing the ray's origin side).
  struct Hit {
    Eigen::Vector3d point;
    Eigen::Vector3d normal;
    double distance_m = 0;
  };
  std::optional<Hit> Raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_m) const;
  // Whether a building wall or roof lies along the ray within max_m.
  bool Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_m) const;
  size_t TriangleCount() const { return bvh_.TriangleCount(); }
  size_t OccluderTriangleCount() const { return occluder_bvh_.TriangleCount(); }

 private:
  TriangleMesh ground_;
  MeshBvh bvh_;
  MeshBvh occluder_bvh_;  // walls and roofs (the BVH keeps its own copy of the triangles)
};

struct PlacementOptions {
  double max_range_m = 500;         // farther ground contacts are refused
  double min_grazing_deg = 1.0;     // rays flatter than this against the ground are refused
  double pixel_sigma = 1.0;         // ground-contact pixel error (pixels, each axis)
  // Used when a frame carries no pose covariance: position (m) and rotation (rad) sigma.
  double default_position_sigma_m = 0.05;
  double default_rotation_sigma_rad = 0.002;

  std::string Check() const;  // empty when usable, else names the field
};

struct Placement {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // ground contact, world (local frame)
  Eigen::Matrix2d covariance_xy = Eigen::Matrix2d::Zero();  // m^2, symmetric, floored
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();    // width, length, height
  double range_m = 0;                                  // camera centre to contact
  ObjectKind kind = ObjectKind::kUnknown;
  ObjectShape shape = ObjectShape::kBillboard;
};

// The camera pixel (pixel-centre convention) undistorted through the Brown-Conrady model, as a unit
// ray in the camera frame. Converges for the distortions real lenses have (|k1| < 1); falls back to
// the distorted ray when the iteration does not settle.
Eigen::Vector3d UndistortedRay(const PinholeIntrinsics& intrinsics, const Eigen::Vector2d& uv);

// Places a box (x0, y0, x1, y1 in wire pixel edges). `pose_covariance` is the wire's row-major 6x6
// (position x y z [m], rotation-vector error x y z [rad], world frame); null or empty = options'
// defaults. Nullopt (with `why` set when given) when the ray never meets the ground (sky, off the
// model), meets it beyond max_range_m, grazes it, meets a building before the ground (the box's
// bottom edge lies on a wall: the person is cut by the building in front, the contact is hidden),
// or any input is not finite.
std::optional<Placement> PlaceBox(const TerrainModel& terrain, const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& world_from_camera, const Eigen::Matrix<double, 6, 6>* pose_covariance,
                                  const std::array<double, 4>& box, const PlacementOptions& options = {},
                                  std::string* why = nullptr);

}  // namespace ave
