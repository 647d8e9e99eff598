#pragma once
// The AVE renderer (paper sections 7-8): the static model shaded by a fixed sun, live camera frames
// projected onto it as projective textures with shadow-map visibility, dynamic objects as boxes,
// and camera frustum wireframes. Everything is in the model's local frame (metres, the
// TriangleMesh origin); large world coordinates never reach the GPU.
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
#include "model_store/geometry/mesh.h"

namespace ave::viewer {

// Projectors are uniform arrays in the scene shader (shaders/scene.frag.glsl MAX_PROJECTORS);
// SetProjectors rejects more. Issue 7 raises the limit to 50.
inline constexpr int kMaxProjectors = 16;

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
};

// A moving object drawn as a solid box; it receives projected video and (by default) casts
// shadows in the projectors' shadow maps.
struct DynamicBox {
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  // bottom centre, local frame
  double heading_rad = 0;                          // box length axis from local +x, counter-clockwise
  Eigen::Vector3d size = Eigen::Vector3d(0.6, 0.4, 1.8);  // length (along heading), width, height; metres
  Eigen::Vector3f color = Eigen::Vector3f(0.8f, 0.2f, 0.2f);
};

// One picture in the framebuffer.
struct View {
  Viewport viewport;
  Eigen::Matrix4d view = Eigen::Matrix4d::Identity();        // GL eye from local
  Eigen::Matrix4d projection = Eigen::Matrix4d::Identity();  // GL clip from eye
  bool draw_frustums = true;
  std::string highlight_camera_id;  // this projector's frustum is drawn brighter and thicker
  Eigen::Vector3f clear_color = Eigen::Vector3f(0.62f, 0.74f, 0.86f);  // sky
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

  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Counters since creation, to check that work is only redone when inputs change.
struct RenderStats {
  uint64_t frames = 0;
  uint64_t shadow_map_renders = 0;      // static-mesh passes into a projector's shadow layer
  uint64_t dynamic_shadow_updates = 0;  // dynamic-box passes into a projector's shadow layer
  uint64_t video_uploads = 0;
};

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
  absl::Status SetDynamicObjects(const std::vector<DynamicBox>& boxes);

  // Draws the views into the currently bound draw framebuffer, each viewport cleared first.
  // Shadow maps are refreshed first where projectors or geometry changed.
  absl::Status Render(const std::vector<View>& views, int framebuffer_width, int framebuffer_height);

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
