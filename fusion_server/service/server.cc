#include "fusion_server/service/server.h"

#include <cmath>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <set>
#include <thread>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include "absl/strings/str_cat.h"
#include "fusion_server/record/replay.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"
#include "model_store/scene/campus.h"

namespace ave {

std::string ServerOptions::Check() const {
  if (listen_address.empty()) return "listen_address is empty";
  if (store_path.empty()) return "store_path is empty";
  if (absl::Status s = net::CheckListenAddressSyntax(listen_address); !s.ok()) return std::string(s.message());
  if (absl::Status s = net::CheckServerTransport(listen_address, tls); !s.ok()) return std::string(s.message());
  if (plaintext_warning_period.count() <= 0) return "plaintext_warning_period must be > 0";
  if (const std::string why = auth_limit.Check(); !why.empty()) return why;
  if (sensor_requires_client_cert && tls.client_ca_file.empty()) {
    return "sensor_requires_client_cert needs tls.client_ca_file (--tls-client-ca)";
  }
  if (!(flow.max_ingest_fps >= 0) || !(flow.max_ingest_mbps >= 0)) return "flow budgets must be >= 0";
  if (frame_limits.max_jpeg_bytes == 0 || frame_limits.max_jpeg_bytes + (1 << 16) > size_t(max_message_bytes)) {
    return "frame_limits.max_jpeg_bytes must be > 0 and leave 64 KiB below max_message_bytes";
  }
  if (!(max_fps_hint >= 0) || !std::isfinite(max_fps_hint)) return "max_fps_hint must be finite and >= 0";
  if (jpeg_quality_hint > 100) return "jpeg_quality_hint must be 0..100";
  if (!(default_viewer_rate_hz > 0) || !(max_viewer_rate_hz > 0)) return "viewer rates must be > 0";
  if (!(campus_grid_m >= 0.25 && campus_grid_m <= 20)) return "campus_grid_m must be in 0.25..20";
  if (!record_dir.empty() && store_path == ":memory:") return "--record-dir needs a store file (--store), not :memory:";
  if (record_retention.count() < 0) return "--retention must be >= 0 s";
  if (record_max_bytes < 0) return "--record-max-bytes must be >= 0";
  if (record_sync_period.count() < 10 || record_sync_period.count() > 60'000) return "--record-sync-ms must be 10..60000";
  return {};
}

namespace {

// Runs `task` every `period` on its own thread until destroyed; the destructor wakes and joins it
// at once, whatever the period.
class PeriodicTask {
 public:
  PeriodicTask(std::chrono::milliseconds period, std::function<void()> task)
      : period_(period), task_(std::move(task)), thread_([this] { Run(); }) {}
  ~PeriodicTask() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  void Run() {
    std::unique_lock lock(mu_);
    while (!cv_.wait_for(lock, period_, [this] { return stop_; })) {
      lock.unlock();
      task_();
      lock.lock();
    }
  }
  const std::chrono::milliseconds period_;
  const std::function<void()> task_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace

struct FusionServer::Impl {
  ServerOptions options;
  std::unique_ptr<store::Store> store;
  SceneState state;
  std::unique_ptr<internal::ServerShared> shared;
  std::unique_ptr<record::Recorder> recorder;  // issue 18; null when not recording
  std::unique_ptr<MetricsHttpServer> metrics_http;
  std::unique_ptr<PeriodicTask> plaintext_warning;  // while serving plaintext off loopback
  uint64_t model_version = 0;
  std::unique_ptr<internal::SensorServiceImpl> sensor;
  std::unique_ptr<internal::SceneServiceImpl> scene;
  std::unique_ptr<internal::AdminServiceImpl> admin;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  bool shut_down = false;

  explicit Impl(const ServerOptions& o) : options(o), state(o.scene) {}
};

namespace {

// Recording (issue 18): the recorder hangs on the state's accepted frames and sweeps; the fused
// objects are sampled by its writer thread; its counters join the Prometheus text.
absl::Status StartRecorder(FusionServer::Impl& impl) {
  record::RecorderOptions ro;
  ro.dir = impl.options.record_dir;
  ro.max_age = impl.options.record_retention;
  ro.max_bytes = impl.options.record_max_bytes;
  ro.flush_period = impl.options.record_sync_period;
  ro.direct_io = impl.options.record_direct_io;
  ro.sync_method = impl.options.record_sync_per_file ? record::RecorderOptions::SyncMethod::kPerFile
                                                     : record::RecorderOptions::SyncMethod::kFilesystem;
  SceneState* state = &impl.state;
  ro.objects_source = [state] {
    ViewerCursor cursor;
    v1::SceneUpdate update = state->BuildUpdate({}, false, record::WallNowNs(), cursor);
    update.clear_cameras();
    update.clear_lidars();
    update.clear_removed_camera_ids();
    return update;
  };
  absl::StatusOr<std::unique_ptr<record::Recorder>> recorder = record::Recorder::Open(impl.options.store_path, ro);
  if (!recorder.ok()) return recorder.status();
  impl.recorder = *std::move(recorder);
  record::Recorder* r = impl.recorder.get();
  impl.shared->recorder = r;
  // Each sensor's registry entry is noted with its first recorded frame of this server's life, so
  // that it replays after being removed from the registry.
  auto noted = std::make_shared<std::pair<std::mutex, std::set<std::string>>>();
  auto note = [r, state, noted](const std::string& id) {
    {
      std::lock_guard lock(noted->first);
      if (!noted->second.insert(id).second) return;
    }
    if (std::optional<CameraEntry> entry = state->FindCamera(id)) r->NoteSensor(id, record::EntryBytes(*entry));
  };
  impl.state.SetObservers(
      [r, note](const std::string& id, const std::shared_ptr<const v1::SensorFrame>& frame, int64_t received_ns,
                int64_t capture_server_ns) {
        note(id);
        r->SubmitFrame(id, frame, received_ns, capture_server_ns);
      },
      [r, note](const std::string& id, const std::shared_ptr<const v1::LidarSweepFrame>& sweep, int64_t received_ns,
                int64_t capture_server_ns) {
        note(id);
        r->SubmitSweep(id, sweep, received_ns, capture_server_ns);
      });
  impl.shared->metrics.render_extra = [r](std::string& out) { r->RenderPrometheus(out); };
  return absl::OkStatus();
}

}  // namespace

FusionServer::FusionServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

FusionServer::~FusionServer() { Shutdown(std::chrono::milliseconds(0)); }

absl::StatusOr<std::unique_ptr<FusionServer>> FusionServer::Start(const ServerOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) {
    return absl::InvalidArgumentError("server options: " + why);
  }
  auto impl = std::make_unique<Impl>(options);
  absl::StatusOr<std::unique_ptr<store::Store>> store = store::Store::Open(options.store_path);
  if (!store.ok()) return store.status();
  impl->store = std::move(*store);

  // Camera registry from the store.
  absl::StatusOr<std::vector<store::CameraRecord>> cameras = impl->store->ListCameras();
  if (!cameras.ok()) return cameras.status();
  for (const auto& c : *cameras) impl->state.UpsertCamera(internal::ToEntry(c));

  // Static model: the newest in the store, or the built-in campus on a fresh store.
  absl::StatusOr<std::optional<store::StaticModelRecord>> model = impl->store->LatestStaticModel();
  if (!model.ok()) return model.status();
  if (!model->has_value() && options.seed_campus) {
    const scene::SyntheticCampus campus = scene::BuiltinCampus();
    absl::StatusOr<int64_t> version =
        impl->store->PutStaticModel(campus.name, scene::BuildStaticMesh(campus, options.campus_grid_m));
    if (!version.ok()) return version.status();
    model = impl->store->LatestStaticModel();
    if (!model.ok()) return model.status();
    AVE_LOG(INFO) << "stored the built-in campus as static model version " << *version;
  }
  std::vector<v1::StaticModelChunk> chunks;
  if (model->has_value()) {
    const store::StaticModelRecord& record = **model;
    impl->model_version = static_cast<uint64_t>(record.version);
    chunks = internal::ChunkMesh(record.mesh, impl->model_version, record.name);
    impl->state.SetStaticModel(record.mesh);  // moving objects are placed on its terrain (issue 6)
    AVE_LOG(INFO) << "static model '" << record.name << "' version " << record.version << ": "
                  << record.mesh.TriangleCount() << " triangles in " << chunks.size() << " chunks";
  } else {
    AVE_LOG(WARNING) << "the store holds no static model; viewers will see cameras only";
  }

  // Avatar sequences (issue 17): people get them from the first update on.
  if (absl::Status s = internal::PublishAvatarSequences(*impl->store, impl->state); !s.ok()) return s;

  impl->shared = std::make_unique<internal::ServerShared>(impl->options, impl->state, *impl->store);
  if (!options.record_dir.empty()) {
    if (absl::Status s = StartRecorder(*impl); !s.ok()) return s;
  }
  // Tokens: bootstrap ones from the options, then the issued ones in the store (hashes only).
  TokenRegistry& tokens = impl->shared->tokens;
  const std::pair<const std::string*, Role> bootstrap[] = {
      {&options.sensor_token, Role::kSensor}, {&options.viewer_token, Role::kViewer}, {&options.admin_token, Role::kAdmin}};
  for (const auto& [token, role] : bootstrap) {
    if (!token->empty()) tokens.Add(HashToken(*token), Principal{role, "", "", true});
  }
  absl::StatusOr<std::vector<store::TokenRecord>> stored = impl->store->ListTokens();
  if (!stored.ok()) return stored.status();
  for (const store::TokenRecord& t : *stored) {
    if (t.revoked) continue;
    absl::StatusOr<Role> role = ParseRole(t.role);
    if (!role.ok()) {
      // A row written by a newer release or edited by hand: nobody may use it, and the operator
      // should know why a token that `ave-admin list-tokens` shows does not let its holder in.
      AVE_LOG(WARNING) << "model store: token " << t.hash.substr(0, 12) << " ('" << t.label << "') has role '"
                       << t.role << "', which this server does not know (sensor, viewer, admin): it is refused";
      continue;
    }
    tokens.Add(t.hash, Principal{*role, t.camera_id});
  }
  if (tokens.size() == 0) {
    return absl::InvalidArgumentError(
        "server options: no token (--sensor-token, --viewer-token, --admin-token, or issued tokens in the store): "
        "nobody could connect");
  }
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials = net::ServerCredentials(options.tls);
  if (!credentials.ok()) return credentials.status();
  if (!options.metrics_listen.empty()) {
    internal::ServerShared* shared = impl->shared.get();
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> http =
        MetricsHttpServer::Start(options.metrics_listen, [shared] { return shared->metrics.RenderPrometheus(); });
    if (!http.ok()) return http.status();
    impl->metrics_http = std::move(*http);
    // The metrics carry aggregate counts only (no token, camera id or peer address), so they may
    // be scraped across the network in plaintext; say so when they are.
    if (!net::IsLoopbackAddress(options.metrics_listen)) {
      AVE_LOG(INFO) << "metrics on " << options.metrics_listen
                    << " are plaintext HTTP without authentication (aggregate counts only)";
    }
  }

  impl->sensor = std::make_unique<internal::SensorServiceImpl>(*impl->shared);
  impl->scene = std::make_unique<internal::SceneServiceImpl>(*impl->shared, std::move(chunks));
  impl->admin = std::make_unique<internal::AdminServiceImpl>(*impl->shared);

  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(options.listen_address, *credentials, &impl->port);
  // Agents ping every ~1.5 s to detect dead links (AgentOptions::keepalive): allow it, or gRPC
  // answers frequent pings with GOAWAY "too_many_pings".
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 500);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 0);
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.SetMaxSendMessageSize(options.max_message_bytes);
  builder.RegisterService(impl->sensor.get());
  builder.RegisterService(impl->scene.get());
  builder.RegisterService(impl->admin.get());
  impl->server = builder.BuildAndStart();
  if (!impl->server || impl->port == 0) {
    return net::ExplainUnusableListenAddress(options.listen_address);
  }
  if (options.tls.cert_file.empty() && !net::IsLoopbackAddress(options.listen_address)) {
    // Allowed by --insecure-plaintext only (Check()); repeated so that nobody forgets it is on.
    ServerMetrics* metrics = &impl->shared->metrics;
    auto warn = [metrics, address = absl::StrCat(options.listen_address, " (port ", impl->port, ")")] {
      ++metrics->insecure_plaintext_warnings;
      AVE_LOG(WARNING) << "serving PLAINTEXT on " << address
                       << " (--insecure-plaintext): bearer tokens and video cross the network in clear; "
                          "serve TLS with --tls-cert/--tls-key";
    };
    metrics->insecure_plaintext = 1;
    warn();
    impl->plaintext_warning = std::make_unique<PeriodicTask>(options.plaintext_warning_period, warn);
  }
  AVE_LOG(INFO) << "ave-server listening on port " << impl->port << (options.tls.cert_file.empty() ? " (plaintext)" : " (TLS)")
                << ", store " << options.store_path << ", " << cameras->size() << " cameras registered, "
                << stored->size() << " issued tokens"
                << (impl->metrics_http ? absl::StrCat(", metrics on port ", impl->metrics_http->port()) : "");
  return std::unique_ptr<FusionServer>(new FusionServer(std::move(impl)));
}

int FusionServer::port() const { return impl_->port; }
int FusionServer::metrics_port() const { return impl_->metrics_http ? impl_->metrics_http->port() : 0; }
std::string FusionServer::RenderMetrics() const { return impl_->shared->metrics.RenderPrometheus(); }
SceneState& FusionServer::state() { return impl_->state; }
void FusionServer::DrainRecorder() {
  if (impl_->recorder) impl_->recorder->Drain();
}
uint64_t FusionServer::static_model_version() const { return impl_->model_version; }

void FusionServer::Shutdown(std::chrono::milliseconds grace) {
  if (impl_->shut_down || !impl_->server) return;
  impl_->shut_down = true;
  if (auto* health = impl_->server->GetHealthCheckService()) health->Shutdown();  // NOT_SERVING from now on
  impl_->state.Shutdown();
  impl_->server->Shutdown(std::chrono::system_clock::now() + grace);
  impl_->metrics_http.reset();
  impl_->plaintext_warning.reset();
  AVE_LOG(INFO) << "ave-server stopped";
}

void FusionServer::Wait() {
  if (impl_->server) impl_->server->Wait();
}

}  // namespace ave
