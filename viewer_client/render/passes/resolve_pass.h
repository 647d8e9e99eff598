#pragma once
// Internal to ave_render: the resolve pass. One full-screen triangle per view writes colour and
// depth into the caller's framebuffer from a G-buffer and the projectors' imagery: the working
// accumulation targets, or a view cache (its G-buffer, retained targets and per-pixel mapping
// sampled against the current video). Compiled per combination of inputs present (resolve.frag.glsl
// LIVE, RETAINED, CACHED, SHADOWED, MARK), so a view without video pays only for colour and depth.
#include <array>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/shadow_maps.h"
#include "viewer_client/render/passes/video_layers.h"

namespace ave::viewer::internal {

// Where a resolve reads from.
struct ResolveSource {
  GLuint color = 0, depth = 0, retained = 0, fade = 0;
  GLuint live = 0;     // the live accumulation (not cached)
  bool cached = false;  // live imagery through the view cache's mapping
  GLuint mapping = 0, normal = 0;  // cached: the mapping array, the cached G-buffer's normals
  double built_s = 0;  // cached: Clock::Now() when the retained targets were drawn
};

enum class ResolveMode {
  kPlain,
  // Cached entries tested against the live shadow maps with the dynamic models (needs a cached
  // source with live passes). kMarkEntries only sets kEntryStencilBit where some entry may be
  // hidden; kMarked draws where that bit is set, kInVolumes where the volume count
  // (ShadowVolumePass::Mark) is not 0.
  kMarkEntries,
  kMarked,
  kInVolumes,
  // The plain cached resolve with every entry tested as kInVolumes tests them, colour and depth on
  // every pixel: for a crowd, whose shadow volumes cost more to count than this (issue 17).
  kShadowedAll,
  // The plain resolve of a working G-buffer only where its depth is nearer than the bound
  // framebuffer's (depth test less): the models drawn over a cached view keep the cached resolve
  // around them (issue 17).
  kNearer,
};

class ResolvePass {
 public:
  // `video` and `shadows` must outlive the pass. with_cache: the CACHED variants too.
  static absl::StatusOr<std::unique_ptr<ResolvePass>> Create(const RendererOptions& options, bool with_cache,
                                                             const VideoLayers& video, const ShadowMaps& shadows);

  // `view` into the bound framebuffer, within the scissor box. drawn (not cached): the viewport
  // the source holds the view in (the view's own, or a reduced one at the same corner: scaled up).
  void Resolve(const FrameContext& frame, const View& view, bool any_live, bool any_retained,
               const ResolveSource& source, ResolveMode mode = ResolveMode::kPlain,
               const Viewport* drawn = nullptr) const;

 private:
  ResolvePass(const RendererOptions& options, const VideoLayers& video, const ShadowMaps& shadows)
      : options_(options), video_(video), shadows_(shadows) {}
  static void ApplyState(ResolveMode mode);
  // The shadow test's per-layer uniforms of the live passes whose shadow maps hold models.
  void BindShadowTest(const FrameContext& frame, const View& view, const Uniforms& u, GLuint normal) const;

  const RendererOptions& options_;
  const VideoLayers& video_;
  const ShadowMaps& shadows_;
  std::array<Program, 64> variants_;  // by bits: live 1, retained 2, cached 4, shadowed 8, mark 16, depth 32
  VertexArray empty_vao_ = VertexArray::Create();
};

}  // namespace ave::viewer::internal
