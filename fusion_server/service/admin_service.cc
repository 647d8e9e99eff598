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
  if (r.kind == store::kSensorKindRotatingLidar) {
    c.clear_intrinsics();
    c.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
  }
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
  e.kind = r.kind == store::kSensorKindRotatingLidar ? SensorKind::kRotatingLidar : SensorKind::kCamera;
  return e;
}

void AdminServiceImpl::Audit(const Principal& who, const grpc::ServerContext& context, const std::string& action,
                             const std::string& target, const std::string& before, const std::string& after) {
  // Who: the token's id (a hash prefix, never the token) and the peer address.
  const std::string actor = absl::StrCat(RoleName(who.role), ":", who.token_id, who.bootstrap ? " (bootstrap)" : "",
                                         "@", context.peer());
  if (auto s = store_.AppendAudit(actor, action, target, before, after); !s.ok()) {
    AVE_LOG(ERROR) << "audit write failed: " << s.status().message();
  }
  AVE_LOG(INFO) << action << " '" << target << "' by " << actor;
}

grpc::Status AdminServiceImpl::Upsert(grpc::ServerContext* context, const v1::Camera& camera, bool add,
                                      v1::Camera* response) {
  Principal principal;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageCameras, {}, {}, &principal); !s.ok()) return s;
  const std::string who = absl::StrCat("camera '", camera.id(), "': ");
  if (!IsValidCameraId(camera.id())) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera.id must be 1..64 characters of [A-Za-z0-9_.-]");
  }
  if (!v1::SensorKind_IsValid(camera.kind())) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        absl::StrCat(who, "camera.kind ", camera.kind(), " is not a known sensor kind"));
  }
  const bool lidar = camera.kind() == v1::SENSOR_KIND_ROTATING_LIDAR;
  if (lidar && camera.has_intrinsics()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + "camera.intrinsics must be absent for a rotating LiDAR");
  }
  if (!lidar && camera.intrinsics().distortion_size() != 0 && camera.intrinsics().distortion_size() != 5) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + "camera.intrinsics.distortion must have 0 or 5 values");
  }
  if (const std::string why = FromProto(camera.intrinsics()).Check(); !lidar && !why.empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + "camera.intrinsics." + why);
  }
  if (absl::Status s = ValidatePose(camera.mounting_pose(), "camera.mounting_pose"); !s.ok()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, who + std::string(s.message()));
  }
  store::CameraRecord record;
  record.id = camera.id();
  record.name = camera.name();
  record.intrinsics = lidar ? PinholeIntrinsics{} : FromProto(camera.intrinsics());
  record.kind = lidar ? store::kSensorKindRotatingLidar : store::kSensorKindCamera;
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
  Audit(principal, *context, add ? "AddCamera" : "UpdateCamera", record.id, before, ToJson(*response));
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
  Principal who;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageCameras, {}, {}, &who); !s.ok()) return s;
  if (!IsValidCameraId(request->id())) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "id must be 1..64 characters of [A-Za-z0-9_.-]");
  }
  absl::StatusOr<store::CameraRecord> old = store_.GetCamera(request->id());
  if (!old.ok()) return ToGrpc(old.status());
  if (absl::Status s = store_.RemoveCamera(request->id()); !s.ok()) return ToGrpc(s);
  state_.RemoveCamera(request->id());
  Audit(who, *context, "RemoveCamera", request->id(), ToJson(ToProto(*old)), "{}");
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::ListCameras(grpc::ServerContext* context, const v1::ListCamerasRequest*,
                                           v1::ListCamerasResponse* response) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageCameras); !s.ok()) return s;
  absl::StatusOr<std::vector<store::CameraRecord>> cameras = store_.ListCameras();
  if (!cameras.ok()) return ToGrpc(cameras.status());
  for (const auto& c : *cameras) *response->add_cameras() = ToProto(c);
  return grpc::Status::OK;
}

namespace {

v1::TokenInfo ToInfo(const store::TokenRecord& t) {
  v1::TokenInfo info;
  info.set_token_id(t.hash.substr(0, 12));
  info.set_role(t.role);
  info.set_camera_id(t.camera_id);
  info.set_label(t.label);
  info.set_created_at_ns(t.created_at_ns);
  info.set_revoked(t.revoked);
  return info;
}

}  // namespace

grpc::Status AdminServiceImpl::IssueToken(grpc::ServerContext* context, const v1::IssueTokenRequest* request,
                                          v1::IssueTokenResponse* response) {
  Principal who;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageTokens, {}, {}, &who); !s.ok()) return s;
  absl::StatusOr<Role> role = ParseRole(request->role());
  if (!role.ok()) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, std::string(role.status().message()));
  if (*role == Role::kSensor) {
    if (!IsValidCameraId(request->camera_id())) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "camera_id: a sensor token is bound to one camera; give its id ([A-Za-z0-9_.-], 1..64)");
    }
    if (!state_.FindCamera(request->camera_id())) {
      return grpc::Status(grpc::StatusCode::NOT_FOUND,
                          absl::StrCat("camera '", request->camera_id(), "' is not registered (add it first)"));
    }
  } else if (!request->camera_id().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera_id is only for sensor tokens");
  }
  if (request->label().size() > 128) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "label longer than 128 characters");
  }
  absl::StatusOr<std::string> token = NewRandomToken();
  if (!token.ok()) return ToGrpc(token.status());
  store::TokenRecord record{HashToken(*token), request->role(), request->camera_id(), request->label()};
  if (absl::Status s = store_.AddToken(record); !s.ok()) return ToGrpc(s);
  shared_.tokens.Add(record.hash, Principal{*role, request->camera_id()});
  response->set_token(*token);
  *response->mutable_info() = ToInfo(record);
  Audit(who, *context, "IssueToken", response->info().token_id(), "{}", ToJson(response->info()));
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::RevokeToken(grpc::ServerContext* context, const v1::RevokeTokenRequest* request,
                                           v1::RevokeTokenResponse*) {
  Principal who;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageTokens, {}, {}, &who); !s.ok()) return s;
  const std::string& id = request->token_id();
  for (char c : id) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "token_id must be lowercase hex (a hash prefix)");
    }
  }
  if (absl::Status s = store_.RevokeToken(id); !s.ok()) return ToGrpc(s);
  shared_.tokens.Revoke(id);
  Audit(who, *context, "RevokeToken", id, "{}", "{\"revoked\":true}");
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::ListTokens(grpc::ServerContext* context, const v1::ListTokensRequest*,
                                          v1::ListTokensResponse* response) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageTokens); !s.ok()) return s;
  absl::StatusOr<std::vector<store::TokenRecord>> tokens = store_.ListTokens();
  if (!tokens.ok()) return ToGrpc(tokens.status());
  for (const auto& t : *tokens) *response->add_tokens() = ToInfo(t);
  return grpc::Status::OK;
}

}  // namespace ave::internal
