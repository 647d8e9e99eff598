// ave-loadgen: load test of the fusion server on this machine (MISSION part G, issue 8).
//
// N simulated agents stream pre-encoded JPEG frames (640x480 or 1920x1080) with a pose and boxes
// at --fps, plus metadata-only pose updates up to --pose-hz; M viewers subscribe to every camera.
// Latency is capture stamp -> viewer receipt, both on this host's clock. Server CPU and resident
// memory come from /proc/<pid> of a server it starts itself (or one given by --server-pid).
// Only loopback targets are accepted; it stops by itself after --duration seconds.
// Last line on stdout: a JSON summary.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <random>
#include <sstream>
#include <thread>

#include <CLI/CLI.hpp>
#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ave/net/tls.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/admin/admin_client.h"
#include "model_store/common/cli.h"
#include "fusion_server/core/convert.h"
#include "model_store/common/log.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  int streams = 50;
  int viewers = 1;
  double fps = 15;
  double pose_hz = 30;
  int boxes = 4;
  std::string size = "640x480";
  double duration_s = 10;
  double warmup_s = 1;
  std::string server;  // empty: start our own
  std::string server_bin;
  int server_pid = 0;
  std::string sensor_token, viewer_token, admin_token;
  std::string tls_ca;
  std::string plot = "loadgen.png";
  double viewer_rate_hz = 60;
  int64_t max_drops = -1;    // fail (exit 1) when exceeded; -1 = no check
  double max_p99_ms = 0;     // fail when exceeded; 0 = no check
  double min_received_ratio = 0;  // fail when viewers got less than this share of frames sent
  // Fail when a viewer's frames neither received nor counted as skipped by the server exceed this
  // many per stream (-1 = no check): the latest-frame policy may skip frames for a slow viewer,
  // but must count each one; at the end a camera may still hold one unsent frame (and the skip
  // it replaced) when the viewer stops, hence 2.
  int64_t max_unaccounted_per_stream = -1;
  int quality = 80;
};

// JPEGs with texture like a real scene (gradients, blocks, mild noise): ~40-60 KB at 640x480 q80.
std::vector<std::string> MakeJpegs(int width, int height, int count, int quality) {
  std::vector<std::string> out;
  std::mt19937 rng(7);
  for (int k = 0; k < count; ++k) {
    cv::Mat image(height, width, CV_8UC3);
    for (int y = 0; y < height; ++y) {
      auto* row = image.ptr<cv::Vec3b>(y);
      for (int x = 0; x < width; ++x) {
        row[x] = cv::Vec3b(static_cast<uchar>((x * 255) / width), static_cast<uchar>((y * 255) / height),
                           static_cast<uchar>(((x + y + 13 * k) * 3) & 255));
      }
    }
    std::uniform_int_distribution<int> px(0, width - 1), py(0, height - 1), c(0, 255);
    for (int r = 0; r < 60; ++r) {
      const cv::Point a(px(rng), py(rng));
      cv::rectangle(image, a, a + cv::Point(width / 12, height / 10), cv::Scalar(c(rng), c(rng), c(rng)), cv::FILLED);
    }
    cv::Mat noise(height, width, CV_8UC3);
    cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(6));
    image += noise;
    std::vector<uchar> bytes;
    cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, quality});
    out.emplace_back(bytes.begin(), bytes.end());
  }
  return out;
}

// Server process started by the load generator.
struct ServerProcess {
  pid_t pid = 0;
  std::string address;
  std::filesystem::path dir;
};

absl::StatusOr<ServerProcess> StartServer(const Options& o, int64_t max_frame_bytes) {
  ServerProcess p;
  if (::access(o.server_bin.c_str(), X_OK) != 0) {
    return absl::NotFoundError("--server-bin " + o.server_bin + ": not an executable file");
  }
  p.dir = std::filesystem::temp_directory_path() / ("ave_loadgen_" + std::to_string(::getpid()));
  std::filesystem::create_directories(p.dir);
  const std::string out_path = (p.dir / "server.out").string();
  const std::string log_path = (p.dir / "server.log").string();
  const std::string max_mb = std::to_string(std::max<double>(8.0, 2.0 * max_frame_bytes / (1 << 20)));
  p.pid = ::fork();
  if (p.pid < 0) return absl::InternalError("fork failed");
  if (p.pid == 0) {
    std::freopen(out_path.c_str(), "w", stdout);
    std::freopen(log_path.c_str(), "w", stderr);
    ::setenv("AVE_SENSOR_TOKEN", o.sensor_token.c_str(), 1);
    ::setenv("AVE_VIEWER_TOKEN", o.viewer_token.c_str(), 1);
    ::setenv("AVE_ADMIN_TOKEN", o.admin_token.c_str(), 1);
    const std::string store = (p.dir / "ave.db").string();
    const std::string hint = std::to_string(std::max(o.fps, 30.0));
    execl(o.server_bin.c_str(), o.server_bin.c_str(), "--listen", "127.0.0.1:0", "--store", store.c_str(),
          "--campus-grid", "8", "--log-level", "warning", "--max-fps-hint", hint.c_str(), "--max-frame-mb",
          max_mb.c_str(), static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  for (int i = 0; i < 300; ++i) {
    std::ifstream in(out_path);
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("listening on port ", 0) == 0) {
        p.address = "127.0.0.1:" + line.substr(18);
        return p;
      }
    }
    int status = 0;
    if (::waitpid(p.pid, &status, WNOHANG) == p.pid) {
      std::ifstream log(log_path);
      std::stringstream ss;
      ss << log.rdbuf();
      return absl::UnavailableError("ave-server exited during start-up: " + ss.str());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ::kill(p.pid, SIGKILL);
  return absl::DeadlineExceededError("ave-server did not report its port within 15 s");
}

struct ProcSample {
  double t_s;
  double cpu_pct;  // 100 = one core
  double rss_mb;
};

bool ReadProc(int pid, uint64_t* ticks, double* rss_mb) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string content;
  if (!std::getline(stat, content)) return false;
  // Fields after the command name (which may hold spaces): state is field 3, utime 14, stime 15.
  const size_t close = content.rfind(')');
  std::istringstream rest(content.substr(close + 2));
  std::string field;
  uint64_t utime = 0, stime = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stoull(field);
    if (i == 15) stime = std::stoull(field);
  }
  *ticks = utime + stime;
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) *rss_mb = std::stod(line.substr(6)) / 1024.0;
  }
  return true;
}

double Percentile(std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

struct PerSecond {
  std::atomic<int64_t> sent{0};
  std::atomic<int64_t> received{0};
  std::mutex mu;
  std::vector<double> latency_ms;
};

void Plot(const std::string& path, const std::vector<std::unique_ptr<PerSecond>>& seconds,
          const std::vector<ProcSample>& proc, int streams, int viewers) {
  const int W = 1200, H = 900, panel = H / 3, left = 70, right = 20;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const int n = static_cast<int>(seconds.size());
  auto x_of = [&](double t) { return left + static_cast<int>((W - left - right) * t / std::max(1, n)); };
  struct Series {
    std::vector<std::pair<double, double>> pts;
    cv::Scalar color;
    std::string name;
  };
  auto draw_panel = [&](int index, const std::string& title, const std::vector<Series>& series) {
    const int top = index * panel + 25, bottom = (index + 1) * panel - 25;
    double ymax = 1e-9;
    for (const auto& s : series)
      for (const auto& [t, y] : s.pts) ymax = std::max(ymax, y);
    ymax *= 1.1;
    cv::rectangle(img, {left, top}, {W - right, bottom}, cv::Scalar(0, 0, 0));
    cv::putText(img, title, {left, top - 6}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1);
    for (int k = 0; k <= 4; ++k) {
      const int y = bottom - (bottom - top) * k / 4;
      char label[32];
      std::snprintf(label, sizeof label, "%.0f", ymax * k / 4);
      cv::putText(img, label, {5, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(80, 80, 80), 1);
      cv::line(img, {left, y}, {W - right, y}, cv::Scalar(230, 230, 230));
    }
    int legend = left + 10;
    for (const auto& s : series) {
      for (size_t i = 1; i < s.pts.size(); ++i) {
        auto p = [&](const std::pair<double, double>& q) {
          return cv::Point(x_of(q.first), bottom - static_cast<int>((bottom - top) * q.second / ymax));
        };
        cv::line(img, p(s.pts[i - 1]), p(s.pts[i]), s.color, 2, cv::LINE_AA);
      }
      cv::putText(img, s.name, {legend, top + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, s.color, 1);
      legend += 12 + 8 * static_cast<int>(s.name.size());
    }
  };
  Series sent{{}, cv::Scalar(200, 80, 0), "frames/s sent"}, received{{}, cv::Scalar(0, 150, 0), "frames/s received per viewer"};
  Series p50{{}, cv::Scalar(0, 150, 0), "p50 ms"}, p99{{}, cv::Scalar(0, 0, 220), "p99 ms"};
  for (int i = 0; i < n; ++i) {
    sent.pts.emplace_back(i + 0.5, static_cast<double>(seconds[i]->sent.load()));
    received.pts.emplace_back(i + 0.5, static_cast<double>(seconds[i]->received.load()) / std::max(1, viewers));
    std::vector<double> v = seconds[i]->latency_ms;
    if (!v.empty()) {
      p50.pts.emplace_back(i + 0.5, Percentile(v, 0.5));
      p99.pts.emplace_back(i + 0.5, Percentile(v, 0.99));
    }
  }
  Series cpu{{}, cv::Scalar(200, 0, 200), "server CPU % (100 = 1 core)"}, rss{{}, cv::Scalar(0, 120, 200), "server RSS MB"};
  for (const auto& s : proc) {
    cpu.pts.emplace_back(s.t_s, s.cpu_pct);
    rss.pts.emplace_back(s.t_s, s.rss_mb);
  }
  draw_panel(0, "throughput, " + std::to_string(streams) + " streams", {sent, received});
  draw_panel(1, "latency capture -> viewer receipt (ms), per second", {p50, p99});
  draw_panel(2, "server process (time axis: seconds)", {cpu, rss});
  cv::imwrite(path, img);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"ave-loadgen: N simulated agents + M viewers against a loopback ave-server; JSON summary last"};
  app.add_option("--streams", o.streams, "simulated agents (cameras)")->capture_default_str()->check(ave::cli::Range(1, 2000));
  app.add_option("--viewers", o.viewers, "subscribing viewers")->capture_default_str()->check(ave::cli::Range(0, 64));
  app.add_option("--fps", o.fps, "JPEG frames per second per stream")->capture_default_str()->check(ave::cli::Range(0.5, 120.0));
  app.add_option("--pose-hz", o.pose_hz, "pose updates per second per stream (metadata-only between frames; 0 = with frames only)")
      ->capture_default_str()->check(ave::cli::Range(0.0, 120.0));
  app.add_option("--boxes", o.boxes, "boxes per frame")->capture_default_str()->check(ave::cli::Range(0, 64));
  app.add_option("--size", o.size, "frame size")->capture_default_str()->check(CLI::IsMember({"640x480", "1920x1080"}));
  app.add_option("--quality", o.quality, "JPEG quality of the pre-encoded frames")->capture_default_str()->check(ave::cli::Range(1, 100));
  app.add_option("--duration", o.duration_s, "seconds of load (stops by itself)")->capture_default_str()->check(ave::cli::Range(1.0, 600.0));
  app.add_option("--warmup", o.warmup_s, "seconds at the start left out of latency figures")->capture_default_str()->check(ave::cli::Range(0.0, 600.0));
  app.add_option("--server", o.server, "host:port of a running loopback server (default: start one)");
  app.add_option("--server-bin", o.server_bin, "ave-server to start (default: next to this program)");
  app.add_option("--server-pid", o.server_pid, "pid of the --server process, for CPU and memory figures");
  app.add_option("--sensor-token", o.sensor_token, "with --server: sensor token (env AVE_SENSOR_TOKEN)");
  app.add_option("--viewer-token", o.viewer_token, "with --server: viewer token (env AVE_VIEWER_TOKEN)");
  app.add_option("--admin-token", o.admin_token, "with --server: admin token (env AVE_ADMIN_TOKEN)");
  app.add_option("--tls-ca", o.tls_ca, "with --server: PEM CA when the server speaks TLS");
  app.add_option("--viewer-rate", o.viewer_rate_hz, "update rate viewers ask for (Hz)")->capture_default_str()->check(ave::cli::Range(0.1, 1000.0));
  app.add_option("--plot", o.plot, "PNG plot over time")->capture_default_str()->check(ave::cli::WritableFile());
  app.add_option("--max-drops", o.max_drops, "exit 1 if viewers skipped more frames than this (-1 = no check)");
  app.add_option("--max-p99-ms", o.max_p99_ms, "exit 1 if p99 latency exceeds this (0 = no check)")->check(ave::cli::Range(0.0, 1e9));
  app.add_option("--max-unaccounted-per-stream", o.max_unaccounted_per_stream,
                 "exit 1 if a viewer's frames neither received nor counted as skipped exceed this per stream (-1 = no check)");
  app.add_option("--min-received-ratio", o.min_received_ratio,
                 "exit 1 if a viewer received less than this share of the frames sent (0 = no check)")
      ->check(ave::cli::Range(0.0, 1.0));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) {
      std::cout << app.help();
      return 0;
    }
    std::cerr << "ave-loadgen: " << e.what() << "\n";
    return 2;
  }
  ave::log::MinLevel() = ave::log::Level::kWARNING;
  auto env = [](const char* name) { const char* v = std::getenv(name); return std::string(v ? v : ""); };
  int width = 640, height = 480;
  if (o.size == "1920x1080") width = 1920, height = 1080;

  ServerProcess own;
  if (o.server.empty()) {
    if (o.server_bin.empty()) {
      o.server_bin = (std::filesystem::canonical("/proc/self/exe").parent_path() / "ave-server").string();
    }
    std::mt19937_64 rng(std::random_device{}());
    o.sensor_token = "s" + std::to_string(rng());
    o.viewer_token = "v" + std::to_string(rng());
    o.admin_token = "a" + std::to_string(rng());
  } else {
    if (!ave::net::IsLoopbackAddress(o.server)) {
      std::cerr << "ave-loadgen: refusing non-loopback target '" << o.server << "' (load tests run on this host only)\n";
      return 2;
    }
    if (o.sensor_token.empty()) o.sensor_token = env("AVE_SENSOR_TOKEN");
    if (o.viewer_token.empty()) o.viewer_token = env("AVE_VIEWER_TOKEN");
    if (o.admin_token.empty()) o.admin_token = env("AVE_ADMIN_TOKEN");
  }

  std::cerr << "ave-loadgen: encoding frames " << o.size << "\n";
  const std::vector<std::string> jpegs = MakeJpegs(width, height, 8, o.quality);
  size_t jpeg_bytes = 0;
  for (const auto& j : jpegs) jpeg_bytes = std::max(jpeg_bytes, j.size());

  if (o.server.empty()) {
    absl::StatusOr<ServerProcess> started = StartServer(o, static_cast<int64_t>(jpeg_bytes));
    if (!started.ok()) {
      std::cerr << "ave-loadgen: " << started.status().message() << "\n";
      return 1;
    }
    own = *started;
    o.server = own.address;
    o.server_pid = own.pid;
  }
  auto stop_server = [&] {
    if (own.pid > 0) {
      ::kill(own.pid, SIGTERM);
      int status = 0;
      ::waitpid(own.pid, &status, 0);
      std::filesystem::remove_all(own.dir);
      own.pid = 0;
    }
  };
  const ave::net::TlsClientOptions tls{.ca_file = o.tls_ca};
  auto make_channel = [&](int index) {
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // one connection per simulated node
    args.SetInt("ave.loadgen.node", index);
    args.SetMaxReceiveMessageSize(64 << 20);
    return ave::net::MakeChannel(o.server, tls, args);
  };

  // Register the cameras.
  auto admin_channel = make_channel(-1);
  if (!admin_channel.ok()) {
    std::cerr << "ave-loadgen: " << admin_channel.status().message() << "\n";
    stop_server();
    return 1;
  }
  ave::AdminClient admin(*admin_channel, o.admin_token);
  auto camera_id = [](int i) {
    char id[32];
    std::snprintf(id, sizeof id, "load-%04d", i);
    return std::string(id);
  };
  const ave::PinholeIntrinsics intrinsics = ave::PinholeIntrinsics::FromFov(width, height, 60);
  for (int i = 0; i < o.streams; ++i) {
    ave::v1::Camera c;
    c.set_id(camera_id(i));
    c.set_name(camera_id(i));
    *c.mutable_intrinsics() = ave::ToProto(intrinsics);
    *c.mutable_mounting_pose() = ave::ToProto(ave::LookAt({i * 2.0, 0, 10}, {i * 2.0, 20, 0}));
    c.set_enabled(true);
    absl::StatusOr<ave::v1::Camera> added = admin.AddCamera(c);
    if (!added.ok() && !absl::IsAlreadyExists(added.status())) {
      std::cerr << "ave-loadgen: registering " << c.id() << ": " << added.status().message() << "\n";
      stop_server();
      return 1;
    }
  }

  const int total_seconds = static_cast<int>(std::ceil(o.duration_s)) + 2;
  std::vector<std::unique_ptr<PerSecond>> seconds;
  for (int i = 0; i < total_seconds; ++i) seconds.push_back(std::make_unique<PerSecond>());
  // The load starts a little in the future, once the viewers are subscribed, so that no stream
  // begins with a burst of catch-up frames.
  const auto start = Clock::now() + std::chrono::milliseconds(500);
  const auto end = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration_s));
  auto second_of = [&](Clock::time_point t) {
    return std::clamp(static_cast<int>(std::chrono::duration<double>(t - start).count()), 0, total_seconds - 1);
  };
  std::atomic<bool> agents_stop{false}, viewers_stop{false};
  std::atomic<int64_t> frames_sent{0}, poses_sent{0}, agent_errors{0};
  std::atomic<float> hint_min_fps{1e9};
  std::vector<int64_t> sent_per_stream(o.streams, 0);
  std::mutex error_mu;
  std::string first_error;

  // Viewers first, so that they see every frame.
  struct ViewerResult {
    int64_t received = 0;
    uint64_t skipped = 0;  // server-counted frames skipped for this viewer (latest-frame semantics)
    std::vector<int64_t> per_stream;
    std::string error;
  };
  std::vector<ViewerResult> viewer_results(o.viewers);
  std::vector<std::thread> threads;
  std::atomic<int> viewers_ready{0};
  for (int v = 0; v < o.viewers; ++v) {
    threads.emplace_back([&, v] {
      ViewerResult& r = viewer_results[v];
      r.per_stream.assign(o.streams, 0);
      std::map<std::string, uint64_t> skipped;
      auto channel = make_channel(100000 + v);
      if (!channel.ok()) {
        r.error = std::string(channel.status().message());
        ++viewers_ready;
        return;
      }
      auto stub = ave::v1::SceneService::NewStub(*channel);
      grpc::ClientContext context;
      context.set_wait_for_ready(true);  // as the sensor streams below
      context.AddMetadata("authorization", "Bearer " + o.viewer_token);
      ave::v1::SubscribeRequest request;
      request.set_viewer_id("loadgen-viewer-" + std::to_string(v));
      request.set_include_jpeg(true);
      request.set_max_rate_hz(static_cast<float>(o.viewer_rate_hz));
      auto reader = stub->Subscribe(&context, request);
      ++viewers_ready;
      std::thread canceller([&] {
        while (!viewers_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        context.TryCancel();
      });
      ave::v1::SceneUpdate update;
      while (reader->Read(&update)) {
        const int64_t now = ave::NowNs();
        const auto t = Clock::now();
        const bool measured = t - start >= std::chrono::duration<double>(o.warmup_s);
        PerSecond& bucket = *seconds[second_of(t)];
        for (const auto& cam : update.cameras()) {
          skipped[cam.camera_id()] = cam.frames_skipped();
          if (cam.jpeg().empty()) continue;
          ++r.received;
          bucket.received++;
          const int index = std::atoi(cam.camera_id().c_str() + 5);
          if (index >= 0 && index < o.streams) ++r.per_stream[index];
          if (measured) {
            const double ms = (now - cam.frame_capture_time_ns()) * 1e-6;
            std::lock_guard lock(bucket.mu);
            bucket.latency_ms.push_back(ms);
          }
        }
      }
      const grpc::Status s = reader->Finish();
      if (!s.ok() && s.error_code() != grpc::StatusCode::CANCELLED) r.error = s.error_message();
      for (const auto& [id, n] : skipped) r.skipped += n;
      canceller.join();
    });
  }
  while (viewers_ready.load() < o.viewers) std::this_thread::sleep_for(std::chrono::milliseconds(10));

  for (int i = 0; i < o.streams; ++i) {
    threads.emplace_back([&, i] {
      auto fail = [&](const std::string& what) {
        ++agent_errors;
        std::lock_guard lock(error_mu);
        if (first_error.empty()) first_error = camera_id(i) + ": " + what;
      };
      auto channel = make_channel(i);
      if (!channel.ok()) return fail(std::string(channel.status().message()));
      auto stub = ave::v1::SensorService::NewStub(*channel);
      grpc::ClientContext context;
      // Hundreds of connections open at once on a loaded machine: a node's first connect attempt
      // can fail (seen once in 12 CI-like runs: "failed to connect to all addresses"), and gRPC
      // then fails a call that does not wait at once. A real agent retries with backoff
      // (AgentStreamer); here the call waits for the channel's own reconnection instead.
      context.set_wait_for_ready(true);
      auto stream = stub->Stream(&context);
      ave::v1::SensorMessage m;
      m.mutable_hello()->set_camera_id(camera_id(i));
      m.mutable_hello()->set_token(o.sensor_token);
      *m.mutable_hello()->mutable_intrinsics() = ave::ToProto(intrinsics);
      m.mutable_hello()->set_software_version("ave-loadgen");
      if (!stream->Write(m)) return fail("hello not sent: " + stream->Finish().error_message());
      std::thread reader([&] {
        ave::v1::SensorAck ack;
        while (stream->Read(&ack)) {
          const float hint = ack.hint().max_fps();
          float seen = hint_min_fps.load();
          while (hint > 0 && hint < seen && !hint_min_fps.compare_exchange_weak(seen, hint)) {
          }
        }
      });
      // Stagger the streams over one frame period so frames do not arrive in lockstep.
      const double period_s = 1.0 / o.fps;
      const double pose_period_s = o.pose_hz > o.fps ? 1.0 / o.pose_hz : period_s;
      auto next_frame = start + std::chrono::duration_cast<Clock::duration>(
                                    std::chrono::duration<double>(period_s * i / o.streams));
      auto next_pose = next_frame + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(pose_period_s));
      uint64_t sequence = 0;
      const ave::v1::Pose pose = ave::ToProto(ave::LookAt({i * 2.0, 0, 10}, {i * 2.0, 20, 0}));
      int k = i;
      while (!agents_stop.load()) {
        const bool frame_due = next_frame <= next_pose;
        const auto due = frame_due ? next_frame : next_pose;
        if (due >= end) break;
        std::this_thread::sleep_until(due);
        ave::v1::SensorFrame* f = m.mutable_frame();
        f->Clear();
        f->set_sequence(++sequence);
        *f->mutable_pose() = pose;
        for (int b = 0; b < o.boxes; ++b) {
          ave::v1::DetectedBox* box = f->add_boxes();
          box->set_track_id(static_cast<uint32_t>(b + 1));
          box->set_score(0.9f);
          const float x = static_cast<float>(20 + 60 * b + (k % 20)), y = 200;
          for (auto [cx, cy] : {std::pair{x, y}, {x + 40, y}, {x + 40, y + 90}, {x, y + 90}}) {
            ave::v1::Point2* p = box->add_corners();
            p->set_x(cx);
            p->set_y(cy);
          }
        }
        if (frame_due) {
          f->set_jpeg(jpegs[static_cast<size_t>(k++) % jpegs.size()]);
        } else {
          f->set_metadata_only(true);
        }
        f->set_capture_time_ns(ave::NowNs());  // the capture stamp: latency is measured from here
        if (!stream->Write(m)) {
          fail("stream broke");
          break;
        }
        if (frame_due) {
          ++frames_sent;
          ++sent_per_stream[i];
          seconds[second_of(Clock::now())]->sent++;
          next_frame += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
          if (pose_period_s < period_s) {
            next_pose = next_frame - std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(period_s - pose_period_s));
          } else {
            next_pose = next_frame + std::chrono::hours(1);
          }
        } else {
          ++poses_sent;
          next_pose += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(pose_period_s));
          if (next_pose > next_frame) next_pose = next_frame + std::chrono::hours(1);
        }
      }
      stream->WritesDone();
      const grpc::Status s = stream->Finish();
      reader.join();
      if (!s.ok()) fail(s.error_message());
    });
  }

  // Sample the server process until the end.
  std::vector<ProcSample> proc;
  uint64_t last_ticks = 0;
  double rss = 0, peak_rss = 0;
  const double ticks_per_s = static_cast<double>(::sysconf(_SC_CLK_TCK));
  auto last_t = Clock::now();
  if (o.server_pid > 0) ReadProc(o.server_pid, &last_ticks, &rss);
  double cpu_sum = 0;
  int cpu_n = 0;
  while (Clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    if (o.server_pid <= 0) continue;
    uint64_t ticks = 0;
    if (!ReadProc(o.server_pid, &ticks, &rss)) continue;
    const auto t = Clock::now();
    const double cpu = 100.0 * (ticks - last_ticks) / ticks_per_s / std::chrono::duration<double>(t - last_t).count();
    last_ticks = ticks;
    last_t = t;
    peak_rss = std::max(peak_rss, rss);
    const double t_s = std::chrono::duration<double>(t - start).count();
    proc.push_back({t_s, cpu, rss});
    if (t_s >= o.warmup_s) {
      cpu_sum += cpu;
      ++cpu_n;
    }
  }
  agents_stop = true;
  for (int i = o.viewers; i < static_cast<int>(threads.size()); ++i) threads[i].join();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the last frames reach the viewers
  viewers_stop = true;
  for (int i = 0; i < o.viewers; ++i) threads[i].join();
  stop_server();

  // Figures.
  const double duration = o.duration_s;
  std::vector<double> all;
  for (const auto& s : seconds) all.insert(all.end(), s->latency_ms.begin(), s->latency_ms.end());
  const double p50 = Percentile(all, 0.5), p95 = Percentile(all, 0.95), p99 = Percentile(all, 0.99);
  int64_t received = 0;
  uint64_t drops = 0;
  std::string viewer_error;
  double min_ratio = 1e9;
  int64_t max_unaccounted = 0;  // over the viewers: frames sent - received - skipped
  for (const auto& r : viewer_results) {
    received += r.received;
    drops += r.skipped;
    max_unaccounted = std::max(max_unaccounted, frames_sent.load() - r.received - static_cast<int64_t>(r.skipped));
    if (!r.error.empty()) viewer_error = r.error;
    min_ratio = std::min(min_ratio, frames_sent.load() > 0 ? double(r.received) / frames_sent.load() : 0.0);
  }
  if (o.viewers == 0) min_ratio = 0;
  const double fps_sent = frames_sent.load() / duration;
  const double fps_received = o.viewers > 0 ? received / duration / o.viewers : 0;
  const double cpu_pct = cpu_n > 0 ? cpu_sum / cpu_n : 0;

  std::cout << "per stream (frames sent / received by viewer 0):\n";
  for (int i = 0; i < o.streams; ++i) {
    std::cout << "  " << camera_id(i) << " sent " << sent_per_stream[i] << " (" << sent_per_stream[i] / duration
              << " fps)";
    if (o.viewers > 0) std::cout << " received " << viewer_results[0].per_stream[i];
    std::cout << "\n";
  }
  std::cout << "over time (s: sent/s, received/s, p99 ms, server CPU %, RSS MB):\n";
  for (size_t i = 0; i < seconds.size(); ++i) {
    std::vector<double> v = seconds[i]->latency_ms;
    double cpu = 0, mem = 0;
    for (const auto& s : proc) {
      if (static_cast<size_t>(s.t_s) == i) cpu = s.cpu_pct, mem = s.rss_mb;
    }
    std::cout << "  " << i << ": " << seconds[i]->sent.load() << ", " << seconds[i]->received.load() << ", "
              << (v.empty() ? 0.0 : Percentile(v, 0.99)) << ", " << cpu << ", " << mem << "\n";
  }
  if (!first_error.empty()) std::cerr << "ave-loadgen: " << agent_errors.load() << " agent errors, first: " << first_error << "\n";
  if (!viewer_error.empty()) std::cerr << "ave-loadgen: viewer error: " << viewer_error << "\n";
  if (!o.plot.empty()) Plot(o.plot, seconds, proc, o.streams, o.viewers);

  char json[1024];
  std::snprintf(json, sizeof json,
                "{\"streams\":%d,\"viewers\":%d,\"size\":\"%s\",\"duration_s\":%.1f,\"fps_sent\":%.1f,"
                "\"fps_received\":%.1f,\"drops\":%llu,\"unaccounted\":%lld,\"p50_ms\":%.2f,\"p95_ms\":%.2f,\"p99_ms\":%.2f,"
                "\"server_cpu_pct\":%.1f,\"server_cpu_pct_per_stream\":%.2f,\"server_peak_rss_mb\":%.1f,"
                "\"poses_per_s\":%.1f,\"agent_errors\":%lld,\"min_hint_fps\":%.1f}",
                o.streams, o.viewers, o.size.c_str(), duration, fps_sent, fps_received,
                static_cast<unsigned long long>(drops), static_cast<long long>(max_unaccounted), p50, p95, p99, cpu_pct, cpu_pct / o.streams, peak_rss,
                (frames_sent.load() + poses_sent.load()) / duration, static_cast<long long>(agent_errors.load()),
                hint_min_fps.load() > 1e8 ? 0.0 : hint_min_fps.load());
  std::cout << json << std::endl;

  int rc = 0;
  if (agent_errors.load() > 0 || !viewer_error.empty()) rc = 1;
  if (o.max_drops >= 0 && static_cast<int64_t>(drops) > o.max_drops) {
    std::cerr << "ave-loadgen: FAIL " << drops << " drops > " << o.max_drops << "\n";
    rc = 1;
  }
  if (o.max_unaccounted_per_stream >= 0 && o.viewers > 0 && max_unaccounted > o.max_unaccounted_per_stream * o.streams) {
    std::cerr << "ave-loadgen: FAIL a viewer neither received nor was told of " << max_unaccounted << " of "
              << frames_sent.load() << " frames (at most " << o.max_unaccounted_per_stream << " per stream)\n";
    rc = 1;
  }
  if (o.max_p99_ms > 0 && p99 > o.max_p99_ms) {
    std::cerr << "ave-loadgen: FAIL p99 " << p99 << " ms > " << o.max_p99_ms << " ms\n";
    rc = 1;
  }
  if (o.min_received_ratio > 0 && min_ratio < o.min_received_ratio) {
    std::cerr << "ave-loadgen: FAIL a viewer received " << min_ratio << " of the frames sent (< " << o.min_received_ratio << ")\n";
    rc = 1;
  }
  return rc;
}
