#pragma once
// Files of the studio: the calibration ave-sim studio writes (docs/SIMULATOR_FORMATS.md, format
// "ave-studio-calibration-1"), PNG images, and a textured mesh as OBJ + MTL + PNG atlas.
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/avatar/avatar_sequence.h"
#include "model_store/studio/studio_types.h"

namespace ave::studio {

struct StudioCalibration {
  double fps = 0;
  int frames = 0;
  double floor_z_m = 0;
  std::vector<StudioCameraModel> cameras;
};

// Errors name the file and the field (and the camera's index or id).
absl::StatusOr<StudioCalibration> ReadStudioCalibration(const std::string& path);

// An 8-bit colour (BGR) or grey image; errors name the file.
absl::StatusOr<Image> ReadColourPng(const std::string& path);
absl::StatusOr<Mask> ReadMaskPng(const std::string& path);
absl::Status WritePng(const std::string& path, const Image& image);

// <dir>/<stem>.obj, <stem>.mtl and <stem>.png (the atlas). OBJ texture v runs up, so v_obj = 1 - v.
absl::Status WriteTexturedObj(const avatar::AvatarFrame& mesh, const std::string& dir, const std::string& stem);

}  // namespace ave::studio
