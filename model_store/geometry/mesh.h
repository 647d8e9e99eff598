#pragma once
// Triangle meshes in a local frame: float positions relative to a double-precision origin
// (MISSION part A: never lose centimetres to float at ~1e6 m survey coordinates).
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace ave {

// What a triangle is made of; the simulator paints by material, the viewer ignores it.
enum class SurfaceMaterial : uint8_t { kTerrain = 0, kRoad = 1, kWall = 2, kRoof = 3, kObject = 4, kVegetation = 5 };

struct TriangleMesh {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates of the local zero
  std::vector<Eigen::Vector3f> positions;            // metres, relative to origin
  std::vector<Eigen::Vector3f> normals;              // unit, per vertex
  std::vector<Eigen::Vector3f> colors;               // rgb in [0, 1]: the model's own colour
  std::vector<uint32_t> indices;                     // three per triangle
  std::vector<SurfaceMaterial> triangle_material;    // one per triangle
  std::vector<int32_t> triangle_object;              // one per triangle: building index, or -1

  size_t TriangleCount() const { return indices.size() / 3; }
};

}  // namespace ave
