#pragma once
// A simulation scenario (docs/SCENARIOS.md): the site (scene part, model_store/scene/scene_file.h)
// plus what the simulator needs beyond it: the seed, the effects the scene calls for (MISSION
// standing demand 3: only these ever run) and the sensors to simulate (GPS/IMU carriers, rotating
// and airborne LiDAR, a multi-camera studio).
//
// Errors name the file, line and field: "campus.yaml:42: cameras[3].fps: must be > 0".
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/sim/airborne_lidar.h"
#include "sensor_agent/sim/effects.h"
#include "sensor_agent/sim/gps_imu.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/studio.h"

namespace ave::sim {

struct Scenario {
  std::string name;
  std::string label;  // what errors and outputs call the file ("campus.yaml", "/path/x.yaml")
  uint64_t seed = 0;
  scene::SyntheticCampus world;
  EffectSet effects;
  // Effects limited to some cameras (the entry's `cameras:` list); absent: every camera.
  std::map<EffectKind, std::vector<std::string>> effect_cameras;
  std::vector<GpsImuSpec> gps_imu;
  std::vector<RotatingLidarSpec> rotating_lidars;
  std::optional<AirborneLidarSpec> airborne_lidar;
  std::optional<StudioSpec> studio;

  // The effects that apply to one camera's images.
  EffectSet EffectsForCamera(const std::string& camera_id) const;
};

// `name_or_path`: a bundled scenario name (campus, courtyard, studio, minimal) or a .yaml path.
absl::StatusOr<Scenario> LoadScenario(const std::string& name_or_path);
// `name` labels errors (usually the file name).
absl::StatusOr<Scenario> LoadScenarioText(const std::string& text, const std::string& name);

// Parameter names each effect accepts (for validation and docs); empty: not checked here.
std::vector<std::string> KnownEffectParams(EffectKind kind);

}  // namespace ave::sim
