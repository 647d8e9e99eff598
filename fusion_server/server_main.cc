// ave-server: the fusion server. Thin main over fusion_server/service.
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <iostream>
#include <map>
#include <optional>
#include <thread>


#include "fusion_server/service/server.h"
#include "model_store/common/cli.h"
#include "model_store/common/log.h"

namespace {

std::string EnvOr(const char* name, std::string fallback) {
  const char* v = std::getenv(name);
  return v ? std::string(v) : fallback;
}

}  // namespace

int main(int argc, char** argv) {
  ave::ServerOptions options;
  options.sensor_token = EnvOr("AVE_SENSOR_TOKEN", "");
  options.viewer_token = EnvOr("AVE_VIEWER_TOKEN", "");
  options.admin_token = EnvOr("AVE_ADMIN_TOKEN", "");
  options.tls.cert_file = EnvOr("AVE_TLS_CERT", "");
  options.tls.key_file = EnvOr("AVE_TLS_KEY", "");
  double max_frame_mb = 8;
  std::string log_level = "info";

  CLI::App app{"ave-server: AVE fusion server (sensor ingest, camera registry, scene state for viewers)"};
  app.add_option("--listen", options.listen_address, "host:port to listen on (port 0 = any free port)")
      ->capture_default_str();
  app.add_option("--store", options.store_path, "SQLite model store file (created if missing)")->capture_default_str();
  app.add_option("--sensor-token", options.sensor_token, "bearer token sensors present (env AVE_SENSOR_TOKEN)");
  app.add_option("--viewer-token", options.viewer_token, "bearer token viewers present (env AVE_VIEWER_TOKEN)");
  app.add_option("--admin-token", options.admin_token, "bearer token administrators present (env AVE_ADMIN_TOKEN)");
  app.add_option("--tls-cert", options.tls.cert_file, "PEM server certificate: serve TLS (env AVE_TLS_CERT)");
  app.add_option("--tls-key", options.tls.key_file, "PEM server private key (env AVE_TLS_KEY)");
  app.add_option("--tls-client-ca", options.tls.client_ca_file,
                 "PEM CA for client certificates: enables mutual TLS for clients that present one");
  app.add_flag("--insecure-plaintext", options.tls.insecure_plaintext,
               "serve plaintext on a non-loopback --listen address (tokens cross the network in clear; "
               "warned about every minute)");
  app.add_flag("--require-client-cert", options.tls.require_client_cert,
               "refuse TLS handshakes without a client certificate (every client)");
  app.add_flag("--sensor-client-cert", options.sensor_requires_client_cert,
               "sensors must present a verified client certificate (mutual TLS for sensor nodes)");
  app.add_option("--metrics-listen", options.metrics_listen,
                 "host:port for Prometheus text metrics over HTTP (GET /metrics); empty = off");
  double auth_window_s = options.auth_limit.window_ns / 1e9;
  app.add_option("--auth-max-failures", options.auth_limit.max_failures,
                 "failed authentications a peer address may make per window before its calls are refused (0 = no limit)")
      ->capture_default_str()->check(CLI::Range(0, 1000000));
  app.add_option("--auth-window", auth_window_s, "that window, seconds")->capture_default_str()->check(CLI::Range(1.0, 86400.0));
  app.add_option("--max-ingest-fps", options.flow.max_ingest_fps,
                 "server-wide frame budget: sensors are asked to share it (0 = unlimited)")->capture_default_str();
  app.add_option("--max-ingest-mbps", options.flow.max_ingest_mbps,
                 "server-wide JPEG byte budget, MB/s: above it sensors are asked for a lower quality (0 = unlimited)")
      ->capture_default_str();
  app.add_option("--max-frame-mb", max_frame_mb, "largest JPEG accepted, MiB")->capture_default_str()->check(CLI::Range(0.01, 15.0));
  app.add_option("--max-fps-hint", options.max_fps_hint, "frame rate asked of sensors (0 = any)")->capture_default_str();
  app.add_option("--campus-grid", options.campus_grid_m, "terrain grid (m) when seeding the built-in campus")
      ->capture_default_str();
  app.add_flag("!--no-seed-campus", options.seed_campus, "do not store the built-in campus in an empty store");
  std::string retention = "0", record_max = "0";
  app.add_option("--record-dir", options.record_dir,
                 "record every accepted frame (JPEG segments here, index in --store) for replay; empty = off");
  app.add_option("--retention", retention, "delete recordings older than this: 90s, 30m, 12h, 7d (0 = keep)")
      ->capture_default_str();
  app.add_option("--record-max-bytes", record_max,
                 "recording budget: oldest segments are deleted beyond it, recording stops when it cannot be kept "
                 "(bytes, or with K/M/G/T; 0 = the disk)")->capture_default_str();
  int record_sync_ms = 500;
  app.add_option("--record-sync-ms", record_sync_ms,
                 "recorder: write, sync and index every this many ms; a crash may lose the frames of the last "
                 "period plus one flush (acknowledged frames never)")
      ->capture_default_str()->check(CLI::Range(10, 60000));
  std::string record_sync = "syncfs";
  app.add_option("--record-sync", record_sync,
                 "recorder: syncfs (one sync of the recording's filesystem per period) or fdatasync (one per "
                 "segment; bounds the flush time on a disk shared with heavy writers)")
      ->capture_default_str()->check(CLI::IsMember({"syncfs", "fdatasync"}));
  bool record_direct_io = true;
  app.add_flag("--record-direct-io,!--record-buffered-io", record_direct_io,
               "recorder: write segment batches with O_DIRECT from an aligned buffer (the default: no page cache "
               "copy or writeback of the JPEGs; replay reads recent frames from the disk); --record-buffered-io "
               "writes through the page cache instead");
  app.add_option("--log-level", log_level, "debug, info, warning or error")->check(CLI::IsMember({"debug", "info", "warning", "error"}));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-server")) return *exit_code;
  ave::log::MinLevel() = log_level == "debug" ? ave::log::Level::kDEBUG
                         : log_level == "warning" ? ave::log::Level::kWARNING
                         : log_level == "error"   ? ave::log::Level::kERROR
                                                  : ave::log::Level::kINFO;
  options.frame_limits.max_jpeg_bytes = static_cast<size_t>(max_frame_mb * (1 << 20));
  options.auth_limit.window_ns = static_cast<int64_t>(auth_window_s * 1e9);
  // "<number><unit>" with the unit's multiplier, or nullopt.
  auto scaled = [](const std::string& text, const std::map<char, double>& units) -> std::optional<double> {
    if (text.empty()) return std::nullopt;
    double scale = 1;
    std::string number = text;
    if (auto it = units.find(static_cast<char>(std::tolower(text.back()))); it != units.end()) {
      scale = it->second;
      number.pop_back();
    }
    char* end = nullptr;
    const double value = std::strtod(number.c_str(), &end);
    if (number.empty() || end != number.c_str() + number.size() || !std::isfinite(value) || value < 0) return std::nullopt;
    return value * scale;
  };
  const std::optional<double> retention_s = scaled(retention, {{'s', 1}, {'m', 60}, {'h', 3600}, {'d', 86400}});
  if (!retention_s) {
    std::cerr << "ave-server: --retention '" << retention << "': expected a duration such as 90s, 30m, 12h or 7d\n";
    return 1;
  }
  options.record_retention = std::chrono::seconds(static_cast<int64_t>(*retention_s));
  const std::optional<double> max_bytes =
      scaled(record_max, {{'k', 1024.0}, {'m', 1048576.0}, {'g', 1073741824.0}, {'t', 1099511627776.0}});
  if (!max_bytes) {
    std::cerr << "ave-server: --record-max-bytes '" << record_max << "': expected bytes such as 500000000 or 20G\n";
    return 1;
  }
  options.record_max_bytes = static_cast<int64_t>(*max_bytes);
  options.record_sync_period = std::chrono::milliseconds(record_sync_ms);
  options.record_sync_per_file = record_sync == "fdatasync";
  options.record_direct_io = record_direct_io;

  // Signals are taken by a waiting thread, so shutdown runs outside any signal handler.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = ave::FusionServer::Start(options);
  if (!server.ok()) {
    std::cerr << "ave-server: " << server.status().message() << "\n";
    return 1;
  }
  std::cout << "listening on port " << (*server)->port() << std::endl;
  if ((*server)->metrics_port() != 0) std::cout << "metrics on port " << (*server)->metrics_port() << std::endl;
  std::thread waiter([&] {
    int sig = 0;
    sigwait(&signals, &sig);
    AVE_LOG(INFO) << "signal " << sig << ": draining streams and shutting down";
    (*server)->Shutdown(std::chrono::milliseconds(2000));
  });
  (*server)->Wait();
  waiter.join();
  return 0;
}
