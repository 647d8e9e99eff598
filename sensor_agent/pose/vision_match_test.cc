// The coarse pass's image alignment (vision_match.h): offset and turn about the principal point.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "sensor_agent/pose/vision_match.h"

namespace ave::pose::internal {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Outlines of a few rectangles (a skyline of boxes) as model-edge samples every 4 px.
std::vector<Eigen::Vector2d> BoxEdges() {
  const std::vector<cv::Rect2d> boxes = {{40, 180, 120, 260}, {200, 120, 90, 320}, {330, 220, 160, 220}, {520, 160, 80, 280}};
  std::vector<Eigen::Vector2d> samples;
  for (const cv::Rect2d& b : boxes) {
    for (double t = 0; t <= 1.0; t += 4.0 / b.width) {
      samples.emplace_back(b.x + t * b.width, b.y);
      samples.emplace_back(b.x + t * b.width, b.y + b.height);
    }
    for (double t = 0; t <= 1.0; t += 4.0 / b.height) {
      samples.emplace_back(b.x, b.y + t * b.height);
      samples.emplace_back(b.x + b.width, b.y + t * b.height);
    }
  }
  return samples;
}

// A 640x480 frame showing the boxes moved by `motion` (filled polygons: their outlines are the edges).
cv::Mat Frame(const ImageAlignment& motion, const Eigen::Vector2d& centre) {
  cv::Mat gray(480, 640, CV_8U, cv::Scalar(200));
  const std::vector<cv::Rect2d> boxes = {{40, 180, 120, 260}, {200, 120, 90, 320}, {330, 220, 160, 220}, {520, 160, 80, 280}};
  int shade = 40;
  for (const cv::Rect2d& b : boxes) {
    std::vector<cv::Point> corners;
    for (const Eigen::Vector2d& c : {Eigen::Vector2d(b.x, b.y), Eigen::Vector2d(b.x + b.width, b.y), Eigen::Vector2d(b.x + b.width, b.y + b.height),
                                     Eigen::Vector2d(b.x, b.y + b.height)}) {
      const Eigen::Vector2d m = motion.Apply(c, centre);
      corners.emplace_back(static_cast<int>(std::lround(m.x() * 16)), static_cast<int>(std::lround(m.y() * 16)));
    }
    cv::fillConvexPoly(gray, corners, cv::Scalar(shade), cv::LINE_AA, 4);
    shade += 35;
  }
  return gray;
}

TEST(ChamferAlign, FindsTheTurnAShiftCannot) {
  const Eigen::Vector2d centre(319.5, 239.5);
  ImageAlignment truth;
  truth.offset = Eigen::Vector2d(7, -4);
  truth.rotation_rad = 2.0 * kPi / 180;  // 2 deg: 8 px at the image's sides
  cv::Mat edge_distance, skyline_distance;
  EdgeDistances(Frame(truth, centre), edge_distance, skyline_distance);
  const std::vector<Eigen::Vector2d> samples = BoxEdges();

  const ImageAlignment shift_only = ChamferAlign(edge_distance, samples, skyline_distance, {}, 60, centre, 0, 0.5 * kPi / 180);
  EXPECT_EQ(shift_only.rotation_rad, 0.0);
  const ImageAlignment found = ChamferAlign(edge_distance, samples, skyline_distance, {}, 60, centre, 3 * kPi / 180, 0.5 * kPi / 180);
  EXPECT_NEAR(found.rotation_rad, truth.rotation_rad, 1e-9) << "on the 0.5 deg grid";
  EXPECT_NEAR(found.offset.x(), truth.offset.x(), 1.0);
  EXPECT_NEAR(found.offset.y(), truth.offset.y(), 1.0);
  EXPECT_LT(found.score_px, shift_only.score_px - 0.5) << "the turn lays the edges down where the shift leaves them 8 px off";
  EXPECT_LT(found.score_px, 1.0);
  // The samples moved by the result land on the frame's edges.
  double worst = 0;
  for (const Eigen::Vector2d& s : samples) {
    const Eigen::Vector2d m = found.Apply(s, centre);
    if (m.x() < 2 || m.y() < 2 || m.x() > 637 || m.y() > 477) continue;
    worst = std::max(worst, static_cast<double>(edge_distance.at<float>(static_cast<int>(std::lround(m.y())), static_cast<int>(std::lround(m.x())))));
  }
  EXPECT_LE(worst, 2.5);
}

TEST(ChamferAlign, NoTurnWhenTheFrameIsNotTurned) {
  const Eigen::Vector2d centre(319.5, 239.5);
  ImageAlignment truth;
  truth.offset = Eigen::Vector2d(-12, 5);
  cv::Mat edge_distance, skyline_distance;
  EdgeDistances(Frame(truth, centre), edge_distance, skyline_distance);
  const ImageAlignment found = ChamferAlign(edge_distance, BoxEdges(), skyline_distance, {}, 60, centre, 3 * kPi / 180, 0.5 * kPi / 180);
  EXPECT_EQ(found.rotation_rad, 0.0);
  EXPECT_NEAR(found.offset.x(), -12, 1.0);
  EXPECT_NEAR(found.offset.y(), 5, 1.0);
}

// Hard cases: too few samples, samples all off the frame, and an empty (edgeless) frame give the
// identity, never a NaN score (+infinity for too few samples: nothing to score).
TEST(ChamferAlign, DegenerateInputsGiveTheIdentity) {
  const Eigen::Vector2d centre(319.5, 239.5);
  cv::Mat edge_distance, skyline_distance;
  EdgeDistances(cv::Mat(480, 640, CV_8U, cv::Scalar(128)), edge_distance, skyline_distance);
  const std::vector<Eigen::Vector2d> few = {{100, 100}, {200, 200}};
  std::vector<Eigen::Vector2d> off_frame;
  for (int i = 0; i < 50; ++i) off_frame.emplace_back(-1e6 - i, 1e6);
  for (const auto& samples : {few, off_frame, BoxEdges()}) {
    const ImageAlignment a = ChamferAlign(edge_distance, samples, skyline_distance, {}, 60, centre, 3 * kPi / 180, 0.5 * kPi / 180);
    EXPECT_EQ(a.rotation_rad, 0.0);
    EXPECT_EQ(a.offset, Eigen::Vector2d::Zero());
    EXPECT_FALSE(std::isnan(a.score_px));
    // Two samples are nothing to score: never a good fit (a relocalisation candidate must not win by it).
    EXPECT_EQ(std::isinf(a.score_px), samples.size() < 10);
  }
}

}  // namespace
}  // namespace ave::pose::internal
