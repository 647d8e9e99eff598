#pragma once
// Small fixtures shared by the fusion_server service tests, the end-to-end tests and the benches
// that start a server in-process (test-only header).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <grpcpp/grpcpp.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"

namespace ave::fixtures {

// A loopback TCP port free a moment ago (bound, read and closed), for a server process started
// with a fixed --listen so that it can be restarted on the same address.
inline int FreeLoopbackPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  ::close(fd);
  return ntohs(addr.sin_port);
}

// An environment variable as a count of at least 1 (a test's full form), or `fallback`.
inline int EnvCount(const char* name, int fallback) {
  const char* v = std::getenv(name);
  return v ? std::max(1, std::atoi(v)) : fallback;
}

// A server on a free loopback port with its store at `store_path` and the given bootstrap tokens
// (empty = none): the start every service and end-to-end test shares.
inline ServerOptions LoopbackServer(const std::string& store_path, const std::string& sensor_token,
                                    const std::string& viewer_token, const std::string& admin_token) {
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.store_path = store_path;
  options.sensor_token = sensor_token;
  options.viewer_token = viewer_token;
  options.admin_token = admin_token;
  return options;
}

// A FusionServer on a free loopback port with its store in a fresh temporary directory
// (<tmp>/<tag>_<pid>_<n>): the start-up every service, end-to-end and bench test shares.
//   fixtures::LocalServer server("ave_e2e");
//   ServerOptions options = server.Options(kSensor, kViewer, kAdmin);  // then adjust
//   ASSERT_TRUE(server.Start(options).ok());
//   server->state() ...; server.address(); server.InsecureChannel();
// Start() again restarts on the same store (a new port unless options.listen_address names one);
// destruction stops the server and removes the directory.
class LocalServer {
 public:
  explicit LocalServer(const std::string& tag)
      : dir_(std::filesystem::temp_directory_path() /
             (tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter_++))) {
    std::filesystem::create_directories(dir_);
  }
  ~LocalServer() {
    Stop();
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }
  LocalServer(const LocalServer&) = delete;
  LocalServer& operator=(const LocalServer&) = delete;

  // LoopbackServer options with the store in this directory (empty token = none).
  ServerOptions Options(const std::string& sensor_token, const std::string& viewer_token,
                        const std::string& admin_token) const {
    return LoopbackServer(store_path(), sensor_token, viewer_token, admin_token);
  }
  // Starts a server with `options`, stopping the running one first.
  absl::Status Start(const ServerOptions& options) {
    Stop();
    absl::StatusOr<std::unique_ptr<FusionServer>> server = FusionServer::Start(options);
    if (!server.ok()) return server.status();
    server_ = *std::move(server);
    return absl::OkStatus();
  }
  void Stop() { server_.reset(); }

  FusionServer* operator->() const { return server_.get(); }
  FusionServer& operator*() const { return *server_; }
  bool running() const { return server_ != nullptr; }
  int port() const { return server_->port(); }
  std::string address() const { return "127.0.0.1:" + std::to_string(server_->port()); }
  std::shared_ptr<grpc::Channel> InsecureChannel() const {
    return grpc::CreateChannel(address(), grpc::InsecureChannelCredentials());
  }
  const std::filesystem::path& dir() const { return dir_; }
  std::string store_path() const { return (dir_ / "ave.db").string(); }

 private:
  static inline std::atomic<int> counter_{0};
  std::filesystem::path dir_;
  std::unique_ptr<FusionServer> server_;
};

// A real, decodable JPEG of the given size.
inline std::string Jpeg(int w, int h) {
  std::vector<uchar> bytes;
  cv::imencode(".jpg", cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 200, 30)), bytes);
  return std::string(bytes.begin(), bytes.end());
}

// A valid 64x48 camera record looking along +x from 10 m up.
inline v1::Camera CameraRecord(const std::string& id) {
  v1::Camera c;
  c.set_id(id);
  c.set_name("Test " + id);
  *c.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
  *c.mutable_mounting_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
  c.set_enabled(true);
  return c;
}

// Opens a sensor stream, sends `hello` then each frame (waiting for its ack), and returns the
// final status; `acks` receives the number of acks read.
inline grpc::Status StreamFrames(v1::SensorService::StubInterface& stub, const v1::SensorHello& hello,
                                 const std::vector<v1::SensorFrame>& frames, int* acks = nullptr) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto stream = stub.Stream(&context);
  v1::SensorMessage m;
  *m.mutable_hello() = hello;
  stream->Write(m);
  int read = 0;
  for (const auto& f : frames) {
    *m.mutable_frame() = f;
    if (!stream->Write(m)) break;
    v1::SensorAck ack;
    if (!stream->Read(&ack)) break;
    ++read;
  }
  stream->WritesDone();
  if (acks) *acks = read;
  return stream->Finish();
}

// Runs `streamer.Run(stop)` (an agent's camera or LiDAR streamer) on a thread until it returns by
// itself or `bound` passes, when it is told to stop: whether it ended by itself, and its status.
struct StreamerRun {
  bool ended_by_itself = false;
  absl::Status status;
};
template <typename Streamer>
StreamerRun RunUntilItEnds(Streamer& streamer, std::chrono::milliseconds bound) {
  std::atomic<bool> stop{false};
  std::promise<absl::Status> result;
  std::future<absl::Status> done = result.get_future();
  std::thread run([&] { result.set_value(streamer.Run(stop)); });
  const bool ended = done.wait_for(bound) == std::future_status::ready;
  stop = true;
  run.join();
  return {ended, done.get()};
}

}  // namespace ave::fixtures
