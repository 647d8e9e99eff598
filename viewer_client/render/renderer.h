#pragma once
// The AVE renderer (paper sections 7-8): the static model shaded by a fixed sun, live camera frames
// projected onto it as projective textures with shadow-map visibility, dynamic objects as standing
// models, camera frustum wireframes and object paths. Everything is in the model's local frame
// (metres, the TriangleMesh origin); large world coordinates never reach the GPU: convert world
// poses to local in double (subtract the origin) before building matrices.
//
// How a frame is drawn (deferred, issue 7; see docs/ARCHITECTURE.md): per view, the model goes once
// into a G-buffer (shaded colour, normal, depth); then each projector whose frustum meets the view
// adds its video in a screen-space pass limited to its frustum's footprint (back faces of the
// frustum volume), weighted per pixel by the overlap policy; then a resolve pass writes colour and
// depth into the caller's framebuffer, and points (SetPointCloud) and lines (frustums, paths) are
// drawn on top, depth tested. Shadow maps are
// rendered only when a projector's pose or the geometry changed. Cost on llvmpipe (issue 7
// performance, docs/BENCHMARKS.md "## Rendering"): the static model is split into grid chunks and
// each view or shadow map draws only the chunks its frustum may see; the projector pass rejects
// pixels outside the frustum before its other work; the resolve is compiled per combination of
// live / retained passes present, so a view without video pays only for colour and depth.
//
// Texture retention: when a camera turns away (its pose leaves the pose of its last snapshot by
// more than RendererOptions::retention_turn_deg / retention_move_m), its last frame, pose and
// capture time become a "retained snapshot" (a copy of the video layer plus the old projector,
// with its own static shadow map). Removing or disabling a camera removes its live imagery at
// once; snapshots it left behind earlier stay until they fade. Snapshots are drawn under the live
// video only where no live camera reaches, faded by 0.5^(age / half-life); newer snapshots win over
// older ones. Chosen over a model-space texture atlas because it costs nothing while no camera
// turns (one layer copy per snapshot, its shadow map once), where an atlas needs a bake pass over
// the textured model on every new frame, which llvmpipe cannot afford. The price: a panning camera
// leaves a snapshot only every retention_turn_deg (at most max_retained_per_camera kept), so
// imagery seen only in between is not kept.
//
// For the application (h7b): keep using SetProjectors / SetDynamicObjects / Render as before. New:
// SetDynamicModels (billboard / cuboid / cylinder), SetPaths (polylines), SetDisplayOptions (overlap
// policy, retention half-life, age tint, sky: ImGui toggles), SetClock (replay time), StaleCameras()
// (cameras whose last pose had NaNs), ReadLinearDepth + WriteDepthExr (--depth F.exr).
//
// Still views (RendererOptions::view_cache): a view whose inputs other than the video content and
// the dynamic models did not change since its last frame reuses its G-buffer and a per-pixel
// mapping of the projectors reaching each pixel; only the resolve and the rectangles around
// dynamic models are drawn again. A view whose inputs change every frame (flying, a turning
// camera) is drawn at reduced resolution (RendererOptions::moving_view_scale) until it stops, its
// live projectors in combined full-screen passes (RendererOptions::combined_live_passes).
//
// Needs a current GL 3.3+ core context (gl_context.h) for its whole life: create it after the
// context is current, call it on that thread, destroy it before the context.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "model_store/avatar/avatar_sequence.h"
#include "model_store/geometry/mesh.h"

namespace ave::viewer {

// Live projectors are layers of one video texture array and one shadow-map array; SetProjectors
// rejects more than this.
inline constexpr int kMaxProjectors = 64;
inline constexpr double kMaxMovingViewScale = 4;  // RendererOptions::moving_view_cameras

// Where several cameras see the same surface point.
enum class OverlapPolicy {
  kBlendBestView,  // weighted by view angle and resolution (cos / distance^2), seams feathered
  kBestView,       // the same weight to the 4th power: close to the single best camera, soft seams
  kLastWins,       // the later projector in the list paints over earlier ones
};

// A rectangle of the framebuffer in pixels, GL convention: (x, y) is its bottom-left corner,
// counted from the framebuffer's bottom-left pixel.
struct Viewport {
  int x = 0, y = 0, width = 0, height = 0;
};

// One camera whose live frame is projected onto the model.
struct Projector {
  std::string camera_id;
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();        // GL eye from local (ave::GlViewFromWorld)
  Eigen::Matrix4d projection = Eigen::Matrix4d::Identity();  // ave::GlProjection(intrinsics, near_m, far_m)
  double near_m = 0.5, far_m = 300;                          // the planes `projection` was built with
  Eigen::Vector3d position = Eigen::Vector3d::Zero();        // camera centre, local frame
  // The frame: RGBA8, rows top first, image_width * image_height * 4 bytes, any size (it is
  // resampled into a fixed-size texture layer). Read only during SetProjectors. It is uploaded when
  // image_serial changes or another camera_id takes this index; empty keeps the frame last uploaded
  // for this camera at this index. A projector that never had a frame projects nothing (its frustum
  // is still drawn).
  int image_width = 0, image_height = 0;
  std::span<const uint8_t> image_rgba;
  uint64_t image_serial = 0;
  Eigen::Vector3f color = Eigen::Vector3f(1, 1, 0);  // frustum colour, rgb in [0, 1]
  bool enabled = true;                               // disabled: neither projected nor drawn
  // Lens distortion of the frame (Intrinsics.distortion: k1 k2 p1 p2 k3, OpenCV order; zeros: an
  // ideal pinhole). The shader applies the forward model to find the frame pixel of a surface point.
  std::array<double, 5> distortion{};
};

// A projector with a non-finite view, projection or position is not rejected: SetProjectors keeps
// the camera's last good pose and frame (or skips it if it never had one) and lists it in
// Renderer::StaleCameras() until a finite pose arrives (issue 7 hard case: a pose with NaNs).

// A moving object drawn as a solid box; it receives projected video and (by default) casts
// shadows in the projectors' shadow maps.
struct DynamicBox {
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  // bottom centre, local frame
  double heading_rad = 0;                          // box length axis from local +x, counter-clockwise
  Eigen::Vector3d size = Eigen::Vector3d(0.6, 0.4, 1.8);  // length (along heading), width, height; metres
  Eigen::Vector3f color = Eigen::Vector3f(0.8f, 0.2f, 0.2f);
};

// How a dynamic object is modelled (proto ObjectModel).
enum class ModelShape {
  kCuboid,     // oriented box
  kCylinder,   // upright cylinder, diameter = size.y (width), 16 sides
  kBillboard,  // two crossed upright quads (size.y wide): looks the same from every side
};

// A standing model for a DynamicObject (h7b converts from the proto; local frame).
struct DynamicModel {
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  // ground contact, bottom centre
  double heading_rad = 0;                          // length axis from local +x, counter-clockwise
  Eigen::Vector3d size = Eigen::Vector3d(0.6, 0.4, 1.8);  // length (along heading), width, height; metres
  Eigen::Vector3f color = Eigen::Vector3f(0.8f, 0.2f, 0.2f);
  ModelShape shape = ModelShape::kCuboid;
};

// A person drawn as a frame of an avatar sequence (issue 17, i4D §5; Renderer::SetAvatars): the
// sequence's foot centre at `base`, its +x axis (the walking direction) at heading_rad.
struct AvatarInstance {
  std::string sequence;                            // a name given to SetAvatarSequence
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  // ground contact, local frame
  double heading_rad = 0;                          // from local +x, counter-clockwise
  double phase_cycles = 0;                         // walk phase: frame floor(phase * frames), wrapped
};

// A polyline drawn as lines (object paths), local frame.
struct Polyline {
  std::vector<Eigen::Vector3d> points;
  Eigen::Vector3f color = Eigen::Vector3f(1, 1, 1);
};

// Points drawn as squares of point_size_px pixels, depth tested against the scene (LiDAR foreground
// points, issue 16); they receive no video. Positions in the local frame, relative to the model's
// origin (floats are fine there), one RGB colour in [0, 1] per point.
struct PointCloud {
  std::vector<Eigen::Vector3f> positions_local_m;
  std::vector<Eigen::Vector3f> colors;
  float point_size_px = 3;  // 1..64, clamped to what the GL supports
};

// One picture in the framebuffer.
struct View {
  Viewport viewport;
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();        // GL eye from local
  Eigen::Matrix4d projection = Eigen::Matrix4d::Identity();  // GL clip from eye
  bool draw_frustums = true;
  bool draw_paths = true;           // the polylines of SetPaths
  bool draw_points = true;          // the point cloud of SetPointCloud
  std::string highlight_camera_id;  // this projector's frustum is drawn brighter and thicker
  Eigen::Vector3f clear_color = Eigen::Vector3f(0.62f, 0.74f, 0.86f);  // sky
};

// What the user may toggle at any time (Renderer::SetDisplayOptions).
struct DisplayOptions {
  OverlapPolicy overlap = OverlapPolicy::kBlendBestView;
  // Seam feathering: a projector's weight falls to zero over this fraction of its image's
  // half-width at the image border (0: hard edges).
  double seam_feather = 0.1;
  // Retained imagery fades as 0.5^(age / half-life); <= 0 turns retained imagery off.
  double retention_half_life_s = 60;
  bool tint_by_age = false;  // tint retained imagery from yellow (fresh) to blue (old)
  bool sky = true;           // a sky dome receives imagery above the horizon
  // Projected video lands on avatars (issue 17). false: the privacy export (--avatars-only):
  // people show their avatar's own texture and no video pixel lands on them.
  bool video_on_people = true;

  std::string Check() const;  // empty when usable; otherwise names the first bad field
};

struct RendererOptions {
  // Every frame is resampled into a texture layer of this size (pixels).
  int video_layer_width = 640;
  int video_layer_height = 480;
  int shadow_map_size = 1024;  // pixels per side, per projector
  // Model shading: colour * (ambient + diffuse * max(0, n . sun)).
  Eigen::Vector3f sun_direction = Eigen::Vector3f(0.35f, 0.25f, 0.9f);  // towards the sun; normalised
  float ambient = 0.45f;
  float diffuse = 0.55f;
  // Frustum wireframes end this far in front of the camera (depth along its optical axis).
  double frustum_depth_m = 12;
  // Dynamic boxes occlude video behind them. Costs a depth copy per projector per change.
  bool dynamic_objects_cast_shadows = true;
  // Retained snapshots: at most this many in all (texture layers), and per camera.
  int max_retained = 16;
  int max_retained_per_camera = 2;
  // A camera turning by more than this (optical axis) or moving more than this since its last
  // snapshot leaves a snapshot of its previous pose and frame behind.
  double retention_turn_deg = 10;
  double retention_move_m = 1.0;
  // Pose jitter (issue 7 performance): a camera whose new pose moves the image corners and centre
  // at frustum_depth_m in front of it by less than this many pixels of the video layer (against
  // the pose kept so far) keeps its kept pose, so fused poses (EKF) that wobble by tiny amounts
  // leave its shadow map and the view caches alone. 0: every change of the matrices counts.
  double still_pose_tolerance_px = 0.25;
  // Sky dome (elevation -10 to 90 degrees) centred on the bottom centre of the static model's
  // bounding box; radius in metres, 0: 1.2 x the box's half diagonal (at least 100 m). Projectors
  // reach it only within their far plane. It is drawn in the view's clear colour.
  double sky_radius_m = 0;
  // View cache (issue 7 performance; docs/BENCHMARKS.md "## Rendering"): for a view whose matrices,
  // viewport and clear colour, the static model, the active projectors' poses, distortion and
  // layers, the display options and the retained snapshots are as in its last frame, the G-buffer
  // of the static model and a per-pixel mapping of the view_cache_entries best live projector
  // entries (video u, v, layer, weight) are kept; such a frame is one resolve pass that samples the
  // current video through the mapping. A cached entry whose video (u, v) lies where dynamic models
  // are in its projector's image (a rectangle per projector, from the models' extent in its shadow
  // map) is also tested against that shadow map with the models; in a model's own screen box the
  // exact passes are drawn. Where
  // more than view_cache_entries cameras overlap, only the best ones are blended (and where a model
  // hides one of them, the next one is not brought in). A view whose inputs change from one frame
  // to the next (flying, a turning camera) is drawn in full; its cache is built in the first frame
  // they stay as in the frame before. Needs OpenGL 4.3 (image load/store, copy image); on an older
  // context, or for views whose viewports overlap another view of the same Render, every frame is
  // drawn in full.
  bool view_cache = true;
  // Live projector entries kept per pixel (1..kMaxViewCacheEntries): each costs 16 bytes per
  // framebuffer pixel and a texel fetch per covered pixel in every cached frame; see
  // docs/BENCHMARKS.md for the difference to the exact blend where more cameras overlap.
  int view_cache_entries = 4;
  // Live projectors of a view drawn exactly (flying, turning, model rectangles over a cached view,
  // cache off) in full-screen passes of up to 16 projectors each, scissored to their footprints:
  // the G-buffer read and the point reconstruction happen once per pixel instead of once per
  // projector (issue 7 performance). false: one pass per projector over its frustum volume's back
  // faces, as before (same picture; kept for comparison).
  bool combined_live_passes = true;
  // A view whose inputs changed since its previous frame (flying, a turning camera; view cache on)
  // is drawn at 1 / moving_view_scale of its viewport's width and height and scaled up (nearest)
  // in the resolve: the per-pixel work of a frame the next one replaces drops by its square. The
  // first frame its inputs stay the same is drawn at full resolution (the cache build). 1: full
  // resolution always. Lines are drawn at full resolution.
  double moving_view_scale = 2;
  // A moving view that sees more live cameras than this is reduced further, by the square root of
  // the excess (its per-pixel work grows with the cameras), up to kMaxMovingViewScale: with 50
  // cameras a flying browse view stays interactive, and is sharp again when it stops. A large
  // value: moving_view_scale alone.
  int moving_view_cameras = 8;
  DisplayOptions display;

  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Counters since creation, to check that work is only redone when inputs change.
struct RenderStats {
  uint64_t frames = 0;
  uint64_t shadow_map_renders = 0;      // static-mesh passes into a projector's shadow layer
  uint64_t dynamic_shadow_updates = 0;  // dynamic-box passes into a projector's shadow layer
  uint64_t video_uploads = 0;
  uint64_t projector_passes = 0;     // per-camera screen-space passes drawn (live + retained)
  uint64_t projectors_culled = 0;    // per-view projector passes skipped: frustum outside the view
  uint64_t retained_snapshots = 0;   // snapshots taken
  uint64_t retained_shadow_renders = 0;
  uint64_t chunks_culled = 0;        // static-model chunks skipped (G-buffer and shadow passes): off screen
  uint64_t view_cache_builds = 0;    // views whose cache was (re)built: G-buffer and mapping drawn
  uint64_t view_cache_hits = 0;      // views drawn from an unchanged cache (resolve only)
  // Screen rectangles around dynamic models drawn exactly over a cached view.
  uint64_t view_cache_patches = 0;
  // Cached views resolved with the models' shadow test: some visible live projector's shadow map
  // held a model, and entries whose video lies where the models are in its image were tested.
  uint64_t view_cache_shadow_tests = 0;
  // ... of which saw more live cameras than view_cache_entries: pixels with an entry the models may
  // hide were picked first (a full-view pass), the shadow volumes alone do not bound them then.
  uint64_t view_cache_entry_marks = 0;
  // Views drawn in full: cache off or unsupported, overlapping views, or inputs that changed since
  // the view's previous frame (the cache is built on the first frame they stay the same).
  uint64_t views_uncached = 0;
  uint64_t views_reduced = 0;  // of those, drawn at reduced resolution (RendererOptions::moving_view_scale)
  // Views drawn in full whose static G-buffer came from their cache (only projectors changed).
  uint64_t views_static_from_cache = 0;
  // ... of which tested every pixel's entries in the resolve: a crowd of over 24 models, whose
  // shadow volumes cost more to count than that.
  uint64_t view_cache_shadowed_all = 0;
  // Cached views drawn exactly because the dynamic models' rectangles covered over a third of the
  // view (patching them costs more then).
  uint64_t views_exact_for_models = 0;
};

// Most live projector entries the view cache keeps per pixel (RendererOptions::view_cache_entries).
inline constexpr int kMaxViewCacheEntries = 8;

class Renderer {
 public:
  // Compiles the shaders and allocates textures; fails with the shader file and info log.
  static absl::StatusOr<std::unique_ptr<Renderer>> Create(const RendererOptions& options = {});
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Uploads positions, normals and colours (local frame). Indices must address existing vertices.
  absl::Status SetStaticMesh(const TriangleMesh& mesh);
  // The projectors in order; index i uses texture layer i. At most kMaxProjectors.
  absl::Status SetProjectors(const std::vector<Projector>& projectors);
  absl::Status SetDynamicObjects(const std::vector<DynamicBox>& boxes);  // = cuboid DynamicModels
  absl::Status SetDynamicModels(const std::vector<DynamicModel>& models);
  absl::Status SetPaths(const std::vector<Polyline>& paths);
  // Avatars (issue 17): a sequence's frames are uploaded once (replacing one of the same name);
  // SetAvatars then places the people, each an instance drawn with the dynamic models (G-buffer,
  // shadow maps). Errors name the sequence and frame, or the avatar.
  absl::Status SetAvatarSequence(const avatar::AvatarSequence& sequence);
  absl::Status SetAvatars(const std::vector<AvatarInstance>& avatars);
  // Replaces the point cloud (uploaded once, drawn every frame until replaced); empty: none.
  absl::Status SetPointCloud(const PointCloud& points);
  absl::Status SetDisplayOptions(const DisplayOptions& display);
  // Seconds on any monotonic clock for snapshot ages; until the first call the renderer uses its
  // own steady clock. Replays and tests pass their own time.
  void SetClock(double now_s);
  // Cameras whose last SetProjectors entry had a non-finite pose, sorted.
  std::vector<std::string> StaleCameras() const;

  // Draws the views into the currently bound draw framebuffer, each viewport cleared first.
  // Shadow maps are refreshed first where projectors or geometry changed.
  absl::Status Render(const std::vector<View>& views, int framebuffer_width, int framebuffer_height);

  // Linear depth (metres along the view's optical axis) of `view` as drawn by the last Render
  // (pass the same View); width * height floats, rows top first; +inf where only sky or nothing.
  absl::StatusOr<std::vector<float>> ReadLinearDepth(const View& view) const;

  const RendererOptions& options() const;
  RenderStats stats() const;

 private:
  struct Impl;
  explicit Renderer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The model's own colour as the scene shader shades it where no video falls (tests use it).
Eigen::Vector3f ShadedModelColor(const RendererOptions& options, const Eigen::Vector3f& color,
                                 const Eigen::Vector3f& normal);

// Writes a single-channel float OpenEXR image (channel "Z"), rows top first (--depth F.exr).
absl::Status WriteDepthExr(const std::string& path, const std::vector<float>& depth, int width, int height);

// Four equal quadrants of a width x height framebuffer, in GL viewport coordinates (origin at the
// bottom-left): [0] top-left (the browse view), [1] top-right, [2] bottom-left, [3] bottom-right
// (the three camera-locked views). Odd sizes give the extra pixel to the right / top cells.
std::array<Viewport, 4> QuadLayout(int width, int height);

// A view that looks through a projector's camera. The camera image keeps its aspect and is
// centred in the viewport, as large as fits: the projection is widened (not cropped) along the
// viewport's longer side, so the video fills the image's own rectangle exactly and the model
// around the camera's field of view fills the margin (no black bars). Frustums are not drawn in
// it; its own frustum is the highlight.
View ViewLockedToProjector(const Projector& projector, const Viewport& viewport);

}  // namespace ave::viewer
