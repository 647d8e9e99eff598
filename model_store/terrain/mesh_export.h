#pragma once
// Terrain tessellation and file export (MISSION part A: "tessellate into a mesh (simplify flat
// areas) ... height fields stored as OpenEXR float images; meshes exportable as PLY, OBJ, glTF").
//
// Every export writes float positions relative to the mesh's double origin and records the origin
// in the file (PLY `comment origin`, OBJ `# origin`, glTF `asset.extras.origin`, EXR attribute
// `aveOrigin`), so large world coordinates never pass through float.
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/geometry/mesh.h"
#include "model_store/terrain/grid.h"

namespace ave::model {

struct TessellateOptions {
  // A quadtree block becomes one fan of triangles when every DTM sample inside it lies within this
  // of the bilinear surface through its corners.
  double flat_tolerance_m = 0.05;
  int max_block_cells = 32;  // power of two: the largest block side, in cells
  std::string Check() const;
};

// The DTM (grid.dtm, one vertex per cell centre) as a crack-free triangle mesh: flat blocks become
// one fan whose rim includes every vertex its finer neighbours use (no T-junction gaps).
// Material kTerrain, object -1, origin = grid.origin. Empty mesh when the grid has no DTM.
TriangleMesh TessellateDtm(const HeightGrid& grid, const TessellateOptions& options = {});

// Mesh files, chosen by extension: .ply (binary little-endian), .obj, .gltf (glTF 2.0, buffer
// embedded as a base64 data URI), .glb (binary glTF 2.0). These are derived products, never a
// rewrite of the user's point cloud (that is las_rewrite.h), so they have their own fixed layout:
// metres whatever the survey's unit (the reader applied it), positions as float relative to the
// origin, which is written at full precision in a "comment origin X Y Z" line (PLY), a comment
// (OBJ) or asset.extras.origin (glTF); no CRS. PLY: vertex float x y z, then float nx ny nz and
// uchar red green blue when the mesh has them, then face lists (uchar count, uint indices).
absl::Status WriteMesh(const TriangleMesh& mesh, const std::string& path);
absl::StatusOr<std::string> EncodeGltf(const TriangleMesh& mesh, bool binary);

// Height grid as a 32-bit float OpenEXR image: channel "Z" the DTM, "DSM" the per-cell maximum
// (NaN where empty); image row 0 is the grid's northernmost row. Attributes carry the origin,
// corner and resolution so ReadHeightExr restores the grid's geometry.
absl::Status WriteHeightExr(const HeightGrid& grid, const std::string& path);
// Restores origin, min_xy, resolution, cols, rows, dtm and zmax.
absl::StatusOr<HeightGrid> ReadHeightExr(const std::string& path);

}  // namespace ave::model
