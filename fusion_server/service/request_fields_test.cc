// Issue 14 (part 4): every field of every request message, with a bad value, through a real
// server on loopback. Each case asserts the status code and that the message names the field
// (and the camera where there is one). The first test walks the proto descriptors of the three
// services' request types, so a field added to ave.proto fails it until it has a case here and a
// row in docs/RELIABILITY.md ("Input surfaces").
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <set>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
namespace pb = google::protobuf;

constexpr char kSensor[] = "sensor-secret";
constexpr char kViewer[] = "viewer-secret";
constexpr char kAdmin[] = "admin-secret";

// Fields whose cases are below. Fields that accept every value say so in their case.
const std::set<std::string>& CoveredFields() {
  static const std::set<std::string> fields = {
      "ave.v1.SensorMessage.hello", "ave.v1.SensorMessage.frame",
      "ave.v1.SensorHello.camera_id", "ave.v1.SensorHello.token", "ave.v1.SensorHello.intrinsics",
      "ave.v1.SensorHello.software_version",
      "ave.v1.Intrinsics.width", "ave.v1.Intrinsics.height", "ave.v1.Intrinsics.fx", "ave.v1.Intrinsics.fy",
      "ave.v1.Intrinsics.cx", "ave.v1.Intrinsics.cy", "ave.v1.Intrinsics.distortion",
      "ave.v1.SensorFrame.capture_time_ns", "ave.v1.SensorFrame.sequence", "ave.v1.SensorFrame.pose",
      "ave.v1.SensorFrame.boxes", "ave.v1.SensorFrame.jpeg", "ave.v1.SensorFrame.metadata_only",
      "ave.v1.SensorFrame.clock_offset_ns",
      "ave.v1.Pose.position", "ave.v1.Pose.orientation", "ave.v1.Pose.covariance",
      "ave.v1.Vec3.x", "ave.v1.Vec3.y", "ave.v1.Vec3.z",
      "ave.v1.Quaternion.w", "ave.v1.Quaternion.x", "ave.v1.Quaternion.y", "ave.v1.Quaternion.z",
      "ave.v1.DetectedBox.track_id", "ave.v1.DetectedBox.corners", "ave.v1.DetectedBox.score",
      "ave.v1.Point2.x", "ave.v1.Point2.y",
      "ave.v1.SubscribeRequest.viewer_id", "ave.v1.SubscribeRequest.camera_ids",
      "ave.v1.SubscribeRequest.max_rate_hz", "ave.v1.SubscribeRequest.include_jpeg",
      "ave.v1.SubscribeRequest.views", "ave.v1.SubscribeRequest.max_jpeg_width",
      "ave.v1.ViewFrustum.view_projection", "ave.v1.ViewFrustum.origin_x", "ave.v1.ViewFrustum.origin_y",
      "ave.v1.ViewFrustum.origin_z",
      "ave.v1.StaticModelRequest.known_version",
      "ave.v1.AddCameraRequest.camera", "ave.v1.UpdateCameraRequest.camera", "ave.v1.RemoveCameraRequest.id",
      "ave.v1.Camera.id", "ave.v1.Camera.name", "ave.v1.Camera.intrinsics", "ave.v1.Camera.mounting_pose",
      "ave.v1.Camera.source_url", "ave.v1.Camera.enabled",
      "ave.v1.IssueTokenRequest.role", "ave.v1.IssueTokenRequest.camera_id", "ave.v1.IssueTokenRequest.label",
      "ave.v1.RevokeTokenRequest.token_id",
      // Issue 16: rotating LiDARs (LidarFieldsAreRefusedByNameWithTheSensor below).
      "ave.v1.Camera.kind", "ave.v1.SensorHello.kind", "ave.v1.SensorMessage.lidar_sweep",
      "ave.v1.LidarSweepFrame.sequence", "ave.v1.LidarSweepFrame.capture_time_ns",
      "ave.v1.LidarSweepFrame.clock_offset_ns", "ave.v1.LidarSweepFrame.world_from_sensor",
      "ave.v1.LidarSweepFrame.tracks", "ave.v1.LidarSweepFrame.foreground",
      "ave.v1.FootTrack.track_id", "ave.v1.FootTrack.position", "ave.v1.FootTrack.velocity_x_mps",
      "ave.v1.FootTrack.velocity_y_mps", "ave.v1.FootTrack.covariance", "ave.v1.FootTrack.age_sweeps",
      "ave.v1.LidarPoints.count", "ave.v1.LidarPoints.packed", "ave.v1.SubscribeRequest.include_lidar_points",
      // Issue 18: SceneService.Replay (ReplayFieldsAreRefusedByName below).
      "ave.v1.ReplayRequest.viewer_id", "ave.v1.ReplayRequest.camera_ids", "ave.v1.ReplayRequest.start_time_ns",
      "ave.v1.ReplayRequest.end_time_ns", "ave.v1.ReplayRequest.rate", "ave.v1.ReplayRequest.include_jpeg",
      "ave.v1.ReplayRequest.views", "ave.v1.ReplayRequest.max_rate_hz", "ave.v1.ReplayRequest.include_lidar_points",
      "ave.v1.ReplayRequest.max_updates", "ave.v1.ReplayRequest.purpose",
      // Issue 18: SceneService.RecordedSpans (RecordedSpansFieldsAreRefusedByName below).
      "ave.v1.RecordedSpansRequest.camera_ids", "ave.v1.RecordedSpansRequest.merge_gap_ns",
      // Issue 17: avatar sequences (avatar_service_test.cc, EveryRequestFieldIsRefusedByName).
      "ave.v1.AvatarSequenceRequest.name", "ave.v1.AvatarSequenceRequest.known_version",
      "ave.v1.AvatarSequenceChunk.name", "ave.v1.AvatarSequenceChunk.version", "ave.v1.AvatarSequenceChunk.chunk_index",
      "ave.v1.AvatarSequenceChunk.chunk_count", "ave.v1.AvatarSequenceChunk.total_bytes",
      "ave.v1.AvatarSequenceChunk.data",
  };
  return fields;
}

void CollectFields(const pb::Descriptor* message, std::set<std::string>& fields, std::set<std::string>& seen) {
  if (!seen.insert(message->full_name()).second) return;
  for (int i = 0; i < message->field_count(); ++i) {
    const pb::FieldDescriptor* f = message->field(i);
    fields.insert(f->full_name());
    if (f->message_type()) CollectFields(f->message_type(), fields, seen);
  }
}

TEST(RequestFields, EveryFieldOfEveryRequestMessageHasACase) {
  std::set<std::string> fields, seen;
  const pb::FileDescriptor* file = v1::SensorMessage::descriptor()->file();
  ASSERT_EQ(file->service_count(), 3);  // SensorService, SceneService, AdminService
  for (int i = 0; i < file->service_count(); ++i) {
    const pb::ServiceDescriptor* service = file->service(i);
    for (int m = 0; m < service->method_count(); ++m) CollectFields(service->method(m)->input_type(), fields, seen);
  }
  for (const std::string& f : fields) {
    EXPECT_TRUE(CoveredFields().count(f)) << f << " has no bad-input case here (and no row in docs/RELIABILITY.md)";
  }
  for (const std::string& f : CoveredFields()) EXPECT_TRUE(fields.count(f)) << f << " is no longer a request field";
}

class RequestFieldsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("ave_request_fields_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    ServerOptions options = fixtures::LoopbackServer((dir_ / "ave.db").string(), kSensor, kViewer, kAdmin);
    options.frame_limits.max_jpeg_bytes = 1 << 20;
    options.max_message_bytes = 4 << 20;
    options.campus_grid_m = 8;
    auto server = FusionServer::Start(options);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials());
    admin_ = v1::AdminService::NewStub(channel_);
    sensor_ = v1::SensorService::NewStub(channel_);
    scene_ = v1::SceneService::NewStub(channel_);
    ASSERT_TRUE(AddCamera(fixtures::CameraRecord("a")).ok());
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(dir_);
  }

  static v1::SensorHello Hello() {
    v1::SensorHello h;
    h.set_camera_id("a");
    h.set_token(kSensor);
    *h.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
    h.set_software_version("test");
    return h;
  }
  static v1::SensorFrame Frame(uint64_t seq = 1) {
    v1::SensorFrame f;
    f.set_sequence(seq);
    f.set_capture_time_ns(1'700'000'000'000'000'000 + seq);
    *f.mutable_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
    f.set_jpeg(fixtures::Jpeg(64, 48));
    v1::DetectedBox* box = f.add_boxes();
    box->set_track_id(1);
    box->set_score(0.9f);
    for (auto [x, y] : {std::pair{20.f, 10.f}, {30.f, 10.f}, {30.f, 40.f}, {20.f, 40.f}}) {
      v1::Point2* c = box->add_corners();
      c->set_x(x);
      c->set_y(y);
    }
    return f;
  }

  grpc::Status AddCamera(const v1::Camera& camera, bool update = false) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::Camera response;
    if (update) {
      v1::UpdateCameraRequest request;
      *request.mutable_camera() = camera;
      return admin_->UpdateCamera(&context, request, &response);
    }
    v1::AddCameraRequest request;
    *request.mutable_camera() = camera;
    return admin_->AddCamera(&context, request, &response);
  }
  grpc::Status Subscribe(const v1::SubscribeRequest& request, v1::SceneUpdate* first = nullptr) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto reader = scene_->Subscribe(&context, request);
    v1::SceneUpdate update;
    if (reader->Read(&update)) {  // accepted: one update is enough
      if (first) *first = update;
      context.TryCancel();
      reader->Finish();
      return grpc::Status::OK;
    }
    return reader->Finish();
  }

  std::filesystem::path dir_;
  std::unique_ptr<FusionServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::AdminService::Stub> admin_;
  std::unique_ptr<v1::SensorService::Stub> sensor_;
  std::unique_ptr<v1::SceneService::Stub> scene_;
};

struct StreamCase {
  const char* what;
  std::function<void(v1::SensorHello&, v1::SensorFrame&)> mutate;
  grpc::StatusCode code;
  const char* names;  // substring the error must contain (besides the camera, checked where known)
};

TEST_F(RequestFieldsTest, SensorHelloFieldsAreRefusedByName) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<StreamCase> cases = {
      {"camera_id", [](auto& h, auto&) { h.set_camera_id("a b"); }, grpc::StatusCode::INVALID_ARGUMENT, "hello.camera_id"},
      {"camera_id unknown", [](auto& h, auto&) { h.set_camera_id("zz"); }, grpc::StatusCode::NOT_FOUND, "camera 'zz'"},
      {"token missing", [](auto& h, auto&) { h.clear_token(); }, grpc::StatusCode::UNAUTHENTICATED, "hello.token"},
      {"token too long", [](auto& h, auto&) { h.set_token(std::string(5000, 't')); }, grpc::StatusCode::UNAUTHENTICATED,
       "hello.token"},
      {"token wrong", [](auto& h, auto&) { h.set_token("guess"); }, grpc::StatusCode::UNAUTHENTICATED, "camera 'a'"},
      {"software_version", [](auto& h, auto&) { h.set_software_version(std::string(129, 'v')); },
       grpc::StatusCode::INVALID_ARGUMENT, "hello.software_version"},
      {"intrinsics missing", [](auto& h, auto&) { h.clear_intrinsics(); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.width"},
      {"width", [](auto& h, auto&) { h.mutable_intrinsics()->set_width(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.width"},
      {"height", [](auto& h, auto&) { h.mutable_intrinsics()->set_height(20000); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.height"},
      {"fx", [](auto& h, auto&) { h.mutable_intrinsics()->set_fx(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.fx"},
      {"fy", [=](auto& h, auto&) { h.mutable_intrinsics()->set_fy(nan); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.fy"},
      {"cx", [](auto& h, auto&) { h.mutable_intrinsics()->set_cx(64); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.cx"},
      {"cy", [](auto& h, auto&) { h.mutable_intrinsics()->set_cy(-1); }, grpc::StatusCode::INVALID_ARGUMENT,
       "hello.intrinsics.cy"},
      {"distortion count", [](auto& h, auto&) { h.mutable_intrinsics()->add_distortion(0.1); },
       grpc::StatusCode::INVALID_ARGUMENT, "hello.intrinsics.distortion"},
      {"distortion value",
       [=](auto& h, auto&) {
         for (int i = 0; i < 5; ++i) h.mutable_intrinsics()->add_distortion(i == 2 ? nan : 0.0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "hello.intrinsics.distortion"},
  };
  for (const StreamCase& c : cases) {
    SCOPED_TRACE(c.what);
    v1::SensorHello hello = Hello();
    v1::SensorFrame frame = Frame();
    c.mutate(hello, frame);
    const grpc::Status s = fixtures::StreamFrames(*sensor_, hello, {frame});
    EXPECT_EQ(s.error_code(), c.code) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
    if (!hello.camera_id().empty() && hello.camera_id() != "a b") {
      EXPECT_THAT(s.error_message(), HasSubstr("camera '" + hello.camera_id() + "'"));
    }
  }
  EXPECT_EQ(server_->state().LatestFrame("a"), nullptr);  // nothing slipped through
}

TEST_F(RequestFieldsTest, SensorFrameFieldsAreRefusedByNameWithTheCamera) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<StreamCase> cases = {
      {"sequence 0", [](auto&, auto& f) { f.set_sequence(0); }, grpc::StatusCode::INVALID_ARGUMENT, "sequence must increase"},
      {"capture_time_ns", [](auto&, auto& f) { f.set_capture_time_ns(-5); }, grpc::StatusCode::INVALID_ARGUMENT,
       "capture_time_ns"},
      {"clock_offset_ns", [](auto&, auto& f) { f.set_clock_offset_ns(std::numeric_limits<int64_t>::min()); },
       grpc::StatusCode::INVALID_ARGUMENT, "clock_offset_ns"},
      {"position.x", [=](auto&, auto& f) { f.mutable_pose()->mutable_position()->set_x(nan); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.position"},
      {"position.y", [](auto&, auto& f) { f.mutable_pose()->mutable_position()->set_y(INFINITY); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.position"},
      {"position.z", [](auto&, auto& f) { f.mutable_pose()->mutable_position()->set_z(-INFINITY); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.position"},
      {"orientation.w", [](auto&, auto& f) { f.mutable_pose()->mutable_orientation()->set_w(2); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.orientation"},
      {"orientation.x", [=](auto&, auto& f) { f.mutable_pose()->mutable_orientation()->set_x(nan); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.orientation"},
      {"orientation.y", [](auto&, auto& f) { f.mutable_pose()->mutable_orientation()->set_y(1e300); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.orientation"},
      {"orientation.z", [](auto&, auto& f) { f.mutable_pose()->mutable_orientation()->set_z(0.5); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.orientation"},
      {"orientation missing", [](auto&, auto& f) { f.mutable_pose()->clear_orientation(); },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.orientation"},
      {"covariance count", [](auto&, auto& f) { f.mutable_pose()->add_covariance(1); }, grpc::StatusCode::INVALID_ARGUMENT,
       "pose.covariance"},
      {"covariance value",
       [=](auto&, auto& f) {
         for (int i = 0; i < 36; ++i) f.mutable_pose()->add_covariance(i == 7 ? nan : 0.0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.covariance[7]"},
      {"covariance diagonal",
       [](auto&, auto& f) {
         for (int i = 0; i < 36; ++i) f.mutable_pose()->add_covariance(i == 14 ? -1.0 : 0.0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "pose.covariance diagonal [2]"},
      {"boxes count",
       [](auto&, auto& f) {
         for (int i = 0; i < 1100; ++i) *f.add_boxes() = f.boxes(0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "boxes (at most 1024)"},
      {"corners count", [](auto&, auto& f) { f.mutable_boxes(0)->mutable_corners()->RemoveLast(); },
       grpc::StatusCode::INVALID_ARGUMENT, "boxes[0] must have 4 corners"},
      {"corner x", [](auto&, auto& f) { f.mutable_boxes(0)->mutable_corners(1)->set_x(NAN); },
       grpc::StatusCode::INVALID_ARGUMENT, "boxes[0] has a non-finite corner"},
      {"corner y", [](auto&, auto& f) { f.mutable_boxes(0)->mutable_corners(2)->set_y(INFINITY); },
       grpc::StatusCode::INVALID_ARGUMENT, "boxes[0] has a non-finite corner"},
      {"score", [](auto&, auto& f) { f.mutable_boxes(0)->set_score(1.5f); }, grpc::StatusCode::INVALID_ARGUMENT,
       "boxes[0].score"},
      {"jpeg garbage", [](auto&, auto& f) { f.set_jpeg("not a jpeg"); }, grpc::StatusCode::INVALID_ARGUMENT,
       "jpeg: not a JPEG"},
      {"jpeg size", [](auto&, auto& f) { f.set_jpeg(fixtures::Jpeg(32, 24)); }, grpc::StatusCode::INVALID_ARGUMENT,
       "jpeg is 32x24 but the camera's intrinsics say 64x48"},
      {"jpeg bytes", [](auto&, auto& f) { f.set_jpeg(std::string(2 << 20, 'x')); }, grpc::StatusCode::RESOURCE_EXHAUSTED,
       "jpeg is 2097152 bytes"},
      {"metadata_only with jpeg", [](auto&, auto& f) { f.set_metadata_only(true); }, grpc::StatusCode::INVALID_ARGUMENT,
       "metadata_only"},
  };
  for (const StreamCase& c : cases) {
    SCOPED_TRACE(c.what);
    v1::SensorHello hello = Hello();
    v1::SensorFrame frame = Frame();
    c.mutate(hello, frame);
    int acks = -1;
    const grpc::Status s = fixtures::StreamFrames(*sensor_, hello, {frame}, &acks);
    EXPECT_EQ(s.error_code(), c.code) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
    EXPECT_THAT(s.error_message(), HasSubstr("camera 'a': frame "));
    EXPECT_EQ(acks, 0);
  }
  EXPECT_EQ(server_->state().LatestFrame("a"), nullptr);
}

TEST_F(RequestFieldsTest, StreamMessageOrderAndValuesEveryRangeAccepts) {
  // A frame before the hello, and a second hello.
  {
    grpc::ClientContext context;
    auto stream = sensor_->Stream(&context);
    v1::SensorMessage m;
    *m.mutable_frame() = Frame();
    stream->Write(m);
    stream->WritesDone();
    const grpc::Status s = stream->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_THAT(s.error_message(), HasSubstr("first message must be a hello"));
  }
  {
    grpc::ClientContext context;
    auto stream = sensor_->Stream(&context);
    v1::SensorMessage m;
    *m.mutable_hello() = Hello();
    stream->Write(m);
    stream->Write(m);
    stream->WritesDone();
    const grpc::Status s = stream->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_THAT(s.error_message(), HasSubstr("camera 'a': a second hello"));
  }
  // Values every range accepts: any track id, corners far outside the image, a metadata-only
  // frame without a pose, a frame without boxes.
  v1::SensorFrame edge = Frame(1);
  edge.mutable_boxes(0)->set_track_id(std::numeric_limits<uint32_t>::max());
  edge.mutable_boxes(0)->mutable_corners(2)->set_x(1e30f);
  edge.mutable_boxes(0)->mutable_corners(3)->set_y(-1e30f);
  v1::SensorFrame bare = Frame(2);
  bare.clear_boxes();
  bare.clear_pose();
  bare.clear_jpeg();
  bare.set_metadata_only(true);
  int acks = 0;
  const grpc::Status s = fixtures::StreamFrames(*sensor_, Hello(), {edge, bare, Frame(3)}, &acks);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(acks, 3);
  ASSERT_NE(server_->state().LatestFrame("a"), nullptr);
}

TEST_F(RequestFieldsTest, SubscribeFieldsAreRefusedByName) {
  struct Case {
    const char* what;
    std::function<void(v1::SubscribeRequest&)> mutate;
    const char* names;
  };
  const auto identity = [](v1::ViewFrustum* f) {
    for (int k = 0; k < 16; ++k) f->add_view_projection(k % 5 == 0 ? 1.f : 0.f);
  };
  const std::vector<Case> cases = {
      {"viewer_id", [](auto& r) { r.set_viewer_id(std::string(129, 'v')); }, "viewer_id"},
      {"camera_ids bad id", [](auto& r) { r.add_camera_ids("a/b"); }, "camera_ids: 'a/b'"},
      {"camera_ids too many",
       [](auto& r) {
         for (int i = 0; i < 4097; ++i) r.add_camera_ids("c" + std::to_string(i));
       },
       "camera_ids: at most 4096"},
      {"max_rate_hz negative", [](auto& r) { r.set_max_rate_hz(-1); }, "max_rate_hz"},
      {"max_rate_hz tiny", [](auto& r) { r.set_max_rate_hz(1e-30f); }, "max_rate_hz"},
      {"views too many",
       [&](auto& r) {
         for (int i = 0; i < 17; ++i) identity(r.add_views());
       },
       "views: at most 16"},
      {"view_projection count", [](auto& r) { r.add_views()->add_view_projection(1); }, "views[0].view_projection: 16 floats"},
      {"view_projection nan",
       [&](auto& r) {
         identity(r.add_views());
         r.mutable_views(0)->set_view_projection(5, NAN);
       },
       "views[0]: view frustum: matrix is not finite"},
      {"view_projection singular",
       [](auto& r) {
         v1::ViewFrustum* view = r.add_views();
         for (int k = 0; k < 16; ++k) view->add_view_projection(0);
       },
       "views[0]: view frustum: matrix is singular"},
      {"origin_x", [&](auto& r) { identity(r.add_views()); r.mutable_views(0)->set_origin_x(INFINITY); },
       "views[0]: origin is not finite"},
      {"origin_y", [&](auto& r) { identity(r.add_views()); r.mutable_views(0)->set_origin_y(NAN); },
       "views[0]: origin is not finite"},
      {"origin_z", [&](auto& r) { identity(r.add_views()); r.mutable_views(0)->set_origin_z(-INFINITY); },
       "views[0]: origin is not finite"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    v1::SubscribeRequest request;
    c.mutate(request);
    const grpc::Status s = Subscribe(request);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
  }
  // Hints any value of which is fine: include_jpeg either way, max_jpeg_width up to its maximum
  // (the server ignores it today), an unknown but well-formed camera id (nothing to send).
  v1::SubscribeRequest request;
  request.set_include_jpeg(true);
  request.set_max_jpeg_width(std::numeric_limits<uint32_t>::max());
  request.add_camera_ids("a");
  request.add_camera_ids("not-registered");
  v1::SceneUpdate update;
  const grpc::Status s = Subscribe(request, &update);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(update.cameras_size(), 1);
}

// Issue 18: every ReplayRequest field with a bad value, named; the fields any value of which is
// fine reach the next check (this server does not record: FAILED_PRECONDITION naming --record-dir).
// Recorded data, gaps and roles are in replay_service_test.cc.
TEST_F(RequestFieldsTest, ReplayFieldsAreRefusedByName) {
  auto replay = [&](const v1::ReplayRequest& request) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto reader = scene_->Replay(&context, request);
    v1::SceneUpdate update;
    while (reader->Read(&update)) {
    }
    return reader->Finish();
  };
  struct Case {
    const char* what;
    std::function<void(v1::ReplayRequest&)> mutate;
    const char* names;
  };
  const std::vector<Case> cases = {
      {"viewer_id", [](auto& r) { r.set_viewer_id(std::string(129, 'v')); }, "viewer_id"},
      {"camera_ids", [](auto& r) { r.add_camera_ids("a/b"); }, "camera_ids: 'a/b'"},
      {"start after end", [](auto& r) { r.set_start_time_ns(r.end_time_ns()); }, "end_time_ns"},
      {"end before start", [](auto& r) { r.set_end_time_ns(r.start_time_ns() - 1); }, "end_time_ns"},
      {"rate too fast", [](auto& r) { r.set_rate(17); }, "rate: must be 0 (1x) or 0.25 .. 16"},
      {"rate nan", [](auto& r) { r.set_rate(NAN); }, "rate"},
      {"max_rate_hz", [](auto& r) { r.set_max_rate_hz(-1); }, "max_rate_hz"},
      {"views", [](auto& r) { r.add_views()->add_view_projection(1); }, "views[0].view_projection: 16 floats"},
      {"purpose", [](auto& r) { r.set_purpose("backup"); }, "purpose"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    v1::ReplayRequest request;
    request.set_start_time_ns(1'000'000'000);
    request.set_end_time_ns(2'000'000'000);
    c.mutate(request);
    const grpc::Status s = replay(request);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
  }
  v1::ReplayRequest request;
  request.set_start_time_ns(1'000'000'000);
  request.set_end_time_ns(2'000'000'000);
  request.set_include_jpeg(true);
  request.set_include_lidar_points(true);
  request.set_max_updates(std::numeric_limits<uint32_t>::max());
  request.set_rate(0.25f);
  request.set_purpose("export");
  const grpc::Status s = replay(request);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("--record-dir"));
}

// Issue 18: RecordedSpansRequest's fields with bad values, named; good ones reach the next check
// (this server does not record: FAILED_PRECONDITION naming --record-dir).
TEST_F(RequestFieldsTest, RecordedSpansFieldsAreRefusedByName) {
  auto spans = [&](const v1::RecordedSpansRequest& request) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    v1::RecordedSpansResponse response;
    return scene_->RecordedSpans(&context, request, &response);
  };
  v1::RecordedSpansRequest bad_id;
  bad_id.add_camera_ids("a/b");
  grpc::Status s = spans(bad_id);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("camera_ids: 'a/b'"));
  v1::RecordedSpansRequest bad_gap;
  bad_gap.set_merge_gap_ns(-1);
  s = spans(bad_gap);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("merge_gap_ns"));
  v1::RecordedSpansRequest good;
  good.add_camera_ids("cam1");
  good.set_merge_gap_ns(std::numeric_limits<int64_t>::max());
  s = spans(good);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("--record-dir"));
}

TEST_F(RequestFieldsTest, GetStaticModelIgnoresKnownVersion) {
  for (uint64_t known : {uint64_t{0}, server_->static_model_version(), std::numeric_limits<uint64_t>::max()}) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    v1::StaticModelRequest request;
    request.set_known_version(known);
    auto reader = scene_->GetStaticModel(&context, request);
    v1::StaticModelChunk chunk;
    int chunks = 0;
    while (reader->Read(&chunk)) ++chunks;
    EXPECT_TRUE(reader->Finish().ok()) << known;
    EXPECT_GE(chunks, 1) << known;  // the whole model, whatever version the viewer says it has
  }
}

TEST_F(RequestFieldsTest, AdminCameraFieldsAreRefusedByNameAndNothingIsStored) {
  struct Case {
    const char* what;
    std::function<void(v1::Camera&)> mutate;
    const char* names;
  };
  const std::vector<Case> cases = {
      {"id", [](auto& c) { c.set_id(std::string(65, 'x')); }, "camera.id"},
      {"id empty", [](auto& c) { c.clear_id(); }, "camera.id"},
      {"name", [](auto& c) { c.set_name(std::string(129, 'n')); }, "camera 'n1': name must be at most 128"},
      {"intrinsics missing", [](auto& c) { c.clear_intrinsics(); }, "camera 'n1': camera.intrinsics.width"},
      {"intrinsics.cx", [](auto& c) { c.mutable_intrinsics()->set_cx(1e9); }, "camera 'n1': camera.intrinsics.cx"},
      {"intrinsics.distortion", [](auto& c) { c.mutable_intrinsics()->add_distortion(1); },
       "camera 'n1': camera.intrinsics.distortion"},
      {"mounting_pose missing", [](auto& c) { c.clear_mounting_pose(); }, "camera 'n1': camera.mounting_pose.orientation"},
      {"mounting_pose.position", [](auto& c) { c.mutable_mounting_pose()->mutable_position()->set_x(NAN); },
       "camera 'n1': camera.mounting_pose.position"},
      {"mounting_pose.covariance", [](auto& c) { c.mutable_mounting_pose()->add_covariance(1); },
       "camera 'n1': camera.mounting_pose.covariance"},
      {"source_url", [](auto& c) { c.set_source_url(std::string(1025, 'u')); }, "camera 'n1': source_url"},
  };
  for (bool update : {false, true}) {
    for (const Case& c : cases) {
      SCOPED_TRACE(std::string(c.what) + (update ? " (update)" : " (add)"));
      v1::Camera camera = fixtures::CameraRecord(update ? "a" : "n1");
      c.mutate(camera);
      const grpc::Status s = AddCamera(camera, update);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
      std::string names = c.names;
      if (update && names.find("'n1'") != std::string::npos) names.replace(names.find("'n1'"), 4, "'a'");
      EXPECT_THAT(s.error_message(), HasSubstr(names));
    }
  }
  // Update of an unknown camera; enabled either way is fine.
  const grpc::Status unknown = AddCamera(fixtures::CameraRecord("zz"), true);
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(unknown.error_message(), HasSubstr("'zz'"));
  v1::Camera disabled = fixtures::CameraRecord("a");
  disabled.set_enabled(false);
  EXPECT_TRUE(AddCamera(disabled, true).ok());

  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
  v1::ListCamerasResponse list;
  ASSERT_TRUE(admin_->ListCameras(&context, v1::ListCamerasRequest(), &list).ok());
  ASSERT_EQ(list.cameras_size(), 1);  // only "a": no invalid record was stored
  EXPECT_FALSE(list.cameras(0).enabled());
}

TEST_F(RequestFieldsTest, AdminRemoveAndTokenFieldsAreRefusedByName) {
  auto remove = [&](const std::string& id) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::RemoveCameraRequest request;
    request.set_id(id);
    v1::RemoveCameraResponse response;
    return admin_->RemoveCamera(&context, request, &response);
  };
  grpc::Status s = remove("../a");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("id must be 1..64"));
  s = remove("zz");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(s.error_message(), HasSubstr("'zz'"));

  auto issue = [&](const std::string& role, const std::string& camera, const std::string& label) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::IssueTokenRequest request;
    request.set_role(role);
    request.set_camera_id(camera);
    request.set_label(label);
    v1::IssueTokenResponse response;
    return admin_->IssueToken(&context, request, &response);
  };
  struct Case {
    std::string role, camera, label;
    grpc::StatusCode code;
    const char* names;
  };
  for (const Case& c : std::vector<Case>{
           {"root", "", "", grpc::StatusCode::INVALID_ARGUMENT, "role must be sensor, viewer or admin, not 'root'"},
           {"sensor", "", "", grpc::StatusCode::INVALID_ARGUMENT, "camera_id: a sensor token is bound to one camera"},
           {"sensor", "a b", "", grpc::StatusCode::INVALID_ARGUMENT, "camera_id"},
           {"sensor", "zz", "", grpc::StatusCode::NOT_FOUND, "camera 'zz'"},
           {"viewer", "a", "", grpc::StatusCode::INVALID_ARGUMENT, "camera_id is only for sensor tokens"},
           {"viewer", "", std::string(129, 'l'), grpc::StatusCode::INVALID_ARGUMENT, "label"},
       }) {
    SCOPED_TRACE(c.role + "/" + c.camera);
    s = issue(c.role, c.camera, c.label);
    EXPECT_EQ(s.error_code(), c.code) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
  }
  EXPECT_TRUE(issue("sensor", "a", std::string(128, 'l')).ok());

  auto revoke = [&](const std::string& id) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::RevokeTokenRequest request;
    request.set_token_id(id);
    v1::RevokeTokenResponse response;
    return admin_->RevokeToken(&context, request, &response);
  };
  for (const auto& [id, code, names] : std::vector<std::tuple<std::string, grpc::StatusCode, const char*>>{
           {"ABCDEF12", grpc::StatusCode::INVALID_ARGUMENT, "token_id must be lowercase hex"},
           {"abc", grpc::StatusCode::INVALID_ARGUMENT, "8..64 hex characters"},
           {"", grpc::StatusCode::INVALID_ARGUMENT, "8..64 hex characters"},
           {std::string(65, 'a'), grpc::StatusCode::INVALID_ARGUMENT, "8..64 hex characters"},
           {"0123456789abcdef", grpc::StatusCode::NOT_FOUND, "token 0123456789abcdef not found"},
       }) {
    SCOPED_TRACE(id);
    s = revoke(id);
    EXPECT_EQ(s.error_code(), code) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(names));
  }
}

// Issue 16: every field a rotating LiDAR sends, refused by name with the sensor, and nothing of a
// refused sweep kept (the server answers with the stream's end, never an ack).
TEST_F(RequestFieldsTest, LidarFieldsAreRefusedByNameWithTheSensor) {
  v1::Camera lidar;
  lidar.set_id("l");
  lidar.set_name("LiDAR");
  lidar.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
  *lidar.mutable_mounting_pose() = ToProto(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 2)));
  lidar.set_enabled(true);
  v1::Camera unknown_kind = lidar;
  unknown_kind.set_id("k");
  unknown_kind.set_kind(static_cast<v1::SensorKind>(99));
  grpc::Status s = AddCamera(unknown_kind);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("camera.kind 99"));
  ASSERT_TRUE(AddCamera(lidar).ok());

  auto stream = [&](const v1::SensorHello& hello, const v1::SensorMessage& second, int* acks) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto st = sensor_->Stream(&context);
    v1::SensorMessage m;
    *m.mutable_hello() = hello;
    st->Write(m);
    *acks = 0;
    if (st->Write(second)) {
      v1::SensorAck ack;
      if (st->Read(&ack)) ++*acks;
    }
    st->WritesDone();
    return st->Finish();
  };
  v1::SensorHello hello;
  hello.set_camera_id("l");
  hello.set_token(kSensor);
  hello.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
  auto sweep = [] {
    v1::LidarSweepFrame f;
    f.set_sequence(1);
    f.set_capture_time_ns(1'700'000'000'000'000'000);
    *f.mutable_world_from_sensor() = ToProto(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 2)));
    v1::FootTrack* t = f.add_tracks();
    t->set_track_id(3);
    t->mutable_position()->set_x(4);
    t->mutable_position()->set_y(5);
    t->set_age_sweeps(7);
    for (float c : {0.01f, 0.0f, 0.01f}) t->add_covariance(c);
    f.mutable_foreground()->set_count(1);
    f.mutable_foreground()->set_packed(std::string("\x64\x00\x00\x00\x00\x00\x01\x00", 8));
    return f;
  };
  int acks = -1;
  {  // The good sweep is acked: each case below changes one field of it.
    v1::SensorMessage m;
    *m.mutable_lidar_sweep() = sweep();
    s = stream(hello, m, &acks);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(acks, 1);
  }
  {  // SensorHello.kind: a kind nobody knows; a camera hello for the LiDAR; a LiDAR sweep on a camera stream.
    v1::SensorHello bad = hello;
    bad.set_kind(static_cast<v1::SensorKind>(42));
    v1::SensorMessage m;
    *m.mutable_lidar_sweep() = sweep();
    s = stream(bad, m, &acks);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr("hello.kind 42"));
    m.mutable_lidar_sweep()->set_sequence(2);
    s = stream(Hello(), m, &acks);  // camera 'a' sends a LiDAR sweep
    EXPECT_FALSE(s.ok());
    EXPECT_THAT(s.error_message(), HasSubstr("camera 'a': not a frame"));
    EXPECT_EQ(acks, 0);
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<std::tuple<const char*, std::function<void(v1::LidarSweepFrame&)>, grpc::StatusCode, const char*>> cases = {
      {"sequence", [](auto& f) { f.set_sequence(0); }, grpc::StatusCode::INVALID_ARGUMENT, "sequence must increase"},
      {"capture_time_ns", [](auto& f) { f.set_capture_time_ns(-1); }, grpc::StatusCode::INVALID_ARGUMENT, "capture_time_ns"},
      {"clock_offset_ns", [](auto& f) { f.set_clock_offset_ns(std::numeric_limits<int64_t>::max()); },
       grpc::StatusCode::INVALID_ARGUMENT, "clock_offset_ns"},
      {"world_from_sensor", [=](auto& f) { f.mutable_world_from_sensor()->mutable_position()->set_z(nan); },
       grpc::StatusCode::INVALID_ARGUMENT, "world_from_sensor"},
      {"tracks count",
       [](auto& f) {
         for (uint32_t i = 0; i < 5000; ++i) {
           v1::FootTrack* t = f.add_tracks();
           *t = f.tracks(0);
           t->set_track_id(100 + i);
         }
       },
       grpc::StatusCode::INVALID_ARGUMENT, "tracks (at most"},
      {"track_id 0", [](auto& f) { f.mutable_tracks(0)->set_track_id(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "tracks[0].track_id must be > 0"},
      {"track_id twice", [](auto& f) { *f.add_tracks() = f.tracks(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "track_id 3 appears twice"},
      {"position", [](auto& f) { f.mutable_tracks(0)->mutable_position()->set_y(INFINITY); },
       grpc::StatusCode::INVALID_ARGUMENT, "tracks[0].position"},
      {"velocity_x_mps", [=](auto& f) { f.mutable_tracks(0)->set_velocity_x_mps(nan); }, grpc::StatusCode::INVALID_ARGUMENT,
       "tracks[0].velocity"},
      {"velocity_y_mps", [](auto& f) { f.mutable_tracks(0)->set_velocity_y_mps(1e9); }, grpc::StatusCode::INVALID_ARGUMENT,
       "tracks[0].velocity"},
      {"covariance count", [](auto& f) { f.mutable_tracks(0)->add_covariance(0); }, grpc::StatusCode::INVALID_ARGUMENT,
       "tracks[0].covariance must have 3 values"},
      {"covariance value", [=](auto& f) { f.mutable_tracks(0)->set_covariance(1, nan); }, grpc::StatusCode::INVALID_ARGUMENT,
       "tracks[0].covariance must be finite"},
      {"covariance not PSD", [](auto& f) { f.mutable_tracks(0)->set_covariance(0, -1); }, grpc::StatusCode::INVALID_ARGUMENT,
       "not positive semi-definite"},
      {"foreground.count", [](auto& f) { f.mutable_foreground()->set_count(1u << 30); }, grpc::StatusCode::RESOURCE_EXHAUSTED,
       "foreground.count"},
      {"foreground.packed", [](auto& f) { f.mutable_foreground()->set_packed("123"); }, grpc::StatusCode::INVALID_ARGUMENT,
       "foreground.packed is 3 bytes"},
  };
  for (const auto& [what, mutate, code, names] : cases) {
    SCOPED_TRACE(what);
    v1::SensorMessage m;
    *m.mutable_lidar_sweep() = sweep();
    m.mutable_lidar_sweep()->set_sequence(1000);
    mutate(*m.mutable_lidar_sweep());
    s = stream(hello, m, &acks);
    EXPECT_EQ(s.error_code(), code) << s.error_message();
    EXPECT_THAT(s.error_message(), HasSubstr(names));
    EXPECT_THAT(s.error_message(), HasSubstr("lidar 'l': sweep "));
    EXPECT_EQ(acks, 0);
  }
  // age_sweeps is informative: every value is accepted.
  v1::SensorMessage m;
  *m.mutable_lidar_sweep() = sweep();
  m.mutable_lidar_sweep()->set_sequence(2000);
  m.mutable_lidar_sweep()->mutable_tracks(0)->set_age_sweeps(std::numeric_limits<uint32_t>::max());
  s = stream(hello, m, &acks);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(acks, 1);
  // SubscribeRequest.include_lidar_points, a bool, accepts both values; true brings the points.
  for (const bool points : {false, true}) {
    v1::SubscribeRequest request;
    request.set_viewer_id("fields");
    request.set_include_lidar_points(points);
    v1::SceneUpdate update;
    s = Subscribe(request, &update);
    ASSERT_TRUE(s.ok()) << s.error_message();
    ASSERT_EQ(update.lidars_size(), 1);
    EXPECT_EQ(update.lidars(0).foreground().count(), points ? 1u : 0u);
  }
}

}  // namespace
}  // namespace ave
