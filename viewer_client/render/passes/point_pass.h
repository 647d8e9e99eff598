#pragma once
// Internal to ave_render: the point pass (issue 16), drawn over each resolved view like the lines:
// GL_POINTS of a point cloud (LiDAR foreground points), one colour per point, a fixed size in
// pixels, depth tested against the scene (buildings hide them); they receive no video.
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "viewer_client/render/passes/frame.h"
#include "viewer_client/render/passes/gl_util.h"

namespace ave::viewer::internal {

class PointPass {
 public:
  static absl::StatusOr<std::unique_ptr<PointPass>> Create();

  // Renderer::SetPointCloud: validates (the error names the point) and uploads once; an empty
  // cloud draws nothing.
  absl::Status Set(const PointCloud& cloud);
  // The points into the bound framebuffer, within the scissor box (View::draw_points).
  void Draw(const FrameContext& frame, const View& view, const ViewFrame& seen);
  size_t size() const { return static_cast<size_t>(points_.count()); }

 private:
  PointPass(Program program, float max_point_size)
      : program_(std::move(program)), points_(/*with_normals=*/false, /*indexed=*/false),
        max_point_size_(max_point_size) {}
  static void ApplyState();

  Program program_;
  MeshBuffers points_;  // LineVertex layout: position, colour
  float max_point_size_;
  float point_size_px_ = 1;
};

}  // namespace ave::viewer::internal
