#pragma once
// Internal to ave_render: the G-buffer pass (issue 7, deferred). Per view, the static model (its
// visible chunks), the dynamic models and the sky go into a G-buffer: shaded colour (alpha: the
// kind of surface), packed normal, depth. The working targets are framebuffer-sized; the view
// cache keeps a second set (GbufferTargets) for still views.
#include <memory>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "viewer_client/render/passes/avatar_pass.h"
#include "viewer_client/render/passes/dynamic_models.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/sky.h"
#include "viewer_client/render/passes/static_model.h"

namespace ave::viewer::internal {

// Stencil bit of a G-buffer where a dynamic model or avatar is the nearest surface: set when they
// are drawn with mark_models (GbufferPass::Draw), cleared with the G-buffer (GbufferPass::Clear).
inline constexpr GLuint kModelStencilBit = 0x01;

// A G-buffer: colour (attachment 0), normal (1) and depth-stencil textures on one framebuffer.
struct GbufferTargets {
  Framebuffer fbo = Framebuffer::Create();
  Texture color, normal, depth;

  // (Re)allocates the textures at width x height; `what` names the target in errors.
  absl::Status Resize(int width, int height, const char* what);
};

// What the G-buffer pass draws.
struct SceneLayers {
  const StaticModel& statics;
  const DynamicModels& dynamics;
  const AvatarPass& avatars;  // drawn with the dynamic models (issue 17)
  const Sky& sky;
};

class GbufferPass {
 public:
  static absl::StatusOr<std::unique_ptr<GbufferPass>> Create(const RendererOptions& options);

  absl::Status Resize(int width, int height) { return working_.Resize(width, height, "G-buffer"); }
  // Binds the working G-buffer for drawing.
  void Bind() const { glBindFramebuffer(GL_FRAMEBUFFER, working_.fbo); }
  // The bound framebuffer's colour, depth and stencil cleared within the scissor box (0, 1, 0).
  static void Clear();
  // The static model and sky (with_static) and the dynamic models (with_dynamic) of `view` into
  // the bound G-buffer, within the scissor box. mark_models: kModelStencilBit set where they are drawn.
  void Draw(const View& view, const SceneLayers& layers, bool with_static, bool with_dynamic, RenderStats& stats,
            bool mark_models = false) const;

  const GbufferTargets& working() const { return working_; }
  // The state a G-buffer is drawn and cleared in: scissored, depth tested (less) and written.
  static void ApplyState();

 private:
  GbufferPass(const RendererOptions& options, Program program) : options_(options), program_(std::move(program)) {}

  const RendererOptions& options_;
  Program program_;
  GbufferTargets working_;
};

}  // namespace ave::viewer::internal
