// Network video drop-outs (issue 14): an http:// MJPEG stream served by a small in-process HTTP
// server (multipart/x-mixed-replace JPEG parts, as IP cameras serve them) goes through the same
// OpenCV/FFmpeg network path and the same reconnection code as rtsp:// (Debian's test set-up has no
// RTSP server). The server follows a script: each connection serves some frames and then drops
// (optionally cutting a frame in half), so every step is driven by the data, not by time.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "sensor_agent/source/frame_source.h"

namespace ave {
namespace {

using ::testing::HasSubstr;

// Frame `index` of connection `connection`: a flat colour that says which it is.
cv::Scalar FrameColour(int connection, int index) { return cv::Scalar(40 + 100 * connection, 20 + 20 * index, 128); }

std::string Jpeg(int connection, int index) {
  const cv::Mat m(48, 64, CV_8UC3, FrameColour(connection, index));
  std::vector<uchar> out;
  EXPECT_TRUE(cv::imencode(".jpg", m, out, {cv::IMWRITE_JPEG_QUALITY, 95}));
  return std::string(out.begin(), out.end());
}

class MjpegHttpServer {
 public:
  struct Connection {
    int frames = 0;
    bool cut_a_frame = false;  // after the frames, half a part's headers and JPEG, then the drop
  };

  explicit MjpegHttpServer(std::vector<Connection> script) : script_(std::move(script)) {
    listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(listener_, reinterpret_cast<sockaddr*>(&sa), sizeof sa), 0);
    EXPECT_EQ(::listen(listener_, 4), 0);
    socklen_t len = sizeof sa;
    ::getsockname(listener_, reinterpret_cast<sockaddr*>(&sa), &len);
    port_ = ntohs(sa.sin_port);
    thread_ = std::thread([this] { Serve(); });
  }
  ~MjpegHttpServer() { Stop(); }

  // Closes the listening socket: from now on a connection is refused.
  void Stop() {
    if (!thread_.joinable()) return;
    ::shutdown(listener_, SHUT_RDWR);  // wakes accept()
    thread_.join();
    ::close(listener_);
  }
  std::string url() const { return "http://127.0.0.1:" + std::to_string(port_) + "/cam.mjpg"; }
  std::vector<std::string> requests() const {
    std::lock_guard lock(mu_);
    return requests_;
  }

 private:
  void Serve() {
    for (size_t c = 0;; ++c) {
      const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) return;  // Stop()
      std::string request;
      char buffer[4096];
      while (request.find("\r\n\r\n") == std::string::npos) {
        const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
        if (n <= 0) break;
        request.append(buffer, static_cast<size_t>(n));
      }
      {
        std::lock_guard lock(mu_);
        requests_.push_back(request.substr(0, request.find("\r\n")));
      }
      if (c < script_.size()) {
        std::string out = "HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=aveframe\r\n\r\n";
        for (int i = 0; i < script_[c].frames; ++i) out += Part(Jpeg(static_cast<int>(c), i));
        if (script_[c].cut_a_frame) {
          const std::string part = Part(Jpeg(static_cast<int>(c), script_[c].frames));
          out += part.substr(0, part.size() / 2);
        }
        SendAll(fd, out);
      }
      ::close(fd);  // the drop-out (past the script: a connection that serves nothing)
    }
  }
  static std::string Part(const std::string& jpeg) {
    return "--aveframe\r\nContent-Type: image/jpeg\r\nContent-Length: " + std::to_string(jpeg.size()) + "\r\n\r\n" + jpeg + "\r\n";
  }
  static void SendAll(int fd, const std::string& s) {
    for (size_t at = 0; at < s.size();) {
      const ssize_t n = ::send(fd, s.data() + at, s.size() - at, MSG_NOSIGNAL);
      if (n <= 0) return;
      at += static_cast<size_t>(n);
    }
  }

  std::vector<Connection> script_;
  int listener_ = -1;
  int port_ = 0;
  std::thread thread_;
  mutable std::mutex mu_;
  std::vector<std::string> requests_;
};

void ExpectFrame(const absl::StatusOr<CapturedFrame>& frame, int connection, int index) {
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_EQ(frame->width, 64);
  ASSERT_EQ(frame->height, 48);
  const cv::Scalar want = FrameColour(connection, index);
  for (int ch = 0; ch < 3; ++ch) {
    EXPECT_NEAR(frame->bgr[ch], want[ch], 8) << "connection " << connection << " frame " << index << " channel " << ch;
  }
}

TEST(NetworkSource, HttpMjpegDropOutIsReportedThenReconnectsAndDeliversAgain) {
  MjpegHttpServer server({{5, true}, {4, false}});
  SourceOptions options;
  absl::StatusOr<std::unique_ptr<FrameSource>> source = OpenSource(server.url(), options);
  ASSERT_TRUE(source.ok()) << source.status() << " (OpenCV's FFmpeg backend could not open an http MJPEG stream)";
  FrameSource& s = **source;
  EXPECT_TRUE(s.live());
  for (int i = 0; i < 5; ++i) ExpectFrame(s.Next(), 0, i);

  // The server drops the connection in the middle of the sixth part: no half frame is delivered.
  absl::StatusOr<CapturedFrame> dropped = s.Next();
  ASSERT_FALSE(dropped.ok());
  EXPECT_EQ(dropped.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(dropped.status().message(), server.url() + ": stream dropped after 5 frames (drop-out 1); reconnecting");
  EXPECT_EQ(s.drop_outs(), 1);
  EXPECT_EQ(s.reconnects(), 0);

  // The next call reconnects and the frames of the second connection arrive.
  for (int i = 0; i < 4; ++i) ExpectFrame(s.Next(), 1, i);
  EXPECT_EQ(s.reconnects(), 1);
  EXPECT_EQ(s.intrinsics().width, 64);

  absl::StatusOr<CapturedFrame> second = s.Next();
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().message(), server.url() + ": stream dropped after 9 frames (drop-out 2); reconnecting");

  // The server never comes back: every attempt says so, naming the stream, and nothing is delivered.
  server.Stop();
  for (int attempt = 1; attempt <= 3; ++attempt) {
    absl::StatusOr<CapturedFrame> down = s.Next();
    ASSERT_FALSE(down.ok());
    EXPECT_EQ(down.status().code(), absl::StatusCode::kUnavailable);
    EXPECT_THAT(std::string(down.status().message()), HasSubstr(server.url() + ": stream down for "));
    EXPECT_THAT(std::string(down.status().message()),
                HasSubstr("after 9 frames: reconnection attempt " + std::to_string(attempt) + " failed (cannot open)"));
  }
  EXPECT_EQ(s.drop_outs(), 2);
  EXPECT_EQ(s.reconnects(), 1);
  EXPECT_EQ(server.requests(), std::vector<std::string>(2, "GET /cam.mjpg HTTP/1.1"));
}

TEST(NetworkSource, AServerThatAcceptsButServesNothingIsOneDropOutNotAReconnect) {
  // The first connection serves 5 frames (FFmpeg probes a few parts before it opens the stream);
  // later ones are accepted and closed at once.
  MjpegHttpServer server({{5, false}});
  absl::StatusOr<std::unique_ptr<FrameSource>> source = OpenSource(server.url(), SourceOptions());
  ASSERT_TRUE(source.ok()) << source.status();
  FrameSource& s = **source;
  for (int i = 0; i < 5; ++i) ExpectFrame(s.Next(), 0, i);
  for (int k = 0; k < 3; ++k) {
    absl::StatusOr<CapturedFrame> down = s.Next();
    ASSERT_FALSE(down.ok());
    EXPECT_EQ(down.status().code(), absl::StatusCode::kUnavailable);
    EXPECT_THAT(std::string(down.status().message()), HasSubstr(server.url())) << down.status();
    EXPECT_THAT(std::string(down.status().message()), HasSubstr("after 5 frames")) << down.status();
  }
  EXPECT_EQ(s.drop_outs(), 1);
  EXPECT_EQ(s.reconnects(), 0);
}

TEST(NetworkSource, AStreamThatCannotBeOpenedIsNamed) {
  MjpegHttpServer server({});
  const std::string url = server.url();
  server.Stop();
  absl::StatusOr<std::unique_ptr<FrameSource>> source = OpenSource(url, SourceOptions());
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().message(), "source '" + url + "': cannot open");
}

}  // namespace
}  // namespace ave
