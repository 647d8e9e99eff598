#include "viewer_client/render/renderer.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>

#include <epoxy/gl.h>

#include "model_store/geometry/camera.h"
#include "viewer_client/render/shader_program.h"

namespace ave::viewer {
namespace {

constexpr GLint kVideoUnit = 0;
constexpr GLint kShadowUnit = 1;
// Depth bias of the shadow pass, in addition to the normal offset of the scene shader: the slope
// term absorbs the depth change across one texel on grazing ground (paper section 8).
constexpr float kShadowSlopeBias = 1.5f;
constexpr float kShadowConstantBias = 2.0f;
// Normal offset for the shadow lookup, in shadow-map texels at the fragment's distance.
constexpr float kNormalOffsetTexels = 1.0f;
constexpr float kHighlightLineWidth = 3.0f;

struct Vertex {
  float position[3];
  float normal[3];
  float color[3];
};

struct LineVertex {
  float position[3];
  float color[3];
};

using GlMatrix = std::array<float, 16>;

enum class Pass { kUpload, kShadow, kScene, kLines };

// Every fixed-function state change of the renderer is here (STYLE habit 6).
void ApplyPassState(Pass pass) {
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  switch (pass) {
    case Pass::kUpload:
      glDisable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      glDisable(GL_POLYGON_OFFSET_FILL);
      glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      break;
    case Pass::kShadow:
      glDisable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
      glEnable(GL_POLYGON_OFFSET_FILL);
      glPolygonOffset(kShadowSlopeBias, kShadowConstantBias);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      break;
    case Pass::kScene:
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
      glDisable(GL_POLYGON_OFFSET_FILL);
      glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      break;
    case Pass::kLines:
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LEQUAL);
      glDepthMask(GL_TRUE);
      glDisable(GL_POLYGON_OFFSET_FILL);
      glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      break;
  }
}

// Restores the caller's framebuffer bindings and viewport after internal passes.
class FramebufferGuard {
 public:
  FramebufferGuard() {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw_);
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_);
    glGetIntegerv(GL_VIEWPORT, viewport_);
  }
  ~FramebufferGuard() {
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(draw_));
    glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(read_));
    glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
  }

 private:
  GLint draw_ = 0, read_ = 0;
  GLint viewport_[4] = {0, 0, 0, 0};
};

absl::Status CheckGl(const char* where) {
  const GLenum error = glGetError();
  if (error == GL_NO_ERROR) return absl::OkStatus();
  while (glGetError() != GL_NO_ERROR) {
  }
  char hex[16];
  std::snprintf(hex, sizeof(hex), "0x%04x", static_cast<unsigned>(error));
  return absl::InternalError(std::string(where) + ": GL error " + hex);
}

absl::Status CheckFramebuffer(GLenum target, const char* what) {
  const GLenum status = glCheckFramebufferStatus(target);
  if (status == GL_FRAMEBUFFER_COMPLETE) return absl::OkStatus();
  return absl::InternalError(std::string(what) + ": framebuffer incomplete (status " + std::to_string(status) + ")");
}

struct MeshBuffers {
  GLuint vao = 0, vbo = 0, ebo = 0;
  GLsizei count = 0;  // indices (indexed) or vertices

  void Create(bool with_normals, bool indexed) {
    glGenVertexArrays(1, &vao);
    glGenBuffers(1, &vbo);
    glBindVertexArray(vao);
    glBindBuffer(GL_ARRAY_BUFFER, vbo);
    if (indexed) {
      glGenBuffers(1, &ebo);
      glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo);
    }
    const GLsizei stride = with_normals ? sizeof(Vertex) : sizeof(LineVertex);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(0));
    if (with_normals) {
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(Vertex, normal)));
      glEnableVertexAttribArray(2);
      glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(Vertex, color)));
    } else {
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(LineVertex, color)));
    }
    glBindVertexArray(0);
  }
  void Destroy() {
    if (ebo) glDeleteBuffers(1, &ebo);
    if (vbo) glDeleteBuffers(1, &vbo);
    if (vao) glDeleteVertexArrays(1, &vao);
  }
  void Draw(GLenum mode) const {
    if (count == 0) return;
    glBindVertexArray(vao);
    if (ebo) {
      glDrawElements(mode, count, GL_UNSIGNED_INT, nullptr);
    } else {
      glDrawArrays(mode, 0, count);
    }
  }
};

// What texture layer / shadow layer i currently holds.
struct ProjectorSlot {
  std::string camera_id;
  uint64_t image_serial = 0;
  bool has_image = false;
  bool shadow_valid = false;
  GlMatrix shadow_clip_from_local{};
  uint64_t shadow_static_version = 0;
  uint64_t shadow_dynamic_version = 0;
};

bool Finite(const Eigen::Matrix4d& m) { return m.allFinite(); }

void AppendBoxVertices(const DynamicBox& box, std::vector<Vertex>& out) {
  const double c = std::cos(box.heading_rad), s = std::sin(box.heading_rad);
  const Eigen::Vector3d ax(c, s, 0), ay(-s, c, 0), az(0, 0, 1);
  const Eigen::Vector3d hx = 0.5 * box.size.x() * ax, hy = 0.5 * box.size.y() * ay, h = box.size.z() * az;
  auto corner = [&](int sx, int sy, int sz) -> Eigen::Vector3f {
    return (box.base + sx * hx + sy * hy + sz * h).cast<float>();
  };
  // Counter-clockwise seen from outside; n = (b - a) x (c - a).
  auto quad = [&](Eigen::Vector3f a, Eigen::Vector3f b, Eigen::Vector3f cc, Eigen::Vector3f d) {
    const Eigen::Vector3f n = (b - a).cross(cc - a).normalized();
    for (const Eigen::Vector3f* p : {&a, &b, &cc, &a, &cc, &d}) {
      out.push_back(Vertex{{p->x(), p->y(), p->z()}, {n.x(), n.y(), n.z()}, {box.color.x(), box.color.y(), box.color.z()}});
    }
  };
  quad(corner(-1, -1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(-1, -1, 1));
  quad(corner(1, -1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, -1, 1));
  quad(corner(1, 1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(1, 1, 1));
  quad(corner(-1, 1, 0), corner(-1, -1, 0), corner(-1, -1, 1), corner(-1, 1, 1));
  quad(corner(-1, -1, 1), corner(1, -1, 1), corner(1, 1, 1), corner(-1, 1, 1));
}

// Camera centre to the four image corners at depth_m along the optical axis, plus the rectangle.
std::array<Eigen::Vector3d, 16> FrustumSegments(const Projector& p, double depth_m) {
  const Eigen::Matrix4d local_from_eye = p.view.inverse();
  const Eigen::Matrix4d eye_from_clip = p.projection.inverse();
  const Eigen::Vector3d centre = (local_from_eye * Eigen::Vector4d(0, 0, 0, 1)).head<3>();
  std::array<Eigen::Vector3d, 4> corners;
  const double ndc[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector4d e = eye_from_clip * Eigen::Vector4d(ndc[k][0], ndc[k][1], -1, 1);
    e /= e.w();
    const Eigen::Vector3d at_depth = e.head<3>() * (depth_m / -e.z());
    corners[k] = (local_from_eye * at_depth.homogeneous()).head<3>();
  }
  std::array<Eigen::Vector3d, 16> segments;
  for (int k = 0; k < 4; ++k) {
    segments[4 * k + 0] = centre;
    segments[4 * k + 1] = corners[k];
    segments[4 * k + 2] = corners[k];
    segments[4 * k + 3] = corners[(k + 1) % 4];
  }
  return segments;
}

}  // namespace

struct Renderer::Impl {
  RendererOptions options;
  GLuint scene_program = 0, shadow_program = 0, line_program = 0;
  struct {
    GLint clip_from_local, sun_direction, ambient, diffuse, projector_count, projector_clip_from_local,
        projector_position, projector_layer, projector_normal_offset, video, shadow;
  } scene_uniforms{};
  GLint shadow_clip_from_local = -1, line_clip_from_local = -1;

  MeshBuffers static_mesh, dynamic_mesh, lines;
  GLuint video_array = 0, scratch_texture = 0;
  int scratch_width = 0, scratch_height = 0;
  GLuint shadow_static_array = 0, shadow_dynamic_array = 0;
  int shadow_layers = 0;
  GLuint fbo_video_src = 0, fbo_video_dst = 0, fbo_shadow_src = 0, fbo_shadow_dst = 0;
  float max_line_width = 1;

  std::vector<Projector> projectors;  // image_rgba cleared: only valid during SetProjectors
  std::vector<std::array<Eigen::Vector3d, 16>> frustums;
  std::array<ProjectorSlot, kMaxProjectors> slots;
  uint64_t static_version = 1, dynamic_version = 1;
  std::vector<Vertex> dynamic_vertices;
  RenderStats stats;

  ~Impl() {
    static_mesh.Destroy();
    dynamic_mesh.Destroy();
    lines.Destroy();
    const GLuint textures[] = {video_array, scratch_texture, shadow_static_array, shadow_dynamic_array};
    glDeleteTextures(4, textures);
    const GLuint fbos[] = {fbo_video_src, fbo_video_dst, fbo_shadow_src, fbo_shadow_dst};
    glDeleteFramebuffers(4, fbos);
    for (GLuint program : {scene_program, shadow_program, line_program}) {
      if (program) glDeleteProgram(program);
    }
  }

  GLuint sampled_shadow_array() const {
    return options.dynamic_objects_cast_shadows ? shadow_dynamic_array : shadow_static_array;
  }

  void AllocateShadowArrays(int layers) {
    for (GLuint* texture : {&shadow_static_array, &shadow_dynamic_array}) {
      if (*texture == 0) glGenTextures(1, texture);
      glBindTexture(GL_TEXTURE_2D_ARRAY, *texture);
      glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_DEPTH_COMPONENT32F, options.shadow_map_size, options.shadow_map_size,
                   layers, 0, GL_DEPTH_COMPONENT, GL_FLOAT, nullptr);
      // NEAREST: one depth compare per lookup; LINEAR (2x2 PCF) cost ~15% of the frame on llvmpipe.
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    }
    shadow_layers = layers;
    for (ProjectorSlot& slot : slots) slot.shadow_valid = false;
  }

  absl::Status UploadFrame(int layer, const Projector& p) {
    ApplyPassState(Pass::kUpload);
    const int lw = options.video_layer_width, lh = options.video_layer_height;
    if (p.image_width == lw && p.image_height == lh) {
      glBindTexture(GL_TEXTURE_2D_ARRAY, video_array);
      glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, lw, lh, 1, GL_RGBA, GL_UNSIGNED_BYTE, p.image_rgba.data());
      return CheckGl("upload frame");
    }
    // Other sizes: upload as is, then resample into the layer. Rows stay top first in both.
    glBindTexture(GL_TEXTURE_2D, scratch_texture);
    if (p.image_width != scratch_width || p.image_height != scratch_height) {
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, p.image_width, p.image_height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
      scratch_width = p.image_width;
      scratch_height = p.image_height;
    }
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, p.image_width, p.image_height, GL_RGBA, GL_UNSIGNED_BYTE,
                    p.image_rgba.data());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_video_src);
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, scratch_texture, 0);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_video_dst);
    glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, video_array, 0, layer);
    if (absl::Status s = CheckFramebuffer(GL_READ_FRAMEBUFFER, "frame upload source"); !s.ok()) return s;
    if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "frame upload layer"); !s.ok()) return s;
    glBlitFramebuffer(0, 0, p.image_width, p.image_height, 0, 0, lw, lh, GL_COLOR_BUFFER_BIT, GL_LINEAR);
    return CheckGl("resample frame");
  }

  absl::Status UpdateShadowMaps() {
    const int needed = std::max<int>(1, static_cast<int>(projectors.size()));
    if (needed > shadow_layers) AllocateShadowArrays(needed);
    const int size = options.shadow_map_size;
    bool state_set = false;
    for (size_t i = 0; i < projectors.size(); ++i) {
      const Projector& p = projectors[i];
      ProjectorSlot& slot = slots[i];
      if (!p.enabled || !slot.has_image) continue;
      const GlMatrix clip_from_local = ToGlArray(p.projection * p.view);
      const bool static_dirty = !slot.shadow_valid || slot.shadow_clip_from_local != clip_from_local ||
                                slot.shadow_static_version != static_version;
      const bool dynamic_dirty = options.dynamic_objects_cast_shadows &&
                                 (static_dirty || slot.shadow_dynamic_version != dynamic_version);
      if (!static_dirty && !dynamic_dirty) continue;
      if (!state_set) {
        ApplyPassState(Pass::kShadow);
        glViewport(0, 0, size, size);
        glUseProgram(shadow_program);
        state_set = true;
      }
      glUniformMatrix4fv(shadow_clip_from_local, 1, GL_FALSE, clip_from_local.data());
      const GLint layer = static_cast<GLint>(i);
      glBindFramebuffer(GL_FRAMEBUFFER, fbo_shadow_src);
      glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, shadow_static_array, 0, layer);
      if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "static shadow map"); !s.ok()) return s;
      if (static_dirty) {
        glClear(GL_DEPTH_BUFFER_BIT);
        static_mesh.Draw(GL_TRIANGLES);
        ++stats.shadow_map_renders;
      }
      if (dynamic_dirty) {
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_shadow_dst);
        glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, shadow_dynamic_array, 0, layer);
        if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "dynamic shadow map"); !s.ok()) return s;
        glBlitFramebuffer(0, 0, size, size, 0, 0, size, size, GL_DEPTH_BUFFER_BIT, GL_NEAREST);
        dynamic_mesh.Draw(GL_TRIANGLES);
        ++stats.dynamic_shadow_updates;
      }
      slot.shadow_valid = true;
      slot.shadow_clip_from_local = clip_from_local;
      slot.shadow_static_version = static_version;
      slot.shadow_dynamic_version = dynamic_version;
    }
    return CheckGl("shadow maps");
  }

  void DrawScene(const View& view, const std::vector<GlMatrix>& clip, const std::vector<float>& position,
                 const std::vector<float>& layer, const std::vector<float>& normal_offset) {
    ApplyPassState(Pass::kScene);
    glUseProgram(scene_program);
    const auto& u = scene_uniforms;
    glUniformMatrix4fv(u.clip_from_local, 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    const Eigen::Vector3f sun = options.sun_direction.normalized();
    glUniform3f(u.sun_direction, sun.x(), sun.y(), sun.z());
    glUniform1f(u.ambient, options.ambient);
    glUniform1f(u.diffuse, options.diffuse);
    const GLsizei n = static_cast<GLsizei>(clip.size());
    glUniform1i(u.projector_count, n);
    if (n > 0) {
      glUniformMatrix4fv(u.projector_clip_from_local, n, GL_FALSE, clip[0].data());
      glUniform3fv(u.projector_position, n, position.data());
      glUniform1fv(u.projector_layer, n, layer.data());
      glUniform1fv(u.projector_normal_offset, n, normal_offset.data());
    }
    glUniform1i(u.video, kVideoUnit);
    glUniform1i(u.shadow, kShadowUnit);
    glActiveTexture(GL_TEXTURE0 + kVideoUnit);
    glBindTexture(GL_TEXTURE_2D_ARRAY, video_array);
    glActiveTexture(GL_TEXTURE0 + kShadowUnit);
    glBindTexture(GL_TEXTURE_2D_ARRAY, sampled_shadow_array());
    glActiveTexture(GL_TEXTURE0);
    static_mesh.Draw(GL_TRIANGLES);
    dynamic_mesh.Draw(GL_TRIANGLES);
  }

  void DrawFrustums(const View& view) {
    std::vector<LineVertex> normal_lines, highlight_lines;
    for (size_t i = 0; i < projectors.size(); ++i) {
      const Projector& p = projectors[i];
      if (!p.enabled) continue;
      const bool highlight = !view.highlight_camera_id.empty() && p.camera_id == view.highlight_camera_id;
      const Eigen::Vector3f color = highlight ? Eigen::Vector3f(0.5f * p.color + Eigen::Vector3f::Constant(0.5f)) : p.color;
      for (const Eigen::Vector3d& q : frustums[i]) {
        (highlight ? highlight_lines : normal_lines)
            .push_back(LineVertex{{static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z())},
                                  {color.x(), color.y(), color.z()}});
      }
    }
    const GLsizei normal_count = static_cast<GLsizei>(normal_lines.size());
    normal_lines.insert(normal_lines.end(), highlight_lines.begin(), highlight_lines.end());
    if (normal_lines.empty()) return;
    ApplyPassState(Pass::kLines);
    glUseProgram(line_program);
    glUniformMatrix4fv(line_clip_from_local, 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    glBindBuffer(GL_ARRAY_BUFFER, lines.vbo);
    glBufferData(GL_ARRAY_BUFFER, normal_lines.size() * sizeof(LineVertex), normal_lines.data(), GL_STREAM_DRAW);
    glBindVertexArray(lines.vao);
    glLineWidth(1.0f);
    if (normal_count > 0) glDrawArrays(GL_LINES, 0, normal_count);
    if (!highlight_lines.empty()) {
      glLineWidth(std::min(kHighlightLineWidth, max_line_width));
      glDrawArrays(GL_LINES, normal_count, static_cast<GLsizei>(highlight_lines.size()));
      glLineWidth(1.0f);
    }
  }
};

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::~Renderer() = default;
const RendererOptions& Renderer::options() const { return impl_->options; }
RenderStats Renderer::stats() const { return impl_->stats; }

absl::StatusOr<std::unique_ptr<Renderer>> Renderer::Create(const RendererOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("RendererOptions: " + why);
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  if (major * 10 + minor < 33) {
    return absl::FailedPreconditionError("Renderer needs a current OpenGL 3.3+ core context, got " +
                                         std::to_string(major) + "." + std::to_string(minor));
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;

  absl::StatusOr<GLuint> scene = internal::BuildEmbeddedProgram("shaders/scene.vert.glsl", "shaders/scene.frag.glsl");
  if (!scene.ok()) return scene.status();
  impl->scene_program = *scene;
  absl::StatusOr<GLuint> shadow = internal::BuildEmbeddedProgram("shaders/shadow.vert.glsl", "shaders/shadow.frag.glsl");
  if (!shadow.ok()) return shadow.status();
  impl->shadow_program = *shadow;
  absl::StatusOr<GLuint> line = internal::BuildEmbeddedProgram("shaders/line.vert.glsl", "shaders/line.frag.glsl");
  if (!line.ok()) return line.status();
  impl->line_program = *line;

  auto& u = impl->scene_uniforms;
  const GLuint sp = impl->scene_program;
  u.clip_from_local = glGetUniformLocation(sp, "u_clip_from_local");
  u.sun_direction = glGetUniformLocation(sp, "u_sun_direction");
  u.ambient = glGetUniformLocation(sp, "u_ambient");
  u.diffuse = glGetUniformLocation(sp, "u_diffuse");
  u.projector_count = glGetUniformLocation(sp, "u_projector_count");
  u.projector_clip_from_local = glGetUniformLocation(sp, "u_projector_clip_from_local");
  u.projector_position = glGetUniformLocation(sp, "u_projector_position");
  u.projector_layer = glGetUniformLocation(sp, "u_projector_layer");
  u.projector_normal_offset = glGetUniformLocation(sp, "u_projector_normal_offset");
  u.video = glGetUniformLocation(sp, "u_video");
  u.shadow = glGetUniformLocation(sp, "u_shadow");
  impl->shadow_clip_from_local = glGetUniformLocation(impl->shadow_program, "u_clip_from_local");
  impl->line_clip_from_local = glGetUniformLocation(impl->line_program, "u_clip_from_local");

  impl->static_mesh.Create(/*with_normals=*/true, /*indexed=*/true);
  impl->dynamic_mesh.Create(/*with_normals=*/true, /*indexed=*/false);
  impl->lines.Create(/*with_normals=*/false, /*indexed=*/false);

  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glGenTextures(1, &impl->video_array);
  glBindTexture(GL_TEXTURE_2D_ARRAY, impl->video_array);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA8, options.video_layer_width, options.video_layer_height, kMaxProjectors,
               0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glGenTextures(1, &impl->scratch_texture);
  glBindTexture(GL_TEXTURE_2D, impl->scratch_texture);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  for (GLuint* fbo : {&impl->fbo_video_src, &impl->fbo_video_dst, &impl->fbo_shadow_src, &impl->fbo_shadow_dst}) {
    glGenFramebuffers(1, fbo);
  }
  {
    FramebufferGuard guard;
    for (GLuint fbo : {impl->fbo_shadow_src, impl->fbo_shadow_dst}) {
      glBindFramebuffer(GL_FRAMEBUFFER, fbo);
      glDrawBuffer(GL_NONE);
      glReadBuffer(GL_NONE);
    }
  }
  impl->AllocateShadowArrays(1);
  GLfloat line_range[2] = {1, 1};
  glGetFloatv(GL_ALIASED_LINE_WIDTH_RANGE, line_range);
  impl->max_line_width = line_range[1];
  if (absl::Status s = CheckGl("Renderer::Create"); !s.ok()) return s;
  return std::unique_ptr<Renderer>(new Renderer(std::move(impl)));
}

absl::Status Renderer::SetStaticMesh(const TriangleMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (mesh.normals.size() != n || mesh.colors.size() != n) {
    return absl::InvalidArgumentError("SetStaticMesh: " + std::to_string(n) + " positions but " +
                                      std::to_string(mesh.normals.size()) + " normals and " +
                                      std::to_string(mesh.colors.size()) + " colors");
  }
  if (mesh.indices.size() % 3 != 0) return absl::InvalidArgumentError("SetStaticMesh: indices not a multiple of 3");
  for (size_t k = 0; k < mesh.indices.size(); ++k) {
    if (mesh.indices[k] >= n) {
      return absl::InvalidArgumentError("SetStaticMesh: index " + std::to_string(k) + " = " +
                                        std::to_string(mesh.indices[k]) + " >= vertex count " + std::to_string(n));
    }
  }
  std::vector<Vertex> vertices(n);
  for (size_t k = 0; k < n; ++k) {
    if (!mesh.positions[k].allFinite() || !mesh.normals[k].allFinite() || !mesh.colors[k].allFinite()) {
      return absl::InvalidArgumentError("SetStaticMesh: vertex " + std::to_string(k) + " is not finite");
    }
    std::memcpy(vertices[k].position, mesh.positions[k].data(), sizeof(float) * 3);
    std::memcpy(vertices[k].normal, mesh.normals[k].data(), sizeof(float) * 3);
    std::memcpy(vertices[k].color, mesh.colors[k].data(), sizeof(float) * 3);
  }
  MeshBuffers& m = impl_->static_mesh;
  glBindVertexArray(m.vao);
  glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(Vertex), vertices.data(), GL_STATIC_DRAW);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, mesh.indices.size() * sizeof(uint32_t), mesh.indices.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  m.count = static_cast<GLsizei>(mesh.indices.size());
  ++impl_->static_version;
  return CheckGl("SetStaticMesh");
}

absl::Status Renderer::SetProjectors(const std::vector<Projector>& projectors) {
  if (projectors.size() > static_cast<size_t>(kMaxProjectors)) {
    return absl::InvalidArgumentError("SetProjectors: " + std::to_string(projectors.size()) +
                                      " projectors, the renderer supports at most " + std::to_string(kMaxProjectors) +
                                      " (uniform arrays; issue 7)");
  }
  for (const Projector& p : projectors) {
    const std::string who = "SetProjectors: camera '" + p.camera_id + "': ";
    if (!Finite(p.view) || !Finite(p.projection) || !p.position.allFinite() || !p.color.allFinite()) {
      return absl::InvalidArgumentError(who + "view, projection, position and color must be finite");
    }
    if (!(p.near_m > 0) || !(p.far_m > p.near_m) || !std::isfinite(p.far_m)) {
      return absl::InvalidArgumentError(who + "needs 0 < near_m < far_m");
    }
    if (std::abs(p.projection.determinant()) < 1e-300 || std::abs(p.view.determinant()) < 1e-12) {
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
  d.projectors.clear();
  d.frustums.clear();
  for (size_t i = 0; i < projectors.size(); ++i) {
    const Projector& p = projectors[i];
    ProjectorSlot& slot = d.slots[i];
    if (slot.camera_id != p.camera_id) {
      slot = ProjectorSlot();
      slot.camera_id = p.camera_id;
    }
    if (p.enabled && !p.image_rgba.empty() && (!slot.has_image || slot.image_serial != p.image_serial)) {
      if (absl::Status s = d.UploadFrame(static_cast<int>(i), p); !s.ok()) {
        return absl::InternalError("SetProjectors: camera '" + p.camera_id + "': " + std::string(s.message()));
      }
      slot.has_image = true;
      slot.image_serial = p.image_serial;
      ++d.stats.video_uploads;
    }
    Projector kept = p;
    kept.image_rgba = {};
    d.projectors.push_back(std::move(kept));
    d.frustums.push_back(FrustumSegments(p, d.options.frustum_depth_m));
  }
  for (size_t i = projectors.size(); i < d.slots.size(); ++i) d.slots[i] = ProjectorSlot();
  return CheckGl("SetProjectors");
}

absl::Status Renderer::SetDynamicObjects(const std::vector<DynamicBox>& boxes) {
  std::vector<Vertex> vertices;
  vertices.reserve(boxes.size() * 30);
  for (size_t k = 0; k < boxes.size(); ++k) {
    const DynamicBox& b = boxes[k];
    if (!b.base.allFinite() || !std::isfinite(b.heading_rad) || !b.size.allFinite() || !b.color.allFinite() ||
        (b.size.array() <= 0).any()) {
      return absl::InvalidArgumentError("SetDynamicObjects: box " + std::to_string(k) +
                                        " needs finite values and a positive size");
    }
    AppendBoxVertices(b, vertices);
  }
  Impl& d = *impl_;
  const bool same = vertices.size() == d.dynamic_vertices.size() &&
                    (vertices.empty() ||
                     std::memcmp(vertices.data(), d.dynamic_vertices.data(), vertices.size() * sizeof(Vertex)) == 0);
  if (same) return absl::OkStatus();
  glBindBuffer(GL_ARRAY_BUFFER, d.dynamic_mesh.vbo);
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(Vertex), vertices.data(), GL_DYNAMIC_DRAW);
  d.dynamic_mesh.count = static_cast<GLsizei>(vertices.size());
  d.dynamic_vertices = std::move(vertices);
  ++d.dynamic_version;
  return CheckGl("SetDynamicObjects");
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
    if (!Finite(views[k].view) || !Finite(views[k].projection)) {
      return absl::InvalidArgumentError("Render: view " + std::to_string(k) + " has non-finite matrices");
    }
  }
  Impl& d = *impl_;
  {
    FramebufferGuard guard;
    if (absl::Status s = d.UpdateShadowMaps(); !s.ok()) return s;
  }
  // Projectors that texture this frame, packed for the uniform arrays.
  std::vector<GlMatrix> clip;
  std::vector<float> position, layer, normal_offset;
  for (size_t i = 0; i < d.projectors.size(); ++i) {
    const Projector& p = d.projectors[i];
    if (!p.enabled || !d.slots[i].has_image) continue;
    clip.push_back(ToGlArray(p.projection * p.view));
    position.insert(position.end(), {static_cast<float>(p.position.x()), static_cast<float>(p.position.y()),
                                     static_cast<float>(p.position.z())});
    layer.push_back(static_cast<float>(i));
    // Metres per metre of distance covered by one shadow texel: 2 / (P00 * size) on the wider axis.
    const double texel = 2.0 / (std::min(std::abs(p.projection(0, 0)), std::abs(p.projection(1, 1))) *
                                d.options.shadow_map_size);
    normal_offset.push_back(static_cast<float>(kNormalOffsetTexels * texel));
  }
  for (const View& view : views) {
    const Viewport& v = view.viewport;
    glViewport(v.x, v.y, v.width, v.height);
    glScissor(v.x, v.y, v.width, v.height);
    ApplyPassState(Pass::kScene);
    glClearColor(view.clear_color.x(), view.clear_color.y(), view.clear_color.z(), 1.0f);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    d.DrawScene(view, clip, position, layer, normal_offset);
    if (view.draw_frustums) d.DrawFrustums(view);
  }
  glBindVertexArray(0);
  glUseProgram(0);
  ++d.stats.frames;
  return CheckGl("Render");
}

}  // namespace ave::viewer
