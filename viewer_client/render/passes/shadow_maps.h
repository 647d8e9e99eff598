#pragma once
// Internal to ave_render: the shadow-map pass (paper section 8). Per live projector a depth layer
// of the static model and, with dynamic_objects_cast_shadows, a second layer with the dynamic
// models added; per retained snapshot a static layer. A layer is re-rendered only when its
// projector's pose or the geometry changed; the dynamic layer is a copy of the static one plus the
// models, copied only where the models were or are. The static layer's depth is read back once to
// bound the projector's footprint (ShadowSlot::visible_far_m).
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "viewer_client/render/passes/avatar_pass.h"
#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/dynamic_models.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/static_model.h"

namespace ave::viewer::internal {

class ShadowMaps {
 public:
  static absl::StatusOr<std::unique_ptr<ShadowMaps>> Create(const RendererOptions& options);

  // Brings every active layer up to date with the cameras' poses and the geometry's versions.
  // The avatars (issue 17) cast shadows with the dynamic models (their bounds are among them).
  absl::Status Update(CameraSet& cameras, const StaticModel& statics, const DynamicModels& dynamics,
                      const AvatarPass& avatars, RenderStats& stats);

  GLuint live_static() const { return live_.static_array; }
  GLuint live_dynamic() const { return live_.dynamic_array; }
  GLuint retained_static() const { return retained_.static_array; }

 private:
  // One layer set: a shadow-map array, and optionally a second one with dynamic models added.
  struct Arrays {
    Texture static_array, dynamic_array;
    int layers = 0;
    // True when it reallocated (every layer's content is lost).
    bool Ensure(int needed, int size, bool with_dynamic);
  };

  ShadowMaps(const RendererOptions& options, Program program);
  static void ApplyState();
  // Renders the shadow map of one layer if its projector or the geometry changed.
  absl::Status UpdateLayer(Arrays& arrays, int layer, ShadowSlot& slot, const Projector& p, bool with_dynamic,
                           const StaticModel& statics, const DynamicModels& dynamics, const AvatarPass& avatars,
                           bool& state_set,
                           uint64_t& counter, RenderStats& stats);
  // The static shadow map bound for reading: its farthest depth and whether it sees nothing
  // somewhere. Skipped (bounds from the scene box) above 2048 px, where the read costs more than
  // it saves.
  void ReadExtent(const Eigen::Matrix4d& shadow_projection, ShadowSlot& slot);

  const RendererOptions& options_;
  Program program_;
  GLint clip_from_local_ = -1;
  Arrays live_, retained_;
  Framebuffer src_fbo_, dst_fbo_;
  std::vector<float> readback_;
};

}  // namespace ave::viewer::internal
