#pragma once
// Internal to ave_render: owning GL handles, vertex layouts, texture units and the state every
// pass starts from. Each pass (passes/*.h) owns its GL objects through these handles and sets its
// own fixed-function state from ResetPassState() in one ApplyState function (STYLE habit 6).
// Needs a current GL context wherever a handle is created or destroyed.
#include <array>
#include <initializer_list>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <epoxy/gl.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace ave::viewer::internal {

// Texture units of the deferred passes.
inline constexpr GLint kGbufferColorUnit = 0;
inline constexpr GLint kGbufferNormalUnit = 1;
inline constexpr GLint kGbufferDepthUnit = 2;
inline constexpr GLint kVideoUnit = 3;
inline constexpr GLint kShadowUnit = 4;
inline constexpr GLint kLiveUnit = 5;
inline constexpr GLint kRetainedUnit = 6;
inline constexpr GLint kFadeUnit = 7;
inline constexpr GLint kMappingUnit = 8;
inline constexpr GLuint kMappingImageUnit = 0;

using GlMatrix = std::array<float, 16>;

enum class GlKind { kTexture, kFramebuffer, kBuffer, kVertexArray, kProgram };
void DeleteGlObject(GlKind kind, GLuint name);
GLuint GenGlObject(GlKind kind);

// One GL object, deleted with its owner (RAII); moves, never copies.
template <GlKind K>
class GlObject {
 public:
  GlObject() = default;
  explicit GlObject(GLuint adopt) : name_(adopt) {}
  static GlObject Create() { return GlObject(GenGlObject(K)); }
  ~GlObject() { DeleteGlObject(K, name_); }
  GlObject(GlObject&& other) noexcept : name_(std::exchange(other.name_, 0)) {}
  GlObject& operator=(GlObject&& other) noexcept {
    if (this != &other) {
      DeleteGlObject(K, name_);
      name_ = std::exchange(other.name_, 0);
    }
    return *this;
  }
  GlObject(const GlObject&) = delete;
  GlObject& operator=(const GlObject&) = delete;
  operator GLuint() const { return name_; }  // NOLINT: handles read like the GL names they own

 private:
  GLuint name_ = 0;
};
using Texture = GlObject<GlKind::kTexture>;
using Framebuffer = GlObject<GlKind::kFramebuffer>;
using VertexArray = GlObject<GlKind::kVertexArray>;
using GlBuffer = GlObject<GlKind::kBuffer>;

// Uniform locations by name, looked up once.
class Uniforms {
 public:
  Uniforms() = default;
  Uniforms(GLuint program, std::initializer_list<const char*> names);
  GLint operator[](std::string_view name) const;

 private:
  std::vector<std::pair<std::string_view, GLint>> locations_;
};

// A linked program with its uniform locations.
struct Program {
  GlObject<GlKind::kProgram> id;
  Uniforms u;

  // BuildEmbeddedProgram (shader_program.h) and the locations of `names`.
  static absl::StatusOr<Program> Build(std::string_view vertex, std::string_view fragment, std::string_view defines,
                                       std::initializer_list<const char*> names);
};

struct Vertex {
  float position[3];
  float normal[3];
  float color[3];
};

struct LineVertex {
  float position[3];
  float color[3];
};

Vertex MakeVertex(const Eigen::Vector3f& p, const Eigen::Vector3f& n, const Eigen::Vector3f& c);
LineVertex MakeLineVertex(const Eigen::Vector3d& p, const Eigen::Vector3f& c);

// A vertex array with its buffers: Vertex (with_normals) or LineVertex layout, optionally indexed.
class MeshBuffers {
 public:
  MeshBuffers(bool with_normals, bool indexed);
  template <typename T>
  void Upload(const std::vector<T>& vertices, GLenum usage) {
    glBindBuffer(GL_ARRAY_BUFFER, vbo_);
    glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(T), vertices.data(), usage);
    count_ = static_cast<GLsizei>(vertices.size());
  }
  // Vertices and indices of an indexed mesh (count: the indices).
  void UploadIndexed(const std::vector<Vertex>& vertices, const std::vector<uint32_t>& indices);
  void Draw(GLenum mode, GLint first = 0, GLsizei n = -1) const;
  GLsizei count() const { return count_; }
  GLuint vao() const { return vao_; }

 private:
  VertexArray vao_;
  GlBuffer vbo_, ebo_;
  GLsizei count_ = 0;  // indices (indexed) or vertices
};

// Restores the caller's framebuffer bindings and viewport after internal passes.
class FramebufferGuard {
 public:
  FramebufferGuard();
  ~FramebufferGuard();
  FramebufferGuard(const FramebufferGuard&) = delete;
  FramebufferGuard& operator=(const FramebufferGuard&) = delete;
  GLuint draw() const { return static_cast<GLuint>(draw_); }

 private:
  GLint draw_ = 0, read_ = 0;
  GLint viewport_[4] = {0, 0, 0, 0};
};

// The fixed-function state every pass starts from (no culling, blending, depth clamp, polygon
// offset or stencil; all colour channels written). Each pass's ApplyState calls it first.
void ResetPassState();

absl::Status CheckGl(const char* where);
// Whether the framebuffer bound for drawing (the default one or an object) has depth bits.
bool DrawFramebufferHasDepth();
absl::Status CheckFramebuffer(GLenum target, const char* what);

// Attaches 2D textures (attachment, texture) to `fbo`, leaves it bound and checks it is complete;
// `what` names the target in the error.
absl::Status AttachTextures(GLuint fbo, std::initializer_list<std::pair<GLenum, GLuint>> attachments,
                            const char* what);

// A width x height 2D texture, nearest, clamped.
Texture MakeTexture2D(GLenum internal_format, GLenum format, GLenum type, int width, int height);
void BindTexture(GLint unit, GLenum target, GLuint texture);

}  // namespace ave::viewer::internal
