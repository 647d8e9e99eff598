#include <cmath>

#include "absl/strings/str_cat.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/core/validation.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"

namespace ave::internal {

grpc::Status ToGrpc(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

FlowDecision ServerShared::Flow() {
  FlowOptions flow = options.flow;
  flow.max_fps = options.max_fps_hint;
  flow.jpeg_quality = options.jpeg_quality_hint;
  FlowInputs in;
  in.active_streams = static_cast<int>(metrics.sensors_connected.load());
  in.ingest_fps = ingest.EventsPerSecond();
  in.ingest_mbps = ingest.BytesPerSecond() / 1e6;
  const double sent = viewer_sent.BytesPerSecond(), skipped = viewer_skipped.BytesPerSecond();
  in.viewer_drop_ratio = sent + skipped > 0 ? skipped / (sent + skipped) : 0;
  const FlowDecision d = DecideFlow(flow, in);
  metrics.saturated = d.saturated ? 1 : 0;
  return d;
}

int64_t ServerShared::AuthNowNs() const {
  if (options.auth_clock_ns) return options.auth_clock_ns();
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

namespace {

std::string JsonString(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\u00";
      out += kHex[(c >> 4) & 15];
      out += kHex[c & 15];
    } else {
      out += c;
    }
  }
  return out + "\"";
}

// Feeds a failed authentication to the limiter and audits the first of the peer's window and the
// one that reaches the limit: at most two rows per peer per window, however hard it tries.
void NoteAuthenticationFailure(ServerShared& shared, const std::string& peer, const std::string& call,
                               const std::string& reason, int64_t now_ns) {
  const AuthFailureLimiter::Failure f = shared.auth_limiter.RecordFailure(peer, now_ns);
  shared.metrics.auth_tracked_peers = static_cast<int64_t>(shared.auth_limiter.tracked_peers());
  const AuthLimiterOptions& limit = shared.auth_limiter.options();
  const auto audit = [&](const std::string& action, const std::string& after) {
    if (auto s = shared.store.AppendAudit("unauthenticated@" + peer, action, call, "{}", after); !s.ok()) {
      AVE_LOG(ERROR) << "audit write failed: " << s.status().message();
    }
  };
  if (f.opened_window) {
    std::string after = absl::StrCat("{\"reason\":", JsonString(reason));
    if (f.previous_failures > 0) {
      absl::StrAppend(&after, ",\"previous_window\":{\"failures\":", f.previous_failures,
                      ",\"rate_limited\":", f.previous_refusals, "}");
    }
    audit("AuthRefused", after + "}");
  }
  if (f.now_limited) {
    audit("AuthRateLimited", absl::StrCat("{\"failures\":", f.failures_in_window, ",\"window_s\":",
                                          limit.window_ns / 1e9, ",\"reason\":", JsonString(reason), "}"));
    AVE_LOG(WARNING) << peer << ": " << f.failures_in_window << " failed authentications within "
                     << limit.window_ns / 1e9 << " s: its calls are refused until the window ends";
  }
}

}  // namespace

grpc::Status AuthorizeCall(ServerShared& shared, const grpc::ServerContext& context, Action action,
                           const std::string& camera_id, const std::string& token, Principal* principal) {
  const std::string call = absl::StrCat(ActionName(action), camera_id.empty() ? "" : " as camera '" + camera_id + "'");
  const std::string peer = PeerHost(context.peer());
  const int64_t now_ns = shared.AuthNowNs();
  // Issue 14: a peer over its failure budget is refused before its token is even read, so that
  // a right guess made while limited is not told apart from a wrong one.
  if (const AuthFailureLimiter::Admission a = shared.auth_limiter.Admit(peer, now_ns); !a.allowed) {
    ++shared.metrics.auth_rate_limited;
    const int64_t retry_s = static_cast<int64_t>(std::ceil(a.retry_after_ns / 1e9));
    if (a.first_refusal) AVE_LOG(WARNING) << peer << ": refused to " << call << ": rate limited for " << retry_s << " s";
    return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                        absl::StrCat("too many failed authentications from ", peer, " (", a.failures_in_window,
                                     " within ", shared.auth_limiter.options().window_ns / 1e9, " s): retry in ",
                                     retry_s, " s"));
  }
  const auto refuse = [&](grpc::Status status) {
    ++shared.metrics.auth_failures;
    AVE_LOG(WARNING) << context.peer() << ": refused to " << call << ": " << status.error_message();
    return status;
  };
  // A failure to prove who the caller is (no token, malformed, unknown or revoked): counted
  // against the peer. Refusals of a known token outside its role's rights are not guesses.
  const auto refuse_unauthenticated = [&](const std::string& message) {
    NoteAuthenticationFailure(shared, peer, call, message, now_ns);
    return refuse(grpc::Status(grpc::StatusCode::UNAUTHENTICATED, message));
  };
  std::string presented = token;
  if (presented.empty()) {
    const auto& md = context.client_metadata();
    auto it = md.find("authorization");
    if (it == md.end()) {
      return refuse_unauthenticated(absl::StrCat("missing 'authorization: Bearer <token>' metadata to ", ActionName(action)));
    }
    const std::string value(it->second.data(), it->second.size());
    constexpr std::string_view kBearer = "Bearer ";
    if (value.rfind(kBearer, 0) != 0) return refuse_unauthenticated("authorization metadata must be 'Bearer <token>'");
    presented = value.substr(kBearer.size());
  }
  absl::StatusOr<Principal> who = shared.tokens.Authenticate(presented);
  if (!who.ok()) {
    const std::string where = camera_id.empty() ? "" : absl::StrCat("camera '", camera_id, "': ");
    return refuse_unauthenticated(
        absl::StrCat(where, std::string(who.status().message()), " (to ", ActionName(action), ")"));
  }
  if (absl::Status s = Authorize(*who, action, camera_id); !s.ok()) return refuse(ToGrpc(s));
  if (action == Action::kStream && shared.options.sensor_requires_client_cert) {
    const auto auth = context.auth_context();
    if (!auth || !auth->IsPeerAuthenticated()) {
      return refuse(grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                                 absl::StrCat("camera '", camera_id,
                                              "': this server requires sensors to present a TLS client certificate")));
    }
  }
  if (principal) *principal = *who;
  return grpc::Status::OK;
}

grpc::Status SensorServiceImpl::Stream(grpc::ServerContext* context,
                                       grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream) {
  const int64_t stream_start_ns = NowNs();  // acks report what this stream got recorded
  const std::string peer = context->peer();
  v1::SensorMessage message;
  if (!stream->Read(&message)) {
    return grpc::Status(grpc::StatusCode::CANCELLED, "stream closed before the hello");
  }
  if (!message.has_hello()) {
    AVE_LOG(WARNING) << "sensor " << peer << ": first message is not a hello";
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "the first message must be a hello");
  }
  const v1::SensorHello hello = message.hello();
  const std::string& id = hello.camera_id();
  if (absl::Status s = ValidateHello(hello); !s.ok()) {
    AVE_LOG(WARNING) << "sensor " << peer << ": refused hello: " << s.message();
    return ToGrpc(s);
  }
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kStream, id, hello.token()); !s.ok()) return s;
  const std::optional<CameraEntry> camera = state_.FindCamera(id);
  if (!camera) {
    AVE_LOG(WARNING) << "camera '" << id << "' (" << peer << "): unknown camera id";
    return grpc::Status(grpc::StatusCode::NOT_FOUND,
                        absl::StrCat("camera '", id, "' is not registered (add it with ave-admin add-camera)"));
  }
  if (!camera->enabled) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, absl::StrCat("camera '", id, "' is disabled"));
  }
  const bool lidar_hello = hello.kind() == v1::SENSOR_KIND_ROTATING_LIDAR;
  if (lidar_hello != (camera->kind == SensorKind::kRotatingLidar)) {
    AVE_LOG(WARNING) << "sensor '" << id << "' (" << peer << "): hello kind does not match the registry";
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                        absl::StrCat("sensor '", id, "' is registered as a ",
                                     lidar_hello ? "camera" : "rotating LiDAR", " but its hello says ",
                                     lidar_hello ? "rotating LiDAR" : "camera"));
  }
  if (lidar_hello) {
    AVE_LOG(INFO) << "lidar '" << id << "' connected from " << peer << " (" << hello.software_version() << ")";
    return StreamLidar(id, stream);
  }
  AVE_LOG(INFO) << "camera '" << id << "' connected from " << peer << " (" << hello.software_version() << ", "
                << hello.intrinsics().width() << "x" << hello.intrinsics().height() << ")";
  const uint64_t session = state_.StreamOpened(id, FromProto(hello.intrinsics()));
  ServerMetrics& metrics = shared_.metrics;
  ++metrics.sensors_connected;

  uint64_t last_sequence = 0;
  uint64_t accepted = 0, metadata = 0;
  grpc::Status result = grpc::Status::OK;
  FlowDecision flow = shared_.Flow();
  auto next_flow = std::chrono::steady_clock::now();
  while (stream->Read(&message)) {
    if (!message.has_frame()) {
      result = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            absl::StrCat("camera '", id, "': ", message.has_hello() ? "a second hello" : "not a frame"));
      break;
    }
    if (absl::Status s = ValidateFrame(message.frame(), hello.intrinsics(), last_sequence, options_.frame_limits);
        !s.ok()) {
      ++metrics.frames_rejected;
      AVE_LOG(WARNING) << "camera '" << id << "': refused " << s.message();
      result = ToGrpc(absl::Status(s.code(), absl::StrCat("camera '", id, "': ", s.message())));
      break;
    }
    const int64_t received_ns = NowNs();
    last_sequence = message.frame().sequence();
    const int64_t capture_ns = message.frame().capture_time_ns();
    const bool metadata_only = message.frame().metadata_only();
    const size_t jpeg_bytes = message.frame().jpeg().size();
    if (!metadata_only && jpeg_bytes > 0) {
      metrics.capture_to_ingest_s.Observe((received_ns - capture_ns - message.frame().clock_offset_ns()) * 1e-9);
    }
    auto frame = std::make_shared<v1::SensorFrame>(std::move(*message.mutable_frame()));
    if (absl::Status s = state_.AcceptFrame(id, std::move(frame), received_ns, session); !s.ok()) {
      AVE_LOG(WARNING) << "camera '" << id << "': " << s.message() << " (removed while streaming)";
      result = ToGrpc(s);
      break;
    }
    if (metadata_only) {
      ++metadata;
      ++metrics.metadata_frames_in;
    } else {
      ++accepted;
      ++metrics.frames_in;
      metrics.bytes_in += jpeg_bytes;
      shared_.ingest.Add(jpeg_bytes);
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_flow) {  // the hint changes slowly: recompute a few times a second
      flow = shared_.Flow();
      next_flow = now + std::chrono::milliseconds(250);
    }
    v1::SensorAck ack;
    ack.set_sequence(last_sequence);
    ack.set_server_time_ns(NowNs());
    ack.set_capture_time_ns(capture_ns);
    if (shared_.recorder) ack.set_recorded_sequence(shared_.recorder->RecordedSequence(id, stream_start_ns));
    ack.mutable_hint()->set_max_fps(flow.max_fps);
    ack.mutable_hint()->set_jpeg_quality(flow.jpeg_quality);
    ack.mutable_hint()->set_saturated(flow.saturated);
    if (!stream->Write(ack)) break;
    if (state_.shut_down()) {
      // Graceful shutdown: everything read so far was accepted and acked; the agent reconnects.
      result = grpc::Status(grpc::StatusCode::UNAVAILABLE, "server shutting down; reconnect later");
      break;
    }
  }
  --metrics.sensors_connected;
  state_.StreamClosed(id);
  AVE_LOG(INFO) << "camera '" << id << "' disconnected after " << accepted << " frames"
                << (metadata ? absl::StrCat(" and ", metadata, " replayed metadata records") : "")
                << (result.ok() ? "" : " (" + result.error_message() + ")");
  return result;
}

grpc::Status SensorServiceImpl::StreamLidar(const std::string& id,
                                            grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream) {
  const int64_t stream_start_ns = NowNs();  // acks report what this stream got recorded
  const uint64_t session = state_.StreamOpened(id);
  ServerMetrics& metrics = shared_.metrics;
  ++metrics.sensors_connected;
  uint64_t last_sequence = 0, accepted = 0;
  grpc::Status result = grpc::Status::OK;
  v1::SensorMessage message;
  while (stream->Read(&message)) {
    if (!message.has_lidar_sweep()) {
      result = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            absl::StrCat("lidar '", id, "': ", message.has_hello() ? "a second hello" : "not a lidar_sweep"));
      break;
    }
    if (absl::Status s = ValidateLidarSweep(message.lidar_sweep(), last_sequence, options_.frame_limits); !s.ok()) {
      ++metrics.frames_rejected;
      AVE_LOG(WARNING) << "lidar '" << id << "': refused " << s.message();
      result = ToGrpc(absl::Status(s.code(), absl::StrCat("lidar '", id, "': ", s.message())));
      break;
    }
    const int64_t received_ns = NowNs();
    last_sequence = message.lidar_sweep().sequence();
    const int64_t capture_ns = message.lidar_sweep().capture_time_ns();
    const size_t bytes = message.lidar_sweep().foreground().packed().size();
    auto sweep = std::make_shared<v1::LidarSweepFrame>(std::move(*message.mutable_lidar_sweep()));
    if (absl::Status s = state_.AcceptLidarSweep(id, std::move(sweep), received_ns, session); !s.ok()) {
      AVE_LOG(WARNING) << "lidar '" << id << "': " << s.message() << " (removed while streaming)";
      result = ToGrpc(s);
      break;
    }
    ++accepted;
    ++metrics.lidar_sweeps_in;
    metrics.bytes_in += bytes;
    // No flow hint: a LiDAR's sweep rate is its spin rate, and its sweeps are small.
    v1::SensorAck ack;
    ack.set_sequence(last_sequence);
    ack.set_server_time_ns(NowNs());
    ack.set_capture_time_ns(capture_ns);
    if (shared_.recorder) ack.set_recorded_sequence(shared_.recorder->RecordedSequence(id, stream_start_ns));
    if (!stream->Write(ack)) break;
    if (state_.shut_down()) {
      result = grpc::Status(grpc::StatusCode::UNAVAILABLE, "server shutting down; reconnect later");
      break;
    }
  }
  --metrics.sensors_connected;
  state_.StreamClosed(id);
  AVE_LOG(INFO) << "lidar '" << id << "' disconnected after " << accepted << " sweeps"
                << (result.ok() ? "" : " (" + result.error_message() + ")");
  return result;
}

}  // namespace ave::internal
