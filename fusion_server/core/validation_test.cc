#include "fusion_server/core/validation.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/image/jpeg_header.h"

namespace ave {
namespace {

using ::testing::HasSubstr;

std::string EncodeJpeg(int width, int height, bool progressive = false) {
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(30, 120, 200));
  std::vector<uchar> bytes;
  std::vector<int> params = {cv::IMWRITE_JPEG_QUALITY, 80};
  if (progressive) params.insert(params.end(), {cv::IMWRITE_JPEG_PROGRESSIVE, 1});
  cv::imencode(".jpg", image, bytes, params);
  return std::string(bytes.begin(), bytes.end());
}

v1::Intrinsics Intrinsics(int w, int h) {
  v1::Intrinsics k;
  k.set_width(w);
  k.set_height(h);
  k.set_fx(500);
  k.set_fy(500);
  k.set_cx(w / 2.0 - 0.5);
  k.set_cy(h / 2.0 - 0.5);
  return k;
}

v1::SensorFrame GoodFrame(uint64_t seq) {
  v1::SensorFrame f;
  f.set_sequence(seq);
  f.set_capture_time_ns(1'000'000'000);
  f.mutable_pose()->mutable_orientation()->set_w(1);
  f.set_jpeg(EncodeJpeg(64, 48));
  return f;
}

TEST(ParseJpegHeader, ReadsDimensionsWithoutDecoding) {
  for (bool progressive : {false, true}) {
    const auto info = ParseJpegHeader(EncodeJpeg(320, 200, progressive));
    ASSERT_TRUE(info.ok()) << info.status();
    EXPECT_EQ(info->width, 320);
    EXPECT_EQ(info->height, 200);
    EXPECT_EQ(info->components, 3);
    EXPECT_EQ(info->progressive, progressive);
  }
}

TEST(ParseJpegHeader, TruncatedOrGarbageIsRejectedWithReason) {
  const std::string jpeg = EncodeJpeg(64, 48);
  EXPECT_THAT(std::string(ParseJpegHeader(jpeg.substr(0, jpeg.size() / 2)).status().message()), HasSubstr("truncated"));
  EXPECT_THAT(std::string(ParseJpegHeader(jpeg.substr(0, 20)).status().message()), HasSubstr("truncated"));
  EXPECT_THAT(std::string(ParseJpegHeader("hello world").status().message()), HasSubstr("start-of-image"));
  EXPECT_FALSE(ParseJpegHeader("").ok());
  // SOI and EOI only, nothing between.
  EXPECT_FALSE(ParseJpegHeader(std::string("\xFF\xD8\xFF\xD9", 4)).ok());
}

TEST(ValidateFrame, AcceptsAGoodFrame) {
  EXPECT_TRUE(ValidateFrame(GoodFrame(1), Intrinsics(64, 48), 0, {}).ok());
}

TEST(ValidateFrame, RejectsNanAndNonUnitQuaternions) {
  v1::SensorFrame f = GoodFrame(1);
  f.mutable_pose()->mutable_orientation()->set_w(NAN);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("pose.orientation"));
  f.mutable_pose()->mutable_orientation()->set_w(1.5);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("unit quaternion"));
  f = GoodFrame(1);
  f.mutable_pose()->mutable_position()->set_z(INFINITY);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("pose.position"));
}

TEST(ValidateFrame, RejectsRepeatedSequenceSizeMismatchAndOversize) {
  EXPECT_THAT(std::string(ValidateFrame(GoodFrame(5), Intrinsics(64, 48), 5, {}).message()), HasSubstr("sequence"));
  EXPECT_THAT(std::string(ValidateFrame(GoodFrame(1), Intrinsics(640, 480), 0, {}).message()),
              HasSubstr("64x48 but the camera's intrinsics say 640x480"));
  FrameLimits tiny;
  tiny.max_jpeg_bytes = 100;
  const absl::Status s = ValidateFrame(GoodFrame(1), Intrinsics(64, 48), 0, tiny);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  v1::SensorFrame boxed = GoodFrame(1);
  boxed.add_boxes()->add_corners();
  EXPECT_THAT(std::string(ValidateFrame(boxed, Intrinsics(64, 48), 0, {}).message()), HasSubstr("boxes[0]"));
}

// Regression for a libFuzzer finding (ave_fuzz_sensor_message): capture time plus an unbounded
// clock offset overflowed int64 downstream.
TEST(ValidateFrame, RejectsTimeStampsAndClockOffsetsThatCouldOverflow) {
  v1::SensorFrame f = GoodFrame(1);
  f.set_clock_offset_ns(9'223'372'036'854'775'803);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("clock_offset_ns"));
  f.set_clock_offset_ns(-9'223'372'036'854'775'807 - 1);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("clock_offset_ns"));
  f.set_clock_offset_ns(-5'000'000'000);  // a 5 s skew is fine
  EXPECT_TRUE(ValidateFrame(f, Intrinsics(64, 48), 0, {}).ok());
  f.set_capture_time_ns(9'000'000'000'000'000'000);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("capture_time_ns"));
}

TEST(ParseJpegHeader, AFrameOverTheViewersPixelLimitIsRefusedThoughEachSideFits) {
  std::string jpeg = EncodeJpeg(320, 200, false);
  const auto sof = image::FindJpegFrameHeader(jpeg);
  ASSERT_TRUE(sof.ok()) << sof.status();
  auto set_size = [&](int w, int h) {
    jpeg[sof->offset + 5] = static_cast<char>(h >> 8);
    jpeg[sof->offset + 6] = static_cast<char>(h & 0xFF);
    jpeg[sof->offset + 7] = static_cast<char>(w >> 8);
    jpeg[sof->offset + 8] = static_cast<char>(w & 0xFF);
  };
  set_size(10000, 10000);  // 100 Mpx, each side under 16384
  EXPECT_THAT(std::string(ParseJpegHeader(jpeg).status().message()), HasSubstr("10000x10000 over 64 Mpx"));
  set_size(8192, 8192);  // exactly 64 Mpx
  const auto at_limit = ParseJpegHeader(jpeg);
  ASSERT_TRUE(at_limit.ok()) << at_limit.status();
  EXPECT_EQ(at_limit->width, 8192);
}

TEST(ValidateFrame, MetadataOnlyFramesCarryNoJpeg) {
  v1::SensorFrame f = GoodFrame(1);
  f.set_metadata_only(true);
  EXPECT_THAT(std::string(ValidateFrame(f, Intrinsics(64, 48), 0, {}).message()), HasSubstr("metadata_only"));
  f.clear_jpeg();
  EXPECT_TRUE(ValidateFrame(f, Intrinsics(64, 48), 0, {}).ok());
}

TEST(ValidateHello, NamesTheField) {
  v1::SensorHello hello;
  hello.set_camera_id("cam 1");
  EXPECT_THAT(std::string(ValidateHello(hello).message()), HasSubstr("camera_id"));
  hello.set_camera_id("cam1");
  EXPECT_EQ(ValidateHello(hello).code(), absl::StatusCode::kUnauthenticated);
  hello.set_token("t");
  *hello.mutable_intrinsics() = Intrinsics(64, 48);
  EXPECT_TRUE(ValidateHello(hello).ok());
  hello.mutable_intrinsics()->set_fx(-1);
  EXPECT_THAT(std::string(ValidateHello(hello).message()), HasSubstr("hello.intrinsics.fx"));
}

// ---- Rotating LiDAR streams (issue 16) ----

v1::LidarSweepFrame GoodSweep(uint64_t seq) {
  v1::LidarSweepFrame s;
  s.set_sequence(seq);
  s.set_capture_time_ns(2'000'000'000);
  s.mutable_world_from_sensor()->mutable_orientation()->set_w(1);
  for (uint32_t id : {3u, 7u}) {
    v1::FootTrack* t = s.add_tracks();
    t->set_track_id(id);
    t->mutable_position()->set_x(4.0 * id);
    t->mutable_position()->set_y(-2);
    t->set_velocity_x_mps(1.2f);
    for (float c : {0.04f, 0.01f, 0.05f}) t->add_covariance(c);
  }
  s.mutable_foreground()->set_count(2);
  s.mutable_foreground()->set_packed(std::string(16, '\x01'));
  return s;
}

std::string SweepError(const v1::LidarSweepFrame& s, const FrameLimits& limits = {}) {
  return std::string(ValidateLidarSweep(s, 0, limits).message());
}

TEST(ValidateLidarSweep, AcceptsAGoodSweepAndOneWithoutPointsOrPose) {
  EXPECT_TRUE(ValidateLidarSweep(GoodSweep(1), 0, {}).ok());
  v1::LidarSweepFrame s = GoodSweep(1);
  s.clear_foreground();
  s.clear_world_from_sensor();
  s.clear_tracks();
  EXPECT_TRUE(ValidateLidarSweep(s, 0, {}).ok());
}

TEST(ValidateLidarSweep, NonFiniteTrackFieldsAreNamed) {
  v1::LidarSweepFrame s = GoodSweep(4);
  s.mutable_tracks(1)->mutable_position()->set_y(NAN);
  EXPECT_THAT(SweepError(s), HasSubstr("sweep 4: tracks[1].position"));
  s = GoodSweep(4);
  s.mutable_tracks(0)->mutable_position()->set_z(INFINITY);
  EXPECT_THAT(SweepError(s), HasSubstr("tracks[0].position"));
  s = GoodSweep(4);
  s.mutable_tracks(0)->set_velocity_y_mps(NAN);
  EXPECT_THAT(SweepError(s), HasSubstr("tracks[0].velocity"));
  s = GoodSweep(4);
  s.mutable_tracks(1)->set_covariance(1, INFINITY);
  EXPECT_THAT(SweepError(s), HasSubstr("tracks[1].covariance must be finite"));
  s = GoodSweep(4);
  s.mutable_world_from_sensor()->mutable_orientation()->set_w(2);
  EXPECT_THAT(SweepError(s), HasSubstr("world_from_sensor.orientation"));
}

TEST(ValidateLidarSweep, CovarianceMustBeThreeValuesPositiveSemiDefinite) {
  v1::LidarSweepFrame s = GoodSweep(1);
  s.mutable_tracks(0)->add_covariance(0.1f);
  EXPECT_THAT(SweepError(s), HasSubstr("tracks[0].covariance must have 3 values"));
  s = GoodSweep(1);
  s.mutable_tracks(0)->set_covariance(0, -0.01f);
  EXPECT_THAT(SweepError(s), HasSubstr("not positive semi-definite"));
  s = GoodSweep(1);
  s.mutable_tracks(0)->set_covariance(1, 0.5f);  // |xy| > sqrt(xx yy)
  EXPECT_THAT(SweepError(s), HasSubstr("not positive semi-definite"));
  s = GoodSweep(1);
  s.mutable_tracks(0)->set_covariance(1, 0.0f);  // a singular but valid one: xx = yy = xy = 0
  s.mutable_tracks(0)->set_covariance(0, 0.0f);
  s.mutable_tracks(0)->set_covariance(2, 0.0f);
  EXPECT_TRUE(ValidateLidarSweep(s, 0, {}).ok());
}

TEST(ValidateLidarSweep, IdsArePositiveAndUniqueAndSequencesIncrease) {
  v1::LidarSweepFrame s = GoodSweep(1);
  s.mutable_tracks(0)->set_track_id(0);
  EXPECT_THAT(SweepError(s), HasSubstr("tracks[0].track_id must be > 0"));
  s = GoodSweep(1);
  s.mutable_tracks(1)->set_track_id(3);
  EXPECT_THAT(SweepError(s), HasSubstr("track_id 3 appears twice"));
  EXPECT_THAT(std::string(ValidateLidarSweep(GoodSweep(5), 5, {}).message()), HasSubstr("sequence must increase"));
  s = GoodSweep(1);
  s.set_capture_time_ns(0);
  EXPECT_THAT(SweepError(s), HasSubstr("capture_time_ns"));
  s = GoodSweep(1);
  s.set_clock_offset_ns(-9'223'372'036'854'775'807 - 1);
  EXPECT_THAT(SweepError(s), HasSubstr("clock_offset_ns"));
}

TEST(ValidateLidarSweep, PointsAreCheckedBySizeAndBoundedNeverDecoded) {
  v1::LidarSweepFrame s = GoodSweep(1);
  s.mutable_foreground()->set_packed(std::string(15, '\0'));
  EXPECT_THAT(SweepError(s), HasSubstr("foreground.packed is 15 bytes; count 2 needs 16"));
  s = GoodSweep(1);
  s.mutable_foreground()->set_count(0);
  EXPECT_THAT(SweepError(s), HasSubstr("foreground.packed"));
  FrameLimits limits;
  limits.max_lidar_points = 1;
  EXPECT_EQ(ValidateLidarSweep(GoodSweep(1), 0, limits).code(), absl::StatusCode::kResourceExhausted);
  limits = {};
  limits.max_foot_tracks = 1;
  EXPECT_THAT(SweepError(GoodSweep(1), limits), HasSubstr("2 tracks (at most 1)"));
  // A label byte past the track count is not the server's business: the bytes are forwarded.
  s = GoodSweep(1);
  s.mutable_foreground()->set_packed(std::string(16, '\xFF'));
  EXPECT_TRUE(ValidateLidarSweep(s, 0, {}).ok());
}

TEST(ValidateHello, LidarHelloCarriesNoIntrinsicsAndKindsAreKnown) {
  v1::SensorHello hello;
  hello.set_camera_id("hdl64");
  hello.set_token("t");
  hello.set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
  EXPECT_TRUE(ValidateHello(hello).ok());
  *hello.mutable_intrinsics() = Intrinsics(64, 48);
  EXPECT_THAT(std::string(ValidateHello(hello).message()), HasSubstr("lidar 'hdl64': hello.intrinsics must be absent"));
  hello.set_kind(static_cast<v1::SensorKind>(9));
  EXPECT_THAT(std::string(ValidateHello(hello).message()), HasSubstr("hello.kind 9"));
  // A camera hello from an agent that predates issue 16 (no kind) is what it always was.
  hello.clear_kind();
  EXPECT_TRUE(ValidateHello(hello).ok());
}

}  // namespace
}  // namespace ave
