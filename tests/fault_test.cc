// Issue 8 fault test, short form: a real ave-server process under load from ten agents and one
// viewer is killed with SIGKILL three times mid-load and restarted on the same port and store.
// Every committed camera and audit record must survive, every agent must be streaming again and
// the viewer receiving every camera within 5 s of the server's return, metadata buffered during
// the outages must be replayed, an agent killed and restarted must come back, and SIGTERM must
// drain and exit cleanly.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/test_fixtures.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "model_store/common/log.h"
#include "model_store/db/store.h"
#include "sensor_agent/source/fake_source.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace ave {
namespace {

using Clock = std::chrono::steady_clock;
// The CI form; AVE_FAULT_CAMERAS / AVE_FAULT_KILLS give the full form (50 streams, 10 kills).
const int kCameras = fixtures::EnvCount("AVE_FAULT_CAMERAS", 10);
const int kKills = fixtures::EnvCount("AVE_FAULT_KILLS", 3);

using fixtures::CameraRecord;
using fixtures::FakeSource;

class ServerProcess {
 public:
  ServerProcess(std::filesystem::path dir, int port) : dir_(std::move(dir)), port_(port) {}
  ~ServerProcess() { Kill(SIGKILL); }
  void Start() {
    pid_ = ::fork();
    if (pid_ == 0) {
      const std::string log = (dir_ / "server.log").string();
      std::freopen(log.c_str(), "a", stderr);
      std::freopen("/dev/null", "w", stdout);
      const std::string listen = "127.0.0.1:" + std::to_string(port_);
      const std::string store = (dir_ / "ave.db").string();
      const std::string bin = std::string(AVE_BIN_DIR) + "/ave-server";
      ::setenv("AVE_SENSOR_TOKEN", "sensor", 1);
      ::setenv("AVE_VIEWER_TOKEN", "viewer", 1);
      ::setenv("AVE_ADMIN_TOKEN", "admin", 1);
      execl(bin.c_str(), bin.c_str(), "--listen", listen.c_str(), "--store", store.c_str(), "--campus-grid", "8",
            static_cast<char*>(nullptr));
      std::_Exit(127);
    }
  }
  // Waits until the health service answers SERVING; the time it did, or nullopt.
  std::optional<Clock::time_point> WaitServing(std::chrono::seconds limit) {
    auto channel = grpc::CreateChannel(address(), grpc::InsecureChannelCredentials());
    auto health = grpc::health::v1::Health::NewStub(channel);
    const auto until = Clock::now() + limit;
    while (Clock::now() < until) {
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(200));
      grpc::health::v1::HealthCheckResponse response;
      if (health->Check(&context, {}, &response).ok() &&
          response.status() == grpc::health::v1::HealthCheckResponse::SERVING) {
        return Clock::now();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return std::nullopt;
  }
  // Sends `sig` and reaps; the exit status (or -1).
  int Kill(int sig) {
    if (pid_ <= 0) return -1;
    ::kill(pid_, sig);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = 0;
    return status;
  }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }

 private:
  std::filesystem::path dir_;
  int port_;
  pid_t pid_ = 0;
};

struct Agent {
  std::unique_ptr<AgentStreamer> streamer;
  std::atomic<bool> stop{false};
  std::thread thread;
  absl::Status result;
};

void StartAgent(Agent& a, const std::string& address, const std::string& id, const std::filesystem::path& dir) {
  AgentOptions options;
  options.server = address;
  options.camera_id = id;
  options.token = "sensor";
  options.fps = 10;
  options.backoff_initial = std::chrono::milliseconds(100);
  options.backoff_max = std::chrono::milliseconds(1000);
  options.metadata_in_memory = 4;  // spill to disk in every outage
  options.spill_path = (dir / (id + ".meta")).string();
  a.stop = false;
  a.streamer = std::make_unique<AgentStreamer>(options, std::make_unique<FakeSource>());
  a.thread = std::thread([&a] { a.result = a.streamer->Run(a.stop); });
}

TEST(Faults, KillNineUnderLoadLosesNothingCommittedAndEveryoneIsBackWithinFiveSeconds) {
  log::MinLevel() = log::Level::kERROR;
  const auto dir = std::filesystem::temp_directory_path() / ("ave_fault_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ServerProcess server(dir, fixtures::FreeLoopbackPort());
  server.Start();
  ASSERT_TRUE(server.WaitServing(std::chrono::seconds(20))) << "server did not start";
  auto admin_channel = grpc::CreateChannel(server.address(), grpc::InsecureChannelCredentials());
  AdminClient admin(admin_channel, "admin");
  std::vector<std::string> ids;
  for (int i = 0; i < kCameras; ++i) {
    ids.push_back("cam" + std::to_string(i));
    ASSERT_TRUE(admin.AddCamera(CameraRecord(ids.back())).ok());
  }
  std::vector<Agent> agents(kCameras);
  for (int i = 0; i < kCameras; ++i) StartAgent(agents[i], server.address(), ids[i], dir);

  // The viewer: resubscribes on its own when the stream breaks; records when each camera's JPEG came.
  std::mutex seen_mu;
  std::map<std::string, Clock::time_point> last_jpeg;
  std::atomic<bool> viewer_stop{false};
  std::thread viewer([&] {
    while (!viewer_stop.load()) {
      auto channel = grpc::CreateChannel(server.address(), grpc::InsecureChannelCredentials());
      auto stub = v1::SceneService::NewStub(channel);
      grpc::ClientContext context;
      context.AddMetadata("authorization", "Bearer viewer");
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
      v1::SubscribeRequest request;
      request.set_include_jpeg(true);
      auto reader = stub->Subscribe(&context, request);
      std::atomic<bool> done{false};
      std::thread canceller([&] {
        while (!done.load() && !viewer_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        if (viewer_stop.load()) context.TryCancel();
      });
      v1::SceneUpdate update;
      while (reader->Read(&update)) {
        std::lock_guard lock(seen_mu);
        for (const auto& cam : update.cameras()) {
          if (!cam.jpeg().empty()) last_jpeg[cam.camera_id()] = Clock::now();
        }
      }
      reader->Finish();
      done = true;
      canceller.join();
      if (!viewer_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  });

  auto wait_until = [](const std::function<bool()>& done, Clock::time_point until) {
    while (!done() && Clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return done();
  };
  int committed_cameras = kCameras;
  for (int kill = 0; kill < kKills; ++kill) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // load runs
    // A committed write right before the crash.
    ASSERT_TRUE(admin.AddCamera(CameraRecord("extra" + std::to_string(kill))).ok());
    ++committed_cameras;
    std::vector<int64_t> acked_before;
    for (auto& a : agents) acked_before.push_back(a.streamer->stats().frames_acked);
    server.Kill(SIGKILL);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // the outage
    server.Start();
    const auto back = server.WaitServing(std::chrono::seconds(20));
    ASSERT_TRUE(back) << "server did not come back after kill " << kill;
    // Every committed camera and audit record is there.
    auto cameras = admin.ListCameras();
    ASSERT_TRUE(cameras.ok()) << cameras.status();
    EXPECT_EQ(static_cast<int>(cameras->size()), committed_cameras) << "after kill " << kill;
    {
      auto store = store::Store::Open((dir / "ave.db").string());
      ASSERT_TRUE(store.ok()) << store.status();
      auto audit = (*store)->ListAudit(1000);
      ASSERT_TRUE(audit.ok());
      EXPECT_EQ(static_cast<int>(audit->size()), committed_cameras) << "audit rows after kill " << kill;
    }
    // Agents stream again (new acks) and the viewer gets every camera, within 5 s.
    const auto deadline = *back + std::chrono::seconds(5);
    const bool agents_back = wait_until(
        [&] {
          for (int i = 0; i < kCameras; ++i) {
            if (agents[i].streamer->stats().frames_acked <= acked_before[i]) return false;
          }
          return true;
        },
        deadline);
    EXPECT_TRUE(agents_back) << "not every agent was back within 5 s after kill " << kill;
    const bool viewer_back = wait_until(
        [&] {
          std::lock_guard lock(seen_mu);
          for (const auto& id : ids) {
            auto it = last_jpeg.find(id);
            if (it == last_jpeg.end() || it->second < *back) return false;
          }
          return true;
        },
        deadline);
    EXPECT_TRUE(viewer_back) << "the viewer did not get every camera within 5 s after kill " << kill;
  }

  // An agent killed and restarted comes back; the others never noticed.
  agents[0].stop = true;
  agents[0].thread.join();
  const int64_t others_before = agents[1].streamer->stats().frames_acked;
  StartAgent(agents[0], server.address(), ids[0], dir);
  EXPECT_TRUE(wait_until([&] { return agents[0].streamer->stats().frames_acked > 3; }, Clock::now() + std::chrono::seconds(5)));
  EXPECT_GT(agents[1].streamer->stats().frames_acked, others_before);

  // SIGTERM drains: the server exits by itself, cleanly.
  for (auto& a : agents) a.stop = true;
  for (auto& a : agents) a.thread.join();
  viewer_stop = true;
  const auto term_start = Clock::now();
  const int status = server.Kill(SIGTERM);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - term_start).count(), 5.0);
  viewer.join();

  int64_t buffered = 0, replayed = 0, dropped = 0;
  for (int i = 1; i < kCameras; ++i) {
    const AgentStats s = agents[i].streamer->stats();
    EXPECT_TRUE(agents[i].result.ok()) << agents[i].result;
    EXPECT_GE(s.connects, 1 + kKills) << ids[i];
    buffered += s.metadata_buffered;
    replayed += s.metadata_replayed;
    dropped += s.metadata_dropped;
  }
  EXPECT_GT(buffered, 0);  // the outages were long enough to buffer
  EXPECT_EQ(dropped, 0);
  // Everything buffered before the last restart was replayed (the final stop may leave a few).
  EXPECT_GE(replayed, buffered - 2 * kCameras);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace ave
