#include "fusion_server/admin/admin_client.h"

#include <algorithm>

#include "fusion_server/core/convert.h"

namespace ave {

absl::Status FromGrpc(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

AdminClient::AdminClient(std::shared_ptr<grpc::Channel> channel, std::string admin_token)
    : stub_(v1::AdminService::NewStub(std::move(channel))), token_(std::move(admin_token)) {}

template <typename Request, typename Response>
absl::StatusOr<Response> AdminClient::Call(
    grpc::Status (v1::AdminService::StubInterface::*method)(grpc::ClientContext*, const Request&, Response*),
    const Request& request) {
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token_);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  Response response;
  if (absl::Status s = FromGrpc(((*stub_).*method)(&context, request, &response)); !s.ok()) return s;
  return response;
}

absl::StatusOr<v1::Camera> AdminClient::AddCamera(const v1::Camera& camera) {
  v1::AddCameraRequest request;
  *request.mutable_camera() = camera;
  return Call(&v1::AdminService::StubInterface::AddCamera, request);
}

absl::StatusOr<v1::Camera> AdminClient::UpdateCamera(const v1::Camera& camera) {
  v1::UpdateCameraRequest request;
  *request.mutable_camera() = camera;
  return Call(&v1::AdminService::StubInterface::UpdateCamera, request);
}

absl::Status AdminClient::RemoveCamera(const std::string& id) {
  v1::RemoveCameraRequest request;
  request.set_id(id);
  return Call(&v1::AdminService::StubInterface::RemoveCamera, request).status();
}

absl::StatusOr<std::vector<v1::Camera>> AdminClient::ListCameras() {
  absl::StatusOr<v1::ListCamerasResponse> response = Call(&v1::AdminService::StubInterface::ListCameras, v1::ListCamerasRequest());
  if (!response.ok()) return response.status();
  return std::vector<v1::Camera>(response->cameras().begin(), response->cameras().end());
}

absl::StatusOr<v1::IssueTokenResponse> AdminClient::IssueToken(const std::string& role, const std::string& camera_id,
                                                              const std::string& label) {
  v1::IssueTokenRequest request;
  request.set_role(role);
  request.set_camera_id(camera_id);
  request.set_label(label);
  return Call(&v1::AdminService::StubInterface::IssueToken, request);
}

absl::Status AdminClient::RevokeToken(const std::string& token_id) {
  v1::RevokeTokenRequest request;
  request.set_token_id(token_id);
  return Call(&v1::AdminService::StubInterface::RevokeToken, request).status();
}

absl::StatusOr<std::vector<v1::TokenInfo>> AdminClient::ListTokens() {
  absl::StatusOr<v1::ListTokensResponse> response = Call(&v1::AdminService::StubInterface::ListTokens, v1::ListTokensRequest());
  if (!response.ok()) return response.status();
  return std::vector<v1::TokenInfo>(response->tokens().begin(), response->tokens().end());
}

absl::StatusOr<v1::AvatarSequenceInfo> AdminClient::PutAvatarSequence(const std::string& blob, const std::string& name) {
  constexpr size_t kChunk = 1 << 20;
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token_);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  v1::AvatarSequenceInfo response;
  std::unique_ptr<grpc::ClientWriterInterface<v1::AvatarSequenceChunk>> writer =
      stub_->PutAvatarSequence(&context, &response);
  const uint32_t count = static_cast<uint32_t>(std::max<size_t>(1, (blob.size() + kChunk - 1) / kChunk));
  for (uint32_t i = 0; i < count; ++i) {
    v1::AvatarSequenceChunk chunk;
    if (i == 0) chunk.set_name(name);
    chunk.set_chunk_index(i);
    chunk.set_chunk_count(count);
    chunk.set_total_bytes(blob.size());
    chunk.set_data(blob.substr(i * kChunk, kChunk));
    if (!writer->Write(chunk)) break;  // the server ended the call: Finish says why
  }
  writer->WritesDone();
  if (absl::Status s = FromGrpc(writer->Finish()); !s.ok()) return s;
  return response;
}

absl::StatusOr<std::vector<v1::AvatarSequenceInfo>> AdminClient::ListAvatarSequences() {
  absl::StatusOr<v1::ListAvatarSequencesResponse> response =
      Call(&v1::AdminService::StubInterface::ListAvatarSequences, v1::ListAvatarSequencesRequest());
  if (!response.ok()) return response.status();
  return std::vector<v1::AvatarSequenceInfo>(response->sequences().begin(), response->sequences().end());
}

v1::Camera CampusCameraRecord(const scene::CameraSpec& spec) {
  v1::Camera camera;
  camera.set_id(spec.id);
  camera.set_name(spec.name);
  *camera.mutable_intrinsics() = ToProto(spec.intrinsics);
  *camera.mutable_mounting_pose() = ToProto(spec.world_from_camera);
  camera.set_source_url("sim:campus#" + spec.id);
  camera.set_enabled(true);
  return camera;
}

v1::Camera LidarRecord(const std::string& id, const std::string& name, const Rigid3d& world_from_sensor,
                       const std::string& source_url) {
  v1::Camera lidar;
  lidar.set_id(id);
  lidar.set_name(name.empty() ? id : name);
  lidar.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
  *lidar.mutable_mounting_pose() = ToProto(world_from_sensor);
  lidar.set_source_url(source_url);
  lidar.set_enabled(true);
  return lidar;
}

}  // namespace ave
