#pragma once
// Internal to ave_render: the line pass, drawn over each resolved view with depth test: projector
// frustum wireframes (the view's highlighted camera brighter and thicker) and object paths.
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "viewer_client/render/passes/cameras.h"
#include "viewer_client/render/passes/gl_util.h"

namespace ave::viewer::internal {

class LinePass {
 public:
  static absl::StatusOr<std::unique_ptr<LinePass>> Create();

  // Renderer::SetPaths: validates (the error names the path and point) and keeps the segments.
  absl::Status SetPaths(const std::vector<Polyline>& paths);
  // The view's frustums (View::draw_frustums) and paths (View::draw_paths) into the bound
  // framebuffer, within the scissor box.
  void Draw(const View& view, const CameraSet& cameras);

 private:
  LinePass(Program program, float max_line_width)
      : program_(std::move(program)), lines_(/*with_normals=*/false, /*indexed=*/false),
        max_line_width_(max_line_width) {}
  static void ApplyState();

  Program program_;
  MeshBuffers lines_;
  float max_line_width_;
  std::vector<LineVertex> path_vertices_;
};

}  // namespace ave::viewer::internal
