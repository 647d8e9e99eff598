#include "viewer_client/render/passes/video_layers.h"

namespace ave::viewer::internal {
namespace {

// Layers grow in steps of this many (a reallocation copies the old layers).
constexpr int kLayerStep = 4;

Texture MakeVideoArray(int width, int height, int layers) {
  Texture texture = Texture::Create();
  glBindTexture(GL_TEXTURE_2D_ARRAY, texture);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA8, width, height, layers, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return texture;
}

}  // namespace

// Every fixed-function state change of the video pass: copies and uploads, nothing tested.
void VideoLayers::ApplyState() {
  ResetPassState();
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_DEPTH_TEST);
}

VideoLayers::VideoLayers(const RendererOptions& options)
    : width_(options.video_layer_width), height_(options.video_layer_height) {
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  // One layer each until frames arrive (Ensure grows them), so the samplers are complete.
  live_ = MakeVideoArray(width_, height_, 1);
  retained_ = MakeVideoArray(width_, height_, 1);
  scratch_ = Texture::Create();
  glBindTexture(GL_TEXTURE_2D, scratch_);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  src_fbo_ = Framebuffer::Create();
  dst_fbo_ = Framebuffer::Create();
}

void VideoLayers::CopyLayer(GLuint from, int from_layer, GLuint to, int to_layer) {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, src_fbo_);
  glFramebufferTextureLayer(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, from, 0, from_layer);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, dst_fbo_);
  glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, to, 0, to_layer);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
}

absl::Status VideoLayers::Ensure(Texture& array, int& layers, int needed) {
  if (needed <= layers) return absl::OkStatus();
  const int grown = (needed + kLayerStep - 1) / kLayerStep * kLayerStep;
  Texture fresh = MakeVideoArray(width_, height_, grown);
  ApplyState();
  for (int layer = 0; layer < layers; ++layer) CopyLayer(array, layer, fresh, layer);
  array = std::move(fresh);
  layers = grown;
  return CheckGl("video layers");
}

absl::Status VideoLayers::Upload(int layer, const Projector& p) {
  if (absl::Status s = Ensure(live_, live_layers_, layer + 1); !s.ok()) return s;
  ApplyState();
  if (p.image_width == width_ && p.image_height == height_) {
    glBindTexture(GL_TEXTURE_2D_ARRAY, live_);
    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, width_, height_, 1, GL_RGBA, GL_UNSIGNED_BYTE,
                    p.image_rgba.data());
    return CheckGl("upload frame");
  }
  // Other sizes: upload as is, then resample into the layer. Rows stay top first in both.
  glBindTexture(GL_TEXTURE_2D, scratch_);
  if (p.image_width != scratch_width_ || p.image_height != scratch_height_) {
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, p.image_width, p.image_height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    scratch_width_ = p.image_width;
    scratch_height_ = p.image_height;
  }
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, p.image_width, p.image_height, GL_RGBA, GL_UNSIGNED_BYTE,
                  p.image_rgba.data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, src_fbo_);
  glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, scratch_, 0);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, dst_fbo_);
  glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, live_, 0, layer);
  if (absl::Status s = CheckFramebuffer(GL_READ_FRAMEBUFFER, "frame upload source"); !s.ok()) return s;
  if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "frame upload layer"); !s.ok()) return s;
  glBlitFramebuffer(0, 0, p.image_width, p.image_height, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_LINEAR);
  return CheckGl("resample frame");
}

absl::Status VideoLayers::KeepAsRetained(int live_layer, int retained_layer) {
  if (absl::Status s = Ensure(retained_, retained_layers_, retained_layer + 1); !s.ok()) return s;
  ApplyState();
  CopyLayer(live_, live_layer, retained_, retained_layer);
  return absl::OkStatus();
}

}  // namespace ave::viewer::internal
