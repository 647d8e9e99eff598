#pragma once
// Private to fusion_server/service: the gRPC service classes. They validate, translate absl::Status
// into grpc::Status and hand over to SceneState / Store; nothing else.
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/service/server.h"
#include "model_store/db/store.h"

namespace ave::internal {

grpc::Status ToGrpc(const absl::Status& status);
// Checks "authorization: Bearer <token>" metadata against `expected` (empty = role disabled).
grpc::Status CheckBearer(const grpc::ServerContext& context, const std::string& expected, const char* role);

class SensorServiceImpl final : public v1::SensorService::Service {
 public:
  SensorServiceImpl(const ServerOptions& options, SceneState& state) : options_(options), state_(state) {}
  grpc::Status Stream(grpc::ServerContext* context,
                      grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream) override;

 private:
  const ServerOptions& options_;
  SceneState& state_;
};

class SceneServiceImpl final : public v1::SceneService::Service {
 public:
  SceneServiceImpl(const ServerOptions& options, SceneState& state, std::vector<v1::StaticModelChunk> chunks)
      : options_(options), state_(state), chunks_(std::move(chunks)) {}
  grpc::Status Subscribe(grpc::ServerContext* context, const v1::SubscribeRequest* request,
                         grpc::ServerWriter<v1::SceneUpdate>* writer) override;
  grpc::Status GetStaticModel(grpc::ServerContext* context, const v1::StaticModelRequest* request,
                              grpc::ServerWriter<v1::StaticModelChunk>* writer) override;

 private:
  const ServerOptions& options_;
  SceneState& state_;
  const std::vector<v1::StaticModelChunk> chunks_;
};

class AdminServiceImpl final : public v1::AdminService::Service {
 public:
  AdminServiceImpl(const ServerOptions& options, SceneState& state, store::Store& store)
      : options_(options), state_(state), store_(store) {}
  grpc::Status AddCamera(grpc::ServerContext* context, const v1::AddCameraRequest* request,
                         v1::Camera* response) override;
  grpc::Status UpdateCamera(grpc::ServerContext* context, const v1::UpdateCameraRequest* request,
                            v1::Camera* response) override;
  grpc::Status RemoveCamera(grpc::ServerContext* context, const v1::RemoveCameraRequest* request,
                            v1::RemoveCameraResponse* response) override;
  grpc::Status ListCameras(grpc::ServerContext* context, const v1::ListCamerasRequest* request,
                           v1::ListCamerasResponse* response) override;

 private:
  grpc::Status Upsert(grpc::ServerContext* context, const v1::Camera& camera, bool add, v1::Camera* response);

  const ServerOptions& options_;
  SceneState& state_;
  store::Store& store_;
};

// Splits a mesh into chunks of at most `max_vertices` vertices with chunk-local indices.
std::vector<v1::StaticModelChunk> ChunkMesh(const TriangleMesh& mesh, uint64_t version, const std::string& name,
                                            size_t max_vertices = 60000);

// Store record <-> wire / scene state.
v1::Camera ToProto(const store::CameraRecord& record);
CameraEntry ToEntry(const store::CameraRecord& record);

}  // namespace ave::internal
