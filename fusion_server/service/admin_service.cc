#include <google/protobuf/util/json_util.h>

#include "absl/strings/str_cat.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/core/validation.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"

namespace ave::internal {
namespace {

std::string ToJson(const google::protobuf::Message& message) {
  std::string json;
  if (!google::protobuf::util::MessageToJsonString(message, &json).ok()) return "{}";
  return json;
}

}  // namespace

v1::Camera ToProto(const store::CameraRecord& r) {
  v1::Camera c;
  c.set_id(r.id);
  c.set_name(r.name);
  *c.mutable_intrinsics() = ave::ToProto(r.intrinsics);
  *c.mutable_mounting_pose() = ave::ToProto(r.world_from_camera);
  c.set_source_url(r.source_url);
  c.set_enabled(r.enabled);
  return c;
}

CameraEntry ToEntry(const store::CameraRecord& r) {
  CameraEntry e;
  e.id = r.id;
  e.name = r.name;
  e.intrinsics = r.intrinsics;
  e.mounting_pose = r.world_from_camera;
  e.source_url = r.source_url;
  e.enabled = r.enabled;
  return e;
}

grpc::Status AdminServiceImpl::Upsert(grpc::ServerContext* context, const v1::Camera& camera, bool add,
                                      v1::Camera* response) {
  if (grpc::Status s = CheckBearer(*context, options_.admin_token, "admin"); !s.ok()) return s;
  const std::string who = absl::StrCat("camera '", camera.id(), "': ");
  if (!IsValidCameraId(camera.id())) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera.id must be 1..64 characters of [A-Za-z0-9_.-]");
  }
  if (camera.intrinsics().distortion_size() != 0 && camera.intrinsics().distortion_size() != 5) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + "camera.intrinsics.distortion must have 0 or 5 values");
  }
  if (const std::string why = FromProto(camera.intrinsics()).Check(); !why.empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + "camera.intrinsics." + why);
  }
  if (absl::Status s = ValidatePose(camera.mounting_pose(), "camera.mounting_pose"); !s.ok()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + std::string(s.message()));
  }
  store::CameraRecord record;
  record.id = camera.id();
  record.name = camera.name();
  record.intrinsics = FromProto(camera.intrinsics());
  record.world_from_camera = FromProto(camera.mounting_pose());
  record.source_url = camera.source_url();
  record.enabled = camera.enabled();
  if (const std::string why = store::ValidateCamera(record); !why.empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, why);
  }
  std::string before = "{}";
  if (!add) {
    absl::StatusOr<store::CameraRecord> old = store_.GetCamera(record.id);
    if (!old.ok()) return ToGrpc(old.status());
    before = ToJson(ToProto(*old));
  }
  if (absl::Status s = add ? store_.AddCamera(record) : store_.UpdateCamera(record); !s.ok()) return ToGrpc(s);
  state_.UpsertCamera(ToEntry(record));
  *response = ToProto(record);
  const std::string actor = "admin@" + context->peer();
  if (auto s = store_.AppendAudit(actor, add ? "AddCamera" : "UpdateCamera", record.id, before, ToJson(*response));
      !s.ok()) {
    AVE_LOG(ERROR) << "audit write failed: " << s.status().message();
  }
  AVE_LOG(INFO) << (add ? "added" : "updated") << " camera '" << record.id << "' (" << actor << ")";
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::AddCamera(grpc::ServerContext* context, const v1::AddCameraRequest* request,
                                         v1::Camera* response) {
  return Upsert(context, request->camera(), true, response);
}

grpc::Status AdminServiceImpl::UpdateCamera(grpc::ServerContext* context, const v1::UpdateCameraRequest* request,
                                            v1::Camera* response) {
  return Upsert(context, request->camera(), false, response);
}

grpc::Status AdminServiceImpl::RemoveCamera(grpc::ServerContext* context, const v1::RemoveCameraRequest* request,
                                            v1::RemoveCameraResponse*) {
  if (grpc::Status s = CheckBearer(*context, options_.admin_token, "admin"); !s.ok()) return s;
  absl::StatusOr<store::CameraRecord> old = store_.GetCamera(request->id());
  if (!old.ok()) return ToGrpc(old.status());
  if (absl::Status s = store_.RemoveCamera(request->id()); !s.ok()) return ToGrpc(s);
  state_.RemoveCamera(request->id());
  const std::string actor = "admin@" + context->peer();
  if (auto s = store_.AppendAudit(actor, "RemoveCamera", request->id(), ToJson(ToProto(*old)), "{}"); !s.ok()) {
    AVE_LOG(ERROR) << "audit write failed: " << s.status().message();
  }
  AVE_LOG(INFO) << "removed camera '" << request->id() << "' (" << actor << ")";
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::ListCameras(grpc::ServerContext* context, const v1::ListCamerasRequest*,
                                           v1::ListCamerasResponse* response) {
  if (grpc::Status s = CheckBearer(*context, options_.admin_token, "admin"); !s.ok()) return s;
  absl::StatusOr<std::vector<store::CameraRecord>> cameras = store_.ListCameras();
  if (!cameras.ok()) return ToGrpc(cameras.status());
  for (const auto& c : *cameras) *response->add_cameras() = ToProto(c);
  return grpc::Status::OK;
}

}  // namespace ave::internal
