#include "viewer_client/render/passes/view_cache.h"

#include <array>

#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/projector_geometry.h"

namespace ave::viewer::internal {
namespace {

void AppendMatrix(const Eigen::Matrix4d& m, std::vector<double>& out) { out.insert(out.end(), m.data(), m.data() + 16); }

}  // namespace

absl::Status ViewCachePass::Resize(int width, int height) {
  entries_.clear();
  for (Texture* t : {&gbuffer_.color, &gbuffer_.normal, &gbuffer_.depth, &retained_, &fade_, &mapping_}) *t = Texture();
  if (!On()) return absl::OkStatus();
  if (absl::Status s = gbuffer_.Resize(width, height, "view cache G-buffer"); !s.ok()) return s;
  retained_ = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
  fade_ = MakeTexture2D(GL_R32F, GL_RED, GL_FLOAT, width, height);
  mapping_ = Texture::Create();
  glBindTexture(GL_TEXTURE_2D_ARRAY, mapping_);
  glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, GL_RGBA32F, width, height, options_.view_cache_entries);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  if (absl::Status s = AttachTextures(accum_fbo_, {{GL_COLOR_ATTACHMENT1, retained_}, {GL_COLOR_ATTACHMENT2, fade_}},
                                      "view cache retained");
      !s.ok()) {
    return s;
  }
  glBindFramebuffer(GL_FRAMEBUFFER, mapping_fbo_);
  std::array<GLenum, kMaxViewCacheEntries> entries{};
  for (int k = 0; k < options_.view_cache_entries; ++k) {
    glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0 + k, mapping_, 0, k);
    entries[k] = GL_COLOR_ATTACHMENT0 + k;
  }
  glDrawBuffers(options_.view_cache_entries, entries.data());
  if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "view cache mapping"); !s.ok()) return s;
  return CheckGl("view cache targets");
}

std::vector<double> ViewCachePass::Signature(const FrameContext& frame, const View& view,
                                             const ViewFrame& seen) const {
  std::vector<double> sig = StaticSignature(frame, view);
  for (size_t k = 0; k < frame.passes.size(); ++k) {
    if (!seen.visible[k]) continue;
    const ProjectorPass& pass = frame.passes[k];
    const Projector& p = *pass.projector;
    sig.insert(sig.end(), {double(pass.retained), double(pass.layer), p.near_m, p.far_m});
    if (pass.retained) sig.push_back(double(frame.cameras.retained()[pass.layer].order));
    AppendMatrix(p.view, sig);
    AppendMatrix(p.projection, sig);
    sig.insert(sig.end(), p.distortion.begin(), p.distortion.end());
    for (const Eigen::Vector3d& c : pass.corners) sig.insert(sig.end(), c.data(), c.data() + 3);
  }
  return sig;
}

std::vector<double> ViewCachePass::StaticSignature(const FrameContext& frame, const View& view) const {
  std::vector<double> sig;
  sig.reserve(11 + 3 + 2 * 16);
  const Viewport& v = view.viewport;
  const DisplayOptions& display = options_.display;
  sig.insert(sig.end(), {double(frame.width), double(frame.height), double(v.x), double(v.y), double(v.width),
                         double(v.height), double(frame.static_version), double(static_cast<int>(display.overlap)),
                         display.seam_feather, display.retention_half_life_s, double(display.sky)});
  sig.insert(sig.end(), view.clear_color.data(), view.clear_color.data() + 3);
  AppendMatrix(view.view, sig);
  AppendMatrix(view.projection, sig);
  return sig;
}

ViewCache& ViewCachePass::Entry(size_t slot, size_t views) {
  if (entries_.size() < views) entries_.resize(views);
  return entries_[slot];
}

void ViewCachePass::Trim(size_t views) {
  if (entries_.size() > views) entries_.resize(views);
}

void ViewCachePass::Forget(size_t slot) {
  if (slot < entries_.size()) entries_[slot] = ViewCache();
}

void ViewCachePass::Claim(size_t slot, const Viewport& viewport) {
  for (size_t k = 0; k < entries_.size(); ++k) {
    if (k != slot && Overlap(entries_[k].viewport, viewport)) entries_[k].valid = entries_[k].static_valid = false;
  }
}

void ViewCachePass::BeginStatic() {
  glBindFramebuffer(GL_FRAMEBUFFER, gbuffer_.fbo);
  GbufferPass::ApplyState();
  GbufferPass::Clear();
}

void ViewCachePass::BeginProjectors(bool any_live, bool any_retained) {
  glBindFramebuffer(GL_FRAMEBUFFER, mapping_fbo_);
  GbufferPass::ApplyState();
  if (any_live) glClear(GL_COLOR_BUFFER_BIT);
  glBindFramebuffer(GL_FRAMEBUFFER, accum_fbo_);
  const GLenum retained_buffers[] = {GL_NONE, GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
  glDrawBuffers(3, retained_buffers);
  if (any_retained) glClear(GL_COLOR_BUFFER_BIT);
  const GLenum no_buffers[] = {GL_NONE, GL_NONE};
  glDrawBuffers(2, no_buffers);
}

ResolveSource ViewCachePass::Source(const ViewCache& cache) const {
  ResolveSource source;
  source.color = gbuffer_.color;
  source.depth = gbuffer_.depth;
  source.normal = gbuffer_.normal;
  source.retained = retained_;
  source.fade = fade_;
  source.cached = true;
  source.mapping = mapping_;
  source.built_s = cache.built_s;
  return source;
}

void ViewCachePass::CopyStatic(const Viewport& from, const Viewport& to, const GbufferTargets& working) const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, gbuffer_.fbo);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, working.fbo);
  for (GLenum attachment : {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1}) {
    glReadBuffer(attachment);
    const GLenum one[] = {attachment == GL_COLOR_ATTACHMENT0 ? attachment : GLenum{GL_NONE},
                          attachment == GL_COLOR_ATTACHMENT1 ? attachment : GLenum{GL_NONE}};
    glDrawBuffers(2, one);
    glBlitFramebuffer(from.x, from.y, from.x + from.width, from.y + from.height, to.x, to.y, to.x + to.width,
                      to.y + to.height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  }
  glBlitFramebuffer(from.x, from.y, from.x + from.width, from.y + from.height, to.x, to.y, to.x + to.width,
                    to.y + to.height, GL_DEPTH_BUFFER_BIT, GL_NEAREST);
  const GLenum both[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glDrawBuffers(2, both);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glBindFramebuffer(GL_FRAMEBUFFER, working.fbo);
}

void ViewCachePass::CopyRect(const Viewport& r, const GbufferTargets& working) const {
  for (const auto& [from, to] : {std::pair<GLuint, GLuint>{gbuffer_.color, working.color},
                                 std::pair<GLuint, GLuint>{gbuffer_.normal, working.normal},
                                 std::pair<GLuint, GLuint>{gbuffer_.depth, working.depth}}) {
    glCopyImageSubData(from, GL_TEXTURE_2D, 0, r.x, r.y, 0, to, GL_TEXTURE_2D, 0, r.x, r.y, 0, r.width, r.height, 1);
  }
}

}  // namespace ave::viewer::internal
