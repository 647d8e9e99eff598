// Issue 19, seventeenth session: one image segment measures one model line at most. Two model lines
// whose images lie a few pixels apart and parallel (a near roof edge in front of a far one) both
// reached the one segment detected there, and the one it was not took the other's edge as its own
// on every keyframe (the walk at 82.5 s: 4 px off for a second, then a 10 m slide). Real parts: the
// VisionTracker's keyframe (Fast Line Detector, its refinement, the EKF updates) on a drawn frame.
#include <optional>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include "sensor_agent/pose/vision.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

PinholeIntrinsics Camera() {
  PinholeIntrinsics k;
  k.width = 640, k.height = 480, k.fx = 500, k.fy = 500, k.cx = 320, k.cy = 240;
  return k;
}

// A model point at pixel (u, v) and depth z of the identity camera (x right, y down, z forward).
Eigen::Vector3d At(double u, double v, double z) { return {(u - 320) / 500 * z, (v - 240) / 500 * z, z}; }

LineFeature Line(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  LineFeature f;
  f.a = a, f.b = b;
  f.line = Line3d{a, (b - a).normalized()};
  return f;
}

// A bright panel on a dark frame: its top edge at v = 200 (u 150-490), its left edge at u = 150.
cv::Mat Frame() {
  cv::Mat bgr(480, 640, CV_8UC3, cv::Scalar(60, 60, 60));
  cv::rectangle(bgr, cv::Point(150, 200), cv::Point(490, 420), cv::Scalar(210, 210, 210), cv::FILLED);
  return bgr;
}

// The far line lies on the top edge 50 m away, the near one 35 m away projects 1.5 px below it
// (within the match window of the same segment), and the left edge's line stands alone.
FeatureMap Map() {
  FeatureMap map;
  map.lines.push_back(Line(At(160, 200, 50), At(480, 200, 50)));    // 0: far, on the edge
  map.lines.push_back(Line(At(170, 201.5, 35), At(470, 201.5, 35)));  // 1: near, 1.5 px off it
  map.lines.push_back(Line(At(150, 215, 50), At(150, 400, 50)));    // 2: the left edge, alone
  return map;
}

struct Keyframe {
  VisionFrameStats stats;
  std::vector<int> matched;  // model lines applied, by index
};

Keyframe RunKeyframe(const VisionOptions& changes) {
  VisionOptions options = changes;
  options.relocalize_extent_m = 0;  // the identity pose is the truth here
  const FeatureMap map = Map();
  VisionTracker vision(map, TriangleMesh{}, Camera(), options);
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(), 0.05, 0.05 * kDeg);
  cv::Mat frame = Frame();
  Keyframe out;
  out.stats = vision.Update(frame.data, frame.cols, frame.rows, ekf);
  for (const VisionFrameStats::LineMatch& m : out.stats.line_matches)
    for (size_t i = 0; i < map.lines.size(); ++i)
      if (m.a == map.lines[i].a && m.b == map.lines[i].b) out.matched.push_back(static_cast<int>(i));
  return out;
}

TEST(VisionLines, ASegmentTwoModelLinesReachGoesToTheClearlyNearerOne) {
  const Keyframe k = RunKeyframe(VisionOptions());
  EXPECT_TRUE(k.stats.keyframe);
  EXPECT_EQ(k.matched, (std::vector<int>{0, 2})) << "the far line keeps its edge, the near one (1.5 px off) is left without";
  EXPECT_EQ(k.stats.rejected_ambiguous, 1);
  // The applied top-edge segment is the drawn edge, not moved onto the near line's prediction.
  for (const VisionFrameStats::LineMatch& m : k.stats.line_matches) {
    if (m.a != Map().lines[0].a) continue;
    EXPECT_NEAR(m.image_a.y(), 199.5, 0.5);  // the step between rows 199 and 200
    EXPECT_NEAR(m.image_b.y(), 199.5, 0.5);
  }
}

TEST(VisionLines, ASegmentNeitherLineIsClearlyNearerToGoesToNeither) {
  VisionOptions options;
  options.line_ambiguity_ratio = 0;  // never clear: a shared segment goes to no line
  const Keyframe k = RunKeyframe(options);
  EXPECT_EQ(k.matched, (std::vector<int>{2})) << "only the line alone at its edge is measured";
  EXPECT_EQ(k.stats.rejected_ambiguous, 2);
}

// Degenerate: two model lines whose images coincide (one 50 m away, one on the same rays at 35 m)
// lie on the segment at the same distance: a tie, so the segment goes to neither, and nothing
// becomes NaN. (The comparison is strict so that an exact tie at distance 0 is refused too; the
// detected edge here sits a fraction of a pixel off, so this frame does not reach that case.)
TEST(VisionLines, TwoLinesWithTheSameImageGoToNeither) {
  FeatureMap map;
  map.lines.push_back(Line(At(160, 199.5, 50), At(480, 199.5, 50)));
  map.lines.push_back(Line(At(160, 199.5, 35), At(480, 199.5, 35)));
  VisionOptions options;
  options.relocalize_extent_m = 0;
  VisionTracker vision(map, TriangleMesh{}, Camera(), options);
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(), 0.05, 0.05 * kDeg);
  cv::Mat frame = Frame();
  const VisionFrameStats s = vision.Update(frame.data, frame.cols, frame.rows, ekf);
  EXPECT_TRUE(s.line_matches.empty());
  EXPECT_EQ(s.rejected_ambiguous, 2);
  EXPECT_TRUE(ekf.covariance().allFinite());
}

// Issue 19, eighteenth session: a segment that reaches far beyond a model line's image is another
// straight edge, not that line (the walk at 84.2 s: a 6 m building corner, 83 px in the image, took
// the lens occluder's 150 px side and followed it 18 px off in 0.8 s). Here a model line 60 px long
// on the panel's 220 px left edge: refused, counted; matched when the check is off. The edge
// overhanging the line of the first test by 35 px (less than 8 px + 20 % of its 185 px) still is.
TEST(VisionLines, ASegmentReachingFarBeyondTheLinesImageIsNotThatLine) {
  FeatureMap map;
  map.lines.push_back(Line(At(150, 300, 50), At(150, 360, 50)));
  auto run = [&](double max_overhang_px) {
    VisionOptions options;
    options.relocalize_extent_m = 0;
    options.line_max_overhang_px = max_overhang_px;
    options.max_alignment_score_px = 0;  // one short line is too little outline for the whole frame's fit test
    VisionTracker vision(map, TriangleMesh{}, Camera(), options);
    PoseEkf ekf;
    ekf.Initialize(0, Rigid3d(), 0.05, 0.05 * kDeg);
    cv::Mat frame = Frame();
    return vision.Update(frame.data, frame.cols, frame.rows, ekf);
  };
  const VisionFrameStats checked = run(VisionOptions().line_max_overhang_px);
  EXPECT_TRUE(checked.line_matches.empty());
  EXPECT_EQ(checked.rejected_overhang, 1);
  const VisionFrameStats unchecked = run(0);
  EXPECT_EQ(unchecked.line_matches.size(), 1u);
  EXPECT_EQ(unchecked.rejected_overhang, 0);
  const Keyframe first = RunKeyframe(VisionOptions());
  EXPECT_EQ(first.stats.rejected_overhang, 0);
}

}  // namespace
}  // namespace ave::pose
