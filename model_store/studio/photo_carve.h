#pragma once
// Photo-consistency carving of a visual hull (space carving, Kutulakos and Seitz 2000): a surface
// voxel whose colour disagrees between the cameras that see it (visibility from each camera's
// depth buffer of the current surface voxels) is not on the actor and is removed; repeated for
// a few passes, each exposing the next layer.
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/studio/studio_types.h"
#include "model_store/studio/visual_hull.h"

namespace ave::studio {

struct PhotoCarveOptions {
  int passes = 0;                 // [0, 64]; 0 turns it off
  double max_std_levels = 10;     // > 0: colour standard deviation (8-bit levels, mean of B, G, R)
  int min_cameras = 3;            // >= 2: a voxel seen by fewer is kept
  std::string Check() const;
};

// Carves `grid` in place; returns the voxels removed. Images one per camera, each its size (an
// error names the camera).
absl::StatusOr<int64_t> PhotoCarve(VoxelGrid& grid, const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                   const PhotoCarveOptions& options);

}  // namespace ave::studio
