#include "viewer_client/render/passes/line_pass.h"

#include <algorithm>
#include <string>

#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {
namespace {

constexpr float kHighlightLineWidth = 3.0f;

}  // namespace

// Every fixed-function state change of the line pass: depth tested (lines on surfaces pass) and
// written, scissored to the view.
void LinePass::ApplyState() {
  ResetPassState();
  glEnable(GL_SCISSOR_TEST);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDepthMask(GL_TRUE);
}

absl::StatusOr<std::unique_ptr<LinePass>> LinePass::Create() {
  absl::StatusOr<Program> program =
      Program::Build("shaders/line.vert.glsl", "shaders/line.frag.glsl", "", {"u_clip_from_local"});
  if (!program.ok()) return program.status();
  GLfloat line_range[2] = {1, 1};
  glGetFloatv(GL_ALIASED_LINE_WIDTH_RANGE, line_range);
  return std::unique_ptr<LinePass>(new LinePass(*std::move(program), line_range[1]));
}

absl::Status LinePass::SetPaths(const std::vector<Polyline>& paths) {
  std::vector<LineVertex> vertices;
  for (size_t k = 0; k < paths.size(); ++k) {
    const Polyline& path = paths[k];
    if (!path.color.allFinite()) return absl::InvalidArgumentError("SetPaths: path " + std::to_string(k) + " color");
    for (size_t j = 0; j + 1 < path.points.size(); ++j) {
      if (!path.points[j].allFinite() || !path.points[j + 1].allFinite()) {
        return absl::InvalidArgumentError("SetPaths: path " + std::to_string(k) + " point " + std::to_string(j) +
                                          " is not finite");
      }
      vertices.push_back(MakeLineVertex(path.points[j], path.color));
      vertices.push_back(MakeLineVertex(path.points[j + 1], path.color));
    }
  }
  path_vertices_ = std::move(vertices);
  return absl::OkStatus();
}

void LinePass::Draw(const View& view, const CameraSet& cameras) {
  std::vector<LineVertex> normal_lines, highlight_lines;
  if (view.draw_frustums) {
    const std::vector<Projector>& projectors = cameras.projectors();
    for (size_t i = 0; i < projectors.size(); ++i) {
      const Projector& p = projectors[i];
      if (!p.enabled) continue;
      const bool highlight = !view.highlight_camera_id.empty() && p.camera_id == view.highlight_camera_id;
      const Eigen::Vector3f color =
          highlight ? Eigen::Vector3f(0.5f * p.color + Eigen::Vector3f::Constant(0.5f)) : p.color;
      for (const Eigen::Vector3d& q : cameras.frustums()[i]) {
        (highlight ? highlight_lines : normal_lines).push_back(MakeLineVertex(q, color));
      }
    }
  }
  if (view.draw_paths) normal_lines.insert(normal_lines.end(), path_vertices_.begin(), path_vertices_.end());
  const GLsizei normal_count = static_cast<GLsizei>(normal_lines.size());
  normal_lines.insert(normal_lines.end(), highlight_lines.begin(), highlight_lines.end());
  if (normal_lines.empty()) return;
  ApplyState();
  glUseProgram(program_.id);
  glUniformMatrix4fv(program_.u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
  lines_.Upload(normal_lines, GL_STREAM_DRAW);
  glLineWidth(1.0f);
  if (normal_count > 0) lines_.Draw(GL_LINES, 0, normal_count);
  if (!highlight_lines.empty()) {
    glLineWidth(std::min(kHighlightLineWidth, max_line_width_));
    lines_.Draw(GL_LINES, normal_count, static_cast<GLsizei>(highlight_lines.size()));
    glLineWidth(1.0f);
  }
}

}  // namespace ave::viewer::internal
