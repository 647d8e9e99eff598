#include "model_store/geometry/bvh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace ave {

MeshBvh::MeshBvh(const TriangleMesh& mesh) {
  const size_t n = mesh.TriangleCount();
  std::vector<Eigen::Vector3d> centroids(n), lo(n), hi(n);
  std::vector<Triangle> source(n);
  for (size_t t = 0; t < n; ++t) {
    const Eigen::Vector3d v0 = mesh.positions[mesh.indices[3 * t]].cast<double>();
    const Eigen::Vector3d v1 = mesh.positions[mesh.indices[3 * t + 1]].cast<double>();
    const Eigen::Vector3d v2 = mesh.positions[mesh.indices[3 * t + 2]].cast<double>();
    source[t] = Triangle{v0, v1 - v0, v2 - v0, static_cast<uint32_t>(t)};
    lo[t] = v0.cwiseMin(v1).cwiseMin(v2);
    hi[t] = v0.cwiseMax(v1).cwiseMax(v2);
    centroids[t] = (v0 + v1 + v2) / 3.0;
  }
  if (n == 0) return;
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  nodes_.reserve(2 * n / kLeafSize + 1);
  Build(order, centroids, lo, hi, 0, static_cast<uint32_t>(n));
  triangles_.reserve(n);
  for (uint32_t i : order) triangles_.push_back(source[i]);
}

uint32_t MeshBvh::Build(std::vector<uint32_t>& order, const std::vector<Eigen::Vector3d>& centroids,
                        const std::vector<Eigen::Vector3d>& lo, const std::vector<Eigen::Vector3d>& hi, uint32_t begin,
                        uint32_t end) {
  const uint32_t node_index = static_cast<uint32_t>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3d box_lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d box_hi = -box_lo, c_lo = box_lo, c_hi = box_hi;
  for (uint32_t i = begin; i < end; ++i) {
    box_lo = box_lo.cwiseMin(lo[order[i]]);
    box_hi = box_hi.cwiseMax(hi[order[i]]);
    c_lo = c_lo.cwiseMin(centroids[order[i]]);
    c_hi = c_hi.cwiseMax(centroids[order[i]]);
  }
  nodes_[node_index].lo = box_lo;
  nodes_[node_index].hi = box_hi;
  int axis = 0;
  (c_hi - c_lo).maxCoeff(&axis);
  if (end - begin <= static_cast<uint32_t>(kLeafSize) || !(c_hi[axis] > c_lo[axis])) {
    nodes_[node_index].first = begin;
    nodes_[node_index].count = end - begin;
    return node_index;
  }
  // Median split on the longest centroid axis; ties broken by index so the build is deterministic.
  const uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end, [&](uint32_t a, uint32_t b) {
    const double ca = centroids[a][axis], cb = centroids[b][axis];
    return ca < cb || (ca == cb && a < b);
  });
  Build(order, centroids, lo, hi, begin, mid);
  const uint32_t right = Build(order, centroids, lo, hi, mid, end);
  nodes_[node_index].first = right;
  nodes_[node_index].count = 0;
  return node_index;
}

namespace {

// Slab test; returns the entry distance or +inf when the ray misses [t_min, t_max]. Zero direction
// components give ±inf inverse components; the NaN of 0 * inf (origin on a slab plane) is avoided
// by testing those axes directly.
inline double EnterBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& o, const Eigen::Vector3d& inv,
                       const Eigen::Vector3d& d, double t_min, double t_max) {
  double t0 = t_min, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return std::numeric_limits<double>::infinity();
      continue;
    }
    double ta = (lo[a] - o[a]) * inv[a], tb = (hi[a] - o[a]) * inv[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  // A little slack so triangles lying in a box face (flat roofs, axis-aligned walls) are not lost to rounding.
  return t0 <= t1 * (1 + 1e-12) + 1e-9 ? t0 : std::numeric_limits<double>::infinity();
}

}  // namespace

std::optional<RayHit> MeshBvh::Raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double min_distance_m,
                                       double max_distance_m, Work* work) const {
  const double len = direction.norm();
  if (nodes_.empty() || !(len > 0) || !std::isfinite(len) || !origin.allFinite()) return std::nullopt;
  const Eigen::Vector3d d = direction / len;
  const Eigen::Vector3d inv(1.0 / d.x(), 1.0 / d.y(), 1.0 / d.z());
  double best_t = max_distance_m;
  uint32_t best_index = std::numeric_limits<uint32_t>::max();
  bool found = false;

  uint32_t stack[64];
  int top = 0;
  if (EnterBox(nodes_[0].lo, nodes_[0].hi, origin, inv, d, 0, best_t) == std::numeric_limits<double>::infinity()) return std::nullopt;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (work) {
      ++work->nodes_visited;
      work->triangles_tested += node.count;
    }
    if (node.count > 0) {
      // Möller–Trumbore in double, exactly as RaycastMesh (same grazing threshold).
      for (uint32_t i = node.first; i < node.first + node.count; ++i) {
        const Triangle& tri = triangles_[i];
        const Eigen::Vector3d pvec = d.cross(tri.e2);
        const double det = tri.e1.dot(pvec);
        if (std::abs(det) < 1e-12 * tri.e1.norm() * tri.e2.norm()) continue;
        const double inv_det = 1.0 / det;
        const Eigen::Vector3d tvec = origin - tri.v0;
        const double u = tvec.dot(pvec) * inv_det;
        if (u < 0 || u > 1) continue;
        const Eigen::Vector3d qvec = tvec.cross(tri.e1);
        const double v = d.dot(qvec) * inv_det;
        if (v < 0 || u + v > 1) continue;
        const double t = tri.e2.dot(qvec) * inv_det;
        if (t > min_distance_m && (t < best_t || (t == best_t && (!found || tri.index < best_index)))) {
          best_t = t;
          best_index = tri.index;
          found = true;
        }
      }
      continue;
    }
    const uint32_t left = static_cast<uint32_t>(&node - nodes_.data()) + 1, right = node.first;
    const double t_left = EnterBox(nodes_[left].lo, nodes_[left].hi, origin, inv, d, 0, best_t);
    const double t_right = EnterBox(nodes_[right].lo, nodes_[right].hi, origin, inv, d, 0, best_t);
    const bool hit_left = t_left != std::numeric_limits<double>::infinity();
    const bool hit_right = t_right != std::numeric_limits<double>::infinity();
    // Push the farther child first so the nearer one is visited first and shrinks best_t.
    if (hit_left && hit_right) {
      if (t_left <= t_right) {
        stack[top++] = right;
        stack[top++] = left;
      } else {
        stack[top++] = left;
        stack[top++] = right;
      }
    } else if (hit_left) {
      stack[top++] = left;
    } else if (hit_right) {
      stack[top++] = right;
    }
  }
  if (!found) return std::nullopt;
  return RayHit{best_t, best_index};
}

}  // namespace ave
