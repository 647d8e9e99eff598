#include "sensor_agent/sim/scenario.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "model_store/scene/scene_file.h"
#include "model_store/scene/yaml_fields.h"

namespace ave::sim {
namespace {

using scene::yaml::Fail;
using scene::yaml::kUnbounded;
using scene::yaml::Map;

std::string Indexed(const std::string& list, size_t i) { return list + "[" + std::to_string(i) + "]"; }

void ParseEffects(const YAML::Node& list, Scenario& s) {
  scene::yaml::RequireSequence(list, "effects");
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string field = Indexed("effects", i);
    const YAML::Node entry = list[i];
    std::string name;
    EffectParams params;
    std::vector<std::string> cameras;
    YAML::Node name_node = entry;
    if (entry.IsScalar()) {
      name = entry.Scalar();
    } else {
      const Map m(entry, field);
      m.AllowOnly({"name", "params", "cameras"});
      name = m.String("name");
      name_node.reset(m.Get("name"));  // reset: Node::operator= would overwrite the entry itself
      if (m.Has("params")) {
        const Map pm(m.Get("params"), m.Field("params"));
        const std::optional<EffectKind> kind = EffectFromName(name);
        const std::vector<std::string> known = kind ? KnownEffectParams(*kind) : std::vector<std::string>{};
        if (!known.empty()) pm.AllowOnly(std::set<std::string>(known.begin(), known.end()));
        for (auto it = pm.node().begin(); it != pm.node().end(); ++it) {
          const std::string key = it->first.Scalar();
          params.values[key] = scene::yaml::ToNumber(it->second, pm.field() + "." + key);
        }
      }
      if (m.Has("cameras")) {
        const YAML::Node c = m.Get("cameras");
        scene::yaml::RequireSequence(c, m.Field("cameras"));
        for (size_t k = 0; k < c.size(); ++k) {
          const std::string id = c[k].IsScalar() ? c[k].Scalar() : "";
          if (!s.world.FindCamera(id)) Fail(c[k], Indexed(m.Field("cameras"), k), "no camera '" + id + "' in this scenario");
          cameras.push_back(id);
        }
      }
    }
    const std::optional<EffectKind> kind = EffectFromName(name);
    if (!kind) {
      std::string known;
      for (const auto& n : AllEffectNames()) known += (known.empty() ? "" : ", ") + n;
      Fail(name_node, field + ".name", "unknown effect '" + name + "' (known: " + known + ")");
    }
    if (s.effects.Has(*kind)) Fail(name_node, field + ".name", "effect '" + name + "' is named twice");
    // Parameters that must be positive when given.
    for (const auto& [key, value] : params.values) {
      const bool positive = key == "sigma" || key == "sigma_m" || key == "period_s" || key == "duration_s" ||
                            key == "quality" || key == "width_frac" || key == "frequency_hz";
      const YAML::Node where = entry.IsMap() ? entry["params"][key] : entry;
      if (positive && !(value > 0)) Fail(where, field + ".params." + key, "must be > 0");
      if (!positive && key != "wind_deg" && key != "start_s" && value < 0) Fail(where, field + ".params." + key, "must be >= 0");
      if (*kind == EffectKind::kPixelArea && key == "samples" && !(value == std::floor(value) && value >= 1 && value <= kMaxPixelAreaSamples))
        Fail(where, field + ".params." + key, "must be a whole number of samples per axis from 1 to " + std::to_string(kMaxPixelAreaSamples));
    }
    s.effects.Enable(*kind, params);
    if (!cameras.empty()) s.effect_cameras[*kind] = cameras;
  }
}

// [x, y] + height_above_ground_m, or [x, y, z].
Eigen::Vector3d PlacedPoint(const Map& m, const scene::SyntheticCampus& world, double default_height) {
  const std::vector<double> v = m.Numbers("position", 2, 3);
  if (v.size() == 3) {
    if (m.Has("height_above_ground_m")) Fail(m.Get("height_above_ground_m"), m.Field("height_above_ground_m"), "give position as [x, y] with a height above ground, or [x, y, z], not both");
    return {v[0], v[1], v[2]};
  }
  return {v[0], v[1], world.TerrainHeight(v[0], v[1]) + m.NumberOr("height_above_ground_m", default_height)};
}

void ParseSensors(const Map& sensors, Scenario& s) {
  sensors.AllowOnly({"gps_imu", "rotating_lidar", "airborne_lidar", "studio"});
  if (sensors.Has("gps_imu")) {
    const YAML::Node list = sensors.Get("gps_imu");
    scene::yaml::RequireSequence(list, sensors.Field("gps_imu"));
    for (size_t i = 0; i < list.size(); ++i) {
      const Map m(list[i], Indexed(sensors.Field("gps_imu"), i));
      m.AllowOnly({"camera", "gps_rate_hz", "imu_rate_hz", "duration_s"});
      GpsImuSpec spec;
      spec.camera_id = m.String("camera");
      if (!s.world.FindCamera(spec.camera_id)) Fail(m.Get("camera"), m.Field("camera"), "no camera '" + spec.camera_id + "' in this scenario");
      spec.gps_rate_hz = m.PositiveUpTo("gps_rate_hz", spec.gps_rate_hz, 100);
      spec.imu_rate_hz = m.PositiveUpTo("imu_rate_hz", spec.imu_rate_hz, 2000);
      spec.duration_s = m.NumberIn("duration_s", spec.duration_s, 0, 86400);
      s.gps_imu.push_back(spec);
    }
  }
  if (sensors.Has("rotating_lidar")) {
    const YAML::Node list = sensors.Get("rotating_lidar");
    scene::yaml::RequireSequence(list, sensors.Field("rotating_lidar"));
    std::set<std::string> ids;
    for (size_t i = 0; i < list.size(); ++i) {
      const Map m(list[i], Indexed(sensors.Field("rotating_lidar"), i));
      m.AllowOnly({"id", "position", "height_above_ground_m", "rate_hz", "rings", "fov_up_deg", "fov_down_deg", "azimuth_steps", "max_range_m"});
      RotatingLidarSpec spec;
      spec.id = m.String("id");
      if (!ids.insert(spec.id).second) Fail(m.Get("id"), m.Field("id"), "duplicate LiDAR id '" + spec.id + "'");
      spec.position_m = PlacedPoint(m, s.world, 2.0);
      spec.rate_hz = m.PositiveUpTo("rate_hz", spec.rate_hz, 50);
      spec.rings = m.IntIn("rings", spec.rings, 1, 64);
      spec.fov_up_deg = m.NumberIn("fov_up_deg", spec.fov_up_deg, -89, 89);
      spec.fov_down_deg = m.NumberIn("fov_down_deg", spec.fov_down_deg, -89, 89);
      spec.azimuth_steps = m.IntIn("azimuth_steps", spec.azimuth_steps, 16, 36000);
      spec.max_range_m = m.PositiveUpTo("max_range_m", spec.max_range_m, 130);
      if (!(spec.fov_down_deg < spec.fov_up_deg)) Fail(m.Has("fov_down_deg") ? m.Get("fov_down_deg") : m.node(), m.Field("fov_down_deg"), "must be below fov_up_deg");
      const int b = s.world.BuildingAt(spec.position_m.x(), spec.position_m.y());
      if (b >= 0) {
        const auto roof = s.world.RoofHeightAt(s.world.buildings[b], spec.position_m.x(), spec.position_m.y());
        if (roof && spec.position_m.z() <= *roof) Fail(m.Get("position"), m.Field("position"), "the LiDAR is inside building '" + s.world.buildings[b].id + "'");
      }
      s.rotating_lidars.push_back(spec);
    }
  }
  if (sensors.Has("airborne_lidar")) {
    const Map m(sensors.Get("airborne_lidar"), sensors.Field("airborne_lidar"));
    m.AllowOnly({"altitude_m", "swath_half_angle_deg", "point_spacing_m"});
    AirborneLidarSpec spec;
    spec.altitude_m = m.PositiveUpTo("altitude_m", spec.altitude_m, 10000);
    spec.swath_half_angle_deg = m.PositiveUpTo("swath_half_angle_deg", spec.swath_half_angle_deg, 59.9);
    spec.point_spacing_m = m.PositiveIn("point_spacing_m", spec.point_spacing_m, 0.05, 100);
    s.airborne_lidar = spec;
  }
  if (sensors.Has("studio")) {
    const Map m(sensors.Get("studio"), sensors.Field("studio"));
    m.AllowOnly({"cameras", "radius_m", "overhead", "fps", "duration_s", "width", "height", "actor"});
    StudioSpec spec;
    spec.cameras = m.IntIn("cameras", spec.cameras, 1, 64);
    spec.radius_m = m.NumberIn("radius_m", spec.radius_m, 1.001, 50);
    spec.overhead = m.BoolOr("overhead", spec.overhead);
    spec.fps = m.PositiveUpTo("fps", spec.fps, 120);
    spec.duration_s = m.NumberIn("duration_s", spec.duration_s, 0, kUnbounded);
    spec.width = m.IntIn("width", spec.width, 16, 8192);
    spec.height = m.IntIn("height", spec.height, 16, 8192);
    const std::string actor = m.StringOr("actor", StudioActorName(spec.actor));
    const std::optional<StudioActor> kind = ParseStudioActor(actor);
    if (!kind) Fail(m.Get("actor"), m.Field("actor"), "must be body or boxes, not '" + actor + "'");
    spec.actor = *kind;
    s.studio = spec;
  }
}

}  // namespace

std::vector<std::string> KnownEffectParams(EffectKind kind) {
  switch (kind) {
    case EffectKind::kCameraNoise: return {"sigma"};
    case EffectKind::kIllumination: return {"amplitude", "period_s"};
    case EffectKind::kJpegArtefacts: return {"quality"};
    case EffectKind::kRollingOcclusion: return {"period_s", "duration_s", "width_frac", "start_s"};
    case EffectKind::kWavingVegetation: return {"amplitude_m", "frequency_hz", "wind_deg"};
    case EffectKind::kPixelArea: return {"samples"};
    default: return {};  // GPS, IMU and LiDAR effects: their parameters are the sensor simulators' (docs/SIMULATOR_FORMATS.md)
  }
}

EffectSet Scenario::EffectsForCamera(const std::string& camera_id) const {
  EffectSet out;
  for (int i = 0; i < kEffectCount; ++i) {
    const auto kind = static_cast<EffectKind>(i);
    const EffectParams* p = effects.Find(kind);
    if (!p) continue;
    auto it = effect_cameras.find(kind);
    if (it != effect_cameras.end() && std::find(it->second.begin(), it->second.end(), camera_id) == it->second.end()) continue;
    out.Enable(kind, *p);
  }
  return out;
}

absl::StatusOr<Scenario> LoadScenarioText(const std::string& text, const std::string& name) {
  try {
    const YAML::Node root = scene::yaml::ParseYamlText(text);
    Scenario s;
    s.label = name;
    s.world = scene::yaml::ParseScene(root, {"seed", "effects", "sensors"});
    s.name = s.world.name;
    const Map top(root, "");
    if (top.Has("seed")) {
      const YAML::Node n = top.Get("seed");
      try {
        s.seed = n.as<uint64_t>();
      } catch (const YAML::Exception&) {
        Fail(n, "seed", "must be a whole number >= 0");
      }
    }
    if (top.Has("effects") && !top.Get("effects").IsNull()) ParseEffects(top.Get("effects"), s);
    if (top.Has("sensors")) ParseSensors(Map(top.Get("sensors"), "sensors"), s);
    return s;
  } catch (const scene::yaml::FieldError& e) {
    return absl::InvalidArgumentError(scene::yaml::FormatFieldError(name, e));
  } catch (const YAML::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, ":", e.mark.line + 1, ": ", e.msg));
  }
}

absl::StatusOr<Scenario> LoadScenario(const std::string& name_or_path) {
  absl::StatusOr<scene::ScenarioSource> source = scene::ReadScenarioSource(name_or_path);
  if (!source.ok()) return source.status();
  return LoadScenarioText(source->text, source->label);
}

}  // namespace ave::sim
