#include "fusion_server/core/validation.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

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

}  // namespace
}  // namespace ave
