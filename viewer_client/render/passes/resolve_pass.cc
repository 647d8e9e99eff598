#include "viewer_client/render/passes/resolve_pass.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "model_store/geometry/camera.h"
#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/projection_pass.h"
#include "viewer_client/render/passes/shadow_volumes.h"

namespace ave::viewer::internal {

// Every fixed-function state change of the resolve. kPlain writes colour and depth (always).
// kMarkEntries: where some volume holds the surface, sets kEntryStencilBit where the fragment
// survives (the MARK variant discards pixels none of whose entries the models may hide).
// kMarked / kInVolumes: colour only where kMarkEntries set its bit (or Mark counted a volume); the
// shader writes no depth and never discards, so the stencil test runs before it and llvmpipe skips
// blocks that fail it. Without a stencil buffer the test passes everywhere: the same picture, at
// full cost.
void ResolvePass::ApplyState(ResolveMode mode) {
  ResetPassState();
  glEnable(GL_SCISSOR_TEST);
  switch (mode) {
    case ResolveMode::kPlain:
    case ResolveMode::kShadowedAll:
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_ALWAYS);
      glDepthMask(GL_TRUE);
      break;
    case ResolveMode::kNearer:
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
      break;
    case ResolveMode::kMarkEntries:
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      glEnable(GL_STENCIL_TEST);
      glStencilMask(kEntryStencilBit);
      glStencilFunc(GL_NOTEQUAL, kEntryStencilBit, kVolumeStencilBits);
      glStencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
      break;
    case ResolveMode::kMarked:
    case ResolveMode::kInVolumes:
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
      glEnable(GL_STENCIL_TEST);
      glStencilMask(0);
      if (mode == ResolveMode::kMarked) {
        glStencilFunc(GL_EQUAL, kEntryStencilBit, kEntryStencilBit);
      } else {
        glStencilFunc(GL_NOTEQUAL, 0, kVolumeStencilBits);
      }
      glStencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
      break;
  }
}

absl::StatusOr<std::unique_ptr<ResolvePass>> ResolvePass::Create(const RendererOptions& options, bool with_cache,
                                                                  const VideoLayers& video, const ShadowMaps& shadows) {
  std::unique_ptr<ResolvePass> pass(new ResolvePass(options, video, shadows));
  const std::string entries = "#define ENTRIES " + std::to_string(options.view_cache_entries) + "\n";
  for (int variant = 0; variant < (with_cache ? 64 : 4); ++variant) {
    if ((variant & 8) && (variant & 5) != 5) continue;
    if ((variant & 16) && !(variant & 8)) continue;
    if ((variant & 32) && (!(variant & 8) || (variant & 16))) continue;
    const std::string defines = std::string(variant & 1 ? "#define LIVE\n" : "") +
                                (variant & 2 ? "#define RETAINED\n" : "") + (variant & 4 ? "#define CACHED\n" : "") +
                                (variant & 8 ? "#define SHADOWED\n" : "") + (variant & 16 ? "#define MARK\n" : "") +
                                (variant & 32 ? "#define WITH_DEPTH\n" : "") +
                                entries + "#define MAX_PROJECTORS " + std::to_string(kMaxProjectors) + "\n";
    absl::StatusOr<Program> program =
        Program::Build("shaders/resolve.vert.glsl", "shaders/resolve.frag.glsl", defines,
                       {"u_gbuffer_color", "u_gbuffer_depth", "u_live", "u_retained", "u_fade", "u_clear_color",
                        "u_tint_by_age", "u_fade_scale", "u_mapping", "u_video", "u_last_wins", "u_gbuffer_normal",
                        "u_local_from_window", "u_shadow", "u_shadow_clip_from_local", "u_position_offset",
                        "u_model_uv", "u_source_origin", "u_source_scale"});
    if (!program.ok()) return program.status();
    pass->variants_[variant] = *std::move(program);
  }
  return pass;
}

void ResolvePass::Resolve(const FrameContext& frame, const View& view, bool any_live, bool any_retained,
                          const ResolveSource& source, ResolveMode mode, const Viewport* drawn) const {
  const bool shadowed = mode != ResolveMode::kPlain && mode != ResolveMode::kNearer;
  const bool mark = mode == ResolveMode::kMarkEntries;
  ApplyState(mode);
  const int variant = (any_live ? 1 : 0) + (any_retained ? 2 : 0) + (source.cached ? 4 : 0) + (shadowed ? 8 : 0) +
                      (mark ? 16 : 0) + (mode == ResolveMode::kShadowedAll ? 32 : 0);
  glUseProgram(variants_[variant].id);
  const Uniforms& u = variants_[variant].u;
  const Viewport& v = view.viewport;
  glUniform2f(u["u_source_origin"], static_cast<float>(v.x), static_cast<float>(v.y));
  glUniform2f(u["u_source_scale"], drawn ? static_cast<float>(drawn->width) / v.width : 1.0f,
              drawn ? static_cast<float>(drawn->height) / v.height : 1.0f);
  glUniform1i(u["u_gbuffer_color"], kGbufferColorUnit);
  glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
  glUniform1i(u["u_live"], kLiveUnit);
  glUniform1i(u["u_retained"], kRetainedUnit);
  glUniform1i(u["u_fade"], kFadeUnit);
  glUniform3f(u["u_clear_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
  glUniform1i(u["u_tint_by_age"], options_.display.tint_by_age ? 1 : 0);
  const double half_life = options_.display.retention_half_life_s;
  const double elapsed = source.cached ? std::max(0.0, frame.clock.Now() - source.built_s) : 0.0;
  glUniform1f(u["u_fade_scale"], half_life > 0 ? static_cast<float>(std::pow(0.5, elapsed / half_life)) : 0.0f);
  BindTexture(kGbufferColorUnit, GL_TEXTURE_2D, source.color);
  BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, source.depth);
  BindTexture(kRetainedUnit, GL_TEXTURE_2D, source.retained);
  BindTexture(kFadeUnit, GL_TEXTURE_2D, source.fade);
  if (source.cached) {
    glUniform1i(u["u_mapping"], kMappingUnit);
    glUniform1i(u["u_video"], kVideoUnit);
    glUniform1i(u["u_last_wins"], options_.display.overlap == OverlapPolicy::kLastWins ? 1 : 0);
    BindTexture(kMappingUnit, GL_TEXTURE_2D_ARRAY, source.mapping);
    BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, video_.live());
  } else {
    BindTexture(kLiveUnit, GL_TEXTURE_2D, source.live);
  }
  if (shadowed) BindShadowTest(frame, view, u, source.normal);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 3);
}

void ResolvePass::BindShadowTest(const FrameContext& frame, const View& view, const Uniforms& u, GLuint normal) const {
  std::vector<float> matrices(16 * kMaxProjectors, 0.0f), position_offset(4 * kMaxProjectors, 0.0f),
      model_uv(4 * kMaxProjectors, 0.0f);
  for (int l = 0; l < kMaxProjectors; ++l) model_uv[4 * l] = 1.0f;  // empty: u0 > u1
  for (const ProjectorPass& pass : frame.passes) {
    if (pass.retained) continue;
    const ShadowSlot& slot = frame.cameras.slots()[pass.layer].shadow;
    if (!slot.dynamic_has_models) continue;
    const ProjectorGl g = MakeProjectorGl(*pass.projector, options_.shadow_map_size);
    std::copy(g.shadow_clip_from_local.begin(), g.shadow_clip_from_local.end(), matrices.begin() + 16 * pass.layer);
    for (int k = 0; k < 3; ++k) position_offset[4 * pass.layer + k] = static_cast<float>(pass.projector->position[k]);
    position_offset[4 * pass.layer + 3] = g.normal_offset;
    const Eigen::Vector4f uv = ModelUvRect(*pass.projector, slot.dynamic_rect, options_.shadow_map_size,
                                           options_.video_layer_width, options_.video_layer_height);
    std::copy(uv.data(), uv.data() + 4, model_uv.begin() + 4 * pass.layer);
  }
  glUniformMatrix4fv(u["u_shadow_clip_from_local"], kMaxProjectors, GL_FALSE, matrices.data());
  glUniform4fv(u["u_position_offset"], kMaxProjectors, position_offset.data());
  glUniform4fv(u["u_model_uv"], kMaxProjectors, model_uv.data());
  glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(LocalFromWindow(view)).data());
  glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
  glUniform1i(u["u_shadow"], kShadowUnit);
  BindTexture(kGbufferNormalUnit, GL_TEXTURE_2D, normal);
  BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, shadows_.live_dynamic());
}

}  // namespace ave::viewer::internal
