// The agent against a real in-process server: outages are survived with metadata replayed in order,
// and the sensor clock's offset is measured and corrected (issue 8).
#include "sensor_agent/source/fake_source.h"
#include "sensor_agent/stream/agent_streamer.h"
#include "sensor_agent/stream/link.h"


#include <filesystem>
#include <set>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"

namespace ave {
namespace {

using fixtures::FakeSource;

TEST(AgentOptions, PlaintextTokenToANonLoopbackServerIsRefusedUnlessTold) {
  AgentOptions options;
  options.camera_id = "cam";
  EXPECT_EQ(options.Check(), "");  // 127.0.0.1: as before
  options.server = "ave-server.example:50051";
  EXPECT_NE(options.Check().find("'ave-server.example:50051'"), std::string::npos);
  EXPECT_NE(options.Check().find("--insecure-plaintext"), std::string::npos);
  options.tls.insecure_plaintext = true;
  EXPECT_EQ(options.Check(), "");
  options.tls = {.ca_file = "ca.pem"};
  EXPECT_EQ(options.Check(), "");
}

// Issue 19: a paced camera loop keeps its 30 Hz schedule through a late frame (the next frames go
// out sooner) within the lag bound, and restarts it from now beyond (the tick arithmetic; no
// sleeping or wall time involved).
TEST(Pacing, ALateFrameWithinTheLagBoundKeepsTheSchedule) {
  using stream_link::Clock;
  using std::chrono::milliseconds;
  const Clock::time_point t0{};  // a fixed origin: the arithmetic, not the clock
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / 30));
  // 100 ms behind the schedule: within a 250 ms bound the next tick is one period on, in the past.
  const Clock::time_point now = t0 + milliseconds(100);
  EXPECT_EQ(stream_link::NextTick(t0, 30, now, milliseconds(250)), t0 + period);
  // Without a bound (before issue 19) every late frame restarted the schedule: the lost time stays lost.
  EXPECT_EQ(stream_link::NextTick(t0, 30, now), now);
  // Beyond the bound (a stall): restart from now rather than burst a second of frames.
  EXPECT_EQ(stream_link::NextTick(t0, 30, t0 + milliseconds(400), milliseconds(250)), t0 + milliseconds(400));
  // On time: one period on, whatever the bound.
  EXPECT_EQ(stream_link::NextTick(t0, 30, t0 + milliseconds(10), milliseconds(250)), t0 + period);
  EXPECT_EQ(stream_link::NextTick(t0, 30, t0 + milliseconds(10)), t0 + period);
  AgentOptions options;
  options.camera_id = "c";
  options.pace_max_lag = milliseconds(-1);
  EXPECT_EQ(options.Check(), "pace_max_lag must be >= 0");
}

TEST(ClockOffsetEstimator, TakesTheSmallestRoundTrip) {
  ClockOffsetEstimator e;
  e.Sent(1, 1000);
  e.Sent(2, 2000);
  ASSERT_TRUE(e.Acked(1, 50'000 + 1100, 1400));  // rtt 400: offset 50'000 - 100
  EXPECT_EQ(e.offset_ns(), 50'000 + 1100 - 1200);
  ASSERT_TRUE(e.Acked(2, 50'000 + 2010, 2020));  // rtt 20: a better sample
  EXPECT_EQ(e.rtt_ns(), 20);
  EXPECT_EQ(e.offset_ns(), 50'000 + 2010 - 2010);
  EXPECT_FALSE(e.Acked(77, 0, 3000));  // unknown sequence
}

// Issue 14: --duration (or --max-frames) ends the agent even when the server never answers; it
// used to reconnect in a tight loop for ever once the limit was reached during the outage.
TEST(AgentLimits, DurationEndsTheRunWhileTheServerIsUnreachable) {
  AgentOptions options;
  options.server = "127.0.0.1:1";  // nothing listens: every connect is refused
  options.camera_id = "cam";
  options.token = "sensor";
  options.duration_s = 0.3;
  options.spill_path = "-";
  options.backoff_initial = std::chrono::milliseconds(20);
  options.backoff_max = std::chrono::milliseconds(40);
  AgentStreamer streamer(options, std::make_unique<FakeSource>());
  const fixtures::StreamerRun run = fixtures::RunUntilItEnds(streamer, std::chrono::seconds(20));
  EXPECT_TRUE(run.ended_by_itself) << "still running 20 s after a 0.3 s --duration; " << streamer.stats().connects
                                   << " connection attempts";
  EXPECT_TRUE(run.status.ok()) << run.status;
  EXPECT_LT(streamer.stats().connects, 100);
  EXPECT_GT(streamer.stats().metadata_buffered, 0);
}

TEST(AgentLimits, SpillFileInAMissingFolderIsRefusedUpFront) {
  AgentOptions options;
  options.server = "127.0.0.1:1";
  options.camera_id = "cam";
  options.spill_path = "/nonexistent-ave-folder/cam.meta";
  AgentStreamer streamer(options, std::make_unique<FakeSource>());
  std::atomic<bool> stop{false};
  const absl::Status status = streamer.Run(stop);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(status.message()).find("camera 'cam': --spill /nonexistent-ave-folder/cam.meta: no folder"),
            std::string::npos)
      << status;
  EXPECT_EQ(streamer.stats().connects, 0);
}

class AgentFaults : public ::testing::Test {
 protected:
  void SetUp() override {
    Start("127.0.0.1:0");
    port_ = server_.port();
    AdminClient admin(server_.InsecureChannel(), "admin");
    ASSERT_TRUE(admin.AddCamera(fixtures::CameraRecord("cam")).ok());
  }
  // Starts the server on `listen` (the same store each time).
  void Start(const std::string& listen) {
    ServerOptions options = server_.Options("sensor", "", "admin");
    options.listen_address = listen;
    options.campus_grid_m = 8;
    const absl::Status started = server_.Start(options);
    ASSERT_TRUE(started.ok()) << started;
  }
  std::string Address() const { return "127.0.0.1:" + std::to_string(port_); }

  fixtures::LocalServer server_{"ave_agent_test"};
  int port_ = 0;
};

TEST_F(AgentFaults, OutageMetadataIsReplayedInOrderAndSkewIsCorrected) {
  constexpr int64_t kSkewNs = 5'000'000'000;  // the sensor's clock runs 5 s ahead of the server's
  auto sensor_clock = [] { return NowNs() + kSkewNs; };
  AgentOptions options;
  options.server = Address();
  options.camera_id = "cam";
  options.token = "sensor";
  options.fps = 30;
  options.backoff_initial = std::chrono::milliseconds(100);
  options.backoff_max = std::chrono::milliseconds(400);
  options.metadata_in_memory = 5;  // force a spill to disk during the outage
  options.spill_path = (server_.dir() / "cam.meta").string();
  options.clock = sensor_clock;
  AgentStreamer streamer(options, std::make_unique<FakeSource>(sensor_clock));
  std::atomic<bool> stop{false};
  absl::Status result;
  std::thread agent([&] { result = streamer.Run(stop); });

  auto wait_for = [&](const std::function<bool()>& done, std::chrono::seconds limit) {
    const auto until = std::chrono::steady_clock::now() + limit;
    while (!done() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return done();
  };
  ASSERT_TRUE(wait_for([&] { return streamer.stats().frames_acked >= 10; }, std::chrono::seconds(20)));

  server_.Stop();  // outage: ~1.5 s, the agent keeps capturing
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_GT(streamer.stats().metadata_buffered, 10);
  const auto back = std::chrono::steady_clock::now();
  Start(Address());
  ASSERT_TRUE(wait_for([&] { return server_->state().AcceptedCount("cam") >= 5; }, std::chrono::seconds(10)));
  const double back_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - back).count();
  EXPECT_LT(back_s, 5.0) << "the agent took too long to come back";
  stop = true;
  agent.join();
  ASSERT_TRUE(result.ok()) << result;

  const AgentStats s = streamer.stats();
  EXPECT_GE(s.connects, 2);
  EXPECT_EQ(s.metadata_dropped, 0);
  EXPECT_EQ(s.metadata_replayed, s.metadata_buffered);
  // Every replayed record reached the server (it validated their increasing sequences).
  EXPECT_EQ(server_->state().MetadataCount("cam"), static_cast<uint64_t>(s.metadata_replayed));
  // The offset estimate cancels the 5 s skew to within the loopback round trip.
  EXPECT_NEAR(s.clock_offset_ns, -kSkewNs, 50e6);
  auto latest = server_->state().LatestFrame("cam");
  ASSERT_NE(latest, nullptr);
  const int64_t capture_on_server = latest->capture_time_ns() + latest->clock_offset_ns();
  EXPECT_NEAR(static_cast<double>(capture_on_server), static_cast<double>(NowNs()), 2e9);
}

// A source that fails on the given reads (0-based), as a network camera that goes down does.
class FlakySource final : public FakeSource {
 public:
  explicit FlakySource(std::set<int> failing) : failing_(std::move(failing)) {}
  absl::StatusOr<CapturedFrame> Next() override {
    if (failing_.count(reads_++) > 0) return absl::UnavailableError("fake: stream down");
    return FakeSource::Next();
  }

 private:
  std::set<int> failing_;
  int reads_ = 0;
};

TEST_F(AgentFaults, ASourceThatGoesDownIsRetriedWithADoublingWaitAndItsOutagesCounted) {
  AgentOptions options;
  options.server = Address();
  options.camera_id = "cam";
  options.token = "sensor";
  options.fps = 200;
  options.max_frames = 12;
  options.spill_path = "-";
  options.source_retry_initial = std::chrono::milliseconds(10);
  options.source_retry_max = std::chrono::milliseconds(40);
  // Two outages: reads 2-6 (five failures: waits 10, 20, 40, 40, 40 ms) and 10-12 (10, 20, 40 ms).
  AgentStreamer streamer(options, std::make_unique<FlakySource>(std::set<int>{2, 3, 4, 5, 6, 10, 11, 12}));
  std::atomic<bool> stop{false};
  const absl::Status status = streamer.Run(stop);
  ASSERT_TRUE(status.ok()) << status;
  const AgentStats s = streamer.stats();
  EXPECT_EQ(s.frames_sent, 12);
  EXPECT_EQ(s.source_errors, 8);
  EXPECT_EQ(s.source_outages, 2);
  EXPECT_GE(s.source_down_s, 0.219) << "the waits double from 10 ms to 40 ms: 150 + 70 ms at least";
  EXPECT_EQ(s.last_error, "fake: stream down");
}

TEST(AgentOptions, ASourceRetryThatCannotDoubleIsRefused) {
  AgentOptions options;
  options.camera_id = "cam";
  options.source_retry_initial = std::chrono::milliseconds(100);
  options.source_retry_max = std::chrono::milliseconds(50);
  EXPECT_EQ(options.Check(), "source retry must be 0 < initial <= max");
}

}  // namespace
}  // namespace ave
