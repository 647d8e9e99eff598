#include "viewer_client/render/passes/static_model.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace ave::viewer::internal {
namespace {

// Reorders `indices` (triangles) by grid cell over the x-y box of `positions`, cells of about
// kTrianglesPerChunk triangles; returns the chunks in index-buffer order.
constexpr size_t kTrianglesPerChunk = 1024;
std::vector<MeshChunk> SortIntoChunks(const std::vector<Eigen::Vector3f>& positions, const Bounds& box,
                                      std::vector<uint32_t>& indices) {
  const size_t triangles = indices.size() / 3;
  if (triangles == 0 || box.empty()) return {};
  const int cells = std::clamp(static_cast<int>(std::sqrt(static_cast<double>(triangles) / kTrianglesPerChunk)), 1, 32);
  const Eigen::Vector3d extent = (box.hi - box.lo).cwiseMax(1e-9);
  std::vector<int> cell_of(triangles);
  std::vector<size_t> per_cell(static_cast<size_t>(cells) * cells + 1, 0);
  for (size_t t = 0; t < triangles; ++t) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) centroid += positions[indices[3 * t + k]].cast<double>() / 3;
    const int cx = std::clamp(static_cast<int>((centroid.x() - box.lo.x()) / extent.x() * cells), 0, cells - 1);
    const int cy = std::clamp(static_cast<int>((centroid.y() - box.lo.y()) / extent.y() * cells), 0, cells - 1);
    cell_of[t] = cy * cells + cx;
    ++per_cell[cell_of[t] + 1];
  }
  for (size_t c = 1; c < per_cell.size(); ++c) per_cell[c] += per_cell[c - 1];  // first triangle of each cell
  std::vector<MeshChunk> chunks(static_cast<size_t>(cells) * cells);
  std::vector<size_t> next(per_cell.begin(), per_cell.end() - 1);
  std::vector<uint32_t> sorted(indices.size());
  for (size_t t = 0; t < triangles; ++t) {  // stable: the mesh's own order within a cell
    const size_t slot = next[cell_of[t]]++;
    MeshChunk& chunk = chunks[cell_of[t]];
    for (int k = 0; k < 3; ++k) {
      sorted[3 * slot + k] = indices[3 * t + k];
      chunk.bounds.Add(positions[indices[3 * t + k]].cast<double>());
    }
  }
  for (size_t c = 0; c < chunks.size(); ++c) {
    chunks[c].first_index = 3 * per_cell[c];
    chunks[c].index_count = 3 * (per_cell[c + 1] - per_cell[c]);
  }
  std::erase_if(chunks, [](const MeshChunk& c) { return c.index_count == 0; });
  indices = std::move(sorted);
  return chunks;
}

}  // namespace

absl::Status StaticModel::Set(const TriangleMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (mesh.normals.size() != n || mesh.colors.size() != n) {
    return absl::InvalidArgumentError("SetStaticMesh: " + std::to_string(n) + " positions but " +
                                      std::to_string(mesh.normals.size()) + " normals and " +
                                      std::to_string(mesh.colors.size()) + " colors");
  }
  if (mesh.indices.size() % 3 != 0) return absl::InvalidArgumentError("SetStaticMesh: indices not a multiple of 3");
  for (size_t k = 0; k < mesh.indices.size(); ++k) {
    if (mesh.indices[k] >= n) {
      return absl::InvalidArgumentError("SetStaticMesh: index " + std::to_string(k) + " = " +
                                        std::to_string(mesh.indices[k]) + " >= vertex count " + std::to_string(n));
    }
  }
  std::vector<Vertex> vertices(n);
  Bounds bounds;
  for (size_t k = 0; k < n; ++k) {
    if (!mesh.positions[k].allFinite() || !mesh.normals[k].allFinite() || !mesh.colors[k].allFinite()) {
      return absl::InvalidArgumentError("SetStaticMesh: vertex " + std::to_string(k) + " is not finite");
    }
    vertices[k] = MakeVertex(mesh.positions[k], mesh.normals[k], mesh.colors[k].cwiseMax(0.0f));
    bounds.Add(mesh.positions[k].cast<double>());
  }
  std::vector<uint32_t> indices = mesh.indices;
  chunks_ = SortIntoChunks(mesh.positions, bounds, indices);
  mesh_.UploadIndexed(vertices, indices);
  bounds_ = bounds;
  ++version_;
  return CheckGl("SetStaticMesh");
}

void StaticModel::DrawChunks(const Eigen::Matrix4d& clip_from_local, RenderStats& stats) const {
  if (mesh_.count() == 0) return;
  glBindVertexArray(mesh_.vao());
  size_t run_first = 0, run_count = 0;
  auto flush = [&] {
    if (run_count > 0) {
      glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(run_count), GL_UNSIGNED_INT,
                     reinterpret_cast<void*>(run_first * sizeof(uint32_t)));
    }
    run_count = 0;
  };
  for (const MeshChunk& chunk : chunks_) {
    if (!VolumeMayBeVisible(chunk.bounds.Corners(), clip_from_local)) {
      ++stats.chunks_culled;
      continue;
    }
    if (run_count > 0 && run_first + run_count != chunk.first_index) flush();
    if (run_count == 0) run_first = chunk.first_index;
    run_count += chunk.index_count;
  }
  flush();
}

}  // namespace ave::viewer::internal
