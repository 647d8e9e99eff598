#pragma once
// Internal to ave_render: the shadow-volume pass of cached views. Per live projector whose dynamic
// shadow map holds models, the parts of its frustum where that map may differ from the static one
// (per model: the shadow-map rectangle it covers, from its nearest corner to the end of the
// projector's volume). Mark() counts in the stencil the volumes that hold the surface in the depth
// buffer: only there may the models hide a cached entry (ResolvePass tests those pixels).
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/dynamic_models.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gl_util.h"

namespace ave::viewer::internal {

// Stencil of the shadow-tested cached resolve: volume counts (Mark) in the low bits, then a bit
// for pixels with an entry the models may hide (ResolveMode::kMarkEntries).
inline constexpr GLuint kVolumeStencilBits = 0x7F, kEntryStencilBit = 0x80;

class ShadowVolumePass {
 public:
  static absl::StatusOr<std::unique_ptr<ShadowVolumePass>> Create();

  // The volumes of the frame's live passes (none without dynamic_objects_cast_shadows).
  void Upload(const FrameContext& frame, const DynamicModels& dynamics);
  // Stencil > 0 (within the current scissor box, cleared first) where the surface in the depth
  // buffer lies inside some volume.
  void Mark(const View& view) const;

 private:
  explicit ShadowVolumePass(Program program)
      : program_(std::move(program)), volumes_(/*with_normals=*/false, /*indexed=*/false) {}
  static void ApplyState();

  Program program_;
  MeshBuffers volumes_;
};

}  // namespace ave::viewer::internal
