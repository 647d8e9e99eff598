#pragma once
// Bounding-volume hierarchy over a TriangleMesh for fast nearest-hit ray casting (the LiDAR
// simulators cast ~65k rays per rotating frame and millions per airborne flight; the brute-force
// RaycastMesh in raycast.h stays the reference it is tested against).
//
// Built once over the mesh's local-frame float positions (copied to double per triangle so the
// intersection test is identical to RaycastMesh's Möller–Trumbore in double). Median split on the
// longest axis of the centroid bounds; leaves hold at most `kLeafSize` triangles.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/mesh.h"
#include "model_store/geometry/raycast.h"

namespace ave {

class MeshBvh {
 public:
  static constexpr int kLeafSize = 4;

  MeshBvh() = default;
  // Keeps no reference to `mesh`: triangles are copied (the mesh may be discarded afterwards).
  explicit MeshBvh(const TriangleMesh& mesh);

  // Same contract as RaycastMesh: nearest hit with distance in (min_distance_m, max_distance_m]
  // along the normalised direction, grazing (parallel) triangles never hit, a zero or non-finite
  // direction or origin never hits. The triangle index is the mesh's. On exact ties in distance
  // the lower triangle index wins (RaycastMesh keeps the later one; distances agree).
  // The work one or more casts did, added to when passed to Raycast: what makes the hierarchy pay,
  // counted rather than timed (a timed assertion fails on a loaded machine).
  struct Work {
    uint64_t nodes_visited = 0;
    uint64_t triangles_tested = 0;
  };
  std::optional<RayHit> Raycast(const Eigen::Vector3d& origin_local, const Eigen::Vector3d& direction,
                                double min_distance_m = 1e-4, double max_distance_m = 1e9, Work* work = nullptr) const;

  size_t TriangleCount() const { return triangles_.size(); }
  size_t NodeCount() const { return nodes_.size(); }

 private:
  struct Triangle {
    Eigen::Vector3d v0, e1, e2;  // vertex 0 and the two edges from it
    uint32_t index;              // triangle index in the mesh
  };
  struct Node {
    Eigen::Vector3d lo, hi;  // bounds
    uint32_t first = 0;      // leaf: first triangle in triangles_; inner: index of the right child
    uint32_t count = 0;      // leaf: triangle count (> 0); inner: 0 (left child is the next node)
  };
  uint32_t Build(std::vector<uint32_t>& order, const std::vector<Eigen::Vector3d>& centroids,
                 const std::vector<Eigen::Vector3d>& lo, const std::vector<Eigen::Vector3d>& hi, uint32_t begin,
                 uint32_t end);

  std::vector<Triangle> triangles_;
  std::vector<Node> nodes_;
};

}  // namespace ave
