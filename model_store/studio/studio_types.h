#pragma once
// Vocabulary of the 4D studio reconstruction (i4D §4): calibrated cameras, 8-bit images and
// silhouette masks. Frames follow docs/ARCHITECTURE.md: studio world in metres, z up, floor at
// floor_z_m; cameras are OpenCV pinholes with world_from_camera poses (geometry/camera.h).
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"

namespace ave::studio {

struct StudioCameraModel {
  std::string id;  // names the camera in every error ("ring03")
  PinholeIntrinsics intrinsics;  // distortion must be zero (undistort first)
  Rigid3d world_from_camera;
};

// BGR, 8 bits a channel, top row first.
struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> bgr;
};

// 255 where the actor (foreground) is, else 0; top row first.
struct Mask {
  int width = 0, height = 0;
  std::vector<uint8_t> data;
};

// A closed triangle mesh in studio world coordinates (metres), counter-clockwise outward.
struct SurfaceMesh {
  std::vector<Eigen::Vector3f> positions_m;
  std::vector<Eigen::Vector3f> normals;  // unit, per vertex
  std::vector<uint32_t> indices;         // three per triangle
  size_t TriangleCount() const { return indices.size() / 3; }
};

}  // namespace ave::studio
