#include "sensor_agent/calibrate/calibrate.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/scene/intrinsics_file.h"

namespace ave::calib {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr int kCols = 9, kRows = 6;     // inner corners
constexpr double kSquare_m = 0.04;
constexpr int kPxPerSquare = 40;        // resolution of the flat board texture

// The true camera the synthetic images are taken with.
const cv::Matx33d kK(620, 0, 322, 0, 615, 236, 0, 0, 1);

// A board of (kCols + 1) x (kRows + 1) squares with a white margin of one square.
cv::Mat BoardTexture() {
  const int w = (kCols + 3) * kPxPerSquare, h = (kRows + 3) * kPxPerSquare;
  cv::Mat board(h, w, CV_8UC1, cv::Scalar(255));
  for (int r = 0; r < kRows + 1; ++r) {
    for (int c = 0; c < kCols + 1; ++c) {
      if ((r + c) % 2 == 0) continue;
      cv::rectangle(board, cv::Rect((c + 1) * kPxPerSquare, (r + 1) * kPxPerSquare, kPxPerSquare, kPxPerSquare), cv::Scalar(0), cv::FILLED);
    }
  }
  return board;
}

// The board seen by kK with the board rotated by (rx, ry, rz) radians about its centre and that
// centre at `centre_m` in the camera frame: image = K [r1 r2 t] S texture, by warpPerspective.
cv::Mat View(const cv::Mat& board, double rx, double ry, double rz, const cv::Vec3d& centre_m) {
  cv::Matx33d R;
  cv::Rodrigues(cv::Vec3d(rx, ry, rz), R);
  const double m_per_px = kSquare_m / kPxPerSquare;
  // Texture pixel -> board metres with the origin at the board centre.
  const cv::Matx33d S(m_per_px, 0, -0.5 * board.cols * m_per_px, 0, m_per_px, -0.5 * board.rows * m_per_px, 0, 0, 1);
  const cv::Matx33d Rt(R(0, 0), R(0, 1), centre_m[0], R(1, 0), R(1, 1), centre_m[1], R(2, 0), R(2, 1), centre_m[2]);
  const cv::Matx33d H = kK * Rt * S;
  cv::Mat image;
  cv::warpPerspective(board, image, cv::Mat(H), cv::Size(640, 480), cv::INTER_AREA, cv::BORDER_CONSTANT, cv::Scalar(128));
  return image;
}

class CalibrateTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("ave_calibrate_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  void Write(int i, const cv::Mat& image) { ASSERT_TRUE(cv::imwrite((dir_ / ("view_" + std::to_string(i) + ".png")).string(), image)); }
  std::vector<std::string> Files() const { return GlobFiles((dir_ / "*.png").string()); }
  fs::path dir_;
};

BoardSpec Board() { return {kCols, kRows, kSquare_m}; }

TEST_F(CalibrateTest, RecoversTheIntrinsicsOfSyntheticTiltedViews) {
  const cv::Mat board = BoardTexture();
  const double tilts[][3] = {{0.35, 0.0, 0.05}, {-0.35, 0.1, -0.1}, {0.0, 0.4, 0.0},  {0.1, -0.4, 0.2},
                             {0.3, 0.3, -0.05}, {-0.3, -0.3, 0.1}, {0.2, -0.15, 0.3}, {-0.15, 0.25, -0.3}};
  int i = 0;
  for (const auto& t : tilts) {
    Write(i, View(board, t[0], t[1], t[2], cv::Vec3d(0.02 * (i % 3 - 1), 0.015 * (i % 2), 0.55 + 0.03 * i)));
    ++i;
  }
  Write(i, cv::Mat(480, 640, CV_8UC1, cv::Scalar(90)));  // no board: skipped, named
  const auto r = CalibrateFromImages(Files(), Board());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->images_given, 9);
  EXPECT_EQ(r->images_used, 8);
  ASSERT_EQ(r->skipped.size(), 1u);
  EXPECT_THAT(r->skipped[0], HasSubstr("no 9x6 chessboard found"));
  const PinholeIntrinsics& k = r->intrinsics;
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
  EXPECT_NEAR(k.fx, 620, 620 * 0.01);
  EXPECT_NEAR(k.fy, 615, 615 * 0.01);
  EXPECT_NEAR(k.cx, 322, 4);
  EXPECT_NEAR(k.cy, 236, 4);
  EXPECT_NEAR(k.distortion[0], 0, 0.05);
  EXPECT_LT(r->rms_px, 0.5);
  EXPECT_THAT(SummaryJson(*r, "cam.yaml"), HasSubstr("\"images_used\":8,\"image_size\":[640,480]"));
  // The written file reads back as the same intrinsics.
  const std::string yaml = (dir_ / "cam.yaml").string();
  ASSERT_TRUE(WriteIntrinsicsFile(yaml, k, r->rms_px, r->images_used).ok());
  const auto back = ReadIntrinsicsFile(yaml);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_NEAR(back->fx, k.fx, 1e-6);
  EXPECT_NEAR(back->cy, k.cy, 1e-6);
  EXPECT_NEAR(back->distortion[1], k.distortion[1], 1e-9);
}

TEST_F(CalibrateTest, RefusesTooFewViews) {
  const cv::Mat board = BoardTexture();
  Write(0, View(board, 0.3, 0.1, 0, cv::Vec3d(0, 0, 0.6)));
  Write(1, View(board, -0.2, 0.3, 0, cv::Vec3d(0, 0, 0.6)));
  const auto r = CalibrateFromImages(Files(), Board());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("too few views: the board was found in 2 of 2 images"));
}

TEST_F(CalibrateTest, RefusesAllParallelViews) {
  const cv::Mat board = BoardTexture();
  for (int i = 0; i < 5; ++i) Write(i, View(board, 0, 0, 0.1 * i, cv::Vec3d(0.03 * (i - 2), 0.02 * (i % 2), 0.5 + 0.05 * i)));
  const auto r = CalibrateFromImages(Files(), Board());
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("all 5 views are parallel"));
}

TEST(BoardSize, ParsesColsByRowsOnly) {
  int c = 0, r = 0;
  EXPECT_TRUE(ParseBoardSize("9x6", c, r));
  EXPECT_EQ(c, 9);
  EXPECT_EQ(r, 6);
  EXPECT_FALSE(ParseBoardSize("9*6", c, r));
  EXPECT_FALSE(ParseBoardSize("9x", c, r));
  EXPECT_FALSE(ParseBoardSize("9x6x2", c, r));
  EXPECT_THAT((BoardSpec{6, 6, 0.02}.Check()), HasSubstr("ambiguous"));
  EXPECT_THAT((BoardSpec{9, 6, 0}.Check()), HasSubstr("square size"));
}

TEST(IntrinsicsFile, ErrorsNameTheFileLineAndField) {
  const auto typo = ParseIntrinsicsYaml("width: 640\nheight: 480\nfx: 500\nfy: 500\ncx: 319.5\ncy: 239.5\nfxx: 1\n", "cam.yaml");
  ASSERT_FALSE(typo.ok());
  EXPECT_THAT(typo.status().message(), HasSubstr("cam.yaml:7: intrinsics.fxx"));
  const auto negative = ParseIntrinsicsYaml("width: 640\nheight: 480\nfx: -5\nfy: 500\ncx: 319.5\ncy: 239.5\n", "cam.yaml");
  ASSERT_FALSE(negative.ok());
  EXPECT_THAT(negative.status().message(), HasSubstr("intrinsics.fx"));
  const auto missing = ParseIntrinsicsYaml("width: 640\nheight: 480\nfx: 500\n", "cam.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.status().message(), HasSubstr("fy"));
  EXPECT_FALSE(ReadIntrinsicsFile("/nonexistent/cam.yaml").ok());
}

}  // namespace
}  // namespace ave::calib
