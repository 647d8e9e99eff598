#pragma once
// Camera effects of the simulator (issue 3; MISSION standing demand 3), each a separate function
// that starts with CountEvaluation(its kind) and is called only when the scenario names it:
//
//   effect              params (default)                         what it does
//   camera_noise        sigma (2.0 grey levels)                  zero-mean Gaussian sensor noise per channel
//   illumination        amplitude (0.15), period_s (20)          exposure gain 1 + amplitude * c(t), c a smooth
//                                                                 seeded "passing clouds" signal in [-1, 1]
//   jpeg_artefacts      quality (70, 1..100)                     JPEG encode + decode (OpenCV, libjpeg)
//   rolling_occlusion   period_s (30), duration_s (3),           a dark occluder (a passer-by close to the lens)
//                       width_frac (0.2)                         sweeps left to right for duration_s every period_s
//   waving_vegetation   amplitude_m (0.3), frequency_hz (0.4),   tree crowns sway with time (renderer side: the
//                       wind_deg (30)                            crown geometry moves, masks follow)
//   pixel_area          samples (3, per axis, 1..5)              each pixel integrates the light over its area: the
//                                                                 render is samples x samples finer and box-averaged
//                                                                 down (cv::resize INTER_AREA); ids, classes and
//                                                                 depths are the centre sample's (renderer side)
//
// SimulatedCamera is the camera pipeline: render (sim_camera.h, with waving_vegetation inside)
// -> lens distortion (a camera property, not an effect: the ideal render is warped by the
// intrinsics' Brown-Conrady coefficients, masks by nearest neighbour) -> pixel_area (render and lens
// work `samples` times finer, then each pixel averages its block) -> rolling_occlusion ->
// illumination -> camera_noise -> jpeg_artefacts. Frame k's random numbers come from (seed, k) only, so a frame is the same
// whenever it is rendered. With no effects and no distortion a frame is exactly the render.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "model_store/scene/campus.h"
#include "sensor_agent/sim/effects.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::sim {

// Seed of frame `frame_index` of a camera (splitmix64 of the two).
uint64_t FrameSeed(uint64_t seed, int64_t frame_index);

void ApplyCameraNoise(const EffectParams& params, uint64_t frame_seed, SimImage& image);
void ApplyIllumination(const EffectParams& params, uint64_t seed, double t_s, SimImage& image);
void ApplyJpegArtefacts(const EffectParams& params, SimImage& image);
void ApplyRollingOcclusion(const EffectParams& params, uint64_t seed, double t_s, SimImage& image);
// pixel_area: `fine` rendered `samples` times finer on each axis (width * samples wide) -> the
// width x height image whose pixels are the means of their samples x samples fine pixels.
SimImage AveragePixelArea(const SimImage& fine, int samples, int width, int height);

// A tree crown's vertices in a renderer's vertex array.
struct SwayingCrown {
  size_t first_vertex = 0, end_vertex = 0;
  float bottom_z = 0, height_m = 1;  // the crown's vertical extent (weights grow from 0 to 1 up it)
  float phase_rad = 0;
};
// Writes the swayed crown vertices into `positions` (which holds the rest positions `rest` for
// every vertex on entry; only crown vertices change). Waving vegetation, renderer side.
void SwayVegetation(const EffectParams& params, double t_s, const std::vector<Eigen::Vector3f>& rest,
                    const std::vector<SwayingCrown>& crowns, std::vector<Eigen::Vector3f>& positions);

// The exposure gain illumination applies at t_s (for tests and truth files).
double IlluminationGain(const EffectParams& params, uint64_t seed, double t_s);

class SimulatedCamera {
 public:
  // `effects` as the scenario names them for this camera; `seed` the scenario's.
  SimulatedCamera(const scene::SyntheticCampus& campus, const scene::CameraSpec& camera, const EffectSet& effects,
                  uint64_t seed, RendererOptions renderer_options = {});
  SimulatedCamera(SimulatedCamera&&) noexcept;
  SimulatedCamera& operator=(SimulatedCamera&&) noexcept;
  ~SimulatedCamera();

  // Frame `frame_index` at scene time t_s with the camera's true pose at t_s.
  SimImage Frame(int64_t frame_index, double t_s) const;
  // The camera's true world_from_camera (local frame) at t_s.
  Rigid3d PoseAt(double t_s) const;
  const scene::CameraSpec& camera() const;

  // Per-stage wall time of the last Frame() call, seconds (render first, then each effect that
  // ran, in pipeline order), for ave-bench.
  struct StageTime {
    const char* stage;
    double seconds;
  };
  const std::vector<StageTime>& last_timings() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::sim
