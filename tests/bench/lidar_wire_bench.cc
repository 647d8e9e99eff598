// ave-bench lidar-wire (issue 16): what a rotating LiDAR's stream costs on the wire and in the
// server, next to a camera frame of the same scene measured in the same run. Per sweep of the
// scenario's rotating LiDAR (full resolution): the people tracked (simulator truth feet, the test
// fixture standing in for the tracker), their labelled foreground points, the message size with and
// without points, the agent's encoding time (SweepToWire) and the server's time to validate, fuse
// and put the sweep into a viewer update. The peer: a camera frame (a real JPEG of the scenario's
// first camera plus one box per visible person) through ValidateFrame, AcceptFrame (placement by
// ray cast) and BuildUpdate.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "fusion_server/core/convert.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/core/validation.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/stream/lidar_streamer.h"
#include "sensor_agent/stream/lidar_test_fixtures.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

struct Options {
  std::string scenario = "courtyard";
  int sweeps = 20;
  double start_s = 2;
  int repeats = 20;  // server timings: each message this many times into fresh state, median
  uint32_t max_points = 262144;  // the agent's point budget (LidarStreamOptions::max_points)
};

using Clock = std::chrono::steady_clock;
double Us(Clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }
double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

int Run(const Options& o) {
  UseOneCore();
  auto scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) return std::fprintf(stderr, "ave-bench: %s\n", std::string(scenario.status().message()).c_str()), 1;
  if (scenario->rotating_lidars.empty() || scenario->world.cameras.empty()) {
    return std::fprintf(stderr, "ave-bench: %s needs a rotating_lidar and a camera\n", o.scenario.c_str()), 1;
  }
  const sim::RotatingLidarSpec& spec = scenario->rotating_lidars.front();
  const scene::CameraSpec& cam = scenario->world.cameras.front();
  const TriangleMesh mesh = scene::BuildStaticMesh(scenario->world, 2.0);
  sim::SimulatedCamera camera(scenario->world, cam, scenario->EffectsForCamera(cam.id), scenario->seed);

  std::vector<double> tracks, points, bytes_points, bytes_tracks, encode_us, server_us, sim_s;
  std::vector<double> cam_bytes, cam_boxes, cam_server_us;
  lidar::SweepTracker tracker = fixtures::TruthFootTracker(0.15);
  for (int k = 0; k < o.sweeps; ++k) {
    const double t = o.start_s + k / spec.rate_hz;
    const auto s0 = Clock::now();
    lidar::LidarSweep sweep = fixtures::SweepFromSim(
        sim::SimulateRotatingLidarFrame(scenario->world, spec, scenario->effects, scenario->seed, t), spec);
    sim_s.push_back(std::chrono::duration<double>(Clock::now() - s0).count());
    sweep.t_ns = 1'000'000'000 + static_cast<int64_t>(t * 1e9);
    absl::StatusOr<lidar::FootTracks> foot = tracker(sweep);
    if (!foot.ok()) return 1;
    const auto e0 = Clock::now();
    v1::LidarSweepFrame wire = SweepToWire(sweep, *foot, true, o.max_points);
    encode_us.push_back(Us(Clock::now() - e0));
    wire.set_sequence(k + 1);
    tracks.push_back(wire.tracks_size());
    points.push_back(wire.foreground().count());
    v1::SensorMessage message;
    *message.mutable_lidar_sweep() = wire;
    bytes_points.push_back(static_cast<double>(message.ByteSizeLong()));
    message.mutable_lidar_sweep()->clear_foreground();
    bytes_tracks.push_back(static_cast<double>(message.ByteSizeLong()));

    // The camera frame of the same instant: its JPEG and a box per person whose foot and head
    // project into the image.
    const sim::SimImage image = camera.Frame(k, t);
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", cv::Mat(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data())), jpeg,
                 {cv::IMWRITE_JPEG_QUALITY, 80});
    v1::SensorFrame frame;
    frame.set_sequence(k + 1);
    frame.set_capture_time_ns(sweep.t_ns);
    *frame.mutable_pose() = ToProto(camera.PoseAt(t));
    frame.set_jpeg(jpeg.data(), jpeg.size());
    const Rigid3d camera_from_world = camera.PoseAt(t).Inverse();
    for (const auto& [label, foot_in_world] : sweep.truth_feet_in_world) {
      const auto bottom = ProjectToPixel(cam.intrinsics, camera_from_world * foot_in_world);
      const auto top = ProjectToPixel(cam.intrinsics, camera_from_world * (foot_in_world + Eigen::Vector3d(0, 0, 1.75)));
      if (!bottom || !top || bottom->y() - top->y() < 4) continue;
      const double h = bottom->y() - top->y(), u = bottom->x() + 0.5, v = bottom->y() + 0.5;
      if (u < 0 || v < h || u >= cam.intrinsics.width || v > cam.intrinsics.height) continue;
      v1::DetectedBox* box = frame.add_boxes();
      box->set_track_id(label);
      box->set_score(0.9f);
      for (const auto& [x, y] : {std::pair{u - 0.2 * h, v - h}, {u + 0.2 * h, v - h}, {u + 0.2 * h, v}, {u - 0.2 * h, v}}) {
        v1::Point2* c = box->add_corners();
        c->set_x(static_cast<float>(x));
        c->set_y(static_cast<float>(y));
      }
    }
    v1::SensorMessage camera_message;
    *camera_message.mutable_frame() = frame;
    cam_bytes.push_back(static_cast<double>(camera_message.ByteSizeLong()));
    cam_boxes.push_back(frame.boxes_size());

    // Server side, each into fresh state with the site's terrain (placement and fusion included).
    std::vector<double> lidar_runs, camera_runs;
    for (int r = 0; r < o.repeats; ++r) {
      SceneState state;
      state.SetStaticModel(mesh);
      CameraEntry lidar_entry;
      lidar_entry.id = spec.id;
      lidar_entry.kind = SensorKind::kRotatingLidar;
      lidar_entry.mounting_pose.translation = spec.position_m;
      state.UpsertCamera(lidar_entry);
      state.UpsertCamera({cam.id, cam.name, cam.intrinsics, cam.world_from_camera, "", true});
      ViewerCursor cursor;
      cursor.include_lidar_points = true;
      const auto l0 = Clock::now();
      if (!ValidateLidarSweep(wire, 0, {}).ok()) return std::fprintf(stderr, "ave-bench: sweep refused\n"), 1;
      (void)state.AcceptLidarSweep(spec.id, std::make_shared<v1::LidarSweepFrame>(wire), sweep.t_ns, 1);
      (void)state.BuildUpdate({}, true, sweep.t_ns, cursor);
      lidar_runs.push_back(Us(Clock::now() - l0));
      ViewerCursor camera_cursor;
      const auto c0 = Clock::now();
      if (!ValidateFrame(frame, ToProto(cam.intrinsics), 0, {}).ok()) return std::fprintf(stderr, "ave-bench: frame refused\n"), 1;
      (void)state.AcceptFrame(cam.id, std::make_shared<v1::SensorFrame>(frame), sweep.t_ns, 2);
      (void)state.BuildUpdate({}, true, sweep.t_ns, camera_cursor);
      camera_runs.push_back(Us(Clock::now() - c0));
    }
    server_us.push_back(Median(lidar_runs));
    cam_server_us.push_back(Median(camera_runs));
  }
  const double rate = spec.rate_hz;
  std::printf("ave-bench lidar-wire: %s, %s (%d rings x %d steps, %.0f Hz) vs %s, %d sweeps from t=%.1f s, "
              "point budget %u, one core\n",
              o.scenario.c_str(), spec.id.c_str(), spec.rings, spec.azimuth_steps, rate, cam.id.c_str(), o.sweeps, o.start_s,
              o.max_points);
  std::printf("| stream | people/boxes | points | bytes/message | kB/s | agent encode us | server us (validate+fuse+update) |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- |\n");
  std::printf("| %s tracks + points | %.0f | %.0f | %.0f | %.1f | %.0f | %.0f |\n", spec.id.c_str(), Median(tracks),
              Median(points), Median(bytes_points), Median(bytes_points) * rate / 1e3, Median(encode_us), Median(server_us));
  std::printf("| %s tracks only | %.0f | 0 | %.0f | %.1f | - | - |\n", spec.id.c_str(), Median(tracks),
              Median(bytes_tracks), Median(bytes_tracks) * rate / 1e3);
  std::printf("| %s frame (JPEG q80 + boxes), same run | %.0f | - | %.0f | %.1f at %.0f fps | - | %.0f |\n", cam.id.c_str(),
              Median(cam_boxes), Median(cam_bytes), Median(cam_bytes) * cam.fps / 1e3, cam.fps, Median(cam_server_us));
  std::printf("ratios (LiDAR with points / camera frame): bytes %.3f, server time %.2f; simulating one sweep: %.2f s\n",
              Median(bytes_points) / Median(cam_bytes), Median(server_us) / Median(cam_server_us), Median(sim_s));
  return 0;
}

}  // namespace

Runner AddLidarWireBench(CLI::App& sub) {
  auto o = std::make_shared<Options>();
  sub.add_option("--scenario", o->scenario, "bundled scenario or .yaml path with a rotating_lidar and a camera")->capture_default_str();
  sub.add_option("--sweeps", o->sweeps, "sweeps measured")->capture_default_str()->check(CLI::Range(1, 10000));
  sub.add_option("--start", o->start_s, "scene time of the first sweep (s)")->capture_default_str();
  sub.add_option("--max-points", o->max_points, "the agent's point budget per sweep")->capture_default_str();
  sub.add_option("--repeats", o->repeats, "server timings: runs per message (median)")->capture_default_str()->check(CLI::Range(1, 1000));
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
