// Issue 16 end to end on loopback: a real FusionServer with the courtyard's static model; a real
// LidarStreamer streaming the courtyard's rotating LiDAR (hdl64) — simulator sweeps, tracks from
// the simulator's truth feet (a test fixture standing in for the people tracker) — with a sensor
// token issued for it; a real AgentStreamer on courtyard cam1 with the agent's own detection and
// tracking; and a raw SceneService Subscribe that must see a person seen by both sensors as one
// object listing both, near the truth, plus the LiDAR's state with its tracks and points.
//
// Both simulated sensors take their scene time from the wall clock (since the test's start), so a
// camera that renders slower than real time and the LiDAR still see the same instant of the world.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <functional>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "model_store/db/store.h"
#include "sensor_agent/detect/detector.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/stream/agent_streamer.h"
#include "sensor_agent/stream/lidar_streamer.h"
#include "sensor_agent/stream/lidar_test_fixtures.h"
#include "viewer_client/client/scene_client.h"

namespace ave {
namespace {

constexpr char kSensor[] = "s3nsor";
constexpr char kViewer[] = "v1ewer";
constexpr char kAdmin[] = "adm1n";
constexpr double kSceneStartS = 4.0;  // scene time at the test's start

// Scene time of a wall-clock instant.
struct WallScene {
  int64_t start_ns = NowNs();
  double At(int64_t wall_ns) const { return kSceneStartS + (wall_ns - start_ns) * 1e-9; }
};

// cam1 of the courtyard through the simulator's camera pipeline, at the scene time of "now".
class WallClockCamera : public FrameSource {
 public:
  WallClockCamera(const sim::Scenario& scenario, const scene::CameraSpec& camera, const WallScene& clock)
      : camera_(scenario.world, camera, scenario.EffectsForCamera(camera.id), scenario.seed), clock_(clock) {}
  absl::StatusOr<CapturedFrame> Next() override {
    CapturedFrame frame;
    frame.capture_time_ns = NowNs();
    frame.scene_time_s = clock_.At(frame.capture_time_ns);
    sim::SimImage image = camera_.Frame(index_++, frame.scene_time_s);
    frame.width = image.width;
    frame.height = image.height;
    frame.bgr = std::move(image.bgr);
    frame.world_from_camera = camera_.PoseAt(frame.scene_time_s);
    return frame;
  }
  PinholeIntrinsics intrinsics() const override { return camera_.camera().intrinsics; }
  std::string description() const override { return "courtyard cam1 on the wall clock"; }
  bool live() const override { return false; }

 private:
  sim::SimulatedCamera camera_;
  const WallScene& clock_;
  int64_t index_ = 0;
};

TEST(LidarEndToEnd, PersonSeenByCameraAndLidarIsOneObjectListingBothNearTheTruth) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("courtyard");
  ASSERT_TRUE(scenario.ok()) << scenario.status();
  const scene::SyntheticCampus& world = scenario->world;
  const scene::CameraSpec& cam = *world.FindCamera("cam1");
  ASSERT_FALSE(scenario->rotating_lidars.empty());
  // The courtyard's hdl64 at a lower resolution: its points are only forwarded here, and a full
  // 64 x 1024 sweep takes ~0.6 s to simulate on this machine.
  sim::RotatingLidarSpec spec = scenario->rotating_lidars.front();
  spec.rings = 16;
  spec.azimuth_steps = 360;

  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("ave_lidar_e2e_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string store_path = (dir / "ave.db").string();
  {
    auto store = store::Store::Open(store_path);
    ASSERT_TRUE(store.ok()) << store.status();
    ASSERT_TRUE((*store)->PutStaticModel(world.name, scene::BuildStaticMesh(world, 2.0)).ok());
  }
  auto server = FusionServer::Start(fixtures::LoopbackServer(store_path, kSensor, kViewer, kAdmin));
  ASSERT_TRUE(server.ok()) << server.status();
  const std::string address = "127.0.0.1:" + std::to_string((*server)->port());
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  AdminClient admin(channel, kAdmin);
  v1::Camera camera_record = CampusCameraRecord(cam);
  camera_record.set_source_url("sim:courtyard#cam1");
  ASSERT_TRUE(admin.AddCamera(camera_record).ok());
  ASSERT_TRUE(admin.AddCamera(LidarRecord(spec.id, "Courtyard LiDAR", Rigid3d(Eigen::Quaterniond::Identity(), spec.position_m),
                                          "sim:courtyard#hdl64"))
                  .ok());
  auto lidar_token = admin.IssueToken("sensor", spec.id, "lidar e2e");
  ASSERT_TRUE(lidar_token.ok()) << lidar_token.status();

  const WallScene clock;
  std::atomic<bool> stop{false};
  std::thread camera_agent([&] {
    AgentOptions a;
    a.server = address;
    a.camera_id = cam.id;
    a.token = kSensor;
    a.fps = 10;
    auto detector = std::make_shared<detect::Detector>();
    a.detector = [detector](const CapturedFrame& frame) {
      std::vector<FrameBox> boxes;
      for (const detect::Detection& d : detector->Process(frame.bgr.data(), frame.width, frame.height, frame.scene_time_s)) {
        boxes.push_back({d.track_id, d.corners, d.score});
      }
      return boxes;
    };
    AgentStreamer streamer(a, std::make_unique<WallClockCamera>(*scenario, cam, clock));
    EXPECT_TRUE(streamer.Run(stop).ok());
  });
  std::atomic<int64_t> lidar_points_sent{0};
  std::thread lidar_agent([&] {
    LidarStreamOptions l;
    l.server = address;
    l.sensor_id = spec.id;
    l.token = lidar_token->token();
    l.pace_hz = spec.rate_hz;
    SweepSource sweeps = [&]() -> absl::StatusOr<lidar::LidarSweep> {
      const int64_t now = NowNs();
      lidar::LidarSweep sweep = fixtures::SweepFromSim(
          sim::SimulateRotatingLidarFrame(world, spec, scenario->effects, scenario->seed, clock.At(now)), spec);
      sweep.t_ns = now;  // on the agent's clock, like the camera's frames
      return sweep;
    };
    LidarStreamStats stats;
    EXPECT_TRUE(StreamLidar(l, sweeps, fixtures::TruthFootTracker(0.15), stop, &stats).ok());
    lidar_points_sent = stats.points_sent;
  });

  // The viewer's own client library alongside (what ave-viewer draws from).
  viewer::SceneClient client(channel, kViewer, "lidar-e2e-client");
  client.Start({.max_rate_hz = 10, .include_jpeg = false, .include_lidar_points = true});

  // The viewer: poses, objects and LiDAR points, 10 updates a second.
  auto stub = v1::SceneService::NewStub(channel);
  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(40));
  v1::SubscribeRequest request;
  request.set_viewer_id("lidar-e2e");
  request.set_max_rate_hz(10);
  request.set_include_jpeg(false);
  request.set_include_lidar_points(true);
  auto reader = stub->Subscribe(&context, request);

  // Sightings of objects listing both sensors: distance to the nearest true person at the scene
  // time they were last seen, and whether a camera-only object stood within 1 m (a duplicate).
  std::vector<double> errors;
  int duplicates = 0, lidar_updates_with_points = 0, bad_labels = 0;
  size_t max_lidar_tracks = 0;
  v1::SceneUpdate update;
  while (errors.size() < 20 && reader->Read(&update)) {
    for (const v1::LidarState& l : update.lidars()) {
      max_lidar_tracks = std::max<size_t>(max_lidar_tracks, l.tracks_size());
      if (l.foreground().count() == 0) continue;
      ++lidar_updates_with_points;
      for (uint32_t k = 0; k < l.foreground().count(); ++k) {
        uint16_t label = 0;
        std::memcpy(&label, l.foreground().packed().data() + 8 * k + 6, 2);
        bad_labels += label == 0 || label > static_cast<uint32_t>(l.tracks_size());
      }
    }
    for (const v1::DynamicObject& o : update.objects()) {
      const bool by_camera = std::count(o.camera_ids().begin(), o.camera_ids().end(), cam.id) > 0;
      const bool by_lidar = std::count(o.camera_ids().begin(), o.camera_ids().end(), spec.id) > 0;
      if (!by_camera || !by_lidar) continue;
      const double t = clock.At(o.last_seen_ns());
      double error = 1e9;
      for (const scene::Mover& m : world.movers) {
        const Eigen::Vector3d truth = scene::MoverAt(world, m, t).position_m;
        error = std::min(error, std::hypot(o.position().x() - truth.x(), o.position().y() - truth.y()));
      }
      errors.push_back(error);
      for (const v1::DynamicObject& other : update.objects()) {
        // The LiDAR (truth) tracks every person: an object near this one that it does not list is
        // a camera placement of the same person that failed to fuse.
        const bool other_by_lidar = std::count(other.camera_ids().begin(), other.camera_ids().end(), spec.id) > 0;
        if (other.object_id() != o.object_id() && !other_by_lidar &&
            std::hypot(other.position().x() - o.position().x(), other.position().y() - o.position().y()) < 1.0) {
          ++duplicates;
        }
      }
    }
  }
  context.TryCancel();
  reader->Finish();
  const std::vector<viewer::LidarView> client_lidars = client.Lidars();
  const std::vector<viewer::ObjectView> client_objects = client.Objects();
  // The viewer's point layer switched off: the client subscribes again without points and drops
  // them while the LiDAR's sweeps keep arriving; switched on, points come back.
  auto wait_for = [&](const std::function<bool(const viewer::LidarView&)>& done) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < deadline) {
      const std::vector<viewer::LidarView> now = client.Lidars();
      if (now.size() == 1 && done(now.front())) return true;
      client.WaitUntil([](const auto&) { return false; }, std::chrono::milliseconds(50));
    }
    return false;
  };
  const uint64_t subscriptions = client.subscriptions();
  const uint64_t sweep_before_off = client_lidars.empty() ? 0 : client_lidars.front().sweep_sequence;
  client.SetIncludeLidarPoints(false);
  const bool dropped = wait_for([&](const viewer::LidarView& l) {
    return client.subscriptions() > subscriptions && l.points == nullptr && l.sweep_sequence > sweep_before_off;
  });
  client.SetIncludeLidarPoints(true);
  const bool back = wait_for([](const viewer::LidarView& l) { return l.points != nullptr; });
  client.Stop();
  stop = true;
  camera_agent.join();
  lidar_agent.join();
  server->reset();
  std::filesystem::remove_all(dir);

  ASSERT_GE(errors.size(), 20u) << "no object listed both cam1 and " << spec.id << " in 40 s";
  std::sort(errors.begin(), errors.end());
  std::cerr << "sightings of objects seen by both sensors: " << errors.size() << ", error to truth median "
            << errors[errors.size() / 2] << " m, max " << errors.back() << " m; duplicates within 1 m: " << duplicates
            << "; LiDAR tracks up to " << max_lidar_tracks << ", updates with points " << lidar_updates_with_points
            << ", points sent " << lidar_points_sent.load() << "\n";
  // Near the truth: the LiDAR's truth-based foot positions (sigma 0.15 m) dominate the fused
  // estimate; the camera's placements (issue 6: 0.5 m median) pull a little. Seen on three runs:
  // median 0.01-0.11 m, max 0.18-0.32 m (the bounds are issue 6's, for a loaded CI machine).
  EXPECT_LE(errors[errors.size() / 2], 0.5);
  EXPECT_LE(errors.back(), 1.5);
  // One object per person: no camera-only object within 1 m of one that both sensors see.
  EXPECT_EQ(duplicates, 0);
  EXPECT_GE(max_lidar_tracks, 3u);
  EXPECT_GT(lidar_updates_with_points, 0);
  EXPECT_EQ(bad_labels, 0);
  // The client library holds the LiDAR apart from the cameras, its tracks tied to fused objects,
  // and the newest sweep's points in the local frame near the people.
  ASSERT_EQ(client_lidars.size(), 1u);
  const viewer::LidarView& lidar = client_lidars.front();
  EXPECT_EQ(lidar.id, spec.id);
  EXPECT_EQ(lidar.status, viewer::CameraLiveness::kLive);
  ASSERT_FALSE(lidar.tracks.empty());
  EXPECT_TRUE(std::any_of(lidar.tracks.begin(), lidar.tracks.end(), [](const auto& t) { return t.object_id != 0; }));
  ASSERT_NE(lidar.points, nullptr);
  EXPECT_EQ(lidar.points->bad_labels, 0u);
  for (size_t k = 0; k < lidar.points->p_local.size(); ++k) {
    const auto track = std::find_if(lidar.tracks.begin(), lidar.tracks.end(),
                                    [&](const auto& t) { return t.track_id == lidar.points->track_id[k]; });
    if (track == lidar.tracks.end() || lidar.points->sweep_sequence != lidar.sweep_sequence) continue;
    // A person's points lie within a body's reach of its foot point (people are ~0.5 m wide).
    EXPECT_LT((lidar.points->p_local[k].head<2>().cast<double>() - track->position.head<2>()).norm(), 1.0);
  }
  EXPECT_TRUE(dropped) << "points still held (or no new sweep) 20 s after the layer went off";
  EXPECT_TRUE(back) << "no points 20 s after the layer came back on";
  EXPECT_TRUE(std::any_of(client_objects.begin(), client_objects.end(), [&](const viewer::ObjectView& o) {
    return std::count(o.sensor_ids.begin(), o.sensor_ids.end(), spec.id) > 0 && o.kind == 1;
  }));
}

}  // namespace
}  // namespace ave
