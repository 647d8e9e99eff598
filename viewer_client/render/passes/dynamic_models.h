#pragma once
// Internal to ave_render: the dynamic models (DynamicModel: cuboid, cylinder, billboard) as one
// vertex buffer, re-uploaded only when they change. The G-buffer pass draws them (they receive
// video) and the shadow pass adds them to the projectors' dynamic shadow maps (they cast shadows).
#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class DynamicModels {
 public:
  DynamicModels() : mesh_(/*with_normals=*/true, /*indexed=*/false) {}

  // Renderer::SetDynamicModels: validates (the error names the model); an unchanged set keeps
  // version().
  absl::Status Set(const std::vector<DynamicModel>& models);
  // The models with the bound program and state (faces wound counter-clockwise from outside).
  void Draw() const;
  // The avatars' boxes (AvatarPass::instance_bounds, issue 17) join the models' bounds, so the
  // shadow maps, shadow volumes and view-cache rectangles treat avatars as dynamic models too.
  void SetAvatarBounds(const std::vector<Bounds>& avatar_bounds);

  const Bounds& bounds() const { return bounds_; }                     // all models, any heading
  const std::vector<Bounds>& model_bounds() const { return model_bounds_; }  // per model
  uint64_t version() const { return version_; }

 private:
  MeshBuffers mesh_;
  std::vector<Vertex> vertices_;
  Bounds bounds_;
  std::vector<Bounds> model_bounds_;
  Bounds own_bounds_;                        // the models' alone
  std::vector<Bounds> own_model_bounds_;
  std::vector<Bounds> avatar_bounds_;
  void MergeBounds();
  uint64_t version_ = 1;
};

}  // namespace ave::viewer::internal
