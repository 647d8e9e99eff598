#include "viewer_client/render/renderer.h"

// The orchestrator (STYLE habit 6): Renderer::Impl owns the scene layers, the cameras and one
// object per pass (passes/*.h), and Impl::Render draws a frame top to bottom by calling them in
// order. Each pass owns its GL objects and sets its own GL state; what passes share is in the
// FrameContext (the whole Render call) and ViewFrame (one view) of passes/frame.h.
//
// A new layer (avatars, a point cloud, replay) is a new pass: a class in passes/ with a static
// Create (programs, StatusOr), GL objects held by gl_util.h handles, an ApplyState that starts from
// ResetPassState(), and a Draw taking (const FrameContext&, const View&, const ViewFrame&). It is
// a member of Impl, created in Renderer::Create, fed by a Renderer::Set... method, and called at
// its place in Impl::Render (or, for what lands in the G-buffer, from DrawViewExact and the model
// rectangles of DrawViewCached, beside GbufferPass::Draw).
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <utility>

#include <Eigen/LU>

#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/depth_readback.h"
#include "viewer_client/render/passes/dynamic_models.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gbuffer_pass.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/line_pass.h"
#include "viewer_client/render/passes/point_pass.h"
#include "viewer_client/render/passes/projection_pass.h"
#include "viewer_client/render/passes/resolve_pass.h"
#include "viewer_client/render/passes/shadow_maps.h"
#include "viewer_client/render/passes/shadow_volumes.h"
#include "viewer_client/render/passes/sky.h"
#include "viewer_client/render/passes/static_model.h"
#include "viewer_client/render/passes/video_layers.h"
#include "viewer_client/render/passes/view_cache.h"

namespace ave::viewer {

using internal::CameraSet;
using internal::CheckGl;
using internal::Clock;
using internal::DynamicModels;
using internal::FrameContext;
using internal::FramebufferGuard;
using internal::GbufferPass;
using internal::LinePass;
using internal::MatricesFinite;
using internal::PointPass;
using internal::ProjectionPass;
using internal::ResolveMode;
using internal::ResolvePass;
using internal::ResolveSource;
using internal::SceneLayers;
using internal::ShadowMaps;
using internal::ShadowVolumePass;
using internal::Sky;
using internal::StaticModel;
using internal::VideoLayers;
using internal::ViewCache;
using internal::ViewCachePass;
using internal::ViewFrame;

// Dynamic models over which a cached view's shadow test runs on every pixel (kShadowedAll) instead
// of within their shadow volumes.
constexpr size_t kCrowdModels = 24;
// Side of the squares that the model rectangles over a cached view are drawn in.
constexpr int kPatchTilePixels = 8;

struct Renderer::Impl {
  Impl(const RendererOptions& o, bool cache_supported)
      : options(o), sky(options), video(options), cameras(options, clock), cache(options, cache_supported) {}

  absl::Status Render(const std::vector<View>& views, int width, int height);

  RendererOptions options;  // passes keep a reference: SetDisplayOptions changes `display` here
  Clock clock;
  RenderStats stats;
  // What is drawn.
  StaticModel statics;
  DynamicModels dynamics;
  Sky sky;
  VideoLayers video;
  CameraSet cameras;
  // The passes, in the order a frame draws them.
  std::unique_ptr<ShadowMaps> shadows;
  std::unique_ptr<GbufferPass> gbuffer;
  std::unique_ptr<internal::AvatarPass> avatars;  // issue 17: instanced, with the dynamic models
  std::unique_ptr<ProjectionPass> projection;
  std::unique_ptr<ShadowVolumePass> shadow_volumes;
  ViewCachePass cache;
  std::unique_ptr<ResolvePass> resolve;
  std::unique_ptr<PointPass> points;
  std::unique_ptr<LinePass> lines;
  int width = 0, height = 0;  // of the targets
  // Views of the last Render drawn at reduced resolution: (viewport, the part of it drawn into).
  std::vector<std::pair<Viewport, Viewport>> reduced_views;

 private:
  absl::Status EnsureTargets(int w, int h);
  // The projector passes of the frame and the volumes the projector and shadow-volume passes draw.
  FrameContext BeginFrame();
  // Which of the frame's passes the view may see.
  ViewFrame SeenBy(const FrameContext& frame, const View& view, GLuint target);
  // A view drawn in full: its working G-buffer, projector passes and resolve.
  void DrawViewExact(const FrameContext& frame, const View& view, const ViewFrame& seen, double scale = 1,
                     bool static_from_cache = false);
  // A still view from its cache, with the rectangles around dynamic models drawn exactly.
  void DrawViewCached(const FrameContext& frame, const std::vector<View>& views, size_t slot, const ViewFrame& seen);
  void BuildViewCache(const FrameContext& frame, const View& view, const ViewFrame& seen, ViewCache& entry);
  // The projector passes of `view` (the working G-buffer holds it) and its resolve into the
  // target, within the scissor box (or each of `rects`). output: the view as shown when `view` is
  // a reduced copy of it.
  void AccumulateAndResolve(const FrameContext& frame, const View& view, const ViewFrame& seen,
                            const View* output = nullptr, const std::vector<Viewport>* rects = nullptr);
  double MovingViewScale(const FrameContext& frame, const ViewFrame& seen) const;
  std::vector<Viewport> ModelRects(const View& view) const;
  SceneLayers layers() const { return SceneLayers{statics, dynamics, *avatars, sky}; }
};

absl::Status Renderer::Impl::Render(const std::vector<View>& views, int w, int h) {
  FramebufferGuard guard;
  const GLuint target = guard.draw();
  const bool target_depth = internal::DrawFramebufferHasDepth();
  if (absl::Status s = EnsureTargets(w, h); !s.ok()) return s;
  // Shadow maps, only where a projector's pose or the geometry changed.
  if (absl::Status s = shadows->Update(cameras, statics, dynamics, *avatars, stats); !s.ok()) return s;
  // The frame's projector passes, their frustum volumes and the models' shadow volumes.
  const FrameContext frame = BeginFrame();
  reduced_views.clear();
  cache.Trim(views.size());
  for (size_t slot = 0; slot < views.size(); ++slot) {
    const View& view = views[slot];
    const Viewport& v = view.viewport;
    glViewport(v.x, v.y, v.width, v.height);
    glScissor(v.x, v.y, v.width, v.height);
    ViewFrame seen = SeenBy(frame, view, target);
    seen.target_depth = target_depth;
    // Views that share pixels with another view of this call cannot keep a cache (shared targets).
    bool cached = cache.On();
    for (size_t k = 0; k < views.size() && cached; ++k) cached = k == slot || !internal::Overlap(views[k].viewport, v);
    if (cached) {
      DrawViewCached(frame, views, slot, seen);  // resolve from the cache, models drawn exactly
    } else {
      cache.Forget(slot);
      DrawViewExact(frame, view, seen);  // G-buffer, projector passes, resolve
    }
    points->Draw(frame, view, seen);  // point cloud, depth tested against the resolved scene
    lines->Draw(view, cameras);       // frustums and paths on top
  }
  glBindVertexArray(0);
  glUseProgram(0);
  ++stats.frames;
  return CheckGl("Render");
}

absl::Status Renderer::Impl::EnsureTargets(int w, int h) {
  if (w == width && h == height) return absl::OkStatus();
  if (absl::Status s = gbuffer->Resize(w, h); !s.ok()) return s;
  if (absl::Status s = projection->Resize(w, h, gbuffer->working().depth); !s.ok()) return s;
  width = w;
  height = h;
  if (absl::Status s = cache.Resize(w, h); !s.ok()) return s;
  return CheckGl("render targets");
}

FrameContext Renderer::Impl::BeginFrame() {
  FrameContext frame{options, clock, stats, cameras, width, height, statics.version(), statics.bounds(), {}};
  if (!dynamics.bounds().empty()) {
    frame.scene.Add(dynamics.bounds().lo);
    frame.scene.Add(dynamics.bounds().hi);
  }
  sky.AddTo(frame.scene, options.display.sky);
  std::vector<internal::LineVertex> volumes;
  frame.passes = cameras.Passes(frame.scene, volumes);
  projection->UploadVolumes(volumes);
  shadow_volumes->Upload(frame, dynamics);
  return frame;
}

ViewFrame Renderer::Impl::SeenBy(const FrameContext& frame, const View& view, GLuint target) {
  ViewFrame seen;
  seen.target = target;
  seen.visible.resize(frame.passes.size());
  const Eigen::Matrix4d clip_from_local = view.projection * view.view;
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    seen.visible[k] = internal::VolumeMayBeVisible(frame.passes[k].corners, clip_from_local);
    if (!seen.visible[k]) ++stats.projectors_culled;
    (frame.passes[k].retained ? seen.any_retained : seen.any_live) |= static_cast<bool>(seen.visible[k]);
  }
  return seen;
}

// scale > 1 (a moving view, MovingViewScale): drawn at that fraction of the viewport's width and
// height and scaled up in the resolve; reduced_views records it for ReadLinearDepth.
// static_from_cache: the view's static G-buffer is taken (scaled, nearest) from its view cache
// instead of drawn: only projectors changed (a turning camera), the view did not.
void Renderer::Impl::DrawViewExact(const FrameContext& frame, const View& view, const ViewFrame& seen, double scale,
                                   bool static_from_cache) {
  View drawn = view;
  Viewport& d = drawn.viewport;
  d.width = std::max(1, static_cast<int>(std::ceil(view.viewport.width / scale)));
  d.height = std::max(1, static_cast<int>(std::ceil(view.viewport.height / scale)));
  const bool smaller = d.width != view.viewport.width || d.height != view.viewport.height;
  glViewport(d.x, d.y, d.width, d.height);
  glScissor(d.x, d.y, d.width, d.height);
  gbuffer->Bind();
  GbufferPass::ApplyState();
  if (static_from_cache) {
    cache.CopyStatic(view.viewport, d, gbuffer->working());
    ++stats.views_static_from_cache;
  } else {
    GbufferPass::Clear();
  }
  gbuffer->Draw(drawn, layers(), /*with_static=*/!static_from_cache, /*with_dynamic=*/true, stats);
  AccumulateAndResolve(frame, drawn, seen, smaller ? &view : nullptr);
  if (smaller) reduced_views.push_back({view.viewport, d});
  ++stats.views_uncached;
  if (smaller) ++stats.views_reduced;
}

void Renderer::Impl::AccumulateAndResolve(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                          const View* output, const std::vector<Viewport>* rects) {
  // The rectangles of a cached view (issue 17): the projector passes shade only the models' own
  // pixels (marked in the G-buffer's stencil), and the resolve writes only where the working
  // depth is nearer than the cached view's already in the target: around the models the cached
  // resolve stays.
  // Without a depth buffer in the target, the rectangles are resolved in full.
  const bool models_only = rects != nullptr && seen.target_depth;
  projection->Accumulate(frame, view, seen, gbuffer->working(), rects, models_only);
  glBindFramebuffer(GL_FRAMEBUFFER, seen.target);
  const internal::GbufferTargets& g = gbuffer->working();
  ResolveSource source;
  source.color = g.color;
  source.depth = g.depth;
  source.retained = projection->retained();
  source.fade = projection->fade();
  source.live = projection->live();
  if (output) {
    const Viewport& o = output->viewport;
    glViewport(o.x, o.y, o.width, o.height);
    glScissor(o.x, o.y, o.width, o.height);
    resolve->Resolve(frame, *output, seen.any_live, seen.any_retained, source, ResolveMode::kPlain, &view.viewport);
  } else if (rects != nullptr) {
    for (const Viewport& r : *rects) {
      glScissor(r.x, r.y, r.width, r.height);
      resolve->Resolve(frame, view, seen.any_live, seen.any_retained, source,
                       models_only ? ResolveMode::kNearer : ResolveMode::kPlain);
    }
  } else {
    resolve->Resolve(frame, view, seen.any_live, seen.any_retained, source);
  }
}

// The cache is rebuilt when its signature changed and the view's inputs were the same in the
// previous frame (or there was none); while they change from frame to frame (a flying browse
// view, a turning camera) the view is drawn in full instead, which costs less than a build that
// the next frame would throw away.
void Renderer::Impl::DrawViewCached(const FrameContext& frame, const std::vector<View>& views, size_t slot,
                                    const ViewFrame& seen) {
  const View& view = views[slot];
  ViewCache& entry = cache.Entry(slot, views.size());
  std::vector<double> signature = cache.Signature(frame, view, seen);
  const bool still = entry.last_signature.empty() || entry.last_signature == signature;
  entry.last_signature = signature;
  if ((!entry.valid || entry.signature != signature) && !still) {
    // Only projectors changed (a camera turning): the cached static G-buffer still holds.
    const bool static_kept = entry.static_valid && entry.static_signature == cache.StaticSignature(frame, view);
    entry.valid = false;
    DrawViewExact(frame, view, seen, MovingViewScale(frame, seen), static_kept);
    return;
  }
  if (!entry.valid || entry.signature != signature) {
    cache.Claim(slot, view.viewport);
    entry.valid = true;
    entry.viewport = view.viewport;
    entry.signature = std::move(signature);
    entry.any_live = seen.any_live;
    entry.any_retained = seen.any_retained;
    BuildViewCache(frame, view, seen, entry);
    ++stats.view_cache_builds;
  } else {
    ++stats.view_cache_hits;
  }
  // When the models' rectangles cover much of the view, patching them (exact passes per
  // rectangle, shadow tests over the cached entries) costs more than drawing the view exactly once
  // (docs/BENCHMARKS.md "Avatars in the viewer"); the cache is kept for when they have gone.
  std::vector<Viewport> rects = ModelRects(view);
  int64_t covered = 0;
  for (const Viewport& r : rects) covered += static_cast<int64_t>(r.width) * r.height;
  if (covered * 3 > static_cast<int64_t>(view.viewport.width) * view.viewport.height) {
    DrawViewExact(frame, view, seen);
    entry.patches = {view.viewport};  // the working G-buffer holds the whole view (ReadLinearDepth)
    entry.last_frame = stats.frames + 1;
    ++stats.views_exact_for_models;
    return;
  }
  // Where a model is in a visible live projector's shadow map, the cached entries are tested
  // against it (only those whose video falls where the models are in that projector's image).
  bool shadowed = false;
  int visible_live = 0;
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    if (!seen.visible[k] || frame.passes[k].retained) continue;
    ++visible_live;
    if (cameras.slots()[frame.passes[k].layer].shadow.dynamic_has_models) shadowed = true;
  }
  shadowed = shadowed && entry.any_live && options.dynamic_objects_cast_shadows;
  // A crowd (issue 17): counting every model's shadow volumes in the stencil and then testing the
  // pixels inside them cost more than testing the entries of every pixel in the resolve itself
  // (ave-bench avatars, 100 people under 3 cameras: ~160 ms against ~50 ms more than the plain
  // resolve, CPU). Still so with the volumes cut where the static surface behind each model ends
  // (~95 ms): the people's shadows from three low cameras cover ~70% of that view, and a stencil
  // of pixels with an entry inside some model's own rectangle, drawn over the whole view, cost as
  // much (~90 ms, docs/BENCHMARKS.md "100 avatars under projected video").
  const bool crowd = shadowed && dynamics.model_bounds().size() > kCrowdModels;
  glBindFramebuffer(GL_FRAMEBUFFER, seen.target);
  const ResolveSource source = cache.Source(entry);
  resolve->Resolve(frame, view, entry.any_live, entry.any_retained, source,
                   crowd ? ResolveMode::kShadowedAll : ResolveMode::kPlain);
  if (crowd) {
    ++stats.view_cache_shadow_tests;
    ++stats.view_cache_shadowed_all;
  } else if (shadowed) {
    shadow_volumes->Mark(view);
    // Inside the volumes, keep only pixels with an entry the models may hide. That pass runs on
    // every pixel of the view (a shader that discards and writes stencil gets no early stencil
    // test on llvmpipe), so it pays only where the view sees more cameras than a pixel keeps
    // entries: with fewer, every volume that holds the surface has its entry there anyway.
    const bool by_entries = visible_live > options.view_cache_entries;
    if (by_entries) {
      resolve->Resolve(frame, view, entry.any_live, entry.any_retained, source, ResolveMode::kMarkEntries);
      ++stats.view_cache_entry_marks;
    }
    resolve->Resolve(frame, view, entry.any_live, entry.any_retained, source,
                     by_entries ? ResolveMode::kMarked : ResolveMode::kInVolumes);
    ++stats.view_cache_shadow_tests;
  }
  entry.patches = std::move(rects);
  entry.last_frame = stats.frames + 1;
  if (!entry.patches.empty()) {
    // The rectangles pass by pass, not one after the other (issue 17): each patch rebound the
    // G-buffer, accumulation and target framebuffers, and 100 people's patches drawn one by one
    // cost ~100 CPU ms per frame on llvmpipe (ave-bench avatars).
    Viewport all = entry.patches.front();
    for (const Viewport& r : entry.patches) {
      cache.CopyRect(r, gbuffer->working());
      all = internal::Union(all, r);
    }
    // Every model lies in its own rectangle: one draw within their union writes no pixel outside.
    glScissor(all.x, all.y, all.width, all.height);
    gbuffer->Bind();
    // The copies brought the cache's stencil (0): the models' own pixels are marked.
    gbuffer->Draw(view, layers(), /*with_static=*/false, /*with_dynamic=*/true, stats, /*mark_models=*/true);
    AccumulateAndResolve(frame, view, seen, nullptr, &entry.patches);
    stats.view_cache_patches += entry.patches.size();
  }
  const Viewport& v = view.viewport;
  glScissor(v.x, v.y, v.width, v.height);
}

// The static G-buffer, the mapping of the live passes and the retained accumulation.
void Renderer::Impl::BuildViewCache(const FrameContext& frame, const View& view, const ViewFrame& seen,
                                    ViewCache& entry) {
  cache.BeginStatic();
  gbuffer->Draw(view, layers(), /*with_static=*/true, /*with_dynamic=*/false, stats);
  entry.static_signature = cache.StaticSignature(frame, view);
  entry.static_valid = true;
  cache.BeginProjectors(entry.any_live, entry.any_retained);
  if (entry.any_live) projection->DrawMapping(frame, view, seen, cache.gbuffer(), cache.mapping());
  if (entry.any_retained) projection->DrawRetained(frame, view, seen, cache.gbuffer());
  entry.built_s = clock.Now();
}

// RendererOptions::moving_view_scale, and more where the view sees more live cameras than
// moving_view_cameras (the per-pixel work grows with them): up to kMaxMovingViewScale.
double Renderer::Impl::MovingViewScale(const FrameContext& frame, const ViewFrame& seen) const {
  if (options.moving_view_scale <= 1) return 1;  // full resolution always
  int live = 0;
  for (size_t k = 0; k < frame.passes.size(); ++k) live += seen.visible[k] && !frame.passes[k].retained;
  const double scale =
      options.moving_view_scale * std::sqrt(std::max(1.0, static_cast<double>(live) / options.moving_view_cameras));
  return std::min(scale, std::max(options.moving_view_scale, kMaxMovingViewScale));
}

// The screen rectangles of a view around the dynamic models' boxes (drawn exactly over a cached
// view), as disjoint runs of squares that cover them.
std::vector<Viewport> Renderer::Impl::ModelRects(const View& view) const {
  std::vector<Viewport> rects;
  const Eigen::Matrix4d clip_from_local = view.projection * view.view;
  for (const internal::Bounds& box : dynamics.model_bounds()) {
    if (const std::optional<Viewport> rect = internal::BoxesScreenRect({&box, 1}, clip_from_local, view.viewport)) {
      rects.push_back(*rect);
    }
  }
  // Squares, not merged rectangles: a crowd's rectangles overlap one another and grew into a few
  // covering most of the view (issue 17, ave-bench avatars: 100 people, 2-3 rectangles over 57% of
  // it; their squares cover 29%).
  return internal::CoveringTiles(rects, view.viewport, kPatchTilePixels);
}

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::~Renderer() = default;
const RendererOptions& Renderer::options() const { return impl_->options; }
RenderStats Renderer::stats() const { return impl_->stats; }
void Renderer::SetClock(double now_s) { impl_->clock.Set(now_s); }
std::vector<std::string> Renderer::StaleCameras() const { return impl_->cameras.Stale(); }

absl::Status Renderer::SetDisplayOptions(const DisplayOptions& display) {
  if (const std::string why = display.Check(); !why.empty()) {
    return absl::InvalidArgumentError("DisplayOptions: " + why);
  }
  impl_->options.display = display;
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<Renderer>> Renderer::Create(const RendererOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("RendererOptions: " + why);
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  if (major * 10 + minor < 33) {
    return absl::FailedPreconditionError("Renderer needs a current OpenGL 3.3+ core context, got " +
                                         std::to_string(major) + "." + std::to_string(minor));
  }
  // The view cache needs image load/store (4.2) and glCopyImageSubData (4.3).
  const bool cache_supported = major * 10 + minor >= 43;
  auto impl = std::make_unique<Impl>(options, cache_supported);
  const RendererOptions& o = impl->options;  // the renderer's copy: passes keep a reference
  // Each pass compiles its programs; the first that fails names its shader file.
  auto assign = [](auto& pass, auto created) -> absl::Status {
    if (!created.ok()) return created.status();
    pass = *std::move(created);
    return absl::OkStatus();
  };
  if (absl::Status s = assign(impl->shadows, ShadowMaps::Create(o)); !s.ok()) return s;
  if (absl::Status s = assign(impl->gbuffer, GbufferPass::Create(o)); !s.ok()) return s;
  if (absl::Status s = assign(impl->avatars, internal::AvatarPass::Create()); !s.ok()) return s;
  if (absl::Status s = assign(impl->projection, ProjectionPass::Create(o, cache_supported, impl->video, *impl->shadows));
      !s.ok()) {
    return s;
  }
  if (absl::Status s = assign(impl->shadow_volumes, ShadowVolumePass::Create()); !s.ok()) return s;
  if (absl::Status s = assign(impl->resolve, ResolvePass::Create(o, cache_supported, impl->video, *impl->shadows));
      !s.ok()) {
    return s;
  }
  if (absl::Status s = assign(impl->points, PointPass::Create()); !s.ok()) return s;
  if (absl::Status s = assign(impl->lines, LinePass::Create()); !s.ok()) return s;
  if (absl::Status s = CheckGl("Renderer::Create"); !s.ok()) return s;
  return std::unique_ptr<Renderer>(new Renderer(std::move(impl)));
}

absl::Status Renderer::SetStaticMesh(const TriangleMesh& mesh) {
  Impl& d = *impl_;
  if (absl::Status s = d.statics.Set(mesh); !s.ok()) return s;
  d.sky.Place(d.statics.bounds());
  return CheckGl("SetStaticMesh");
}

absl::Status Renderer::SetProjectors(const std::vector<Projector>& projectors) {
  if (projectors.size() > static_cast<size_t>(kMaxProjectors)) {
    return absl::InvalidArgumentError("SetProjectors: " + std::to_string(projectors.size()) +
                                      " projectors, the renderer supports at most " + std::to_string(kMaxProjectors));
  }
  for (const Projector& p : projectors) {
    const std::string who = "SetProjectors: camera '" + p.camera_id + "': ";
    if (!p.color.allFinite()) return absl::InvalidArgumentError(who + "color must be finite");
    if (!(p.near_m > 0) || !(p.far_m > p.near_m) || !std::isfinite(p.far_m)) {
      return absl::InvalidArgumentError(who + "needs 0 < near_m < far_m");
    }
    if (!std::all_of(p.distortion.begin(), p.distortion.end(), [](double k) { return std::isfinite(k); })) {
      return absl::InvalidArgumentError(who + "distortion must be finite");
    }
    if (MatricesFinite(p) &&
        (std::abs(p.projection.determinant()) < 1e-300 || std::abs(p.view.determinant()) < 1e-12)) {
      return absl::InvalidArgumentError(who + "view and projection must be invertible");
    }
    if (!p.image_rgba.empty()) {
      if (p.image_width <= 0 || p.image_height <= 0 || p.image_width > 16384 || p.image_height > 16384) {
        return absl::InvalidArgumentError(who + "image size " + std::to_string(p.image_width) + "x" +
                                          std::to_string(p.image_height) + " must be in 1..16384");
      }
      const size_t expected = static_cast<size_t>(p.image_width) * p.image_height * 4;
      if (p.image_rgba.size() != expected) {
        return absl::InvalidArgumentError(who + "image has " + std::to_string(p.image_rgba.size()) +
                                          " bytes, RGBA8 " + std::to_string(p.image_width) + "x" +
                                          std::to_string(p.image_height) + " needs " + std::to_string(expected));
      }
    }
  }
  Impl& d = *impl_;
  FramebufferGuard guard;
  return d.cameras.Set(projectors, d.video, d.stats);
}

absl::Status Renderer::SetDynamicObjects(const std::vector<DynamicBox>& boxes) {
  std::vector<DynamicModel> models;
  models.reserve(boxes.size());
  for (const DynamicBox& b : boxes) models.push_back(DynamicModel{b.base, b.heading_rad, b.size, b.color, ModelShape::kCuboid});
  return SetDynamicModels(models);
}

absl::Status Renderer::SetDynamicModels(const std::vector<DynamicModel>& models) {
  return impl_->dynamics.Set(models);
}

absl::Status Renderer::SetPaths(const std::vector<Polyline>& paths) { return impl_->lines->SetPaths(paths); }

absl::Status Renderer::SetAvatarSequence(const avatar::AvatarSequence& sequence) {
  if (absl::Status s = impl_->avatars->SetSequence(sequence); !s.ok()) return s;
  impl_->dynamics.SetAvatarBounds({});  // its instances are gone until SetAvatars
  return absl::OkStatus();
}

absl::Status Renderer::SetAvatars(const std::vector<AvatarInstance>& avatars) {
  const uint64_t before = impl_->avatars->version();
  if (absl::Status s = impl_->avatars->SetInstances(avatars); !s.ok()) return s;
  if (impl_->avatars->version() != before) impl_->dynamics.SetAvatarBounds(impl_->avatars->instance_bounds());
  return absl::OkStatus();
}

absl::Status Renderer::SetPointCloud(const PointCloud& points) {
  if (absl::Status s = impl_->points->Set(points); !s.ok()) return s;
  return internal::CheckGl("SetPointCloud");
}

absl::Status Renderer::Render(const std::vector<View>& views, int framebuffer_width, int framebuffer_height) {
  if (framebuffer_width <= 0 || framebuffer_height <= 0) {
    return absl::InvalidArgumentError("Render: framebuffer size must be positive");
  }
  for (size_t k = 0; k < views.size(); ++k) {
    const Viewport& v = views[k].viewport;
    if (v.width <= 0 || v.height <= 0 || v.x < 0 || v.y < 0 || v.x + v.width > framebuffer_width ||
        v.y + v.height > framebuffer_height) {
      return absl::InvalidArgumentError("Render: view " + std::to_string(k) + " viewport (" + std::to_string(v.x) +
                                        ", " + std::to_string(v.y) + ", " + std::to_string(v.width) + "x" +
                                        std::to_string(v.height) + ") is not inside the framebuffer");
    }
    if (!views[k].view.allFinite() || !views[k].projection.allFinite()) {
      return absl::InvalidArgumentError("Render: view " + std::to_string(k) + " has non-finite matrices");
    }
  }
  return impl_->Render(views, framebuffer_width, framebuffer_height);
}

absl::StatusOr<std::vector<float>> Renderer::ReadLinearDepth(const View& view) const {
  const Impl& d = *impl_;
  return internal::ReadLinearDepth(
      view, internal::DepthSources{d.width, d.height, d.stats.frames, d.gbuffer->working(), d.cache, d.reduced_views});
}

}  // namespace ave::viewer
