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

grpc::Status CheckBearer(const grpc::ServerContext& context, const std::string& expected, const char* role) {
  if (expected.empty()) {
    return grpc::Status(grpc::StatusCode::PERMISSION_DENIED, absl::StrCat("the ", role, " role is disabled on this server"));
  }
  const auto& md = context.client_metadata();
  auto it = md.find("authorization");
  if (it == md.end()) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                        absl::StrCat("missing 'authorization: Bearer <token>' metadata for the ", role, " role"));
  }
  const std::string value(it->second.data(), it->second.size());
  if (value != "Bearer " + expected) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, absl::StrCat("bad ", role, " token"));
  }
  return grpc::Status::OK;
}

grpc::Status SensorServiceImpl::Stream(grpc::ServerContext* context,
                                       grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream) {
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
  if (options_.sensor_token.empty() || hello.token() != options_.sensor_token) {
    AVE_LOG(WARNING) << "camera '" << id << "' (" << peer << "): bad sensor token";
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, absl::StrCat("camera '", id, "': bad sensor token"));
  }
  const std::optional<CameraEntry> camera = state_.FindCamera(id);
  if (!camera) {
    AVE_LOG(WARNING) << "camera '" << id << "' (" << peer << "): unknown camera id";
    return grpc::Status(grpc::StatusCode::NOT_FOUND,
                        absl::StrCat("camera '", id, "' is not registered (add it with ave-admin add-camera)"));
  }
  if (!camera->enabled) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, absl::StrCat("camera '", id, "' is disabled"));
  }
  AVE_LOG(INFO) << "camera '" << id << "' connected from " << peer << " (" << hello.software_version() << ", "
                << hello.intrinsics().width() << "x" << hello.intrinsics().height() << ")";
  state_.StreamOpened(id, FromProto(hello.intrinsics()));

  uint64_t last_sequence = 0;
  uint64_t accepted = 0;
  grpc::Status result = grpc::Status::OK;
  while (stream->Read(&message)) {
    if (!message.has_frame()) {
      result = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, absl::StrCat("camera '", id, "': a second hello"));
      break;
    }
    if (absl::Status s = ValidateFrame(message.frame(), hello.intrinsics(), last_sequence, options_.frame_limits);
        !s.ok()) {
      AVE_LOG(WARNING) << "camera '" << id << "': refused " << s.message();
      result = ToGrpc(absl::Status(s.code(), absl::StrCat("camera '", id, "': ", s.message())));
      break;
    }
    last_sequence = message.frame().sequence();
    auto frame = std::make_shared<v1::SensorFrame>(std::move(*message.mutable_frame()));
    if (absl::Status s = state_.AcceptFrame(id, std::move(frame), NowNs()); !s.ok()) {
      AVE_LOG(WARNING) << "camera '" << id << "': " << s.message() << " (removed while streaming)";
      result = ToGrpc(s);
      break;
    }
    ++accepted;
    v1::SensorAck ack;
    ack.set_sequence(last_sequence);
    ack.set_server_time_ns(NowNs());
    ack.mutable_hint()->set_max_fps(options_.max_fps_hint);
    ack.mutable_hint()->set_jpeg_quality(options_.jpeg_quality_hint);
    if (!stream->Write(ack)) break;
  }
  state_.StreamClosed(id);
  AVE_LOG(INFO) << "camera '" << id << "' disconnected after " << accepted << " frames"
                << (result.ok() ? "" : " (" + result.error_message() + ")");
  return result;
}

}  // namespace ave::internal
