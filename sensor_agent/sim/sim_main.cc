// ave-sim: generates sensor data with ground truth from a scenario (docs/SCENARIOS.md).
//   ave-sim camera --scenario campus --camera cam1 --out DIR [--frames N --fps F --format png|jpg]
//   ave-sim gps-imu --scenario campus --out DIR [--camera backpack]
//   ave-sim airborne-lidar --scenario campus --out DIR
//   ave-sim rotating-lidar --scenario courtyard --out DIR [--lidar hdl64 --seconds S]
//   ave-sim studio --scenario studio --out DIR
//   ave-sim footage --scenario campus --camera backpack --out FILE [--seconds S --fps F --quality Q --threads N]
// A scenario is a bundled name (campus, courtyard, studio, minimal) or a .yaml path. Bad input
// (scenario errors, unknown camera) is reported before anything is written.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/common/cli.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/footage.h"
#include "sensor_agent/sim/scenario.h"

namespace {

namespace fs = std::filesystem;
using ave::sim::Scenario;

int Fail(const std::string& message, int code = 1) {
  std::cerr << "ave-sim: " << message << "\n";
  return code;
}

// The 16-bit object mask value of an object id: ids below 30000 as they are (sky 0, ground 1,
// vegetation 2, static objects 3, occluder 4, buildings 1000 + index), movers 30000 + Mover::id.
uint16_t MaskId16(uint32_t id) {
  if (ave::sim::IsMoverId(id)) return static_cast<uint16_t>(std::min<uint32_t>(30000 + (id - ave::sim::kMoverIdBase), 65535));
  return static_cast<uint16_t>(std::min<uint32_t>(id, 29999));
}

absl::Status WriteLegend(const Scenario& s, const fs::path& path) {
  std::ofstream out(path);
  out << "mask_value,kind,name\n0,sky,\n1,ground,\n2,vegetation,\n3,static_object,\n4,occluder,\n";
  for (size_t i = 0; i < s.world.buildings.size(); ++i) out << MaskId16(ave::sim::kBuildingIdBase + i) << ",building," << s.world.buildings[i].id << "\n";
  for (const auto& m : s.world.movers) {
    out << MaskId16(ave::sim::kMoverIdBase + m.id) << "," << (m.kind == ave::scene::MoverKind::kPerson ? "person" : "vehicle") << "," << m.id << "\n";
  }
  return out ? absl::OkStatus() : absl::InternalError("cannot write " + path.string());
}

int RunCamera(const Scenario& s, const std::string& camera_id, const fs::path& out_dir, int frames, double fps, double start_s,
              const std::string& format) {
  const ave::scene::CameraSpec* camera = s.world.FindCamera(camera_id);
  if (!camera) {
    std::string known;
    for (const auto& c : s.world.cameras) known += (known.empty() ? "" : ", ") + c.id;
    return Fail(s.label + ": no camera '" + camera_id + "' (cameras: " + known + ")");
  }
  if (fps <= 0) fps = camera->fps;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return Fail("cannot create " + out_dir.string() + ": " + ec.message());
  const ave::sim::EffectSet effects = s.EffectsForCamera(camera_id);
  const ave::sim::SimulatedCamera sim(s.world, *camera, effects, s.seed);
  if (absl::Status st = WriteLegend(s, out_dir / "objects.csv"); !st.ok()) return Fail(std::string(st.message()));
  {
    const ave::PinholeIntrinsics& k = camera->intrinsics;
    std::ofstream intr(out_dir / "intrinsics.csv");
    intr << std::setprecision(17) << "width,height,fx,fy,cx,cy,k1,k2,p1,p2,k3\n"
         << k.width << "," << k.height << "," << k.fx << "," << k.fy << "," << k.cx << "," << k.cy;
    for (double d : k.distortion) intr << "," << d;
    intr << "\n";
  }
  std::ofstream poses(out_dir / "poses.csv");
  poses << std::setprecision(17);
  poses << "# scenario " << s.name << " (" << s.label << "), camera " << camera_id << ", seed " << s.seed << "\n"
        << "# world_from_camera: local ENU frame (x east, y north, z up; m) relative to the origin; camera axes OpenCV (x right, y down, z forward)\n"
        << "# origin " << s.world.origin.x() << " " << s.world.origin.y() << " " << s.world.origin.z() << "\n"
        << "frame,t_s,tx,ty,tz,qw,qx,qy,qz,world_x,world_y,world_z,exposure_gain\n";
  const std::string ext = format == "jpg" ? ".jpg" : ".png";
  for (int f = 0; f < frames; ++f) {
    const double t_s = start_s + f / fps;
    const ave::sim::SimImage image = sim.Frame(f, t_s);
    if (image.width == 0) return Fail("camera '" + camera_id + "' renders nothing (bad intrinsics or pose)");
    char name[64];
    std::snprintf(name, sizeof(name), "%06d", f);
    const cv::Mat bgr(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
    cv::Mat ids(image.height, image.width, CV_16UC1), classes(image.height, image.width, CV_8UC1);
    for (size_t i = 0; i < image.object_id.size(); ++i) {
      ids.at<uint16_t>(static_cast<int>(i)) = MaskId16(image.object_id[i]);
      classes.at<uint8_t>(static_cast<int>(i)) = image.class_id[i];
    }
    const std::vector<int> params = format == "jpg" ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, 92} : std::vector<int>{};
    if (!cv::imwrite((out_dir / ("frame_" + std::string(name) + ext)).string(), bgr, params) ||
        !cv::imwrite((out_dir / ("ids_" + std::string(name) + ".png")).string(), ids) ||
        !cv::imwrite((out_dir / ("class_" + std::string(name) + ".png")).string(), classes)) {
      return Fail("cannot write frame " + std::to_string(f) + " into " + out_dir.string());
    }
    const ave::Rigid3d pose = sim.PoseAt(t_s);
    const Eigen::Vector3d world = s.world.origin + pose.translation;
    const auto* illumination = effects.Find(ave::sim::EffectKind::kIllumination);
    poses << f << "," << t_s << "," << pose.translation.x() << "," << pose.translation.y() << "," << pose.translation.z() << ","
          << pose.rotation.w() << "," << pose.rotation.x() << "," << pose.rotation.y() << "," << pose.rotation.z() << "," << world.x()
          << "," << world.y() << "," << world.z() << "," << (illumination ? ave::sim::IlluminationGain(*illumination, s.seed, t_s) : 1.0)
          << "\n";
  }
  if (!poses) return Fail("cannot write poses.csv into " + out_dir.string());
  std::cout << "{\"scenario\":\"" << s.name << "\",\"camera\":\"" << camera_id << "\",\"frames\":" << frames << ",\"fps\":" << fps
            << ",\"out\":\"" << out_dir.string() << "\"}\n";
  return 0;
}

// Issue 19: a camera's frames pre-rendered as the agent's JPEG into one file the agent's sim
// source plays (--sim-footage); a good file is kept, a missing, corrupt, stale or short one is
// rendered anew (with a log line naming it and why).
int RunFootage(const Scenario& s, const std::string& scenario_name, const std::string& camera_id, const std::string& path,
               double seconds, double fps, double start_s, int quality, int threads) {
  const ave::scene::CameraSpec* camera = s.world.FindCamera(camera_id);
  if (!camera) return Fail(s.label + ": no camera '" + camera_id + "'");
  if (fps <= 0) fps = camera->fps;
  absl::StatusOr<ave::sim::FootageKey> key = ave::sim::MakeFootageKey(scenario_name, camera_id, fps, start_s, quality);
  if (!key.ok()) return Fail(std::string(key.status().message()));
  const int64_t frames = std::max<int64_t>(1, static_cast<int64_t>(std::llround(seconds * fps)));
  // One camera instance per rendering thread (a SimulatedCamera renders one frame at a time).
  std::vector<std::unique_ptr<ave::sim::SimulatedCamera>> sims;
  std::vector<const ave::sim::SimulatedCamera*> cameras;
  for (int t = 0; t < threads; ++t) {
    sims.push_back(std::make_unique<ave::sim::SimulatedCamera>(s.world, *camera, s.EffectsForCamera(camera_id), s.seed));
    cameras.push_back(sims.back().get());
  }
  absl::StatusOr<ave::sim::EnsuredFootage> made = ave::sim::EnsureFootage(path, *key, cameras, frames);
  if (!made.ok()) return Fail(std::string(made.status().message()));
  std::cout << "{\"footage\":\"" << path << "\",\"camera\":\"" << camera_id << "\",\"frames\":" << made->frames << ",\"fps\":" << fps
            << ",\"rendered\":" << (made->rendered ? "true" : "false") << "}\n";
  return 0;
}

int Report(const absl::Status& status, const std::string& what, const fs::path& out) {
  if (!status.ok()) return Fail(std::string(status.message()));
  std::cout << "{\"" << what << "\":\"" << out.string() << "\"}\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ave-sim: scenario-driven sensor simulator with ground truth (docs/SCENARIOS.md)"};
  app.require_subcommand(1);
  std::string scenario_name, out_dir, camera_id, lidar_id, format = "png";
  int frames = 30;
  double fps = 0, start_s = 0, seconds = 1;
  auto common = [&](CLI::App* sub) {
    sub->add_option("--scenario", scenario_name, "bundled name (campus, courtyard, studio, minimal) or a .yaml path")->required();
    sub->add_option("--out", out_dir, "output folder (created)")->required();
  };
  CLI::App* camera = app.add_subcommand("camera", "frames + object-id and class masks + true poses of one camera");
  common(camera);
  camera->add_option("--camera", camera_id, "camera id in the scenario")->required();
  camera->add_option("--frames", frames, "number of frames")->capture_default_str()->check(ave::cli::Range(1, 1000000));
  camera->add_option("--fps", fps, "frames per second (default: the camera's fps)")->check(ave::cli::Range(0.001, 1000.0));
  camera->add_option("--start", start_s, "scene time of the first frame (s)")->capture_default_str()->check(ave::cli::Range(-1e7, 1e7));
  camera->add_option("--format", format, "frame image format")->capture_default_str()->check(CLI::IsMember({"png", "jpg"}));
  CLI::App* gps = app.add_subcommand("gps-imu", "GPS and IMU streams of a carrier camera with the true trajectory");
  common(gps);
  gps->add_option("--camera", camera_id, "carrier camera (default: the scenario's first gps_imu sensor)");
  CLI::App* airborne = app.add_subcommand("airborne-lidar", "an airborne LiDAR survey as LAS 1.4 with classes");
  common(airborne);
  CLI::App* rotating = app.add_subcommand("rotating-lidar", "rotating multi-beam LiDAR frames, pcap and truth");
  common(rotating);
  rotating->add_option("--lidar", lidar_id, "LiDAR id (default: the scenario's first)");
  rotating->add_option("--seconds", seconds, "duration (s)")->capture_default_str()->check(ave::cli::Range(0.0, 3600.0));
  CLI::App* studio = app.add_subcommand("studio", "multi-camera studio images with silhouettes and calibration");
  common(studio);
  CLI::App* footage = app.add_subcommand("footage", "a camera's frames pre-rendered as JPEG into one file (ave-agent --sim-footage)");
  std::string footage_out;
  int quality = 80;
  footage->add_option("--scenario", scenario_name, "bundled name (campus, courtyard, studio, minimal) or a .yaml path")->required();
  footage->add_option("--out", footage_out, "footage file (kept when already good for this camera and simulator)")->required();
  footage->add_option("--camera", camera_id, "camera id in the scenario")->required();
  footage->add_option("--seconds", seconds, "scene seconds of footage")->capture_default_str()->check(ave::cli::Range(0.001, 3600.0));
  footage->add_option("--fps", fps, "frames per second (default: the camera's fps)")->check(ave::cli::Range(0.001, 1000.0));
  footage->add_option("--start", start_s, "scene time of the first frame (s)")->capture_default_str()->check(ave::cli::Range(-1e7, 1e7));
  int threads = 1;
  footage->add_option("--threads", threads, "rendering threads (frames are the same for any count)")->capture_default_str()->check(ave::cli::Range(1, 64));
  footage->add_option("--quality", quality, "JPEG quality (the agent's --jpeg-quality)")->capture_default_str()->check(ave::cli::Range(1, 100));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-sim")) return *exit_code;

  absl::StatusOr<Scenario> scenario = ave::sim::LoadScenario(scenario_name);
  if (!scenario.ok()) return Fail(std::string(scenario.status().message()));
  const Scenario& s = *scenario;
  const fs::path out(out_dir);

  if (camera->parsed()) return RunCamera(s, camera_id, out, frames, fps, start_s, format);
  if (footage->parsed()) return RunFootage(s, scenario_name, camera_id, footage_out, seconds, fps, start_s, quality, threads);
  if (gps->parsed()) {
    ave::sim::GpsImuSpec spec;
    if (camera_id.empty()) {
      if (s.gps_imu.empty()) return Fail(s.label + ": names no gps_imu sensor; pass --camera");
      spec = s.gps_imu.front();
    } else {
      spec.camera_id = camera_id;
      for (const auto& g : s.gps_imu)
        if (g.camera_id == camera_id) spec = g;
    }
    const ave::scene::CameraSpec* carrier = s.world.FindCamera(spec.camera_id);
    if (!carrier) return Fail(s.label + ": no camera '" + spec.camera_id + "'");
    const ave::sim::GpsImuStreams streams = ave::sim::SimulateGpsImu(s.world, *carrier, spec, s.effects, s.seed);
    return Report(ave::sim::WriteGpsImu(streams, out.string()), "gps_imu", out);
  }
  if (airborne->parsed()) {
    const ave::sim::AirborneLidarSpec spec = s.airborne_lidar.value_or(ave::sim::AirborneLidarSpec{});
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec) return Fail("cannot create " + out.string() + ": " + ec.message());
    const fs::path las = out / (s.name + ".las");
    return Report(ave::sim::SimulateAirborneLidar(s.world, spec, s.effects, s.seed, las.string()), "las", las);
  }
  if (rotating->parsed()) {
    if (s.rotating_lidars.empty()) return Fail(s.label + ": names no rotating_lidar sensor");
    const ave::sim::RotatingLidarSpec* spec = &s.rotating_lidars.front();
    if (!lidar_id.empty()) {
      spec = nullptr;
      for (const auto& l : s.rotating_lidars)
        if (l.id == lidar_id) spec = &l;
      if (!spec) return Fail(s.label + ": no rotating LiDAR '" + lidar_id + "'");
    }
    return Report(ave::sim::WriteRotatingLidar(s.world, *spec, s.effects, s.seed, seconds, out.string()), "rotating_lidar", out);
  }
  if (studio->parsed()) {
    if (!s.studio) return Fail(s.label + ": names no studio sensor");
    return Report(ave::sim::SimulateStudio(*s.studio, s.effects, s.seed, out.string()), "studio", out);
  }
  return Fail("no subcommand", 2);
}
