#pragma once
// Visual hull voxels to a closed triangle mesh (i4D §4 step 4): marching cubes (Lorensen and
// Cline 1987, the paper's ref [12]) on the occupancy, optionally box-smoothed first so the
// surface is not a staircase. Two implementations measured side by side (ave-bench studio):
// our own (marching_cubes.cc, Bourke's tables, shared edge vertices) and VTK's
// vtkFlyingEdges3D / vtkMarchingCubes (surface_vtk.cc, the only file that includes VTK).
#include <string>

#include "absl/status/statusor.h"

#include "model_store/studio/studio_types.h"
#include "model_store/studio/visual_hull.h"

namespace ave::studio {

// Whether this build has VTK (the kVtk* methods return Unimplemented without it).
bool VtkSurfaceAvailable();

enum class SurfaceMethod { kOwnMarchingCubes, kVtkFlyingEdges, kVtkMarchingCubes };

struct SurfaceOptions {
  // VTK's flying edges where built in: ~15-20 % faster than ours on the same voxels, the same
  // triangles (ave-bench studio); ours otherwise.
  SurfaceMethod method = VtkSurfaceAvailable() ? SurfaceMethod::kVtkFlyingEdges : SurfaceMethod::kOwnMarchingCubes;
  int smooth_passes = 1;  // 3x3x3 box filter passes on the occupancy before the iso-surface, [0, 4]
  std::string Check() const;
};

// The iso-surface at 0.5 of the (smoothed) occupancy, counter-clockwise outward, with area-weighted
// vertex normals. The grid's empty border keeps it closed: every edge has exactly two triangles.
absl::StatusOr<SurfaceMesh> ExtractSurface(const VoxelGrid& grid, const SurfaceOptions& options);

// --- parts, shared by the implementations ---
// The occupancy as floats after `passes` box-filter passes.
std::vector<float> SmoothedOccupancy(const VoxelGrid& grid, int passes);
// Own marching cubes over a scalar field on the grid's voxel centres (x fastest).
SurfaceMesh MarchingCubes(const std::vector<float>& field, const VoxelGrid& grid, float iso);
// VTK on the same field (surface_vtk.cc).
absl::StatusOr<SurfaceMesh> VtkIsoSurface(const std::vector<float>& field, const VoxelGrid& grid, float iso, bool flying_edges);
// Orients triangles outward (by the signed volume) and sets area-weighted vertex normals.
void OrientAndSetNormals(SurfaceMesh& mesh);

}  // namespace ave::studio
