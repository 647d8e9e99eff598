// The server's contract with misbehaving sensors, viewers and administrators: every bad input gets
// a clear status naming the camera or field, and everyone else keeps being served.
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"

#include <filesystem>
#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "model_store/scene/campus.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
using fixtures::CameraRecord;
using fixtures::Jpeg;

constexpr char kSensor[] = "sensor-secret";
constexpr char kViewer[] = "viewer-secret";
constexpr char kAdmin[] = "admin-secret";

class ServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions options = server_.Options(kSensor, kViewer, kAdmin);
    options.frame_limits.max_jpeg_bytes = 1 << 20;
    options.max_message_bytes = 4 << 20;
    options.campus_grid_m = 8;
    const absl::Status started = server_.Start(options);
    ASSERT_TRUE(started.ok()) << started;
    channel_ = server_.InsecureChannel();
    admin_ = v1::AdminService::NewStub(channel_);
    sensor_ = v1::SensorService::NewStub(channel_);
    scene_ = v1::SceneService::NewStub(channel_);
    for (const char* id : {"a", "b"}) ASSERT_TRUE(Admin(&v1::AdminService::Stub::AddCamera, CameraRecord(id)).ok());
  }
  grpc::Status Admin(grpc::Status (v1::AdminService::Stub::*call)(grpc::ClientContext*, const v1::AddCameraRequest&, v1::Camera*),
                     const v1::Camera& camera, const std::string& token = kAdmin) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    v1::AddCameraRequest request;
    *request.mutable_camera() = camera;
    v1::Camera response;
    return (admin_.get()->*call)(&context, request, &response);
  }

  // Opens a sensor stream, sends the hello and `frames`, and returns the final status with the
  // number of acks read.
  grpc::Status Stream(const v1::SensorHello& hello, const std::vector<v1::SensorFrame>& frames, int* acks = nullptr) {
    return fixtures::StreamFrames(*sensor_, hello, frames, acks);
  }

  v1::SensorHello Hello(const std::string& id, const std::string& token = kSensor) {
    v1::SensorHello h;
    h.set_camera_id(id);
    h.set_token(token);
    *h.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
    h.set_software_version("test");
    return h;
  }

  v1::SensorFrame Frame(uint64_t seq) {
    v1::SensorFrame f;
    f.set_sequence(seq);
    f.set_capture_time_ns(1'700'000'000'000'000'000 + seq);
    *f.mutable_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
    f.set_jpeg(Jpeg(64, 48));
    return f;
  }

  fixtures::LocalServer server_{"ave_server_test"};
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::AdminService::Stub> admin_;
  std::unique_ptr<v1::SensorService::Stub> sensor_;
  std::unique_ptr<v1::SceneService::Stub> scene_;
};

TEST_F(ServerTest, GoodStreamIsAcceptedAndAcked) {
  int acks = 0;
  const grpc::Status s = Stream(Hello("a"), {Frame(1), Frame(2), Frame(3)}, &acks);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(acks, 3);
  ASSERT_NE(server_->state().LatestFrame("a"), nullptr);
  EXPECT_EQ(server_->state().LatestFrame("a")->sequence(), 3u);
}

TEST_F(ServerTest, UnknownCameraAndBadTokenAreRefusedByName) {
  grpc::Status s = Stream(Hello("nope"), {Frame(1)});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(s.error_message(), HasSubstr("camera 'nope'"));
  s = Stream(Hello("a", "wrong"), {Frame(1)});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_THAT(s.error_message(), HasSubstr("camera 'a'"));
}

TEST_F(ServerTest, BadFramesEndTheStreamButKeepWhatWasAccepted) {
  v1::SensorFrame truncated = Frame(2);
  truncated.set_jpeg(truncated.jpeg().substr(0, truncated.jpeg().size() / 2));
  int acks = 0;
  grpc::Status s = Stream(Hello("a"), {Frame(1), truncated}, &acks);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("camera 'a'"));
  EXPECT_THAT(s.error_message(), HasSubstr("truncated"));
  EXPECT_EQ(acks, 1);
  ASSERT_NE(server_->state().LatestFrame("a"), nullptr);
  EXPECT_EQ(server_->state().LatestFrame("a")->sequence(), 1u);  // frame 1 kept

  v1::SensorFrame nan_pose = Frame(1);
  nan_pose.mutable_pose()->mutable_orientation()->set_x(NAN);
  s = Stream(Hello("b"), {nan_pose});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("pose.orientation"));

  v1::SensorFrame non_unit = Frame(1);
  non_unit.mutable_pose()->mutable_orientation()->set_w(2);
  s = Stream(Hello("b"), {non_unit});
  EXPECT_THAT(s.error_message(), HasSubstr("unit quaternion"));
}

TEST_F(ServerTest, OversizedFramesAreRefusedAndOthersKeepFlowing) {
  v1::SensorFrame big = Frame(1);
  big.set_jpeg(std::string(2 << 20, 'x'));  // over the 1 MiB JPEG limit, under the gRPC cap
  grpc::Status s = Stream(Hello("a"), {big});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(s.error_message(), HasSubstr("camera 'a'"));
  v1::SensorFrame huge = Frame(1);
  huge.set_jpeg(std::string(6 << 20, 'x'));  // over the gRPC cap itself
  s = Stream(Hello("a"), {huge});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  // Another camera is unaffected.
  int acks = 0;
  EXPECT_TRUE(Stream(Hello("b"), {Frame(1), Frame(2)}, &acks).ok());
  EXPECT_EQ(acks, 2);
}

TEST_F(ServerTest, AdminRefusesInvalidFieldsByNameAndAudits) {
  v1::Camera bad = CameraRecord("c");
  bad.mutable_intrinsics()->set_fx(NAN);
  grpc::Status s = Admin(&v1::AdminService::Stub::AddCamera, bad);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(s.error_message(), HasSubstr("intrinsics.fx"));
  bad = CameraRecord("c");
  bad.mutable_mounting_pose()->mutable_orientation()->set_w(3);
  EXPECT_THAT(Admin(&v1::AdminService::Stub::AddCamera, bad).error_message(), HasSubstr("mounting_pose.orientation"));
  bad = CameraRecord("bad id!");
  EXPECT_THAT(Admin(&v1::AdminService::Stub::AddCamera, bad).error_message(), HasSubstr("camera.id"));
  EXPECT_EQ(Admin(&v1::AdminService::Stub::AddCamera, CameraRecord("a")).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_EQ(Admin(&v1::AdminService::Stub::AddCamera, CameraRecord("c"), "guess").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);

  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
  v1::ListCamerasResponse list;
  ASSERT_TRUE(admin_->ListCameras(&context, v1::ListCamerasRequest(), &list).ok());
  ASSERT_EQ(list.cameras_size(), 2);  // nothing invalid slipped in
  EXPECT_EQ(list.cameras(0).id(), "a");
}

TEST_F(ServerTest, ViewerGetsStaticModelAndLatestFrames) {
  ASSERT_TRUE(Stream(Hello("a"), {Frame(1), Frame(2)}).ok());
  {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    auto reader = scene_->GetStaticModel(&context, v1::StaticModelRequest());
    v1::StaticModelChunk chunk;
    size_t triangles = 0, chunks = 0;
    while (reader->Read(&chunk)) {
      triangles += chunk.indices_size() / 3;
      ++chunks;
      EXPECT_EQ(chunk.version(), server_->static_model_version());
    }
    ASSERT_TRUE(reader->Finish().ok());
    EXPECT_EQ(triangles, scene::BuildStaticMesh(scene::BuiltinCampus(), 8).TriangleCount());
    EXPECT_GE(chunks, 1u);
  }
  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
  v1::SubscribeRequest request;
  request.add_camera_ids("a");
  request.set_include_jpeg(true);
  auto reader = scene_->Subscribe(&context, request);
  v1::SceneUpdate update;
  ASSERT_TRUE(reader->Read(&update));
  ASSERT_EQ(update.cameras_size(), 1);
  EXPECT_EQ(update.cameras(0).frame_sequence(), 2u);
  EXPECT_EQ(update.cameras(0).jpeg(), Frame(2).jpeg());  // forwarded byte for byte
  EXPECT_EQ(update.cameras(0).view_matrix_size(), 16);
  context.TryCancel();
  reader->Finish();

  grpc::ClientContext bad;
  bad.AddMetadata("authorization", "Bearer nope");
  auto refused = scene_->Subscribe(&bad, request);
  EXPECT_FALSE(refused->Read(&update));
  EXPECT_EQ(refused->Finish().error_code(), grpc::StatusCode::UNAUTHENTICATED);

  // A rate near zero (or not finite) is refused by name: it once overflowed the update interval.
  for (float rate : {1e-30f, -1.0f, NAN, INFINITY}) {
    grpc::ClientContext slow;
    slow.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    request.set_max_rate_hz(rate);
    auto reader_slow = scene_->Subscribe(&slow, request);
    EXPECT_FALSE(reader_slow->Read(&update));
    const grpc::Status s = reader_slow->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << rate;
    EXPECT_THAT(s.error_message(), HasSubstr("max_rate_hz")) << rate;
  }
}

TEST_F(ServerTest, RestartReloadsCamerasFromTheStore) {
  const absl::Status restarted = server_.Start(server_.Options(kSensor, "", ""));
  ASSERT_TRUE(restarted.ok()) << restarted;
  EXPECT_TRUE(server_->state().FindCamera("a").has_value());
  EXPECT_TRUE(server_->state().FindCamera("b").has_value());
}

}  // namespace
}  // namespace ave
