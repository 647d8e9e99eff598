// libFuzzer target: whole gRPC calls into a live FusionServer (issue 8: "protobuf messages into
// the service handlers"). One server is started per process on loopback with a store file of its own;
// each input is one call: which RPC, which credential, then up to eight length-prefixed request
// messages (a sensor stream takes them all, a unary call the first). The service, core and
// validation code is compiled into this target with the sanitizers, so a crash, leak or undefined
// behaviour anywhere from the wire to the scene state is a finding.
//
// The server records (issue 18) into a folder of this process, so Replay and RecordedSpans read
// back what the fuzzed sensor streams wrote; the avatar calls (issue 17) reach the store.
//
// Input layout: byte 0 = RPC (mod 15), byte 1 = credential (mod 5: none, sensor, viewer, admin,
// garbage), then repeated [u16 little-endian length][bytes].
#include <unistd.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <google/protobuf/stubs/logging.h>
#include <grpcpp/grpcpp.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/service/server.h"

namespace {

constexpr char kSensorToken[] = "fuzz-sensor-token-0123456789";
constexpr char kViewerToken[] = "fuzz-viewer-token-0123456789";
constexpr char kAdminToken[] = "fuzz-admin-token-01234567890";

struct Harness {
  std::unique_ptr<ave::FusionServer> server;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<ave::v1::SensorService::Stub> sensor;
  std::unique_ptr<ave::v1::SceneService::Stub> scene;
  std::unique_ptr<ave::v1::AdminService::Stub> admin;
};

Harness& Get() {
  static Harness* harness = [] {
    google::protobuf::SetLogHandler(nullptr);  // malformed UTF-8 strings are expected here
    auto* h = new Harness;
    ave::ServerOptions options;
    options.listen_address = "127.0.0.1:0";
    options.sensor_token = kSensorToken;
    options.viewer_token = kViewerToken;
    options.admin_token = kAdminToken;
    options.seed_campus = true;
    options.campus_grid_m = 16;  // a small static model keeps GetStaticModel quick
    options.auth_limit.max_failures = 0;  // inputs with bad tokens must not lock the harness's own peer out
    // Recording needs a store file (the index lives there): both go in a folder of this process.
    static const std::filesystem::path folder =
        std::filesystem::temp_directory_path() / ("ave_fuzz_grpc_" + std::to_string(::getpid()));
    std::filesystem::remove_all(folder);
    std::filesystem::create_directories(folder);
    std::atexit([] { std::filesystem::remove_all(folder); });
    options.store_path = (folder / "store.sqlite").string();
    options.record_dir = (folder / "record").string();
    options.record_max_bytes = int64_t{64} << 20;  // the budget's retention keeps a long run's disk bounded
    absl::StatusOr<std::unique_ptr<ave::FusionServer>> server = ave::FusionServer::Start(options);
    if (!server.ok()) {
      fprintf(stderr, "fuzz harness: server did not start: %s\n", server.status().ToString().c_str());
      std::abort();
    }
    h->server = std::move(*server);
    h->channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(h->server->port()), grpc::InsecureChannelCredentials());
    h->sensor = ave::v1::SensorService::NewStub(h->channel);
    h->scene = ave::v1::SceneService::NewStub(h->channel);
    h->admin = ave::v1::AdminService::NewStub(h->channel);
    // One registered camera, so sensor streams can get past the registry check.
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdminToken);
    ave::v1::AddCameraRequest add;
    ave::v1::Camera* c = add.mutable_camera();
    c->set_id("fz");
    c->set_name("fuzz camera");
    c->set_enabled(true);
    ave::v1::Intrinsics* k = c->mutable_intrinsics();
    k->set_width(64), k->set_height(48), k->set_fx(50), k->set_fy(50), k->set_cx(32), k->set_cy(24);
    c->mutable_mounting_pose()->mutable_orientation()->set_w(1);
    ave::v1::Camera out;
    grpc::Status status = h->admin->AddCamera(&context, add, &out);
    if (!status.ok()) {
      fprintf(stderr, "fuzz harness: AddCamera failed: %s\n", status.error_message().c_str());
      std::abort();
    }
    return h;
  }();
  return *harness;
}

// Splits the payload into length-prefixed chunks.
std::vector<std::string> Chunks(const uint8_t* data, size_t size) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i + 2 <= size && out.size() < 8) {
    const size_t n = data[i] | (static_cast<size_t>(data[i + 1]) << 8);
    i += 2;
    const size_t take = n < size - i ? n : size - i;
    out.emplace_back(reinterpret_cast<const char*>(data + i), take);
    i += take;
  }
  return out;
}

void Authorize(grpc::ClientContext& context, int credential) {
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  const char* tokens[] = {nullptr, kSensorToken, kViewerToken, kAdminToken};
  if (credential == 0) return;
  if (credential == 4) {
    context.AddMetadata("authorization", "Bearer not-a-token");
    return;
  }
  context.AddMetadata("authorization", std::string("Bearer ") + tokens[credential]);
}

template <typename Request>
bool ParseFirst(const std::vector<std::string>& chunks, Request* request) {
  return !chunks.empty() && request->ParseFromString(chunks[0]);
}

void SensorStream(Harness& h, int credential, const std::vector<std::string>& chunks) {
  grpc::ClientContext context;
  Authorize(context, credential);
  auto stream = h.sensor->Stream(&context);
  for (size_t i = 0; i < chunks.size(); ++i) {
    ave::v1::SensorMessage message;
    if (!message.ParseFromString(chunks[i])) continue;
    // The credential byte decides whether the hello carries the real fleet token, so the fuzzer
    // reaches frame handling instead of stopping at authentication every time.
    if (message.has_hello() && credential == 1) message.mutable_hello()->set_token(kSensorToken);
    if (!stream->Write(message)) break;
  }
  stream->WritesDone();
  ave::v1::SensorAck ack;
  while (stream->Read(&ack)) {
  }
  (void)stream->Finish();
}

template <typename Reader, typename Message>
void Drain(Reader& reader, Message& message, int max_messages) {
  for (int i = 0; i < max_messages && reader->Read(&message); ++i) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  Harness& h = Get();
  const int rpc = data[0] % 15;
  const int credential = data[1] % 5;
  const std::vector<std::string> chunks = Chunks(data + 2, size - 2);
  grpc::ClientContext context;
  Authorize(context, credential);
  switch (rpc) {
    case 0:
      SensorStream(h, credential, chunks);
      break;
    case 1: {
      ave::v1::SubscribeRequest request;
      if (!ParseFirst(chunks, &request)) return 0;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(50));
      auto reader = h.scene->Subscribe(&context, request);
      ave::v1::SceneUpdate update;
      Drain(reader, update, 2);
      context.TryCancel();
      (void)reader->Finish();
      break;
    }
    case 2: {
      ave::v1::StaticModelRequest request;
      if (!ParseFirst(chunks, &request)) return 0;
      auto reader = h.scene->GetStaticModel(&context, request);
      ave::v1::StaticModelChunk chunk;
      Drain(reader, chunk, 1 << 20);
      (void)reader->Finish();
      break;
    }
    case 3: {
      ave::v1::AddCameraRequest request;
      ave::v1::Camera out;
      if (ParseFirst(chunks, &request)) (void)h.admin->AddCamera(&context, request, &out);
      break;
    }
    case 4: {
      ave::v1::UpdateCameraRequest request;
      ave::v1::Camera out;
      if (ParseFirst(chunks, &request)) (void)h.admin->UpdateCamera(&context, request, &out);
      break;
    }
    case 5: {
      ave::v1::RemoveCameraRequest request;
      ave::v1::RemoveCameraResponse out;
      // Keep the stream target registered: removing it would starve the sensor path.
      if (ParseFirst(chunks, &request) && request.id() != "fz") (void)h.admin->RemoveCamera(&context, request, &out);
      break;
    }
    case 6: {
      ave::v1::ListCamerasRequest request;
      ave::v1::ListCamerasResponse out;
      (void)h.admin->ListCameras(&context, request, &out);
      break;
    }
    case 7: {
      ave::v1::IssueTokenRequest request;
      ave::v1::IssueTokenResponse out;
      if (ParseFirst(chunks, &request)) (void)h.admin->IssueToken(&context, request, &out);
      break;
    }
    case 8: {
      ave::v1::RevokeTokenRequest request;
      ave::v1::RevokeTokenResponse out;
      if (ParseFirst(chunks, &request)) (void)h.admin->RevokeToken(&context, request, &out);
      break;
    }
    case 9: {
      ave::v1::ListTokensRequest request;
      ave::v1::ListTokensResponse out;
      (void)h.admin->ListTokens(&context, request, &out);
      break;
    }
    case 10: {
      ave::v1::ReplayRequest request;
      if (!ParseFirst(chunks, &request)) return 0;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(200));
      auto reader = h.scene->Replay(&context, request);
      ave::v1::SceneUpdate update;
      Drain(reader, update, 4);
      context.TryCancel();
      (void)reader->Finish();
      break;
    }
    case 11: {
      ave::v1::RecordedSpansRequest request;
      ave::v1::RecordedSpansResponse out;
      if (ParseFirst(chunks, &request)) (void)h.scene->RecordedSpans(&context, request, &out);
      break;
    }
    case 12: {
      ave::v1::AvatarSequenceRequest request;
      if (!ParseFirst(chunks, &request)) return 0;
      auto reader = h.scene->GetAvatarSequence(&context, request);
      ave::v1::AvatarSequenceChunk chunk;
      Drain(reader, chunk, 1 << 16);
      (void)reader->Finish();
      break;
    }
    case 13: {
      ave::v1::AvatarSequenceInfo out;
      auto writer = h.admin->PutAvatarSequence(&context, &out);
      for (const std::string& bytes : chunks) {
        ave::v1::AvatarSequenceChunk chunk;
        if (!chunk.ParseFromString(bytes) || !writer->Write(chunk)) break;
      }
      writer->WritesDone();
      (void)writer->Finish();
      break;
    }
    default: {
      ave::v1::ListAvatarSequencesRequest request;
      ave::v1::ListAvatarSequencesResponse out;
      (void)h.admin->ListAvatarSequences(&context, request, &out);
      break;
    }
  }
  return 0;
}
