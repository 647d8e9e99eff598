#include "viewer_client/render/passes/shadow_volumes.h"

#include <algorithm>
#include <limits>
#include <optional>

#include <Eigen/LU>

#include "model_store/geometry/camera.h"
#include "viewer_client/render/passes/projector_geometry.h"

namespace ave::viewer::internal {
namespace {

// The parts of a projector's frustum where its dynamic shadow map may differ from the static one:
// per model in its view, the rectangle of the shadow map the model covers (ModelNdcRect), from the
// model's nearest corner to the end of the projector's volume. A surface point outside them sees
// the projector past no model. 36 vertices per model.
void AppendShadowVolumes(const Projector& p, const ShadowSlot& slot, const std::vector<Bounds>& models,
                         const Bounds& scene, int shadow_map_size, std::vector<LineVertex>& out) {
  if (!slot.dynamic_has_models) return;
  const Eigen::Matrix4d projection = MakeProjectorGl(p, shadow_map_size).shadow_projection;
  const Eigen::Matrix4d shadow_clip = projection * p.view;
  const Eigen::Matrix4d local_from_eye = p.view.inverse(), eye_from_clip = p.projection.inverse();
  const double far_m = VolumeFarM(p, scene, slot);
  const Viewport map{0, 0, shadow_map_size, shadow_map_size};
  for (const Bounds& b : models) {
    const std::array<Eigen::Vector3d, 8> corners = b.Corners();
    if (!VolumeMayBeVisible(corners, shadow_clip)) continue;
    double nearest = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& c : corners) nearest = std::min(nearest, -(p.view * c.homogeneous()).z());
    const std::optional<Viewport> rect = BoxesScreenRect({&b, 1}, shadow_clip, map);
    if (!rect) continue;
    const Eigen::Vector4d ndc = ModelNdcRect(p, *rect, shadow_map_size);
    const double near_m = std::clamp(nearest, p.near_m, far_m);
    // Cut where the static surface behind the model ends (issue 17): a surface point farther
    // along the rectangle is hidden from the projector by the static model already (no entry to
    // test), and a volume to the end of the frustum covered much of the view for each person.
    const double behind_m = StaticDeepestM(slot, *rect, projection) * 1.01 + 0.05;
    const double end_m = std::clamp(behind_m, near_m, far_m);
    AppendFrustumPiece(FrustumCorners(local_from_eye, eye_from_clip, ndc, near_m),
                       FrustumCorners(local_from_eye, eye_from_clip, ndc, end_m), out);
  }
}

}  // namespace

// Counts, in the stencil, the convex volumes (wound counter-clockwise from outside) that hold the
// surface already in the depth buffer: +1 for a back face behind the surface, -1 for a front face
// behind it, so a volume adds 1 exactly where its entry lies before the surface and its exit after
// (the eye inside it: no entry). Depth clamping keeps faces beyond the far plane (at depth 1,
// behind any surface); cleared pixels count nothing.
void ShadowVolumePass::ApplyState() {
  ResetPassState();
  glEnable(GL_DEPTH_CLAMP);
  glEnable(GL_SCISSOR_TEST);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_GREATER);
  glDepthMask(GL_FALSE);
  glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
  glEnable(GL_STENCIL_TEST);
  glStencilMask(kVolumeStencilBits);
  glStencilFunc(GL_ALWAYS, 0, 0xFF);
  glStencilOpSeparate(GL_BACK, GL_KEEP, GL_KEEP, GL_INCR_WRAP);
  glStencilOpSeparate(GL_FRONT, GL_KEEP, GL_KEEP, GL_DECR_WRAP);
}

absl::StatusOr<std::unique_ptr<ShadowVolumePass>> ShadowVolumePass::Create() {
  absl::StatusOr<Program> program =
      Program::Build("shaders/line.vert.glsl", "shaders/line.frag.glsl", "", {"u_clip_from_local"});
  if (!program.ok()) return program.status();
  return std::unique_ptr<ShadowVolumePass>(new ShadowVolumePass(*std::move(program)));
}

void ShadowVolumePass::Upload(const FrameContext& frame, const DynamicModels& dynamics) {
  std::vector<LineVertex> vertices;
  if (frame.options.dynamic_objects_cast_shadows) {
    for (const ProjectorPass& pass : frame.passes) {
      if (pass.retained) continue;
      AppendShadowVolumes(*pass.projector, frame.cameras.slots()[pass.layer].shadow, dynamics.model_bounds(),
                          frame.scene, frame.options.shadow_map_size, vertices);
    }
  }
  volumes_.Upload(vertices, GL_STREAM_DRAW);
}

void ShadowVolumePass::Mark(const View& view) const {
  glStencilMask(0xFF);
  glClearStencil(0);
  glClear(GL_STENCIL_BUFFER_BIT);
  if (volumes_.count() == 0) return;
  ApplyState();
  glUseProgram(program_.id);
  glUniformMatrix4fv(program_.u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
  volumes_.Draw(GL_TRIANGLES);
}

}  // namespace ave::viewer::internal
