#include "fusion_server/service/metrics.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstring>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace ave {

void LatencyHistogram::Observe(double seconds) {
  if (!(seconds >= 0)) seconds = 0;  // NaN or a clock that went backwards counts as zero latency
  size_t i = 0;
  while (i < kBounds.size() && seconds > kBounds[i]) ++i;
  buckets_[i].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  sum_us_.fetch_add(static_cast<uint64_t>(std::min(seconds, 1e6) * 1e6), std::memory_order_relaxed);
}

void LatencyHistogram::Render(const std::string& name, const std::string& help, std::string& out) const {
  absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " histogram\n");
  uint64_t cumulative = 0;
  for (size_t i = 0; i < kBounds.size(); ++i) {
    cumulative += buckets_[i].load(std::memory_order_relaxed);
    absl::StrAppend(&out, name, "_bucket{le=\"", kBounds[i], "\"} ", cumulative, "\n");
  }
  cumulative += buckets_[kBounds.size()].load(std::memory_order_relaxed);
  absl::StrAppend(&out, name, "_bucket{le=\"+Inf\"} ", cumulative, "\n");
  absl::StrAppend(&out, name, "_sum ", sum_us_.load(std::memory_order_relaxed) / 1e6, "\n");
  absl::StrAppend(&out, name, "_count ", cumulative, "\n");
}

std::string ServerMetrics::RenderPrometheus() const {
  std::string out;
  auto counter = [&](const char* name, const char* help, const std::atomic<uint64_t>& v) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " counter\n", name, " ",
                    v.load(std::memory_order_relaxed), "\n");
  };
  auto gauge = [&](const char* name, const char* help, const std::atomic<int64_t>& v) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " gauge\n", name, " ",
                    v.load(std::memory_order_relaxed), "\n");
  };
  counter("ave_frames_in_total", "Sensor frames with a JPEG accepted.", frames_in);
  counter("ave_metadata_frames_in_total", "Replayed metadata-only sensor frames accepted.", metadata_frames_in);
  counter("ave_bytes_in_total", "JPEG bytes accepted from sensors.", bytes_in);
  counter("ave_frames_rejected_total", "Sensor frames refused by validation.", frames_rejected);
  counter("ave_lidar_sweeps_in_total", "Rotating-LiDAR sweeps (foot tracks, points) accepted.", lidar_sweeps_in);
  counter("ave_frames_out_total", "JPEG frames written to viewers.", frames_out);
  counter("ave_bytes_out_total", "JPEG bytes written to viewers.", bytes_out);
  counter("ave_viewer_drops_total", "Frames skipped for slow viewers (latest-frame semantics).", viewer_drops);
  counter("ave_scene_updates_out_total", "Scene updates written to viewers.", updates_out);
  counter("ave_auth_failures_total", "Calls refused as unauthenticated or not permitted.", auth_failures);
  counter("ave_auth_rate_limited_total",
          "Calls refused without reading their token: the peer failed to authenticate too often.", auth_rate_limited);
  counter("ave_insecure_plaintext_warnings_total", "Warnings logged that tokens cross the network in clear.",
          insecure_plaintext_warnings);
  gauge("ave_sensors_connected", "Open sensor streams.", sensors_connected);
  gauge("ave_viewers_connected", "Open viewer subscriptions.", viewers_connected);
  gauge("ave_viewer_queue_depth", "Frames waiting in viewers' one-per-camera slots.", viewer_queue_depth);
  gauge("ave_flow_saturated", "1 while sensors are asked for a lower rate or quality.", saturated);
  gauge("ave_insecure_plaintext", "1 while serving plaintext on a non-loopback address (--insecure-plaintext).",
        insecure_plaintext);
  gauge("ave_auth_tracked_peers", "Peers tracked by the failed-authentication limiter (as of the last failure).", auth_tracked_peers);
  capture_to_ingest_s.Render("ave_capture_to_ingest_seconds", "Capture (server clock) to acceptance.", out);
  ingest_to_send_s.Render("ave_ingest_to_send_seconds", "Acceptance to the write to a viewer.", out);
  capture_to_send_s.Render("ave_capture_to_send_seconds", "Capture (server clock) to the write to a viewer.", out);
  if (render_extra) render_extra(out);
  return out;
}

absl::StatusOr<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::Start(const std::string& address,
                                                                            std::function<std::string()> render) {
  const size_t colon = address.rfind(':');
  int port = 0;
  if (colon == std::string::npos || !absl::SimpleAtoi(address.substr(colon + 1), &port) || port < 0 || port > 65535) {
    return absl::InvalidArgumentError("metrics address '" + address + "' must be host:port");
  }
  std::string host = address.substr(0, colon);
  if (host.empty() || host == "localhost") host = "127.0.0.1";
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  if (host == "0.0.0.0") {
    addr.sin_addr.s_addr = htonl(INADDR_ANY);
  } else if (inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1) {
    return absl::InvalidArgumentError("metrics address '" + address + "': host must be an IPv4 address");
  }
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::UnavailableError(absl::StrCat("metrics: socket: ", std::strerror(errno)));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd, 16) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    return absl::UnavailableError("metrics: cannot listen on " + address + ": " + why);
  }
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  return std::unique_ptr<MetricsHttpServer>(new MetricsHttpServer(fd, ntohs(addr.sin_port), std::move(render)));
}

MetricsHttpServer::MetricsHttpServer(int fd, int port, std::function<std::string()> render)
    : fd_(fd), port_(port), render_(std::move(render)) {
  thread_ = std::thread([this] { Loop(); });
}

MetricsHttpServer::~MetricsHttpServer() {
  stop_ = true;
  thread_.join();
  ::close(fd_);
}

void MetricsHttpServer::Loop() {
  while (!stop_.load()) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    const int client = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (client < 0) continue;
    // Read the request line (bounded: 4 KiB, 1 s); anything but GET /metrics or /healthz is a 404.
    timeval tv{1, 0};
    ::setsockopt(client, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    ::setsockopt(client, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    std::string request;
    char buffer[1024];
    // 1 s for the whole request, not per recv: a client trickling a byte a second would hold
    // this (single) loop for an hour (issue 14).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
    while (request.size() < 4096 && request.find("\r\n\r\n") == std::string::npos &&
           request.find("\n\n") == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      const ssize_t n = ::recv(client, buffer, sizeof buffer, 0);
      if (n <= 0) break;
      request.append(buffer, static_cast<size_t>(n));
    }
    std::string status = "404 Not Found", type = "text/plain", body = "not found\n";
    if (request.rfind("GET /metrics", 0) == 0) {
      status = "200 OK";
      type = "text/plain; version=0.0.4";
      body = render_();
    } else if (request.rfind("GET /healthz", 0) == 0) {
      status = "200 OK";
      body = "ok\n";
    }
    const std::string response = absl::StrCat("HTTP/1.0 ", status, "\r\nContent-Type: ", type,
                                              "\r\nContent-Length: ", body.size(), "\r\nConnection: close\r\n\r\n", body);
    size_t sent = 0;
    while (sent < response.size()) {
      const ssize_t n = ::send(client, response.data() + sent, response.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) break;
      sent += static_cast<size_t>(n);
    }
    ::close(client);
  }
}

}  // namespace ave
