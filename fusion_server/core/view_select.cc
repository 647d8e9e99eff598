#include "fusion_server/core/view_select.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/LU>

#include "absl/strings/str_cat.h"

namespace ave {
namespace {

// Corner order: near plane [0..3], far plane [4..7], each (-1,-1), (+1,-1), (+1,+1), (-1,+1) in NDC x, y.
constexpr std::array<std::array<int, 2>, 12> kEdges = {{{0, 1}, {1, 2}, {0, 4}, {1, 5}, {2, 6}, {3, 7},
                                                        {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}}};
// The first kDistinctEdges of kEdges have the distinct directions of a frustum (the near and far
// planes' edges are parallel in pairs); the rest only matter for where the floor cuts.
constexpr size_t kDistinctEdges = 6;
constexpr std::array<std::array<int, 3>, 6> kFaces = {
    {{0, 1, 2}, {4, 5, 6}, {0, 3, 7}, {1, 2, 6}, {0, 1, 5}, {3, 2, 6}}};

// The hexahedron of 8 corners as a convex volume, cut by the half-space z >= floor_z: vertices
// above the floor, plus where edges cross it; the floor adds its normal and, as edges lying in the
// floor, the directions where each face meets it.
ConvexVolume VolumeFromCorners(const std::array<Eigen::Vector3d, 8>& c, double floor_z) {
  ConvexVolume v;
  for (const auto& p : c)
    if (p.z() >= floor_z) v.vertices.push_back(p);
  if (v.vertices.empty()) return v;
  const bool cut = v.vertices.size() < c.size();
  for (size_t e = 0; e < kEdges.size(); ++e) {
    const auto [i, j] = kEdges[e];
    if (e < kDistinctEdges) v.edge_directions.push_back(c[j] - c[i]);
    if (cut && (c[i].z() < floor_z) != (c[j].z() < floor_z)) {
      const double t = (floor_z - c[i].z()) / (c[j].z() - c[i].z());
      v.vertices.push_back(c[i] + t * (c[j] - c[i]));
    }
  }
  for (const auto& [a, b, d] : kFaces) {
    Eigen::Vector3d n = (c[b] - c[a]).cross(c[d] - c[a]);
    if (n.squaredNorm() < 1e-24) n = (c[b] - c[a]).cross(c[d] - c[b]);  // a collapsed near plane
    v.face_normals.push_back(n);
  }
  if (cut) {
    const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
    for (size_t f = 1; f < kFaces.size(); ++f) v.edge_directions.push_back(v.face_normals[f].cross(up));  // near ∥ far
    v.face_normals.push_back(up);
  }
  return v;
}

// Whether the projections of a and b on `axis` are disjoint (with a relative tolerance that keeps
// touching volumes "intersecting": the test must stay conservative).
bool Separates(const Eigen::Vector3d& axis, const ConvexVolume& a, const ConvexVolume& b) {
  const double n = axis.norm();
  if (!(n > 1e-12)) return false;
  const Eigen::Vector3d u = axis / n;
  double a_min = std::numeric_limits<double>::infinity(), a_max = -a_min, b_min = a_min, b_max = -a_min;
  for (const auto& p : a.vertices) {
    const double d = u.dot(p);
    a_min = std::min(a_min, d);
    a_max = std::max(a_max, d);
  }
  for (const auto& p : b.vertices) {
    const double d = u.dot(p);
    b_min = std::min(b_min, d);
    b_max = std::max(b_max, d);
  }
  const double slack = 1e-9 * std::max({1.0, std::abs(a_min), std::abs(a_max), std::abs(b_min), std::abs(b_max)});
  return a_max < b_min - slack || b_max < a_min - slack;
}

}  // namespace

absl::StatusOr<ConvexVolume> FrustumFromClip(const Eigen::Matrix4d& clip_from_local, double max_depth_m,
                                             double floor_z) {
  if (!clip_from_local.allFinite()) return absl::InvalidArgumentError("view frustum: matrix is not finite");
  if (!(max_depth_m > 0)) return absl::InvalidArgumentError("view frustum: max depth must be > 0");
  Eigen::FullPivLU<Eigen::Matrix4d> lu(clip_from_local);
  if (!lu.isInvertible()) return absl::InvalidArgumentError("view frustum: matrix is singular");
  const Eigen::Matrix4d local_from_clip = lu.inverse();
  std::array<Eigen::Vector3d, 8> corners;
  constexpr double kNdc[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector4d near_h = local_from_clip * Eigen::Vector4d(kNdc[k][0], kNdc[k][1], -1, 1);
    const Eigen::Vector4d far_h = local_from_clip * Eigen::Vector4d(kNdc[k][0], kNdc[k][1], 1, 1);
    if (!(near_h.w() > 1e-15)) return absl::InvalidArgumentError(absl::StrCat("view frustum: near corner ", k, " is at or beyond infinity"));
    const Eigen::Vector3d near = near_h.head<3>() / near_h.w();
    Eigen::Vector3d dir;
    double depth = 0;
    if (std::abs(far_h.w()) <= 1e-15 * far_h.head<3>().norm()) {  // infinite far plane: a direction
      dir = far_h.head<3>().normalized();
      depth = max_depth_m;
    } else if (far_h.w() > 0) {
      dir = far_h.head<3>() / far_h.w() - near;
      depth = std::min(dir.norm(), max_depth_m);
      dir.normalize();
    } else {
      return absl::InvalidArgumentError(absl::StrCat("view frustum: far corner ", k, " lies behind the eye"));
    }
    if (!dir.allFinite()) return absl::InvalidArgumentError(absl::StrCat("view frustum: edge ", k, " has no direction"));
    corners[k] = near;
    corners[k + 4] = near + depth * dir;
  }
  return VolumeFromCorners(corners, floor_z);
}

ConvexVolume CameraVolume(const PinholeIntrinsics& intrinsics, const Rigid3d& local_from_camera, double near_m,
                          double far_m, double floor_z) {
  // The image's corners are pixel edges (-0.5 and width - 0.5), as in camera.h.
  std::array<Eigen::Vector3d, 8> corners;
  const double u[4] = {-0.5, intrinsics.width - 0.5, intrinsics.width - 0.5, -0.5};
  const double v[4] = {intrinsics.height - 0.5, intrinsics.height - 0.5, -0.5, -0.5};  // NDC y up = image top
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d ray((u[k] - intrinsics.cx) / intrinsics.fx, (v[k] - intrinsics.cy) / intrinsics.fy, 1);
    corners[k] = local_from_camera * (near_m * ray);
    corners[k + 4] = local_from_camera * (far_m * ray);
  }
  return VolumeFromCorners(corners, floor_z);
}

bool VolumesIntersect(const ConvexVolume& a, const ConvexVolume& b) {
  if (a.empty() || b.empty()) return false;
  // Bounding boxes first: they separate most disjoint pairs cheaply.
  for (int k = 0; k < 3; ++k)
    if (Separates(Eigen::Vector3d::Unit(k), a, b)) return false;
  for (const auto& n : a.face_normals)
    if (Separates(n, a, b)) return false;
  for (const auto& n : b.face_normals)
    if (Separates(n, a, b)) return false;
  for (const auto& ea : a.edge_directions)
    for (const auto& eb : b.edge_directions)
      if (Separates(ea.cross(eb), a, b)) return false;
  return true;
}

bool AnyIntersects(const ConvexVolume& camera, const std::vector<ConvexVolume>& views) {
  return std::any_of(views.begin(), views.end(), [&](const ConvexVolume& v) { return VolumesIntersect(camera, v); });
}

}  // namespace ave
