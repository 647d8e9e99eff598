#pragma once
// Data selection (issue 7 item 5, AVE §8): which cameras' frames a viewer needs. A viewer sends
// the frusta of its views (GL clip from local); the server sends a camera's JPEGs only while the
// camera's own viewing volume intersects one of them, and poses and status for every camera.
//
// The test is conservative: it may report "intersects" for volumes that are in fact disjoint
// (never the other way round), so a viewer never misses a frame it could show. Both volumes are
// cut at the site's floor (the lowest point of the static model) before the test: nothing below it
// can be seen or textured, and without the cut a camera looking down would select every view
// whose frustum reaches under the ground.
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"

namespace ave {

// A convex volume for the separating-axis test: its vertices, plus the normals of its faces and
// the directions of its edges (both any length, any sign). Empty: nothing left (entirely cut off).
struct ConvexVolume {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3d> face_normals;
  std::vector<Eigen::Vector3d> edge_directions;
  bool empty() const { return vertices.empty(); }
};

// Views farther than this are clamped: a viewer with a huge far plane does not select the whole site.
inline constexpr double kDefaultSelectionDepthM = 2000;

// The frustum of a GL `clip_from_local` (projection * view) matrix, cut at z >= floor_z (local
// frame; -infinity for no cut). Far corners beyond `max_depth_m` from their near corners, or at
// infinity (an infinite far plane), are pulled in along their edge to that distance. Fails, naming
// the problem, for a non-finite or singular matrix or one that is not a perspective/orthographic
// frustum (a far corner behind its near corner).
absl::StatusOr<ConvexVolume> FrustumFromClip(const Eigen::Matrix4d& clip_from_local, double max_depth_m,
                                             double floor_z);

// A camera's viewing volume between near_m and far_m (depth along its axis), cut at floor_z.
ConvexVolume CameraVolume(const PinholeIntrinsics& intrinsics, const Rigid3d& local_from_camera, double near_m,
                          double far_m, double floor_z);

// Separating-axis test: false only when some axis (a face normal of either volume, or the cross
// product of an edge of each) separates their projections. Empty volumes intersect nothing.
bool VolumesIntersect(const ConvexVolume& a, const ConvexVolume& b);

// True when `camera` intersects any of `views`.
bool AnyIntersects(const ConvexVolume& camera, const std::vector<ConvexVolume>& views);

}  // namespace ave
