// The LiDAR uplink (issue 16): the wire conversion (world_from_ground applied, points quantised and
// labelled by track) and the streamer against a real in-process server, through a server restart.
#include "sensor_agent/stream/lidar_streamer.h"

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/stream/lidar_test_fixtures.h"

namespace ave {
namespace {

// The packed point k of a wire message: (x_cm, y_cm, z_cm, label).
std::array<int, 4> PointAt(const v1::LidarPoints& points, int k) {
  std::array<int, 4> out{};
  for (int i = 0; i < 4; ++i) {
    uint16_t v = 0;
    std::memcpy(&v, points.packed().data() + 8 * k + 2 * i, 2);  // little-endian host (x86-64, arm64)
    out[i] = i < 3 ? static_cast<int16_t>(v) : v;
  }
  return out;
}

lidar::LidarSweep TwoPointSweep() {
  lidar::LidarSweep sweep;
  sweep.t_ns = 123;
  sweep.points.resize(4);
  sweep.points[0].p_in_sensor = Eigen::Vector3f(1.234f, -2.5f, 0.004f);
  sweep.points[1].p_in_sensor = Eigen::Vector3f(3, 4, 5);
  sweep.points[2].p_in_sensor = Eigen::Vector3f(400, 0, 0);  // beyond int16 cm
  sweep.points[3].p_in_sensor = Eigen::Vector3f(-1, -1, -1);
  return sweep;
}

TEST(SweepToWire, AppliesWorldFromGroundAndLabelsPointsByStreamedTrack) {
  lidar::FootTracks tracks;
  // Ground frame turned 90 degrees about z and lifted: x_ground -> y_world.
  tracks.world_from_ground = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ())),
                                     Eigen::Vector3d(10, 20, 1.5));
  lidar::FootTrack a;
  a.id = 40;
  a.xy_m = Eigen::Vector2d(2, 0);
  a.velocity_mps = Eigen::Vector2d(1, 0);
  a.covariance_m2 << 0.09, 0, 0, 0.01;
  a.confirmed = true;
  a.age_frames = 7;
  lidar::FootTrack unconfirmed = a;
  unconfirmed.id = 41;
  unconfirmed.confirmed = false;
  tracks.tracks = {unconfirmed, a};
  tracks.point_track_id = {40, 0, 40, 41};
  int64_t dropped = 0;
  const v1::LidarSweepFrame wire = SweepToWire(TwoPointSweep(), tracks, true, 1000, &dropped);
  EXPECT_EQ(wire.capture_time_ns(), 123);
  ASSERT_EQ(wire.tracks_size(), 1);  // only confirmed tracks are streamed
  const v1::FootTrack& t = wire.tracks(0);
  EXPECT_EQ(t.track_id(), 40u);
  EXPECT_NEAR(t.position().x(), 10, 1e-9);
  EXPECT_NEAR(t.position().y(), 22, 1e-9);
  EXPECT_NEAR(t.position().z(), 1.5, 1e-9);
  EXPECT_NEAR(t.velocity_x_mps(), 0, 1e-6);
  EXPECT_NEAR(t.velocity_y_mps(), 1, 1e-6);
  ASSERT_EQ(t.covariance_size(), 3);
  EXPECT_NEAR(t.covariance(0), 0.01, 1e-7);  // the ground x variance is now along world y
  EXPECT_NEAR(t.covariance(1), 0, 1e-7);
  EXPECT_NEAR(t.covariance(2), 0.09, 1e-7);
  EXPECT_EQ(t.age_sweeps(), 7u);
  // Point 0 (track 40) goes out; point 2 is out of int16 range, point 3's track is unconfirmed.
  ASSERT_EQ(wire.foreground().count(), 1u);
  ASSERT_EQ(wire.foreground().packed().size(), 8u);
  EXPECT_EQ(PointAt(wire.foreground(), 0), (std::array<int, 4>{123, -250, 0, 1}));
  EXPECT_EQ(dropped, 2);
  // Without points, or with no room for them.
  EXPECT_EQ(SweepToWire(TwoPointSweep(), tracks, false, 1000).foreground().count(), 0u);
  EXPECT_EQ(SweepToWire(TwoPointSweep(), tracks, true, 0).foreground().count(), 0u);
}

TEST(SweepToWire, OverTheBudgetPointsAreDecimatedEvenlyNotCut) {
  lidar::LidarSweep sweep;
  lidar::FootTracks tracks;
  for (uint32_t id : {1u, 2u}) {
    lidar::FootTrack t;
    t.id = id;
    t.confirmed = true;
    tracks.tracks.push_back(t);
  }
  // 100 points of person 1, then 100 of person 2 (as a sweep's azimuth order would give them).
  for (int i = 0; i < 200; ++i) {
    lidar::SweepPoint p;
    p.p_in_sensor = Eigen::Vector3f(0.01f * i, 1, 0);
    sweep.points.push_back(p);
    tracks.point_track_id.push_back(i < 100 ? 1 : 2);
  }
  int64_t dropped = 0;
  const v1::LidarSweepFrame wire = SweepToWire(sweep, tracks, true, 50, &dropped);
  ASSERT_EQ(wire.foreground().count(), 50u);
  EXPECT_EQ(dropped, 150);
  int per_label[3] = {0, 0, 0};
  for (int k = 0; k < 50; ++k) ++per_label[PointAt(wire.foreground(), k)[3]];
  EXPECT_EQ(per_label[1], 25);  // both people keep points
  EXPECT_EQ(per_label[2], 25);
}

TEST(SweepToWire, NonFiniteTracksAreLeftOutNotSentToBeRefused) {
  lidar::FootTracks tracks;
  lidar::FootTrack bad;
  bad.id = 3;
  bad.xy_m = Eigen::Vector2d(NAN, 0);
  bad.confirmed = true;
  tracks.tracks = {bad};
  EXPECT_EQ(SweepToWire(TwoPointSweep(), tracks, true, 10).tracks_size(), 0);
}

TEST(SweepToWire, ATrackFasterThanTheServerTakesIsLeftOutAndTheOthersSent) {
  lidar::FootTracks tracks;
  lidar::FootTrack fast, walking;
  fast.id = 3;
  fast.xy_m = Eigen::Vector2d(4, 0);
  fast.velocity_mps = Eigen::Vector2d(0.01 / 50e-6, 0);  // 1 cm in 50 us: two sweeps stamped almost together
  fast.confirmed = true;
  walking = fast;
  walking.id = 4;
  walking.velocity_mps = Eigen::Vector2d(1.3, 0);
  tracks.tracks = {fast, walking};
  const v1::LidarSweepFrame wire = SweepToWire(TwoPointSweep(), tracks, true, 10);
  ASSERT_EQ(wire.tracks_size(), 1);
  EXPECT_EQ(wire.tracks(0).track_id(), 4u);
  EXPECT_FLOAT_EQ(wire.tracks(0).velocity_x_mps(), 1.3f);
}

// The simulator's courtyard LiDAR through the truth fixture: the people in range, labelled points.
TEST(LidarFixtures, CourtyardSweepHasPeopleAndTheirLabelledPoints) {
  auto scenario = sim::LoadScenario("courtyard");
  ASSERT_TRUE(scenario.ok()) << scenario.status();
  ASSERT_FALSE(scenario->rotating_lidars.empty());
  const sim::RotatingLidarSpec& spec = scenario->rotating_lidars.front();
  EXPECT_EQ(spec.id, "hdl64");
  const auto started = std::chrono::steady_clock::now();
  const lidar::LidarSweep sweep =
      fixtures::SweepFromSim(sim::SimulateRotatingLidarFrame(scenario->world, spec, scenario->effects, scenario->seed, 5.0), spec);
  std::cerr << "one hdl64 sweep: " << sweep.points.size() << " points in "
            << std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() << " s\n";
  ASSERT_GT(sweep.truth_feet_in_world.size(), 2u);
  auto tracks = fixtures::TruthFootTracker()(sweep);
  ASSERT_TRUE(tracks.ok());
  const v1::LidarSweepFrame wire = SweepToWire(sweep, *tracks, true, 262144);
  EXPECT_EQ(wire.tracks_size(), static_cast<int>(sweep.truth_feet_in_world.size()));
  EXPECT_GT(wire.foreground().count(), 50u);
  EXPECT_EQ(wire.world_from_sensor().position().x(), spec.position_m.x());
}

class LidarStreamerFaults : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("ave_lidar_streamer_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    Start("127.0.0.1:0");
    port_ = server_->port();
    AdminClient admin(grpc::CreateChannel(Address(), grpc::InsecureChannelCredentials()), "admin");
    ASSERT_TRUE(admin.AddCamera(LidarRecord("hdl", "hdl", Rigid3d(Eigen::Quaterniond::Identity(), {0, 0, 2}))).ok());
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(dir_);
  }
  void Start(const std::string& listen) {
    ServerOptions options;
    options.listen_address = listen;
    options.store_path = (dir_ / "ave.db").string();
    options.sensor_token = "sensor";
    options.admin_token = "admin";
    options.seed_campus = false;
    auto server = FusionServer::Start(options);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
  }
  std::string Address() const { return "127.0.0.1:" + std::to_string(port_); }

  std::filesystem::path dir_;
  std::unique_ptr<FusionServer> server_;
  int port_ = 0;
};

// A walker 4 m east of the sensor going east at 0.5 m/s, one sweep every call; the tracker is the
// truth fixture. Its position is a function of the sweep's time, as a person's is: a fixed step per
// call made two calls close in time (the streamer's pacing catches up after a stall) a walker at
// over 100 m/s, a velocity the server refuses.
SweepSource WalkerSweeps() {
  const int64_t t0 = NowNs();
  return [t0]() -> absl::StatusOr<lidar::LidarSweep> {
    lidar::LidarSweep sweep;
    sweep.t_ns = NowNs();
    sweep.truth_feet_in_world = {{7, Eigen::Vector3d(4 + 0.5 * (sweep.t_ns - t0) * 1e-9, 0, 0)}};
    return sweep;
  };
}

TEST_F(LidarStreamerFaults, ReconnectsAfterAServerRestartAndTracksThroughTheOutage) {
  LidarStreamOptions options;
  options.server = Address();
  options.sensor_id = "hdl";
  options.token = "sensor";
  options.pace_hz = 50;
  options.backoff_initial = std::chrono::milliseconds(100);
  options.backoff_max = std::chrono::milliseconds(400);
  LidarStreamer streamer(options, WalkerSweeps(), fixtures::TruthFootTracker());
  std::atomic<bool> stop{false};
  absl::Status result;
  std::thread agent([&] { result = streamer.Run(stop); });
  auto wait_for = [&](const std::function<bool()>& done, std::chrono::seconds limit) {
    const auto until = std::chrono::steady_clock::now() + limit;
    while (!done() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return done();
  };
  ASSERT_TRUE(wait_for([&] { return streamer.stats().sweeps_acked >= 10; }, std::chrono::seconds(20)));
  EXPECT_EQ(server_->state().ObjectCount(), 1u);
  server_.reset();
  std::this_thread::sleep_for(std::chrono::milliseconds(800));
  Start(Address());
  ASSERT_TRUE(wait_for([&] { return server_->state().AcceptedCount("hdl") >= 5; }, std::chrono::seconds(10)));
  stop = true;
  agent.join();
  ASSERT_TRUE(result.ok()) << result;
  const LidarStreamStats s = streamer.stats();
  EXPECT_GE(s.connects, 2);
  EXPECT_GT(s.sweeps_dropped, 0);  // swept during the outage: tracked, not sent
  EXPECT_EQ(s.tracker_errors, 0);
  EXPECT_EQ(server_->state().ObjectCount(), 1u);
}

TEST_F(LidarStreamerFaults, AWrongTokenIsFatalNotRetried) {
  LidarStreamOptions options;
  options.server = Address();
  options.sensor_id = "hdl";
  options.token = "not-a-token";
  std::atomic<bool> stop{false};
  const absl::Status s = StreamLidar(options, WalkerSweeps(), fixtures::TruthFootTracker(), stop);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnauthenticated) << s;
}

// Issue 14's agent fix, for the LiDAR uplink too: a --duration reached while the server never
// answers ends the run instead of reconnecting in a tight loop for ever.
TEST(LidarStreamerLimits, DurationEndsTheRunWhileTheServerIsUnreachable) {
  LidarStreamOptions options;
  options.server = "127.0.0.1:1";  // nothing listens: every connect is refused
  options.sensor_id = "hdl";
  options.token = "sensor";
  options.duration_s = 0.3;
  options.pace_hz = 20;
  options.backoff_initial = std::chrono::milliseconds(20);
  options.backoff_max = std::chrono::milliseconds(40);
  LidarStreamer streamer(options, WalkerSweeps(), fixtures::TruthFootTracker());
  const fixtures::StreamerRun run = fixtures::RunUntilItEnds(streamer, std::chrono::seconds(20));
  EXPECT_TRUE(run.ended_by_itself) << "still running 20 s after a 0.3 s --duration; " << streamer.stats().connects
                                   << " connection attempts";
  EXPECT_TRUE(run.status.ok()) << run.status;
  EXPECT_LT(streamer.stats().connects, 100);
}

}  // namespace
}  // namespace ave
