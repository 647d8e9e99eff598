#pragma once
// A small z-buffer rasteriser of a triangle mesh into one studio camera (CPU, pixel centres):
// the visibility test of texturing (which camera sees a triangle) and the re-render of a
// textured mesh that ave-bench studio compares with the camera's image.
#include <cstdint>
#include <vector>

#include "model_store/avatar/avatar_sequence.h"
#include "model_store/studio/studio_types.h"

namespace ave::studio {

struct RasterBuffers {
  int width = 0, height = 0;
  std::vector<float> depth_m;      // camera z of the nearest surface, +inf where none
  std::vector<int32_t> triangle;   // its triangle index, -1 where none
};

// Positions in studio world coordinates; triangles within 5 cm of the camera plane are skipped.
RasterBuffers Rasterize(const StudioCameraModel& camera, const std::vector<Eigen::Vector3f>& positions_m,
                        const std::vector<uint32_t>& indices);

// The textured mesh (positions in studio world) as `camera` sees it, bilinear in the atlas;
// `covered` (optional) gets 255 where the mesh covers the pixel.
Image RenderTextured(const StudioCameraModel& camera, const avatar::AvatarFrame& mesh, Mask* covered = nullptr);

}  // namespace ave::studio
