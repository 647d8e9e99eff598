#include "viewer_client/render/passes/shadow_maps.h"

#include <algorithm>
#include <optional>

#include <Eigen/LU>

#include "viewer_client/render/passes/projector_geometry.h"

namespace ave::viewer::internal {
namespace {

// Depth bias of the shadow pass, in addition to the normal offset of the projector shader: the
// slope term absorbs the depth change across one texel on grazing ground (paper section 8).
constexpr float kShadowSlopeBias = 1.5f;
constexpr float kShadowConstantBias = 2.0f;

}  // namespace

// Every fixed-function state change of the shadow pass: depth only, biased, no scissor.
void ShadowMaps::ApplyState() {
  ResetPassState();
  glDisable(GL_SCISSOR_TEST);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(kShadowSlopeBias, kShadowConstantBias);
  glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
}

bool ShadowMaps::Arrays::Ensure(int needed, int size, bool with_dynamic) {
  if (needed <= layers) return false;
  for (Texture* texture : {&static_array, &dynamic_array}) {
    if (texture == &dynamic_array && !with_dynamic) continue;
    if (*texture == 0) *texture = Texture::Create();
    glBindTexture(GL_TEXTURE_2D_ARRAY, *texture);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_DEPTH_COMPONENT32F, size, size, needed, 0, GL_DEPTH_COMPONENT, GL_FLOAT,
                 nullptr);
    // NEAREST: one depth compare per lookup; LINEAR (2x2 PCF) cost ~15% of the frame on llvmpipe.
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
  }
  layers = needed;
  return true;
}

absl::StatusOr<std::unique_ptr<ShadowMaps>> ShadowMaps::Create(const RendererOptions& options) {
  absl::StatusOr<Program> program =
      Program::Build("shaders/shadow.vert.glsl", "shaders/shadow.frag.glsl", "", {"u_clip_from_local"});
  if (!program.ok()) return program.status();
  return std::unique_ptr<ShadowMaps>(new ShadowMaps(options, *std::move(program)));
}

ShadowMaps::ShadowMaps(const RendererOptions& options, Program program)
    : options_(options), program_(std::move(program)) {
  clip_from_local_ = program_.u["u_clip_from_local"];
  src_fbo_ = Framebuffer::Create();
  dst_fbo_ = Framebuffer::Create();
  {
    FramebufferGuard guard;
    for (GLuint fbo : {GLuint{src_fbo_}, GLuint{dst_fbo_}}) {
      glBindFramebuffer(GL_FRAMEBUFFER, fbo);
      glDrawBuffer(GL_NONE);
      glReadBuffer(GL_NONE);
    }
  }
  live_.Ensure(1, options.shadow_map_size, options.dynamic_objects_cast_shadows);
}

void ShadowMaps::ReadExtent(const Eigen::Matrix4d& shadow_projection, ShadowSlot& slot) {
  const int size = options_.shadow_map_size;
  slot.sees_void = true;
  slot.deepest_tiles.clear();
  if (size > 2048) return;
  readback_.resize(static_cast<size_t>(size) * size);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, size, size, GL_DEPTH_COMPONENT, GL_FLOAT, readback_.data());
  float deepest = 0;
  bool void_seen = false;
  for (float d : readback_) {
    if (d >= 1.0f) {
      void_seen = true;
    } else {
      deepest = std::max(deepest, d);
    }
  }
  const Eigen::Vector4d eye = shadow_projection.inverse() * Eigen::Vector4d(0, 0, 2.0 * deepest - 1, 1);
  slot.visible_far_m = -eye.z() / eye.w();
  slot.sees_void = void_seen;
  SetDeepestTiles(readback_, size, slot);
}

absl::Status ShadowMaps::UpdateLayer(Arrays& arrays, int layer, ShadowSlot& slot, const Projector& p,
                                     bool with_dynamic, const StaticModel& statics, const DynamicModels& dynamics,
                                     const AvatarPass& avatars,
                                     bool& state_set, uint64_t& counter, RenderStats& stats) {
  const int size = options_.shadow_map_size;
  const ProjectorGl g = MakeProjectorGl(p, size);
  const GlMatrix& clip_from_local = g.shadow_clip_from_local;
  const bool static_dirty =
      !slot.valid || slot.clip_from_local != clip_from_local || slot.static_version != statics.version();
  const bool dynamic_dirty = with_dynamic && (static_dirty || slot.dynamic_version != dynamics.version());
  if (!static_dirty && !dynamic_dirty) return absl::OkStatus();
  const Eigen::Matrix4d shadow_clip = Eigen::Map<const Eigen::Matrix4f>(clip_from_local.data()).cast<double>();
  const std::vector<Bounds>& model_bounds = dynamics.model_bounds();
  const bool models_inside = with_dynamic && std::any_of(model_bounds.begin(), model_bounds.end(), [&](const Bounds& b) {
                               return VolumeMayBeVisible(b.Corners(), shadow_clip);
                             });
  if (!static_dirty && !slot.dynamic_has_models && !models_inside) {
    // No model was or is in this projector's view: its dynamic layer is still the static one.
    slot.dynamic_version = dynamics.version();
    return absl::OkStatus();
  }
  if (!state_set) {
    ApplyState();
    glViewport(0, 0, size, size);
    glUseProgram(program_.id);
    state_set = true;
  }
  glUniformMatrix4fv(clip_from_local_, 1, GL_FALSE, clip_from_local.data());
  glBindFramebuffer(GL_FRAMEBUFFER, src_fbo_);
  glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, arrays.static_array, 0, layer);
  if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "static shadow map"); !s.ok()) return s;
  if (static_dirty) {
    glClear(GL_DEPTH_BUFFER_BIT);
    statics.DrawChunks(shadow_clip, stats);
    ++counter;
    ReadExtent(g.shadow_projection, slot);
  }
  if (dynamic_dirty) {
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, dst_fbo_);
    glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, arrays.dynamic_array, 0, layer);
    if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "dynamic shadow map"); !s.ok()) return s;
    // Only where the models were or are does the dynamic layer differ from the static one: the
    // copy (a full-size blit costs llvmpipe a 1024^2 depth pass per projector) is limited to that.
    const Viewport full{0, 0, size, size};
    std::optional<Viewport> now;
    if (models_inside) now = BoxesScreenRect(model_bounds, shadow_clip, full);
    std::optional<Viewport> copy = static_dirty ? std::optional<Viewport>(full) : now;
    if (!static_dirty && slot.dynamic_has_models) copy = copy ? Union(*copy, slot.dynamic_rect) : slot.dynamic_rect;
    if (copy) {
      const Viewport& r = *copy;
      glBlitFramebuffer(r.x, r.y, r.x + r.width, r.y + r.height, r.x, r.y, r.x + r.width, r.y + r.height,
                        GL_DEPTH_BUFFER_BIT, GL_NEAREST);
    }
    dynamics.Draw();
    if (avatars.instance_count() > 0) {
      avatars.Draw(shadow_clip, options_, /*receive_video=*/true);  // depth only here
      glUseProgram(program_.id);
    }
    ++stats.dynamic_shadow_updates;
    slot.dynamic_has_models = now.has_value();
    slot.dynamic_rect = now.value_or(Viewport{});
  }
  slot.valid = true;
  slot.clip_from_local = clip_from_local;
  slot.static_version = statics.version();
  slot.dynamic_version = dynamics.version();
  return absl::OkStatus();
}

absl::Status ShadowMaps::Update(CameraSet& cameras, const StaticModel& statics, const DynamicModels& dynamics,
                                const AvatarPass& avatars, RenderStats& stats) {
  const int size = options_.shadow_map_size;
  const bool with_dynamic = options_.dynamic_objects_cast_shadows;
  const std::vector<Projector>& projectors = cameras.projectors();
  if (live_.Ensure(std::max<int>(1, static_cast<int>(projectors.size())), size, with_dynamic)) {
    for (LiveSlot& slot : cameras.slots()) slot.shadow.valid = false;
  }
  bool state_set = false;
  for (size_t i = 0; i < projectors.size(); ++i) {
    if (!cameras.LiveActive(i)) continue;
    if (absl::Status s = UpdateLayer(live_, static_cast<int>(i), cameras.slots()[i].shadow, projectors[i], with_dynamic,
                                     statics, dynamics, avatars, state_set, stats.shadow_map_renders, stats);
        !s.ok()) {
      return s;
    }
  }
  // Retained snapshots see the static model only: their shadow maps never need redoing for movers.
  std::vector<RetainedSnapshot>& retained = cameras.retained();
  int retained_needed = 0;
  for (size_t k = 0; k < retained.size(); ++k) {
    if (cameras.RetainedActive(retained[k])) retained_needed = static_cast<int>(k) + 1;
  }
  if (retained_needed > 0 && retained_.Ensure(retained_needed, size, false)) {
    for (RetainedSnapshot& r : retained) r.shadow.valid = false;
  }
  for (size_t k = 0; k < retained.size(); ++k) {
    RetainedSnapshot& r = retained[k];
    if (!cameras.RetainedActive(r)) continue;
    if (absl::Status s = UpdateLayer(retained_, static_cast<int>(k), r.shadow, r.projector, false, statics, dynamics,
                                     avatars, state_set, stats.retained_shadow_renders, stats);
        !s.ok()) {
      return s;
    }
  }
  return CheckGl("shadow maps");
}

}  // namespace ave::viewer::internal
