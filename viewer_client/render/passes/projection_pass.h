#pragma once
// Internal to ave_render: the projector pass (paper sections 7-8, issue 7 deferred). Per view, each
// projector whose frustum meets it adds its video to accumulation targets in a screen-space pass
// over its frustum volume's back faces (or, combined_live_passes, up to kCombinedBatch live
// projectors in one full-screen pass scissored to their footprints), reading the G-buffer's
// normal and depth, weighted per pixel by the overlap policy and tested against its shadow map.
// Live imagery goes to target 0, retained snapshots to targets 1 (colour) and 2 (fade). The same
// shader with MAPPING writes the view cache's per-pixel projector entries instead.
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gbuffer_pass.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/shadow_maps.h"
#include "viewer_client/render/passes/video_layers.h"

namespace ave::viewer::internal {

// A local point (homogeneous) from (window x, y in framebuffer pixels, NDC z, 1) of the view.
Eigen::Matrix4d LocalFromWindow(const View& view);

class ProjectionPass {
 public:
  // `video` and `shadows` must outlive the pass. with_mapping: also the view cache's MAPPING
  // program (needs image load/store).
  static absl::StatusOr<std::unique_ptr<ProjectionPass>> Create(const RendererOptions& options, bool with_mapping,
                                                                const VideoLayers& video, const ShadowMaps& shadows);

  // The accumulation targets at width x height; `depth_stencil` (the working G-buffer's, the same
  // size) is attached for Accumulate's models_only stencil test.
  absl::Status Resize(int width, int height, GLuint depth_stencil);
  // The frame's frustum volumes, 36 vertices per FrameContext::passes entry in order.
  void UploadVolumes(const std::vector<LineVertex>& volumes) { volumes_.Upload(volumes, GL_STREAM_DRAW); }

  // The view's visible passes into the working accumulation targets (only those the passes write
  // are cleared), reading `gbuffer`, within the scissor box, or within each of `rects` (the
  // patches of a cached view: every pass draws all of them before the next pass, leaving the
  // scissor box at the last). models_only (needs the image load/store programs of Create's
  // with_mapping): the passes shade only where `gbuffer`, the working one, has kModelStencilBit
  // set (the targets are still cleared within the scissor box or rectangles).
  void Accumulate(const FrameContext& frame, const View& view, const ViewFrame& seen, const GbufferTargets& gbuffer,
                  const std::vector<Viewport>* rects = nullptr, bool models_only = false);
  // The view cache's mapping: the visible live passes' entries into `mapping` (image load/store,
  // a barrier between projectors), reading `gbuffer`.
  void DrawMapping(const FrameContext& frame, const View& view, const ViewFrame& seen, const GbufferTargets& gbuffer,
                   GLuint mapping);
  // The visible retained passes into draw buffers 1 and 2 of the bound accumulation framebuffer.
  void DrawRetained(const FrameContext& frame, const View& view, const ViewFrame& seen, const GbufferTargets& gbuffer);

  GLuint live() const { return live_; }
  GLuint retained() const { return retained_; }
  GLuint fade() const { return fade_; }

 private:
  ProjectionPass(const RendererOptions& options, const VideoLayers& video, const ShadowMaps& shadows)
      : options_(options), video_(video), shadows_(shadows), volumes_(/*with_normals=*/false, /*indexed=*/false) {}
  enum class State { kVolumes, kCombined };
  // With models_only_, the stencil test of Accumulate's models_only.
  void ApplyState(State state, bool blend) const;
  // The per-projector and combined programs, with early stencil tests while models_only_.
  const Program& projector() const { return models_only_ ? projector_models_ : projector_; }
  const Program& combined() const { return models_only_ ? combined_models_ : combined_; }
  // `program` bound with the uniforms every projector program takes (units, view, overlap policy).
  void UseProgram(const View& view, const Program& program) const;
  // UseProgram, and `program` reads the G-buffer's normal and depth.
  void BindInputs(const View& view, const Program& program, const GbufferTargets& gbuffer) const;
  void DrawCombinedLive(const FrameContext& frame, const View& view, const ViewFrame& seen, bool last_wins);
  // One pass over its frustum volume (vertices 36 * index ...) with `u`'s program bound.
  void DrawPass(const Uniforms& u, const ProjectorPass& pass, size_t index, bool last_wins, RenderStats& stats);
  void DrawRetainedPasses(const FrameContext& frame, const ViewFrame& seen);

  const RendererOptions& options_;
  const VideoLayers& video_;
  const ShadowMaps& shadows_;
  Program projector_, combined_, mapping_;
  Program projector_models_, combined_models_;  // EARLY_TESTS (with_mapping only)
  bool models_only_ = false;                    // within Accumulate(models_only = true)
  MeshBuffers volumes_;
  VertexArray empty_vao_ = VertexArray::Create();
  Framebuffer fbo_ = Framebuffer::Create();
  Texture live_, retained_, fade_;
};

}  // namespace ave::viewer::internal
