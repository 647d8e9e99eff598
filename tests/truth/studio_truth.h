#pragma once
// The simulated 4D studio (sensor_agent/sim/studio.h) as model_store/studio's input, and scorers
// of what the studio reconstructs against the simulator's truth (the actor's true mesh and
// silhouettes). Tests and benches only: it links the simulator.
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/geometry/mesh.h"
#include "model_store/studio/studio_types.h"
#include "model_store/studio/visual_hull.h"
#include "sensor_agent/sim/studio.h"

namespace ave::studio::testing {

struct SimulatedFrameSet {
  double t_s = 0;
  std::vector<StudioCameraModel> cameras;
  std::vector<Image> images;            // the camera images (shadow in them)
  std::vector<Image> backgrounds;       // each camera's empty-studio plate
  std::vector<Mask> truth_silhouettes;  // the simulator's masks (no shadow)
  TriangleMesh truth_mesh;              // StudioActorMesh(t_s, actor), studio world
  sim::StudioActor actor = sim::StudioActor::kBody;
};

// Frame `frame` of the bundled "studio" scenario (its spec, effects and seed). `cameras` > 0
// overrides the ring's camera count (the overhead camera stays); `actor` the scenario's actor.
absl::StatusOr<SimulatedFrameSet> SimulateStudioFrameSet(int frame, int cameras = 0, std::optional<sim::StudioActor> actor = std::nullopt);

// Occupancy IoU of the hull against the true mesh voxelised on the same voxel lattice (a voxel
// is inside the truth when its centre is inside at least one of the mesh's closed parts, each by
// the parity of its crossings along +z: overlapping limb boxes count once, whatever their winding).
double HullVolumeIoU(const VoxelGrid& hull, const TriangleMesh& truth);

// The truth's occupancy (that winding-number test) on `lattice`'s voxel lattice, over the box of
// both the lattice's grid and the truth (so the grid may start before lattice.origin_m).
VoxelGrid TruthOccupancy(const VoxelGrid& lattice, const TriangleMesh& truth);

// A mesh's silhouette in one camera by the simulator's rule (a pixel is covered when its centre
// is inside a projected triangle, either winding); the mesh must be in front of the camera.
Mask RenderSilhouette(const StudioCameraModel& camera, const TriangleMesh& mesh);

// An upright prism of `sides` sides (a box for 4, a near-cylinder for many) standing on the floor
// at `centre`, corners at `radius_m`, the first at `yaw_rad`: a convex actor.
TriangleMesh UprightPrism(const Eigen::Vector2d& centre, double radius_m, double height_m, int sides, double yaw_rad);

// The closed parts of a mesh (triangles sharing vertices): the actor's body parts or boxes.
std::vector<TriangleMesh> MeshParts(const TriangleMesh& mesh);

// Symmetric Chamfer distance in millimetres: the mean over both directions of the mean distance
// from area-uniform surface samples of one surface to the other (the truth's faces inside
// another limb part are not its surface and are left out).
double ChamferMm(const SurfaceMesh& mesh, const TriangleMesh& truth, int samples = 20000);

}  // namespace ave::studio::testing
