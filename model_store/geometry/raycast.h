#pragma once
// Ray / mesh intersection, brute force over triangles with a bounding-box reject. Used as the
// ground truth for visibility in tests (a few thousand rays), not in per-pixel hot loops.
#include <optional>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "model_store/geometry/mesh.h"

namespace ave {

struct RayHit {
  double distance_m = 0;  // along the unit direction
  size_t triangle = 0;
};

// Nearest hit with distance in (min_distance_m, max_distance_m]. Rays parallel to a triangle
// (grazing) do not hit it. `origin_local` is in the mesh's local frame; `direction` need not be
// unit (it is normalised; a zero or non-finite direction never hits).
std::optional<RayHit> RaycastMesh(const TriangleMesh& mesh, const Eigen::Vector3d& origin_local,
                                  const Eigen::Vector3d& direction, double min_distance_m = 1e-4,
                                  double max_distance_m = 1e9);

// True when the straight segment from `a` to `b` (local frame) crosses no triangle, with
// `tolerance_m` slack at both ends so surfaces the end points lie on do not count.
bool SegmentIsClear(const TriangleMesh& mesh, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                    double tolerance_m = 0.05);

}  // namespace ave
