#pragma once
// One studio frame set (13 simultaneous images) to a textured mesh, the i4D §4 chain:
// segmentation with shadow removal -> visual hull -> marching cubes -> texture per triangle.
#include <string>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/avatar/avatar_sequence.h"
#include "model_store/studio/segmentation.h"
#include "model_store/studio/studio_types.h"
#include "model_store/studio/surface.h"
#include "model_store/studio/texture.h"
#include "model_store/studio/visual_hull.h"

namespace ave::studio {

struct ReconstructOptions {
  SegmentationOptions segmentation;
  HullOptions hull;
  SurfaceOptions surface;
  TextureOptions texture;
  std::string Check() const;  // the first bad field, prefixed by its part
};

struct FrameSetCost {  // CPU ms of the calling thread per step
  double segment_ms = 0, hull_ms = 0, surface_ms = 0, texture_ms = 0;
  double TotalMs() const { return segment_ms + hull_ms + surface_ms + texture_ms; }
};

struct FrameSetResult {
  std::vector<Mask> silhouettes;  // one per camera
  VoxelGrid hull;
  SurfaceMesh surface;
  avatar::AvatarFrame textured;   // positions in studio world
  HullStats hull_stats;
  TextureStats texture_stats;
  FrameSetCost cost;
};

// `images` and `backgrounds` one per camera, each the camera's size (errors name the camera).
absl::StatusOr<FrameSetResult> ReconstructFrameSet(const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                                                   const std::vector<Image>& backgrounds, const ReconstructOptions& options);

// The same from silhouettes already made (truth masks in tests and benches).
absl::StatusOr<FrameSetResult> ReconstructFromSilhouettes(const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                                                          std::vector<Mask> silhouettes, const ReconstructOptions& options);

}  // namespace ave::studio
