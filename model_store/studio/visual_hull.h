#pragma once
// Visual hull by voxel carving (i4D §4 step 3; Laurentini's visual hull, the paper's ref [11]),
// hierarchical: cells of an octree are projected into every camera as pixel rectangles and
// tested against each silhouette's integral image; a cell that is surely empty or surely full is
// decided whole, only boundary cells are split, down to `voxel_m`.
//
// Vote rule (tolerance for a few bad silhouettes): a voxel survives when at most
// max_background_votes cameras see its centre as background and at least
// max(min_views, ceil(min_view_fraction * cameras)) cameras see it at all (the capture volume:
// space that few cameras see, outside the ring, is not the actor's). A camera whose image does
// not contain the voxel (or that it is behind) does not vote.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include "absl/status/statusor.h"

#include "model_store/studio/studio_types.h"

namespace ave::studio {

struct HullOptions {
  double voxel_m = 0.01;          // finest voxel edge, (0.001, 1]
  int max_background_votes = 1;   // >= 0: cameras that may call a voxel background and not carve it
  int min_views = 2;              // >= 1: cameras that must see a voxel for it to survive
  double min_view_fraction = 0.75;  // [0, 1]: and this share of all cameras
  bool hierarchical = true;       // false: test every voxel of the bounds (the flat peer)
  // After the tolerant carve, a camera calling more than this share of the surviving voxels
  // background is taken for a bad silhouette and ignored (at most max_background_votes of them,
  // the worst first), and the other cameras carve the
  // survivors strictly (no tolerance): the tolerance then costs no accuracy when every camera is
  // good. > 1 turns it off (the tolerant hull is kept as it is).
  double bad_camera_fraction = 0.2;
  // Working volume (studio world, metres). Empty: the box of the camera centres in x and y, from
  // floor_z_m up to the highest camera (an error when that box is flat, e.g. collinear cameras).
  Eigen::AlignedBox3d bounds_m;
  double floor_z_m = 0;
  std::string Check() const;
};

// Occupancy on a regular grid; voxel (x, y, z) spans origin_m + voxel_m * [x, x + 1) etc. The grid
// is the hull's bounding box with one empty voxel all round, so a surface extracted from it closes.
struct VoxelGrid {
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  double voxel_m = 0;
  Eigen::Vector3i size = Eigen::Vector3i::Zero();
  std::vector<uint8_t> occupied;  // 1 = inside; index x + size.x * (y + size.y * z)

  size_t Index(int x, int y, int z) const { return static_cast<size_t>(x) + static_cast<size_t>(size.x()) * (y + static_cast<size_t>(size.y()) * z); }
  Eigen::Vector3d Center(int x, int y, int z) const { return origin_m + voxel_m * Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5); }
  int64_t Count() const;
};

struct HullStats {
  int64_t cells_tested = 0;   // octree cells projected (all levels above the finest)
  int64_t voxels_tested = 0;  // finest voxels whose centre was projected
  std::vector<std::string> bad_cameras;  // ignored by the strict pass (bad_camera_fraction)
};

// The working volume the cameras enclose (HullOptions::bounds_m when empty); an error names the
// flat axis when the cameras span no volume.
absl::StatusOr<Eigen::AlignedBox3d> BoundsFromCameras(const std::vector<StudioCameraModel>& cameras, double floor_z_m);

// One silhouette per camera, each the camera's size. An empty hull is not an error (the grid is
// then a single empty voxel's neighbourhood at the bounds' centre; Count() == 0).
absl::StatusOr<VoxelGrid> CarveVisualHull(const std::vector<StudioCameraModel>& cameras, const std::vector<Mask>& silhouettes,
                                          const HullOptions& options, HullStats* stats = nullptr);

}  // namespace ave::studio
