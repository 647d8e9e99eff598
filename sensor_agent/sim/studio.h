#pragma once
// Simulated multi-camera 4D studio (i4D §4: 13 calibrated cameras on a ring around one actor,
// plus an optional overhead view): a walking articulated figure (torso, head, two-segment arms
// and legs swinging with a walk cycle, walking on a small circle) rendered by a CPU rasteriser,
// with a silhouette mask per image. The figure's parts are rounded closed convex solids (a
// person's body, the default) or axis-aligned boxes on the same skeleton (StudioActor::kBoxes:
// the visual hull's hard case, flat faces between the ring's views). The image also shows the
// actor's floor shadow from a key light; the shadow is NOT in the silhouette, so shadow removal
// has something to remove.
//
// Frames: studio world is metric, z up, floor at z = 0, actor walking around the origin. Cameras
// follow OpenCV (camera.h); poses are world_from_camera. Files: docs/SIMULATOR_FORMATS.md.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include "absl/status/status.h"

#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/sim/effects.h"

namespace ave::sim {

// The actor's body on the one skeleton and walk: kBody, each part (torso, neck, head, upper and
// lower arms and legs, shoes) a closed convex solid with an elliptic 20-gon cross-section, rounded
// ends and limbs tapering a little; kBoxes, each part a box (the earlier actor).
enum class StudioActor { kBody, kBoxes };
const char* StudioActorName(StudioActor actor);                 // "body", "boxes"
std::optional<StudioActor> ParseStudioActor(std::string_view name);  // nullopt for any other name

struct StudioSpec {
  int cameras = 13;       // on the ring, [1, 64]
  double radius_m = 4;    // ring radius, (1, 50]
  bool overhead = true;   // one more camera straight above, looking down
  double fps = 10;        // (0, 120]
  double duration_s = 2;  // >= 0; floor(duration_s * fps) frames, at least one
  int width = 640, height = 480;
  StudioActor actor = StudioActor::kBody;
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

struct StudioCamera {
  std::string id;  // "ring00".."ring12", "overhead"
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;
};

// The studio's calibrated cameras (ring first, then the overhead one).
std::vector<StudioCamera> StudioCameras(const StudioSpec& spec);

// The actor at t_s as a triangle mesh in studio world coordinates (origin zero): one closed,
// convex, outward-wound part after another (parts share no vertex; they overlap at the joints).
TriangleMesh StudioActorMesh(double t_s, StudioActor actor = StudioActor::kBody);

struct StudioView {
  int width = 0, height = 0;
  std::vector<uint8_t> bgr;          // 3 bytes per pixel, top row first
  std::vector<uint8_t> silhouette;   // 255 where the actor covers the pixel centre, else 0
  std::vector<uint8_t> shadow;       // 255 where the actor's floor shadow shows (never in silhouette)
};

// The actor's state at t_s (truth): pelvis ground point, heading (direction of travel from +x,
// counter-clockwise) and walk-cycle phase in [0, 2π).
struct StudioActorState {
  Eigen::Vector3d ground_m = Eigen::Vector3d::Zero();
  double heading_rad = 0;
  double phase_rad = 0;
};
StudioActorState StudioActorAt(double t_s);

// The key light: unit direction towards it (studio world). The floor shadow falls opposite.
Eigen::Vector3d StudioLightDirection();

// One camera's view at t_s: the render, then illumination and camera_noise when named (the
// camera pipeline's effect functions, camera_effects.h; frame_index seeds them). Deterministic.
StudioView RenderStudioView(const StudioCamera& camera, const EffectSet& effects, uint64_t seed, int64_t frame_index, double t_s,
                            StudioActor actor = StudioActor::kBody);

// The empty studio seen by one camera (the background plate a real studio records before the
// actor walks in): the same render and effects, no actor and no shadow.
StudioView RenderStudioBackground(const StudioCamera& camera, const EffectSet& effects, uint64_t seed);

// Writes calibration.json, per camera <camera>/background.png (RenderStudioBackground) and, per
// camera and frame, <camera>/image_NNNN.png and
// <camera>/mask_NNNN.png into `out_dir`, of spec.actor. Nothing is written when the spec is unusable.
absl::Status SimulateStudio(const StudioSpec& spec, const EffectSet& effects, uint64_t seed, const std::string& out_dir);

}  // namespace ave::sim
