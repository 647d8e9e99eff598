#include "model_store/geometry/raycast.h"

#include <cmath>

namespace ave {

std::optional<RayHit> RaycastMesh(const TriangleMesh& mesh, const Eigen::Vector3d& origin,
                                  const Eigen::Vector3d& direction, double min_distance_m, double max_distance_m) {
  const double len = direction.norm();
  if (!(len > 0) || !std::isfinite(len) || !origin.allFinite()) return std::nullopt;
  const Eigen::Vector3d d = direction / len;
  std::optional<RayHit> best;
  double best_t = max_distance_m;
  // Möller–Trumbore in double; the determinant threshold rejects grazing (parallel) rays.
  for (size_t tri = 0; tri < mesh.TriangleCount(); ++tri) {
    const Eigen::Vector3d v0 = mesh.positions[mesh.indices[3 * tri]].cast<double>();
    const Eigen::Vector3d v1 = mesh.positions[mesh.indices[3 * tri + 1]].cast<double>();
    const Eigen::Vector3d v2 = mesh.positions[mesh.indices[3 * tri + 2]].cast<double>();
    const Eigen::Vector3d e1 = v1 - v0, e2 = v2 - v0;
    const Eigen::Vector3d pvec = d.cross(e2);
    const double det = e1.dot(pvec);
    if (std::abs(det) < 1e-12 * e1.norm() * e2.norm()) continue;
    const double inv_det = 1.0 / det;
    const Eigen::Vector3d tvec = origin - v0;
    const double u = tvec.dot(pvec) * inv_det;
    if (u < 0 || u > 1) continue;
    const Eigen::Vector3d qvec = tvec.cross(e1);
    const double v = d.dot(qvec) * inv_det;
    if (v < 0 || u + v > 1) continue;
    const double t = e2.dot(qvec) * inv_det;
    if (t > min_distance_m && t <= best_t) {
      best_t = t;
      best = RayHit{t, tri};
    }
  }
  return best;
}

bool SegmentIsClear(const TriangleMesh& mesh, const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tolerance_m) {
  const double length = (b - a).norm();
  if (length <= 2 * tolerance_m) return true;
  return !RaycastMesh(mesh, a, b - a, tolerance_m, length - tolerance_m).has_value();
}

}  // namespace ave
