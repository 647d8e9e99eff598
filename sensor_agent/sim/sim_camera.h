#pragma once
// The simulated camera of the sensor agent: a deterministic single-threaded CPU rasteriser of the
// synthetic campus (terrain, roads, buildings of every primitive, trees, static objects, movers at
// time t) with per-pixel ground truth. Camera effects (noise, illumination, JPEG, occlusion, lens
// distortion) are applied after rendering by camera_effects.h; waving vegetation is renderer side.
//
// Appearance is the "real world", deliberately unlike the viewer model's flat neutral colours:
// procedural grass, asphalt with lane markings, walls with window grids, coloured roofs and
// Lambert-shaded movers, all computed from the local-frame position so the texture is stable in
// the world (features of 0.5-2 m, smooth over a few pixels so JPEG keeps them).
//
// Frames: "world" in this file is the campus's local frame (east, north, up; metres), the frame
// CameraSpec::world_from_camera is given in. Camera frame and pixel convention are OpenCV's (see
// model_store/geometry/camera.h): integer pixel coordinates are pixel centres. Lens distortion in
// the intrinsics is ignored (ideal pinhole render).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/sim/effects.h"

namespace ave::sim {

// Per-pixel object ids (SimImage::object_id):
//   kSkyId                      the pixel's ray hits nothing;
//   kGroundId                   terrain, roads included;
//   kVegetationId               any tree (trunk or crown);
//   kStaticObjectId             any static object (bench, kiosk, low wall);
//   kOccluderId                 the rolling_occlusion effect's occluder in front of the lens;
//   kBuildingIdBase + i         SyntheticCampus::buildings[i] (walls and roof), i < 999'000;
//   kMoverIdBase + Mover::id    any part of that mover (ids below 2^32 - kMoverIdBase).
// The LiDAR simulators label points with the same scheme (rotating_lidar.h).
inline constexpr uint32_t kSkyId = 0;
inline constexpr uint32_t kGroundId = 1;
inline constexpr uint32_t kVegetationId = 2;
inline constexpr uint32_t kStaticObjectId = 3;
inline constexpr uint32_t kOccluderId = 4;
inline constexpr uint32_t kBuildingIdBase = 1'000;
inline constexpr uint32_t kMoverIdBase = 1'000'000;

inline bool IsBuildingId(uint32_t id) { return id >= kBuildingIdBase && id < kMoverIdBase; }
inline bool IsMoverId(uint32_t id) { return id >= kMoverIdBase; }

// Per-pixel semantic classes (SimImage::class_id), what the class mask PNG stores.
enum class PixelClass : uint8_t {
  kSky = 0,
  kTerrain = 1,
  kRoad = 2,
  kWall = 3,
  kRoof = 4,
  kVegetation = 5,
  kStaticObject = 6,
  kPerson = 7,
  kVehicle = 8,
  kOccluder = 9,
};

struct SimImage {
  int width = 0, height = 0;
  std::vector<uint8_t> bgr;          // 3 bytes per pixel, top row first: cv::Mat(h, w, CV_8UC3, bgr.data())
  std::vector<uint32_t> object_id;   // one per pixel, see the id scheme above
  std::vector<uint8_t> class_id;     // one per pixel, a PixelClass
  std::vector<float> depth_m;        // one per pixel: z in the camera frame; +inf where the sky shows
  // The camera's compressed frame, set by the jpeg_artefacts effect (the pipeline's last stage):
  // JPEG bytes whose decoding (cv::imdecode) is exactly `bgr`. Empty without that effect; code
  // that changes `bgr` afterwards must clear it.
  std::vector<uint8_t> jpeg;

  size_t Index(int u, int v) const { return static_cast<size_t>(v) * width + u; }
};

struct RendererOptions {
  // Terrain triangle grid passed to scene::BuildStaticMesh; at 1 m the facets stay within 1 mm of the analytic hills.
  double terrain_resolution_m = 1.0;
  // Movers (people, cars) at the render time; off gives the static campus only.
  bool draw_movers = true;
  // Unit-less direction towards the sun in the local frame (normalised on use).
  Eigen::Vector3d sun_direction = Eigen::Vector3d(0.45, -0.35, 0.82);
  // Near clipping plane in the camera frame; triangles crossing it are clipped, not dropped.
  double near_m = 0.05;
  // Set: tree crowns sway with time (the waving_vegetation effect, camera_effects.h). Unset, the
  // effect's code never runs.
  std::optional<EffectParams> waving_vegetation;
  // A camera that renders the same view twice in a row (a fixed camera) keeps the raster and the
  // shading of the fixed static scene (terrain, roads, buildings, objects: everything but trees
  // and movers, which are drawn every frame) and from then on draws and shades only the trees,
  // the movers and the pixels they cover or uncover. Bit-identical to rendering everything (the
  // fixed triangles come first in the draw order and their shading does not depend on time).
  bool reuse_static_layer = true;
  // A SimulatedCamera with lens distortion renders a padded ideal image and resamples it; with this
  // set it shades only the ideal pixels that resampling reads (the bilinear neighbours and the
  // nearest pixel of each output pixel; 95 % of the padded image for the backpack lens), the
  // rest stay black sky. Bit-identical output (issue 19, the backpack camera's rate).
  bool shade_only_read_pixels = true;

  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

class CampusRenderer {
 public:
  using Options = RendererOptions;

  // Precomputes the static triangles and their material data. Throws std::invalid_argument with
  // Check()'s reason when `options` are unusable (a programmer error).
  explicit CampusRenderer(const scene::SyntheticCampus& campus, Options options = {});
  CampusRenderer(const CampusRenderer&) = delete;
  CampusRenderer& operator=(const CampusRenderer&) = delete;
  CampusRenderer(CampusRenderer&&) noexcept;
  CampusRenderer& operator=(CampusRenderer&&) noexcept;
  ~CampusRenderer();

  // Renders the campus at `t_s` seconds since the scenario start as seen by a camera at
  // `world_from_camera` (local frame). Invalid intrinsics (PinholeIntrinsics::Check) or a
  // non-finite pose give an empty image (width = height = 0). Pure: the same inputs give
  // bit-identical output.
  // `stats`, when given, receives the time spent in renderer-side effects. `shade_only`, when given
  // (one byte per pixel), restricts shading to the pixels where it is non-zero: the others keep
  // their depth but stay black with the sky's id and class (for a caller that never reads them).
  struct Stats {
    double waving_vegetation_s = 0;  // swaying the crowns (0 when the effect is off)
  };
  SimImage Render(const PinholeIntrinsics& intrinsics, const Rigid3d& world_from_camera, double t_s,
                  Stats* stats = nullptr, const std::vector<uint8_t>* shade_only = nullptr) const;

  const Options& options() const;

 private:
  struct Impl;
  std::unique_ptr<const Impl> impl_;
};

}  // namespace ave::sim
