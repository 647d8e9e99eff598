// The coarse pass's image alignment (vision_match.h): offset and turn about the principal point;
// corners located where their model edges meet.
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

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

// A gable's apex as a far camera sees it: a dark roof (apex angle 80 deg) against a bright sky,
// each pixel's grey the share of its area (8x8 samples; pixel centres at integer coordinates, as
// OpenCV's corner functions and SearchEdge read them) under the roof, then blurred (sigma 1 px: a
// lens and a resampled frame). `apex` is where the sides meet; the unit directions of its two sides
// point away from it.
cv::Mat Gable(const Eigen::Vector2d& apex, std::vector<Eigen::Vector2d>& sides) {
  const double half = 40.0 * kPi / 180;
  sides = {Eigen::Vector2d(-std::sin(half), std::cos(half)), Eigen::Vector2d(std::sin(half), std::cos(half))};
  cv::Mat grey(160, 160, CV_32F);
  for (int y = 0; y < grey.rows; ++y) {
    for (int x = 0; x < grey.cols; ++x) {
      int under = 0;
      for (int i = 0; i < 64; ++i) {
        const Eigen::Vector2d r = Eigen::Vector2d(x + (i % 8 + 0.5) / 8 - 0.5, y + (i / 8 + 0.5) / 8 - 0.5) - apex;
        // Below both sides: on the inner side of each (the side's normal pointing into the roof).
        under += (sides[0].x() * r.y() - sides[0].y() * r.x()) <= 0 && (sides[1].x() * r.y() - sides[1].y() * r.x()) >= 0;
      }
      grey.at<float>(y, x) = static_cast<float>(210 - 140 * under / 64.0);
    }
  }
  cv::GaussianBlur(grey, grey, cv::Size(0, 0), 1.0);
  cv::Mat gray;
  grey.convertTo(gray, CV_8U);
  return gray;
}

TEST(CornerOnEdges, FindsABlurredApexWhereTheCornerDetectorDoesNot) {
  const Eigen::Vector2d apex(80.3, 50.6);
  std::vector<Eigen::Vector2d> sides;
  const cv::Mat gray = Gable(apex, sides);
  // The detector's corner, as the keyframe finds it: off the apex, inside the roof's wedge.
  std::vector<cv::Point2f> detected;
  cv::goodFeaturesToTrack(gray, detected, 1, 0.005, 3);
  ASSERT_EQ(detected.size(), 1u);
  cv::cornerSubPix(gray, detected, cv::Size(4, 4), cv::Size(-1, -1), cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 20, 0.03));
  const Eigen::Vector2d seed(detected[0].x, detected[0].y);
  EXPECT_GT(seed.y() - apex.y(), 0.2) << "the premise: a gradient corner sits inside a blurred wedge, at " << seed.transpose();

  const std::optional<Eigen::Vector2d> met = CornerOnEdges(gray, seed, sides, 10, 2.0, 8.0, 3.0);
  ASSERT_TRUE(met.has_value());
  EXPECT_LT((*met - apex).norm(), 0.1) << "found at " << met->transpose() << ", detected at " << seed.transpose();
  // From a seed 2 px off along an edge, and with a third model edge that the frame does not show
  // (hidden behind the roof), the same place.
  const std::vector<Eigen::Vector2d> with_hidden = {sides[0], Eigen::Vector2d(0, -1), sides[1]};
  const std::optional<Eigen::Vector2d> again = CornerOnEdges(gray, apex + sides[0] * 2.0, with_hidden, 10, 2.0, 8.0, 3.0);
  ASSERT_TRUE(again.has_value());
  EXPECT_LT((*again - apex).norm(), 0.1);
}

// Where the model's edges are not in the frame, nothing is found: a blank frame, a single edge, two
// nearly parallel edges, a seed off the image or not a number, directions not a number or zero, and
// a meeting point beyond max_move_px.
TEST(CornerOnEdges, NothingWhereTheEdgesAreNotFound) {
  const Eigen::Vector2d apex(80.3, 50.6);
  std::vector<Eigen::Vector2d> sides;
  const cv::Mat gray = Gable(apex, sides);
  EXPECT_FALSE(CornerOnEdges(cv::Mat(160, 160, CV_8U, cv::Scalar(128)), apex, sides, 10, 2.0, 8.0, 3.0));
  EXPECT_FALSE(CornerOnEdges(gray, apex, {sides[0]}, 10, 2.0, 8.0, 3.0));
  const Eigen::Vector2d tilted = Eigen::Rotation2Dd(0.1) * sides[0];  // 6 deg from the first side
  EXPECT_FALSE(CornerOnEdges(gray, apex, {sides[0], tilted}, 10, 2.0, 8.0, 3.0));
  EXPECT_FALSE(CornerOnEdges(gray, Eigen::Vector2d(-1e6, 1e6), sides, 10, 2.0, 8.0, 3.0));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(CornerOnEdges(gray, Eigen::Vector2d(nan, nan), sides, 10, 2.0, 8.0, 3.0));
  EXPECT_FALSE(CornerOnEdges(gray, apex, {Eigen::Vector2d(nan, 0), Eigen::Vector2d::Zero()}, 10, 2.0, 8.0, 3.0));
  EXPECT_FALSE(CornerOnEdges(gray, apex + sides[0] * 1.5, sides, 10, 2.0, 8.0, 1.0));
}

}  // namespace
}  // namespace ave::pose::internal
