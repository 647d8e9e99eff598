#pragma once
// Internal to ave_render: the video pass's textures. Live frames in one RGBA8 texture array (layer
// i: projector i), retained snapshots in another, every frame resampled to the layer size
// (RendererOptions::video_layer_width x video_layer_height). Arrays grow in steps of kLayerStep
// layers, keeping the frames they hold.
#include "absl/status/status.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class VideoLayers {
 public:
  explicit VideoLayers(const RendererOptions& options);

  // Projector p's frame (p.image_rgba) into live layer `layer`.
  absl::Status Upload(int layer, const Projector& p);
  // A copy of live layer `live_layer` into retained layer `retained_layer`.
  absl::Status KeepAsRetained(int live_layer, int retained_layer);

  GLuint live() const { return live_; }
  GLuint retained() const { return retained_; }

 private:
  // Grows `array` to at least `needed` layers, keeping the frames it holds.
  absl::Status Ensure(Texture& array, int& layers, int needed);
  // Copies layer `from_layer` of `from` into layer `to_layer` of `to` (both layer-sized).
  void CopyLayer(GLuint from, int from_layer, GLuint to, int to_layer);
  static void ApplyState();

  const int width_, height_;
  Texture live_, retained_, scratch_;
  int live_layers_ = 1, retained_layers_ = 1;
  int scratch_width_ = 0, scratch_height_ = 0;
  Framebuffer src_fbo_, dst_fbo_;
};

}  // namespace ave::viewer::internal
