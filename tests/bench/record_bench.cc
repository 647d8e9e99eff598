// ave-bench record (issue 18): what recording costs and how fast a replay finds its place.
//
// --rounds rounds of two phases against real ave-server processes on loopback, the load from
// ave-loadgen (deploy/loadtest: N agents streaming pre-encoded 640x480 JPEGs at --fps, one viewer):
// recording off, and with --record-dir under the same load, in alternating order round by round.
// Reported side by side: server CPU (from /proc, by ave-loadgen), the overhead recording adds (the
// median of the rounds' on/off ratios), MB/s written, recorder drops (queue full, disk full), then
// over the last recording made: seek latency (ReplaySession::Open at random times:
// the index probes, the warm-up and the JPEG reads), replay start-up (Replay call to first update
// through a restarted server), index bytes per recorded hour (SQLite dbstat of the record_
// tables). A PNG of the figures; last line on stdout a JSON summary.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <thread>

#include <grpcpp/grpcpp.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/record/record_index.h"
#include "fusion_server/record/replay.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct Options {
  int streams = 50;
  double fps = 15;
  double seconds = 20;
  int seeks = 100;
  int rounds = 3;
  bool concurrent = false;
  bool direct_io = true;  // the server's default; false: the recording servers get --record-buffered-io
  std::string plot = "record_bench.png";
  std::string dir;  // recording and stores; default a temporary directory
};

struct Server {
  pid_t pid = 0;
  std::string address;
  int metrics_port = 0;
};

std::string Bin(const std::string& name) {
  return (fs::canonical("/proc/self/exe").parent_path() / name).string();
}

absl::StatusOr<Server> StartServer(const fs::path& dir, const std::string& record_dir, bool direct_io) {
  fs::create_directories(dir);
  const std::string out = (dir / "server.out").string();
  fs::remove(out);
  Server s;
  s.pid = ::fork();
  if (s.pid == 0) {
    std::freopen(out.c_str(), "w", stdout);
    std::freopen((dir / "server.log").c_str(), "a", stderr);
    ::setenv("AVE_SENSOR_TOKEN", "bench-sensor", 1);
    ::setenv("AVE_VIEWER_TOKEN", "bench-viewer", 1);
    ::setenv("AVE_ADMIN_TOKEN", "bench-admin", 1);
    const std::string bin = Bin("ave-server"), store = (dir / "ave.db").string();
    std::vector<std::string> args = {bin, "--listen", "127.0.0.1:0", "--store", store, "--campus-grid", "8",
                                     "--log-level", "warning", "--max-fps-hint", "30", "--metrics-listen", "127.0.0.1:0"};
    if (!record_dir.empty()) args.insert(args.end(), {"--record-dir", record_dir});
    if (!record_dir.empty() && !direct_io) args.push_back("--record-buffered-io");
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(bin.c_str(), argv.data());
    std::_Exit(127);
  }
  for (int i = 0; i < 400; ++i) {
    std::ifstream in(out);
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("listening on port ", 0) == 0) s.address = "127.0.0.1:" + line.substr(18);
      if (line.rfind("metrics on port ", 0) == 0) s.metrics_port = std::stoi(line.substr(16));
    }
    if (!s.address.empty() && s.metrics_port) return s;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ::kill(s.pid, SIGKILL);
  ::waitpid(s.pid, nullptr, 0);
  return absl::DeadlineExceededError("ave-server did not start (see " + (dir / "server.log").string() + ")");
}

void StopServer(Server& s) {
  ::kill(s.pid, SIGTERM);  // drains: the recorder writes and indexes what is queued
  ::waitpid(s.pid, nullptr, 0);
}

// One value of the server's Prometheus text (GET /metrics), or -1.
double Metric(int port, const std::string& name) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  std::string text;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    const std::string request = "GET /metrics HTTP/1.0\r\n\r\n";
    (void)!::write(fd, request.data(), request.size());
    char buf[65536];
    for (ssize_t n; (n = ::read(fd, buf, sizeof buf)) > 0;) text.append(buf, n);
  }
  ::close(fd);
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(name + " ", 0) == 0) return std::stod(line.substr(name.size() + 1));
  }
  return -1;
}

// Runs ave-loadgen against `s`; its JSON summary line parsed into numbers.
std::map<std::string, double> RunLoad(const Server& s, const Options& o, const fs::path& dir, const std::string& tag) {
  const std::string out = (dir / ("loadgen_" + tag + ".out")).string();
  const std::string cmd = Bin("ave-loadgen") + " --server " + s.address + " --server-pid " + std::to_string(s.pid) +
                          " --sensor-token bench-sensor --viewer-token bench-viewer --admin-token bench-admin" +
                          " --streams " + std::to_string(o.streams) + " --fps " + std::to_string(o.fps) +
                          " --duration " + std::to_string(o.seconds) + " --viewers 1 --plot " +
                          (dir / ("loadgen_" + tag + ".png")).string() + " > " + out + " 2>&1";
  std::map<std::string, double> json;
  if (std::system(cmd.c_str()) != 0) {
    std::cerr << "ave-bench record: ave-loadgen failed, see " << out << "\n";
    return json;
  }
  std::ifstream in(out);
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] == '{') last = line;
  }
  // Flat {"key":number,...}: numbers only (strings skipped).
  for (size_t i = 0; (i = last.find('"', i)) != std::string::npos;) {
    const size_t end = last.find('"', i + 1);
    if (end == std::string::npos || end + 1 >= last.size()) break;
    if (last[end + 1] != ':') {  // a string value, not a key
      i = end + 1;
      continue;
    }
    const std::string key = last.substr(i + 1, end - i - 1);
    char* stop = nullptr;
    const double v = std::strtod(last.c_str() + end + 2, &stop);
    if (stop != last.c_str() + end + 2) json[key] = v;
    i = end + 1;
  }
  return json;
}

// CPU seconds (user + system) of the server's recorder thread: the one named "ave-recorder", or,
// for a server that does not name it (before issue 18's cost work), the busiest thread that
// kept the process's name other than the main one. 0 when there is none.
double RecorderCpuSeconds(pid_t pid) {
  double named = -1, busiest = 0;
  std::error_code ec;
  for (const auto& task : fs::directory_iterator("/proc/" + std::to_string(pid) + "/task", ec)) {
    std::string comm;
    std::getline(std::ifstream(task.path() / "comm"), comm);
    std::string stat;
    std::getline(std::ifstream(task.path() / "stat"), stat);
    const size_t paren = stat.rfind(')');
    if (paren == std::string::npos) continue;
    std::istringstream fields(stat.substr(paren + 2));
    std::string f;
    double ticks = 0;
    for (int i = 3; i <= 15 && fields >> f; ++i) {
      if (i == 14 || i == 15) ticks += std::stod(f);  // utime, stime
    }
    const double seconds = ticks / static_cast<double>(::sysconf(_SC_CLK_TCK));
    if (comm == "ave-recorder") named = seconds;
    else if (comm == "ave-server" && task.path().filename() != std::to_string(pid)) busiest = std::max(busiest, seconds);
  }
  return named >= 0 ? named : busiest;
}

double LoadAverage() {  // the 1-minute load average, as the docs quote it
  double v = -1;
  std::ifstream("/proc/loadavg") >> v;
  return v;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))];
}

int64_t IndexBytes(const std::string& store_path) {
  sqlite3* db = nullptr;
  int64_t bytes = -1;
  if (sqlite3_open_v2(store_path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db, "SELECT sum(pgsize) FROM dbstat WHERE name LIKE 'record_%'", -1, &s, nullptr) == SQLITE_OK &&
        sqlite3_step(s) == SQLITE_ROW) {
      bytes = sqlite3_column_int64(s, 0);
    }
    sqlite3_finalize(s);
  }
  sqlite3_close(db);
  return bytes;
}

void Plot(const std::string& path, const std::vector<std::pair<std::string, double>>& bars,
          const std::vector<double>& seeks_ms) {
  cv::Mat img(420, 900, CV_8UC3, cv::Scalar(255, 255, 255));
  cv::putText(img, "ave-bench record: server CPU % (100 = one core) and MB/s", {20, 30}, cv::FONT_HERSHEY_SIMPLEX, 0.6, {0, 0, 0}, 1);
  double top = 1;
  for (const auto& [name, v] : bars) top = std::max(top, v);
  for (size_t i = 0; i < bars.size(); ++i) {
    const int x = 40 + static_cast<int>(i) * 100, h = static_cast<int>(300 * bars[i].second / top);
    cv::rectangle(img, cv::Rect(x, 360 - h, 60, h), i % 2 ? cv::Scalar(40, 40, 200) : cv::Scalar(200, 120, 40), cv::FILLED);
    cv::putText(img, bars[i].first, {x - 10, 380}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0}, 1);
    char v[32];
    std::snprintf(v, sizeof v, "%.1f", bars[i].second);
    cv::putText(img, v, {x, 350 - h}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1);
  }
  // Seek latency distribution (sorted, ms).
  cv::putText(img, "seek latency, sorted (ms)", {560, 60}, cv::FONT_HERSHEY_SIMPLEX, 0.5, {0, 0, 0}, 1);
  cv::rectangle(img, cv::Rect(560, 70, 320, 290), {0, 0, 0}, 1);
  std::vector<double> sorted = seeks_ms;
  std::sort(sorted.begin(), sorted.end());
  const double max_ms = sorted.empty() ? 1 : std::max(1e-3, sorted.back());
  for (size_t i = 0; i < sorted.size(); ++i) {
    const int x = 560 + static_cast<int>(320.0 * i / std::max<size_t>(1, sorted.size() - 1));
    const int y = 360 - static_cast<int>(290 * sorted[i] / max_ms);
    cv::circle(img, {x, y}, 2, {0, 140, 0}, cv::FILLED);
  }
  char label[64];
  std::snprintf(label, sizeof label, "max %.1f ms", max_ms);
  cv::putText(img, label, {565, 88}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1);
  cv::imwrite(path, img);
}

int Run(const Options& o) {
  const fs::path dir = o.dir.empty() ? fs::temp_directory_path() / ("ave_record_bench_" + std::to_string(::getpid())) : fs::path(o.dir);
  fs::remove_all(dir);

  // Rounds of two phases each, recording off and on, in alternating order (off-on, on-off, ...):
  // this machine's load drifts over minutes, and one off phase then one on phase 20 s later
  // measured the drift as much as the recording (+2 % to +27 % in three runs). Each phase runs a
  // fresh server (its own store; recording into its own directory) under the same load; the
  // overhead is the median of the rounds' on/off ratios, so one disturbed round does not decide it.
  std::vector<double> cpu_off, cpu_on, overheads;
  double record_drops = 0, full_skips = 0, frames_in = 0, fps_off = 0, fps_on = 0;
  // The recorder's queue right after a recording phase's ave-loadgen exits (largest over the
  // rounds): its writes, syncs and commits come after ave-loadgen's CPU window, so the on phase's
  // CPU leaves them out. Near 0 (at most a flush period's frames, as many as the window's start
  // carried in) the comparison is fair; a writer falling behind on a loaded machine flatters recording.
  double queue_at_end = 0;
  double recorder_cpu_s = 0;  // the recorder thread's CPU over every recording phase's load
  fs::path on_dir, rec;
  std::vector<fs::path> on_dirs;
  for (int r = 0; r < o.rounds; ++r) {
    double round_cpu[2] = {0, 0};
    struct Phase {
      bool recording = false;
      std::string tag;
      fs::path dir;
      Server server;
      std::map<std::string, double> load;
    };
    auto start = [&](bool recording) -> absl::StatusOr<Phase> {
      Phase p;
      p.recording = recording;
      p.tag = std::string(recording ? "on" : "off") + "_" + std::to_string(r + 1);
      p.dir = dir / p.tag;
      auto server = StartServer(p.dir, recording ? (p.dir / "rec").string() : "", o.direct_io);
      if (!server.ok()) return server.status();
      p.server = *server;
      return p;
    };
    // After the load: the recorder's counters, then the server stops (draining the recorder).
    auto finish = [&](Phase& p) -> bool {
      if (p.recording) {
        record_drops += std::max(0.0, Metric(p.server.metrics_port, "ave_record_drops_total"));
        queue_at_end = std::max(queue_at_end, Metric(p.server.metrics_port, "ave_record_queue_items"));
        full_skips += std::max(0.0, Metric(p.server.metrics_port, "ave_record_disk_full_skips_total"));
        frames_in += std::max(0.0, Metric(p.server.metrics_port, "ave_frames_in_total"));
        on_dir = p.dir;
        rec = p.dir / "rec";
        on_dirs.push_back(p.dir);
      }
      StopServer(p.server);
      if (p.load.empty() || !p.load.count("server_cpu_pct")) return false;
      round_cpu[p.recording] = p.load.at("server_cpu_pct");
      (p.recording ? fps_on : fps_off) += p.load.count("fps_sent") ? p.load.at("fps_sent") / o.rounds : 0;
      std::cerr << "round " << r + 1 << " " << (p.recording ? "on " : "off") << ": server CPU " << round_cpu[p.recording]
                << " % of a core (load average " << LoadAverage() << ")\n";
      return true;
    };
    if (o.concurrent) {
      // Both servers at once, each under its own ave-loadgen: the same moment's load on both.
      auto off = start(false), on = start(true);
      if (!off.ok() || !on.ok()) {
        return std::cerr << "ave-bench record: " << (off.ok() ? on.status() : off.status()).message() << "\n", 1;
      }
      std::thread off_load([&] { off->load = RunLoad(off->server, o, dir, off->tag); });
      const double recorder_before = RecorderCpuSeconds(on->server.pid);
      on->load = RunLoad(on->server, o, dir, on->tag);
      recorder_cpu_s += RecorderCpuSeconds(on->server.pid) - recorder_before;
      off_load.join();
      if (!finish(*off) || !finish(*on)) return 1;
    } else {
      for (const bool recording : {r % 2 == 1, r % 2 == 0}) {
        auto p = start(recording);
        if (!p.ok()) return std::cerr << "ave-bench record: " << p.status().message() << "\n", 1;
        const double recorder_before = RecorderCpuSeconds(p->server.pid);
        p->load = RunLoad(p->server, o, dir, p->tag);
        if (recording) recorder_cpu_s += RecorderCpuSeconds(p->server.pid) - recorder_before;
        if (!finish(*p)) return 1;
      }
    }
    cpu_off.push_back(round_cpu[0]);
    cpu_on.push_back(round_cpu[1]);
    overheads.push_back(round_cpu[0] > 0 ? 100.0 * (round_cpu[1] - round_cpu[0]) / round_cpu[0] : 0);
  }
  // Frames indexed, over every recording phase.
  int64_t frames_all = 0;
  for (const fs::path& d : on_dirs) {
    auto index = record::RecordIndex::Open((d / "ave.db").string());
    if (!index.ok()) return std::cerr << "ave-bench record: " << index.status().message() << "\n", 1;
    auto spans = (*index)->Spans();
    if (!spans.ok()) return std::cerr << "ave-bench record: " << spans.status().message() << "\n", 1;
    for (const auto& span : *spans) frames_all += span.frames;
  }

  // Seeks, replay start-up and index size: over the last recording phase.
  const std::string store = (on_dir / "ave.db").string();
  auto index = record::RecordIndex::Open(store);
  if (!index.ok()) return std::cerr << "ave-bench record: " << index.status().message() << "\n", 1;
  auto spans = (*index)->Spans();
  int64_t first_ns = std::numeric_limits<int64_t>::max(), last_ns = 0, frames = 0;
  for (const auto& span : *spans) {
    first_ns = std::min(first_ns, span.first_ns);
    last_ns = std::max(last_ns, span.last_ns);
    frames += span.frames;
  }
  int64_t segment_bytes = 0;
  for (auto it = fs::recursive_directory_iterator(rec); it != fs::recursive_directory_iterator(); ++it) {
    if (it->is_regular_file()) segment_bytes += static_cast<int64_t>(it->file_size());
  }
  const double recorded_s = std::max(1e-9, (last_ns - first_ns) * 1e-9);
  const double mb_per_s = segment_bytes / 1e6 / recorded_s;
  const int64_t index_bytes = IndexBytes(store);
  const double index_bytes_per_hour = index_bytes * 3600.0 / recorded_s;

  // Seeks: a replay of every camera opened at random recorded times (index probes + warm-up + JPEG reads).
  std::mt19937_64 rng(18);
  std::uniform_int_distribution<int64_t> when(first_ns + 1'000'000'000, std::max(first_ns + 1'000'000'001, last_ns - 1'000'000'000));
  // Twice: with the default 10 s warm-up (objects and paths as live), and without (the index
  // probes and the JPEG reads alone).
  std::vector<double> seek_ms, probe_ms;
  for (int i = 0; i < o.seeks; ++i) {
    record::ReplayOptions ro;
    ro.store_path = store;
    ro.dir = rec.string();
    ro.from_ns = when(rng);
    ro.to_ns = ro.from_ns + 1'000'000'000;
    for (const bool warm : {true, false}) {
      ro.warmup = warm ? std::chrono::seconds(10) : std::chrono::seconds(0);
      const auto t0 = Clock::now();
      auto session = record::ReplaySession::Open(ro, {}, nullptr);
      (warm ? seek_ms : probe_ms).push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      if (!session.ok()) return std::cerr << "ave-bench record: seek: " << session.status().message() << "\n", 1;
    }
  }
  // Replay start-up through a server: the Replay call until its first update arrives.
  auto again = StartServer(on_dir, rec.string(), o.direct_io);
  if (!again.ok()) return std::cerr << "ave-bench record: " << again.status().message() << "\n", 1;
  // A replay's first update carries every camera's image at the seek point: with many cameras it
  // passes gRPC's default 4 MB receive limit, so allow what the server may send (16 MB).
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(16 << 20);
  auto stub = v1::SceneService::NewStub(
      grpc::CreateCustomChannel(again->address, grpc::InsecureChannelCredentials(), args));
  std::vector<double> startup_ms;
  for (int i = 0; i < 10; ++i) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer bench-viewer");
    v1::ReplayRequest request;
    request.set_start_time_ns(when(rng));
    request.set_end_time_ns(request.start_time_ns() + 5'000'000'000);
    request.set_include_jpeg(true);
    request.set_max_updates(1);
    const auto t0 = Clock::now();
    auto reader = stub->Replay(&context, request);
    v1::SceneUpdate update;
    const bool got = reader->Read(&update);
    if (got) startup_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    context.TryCancel();
    const grpc::Status status = reader->Finish();
    if (!got) std::cerr << "ave-bench record: replay start-up: " << status.error_message() << "\n";
  }
  StopServer(*again);

  const double median_off = Percentile(cpu_off, 0.5), median_on = Percentile(cpu_on, 0.5);
  const double overhead_pct = Percentile(overheads, 0.5);
  // The recorder thread's own CPU while the load ran, in % of a core (its share of the overhead
  // that this machine's load cannot blur: the other threads' CPU varies more between phases).
  const double recorder_cpu_pct = 100.0 * recorder_cpu_s / (o.seconds * o.rounds);
  const double drops = record_drops + full_skips;
  std::cout << "recording off: server CPU " << median_off << " % of a core (median of " << o.rounds << " phases), " << fps_off
            << " frames/s sent\n"
            << "recording on:  server CPU " << median_on << " % of a core (median), " << fps_on << " frames/s sent, "
            << frames_all << " of " << frames_in << " accepted frames indexed, " << drops << " recorder drops\n"
            << "overhead per round (on vs off of the same round):";
  for (double v : overheads) std::cout << " " << v << " %";
  std::cout << "; median " << overhead_pct << " % server CPU; " << mb_per_s << " MB/s written over " << recorded_s
            << " s (last round); load average " << LoadAverage() << "\n"
            << "recorder thread: " << recorder_cpu_pct << " % of a core while recording; recorder queue at the load's end: "
            << queue_at_end << " items at most (left out of the on phase's CPU)\n"
            << "seek (" << seek_ms.size() << " random times, all cameras): p50 " << Percentile(seek_ms, 0.5) << " ms, p99 "
            << Percentile(seek_ms, 0.99) << " ms; without the warm-up p50 " << Percentile(probe_ms, 0.5) << " ms, p99 "
            << Percentile(probe_ms, 0.99) << " ms; replay start-up (Replay call to first update) p50 "
            << Percentile(startup_ms, 0.5) << " ms\n"
            << "index: " << index_bytes << " bytes for " << recorded_s << " s = " << index_bytes_per_hour / 1e6
            << " MB per recorded hour (" << (frames ? index_bytes / frames : 0) << " bytes per frame)\n";
  Plot(o.plot, {{"CPU off", median_off}, {"CPU on", median_on}, {"MB/s", mb_per_s}}, seek_ms);
  char json[900];
  std::snprintf(json, sizeof json,
                "{\"streams\":%d,\"fps\":%.1f,\"seconds\":%.1f,\"rounds\":%d,\"concurrent\":%d,\"direct_io\":%d,\"record_drops\":%.0f,\"cpu_off_pct\":%.1f,"
                "\"cpu_on_pct\":%.1f,\"cpu_overhead_pct\":%.1f,\"cpu_overhead_min_pct\":%.1f,\"cpu_overhead_max_pct\":%.1f,"
                "\"mb_per_s\":%.2f,\"seek_p50_ms\":%.2f,"
                "\"seek_p99_ms\":%.2f,\"seek_no_warmup_p99_ms\":%.2f,\"replay_startup_ms\":%.2f,\"index_bytes_per_hour\":%.0f,"
                "\"frames_indexed\":%lld,\"recorder_cpu_pct\":%.2f,\"record_queue_at_end\":%.0f,\"loadavg_1m\":%.2f}",
                o.streams, o.fps, o.seconds, o.rounds, o.concurrent ? 1 : 0, o.direct_io ? 1 : 0, drops, median_off, median_on, overhead_pct,
                *std::min_element(overheads.begin(), overheads.end()), *std::max_element(overheads.begin(), overheads.end()),
                mb_per_s, Percentile(seek_ms, 0.5), Percentile(seek_ms, 0.99), Percentile(probe_ms, 0.99),
                Percentile(startup_ms, 0.5), index_bytes_per_hour, static_cast<long long>(frames_all), recorder_cpu_pct, queue_at_end, LoadAverage());
  std::cout << json << std::endl;
  if (o.dir.empty()) fs::remove_all(dir);
  return 0;
}

}  // namespace

Runner AddRecordBench(CLI::App& sub) {
  auto o = std::make_shared<Options>();
  sub.add_option("--streams", o->streams, "simulated agents")->capture_default_str();
  sub.add_option("--fps", o->fps, "frames per second per stream")->capture_default_str();
  sub.add_option("--seconds", o->seconds, "seconds of load per phase")->capture_default_str();
  sub.add_flag("--concurrent", o->concurrent,
               "run each round's off and on servers at once, each under its own ave-loadgen (the same moment's "
               "machine load on both; twice the load on the machine)");
  sub.add_flag("--direct-io,!--buffered-io", o->direct_io,
               "the recording servers write with O_DIRECT (ave-server's default), or through the page cache "
               "(--buffered-io: ave-server --record-buffered-io)");
  sub.add_option("--rounds", o->rounds, "rounds of an off and an on phase, in alternating order")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  sub.add_option("--seeks", o->seeks, "random seeks timed")->capture_default_str();
  sub.add_option("--plot", o->plot, "PNG of the figures")->capture_default_str();
  sub.add_option("--dir", o->dir, "keep the stores and recording here (default: a temporary directory, removed)");
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
