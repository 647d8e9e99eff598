#pragma once
// Internal to ave_render: the static model's GL buffers, split into grid chunks so that each view
// or shadow map draws only the chunks its frustum may see (llvmpipe is geometry-bound on the
// static model: every triangle drawn costs vertex shading and setup even when it lands off
// screen). The G-buffer and shadow passes draw it with their own program and state.
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "model_store/geometry/mesh.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

// A run of the static mesh's (reordered) index buffer whose triangles lie in one cell of a grid
// over the model's footprint, with the box of its vertices.
struct MeshChunk {
  size_t first_index = 0, index_count = 0;
  Bounds bounds;
};

class StaticModel {
 public:
  StaticModel() : mesh_(/*with_normals=*/true, /*indexed=*/true) {}

  // Renderer::SetStaticMesh: validates (errors name the vertex or index), uploads, bumps version().
  absl::Status Set(const TriangleMesh& mesh);
  // The chunks that may show in a view with this matrix, consecutive ones merged into one draw
  // call, with the bound program and state; skipped chunks count in stats.chunks_culled.
  void DrawChunks(const Eigen::Matrix4d& clip_from_local, RenderStats& stats) const;

  const Bounds& bounds() const { return bounds_; }
  uint64_t version() const { return version_; }  // changes with every Set

 private:
  MeshBuffers mesh_;
  std::vector<MeshChunk> chunks_;  // mesh_'s index buffer, by grid cell
  Bounds bounds_;
  uint64_t version_ = 1;
};

}  // namespace ave::viewer::internal
