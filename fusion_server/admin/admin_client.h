#pragma once
// Client side of AdminService, used by ave-admin, the demo and the tests.
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "ave/v1/ave.grpc.pb.h"
#include "model_store/scene/campus.h"

namespace ave {

class AdminClient {
 public:
  AdminClient(std::shared_ptr<grpc::Channel> channel, std::string admin_token);

  absl::StatusOr<v1::Camera> AddCamera(const v1::Camera& camera);
  absl::StatusOr<v1::Camera> UpdateCamera(const v1::Camera& camera);
  absl::Status RemoveCamera(const std::string& id);
  absl::StatusOr<std::vector<v1::Camera>> ListCameras();
  // Tokens (issue 8): the new token is in the response, once; the server keeps only its hash.
  absl::StatusOr<v1::IssueTokenResponse> IssueToken(const std::string& role, const std::string& camera_id,
                                                    const std::string& label = {});
  absl::Status RevokeToken(const std::string& token_id);
  absl::StatusOr<std::vector<v1::TokenInfo>> ListTokens();
  // Avatar sequences (issue 17): `blob` in avatar_blob.h's form, sent in 1 MiB chunks; an empty
  // `name` keeps the blob's own.
  absl::StatusOr<v1::AvatarSequenceInfo> PutAvatarSequence(const std::string& blob, const std::string& name);
  absl::StatusOr<std::vector<v1::AvatarSequenceInfo>> ListAvatarSequences();

 private:
  // One unary call with the bearer token and a 10 s deadline: the response, or the call's status.
  template <typename Request, typename Response>
  absl::StatusOr<Response> Call(grpc::Status (v1::AdminService::StubInterface::*method)(grpc::ClientContext*, const Request&,
                                                                                       Response*),
                                const Request& request);
  std::unique_ptr<v1::AdminService::StubInterface> stub_;
  std::string token_;
};

// The wire record of one of the built-in campus cameras, with source "sim:campus#<id>".
v1::Camera CampusCameraRecord(const scene::CameraSpec& spec);

// The wire record of a fixed rotating LiDAR (issue 16): kind SENSOR_KIND_ROTATING_LIDAR, no
// intrinsics, mounting_pose = world_from_sensor (rotating_lidar.h's sensor frame).
v1::Camera LidarRecord(const std::string& id, const std::string& name, const Rigid3d& world_from_sensor,
                       const std::string& source_url = {});

absl::Status FromGrpc(const grpc::Status& status);

}  // namespace ave
