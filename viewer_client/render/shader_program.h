#pragma once
// Internal to ave_render: embedded GLSL sources and program linking. Needs a current GL context.
#include <string_view>

#include "absl/status/statusor.h"

namespace ave::viewer::internal {

// Source of an embedded shader by its path under viewer_client/render ("shaders/scene.frag.glsl");
// empty when there is none.
std::string_view EmbeddedShader(std::string_view name);

// Compiles and links a vertex + fragment program. Errors name the shader file and carry the
// driver's info log. The GL object name is returned as unsigned int to keep GL headers out.
absl::StatusOr<unsigned int> BuildProgram(std::string_view vertex_name, std::string_view vertex_source,
                                          std::string_view fragment_name, std::string_view fragment_source);

// BuildProgram on two embedded shaders. `fragment_defines` ("#define LIVE\n...") is inserted after
// the fragment shader's #version line: one source, several specialised programs (llvmpipe runs
// both sides of a branch on a uniform, so a feature a pass does not use is compiled out instead).
absl::StatusOr<unsigned int> BuildEmbeddedProgram(std::string_view vertex_name, std::string_view fragment_name,
                                                  std::string_view fragment_defines = {});

}  // namespace ave::viewer::internal
