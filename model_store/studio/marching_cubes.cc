#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "model_store/studio/surface.h"

namespace ave::studio {
namespace {

#include "model_store/studio/mc_tables.inc"

constexpr int kEdgeCorners[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

}  // namespace

std::string SurfaceOptions::Check() const {
  if (smooth_passes < 0 || smooth_passes > 4) return "smooth_passes must be in [0, 4]";
  return {};
}

std::vector<float> SmoothedOccupancy(const VoxelGrid& grid, int passes) {
  const int nx = grid.size.x(), ny = grid.size.y(), nz = grid.size.z();
  std::vector<float> a(grid.occupied.begin(), grid.occupied.end()), b(a.size());
  const size_t stride[3] = {1, static_cast<size_t>(nx), static_cast<size_t>(nx) * ny};
  const int dims[3] = {nx, ny, nz};
  for (int pass = 0; pass < passes; ++pass) {
    for (int axis = 0; axis < 3; ++axis) {  // separable: [1 1 1] / 3 along each axis
      for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
          for (int x = 0; x < nx; ++x) {
            const size_t i = grid.Index(x, y, z);
            const int c = axis == 0 ? x : axis == 1 ? y : z;
            float s = a[i];
            if (c > 0) s += a[i - stride[axis]];
            if (c + 1 < dims[axis]) s += a[i + stride[axis]];
            b[i] = s / 3.0f;
          }
      a.swap(b);
    }
  }
  return a;
}

SurfaceMesh MarchingCubes(const std::vector<float>& field, const VoxelGrid& grid, float iso) {
  SurfaceMesh mesh;
  const int nx = grid.size.x(), ny = grid.size.y(), nz = grid.size.z();
  if (nx < 2 || ny < 2 || nz < 2) return mesh;
  const Eigen::Vector3f origin = (grid.origin_m + Eigen::Vector3d::Constant(0.5 * grid.voxel_m)).cast<float>();
  const float h = static_cast<float>(grid.voxel_m);
  // Vertex ids on grid edges, by the edge's lower grid point and axis; two z layers kept.
  const size_t layer = static_cast<size_t>(nx) * ny;
  std::vector<int32_t> ids[2][3];
  for (auto& l : ids)
    for (auto& a : l) a.assign(layer, -1);
  auto vertex_on = [&](int x, int y, int z, int axis) -> uint32_t {
    int32_t& id = ids[z & 1][axis][static_cast<size_t>(y) * nx + x];
    if (id >= 0) return static_cast<uint32_t>(id);
    const int x1 = x + (axis == 0), y1 = y + (axis == 1), z1 = z + (axis == 2);
    const float f0 = field[grid.Index(x, y, z)], f1 = field[grid.Index(x1, y1, z1)];
    const float t = std::abs(f1 - f0) > 1e-12f ? std::clamp((iso - f0) / (f1 - f0), 0.0f, 1.0f) : 0.5f;
    Eigen::Vector3f p = origin + h * Eigen::Vector3f(x, y, z);
    p[axis] += h * t;
    id = static_cast<int32_t>(mesh.positions_m.size());
    mesh.positions_m.push_back(p);
    return static_cast<uint32_t>(id);
  };
  for (int z = 0; z + 1 < nz; ++z) {
    for (auto& a : ids[(z + 1) & 1]) std::fill(a.begin(), a.end(), -1);  // the layer above is new
    for (int y = 0; y + 1 < ny; ++y) {
      for (int x = 0; x + 1 < nx; ++x) {
        int cube = 0;
        for (int c = 0; c < 8; ++c) {
          if (field[grid.Index(x + kCorner[c][0], y + kCorner[c][1], z + kCorner[c][2])] < iso) cube |= 1 << c;
        }
        if (kEdgeTable[cube] == 0) continue;
        uint32_t edge_vertex[12];
        for (int e = 0; e < 12; ++e) {
          if (!(kEdgeTable[cube] & (1 << e))) continue;
          const int* a = kCorner[kEdgeCorners[e][0]];
          const int* b = kCorner[kEdgeCorners[e][1]];
          const int axis = a[0] != b[0] ? 0 : a[1] != b[1] ? 1 : 2;
          edge_vertex[e] = vertex_on(x + std::min(a[0], b[0]), y + std::min(a[1], b[1]), z + std::min(a[2], b[2]), axis);
        }
        for (int k = 0; kTriTable[cube][k] >= 0; k += 3) {
          const uint32_t v0 = edge_vertex[kTriTable[cube][k]], v1 = edge_vertex[kTriTable[cube][k + 1]],
                         v2 = edge_vertex[kTriTable[cube][k + 2]];
          if (v0 == v1 || v1 == v2 || v0 == v2) continue;
          mesh.indices.insert(mesh.indices.end(), {v0, v1, v2});
        }
      }
    }
  }
  return mesh;
}

void OrientAndSetNormals(SurfaceMesh& mesh) {
  double volume6 = 0;
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const Eigen::Vector3d a = mesh.positions_m[mesh.indices[3 * t]].cast<double>(), b = mesh.positions_m[mesh.indices[3 * t + 1]].cast<double>(),
                          c = mesh.positions_m[mesh.indices[3 * t + 2]].cast<double>();
    volume6 += a.dot(b.cross(c));
  }
  if (volume6 < 0) {
    for (size_t t = 0; t < mesh.TriangleCount(); ++t) std::swap(mesh.indices[3 * t + 1], mesh.indices[3 * t + 2]);
  }
  mesh.normals.assign(mesh.positions_m.size(), Eigen::Vector3f::Zero());
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const uint32_t i0 = mesh.indices[3 * t], i1 = mesh.indices[3 * t + 1], i2 = mesh.indices[3 * t + 2];
    const Eigen::Vector3f n = (mesh.positions_m[i1] - mesh.positions_m[i0]).cross(mesh.positions_m[i2] - mesh.positions_m[i0]);
    mesh.normals[i0] += n;
    mesh.normals[i1] += n;
    mesh.normals[i2] += n;
  }
  for (Eigen::Vector3f& n : mesh.normals) {
    const float len = n.norm();
    n = len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::UnitZ();
  }
}

absl::StatusOr<SurfaceMesh> ExtractSurface(const VoxelGrid& grid, const SurfaceOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("surface options: " + why);
  if (grid.occupied.size() != static_cast<size_t>(grid.size.x()) * grid.size.y() * grid.size.z()) {
    return absl::InvalidArgumentError("surface: voxel grid size does not match its occupancy");
  }
  const std::vector<float> field = SmoothedOccupancy(grid, options.smooth_passes);
  SurfaceMesh mesh;
  if (options.method == SurfaceMethod::kOwnMarchingCubes) {
    mesh = MarchingCubes(field, grid, 0.5f);
  } else {
    absl::StatusOr<SurfaceMesh> vtk = VtkIsoSurface(field, grid, 0.5f, options.method == SurfaceMethod::kVtkFlyingEdges);
    if (!vtk.ok()) return vtk.status();
    mesh = *std::move(vtk);
  }
  OrientAndSetNormals(mesh);
  return mesh;
}

}  // namespace ave::studio
