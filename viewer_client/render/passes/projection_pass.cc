#include "viewer_client/render/passes/projection_pass.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/LU>

#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {
namespace {

// Live projectors per combined pass (projector.frag.glsl COMBINED: BATCH); 48 floats of uniforms each.
constexpr int kCombinedBatch = 16;
// Retained weights are scaled by fade^kNewerWins so the newest snapshot dominates an overlap.
constexpr double kNewerWins = 16;

}  // namespace

Eigen::Matrix4d LocalFromWindow(const View& view) {
  const Viewport& v = view.viewport;
  Eigen::Matrix4d ndc_from_window = Eigen::Matrix4d::Identity();
  ndc_from_window(0, 0) = 2.0 / v.width;
  ndc_from_window(0, 3) = -1 - 2.0 * v.x / v.width;
  ndc_from_window(1, 1) = 2.0 / v.height;
  ndc_from_window(1, 3) = -1 - 2.0 * v.y / v.height;
  return (view.projection * view.view).inverse() * ndc_from_window;
}

// Every fixed-function state change of the projector pass. kVolumes: back faces of the frustum
// volume cover every pixel whose view ray meets the volume exactly once, with the eye inside or
// outside it; depth clamping keeps far faces beyond the view's far plane. kCombined: full-screen
// triangles. Both add (blend) or overwrite (last wins), scissored, no depth test.
void ProjectionPass::ApplyState(State state, bool blend) const {
  ResetPassState();
  if (models_only_) {
    glEnable(GL_STENCIL_TEST);
    glStencilMask(0);
    glStencilFunc(GL_EQUAL, kModelStencilBit, kModelStencilBit);
    glStencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
  }
  if (state == State::kVolumes) {
    glEnable(GL_CULL_FACE);
    glCullFace(GL_FRONT);
    glEnable(GL_DEPTH_CLAMP);
  }
  glEnable(GL_SCISSOR_TEST);
  glDisable(GL_DEPTH_TEST);
  glDepthMask(GL_FALSE);
  if (blend) {
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE);
  }
}

absl::StatusOr<std::unique_ptr<ProjectionPass>> ProjectionPass::Create(const RendererOptions& options,
                                                                        bool with_mapping, const VideoLayers& video,
                                                                        const ShadowMaps& shadows) {
  std::unique_ptr<ProjectionPass> pass(new ProjectionPass(options, video, shadows));
  const std::initializer_list<const char*> projector_names = {
      "u_gbuffer_normal", "u_gbuffer_depth", "u_view_clip_from_local", "u_local_from_window",
      "u_clip_from_local", "u_shadow_clip_from_local", "u_shadow_widen",
      "u_projector_position", "u_pinhole", "u_k1_k2_p1_p2", "u_k3", "u_distorted", "u_layer", "u_normal_offset",
      "u_feather", "u_best_view", "u_last_wins", "u_fade", "u_weight_scale", "u_video", "u_shadow", "u_mapping"};
  absl::StatusOr<Program> projector =
      Program::Build("shaders/projector.vert.glsl", "shaders/projector.frag.glsl", "", projector_names);
  if (!projector.ok()) return projector.status();
  pass->projector_ = *std::move(projector);
  absl::StatusOr<Program> combined =
      Program::Build("shaders/resolve.vert.glsl", "shaders/projector.frag.glsl",
                     "#define COMBINED\n#define BATCH " + std::to_string(kCombinedBatch) + "\n",
                     {"u_gbuffer_normal", "u_gbuffer_depth", "u_local_from_window", "u_feather", "u_best_view",
                      "u_last_wins", "u_weight_scale", "u_video", "u_shadow", "u_count", "u_clips", "u_shadow_clips",
                      "u_pinholes", "u_distortions", "u_position_layers", "u_extras"});
  if (!combined.ok()) return combined.status();
  pass->combined_ = *std::move(combined);
  if (with_mapping) {
    const std::string defines = "#extension GL_ARB_shader_image_load_store : require\n#define MAPPING\n#define ENTRIES " +
                                std::to_string(options.view_cache_entries) + "\n";
    absl::StatusOr<Program> mapping =
        Program::Build("shaders/projector.vert.glsl", "shaders/projector.frag.glsl", defines, projector_names);
    if (!mapping.ok()) return mapping.status();
    pass->mapping_ = *std::move(mapping);
    const std::string early = "#extension GL_ARB_shader_image_load_store : require\n#define EARLY_TESTS\n";
    absl::StatusOr<Program> projector_models =
        Program::Build("shaders/projector.vert.glsl", "shaders/projector.frag.glsl", early, projector_names);
    if (!projector_models.ok()) return projector_models.status();
    pass->projector_models_ = *std::move(projector_models);
    absl::StatusOr<Program> combined_models =
        Program::Build("shaders/resolve.vert.glsl", "shaders/projector.frag.glsl",
                       early + "#define COMBINED\n#define BATCH " + std::to_string(kCombinedBatch) + "\n",
                       {"u_gbuffer_normal", "u_gbuffer_depth", "u_local_from_window", "u_feather", "u_best_view",
                        "u_last_wins", "u_weight_scale", "u_video", "u_shadow", "u_count", "u_clips",
                        "u_shadow_clips", "u_pinholes", "u_distortions", "u_position_layers", "u_extras"});
    if (!combined_models.ok()) return combined_models.status();
    pass->combined_models_ = *std::move(combined_models);
  }
  return pass;
}

absl::Status ProjectionPass::Resize(int width, int height, GLuint depth_stencil) {
  live_ = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
  retained_ = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
  fade_ = MakeTexture2D(GL_R32F, GL_RED, GL_FLOAT, width, height);
  // The working G-buffer's depth-stencil, for Accumulate's models_only stencil test. The passes
  // sample its depth while it is attached, but never write it (depth test off, stencil mask 0):
  // no texel is both written and read, so no feedback loop (OpenGL 4.5, 9.3.1).
  return AttachTextures(fbo_,
                        {{GL_COLOR_ATTACHMENT0, live_},
                         {GL_COLOR_ATTACHMENT1, retained_},
                         {GL_COLOR_ATTACHMENT2, fade_},
                         {GL_DEPTH_STENCIL_ATTACHMENT, depth_stencil}},
                        "projector accumulation");
}

void ProjectionPass::UseProgram(const View& view, const Program& program) const {
  glUseProgram(program.id);
  const Uniforms& u = program.u;
  glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
  glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
  glUniform1i(u["u_video"], kVideoUnit);
  glUniform1i(u["u_shadow"], kShadowUnit);
  glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(LocalFromWindow(view)).data());
  glUniform1f(u["u_feather"], static_cast<float>(options_.display.seam_feather));
  glUniform1i(u["u_best_view"], options_.display.overlap == OverlapPolicy::kBestView ? 1 : 0);
}

void ProjectionPass::BindInputs(const View& view, const Program& program, const GbufferTargets& gbuffer) const {
  UseProgram(view, program);
  glUniformMatrix4fv(program.u["u_view_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
  BindTexture(kGbufferNormalUnit, GL_TEXTURE_2D, gbuffer.normal);
  BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, gbuffer.depth);
}

void ProjectionPass::Accumulate(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                const GbufferTargets& gbuffer, const std::vector<Viewport>* rects, bool models_only) {
  // Within the scissor box, or within each rectangle in turn (one framebuffer binding for all).
  auto each = [rects](auto&& draw) {
    if (rects == nullptr) return draw();
    for (const Viewport& r : *rects) {
      glScissor(r.x, r.y, r.width, r.height);
      draw();
    }
  };
  const bool last_wins = options_.display.overlap == OverlapPolicy::kLastWins;
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  // Only the targets this view's passes write are cleared, and only those the resolve reads.
  const GLenum none = GL_NONE;
  const GLenum all_accum[] = {seen.any_live ? GLenum{GL_COLOR_ATTACHMENT0} : none,
                              seen.any_retained ? GLenum{GL_COLOR_ATTACHMENT1} : none,
                              seen.any_retained ? GLenum{GL_COLOR_ATTACHMENT2} : none};
  glDrawBuffers(3, all_accum);
  GbufferPass::ApplyState();
  if (seen.any_live || seen.any_retained) each([] { glClear(GL_COLOR_BUFFER_BIT); });
  models_only_ = models_only && projector_models_.id != 0;
  BindInputs(view, projector(), gbuffer);
  BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, video_.live());
  BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY,
              options_.dynamic_objects_cast_shadows ? shadows_.live_dynamic() : shadows_.live_static());
  const GLenum live_buffers[] = {GL_COLOR_ATTACHMENT0, GL_NONE};
  glDrawBuffers(2, live_buffers);
  ApplyState(State::kVolumes, /*blend=*/!last_wins);
  if (options_.combined_live_passes) {
    each([&] { DrawCombinedLive(frame, view, seen, last_wins); });
  } else {
    for (size_t k = 0; k < frame.passes.size(); ++k) {
      if (!seen.visible[k] || frame.passes[k].retained) continue;
      each([&] { DrawPass(projector().u, frame.passes[k], k, last_wins, frame.stats); });
    }
  }
  if (seen.any_retained) each([&] { DrawRetained(frame, view, seen, gbuffer); });
  models_only_ = false;
}

void ProjectionPass::DrawRetained(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                  const GbufferTargets& gbuffer) {
  BindInputs(view, projector(), gbuffer);
  DrawRetainedPasses(frame, seen);
}

void ProjectionPass::DrawRetainedPasses(const FrameContext& frame, const ViewFrame& seen) {
  BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, video_.retained());
  BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, shadows_.retained_static());
  const GLenum retained_buffers[] = {GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
  glDrawBuffers(2, retained_buffers);
  ApplyState(State::kVolumes, /*blend=*/true);
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    if (seen.visible[k] && frame.passes[k].retained) DrawPass(projector().u, frame.passes[k], k, false, frame.stats);
  }
}

void ProjectionPass::DrawMapping(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                 const GbufferTargets& gbuffer, GLuint mapping) {
  BindInputs(view, mapping_, gbuffer);
  BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, shadows_.live_static());
  glBindImageTexture(kMappingImageUnit, mapping, 0, GL_TRUE, 0, GL_READ_WRITE, GL_RGBA32F);
  glUniform1i(mapping_.u["u_mapping"], static_cast<GLint>(kMappingImageUnit));
  ApplyState(State::kVolumes, /*blend=*/false);
  const bool last_wins = options_.display.overlap == OverlapPolicy::kLastWins;
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    if (!seen.visible[k] || frame.passes[k].retained) continue;
    DrawPass(mapping_.u, frame.passes[k], k, last_wins, frame.stats);
    glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
  }
  glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
}

void ProjectionPass::DrawPass(const Uniforms& u, const ProjectorPass& pass, size_t index, bool last_wins,
                              RenderStats& stats) {
  const Projector& p = *pass.projector;
  const ProjectorGl g = MakeProjectorGl(p, options_.shadow_map_size);
  glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, g.clip_from_local.data());
  glUniformMatrix4fv(u["u_shadow_clip_from_local"], 1, GL_FALSE, g.shadow_clip_from_local.data());
  glUniform1f(u["u_shadow_widen"], static_cast<float>(1 / DistortionMargin(p)));
  glUniform3f(u["u_projector_position"], static_cast<float>(p.position.x()), static_cast<float>(p.position.y()),
              static_cast<float>(p.position.z()));
  glUniform4fv(u["u_pinhole"], 1, g.pinhole);
  glUniform4f(u["u_k1_k2_p1_p2"], g.distortion[0], g.distortion[1], g.distortion[2], g.distortion[3]);
  glUniform1f(u["u_k3"], g.distortion[4]);
  glUniform1i(u["u_distorted"], g.distorted ? 1 : 0);
  glUniform1f(u["u_layer"], static_cast<float>(pass.layer));
  glUniform1f(u["u_normal_offset"], g.normal_offset);
  glUniform1i(u["u_last_wins"], last_wins && !pass.retained ? 1 : 0);
  glUniform1f(u["u_fade"], pass.fade);
  glUniform1f(u["u_weight_scale"], pass.retained ? static_cast<float>(std::pow(pass.fade, kNewerWins)) : 1.0f);
  volumes_.Draw(GL_TRIANGLES, static_cast<GLint>(36 * index), 36);
  ++stats.projector_passes;
}

void ProjectionPass::DrawCombinedLive(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                      bool last_wins) {
  GLint box[4];
  glGetIntegerv(GL_SCISSOR_BOX, box);
  const Viewport scissor{box[0], box[1], box[2], box[3]};
  const Eigen::Matrix4d clip_from_local = view.projection * view.view;
  std::vector<std::pair<const ProjectorPass*, Viewport>> reach;
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    if (!seen.visible[k] || frame.passes[k].retained) continue;
    std::vector<Eigen::Vector4d> corners;
    for (const Eigen::Vector3d& c : frame.passes[k].corners) corners.push_back(c.homogeneous());
    const std::optional<Viewport> rect = ScreenRect(corners, clip_from_local, view.viewport);
    if (rect && Overlap(*rect, scissor)) reach.emplace_back(&frame.passes[k], Intersection(*rect, scissor));
  }
  if (reach.empty()) return;
  ApplyState(State::kCombined, /*blend=*/!last_wins);
  UseProgram(view, combined());
  const Uniforms& u = combined().u;
  glUniform1i(u["u_last_wins"], last_wins ? 1 : 0);
  glUniform1f(u["u_weight_scale"], 1.0f);
  glBindVertexArray(empty_vao_);
  for (size_t first = 0; first < reach.size(); first += kCombinedBatch) {
    const size_t count = std::min<size_t>(kCombinedBatch, reach.size() - first);
    std::vector<float> clips(16 * count), shadow_clips(16 * count), pinholes(4 * count), distortions(4 * count),
        position_layers(4 * count), extras(4 * count);
    Viewport area = reach[first].second;
    for (size_t k = 0; k < count; ++k) {
      const auto& [pass, rect] = reach[first + k];
      area = Union(area, rect);
      const Projector& p = *pass->projector;
      const ProjectorGl g = MakeProjectorGl(p, options_.shadow_map_size);
      std::copy(g.clip_from_local.begin(), g.clip_from_local.end(), clips.begin() + 16 * k);
      std::copy(g.shadow_clip_from_local.begin(), g.shadow_clip_from_local.end(), shadow_clips.begin() + 16 * k);
      std::copy(g.pinhole, g.pinhole + 4, pinholes.begin() + 4 * k);
      std::copy(g.distortion, g.distortion + 4, distortions.begin() + 4 * k);
      for (int i = 0; i < 3; ++i) position_layers[4 * k + i] = static_cast<float>(p.position[i]);
      position_layers[4 * k + 3] = static_cast<float>(pass->layer);
      const float e[4] = {static_cast<float>(1 / DistortionMargin(p)), g.distortion[4], g.distorted ? 1.0f : 0.0f,
                          g.normal_offset};
      std::copy(e, e + 4, extras.begin() + 4 * k);
    }
    const GLsizei n = static_cast<GLsizei>(count);
    glUniform1i(u["u_count"], n);
    glUniformMatrix4fv(u["u_clips"], n, GL_FALSE, clips.data());
    glUniformMatrix4fv(u["u_shadow_clips"], n, GL_FALSE, shadow_clips.data());
    glUniform4fv(u["u_pinholes"], n, pinholes.data());
    glUniform4fv(u["u_distortions"], n, distortions.data());
    glUniform4fv(u["u_position_layers"], n, position_layers.data());
    glUniform4fv(u["u_extras"], n, extras.data());
    glScissor(area.x, area.y, area.width, area.height);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    frame.stats.projector_passes += count;
  }
  glScissor(scissor.x, scissor.y, scissor.width, scissor.height);
}

}  // namespace ave::viewer::internal
