#include "viewer_client/render/passes/point_pass.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {

// Every fixed-function state change of the point pass: depth tested against the resolved scene
// (points on a surface pass) and written, scissored to the view; the size comes from the shader.
void PointPass::ApplyState() {
  ResetPassState();
  glEnable(GL_SCISSOR_TEST);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDepthMask(GL_TRUE);
  glEnable(GL_PROGRAM_POINT_SIZE);
}

absl::StatusOr<std::unique_ptr<PointPass>> PointPass::Create() {
  absl::StatusOr<Program> program = Program::Build("shaders/point.vert.glsl", "shaders/line.frag.glsl", "",
                                                   {"u_clip_from_local", "u_point_size_px"});
  if (!program.ok()) return program.status();
  GLfloat range[2] = {1, 1};
  glGetFloatv(GL_POINT_SIZE_RANGE, range);
  return std::unique_ptr<PointPass>(new PointPass(*std::move(program), std::max(1.0f, range[1])));
}

absl::Status PointPass::Set(const PointCloud& cloud) {
  if (cloud.colors.size() != cloud.positions_local_m.size()) {
    return absl::InvalidArgumentError("SetPointCloud: " + std::to_string(cloud.positions_local_m.size()) +
                                      " positions but " + std::to_string(cloud.colors.size()) + " colours");
  }
  if (!(cloud.point_size_px >= 1 && cloud.point_size_px <= 64)) {
    return absl::InvalidArgumentError("SetPointCloud: point_size_px " + std::to_string(cloud.point_size_px) +
                                      " must be in 1..64");
  }
  std::vector<LineVertex> vertices(cloud.positions_local_m.size());
  for (size_t k = 0; k < vertices.size(); ++k) {
    const Eigen::Vector3f& p = cloud.positions_local_m[k];
    const Eigen::Vector3f& c = cloud.colors[k];
    if (!p.allFinite() || !c.allFinite()) {
      return absl::InvalidArgumentError("SetPointCloud: point " + std::to_string(k) + " is not finite");
    }
    vertices[k] = LineVertex{{p.x(), p.y(), p.z()}, {c.x(), c.y(), c.z()}};
  }
  point_size_px_ = std::min(cloud.point_size_px, max_point_size_);
  if (vertices.empty() && points_.count() == 0) return absl::OkStatus();  // nothing before, nothing now
  points_.Upload(vertices, GL_DYNAMIC_DRAW);
  return absl::OkStatus();
}

void PointPass::Draw(const FrameContext& /*frame*/, const View& view, const ViewFrame& seen) {
  if (points_.count() == 0 || !view.draw_points) return;
  ApplyState();
  glBindFramebuffer(GL_FRAMEBUFFER, seen.target);
  glUseProgram(program_.id);
  glUniformMatrix4fv(program_.u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
  glUniform1f(program_.u["u_point_size_px"], point_size_px_);
  points_.Draw(GL_POINTS);
  glDisable(GL_PROGRAM_POINT_SIZE);
}

}  // namespace ave::viewer::internal
