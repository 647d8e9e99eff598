#pragma once
// Texture per triangle (i4D §4 step 5, after the paper's ref [7]): each triangle takes the camera
// that sees it best (largest cos(view angle) x projected area in pixels) among the cameras that
// see it at all (its centre not behind the mesh in that camera's depth buffer, so the back of the
// actor is never textured from a front camera). Neighbouring triangles with the same camera form
// a chart; each chart's pixel rectangle is copied from its camera image into one atlas (shelf
// packing) and vertices get uv into it, duplicated where charts meet (avatar_sequence.h).
#include <string>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/avatar/avatar_sequence.h"
#include "model_store/studio/studio_types.h"

namespace ave::studio {

struct TextureOptions {
  double depth_tolerance_m = 0.03;  // a triangle centre this far behind the depth buffer still counts as seen
  int chart_padding_px = 2;         // pixels around each chart (bilinear filtering never bleeds)
  int max_atlas_width = 2048;       // texels; the atlas grows downwards
  std::string Check() const;
};

struct TextureStats {
  int charts = 0;
  int triangles_unseen = 0;  // no camera sees them (textured from the best facing camera anyway)
  std::vector<int> triangles_per_camera;
};

// `images` one per camera, each the camera's size. The result's positions are studio world.
absl::StatusOr<avatar::AvatarFrame> TextureMesh(const SurfaceMesh& mesh, const std::vector<StudioCameraModel>& cameras,
                                                const std::vector<Image>& images, const TextureOptions& options,
                                                TextureStats* stats = nullptr);

}  // namespace ave::studio
