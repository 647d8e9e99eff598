#include "viewer_client/render/passes/gbuffer_pass.h"

#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {

absl::Status GbufferTargets::Resize(int width, int height, const char* what) {
  color = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
  normal = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
  // Depth with a stencil (issue 17): the people's own pixels, marked when they are drawn over a
  // cached view, limit the projector passes that read this G-buffer (ProjectionPass::Accumulate).
  depth = MakeTexture2D(GL_DEPTH32F_STENCIL8, GL_DEPTH_STENCIL, GL_FLOAT_32_UNSIGNED_INT_24_8_REV, width, height);
  const absl::Status complete = AttachTextures(
      fbo, {{GL_COLOR_ATTACHMENT0, color}, {GL_COLOR_ATTACHMENT1, normal}, {GL_DEPTH_STENCIL_ATTACHMENT, depth}}, what);
  const GLenum gbuffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glDrawBuffers(2, gbuffers);
  return complete;
}

absl::StatusOr<std::unique_ptr<GbufferPass>> GbufferPass::Create(const RendererOptions& options) {
  absl::StatusOr<Program> program =
      Program::Build("shaders/gbuffer.vert.glsl", "shaders/gbuffer.frag.glsl", "",
                     {"u_clip_from_local", "u_sun_direction", "u_ambient", "u_diffuse", "u_sky_color"});
  if (!program.ok()) return program.status();
  return std::unique_ptr<GbufferPass>(new GbufferPass(options, *std::move(program)));
}

void GbufferPass::ApplyState() {
  ResetPassState();
  glEnable(GL_SCISSOR_TEST);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
}

void GbufferPass::Clear() {
  glClearColor(0, 0, 0, 0);
  glClearDepth(1.0);
  glClearStencil(0);
  glStencilMask(0xFF);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT | GL_STENCIL_BUFFER_BIT);
}

void GbufferPass::Draw(const View& view, const SceneLayers& layers, bool with_static, bool with_dynamic,
                       RenderStats& stats, bool mark_models) const {
  ApplyState();
  if (mark_models) {
    glEnable(GL_STENCIL_TEST);
    glStencilMask(kModelStencilBit);
    glStencilFunc(GL_ALWAYS, kModelStencilBit, kModelStencilBit);
    glStencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
  }
  glUseProgram(program_.id);
  const Uniforms& u = program_.u;
  glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
  const Eigen::Vector3f sun = options_.sun_direction.normalized();
  glUniform3f(u["u_sun_direction"], sun.x(), sun.y(), sun.z());
  glUniform1f(u["u_ambient"], options_.ambient);
  glUniform1f(u["u_diffuse"], options_.diffuse);
  glUniform3f(u["u_sky_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
  if (with_static) layers.statics.DrawChunks(view.projection * view.view, stats);
  // The static model is drawn from both sides (open terrain); models and sky are closed or seen
  // from inside: back faces culled.
  glEnable(GL_CULL_FACE);
  glCullFace(GL_BACK);
  if (with_dynamic) {
    layers.dynamics.Draw();
    if (layers.avatars.instance_count() > 0) {
      layers.avatars.Draw(view.projection * view.view, options_, options_.display.video_on_people);
      glUseProgram(program_.id);
    }
  }
  layers.sky.Draw(with_static && options_.display.sky);
}

}  // namespace ave::viewer::internal
