// ave-bench lidar-decode (issue 16): the Velodyne pcap source on the simulator's HDL-64E capture,
// on one core: sweeps/s and points/s of the whole source (our pcap reader + packet decoder), the
// realtime factor against the capture's own rate, and memory over a long looped replay. The peer,
// measured in the same run on the same file: libpcap's pcap_next_ex reading the same records
// (only where libpcap-dev was found at configure time), against our reader alone. PCL's
// HDLGrabber is no throughput peer: its pcap thread sleeps between packets to replay at the
// capture's own rate (PCL 1.13 hdl_grabber.cpp, readPacketsFromPcap), so its realtime factor is
// 1 by construction, and it reports no error for a bad packet.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <unistd.h>

#ifdef AVE_HAVE_LIBPCAP
#include <pcap/pcap.h>
#endif

#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar/pcap_reader.h"
#include "sensor_agent/lidar/velodyne_decoder.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

struct LidarDecodeBenchOptions {
  std::string scenario = "courtyard";
  std::string lidar;  // default: the scenario's first rotating LiDAR
  int azimuth_steps = 2048;
  double seconds = 1;
  int repeats = 3;
  int loops = 30;     // long replay: the capture looped this many times
  std::string dir;    // where the capture goes (default: a temp dir, removed after)
};

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double RssMiB() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024;
  }
  return 0;
}

// The next record; false at the end or on an error (the bench's own capture has none).
bool NextRecord(lidar::PcapReader& reader, lidar::PcapRecord& r) {
  absl::StatusOr<bool> more = reader.Next(r);
  return more.ok() && *more;
}

template <typename Fn>
double BestSeconds(int repeats, Fn fn) {
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    fn();
    best = std::min(best, Seconds(t0));
  }
  return best;
}

int Run(const LidarDecodeBenchOptions& o) {
  UseOneCore();
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench: " << scenario.status().message() << "\n";
    return 1;
  }
  const sim::RotatingLidarSpec* found = nullptr;
  for (const auto& l : scenario->rotating_lidars) {
    if (o.lidar.empty() || l.id == o.lidar) {
      found = &l;
      break;
    }
  }
  if (!found) {
    std::cerr << "ave-bench: " << o.scenario << " has no rotating LiDAR " << o.lidar << "\n";
    return 1;
  }
  sim::RotatingLidarSpec spec = *found;
  spec.azimuth_steps = o.azimuth_steps;
  const bool temp = o.dir.empty();
  const std::string dir = temp ? (std::filesystem::temp_directory_path() / ("ave_lidar_bench_" + std::to_string(::getpid()))).string() : o.dir;
  auto t0 = Clock::now();
  if (absl::Status s = sim::WriteRotatingLidar(scenario->world, spec, scenario->effects, scenario->seed, o.seconds, dir); !s.ok()) {
    std::cerr << "ave-bench: " << s.message() << "\n";
    return 1;
  }
  const double sim_s = Seconds(t0);
  const std::string pcap = dir + "/velodyne.pcap";
  const double file_mib = std::filesystem::file_size(pcap) / 1048576.0;

  // Our reader alone: records and UDP payloads, no decoding.
  int64_t packets = 0;
  const double ours_read_s = BestSeconds(o.repeats, [&] {
    packets = 0;
    auto reader = lidar::PcapReader::Open(pcap);
    lidar::PcapRecord r;
    while (NextRecord(**reader, r)) packets += r.udp && r.dst_port == lidar::kVelodyneDataPort && r.payload_size == 1206;
  });

  double libpcap_read_s = 0;
  int64_t libpcap_packets = 0;
#ifdef AVE_HAVE_LIBPCAP
  libpcap_read_s = BestSeconds(o.repeats, [&] {
    libpcap_packets = 0;
    char err[PCAP_ERRBUF_SIZE];
    pcap_t* p = pcap_open_offline(pcap.c_str(), err);
    if (!p) return;
    pcap_pkthdr* h;
    const u_char* data;
    while (pcap_next_ex(p, &h, &data) == 1) {
      // The same unwrapping our reader does: Ethernet, IPv4 (IHL), UDP port and length.
      if (h->caplen < 42 || data[12] != 0x08 || data[13] != 0x00) continue;
      const size_t ihl = (data[14] & 0x0F) * 4;
      const u_char* udp = data + 14 + ihl;
      if (data[23] == 17 && ((udp[2] << 8) | udp[3]) == lidar::kVelodyneDataPort && ((udp[4] << 8) | udp[5]) - 8 == 1206) ++libpcap_packets;
    }
    pcap_close(p);
  });
#endif

  // The whole source: pcap: through OpenLidarSource, as ave-agent uses it; first with glibc's
  // default allocator thresholds, then with the ones ave-agent's LiDAR mode sets (each sweep's
  // ~4 MB point buffer otherwise goes back to the kernel and page-faults in again).
  int64_t sweeps = 0, points = 0;
  auto decode_all = [&] {
    sweeps = points = 0;
    auto source = lidar::OpenLidarSource("pcap:" + pcap, {});
    for (;;) {
      absl::StatusOr<lidar::LidarSweep> s = (*source)->Next();
      if (!s.ok()) break;
      ++sweeps;
      points += static_cast<int64_t>(s->points.size());
    }
  };
  const double decode_default_s = BestSeconds(o.repeats, decode_all);
  lidar::KeepSweepBuffersInProcess();
  const double decode_s = BestSeconds(o.repeats, decode_all);

  // Long replay: one decoder over the capture looped `loops` times; RSS after the first loop and at the end.
  lidar::VelodyneDecoder decoder({});
  std::vector<lidar::LidarSweep> done;
  auto reader = lidar::PcapReader::Open(pcap);
  double rss_start = 0, rss_mid = 0;
  int64_t replay_sweeps = 0;
  t0 = Clock::now();
  for (int loop = 0; loop < o.loops; ++loop) {
    if (loop > 0 && !(*reader)->Rewind().ok()) return 1;
    lidar::PcapRecord r;
    while (NextRecord(**reader, r)) {
      if (!r.udp || r.dst_port != lidar::kVelodyneDataPort) continue;
      if (!decoder.Add(r.payload, r.payload_size, r.t_ns, done).ok()) return 1;
      replay_sweeps += static_cast<int64_t>(done.size());
      done.clear();
    }
    if (loop == 0) rss_start = RssMiB();
    if (loop == o.loops / 2) rss_mid = RssMiB();
  }
  const double replay_s = Seconds(t0);
  const double rss_end = RssMiB();

  if (temp) std::filesystem::remove_all(dir);
  const double sweeps_per_s = sweeps / decode_s;
  std::printf("capture: %s %s, %d azimuth steps x %d rings, %lld sweeps, %.1f MiB, %lld packets (simulated in %.1f s)\n",
              o.scenario.c_str(), spec.id.c_str(), spec.azimuth_steps, spec.rings, static_cast<long long>(sweeps), file_mib,
              static_cast<long long>(packets), sim_s);
  std::printf("| stage (one core, best of %d) | packets/s | sweeps/s | points/s | realtime x (vs %.0f Hz) |\n", o.repeats, spec.rate_hz);
  std::printf("|---|---|---|---|---|\n");
  std::printf("| our pcap reader (records + UDP unwrap) | %.0f | | | |\n", packets / ours_read_s);
#ifdef AVE_HAVE_LIBPCAP
  std::printf("| libpcap pcap_next_ex + same unwrap (peer) | %.0f | | | |\n", libpcap_packets / libpcap_read_s);
#else
  std::printf("| libpcap peer | not built (no libpcap-dev at configure time) | | | |\n");
#endif
  std::printf("| pcap: source (reader + decoder), glibc default thresholds | %.0f | %.1f | %.3g | %.1f |\n", packets / decode_default_s,
              sweeps / decode_default_s, points / decode_default_s, sweeps / decode_default_s / spec.rate_hz);
  std::printf("| pcap: source, ave-agent's thresholds (KeepSweepBuffersInProcess) | %.0f | %.1f | %.3g | %.1f |\n", packets / decode_s,
              sweeps_per_s, points / decode_s, sweeps_per_s / spec.rate_hz);
  std::printf("long replay: %d loops, %lld sweeps in %.1f s (%.1f sweeps/s); RSS %.1f MiB after loop 1, %.1f MiB half way, %.1f MiB at the end\n",
              o.loops, static_cast<long long>(replay_sweeps), replay_s, replay_sweeps / replay_s, rss_start, rss_mid, rss_end);
  std::printf("{\"sweeps_per_s_default_malloc\":%.2f,\"sweeps_per_s\":%.2f,\"points_per_s\":%.0f,\"realtime_factor\":%.2f,\"reader_packets_per_s\":%.0f,"
              "\"libpcap_packets_per_s\":%.0f,\"rss_start_mib\":%.1f,\"rss_end_mib\":%.1f,\"points_per_sweep\":%.0f}\n",
              sweeps / decode_default_s, sweeps_per_s, points / decode_s, sweeps_per_s / spec.rate_hz, packets / ours_read_s,
              libpcap_read_s > 0 ? libpcap_packets / libpcap_read_s : 0.0, rss_start, rss_end,
              sweeps > 0 ? static_cast<double>(points) / sweeps : 0.0);
  return 0;
}

}  // namespace

Runner AddLidarDecodeBench(CLI::App& sub) {
  auto o = std::make_shared<LidarDecodeBenchOptions>();
  sub.add_option("--scenario", o->scenario, "scenario with a rotating LiDAR")->capture_default_str();
  sub.add_option("--lidar", o->lidar, "rotating LiDAR id (default: the scenario's first)");
  sub.add_option("--azimuth-steps", o->azimuth_steps, "firings per revolution")->capture_default_str()->check(CLI::Range(16, 36000));
  sub.add_option("--seconds", o->seconds, "capture length (s)")->capture_default_str()->check(CLI::Range(0.1, 60.0));
  sub.add_option("--repeats", o->repeats, "timed passes, best kept")->capture_default_str()->check(CLI::Range(1, 50));
  sub.add_option("--loops", o->loops, "long replay: times the capture is looped")->capture_default_str()->check(CLI::Range(1, 100000));
  sub.add_option("--dir", o->dir, "keep the capture in DIR (default: a temp dir, removed)");
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
