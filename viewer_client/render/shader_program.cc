#include "viewer_client/render/shader_program.h"

#include <string>

#include <epoxy/gl.h>

#include "absl/status/status.h"

namespace ave::viewer::internal {
namespace {

std::string InfoLog(GLuint object, bool is_program) {
  GLint length = 0;
  if (is_program) {
    glGetProgramiv(object, GL_INFO_LOG_LENGTH, &length);
  } else {
    glGetShaderiv(object, GL_INFO_LOG_LENGTH, &length);
  }
  std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
  if (is_program) {
    glGetProgramInfoLog(object, length, nullptr, log.data());
  } else {
    glGetShaderInfoLog(object, length, nullptr, log.data());
  }
  while (!log.empty() && (log.back() == '\0' || log.back() == '\n')) log.pop_back();
  return log;
}

absl::StatusOr<GLuint> Compile(GLenum type, std::string_view name, std::string_view source) {
  if (source.empty()) return absl::NotFoundError(std::string(name) + ": shader source is empty or not embedded");
  const GLuint shader = glCreateShader(type);
  const GLchar* text = source.data();
  const GLint length = static_cast<GLint>(source.size());
  glShaderSource(shader, 1, &text, &length);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    const std::string log = InfoLog(shader, false);
    glDeleteShader(shader);
    return absl::InvalidArgumentError(std::string(name) + ": GLSL compile failed: " + log);
  }
  return shader;
}

}  // namespace

absl::StatusOr<unsigned int> BuildProgram(std::string_view vertex_name, std::string_view vertex_source,
                                          std::string_view fragment_name, std::string_view fragment_source) {
  absl::StatusOr<GLuint> vs = Compile(GL_VERTEX_SHADER, vertex_name, vertex_source);
  if (!vs.ok()) return vs.status();
  absl::StatusOr<GLuint> fs = Compile(GL_FRAGMENT_SHADER, fragment_name, fragment_source);
  if (!fs.ok()) {
    glDeleteShader(*vs);
    return fs.status();
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, *vs);
  glAttachShader(program, *fs);
  glLinkProgram(program);
  glDeleteShader(*vs);
  glDeleteShader(*fs);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    const std::string log = InfoLog(program, true);
    glDeleteProgram(program);
    return absl::InvalidArgumentError(std::string(vertex_name) + " + " + std::string(fragment_name) +
                                      ": GLSL link failed: " + log);
  }
  return program;
}

absl::StatusOr<unsigned int> BuildEmbeddedProgram(std::string_view vertex_name, std::string_view fragment_name,
                                                  std::string_view fragment_defines) {
  std::string fragment(EmbeddedShader(fragment_name));
  if (!fragment_defines.empty()) {
    const size_t line_end = fragment.find('\n');
    if (line_end == std::string::npos) return absl::InvalidArgumentError(std::string(fragment_name) + ": no #version line");
    fragment.insert(line_end + 1, fragment_defines);
  }
  return BuildProgram(vertex_name, EmbeddedShader(vertex_name), fragment_name, fragment);
}

}  // namespace ave::viewer::internal
