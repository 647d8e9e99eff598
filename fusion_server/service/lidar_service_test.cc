// Issue 16 at the service edge: a rotating LiDAR registered through AdminService (stored, audited),
// a sensor token issued for it that streams only as it, hello kinds checked against the registry,
// sweeps validated with errors naming the sensor and the field, and tracks reaching viewers.
#include <unistd.h>

#include <filesystem>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/db/store.h"

namespace ave {
namespace {

using ::testing::HasSubstr;

constexpr char kAdmin[] = "adm1n";
constexpr char kViewer[] = "v1ewer";

class LidarService : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("ave_lidar_service_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    ServerOptions options = fixtures::LoopbackServer((dir_ / "ave.db").string(), "", kViewer, kAdmin);
    options.seed_campus = false;
    auto server = FusionServer::Start(options);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials());
    admin_ = v1::AdminService::NewStub(channel_);
    sensor_ = v1::SensorService::NewStub(channel_);
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(dir_);
  }

  grpc::Status Add(const v1::Camera& camera) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::AddCameraRequest request;
    *request.mutable_camera() = camera;
    v1::Camera response;
    return admin_->AddCamera(&context, request, &response);
  }
  std::string IssueSensorToken(const std::string& id) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::IssueTokenRequest request;
    request.set_role("sensor");
    request.set_camera_id(id);
    v1::IssueTokenResponse response;
    EXPECT_TRUE(admin_->IssueToken(&context, request, &response).ok());
    return response.token();
  }
  static v1::Camera Lidar(const std::string& id) {
    v1::Camera c;
    c.set_id(id);
    c.set_name("Courtyard LiDAR");
    c.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
    *c.mutable_mounting_pose() = ToProto(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-2, -3, 2)));
    c.set_enabled(true);
    return c;
  }
  static v1::SensorHello Hello(const std::string& id, const std::string& token, bool lidar) {
    v1::SensorHello hello;
    hello.set_camera_id(id);
    hello.set_token(token);
    if (lidar) {
      hello.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
    } else {
      *hello.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
    }
    return hello;
  }
  static v1::LidarSweepFrame Sweep(uint64_t sequence, double x) {
    v1::LidarSweepFrame s;
    s.mutable_foreground()->set_count(1);
    s.mutable_foreground()->set_packed(std::string("\x64\x00\x00\x00\x00\x00\x01\x00", 8));
    s.set_sequence(sequence);
    s.set_capture_time_ns(1'000'000'000 + static_cast<int64_t>(sequence) * 100'000'000);
    v1::FootTrack* t = s.add_tracks();
    t->set_track_id(5);
    t->mutable_position()->set_x(x);
    t->mutable_position()->set_y(1);
    for (float c : {0.01f, 0.0f, 0.01f}) t->add_covariance(c);
    return s;
  }
  // Sends the hello and the sweeps, one ack each; the stream's final status.
  grpc::Status StreamSweeps(const v1::SensorHello& hello, const std::vector<v1::LidarSweepFrame>& sweeps,
                            int* acks = nullptr) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    auto stream = sensor_->Stream(&context);
    v1::SensorMessage m;
    *m.mutable_hello() = hello;
    stream->Write(m);
    int read = 0;
    for (const auto& s : sweeps) {
      *m.mutable_lidar_sweep() = s;
      if (!stream->Write(m)) break;
      v1::SensorAck ack;
      if (!stream->Read(&ack)) break;
      EXPECT_EQ(ack.sequence(), s.sequence());
      ++read;
    }
    stream->WritesDone();
    if (acks) *acks = read;
    return stream->Finish();
  }

  std::filesystem::path dir_;
  std::unique_ptr<FusionServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::AdminService::Stub> admin_;
  std::unique_ptr<v1::SensorService::Stub> sensor_;
};

TEST_F(LidarService, LidarIsRegisteredStoredAndAuditedLikeACamera) {
  ASSERT_TRUE(Add(Lidar("hdl64")).ok());
  v1::Camera with_intrinsics = Lidar("hdl65");
  *with_intrinsics.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
  const grpc::Status refused = Add(with_intrinsics);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(refused.error_message(), HasSubstr("camera 'hdl65': camera.intrinsics must be absent"));
  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
  v1::ListCamerasResponse list;
  ASSERT_TRUE(admin_->ListCameras(&context, {}, &list).ok());
  ASSERT_EQ(list.cameras_size(), 1);
  EXPECT_EQ(list.cameras(0).kind(), v1::SENSOR_KIND_ROTATING_LIDAR);
  EXPECT_FALSE(list.cameras(0).has_intrinsics());
  EXPECT_EQ(list.cameras(0).mounting_pose().position().y(), -3);
  // In the store (a second connection: WAL) with its kind, and in the audit table.
  auto store = store::Store::Open((dir_ / "ave.db").string());
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->GetCamera("hdl64")->kind, store::kSensorKindRotatingLidar);
  auto audit = (*store)->ListAudit();
  ASSERT_TRUE(audit.ok());
  ASSERT_FALSE(audit->empty());
  EXPECT_EQ(audit->front().action, "AddCamera");
  EXPECT_EQ(audit->front().target, "hdl64");
  EXPECT_THAT(audit->front().after_json, HasSubstr("SENSOR_KIND_ROTATING_LIDAR"));
}

TEST_F(LidarService, IssuedTokenStreamsOnlyAsItsLidarAndKindsMustMatch) {
  ASSERT_TRUE(Add(Lidar("hdl64")).ok());
  ASSERT_TRUE(Add(fixtures::CameraRecord("cam1")).ok());
  const std::string token = IssueSensorToken("hdl64");
  int acks = 0;
  EXPECT_TRUE(StreamSweeps(Hello("hdl64", token, true), {Sweep(1, 3), Sweep(2, 3.1)}, &acks).ok());
  EXPECT_EQ(acks, 2);
  // The LiDAR's token is not cam1's.
  grpc::Status s = StreamSweeps(Hello("cam1", token, true), {Sweep(1, 3)});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(s.error_message(), HasSubstr("bound to camera 'hdl64'"));
  // A camera hello for the LiDAR, a LiDAR hello for the camera: refused, naming both kinds.
  s = StreamSweeps(Hello("hdl64", token, false), {});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_THAT(s.error_message(), HasSubstr("'hdl64' is registered as a rotating LiDAR but its hello says camera"));
  s = StreamSweeps(Hello("cam1", IssueSensorToken("cam1"), true), {});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  // A camera frame on a LiDAR stream.
  grpc::ClientContext context;
  auto stream = sensor_->Stream(&context);
  v1::SensorMessage m;
  *m.mutable_hello() = Hello("hdl64", token, true);
  stream->Write(m);
  m.mutable_frame()->set_sequence(1);
  stream->Write(m);
  stream->WritesDone();
  s = stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("lidar 'hdl64': not a lidar_sweep"));
}

TEST_F(LidarService, BadSweepIsRefusedNamingSensorSweepAndField) {
  ASSERT_TRUE(Add(Lidar("hdl64")).ok());
  const std::string token = IssueSensorToken("hdl64");
  v1::LidarSweepFrame bad = Sweep(2, 3);
  bad.mutable_tracks(0)->set_covariance(2, NAN);
  int acks = 0;
  const grpc::Status s = StreamSweeps(Hello("hdl64", token, true), {Sweep(1, 3), bad}, &acks);
  EXPECT_EQ(acks, 1);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("lidar 'hdl64': sweep 2: tracks[0].covariance must be finite"));
}

TEST_F(LidarService, ViewerSeesTheLidarAndItsPersonAsAnObject) {
  ASSERT_TRUE(Add(Lidar("hdl64")).ok());
  const std::string token = IssueSensorToken("hdl64");
  ASSERT_TRUE(StreamSweeps(Hello("hdl64", token, true), {Sweep(1, 3), Sweep(2, 3.1)}).ok());
  auto scene = v1::SceneService::NewStub(channel_);
  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  v1::SubscribeRequest request;
  request.set_include_lidar_points(true);
  auto reader = scene->Subscribe(&context, request);
  v1::SceneUpdate update;
  ASSERT_TRUE(reader->Read(&update));
  context.TryCancel();
  reader->Finish();
  EXPECT_EQ(update.cameras_size(), 0);
  ASSERT_EQ(update.lidars_size(), 1);
  EXPECT_EQ(update.lidars(0).sensor_id(), "hdl64");
  EXPECT_EQ(update.lidars(0).name(), "Courtyard LiDAR");
  ASSERT_EQ(update.lidars(0).tracks_size(), 1);
  ASSERT_EQ(update.objects_size(), 1);
  EXPECT_EQ(update.lidars(0).track_object_ids(0), update.objects(0).object_id());
  EXPECT_EQ(update.objects(0).kind(), 1u);
  EXPECT_NEAR(update.objects(0).position().x(), 3.1, 0.1);
  // The points, forwarded byte for byte because this viewer asked for them.
  EXPECT_EQ(update.lidars(0).foreground().count(), 1u);
  EXPECT_EQ(update.lidars(0).foreground().packed(), Sweep(2, 3.1).foreground().packed());
}

}  // namespace
}  // namespace ave
