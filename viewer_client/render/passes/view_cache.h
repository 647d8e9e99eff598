#pragma once
// Internal to ave_render: the view cache's targets and bookkeeping (RendererOptions::view_cache,
// renderer.h "Still views"). Framebuffer-sized and shared by views that do not overlap: the static
// G-buffer, the retained accumulation and view_cache_entries mapping layers (live projector entries
// per pixel). The orchestrator (renderer.cc) decides per view whether to build, reuse or bypass it.
#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gbuffer_pass.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/resolve_pass.h"

namespace ave::viewer::internal {

// What a view's cached G-buffer and mapping were built from (exact comparison: any change rebuilds).
struct ViewCache {
  bool valid = false;
  Viewport viewport;
  std::vector<double> signature;
  std::vector<double> last_signature;  // of the view's previous frame, cached or not
  // The static G-buffer in the cache textures (under `viewport`) was drawn for these view inputs
  // (StaticSignature): still usable when only projectors changed and the mapping is not.
  std::vector<double> static_signature;
  bool static_valid = false;
  double built_s = 0;  // Clock::Now() when the retained targets were drawn
  bool any_live = false, any_retained = false;
  std::vector<Viewport> patches;  // rectangles drawn exactly in the last frame (working G-buffer)
  uint64_t last_frame = 0;        // RenderStats::frames after the Render that last drew the view
};

class ViewCachePass {
 public:
  // supported: the context has OpenGL 4.3 (image load/store, copy image).
  ViewCachePass(const RendererOptions& options, bool supported) : options_(options), supported_(supported) {}

  bool On() const { return options_.view_cache && supported_; }
  // Reallocates the targets (none while off) and forgets every view's cache.
  absl::Status Resize(int width, int height);

  // Everything a view's cached G-buffer, mapping and retained targets depend on. Video content is
  // not in it (the mapping is sampled against the current frames), nor the dynamic models
  // (drawn exactly on top), nor the retained fade (scaled in the resolve).
  std::vector<double> Signature(const FrameContext& frame, const View& view, const ViewFrame& seen) const;
  // The part of Signature that is the view's own (what its static G-buffer depends on, and the
  // display options).
  std::vector<double> StaticSignature(const FrameContext& frame, const View& view) const;

  // The cache of the view at `slot` of Render's views (grown to `views`).
  ViewCache& Entry(size_t slot, size_t views);
  // Drops caches of views beyond `views`; forgets the cache of the view at `slot`.
  void Trim(size_t views);
  void Forget(size_t slot);
  // The cache textures under `viewport` now hold the view at `slot`: other views' caches there are lost.
  void Claim(size_t slot, const Viewport& viewport);
  const std::vector<ViewCache>& entries() const { return entries_; }

  // Build steps (ViewCache.any_live / any_retained say which): the static G-buffer bound and
  // cleared, then the mapping cleared and the retained targets bound (cleared) for drawing.
  void BeginStatic();
  void BeginProjectors(bool any_live, bool any_retained);

  ResolveSource Source(const ViewCache& cache) const;
  // The static G-buffer under `from` into `working` under `to` (the same corner, maybe smaller:
  // nearest), colour, normal and depth; leaves `working` bound.
  void CopyStatic(const Viewport& from, const Viewport& to, const GbufferTargets& working) const;
  // The cached G-buffer under `rect` into `working` at the same place.
  void CopyRect(const Viewport& rect, const GbufferTargets& working) const;

  const GbufferTargets& gbuffer() const { return gbuffer_; }
  GLuint mapping() const { return mapping_; }

 private:
  const RendererOptions& options_;
  const bool supported_;
  GbufferTargets gbuffer_;
  Framebuffer accum_fbo_ = Framebuffer::Create(), mapping_fbo_ = Framebuffer::Create();
  Texture retained_, fade_, mapping_;
  std::vector<ViewCache> entries_;  // by the view's index in Render's views
};

}  // namespace ave::viewer::internal
