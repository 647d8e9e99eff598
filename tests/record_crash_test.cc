// Issue 18 crash test, short form: a real ave-server process recording ten agents' streams is
// killed with SIGKILL three times mid-write and restarted on the same store and recording. After
// each kill the index and the segment files agree: every indexed frame lies inside its segment and
// decodes as a JPEG of the declared size, PRAGMA integrity_check is clean; after each restart the
// unindexed tails are cut (every segment file is exactly as long as its indexed bytes) and
// recording goes on; the newest frame each agent's acks called recorded (SensorAck.recorded_sequence)
// before a kill is in the index. AVE_RECORD_CRASH_KILLS gives the issue's full form (10 kills).
// The server runs in turn with the defaults (O_DIRECT batches, --record-sync syncfs,
// --record-sync-ms 500), with fdatasync every 250 ms, and with the defaults plus
// --record-buffered-io (segment bytes through the page cache).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <filesystem>
#include <string>
#include <vector>
#include <fstream>
#include <iostream>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>
#include <opencv2/imgcodecs.hpp>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/record/record_index.h"
#include "fusion_server/record/recorder.h"
#include "fusion_server/service/test_fixtures.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "model_store/common/log.h"
#include "model_store/db/store.h"
#include "sensor_agent/source/fake_source.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace ave {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const int kCameras = 10;
const int kKills = fixtures::EnvCount("AVE_RECORD_CRASH_KILLS", 3);

// ave-server recording into <dir>/rec, as the demo runs it.
class RecordingServer {
 public:
  RecordingServer(fs::path dir, int port) : dir_(std::move(dir)), port_(port) {}
  ~RecordingServer() { Kill(SIGKILL); }
  // kPerFile: --record-sync fdatasync (one fdatasync per segment) every 250 ms instead of the
  // defaults (syncfs every 500 ms, O_DIRECT batches); kBuffered: the defaults plus
  // --record-buffered-io (segment bytes through the page cache).
  enum Mode { kDefaults, kPerFile, kBuffered };
  void Start(Mode mode = kDefaults) {
    const bool per_file = mode == kPerFile;
    pid_ = ::fork();
    if (pid_ == 0) {
      std::freopen((dir_ / "server.log").c_str(), "a", stderr);
      std::freopen("/dev/null", "w", stdout);
      const std::string listen = address();
      const std::string store = (dir_ / "ave.db").string();
      const std::string rec = (dir_ / "rec").string();
      const std::string bin = std::string(AVE_BIN_DIR) + "/ave-server";
      ::setenv("AVE_SENSOR_TOKEN", "sensor", 1);
      ::setenv("AVE_VIEWER_TOKEN", "viewer", 1);
      ::setenv("AVE_ADMIN_TOKEN", "admin", 1);
      std::vector<std::string> args = {bin, "--listen", listen, "--store", store, "--campus-grid", "8", "--record-dir", rec,
                                       "--record-sync", per_file ? "fdatasync" : "syncfs", "--record-sync-ms",
                                       per_file ? "250" : "500"};
      if (mode == kBuffered) args.push_back("--record-buffered-io");
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(bin.c_str(), argv.data());
      std::_Exit(127);
    }
  }
  bool WaitServing(std::chrono::seconds limit) {
    auto health = grpc::health::v1::Health::NewStub(grpc::CreateChannel(address(), grpc::InsecureChannelCredentials()));
    for (const auto until = Clock::now() + limit; Clock::now() < until;) {
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(200));
      grpc::health::v1::HealthCheckResponse response;
      if (health->Check(&context, {}, &response).ok() &&
          response.status() == grpc::health::v1::HealthCheckResponse::SERVING) {
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  void Kill(int sig) {
    if (pid_ <= 0) return;
    ::kill(pid_, sig);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = 0;
  }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }

 private:
  fs::path dir_;
  int port_;
  pid_t pid_ = 0;
};

struct Agent {
  std::unique_ptr<AgentStreamer> streamer;
  std::atomic<bool> stop{false};
  std::thread thread;
};

// Indexed frames, after checking that each one decodes as a 64x48 JPEG from its segment.
int64_t CheckIndexAgainstSegments(const fs::path& dir, bool tails_cut) {
  auto index = record::RecordIndex::Open((dir / "ave.db").string());
  EXPECT_TRUE(index.ok()) << index.status();
  if (!index.ok()) return -1;
  EXPECT_EQ(*(*index)->IntegrityCheck(), "ok");
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 1 << 22);
  EXPECT_TRUE(rows.ok()) << rows.status();
  for (const record::FrameRow& row : *rows) {
    auto bytes = record::ReadSegmentBytes((dir / "rec").string(), row.segment_path, row.offset, row.length);
    EXPECT_TRUE(bytes.ok()) << bytes.status();
    if (!bytes.ok()) return -1;
    const cv::Mat image = cv::imdecode(cv::Mat(1, static_cast<int>(bytes->size()), CV_8U, bytes->data()), cv::IMREAD_COLOR);
    EXPECT_EQ(image.cols, 64) << row.segment_path << " @" << row.offset;
    EXPECT_EQ(image.rows, 48) << row.segment_path << " @" << row.offset;
  }
  if (tails_cut) {
    auto segments = (*index)->Segments();
    for (const record::SegmentRow& seg : *segments) {
      std::error_code ec;
      const auto size = fs::file_size(dir / "rec" / seg.path, ec);
      // The running server may have appended to its open segments since; closed ones are exact.
      if (!ec && seg.closed) {
        EXPECT_EQ(static_cast<int64_t>(size), seg.bytes) << seg.path;
      }
    }
  }
  return static_cast<int64_t>(rows->size());
}

// For each agent whose acks said a frame was recorded (SensorAck.recorded_sequence), whether the
// index holds that frame; the number of agents checked.
int CheckAckedRecordedFramesIndexed(const fs::path& dir, const std::vector<Agent>& agents, int kill) {
  auto index = record::RecordIndex::Open((dir / "ave.db").string());
  EXPECT_TRUE(index.ok()) << index.status();
  if (!index.ok()) return 0;
  int checked = 0;
  for (size_t i = 0; i < agents.size(); ++i) {
    const uint64_t recorded = agents[i].streamer->stats().recorded_sequence;
    if (recorded == 0) continue;
    const std::string id = "cam" + std::to_string(i);
    auto rows = (*index)->Frames({id}, 0, std::numeric_limits<int64_t>::max(), 1 << 20);
    EXPECT_TRUE(rows.ok()) << rows.status();
    if (!rows.ok()) continue;
    EXPECT_TRUE(std::any_of(rows->begin(), rows->end(), [&](const record::FrameRow& r) { return r.sequence == recorded; }))
        << id << ": frame " << recorded << " was acked as recorded before kill " << kill << " but is not indexed";
    ++checked;
  }
  return checked;
}

TEST(RecordCrash, KillNineWhileRecordingLeavesIndexAndSegmentsInAgreement) {
  log::MinLevel() = log::Level::kERROR;
  const fs::path dir = fs::temp_directory_path() / ("ave_record_crash_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  RecordingServer server(dir, fixtures::FreeLoopbackPort());
  server.Start();
  ASSERT_TRUE(server.WaitServing(std::chrono::seconds(20))) << "server did not start";
  AdminClient admin(grpc::CreateChannel(server.address(), grpc::InsecureChannelCredentials()), "admin");
  std::vector<Agent> agents(kCameras);
  for (int i = 0; i < kCameras; ++i) {
    const std::string id = "cam" + std::to_string(i);
    ASSERT_TRUE(admin.AddCamera(fixtures::CameraRecord(id)).ok());
    AgentOptions options;
    options.server = server.address();
    options.camera_id = id;
    options.token = "sensor";
    options.fps = 15;
    options.backoff_initial = std::chrono::milliseconds(100);
    options.backoff_max = std::chrono::milliseconds(500);
    agents[i].streamer = std::make_unique<AgentStreamer>(options, std::make_unique<fixtures::FakeSource>());
    agents[i].thread = std::thread([&a = agents[i]] { a.streamer->Run(a.stop).IgnoreError(); });
  }
  // Waits until the running server has indexed more than `than` frames (it commits every 0.5 s).
  auto wait_indexed = [&](int64_t than) {
    const auto until = Clock::now() + std::chrono::seconds(20);
    int64_t now_indexed = 0;
    while (now_indexed <= than && Clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      auto index = record::RecordIndex::Open((dir / "ave.db").string());
      if (!index.ok()) continue;
      auto spans = (*index)->Spans();
      if (!spans.ok()) continue;
      now_indexed = 0;
      for (const auto& span : *spans) now_indexed += span.frames;
    }
    return now_indexed;
  };
  int64_t indexed = 0;
  int acked_recorded = 0;
  for (int kill = 0; kill < kKills; ++kill) {
    // Kill at a time unrelated to the recorder's commit rhythm, once this run has recorded.
    const int64_t now_indexed = wait_indexed(indexed + kCameras);
    ASSERT_GT(now_indexed, indexed + kCameras) << "recording did not go on before kill " << kill;
    std::this_thread::sleep_for(std::chrono::milliseconds(137 * (kill + 1) % 500));
    server.Kill(SIGKILL);
    const int64_t after_kill = CheckIndexAgainstSegments(dir, false);
    EXPECT_GE(after_kill, now_indexed) << "a committed row vanished in kill " << kill;
    // Acked as recorded means stored: the newest SensorAck.recorded_sequence each agent received
    // before the kill names a frame the index still holds.
    acked_recorded += CheckAckedRecordedFramesIndexed(dir, agents, kill);
    // Each mode is killed mid-write: defaults (kill 0), fdatasync (1), O_DIRECT (2), ...
    server.Start(static_cast<RecordingServer::Mode>((kill + 1) % 3));
    ASSERT_TRUE(server.WaitServing(std::chrono::seconds(20))) << "server did not come back after kill " << kill;
    CheckIndexAgainstSegments(dir, true);
    indexed = after_kill;
  }
  EXPECT_GT(acked_recorded, 0) << "no ack ever said a frame was recorded";
  const int64_t running = wait_indexed(indexed + kCameras);
  EXPECT_GT(running, indexed + kCameras) << "recording did not go on after the last restart";
  for (auto& a : agents) a.stop = true;
  for (auto& a : agents) a.thread.join();
  server.Kill(SIGTERM);  // drains: what was queued is written and indexed
  const int64_t final_indexed = CheckIndexAgainstSegments(dir, true);
  EXPECT_GE(final_indexed, running);
  // What the restarts repaired, from the server's own start-up lines (for docs/RELIABILITY.md).
  std::ifstream log(dir / "server.log");
  int tails = 0, orphans = 0;
  for (std::string line; std::getline(log, line);) {
    const auto at = line.find(" tails truncated, ");
    if (at == std::string::npos) continue;
    tails += std::atoi(line.substr(line.rfind(", ", at - 1) + 2).c_str());
    orphans += std::atoi(line.substr(at + 18).c_str());
  }
  std::cout << "record crash: " << kKills << " kills, " << final_indexed << " frames indexed, " << tails
            << " segment tails truncated and " << orphans << " unindexed segment files removed at restarts; "
            << acked_recorded << " agents' last frame acked as recorded before a kill, all indexed\n";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace ave
