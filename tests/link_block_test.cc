// Issue 8, blocked link (short form): the agent talks to the server through a TCP proxy that can
// silently stop carrying bytes, as a dead route or a dropped Wi-Fi does — no reset, no close.
// The agent must notice (keepalive), buffer its metadata, and be streaming again within 5 s of the
// link's return, replaying what it buffered.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace ave {
namespace {

using Clock = std::chrono::steady_clock;

// A loopback TCP relay. While blocked, bytes already sent stay unread and new connections are
// accepted but never relayed: the peer sees a silent link, exactly like a black-holed route.
class BlackholeProxy {
 public:
  explicit BlackholeProxy(int target_port) : target_port_(target_port) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = 0;
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd_, 16) != 0) {
      ADD_FAILURE() << "proxy: cannot listen";
      return;
    }
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    thread_ = std::thread([this] { Loop(); });
  }
  ~BlackholeProxy() {
    stop_ = true;
    thread_.join();
    for (auto& [a, b] : pairs_) {
      ::close(a);
      ::close(b);
    }
    ::close(listen_fd_);
  }
  int port() const { return port_; }
  void SetBlocked(bool blocked) { blocked_ = blocked; }

 private:
  void Loop() {
    std::vector<char> buffer(1 << 16);
    while (!stop_) {
      std::vector<pollfd> fds{{listen_fd_, POLLIN, 0}};
      if (!blocked_) {
        for (auto& [a, b] : pairs_) {
          fds.push_back({a, POLLIN, 0});
          fds.push_back({b, POLLIN, 0});
        }
      }
      if (::poll(fds.data(), fds.size(), 20) <= 0) continue;
      if (fds[0].revents & POLLIN) {
        const int client = ::accept(listen_fd_, nullptr, nullptr);
        const int upstream = ::socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in to{};
        to.sin_family = AF_INET;
        to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        to.sin_port = htons(static_cast<uint16_t>(target_port_));
        if (client >= 0 && ::connect(upstream, reinterpret_cast<sockaddr*>(&to), sizeof to) == 0) {
          pairs_.emplace_back(client, upstream);
        } else {
          if (client >= 0) ::close(client);
          ::close(upstream);
        }
      }
      for (size_t i = 1; i < fds.size(); ++i) {
        if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        const auto& pair = pairs_[(i - 1) / 2];
        const int from = fds[i].fd, to = from == pair.first ? pair.second : pair.first;
        const ssize_t n = ::read(from, buffer.data(), buffer.size());
        if (n > 0) {
          for (ssize_t off = 0; off < n;) {
            const ssize_t w = ::send(to, buffer.data() + off, n - off, MSG_NOSIGNAL);
            if (w <= 0) break;
            off += w;
          }
        } else {
          ::shutdown(to, SHUT_WR);  // the peer closed: pass it on (closed pairs simply go quiet)
        }
      }
    }
  }

  int target_port_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<bool> blocked_{false};
  std::vector<std::pair<int, int>> pairs_;
  std::thread thread_;
};

TEST(LinkBlock, AgentDetectsASilentLinkAndIsBackWithinFiveSecondsOfItsReturn) {
  fixtures::LocalServer server("ave_link_block");
  ServerOptions options = server.Options("s", "", "a");
  options.campus_grid_m = 8;
  const absl::Status started = server.Start(options);
  ASSERT_TRUE(started.ok()) << started;
  const scene::CameraSpec camera = scene::BuiltinCampus().cameras[0];
  ASSERT_TRUE(AdminClient(server.InsecureChannel(), "a").AddCamera(CampusCameraRecord(camera)).ok());
  BlackholeProxy proxy(server.port());

  AgentOptions a;
  a.server = "127.0.0.1:" + std::to_string(proxy.port());
  a.camera_id = camera.id;
  a.token = "s";
  a.fps = 10;
  a.keepalive = std::chrono::milliseconds(500);
  a.spill_path = (server.dir() / "spill.bin").string();
  auto source = OpenSource("sim:campus#" + camera.id, {.fps = a.fps});
  ASSERT_TRUE(source.ok()) << source.status();
  AgentStreamer streamer(a, std::move(*source));
  std::atomic<bool> stop{false};
  std::thread agent([&] { EXPECT_TRUE(streamer.Run(stop).ok()); });

  auto latest = [&]() -> uint64_t {
    auto f = server->state().LatestFrame(camera.id);
    return f ? f->sequence() : 0;
  };
  auto wait_for = [](const std::function<bool()>& done, std::chrono::milliseconds limit) {
    const auto deadline = Clock::now() + limit;
    while (!done() && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return done();
  };
  ASSERT_TRUE(wait_for([&] { return latest() >= 5; }, std::chrono::seconds(20)));

  // Block the link (6 s in CI; AVE_LINK_BLOCK_S=30 for the issue's full form): nothing new may
  // arrive, and the agent must notice and start buffering.
  const char* block_env = std::getenv("AVE_LINK_BLOCK_S");
  const int block_s = block_env ? std::max(1, std::atoi(block_env)) : 6;
  proxy.SetBlocked(true);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const uint64_t before = latest();
  const int64_t connects_before = streamer.stats().connects;
  std::this_thread::sleep_for(std::chrono::seconds(block_s));
  EXPECT_EQ(latest(), before) << "frames crossed a blocked link";
  const AgentStats during = streamer.stats();
  EXPECT_GT(during.connects, connects_before) << "the agent never noticed the dead link";
  EXPECT_GT(during.metadata_buffered, 0) << "nothing was buffered during the outage";

  // Link back: streaming again within 5 s, with the buffered metadata replayed. Bytes the dead
  // connection left in the relay may arrive first, so "back" means the new stream has replayed
  // the outage's metadata (which only a fresh connection does) and frames advance after that.
  proxy.SetBlocked(false);
  const auto back = Clock::now();
  EXPECT_TRUE(wait_for([&] { return streamer.stats().metadata_replayed >= during.metadata_buffered; },
                       std::chrono::seconds(5)));
  const double back_s = std::chrono::duration<double>(Clock::now() - back).count();
  const uint64_t after_replay = latest();
  EXPECT_TRUE(wait_for([&] { return latest() > after_replay; }, std::chrono::seconds(5)));
  EXPECT_LT(back_s, 5.0);
  RecordProperty("back_after_s", std::to_string(back_s));
  std::cerr << "link block: agent back " << back_s << " s after the link returned; " << during.metadata_buffered
            << " metadata records buffered, " << streamer.stats().metadata_replayed << " replayed, "
            << streamer.stats().connects << " connection attempts\n";
  stop = true;
  agent.join();
  server.Stop();
}

}  // namespace
}  // namespace ave
