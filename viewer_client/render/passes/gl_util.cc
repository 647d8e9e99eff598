#include "viewer_client/render/passes/gl_util.h"

#include <cstddef>
#include <cstdio>

#include "viewer_client/render/shader_program.h"

namespace ave::viewer::internal {

GLuint GenGlObject(GlKind kind) {
  GLuint name = 0;
  switch (kind) {
    case GlKind::kTexture: glGenTextures(1, &name); break;
    case GlKind::kFramebuffer: glGenFramebuffers(1, &name); break;
    case GlKind::kBuffer: glGenBuffers(1, &name); break;
    case GlKind::kVertexArray: glGenVertexArrays(1, &name); break;
    case GlKind::kProgram: break;  // programs come from BuildEmbeddedProgram
  }
  return name;
}

void DeleteGlObject(GlKind kind, GLuint name) {
  if (name == 0) return;
  switch (kind) {
    case GlKind::kTexture: glDeleteTextures(1, &name); break;
    case GlKind::kFramebuffer: glDeleteFramebuffers(1, &name); break;
    case GlKind::kBuffer: glDeleteBuffers(1, &name); break;
    case GlKind::kVertexArray: glDeleteVertexArrays(1, &name); break;
    case GlKind::kProgram: glDeleteProgram(name); break;
  }
}

Uniforms::Uniforms(GLuint program, std::initializer_list<const char*> names) {
  for (const char* name : names) locations_.emplace_back(name, glGetUniformLocation(program, name));
}

GLint Uniforms::operator[](std::string_view name) const {
  for (const auto& [n, location] : locations_) {
    if (n == name) return location;
  }
  return -1;
}

absl::StatusOr<Program> Program::Build(std::string_view vertex, std::string_view fragment, std::string_view defines,
                                       std::initializer_list<const char*> names) {
  absl::StatusOr<GLuint> id = BuildEmbeddedProgram(vertex, fragment, defines);
  if (!id.ok()) return id.status();
  Program program;
  program.id = GlObject<GlKind::kProgram>(*id);
  program.u = Uniforms(*id, names);
  return program;
}

Vertex MakeVertex(const Eigen::Vector3f& p, const Eigen::Vector3f& n, const Eigen::Vector3f& c) {
  return Vertex{{p.x(), p.y(), p.z()}, {n.x(), n.y(), n.z()}, {c.x(), c.y(), c.z()}};
}

LineVertex MakeLineVertex(const Eigen::Vector3d& p, const Eigen::Vector3f& c) {
  return LineVertex{{static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())},
                    {c.x(), c.y(), c.z()}};
}

MeshBuffers::MeshBuffers(bool with_normals, bool indexed)
    : vao_(VertexArray::Create()), vbo_(GlBuffer::Create()), ebo_(indexed ? GlBuffer::Create() : GlBuffer()) {
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  if (indexed) glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo_);
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

void MeshBuffers::UploadIndexed(const std::vector<Vertex>& vertices, const std::vector<uint32_t>& indices) {
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(Vertex), vertices.data(), GL_STATIC_DRAW);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, indices.size() * sizeof(uint32_t), indices.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  count_ = static_cast<GLsizei>(indices.size());
}

void MeshBuffers::Draw(GLenum mode, GLint first, GLsizei n) const {
  if (count_ == 0) return;
  glBindVertexArray(vao_);
  if (ebo_) {
    glDrawElements(mode, count_, GL_UNSIGNED_INT, nullptr);
  } else {
    glDrawArrays(mode, first, n < 0 ? count_ : n);
  }
}

FramebufferGuard::FramebufferGuard() {
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw_);
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_);
  glGetIntegerv(GL_VIEWPORT, viewport_);
}

FramebufferGuard::~FramebufferGuard() {
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(draw_));
  glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(read_));
  glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
}

void ResetPassState() {
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_CLAMP);
  glDisable(GL_POLYGON_OFFSET_FILL);
  glDisable(GL_STENCIL_TEST);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
}

bool DrawFramebufferHasDepth() {
  GLint bound = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &bound);
  const GLenum attachment = bound == 0 ? GLenum{GL_DEPTH} : GLenum{GL_DEPTH_ATTACHMENT};
  GLint type = GL_NONE;
  glGetFramebufferAttachmentParameteriv(GL_DRAW_FRAMEBUFFER, attachment, GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE, &type);
  if (type == GL_NONE) return false;
  GLint bits = 0;
  glGetFramebufferAttachmentParameteriv(GL_DRAW_FRAMEBUFFER, attachment, GL_FRAMEBUFFER_ATTACHMENT_DEPTH_SIZE, &bits);
  return bits > 0;
}

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

absl::Status AttachTextures(GLuint fbo, std::initializer_list<std::pair<GLenum, GLuint>> attachments,
                            const char* what) {
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  for (const auto& [attachment, texture] : attachments) {
    glFramebufferTexture2D(GL_FRAMEBUFFER, attachment, GL_TEXTURE_2D, texture, 0);
  }
  return CheckFramebuffer(GL_FRAMEBUFFER, what);
}

Texture MakeTexture2D(GLenum internal_format, GLenum format, GLenum type, int width, int height) {
  Texture texture = Texture::Create();
  glBindTexture(GL_TEXTURE_2D, texture);
  glTexImage2D(GL_TEXTURE_2D, 0, internal_format, width, height, 0, format, type, nullptr);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return texture;
}

void BindTexture(GLint unit, GLenum target, GLuint texture) {
  glActiveTexture(GL_TEXTURE0 + unit);
  glBindTexture(target, texture);
  glActiveTexture(GL_TEXTURE0);
}

}  // namespace ave::viewer::internal
