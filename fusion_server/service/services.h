#pragma once
// Private to fusion_server/service: the gRPC service classes. They validate, translate absl::Status
// into grpc::Status and hand over to SceneState / Store; nothing else.
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/auth.h"
#include "fusion_server/core/auth_limiter.h"
#include "fusion_server/core/flow.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/record/recorder.h"
#include "fusion_server/service/metrics.h"
#include "fusion_server/service/server.h"
#include "model_store/db/store.h"

namespace ave::internal {

grpc::Status ToGrpc(const absl::Status& status);

// What the three services share: options, live state, store, tokens, metrics and load meters.
struct ServerShared {
  ServerShared(const ServerOptions& o, SceneState& s, store::Store& st)
      : options(o), state(s), store(st), auth_limiter(o.auth_limit) {}
  const ServerOptions& options;
  SceneState& state;
  store::Store& store;
  TokenRegistry tokens;
  AuthFailureLimiter auth_limiter;  // failed authentications per peer address (issue 14)
  int64_t AuthNowNs() const;        // options.auth_clock_ns, or the steady clock
  ServerMetrics metrics;
  RateWindow ingest;          // accepted JPEG frames (bytes = JPEG size)
  RateWindow viewer_sent;     // bytes field = JPEGs written to viewers
  RateWindow viewer_skipped;  // bytes field = frames skipped for viewers
  FlowDecision Flow();        // the hint for sensors now (also sets metrics.saturated)
  record::Recorder* recorder = nullptr;  // issue 18: set when recording (--record-dir)
};

// Authenticates the call's bearer token ("authorization: Bearer <token>" metadata, or `token`
// when non-empty: the sensor hello's) and authorizes `action`. Unauthenticated / PermissionDenied
// with a message naming the call and, for sensors, the camera. Counts refusals in metrics.
// A peer that failed to authenticate too often is refused first, ResourceExhausted, without its
// token being read; authentication failures feed that limiter and are audited (the first of each
// peer's window, and the one that sets the limit off), see auth_limiter.h.
grpc::Status AuthorizeCall(ServerShared& shared, const grpc::ServerContext& context, Action action,
                           const std::string& camera_id = {}, const std::string& token = {},
                           Principal* principal = nullptr);

class SensorServiceImpl final : public v1::SensorService::Service {
 public:
  explicit SensorServiceImpl(ServerShared& shared) : shared_(shared), options_(shared.options), state_(shared.state) {}
  grpc::Status Stream(grpc::ServerContext* context,
                      grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream) override;

 private:
  // The rest of a rotating LiDAR's stream after its hello (issue 16): sweeps in, acks out.
  grpc::Status StreamLidar(const std::string& id, grpc::ServerReaderWriter<v1::SensorAck, v1::SensorMessage>* stream);
  ServerShared& shared_;
  const ServerOptions& options_;
  SceneState& state_;
};

class SceneServiceImpl final : public v1::SceneService::Service {
 public:
  SceneServiceImpl(ServerShared& shared, std::vector<v1::StaticModelChunk> chunks)
      : shared_(shared), options_(shared.options), state_(shared.state), chunks_(std::move(chunks)),
        floor_z_(ModelFloorZ(chunks_)) {}
  grpc::Status Subscribe(grpc::ServerContext* context, const v1::SubscribeRequest* request,
                         grpc::ServerWriter<v1::SceneUpdate>* writer) override;
  grpc::Status GetStaticModel(grpc::ServerContext* context, const v1::StaticModelRequest* request,
                              grpc::ServerWriter<v1::StaticModelChunk>* writer) override;
  // Issue 18 (replay_service.cc): the recorded scene as it was, paced; audited.
  grpc::Status Replay(grpc::ServerContext* context, const v1::ReplayRequest* request,
                      grpc::ServerWriter<v1::SceneUpdate>* writer) override;
  // Issue 18: each camera's recorded intervals (the viewer's time line); index rows only.
  grpc::Status RecordedSpans(grpc::ServerContext* context, const v1::RecordedSpansRequest* request,
                             v1::RecordedSpansResponse* response) override;
  grpc::Status GetAvatarSequence(grpc::ServerContext* context, const v1::AvatarSequenceRequest* request,
                                 grpc::ServerWriter<v1::AvatarSequenceChunk>* writer) override;  // avatar_service.cc

 private:
  ServerShared& shared_;
  const ServerOptions& options_;
  SceneState& state_;
  const std::vector<v1::StaticModelChunk> chunks_;
  // Data selection (issue 7): the static model's lowest z (local frame), -inf without a model.
  static double ModelFloorZ(const std::vector<v1::StaticModelChunk>& chunks);
  const double floor_z_;
};

class AdminServiceImpl final : public v1::AdminService::Service {
 public:
  explicit AdminServiceImpl(ServerShared& shared)
      : shared_(shared), options_(shared.options), state_(shared.state), store_(shared.store) {}
  grpc::Status AddCamera(grpc::ServerContext* context, const v1::AddCameraRequest* request,
                         v1::Camera* response) override;
  grpc::Status UpdateCamera(grpc::ServerContext* context, const v1::UpdateCameraRequest* request,
                            v1::Camera* response) override;
  grpc::Status RemoveCamera(grpc::ServerContext* context, const v1::RemoveCameraRequest* request,
                            v1::RemoveCameraResponse* response) override;
  grpc::Status ListCameras(grpc::ServerContext* context, const v1::ListCamerasRequest* request,
                           v1::ListCamerasResponse* response) override;
  grpc::Status IssueToken(grpc::ServerContext* context, const v1::IssueTokenRequest* request,
                          v1::IssueTokenResponse* response) override;
  grpc::Status RevokeToken(grpc::ServerContext* context, const v1::RevokeTokenRequest* request,
                           v1::RevokeTokenResponse* response) override;
  grpc::Status ListTokens(grpc::ServerContext* context, const v1::ListTokensRequest* request,
                          v1::ListTokensResponse* response) override;
  // Avatar sequences (issue 17), in avatar_service.cc.
  grpc::Status PutAvatarSequence(grpc::ServerContext* context, grpc::ServerReader<v1::AvatarSequenceChunk>* reader,
                                 v1::AvatarSequenceInfo* response) override;
  grpc::Status ListAvatarSequences(grpc::ServerContext* context, const v1::ListAvatarSequencesRequest* request,
                                   v1::ListAvatarSequencesResponse* response) override;

 private:
  grpc::Status Upsert(grpc::ServerContext* context, const v1::Camera& camera, bool add, v1::Camera* response);
  void Audit(const Principal& who, const grpc::ServerContext& context, const std::string& action,
             const std::string& target, const std::string& before, const std::string& after);

  ServerShared& shared_;
  const ServerOptions& options_;
  SceneState& state_;
  store::Store& store_;
};

// Data selection (issue 7): view frusta as volumes in the server's local frame (the static model's),
// cut at the model's floor, into cursor.views. InvalidArgument naming views[i] and the field.
grpc::Status SelectionViews(const google::protobuf::RepeatedPtrField<v1::ViewFrustum>& views,
                            const std::vector<v1::StaticModelChunk>& chunks, double floor_z, ViewerCursor& cursor);

// Splits a mesh into chunks of at most `max_vertices` vertices with chunk-local indices.
std::vector<v1::StaticModelChunk> ChunkMesh(const TriangleMesh& mesh, uint64_t version, const std::string& name,
                                            size_t max_vertices = 60000);

// Hands the store's avatar sequences to the scene state (at start and after every put).
absl::Status PublishAvatarSequences(store::Store& store, SceneState& state);

// Store record <-> wire / scene state.
v1::Camera ToProto(const store::CameraRecord& record);
CameraEntry ToEntry(const store::CameraRecord& record);

}  // namespace ave::internal
