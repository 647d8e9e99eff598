#include "sensor_agent/pose/vision.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/geometry/bvh.h"
#include "sensor_agent/pose/so3.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

double MedianMisregistration(const PinholeIntrinsics& k, const Rigid3d& truth, const Rigid3d& estimate, const std::vector<Eigen::Vector3d>& points) {
  std::vector<double> e;
  for (const auto& p : points) {
    const auto a = ProjectToPixel(k, truth.Inverse() * p), b = ProjectToPixel(k, estimate.Inverse() * p);
    e.push_back(a && b ? (*a - *b).norm() : 1e9);
  }
  std::sort(e.begin(), e.end());
  return e.empty() ? 1e9 : e[e.size() / 2];
}

class VisionTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto s = sim::LoadScenario("campus");
    ASSERT_TRUE(s.ok()) << s.status();
    scenario_ = new sim::Scenario(std::move(*s));
  }
  static void TearDownTestSuite() { delete scenario_; }
  // The front end on the campus's feature map and static mesh.
  static VisionTracker CampusTracker(const PinholeIntrinsics& k, const VisionOptions& options = VisionOptions()) {
    return VisionTracker(CampusFeatureMap(scenario_->world), scene::BuildStaticMesh(scenario_->world, 2.0), k, options);
  }
  // The backpack's frame at 4 s (frame 120) and its true pose: most tests' keyframe.
  struct View {
    sim::SimImage frame;
    Rigid3d truth;
  };
  static View BackpackAt4s() {
    const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
    const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
    return {sim_camera.Frame(120, 4.0), sim_camera.PoseAt(4.0)};
  }
  // A backpack tracker with `options`, `ekf` started at `start` with these sigmas, and the stats of
  // its first frame.
  static VisionFrameStats FirstFrame(const VisionOptions& options, const sim::SimImage& frame, const Rigid3d& start, double position_sigma_m,
                                     double orientation_sigma_rad, PoseEkf& ekf) {
    VisionTracker vision = CampusTracker(scenario_->world.FindCamera("backpack")->intrinsics, options);
    ekf.Initialize(0, start, position_sigma_m, orientation_sigma_rad);
    return vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
  }
  // `truth` turned by `turn_deg` (world rotation vector, degrees) and moved by `offset_m`.
  static Rigid3d Off(const Rigid3d& truth, const Eigen::Vector3d& turn_deg, const Eigen::Vector3d& offset_m) {
    return Rigid3d(SO3Exp(turn_deg * kDeg) * truth.rotation, truth.translation + offset_m);
  }
  // The relocalisation tests' start: as GPS multipath among the buildings leaves it (2.3 m and
  // 1.6 m off, turned 0.2-0.3 deg).
  static Rigid3d MultipathStart(const Rigid3d& truth) { return Off(truth, {0.2, 0.3, -0.2}, {2.3, -1.6, 0}); }
  static sim::Scenario* scenario_;
};
sim::Scenario* VisionTest::scenario_ = nullptr;

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d ClosestOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = 1 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// The feature map is the campus's own wireframe: every point on a building's surface, and every
// line along an edge where two of its faces meet at an angle (a shed's high wall ends at the
// roof's high edge, a gable end has no eaves; issue 19, tenth session: the old map put both at the
// eaves, and their corners were matched 1-2 px off at every keyframe).
TEST_F(VisionTest, CampusFeatureMapIsTheBuildingsWireframe) {
  const FeatureMap map = CampusFeatureMap(scenario_->world);
  const TriangleMesh mesh = scene::BuildStaticMesh(scenario_->world, 2.0);
  auto face_normals_near = [&](const Eigen::Vector3d& x) {
    std::vector<Eigen::Vector3d> normals;
    for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
      if (mesh.triangle_object[t] < 0) continue;  // terrain
      const Eigen::Vector3d a = mesh.positions[mesh.indices[3 * t]].cast<double>(), b = mesh.positions[mesh.indices[3 * t + 1]].cast<double>(),
                            c = mesh.positions[mesh.indices[3 * t + 2]].cast<double>();
      if ((ClosestOnTriangle(x, a, b, c) - x).norm() > 0.01) continue;
      const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
      if (std::none_of(normals.begin(), normals.end(), [&](const Eigen::Vector3d& m) { return m.dot(n) > std::cos(5 * kDeg); })) normals.push_back(n);
    }
    return normals;
  };
  int rectangular = 0, sheds = 0, gables = 0;
  for (const auto& b : scenario_->world.buildings) {
    for (const auto& part : b.Parts()) {
      rectangular += part.kind != scene::PrimitiveKind::kCylinder && part.kind != scene::PrimitiveKind::kDome;
      sheds += part.kind == scene::PrimitiveKind::kShed;
      gables += part.kind == scene::PrimitiveKind::kGable;
    }
  }
  ASSERT_GT(sheds, 0);
  ASSERT_GT(gables, 0);
  EXPECT_GE(map.points.size(), 8u * rectangular);
  for (const Eigen::Vector3d& p : map.points) EXPECT_FALSE(face_normals_near(p).empty()) << "point " << p.transpose() << " is on no building";
  for (const LineFeature& l : map.lines) {
    EXPECT_NEAR(l.line.direction.norm(), 1.0, 1e-12);
    EXPECT_LT((l.b - l.a).normalized().cross(l.line.direction).norm(), 1e-9);
    for (double s : {0.25, 0.5, 0.75}) {
      const Eigen::Vector3d x = l.a + s * (l.b - l.a);
      EXPECT_GE(face_normals_near(x).size(), 2u) << "line " << l.a.transpose() << " -> " << l.b.transpose() << " is not an edge at " << s;
    }
  }
}

TEST_F(VisionTest, StabilisesAPerturbedBackpackPoseToAFewPixels) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  const double t = 4.0;
  const sim::SimImage frame = sim_camera.Frame(120, t);
  const Rigid3d truth = sim_camera.PoseAt(t);
  VisionTracker vision = CampusTracker(camera.intrinsics);
  const std::vector<Eigen::Vector3d> visible = vision.VisiblePoints(truth);
  ASSERT_GE(visible.size(), 6u);
  PoseEkf ekf;
  const Rigid3d start = Off(truth, {0.5, -0.8, 1.5}, {0.4, -0.3, 0.1});
  ekf.Initialize(0, start, 0.5, 2 * kDeg);
  const double before = MedianMisregistration(camera.intrinsics, truth, start, visible);
  EXPECT_GT(before, 10);
  VisionFrameStats stats = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
  EXPECT_GE(stats.points_used + stats.lines_used, 6);
  EXPECT_EQ(stats.points_predicted, static_cast<int>(vision.VisiblePoints(start).size()));
  const double after = MedianMisregistration(camera.intrinsics, truth, ekf.world_from_camera(), visible);
  if (const char* dir = std::getenv("AVE_POSE_PNG_DIR")) {  // true (green), start (red), corrected (blue)
    cv::Mat image;
    cv::resize(cv::Mat(frame.height, frame.width, CV_8UC3, const_cast<uint8_t*>(frame.bgr.data())), image, {}, 3, 3, cv::INTER_NEAREST);
    for (int v = 1; v < frame.height; ++v)
      for (int u = 1; u < frame.width; ++u)
        if (frame.object_id[frame.Index(u, v)] != frame.object_id[frame.Index(u - 1, v)] || frame.object_id[frame.Index(u, v)] != frame.object_id[frame.Index(u, v - 1)])
          cv::rectangle(image, cv::Rect(3 * u, 3 * v, 3, 3), cv::Scalar(0, 255, 255), cv::FILLED);
    for (const auto& p : visible) {
      const std::pair<Rigid3d, cv::Scalar> poses[] = {{truth, {0, 255, 0}}, {start, {0, 0, 255}}, {ekf.world_from_camera(), {255, 0, 0}}};
      for (const auto& [pose, colour] : poses) {
        if (const auto uv = ProjectToPixel(camera.intrinsics, pose.Inverse() * p)) cv::circle(image, cv::Point2d(3 * uv->x() + 1, 3 * uv->y() + 1), 6, colour, 1);
      }
    }
    cv::imwrite(std::string(dir) + "/pose_vision_test.png", image(cv::Rect(0, 0, 1920, 720)));
  }
  EXPECT_LT(after, 2.0) << "before " << before << " px; used " << stats.points_used << " points, " << stats.lines_used << " lines";
  // A frame of the wrong size is ignored.
  const Rigid3d pose = ekf.world_from_camera();
  stats = vision.Update(frame.bgr.data(), frame.width / 2, frame.height, ekf);
  EXPECT_EQ(stats.features_used(), 0);
  EXPECT_TRUE(ekf.world_from_camera().translation.isApprox(pose.translation));
}

// Issue 19 (moonshot): unknown features cost ~1 ms a frame, so they are tracked only when something
// uses them (joint mode, the issue-5 mode, or use_new_points for their figures).
TEST_F(VisionTest, UnknownFeaturesAreTrackedOnlyWhenSomethingUsesThem) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  auto tracked = [&](const VisionOptions& options) {
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    const int first = 120;
    ekf.Initialize(static_cast<int64_t>(std::llround(first * 1e9 / 30)), sim_camera.PoseAt(first / 30.0), 0.3, 0.5 * kDeg);
    int most = 0;
    for (int f = first; f < first + 4; ++f) {
      sim::SimImage frame = sim_camera.Frame(f, f / 30.0);
      ekf.Predict(static_cast<int64_t>(std::llround(f * 1e9 / 30)));
      const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
      EXPECT_EQ(s.new_points_tracked, static_cast<int>(s.unknown_tracks.size()));
      most = std::max(most, s.new_points_tracked);
    }
    return most;
  };
  VisionOptions known_only, joint, figures;
  joint.joint_new_points = true;
  figures.use_new_points = true;
  EXPECT_EQ(tracked(known_only), 0);
  EXPECT_GT(tracked(joint), 20);
  EXPECT_GT(tracked(figures), 20);
}

// Issue 19 (moonshot): the Fast Line Detector (default) and LSD both find the model's edges on a
// keyframe, and each stabilises the perturbed pose.
TEST_F(VisionTest, BothSegmentDetectorsMatchTheModelLinesAndStabiliseThePose) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = Off(truth, {0.5, -0.8, 1.5}, {0.4, -0.3, 0.1});
  for (const SegmentDetector detector : {SegmentDetector::kFastLine, SegmentDetector::kLsd}) {
    VisionOptions options;
    options.segment_detector = detector;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.5, 2 * kDeg);
    const VisionFrameStats stats = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    const int which = static_cast<int>(detector);
    EXPECT_GE(stats.lines_used, 3) << which;
    EXPECT_GT(stats.stage_ms[kStageSegments], 0) << which;
    EXPECT_LT(MedianMisregistration(camera.intrinsics, truth, ekf.world_from_camera(), vision.VisiblePoints(truth)), 2.0) << which;
  }
}

// Issue 19, sixth session: GPS multipath near buildings leaves the first pose metres off with a
// confident covariance; no image shift or turn undoes the parallax, and the first matches would
// take wrong corners. The relocalisation's position search finds the camera on the first frame.
TEST_F(VisionTest, RelocalisationFindsACameraMetresFromItsGpsPosition) {
  const PinholeIntrinsics& k = scenario_->world.FindCamera("backpack")->intrinsics;
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = MultipathStart(truth);
  auto run = [&](double extent_m, double distinct_px = VisionOptions().relocalize_distinct_px) {
    VisionOptions options;
    options.relocalize_extent_m = extent_m;
    options.relocalize_distinct_px = distinct_px;
    VisionTracker vision = CampusTracker(k, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.3, 1 * kDeg);
    const VisionFrameStats stats = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    return std::make_tuple(stats.relocalized, (ekf.world_from_camera().translation - truth.translation).head<2>().norm(),
                           MedianMisregistration(k, truth, ekf.world_from_camera(), vision.VisiblePoints(truth)));
  };
  const auto [moved, error_m, px] = run(VisionOptions().relocalize_extent_m);
  EXPECT_TRUE(moved);
  EXPECT_LT(error_m, 0.8);
  EXPECT_LT(px, 2.0);
  const auto [moved_off, error_off_m, px_off] = run(0);
  EXPECT_FALSE(moved_off);
  // A best fit that does not stand out from the rest of the grid by relocalize_distinct_px is no
  // reason to move (a flat score landscape: draw 11 of 13 moved 2.6 m the wrong way).
  const auto [moved_flat, error_flat_m, px_flat] = run(VisionOptions().relocalize_extent_m, 100.0);
  EXPECT_FALSE(moved_flat);
  EXPECT_NEAR(error_flat_m, std::hypot(2.3, 1.6), 0.5) << "stays near the start";
  EXPECT_GT(px_off, 2 * px) << "without the search the first frame stays off (" << error_off_m << " m)";
}

// Issue 19, eighteenth session: an AHRS beside a building can be 20 deg off in heading, beyond the
// coarse search's 60 px. The first frame searches the heading and turns the filter to the one the
// model fits; without the search the frame fits nowhere and the pose stays turned.
TEST_F(VisionTest, TheFirstFrameFindsAHeading18DegreesOff) {
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = Off(truth, {0, 0, 18}, {0.3, -0.2, 0});
  auto run = [&](double search_deg) {
    VisionOptions options;
    options.acquisition_heading_search_deg = search_deg;
    PoseEkf ekf;
    const VisionFrameStats stats = FirstFrame(options, frame, start, 0.3, 2 * kDeg, ekf);
    return std::make_pair(stats.reoriented_heading_deg, AngleBetweenDeg(ekf.world_from_camera().rotation, truth.rotation));
  };
  const auto [turned_deg, error_deg] = run(VisionOptions().acquisition_heading_search_deg);
  EXPECT_NEAR(turned_deg, -18, 4.5);
  EXPECT_LT(error_deg, 2.0);
  const auto [unturned_deg, unturned_error_deg] = run(0);
  EXPECT_EQ(unturned_deg, 0);
  EXPECT_GT(unturned_error_deg, 10.0) << "without the search the pose stays turned";
}

// Issue 19, eleventh session: a first frame whose view the model fits well nowhere (two draws of
// 13: a tree over the façades' tops) let a wrong position score best by chance, 3 m off. Such a
// relocalisation is not believed: the frame applies nothing, says it is waiting, and the search
// runs again on the next frame, which finds the camera.
TEST_F(VisionTest, RelocalisationWaitsForAFrameTheModelFitsWell) {
  const PinholeIntrinsics& k = scenario_->world.FindCamera("backpack")->intrinsics;
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = MultipathStart(truth);
  sim::SimImage flipped = frame;
  cv::Mat image(flipped.height, flipped.width, CV_8UC3, flipped.bgr.data());
  cv::flip(image.clone(), image, -1);
  // The flipped frame first, then the true frame `more` times; each frame's stats, and how far the
  // first moved the filter and the last left it from the truth.
  auto run = [&](double max_score_px, int retry_frames, int more) {
    VisionOptions options;
    options.relocalize_max_score_px = max_score_px;
    options.relocalize_retry_frames = retry_frames;
    VisionTracker vision = CampusTracker(k, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.3, 1 * kDeg);
    std::vector<VisionFrameStats> stats = {vision.Update(flipped.bgr.data(), flipped.width, flipped.height, ekf)};
    const double first_move_m = (ekf.world_from_camera().translation - start.translation).norm();
    for (int i = 0; i < more; ++i) stats.push_back(vision.Update(frame.bgr.data(), frame.width, frame.height, ekf));
    EXPECT_TRUE(ekf.covariance().allFinite());
    return std::make_tuple(stats, first_move_m, (ekf.world_from_camera().translation - truth.translation).head<2>().norm());
  };
  const auto [stats, first_move_m, error_m] = run(VisionOptions().relocalize_max_score_px, 1, 1);
  EXPECT_TRUE(stats[0].relocalize_waiting);
  EXPECT_FALSE(stats[0].relocalized);
  EXPECT_EQ(stats[0].features_used(), 0);
  EXPECT_EQ(stats[0].relocks, 0);
  EXPECT_LT(first_move_m, 0.1) << "nothing applied while waiting";
  EXPECT_FALSE(stats[1].relocalize_waiting);
  EXPECT_TRUE(stats[1].relocalized);
  EXPECT_LT(error_m, 0.8);
  // Without the rule the first frame's search is spent on the frame that fits nowhere, and the
  // second starts from the GPS position.
  const auto [stats_off, first_move_off_m, error_off_m] = run(0, 1, 1);
  EXPECT_FALSE(stats_off[0].relocalize_waiting);
  EXPECT_FALSE(stats_off[1].relocalized);
  EXPECT_GT(error_off_m, 2 * error_m + 0.5);
  // Searching again every third frame: the two frames between wait without a search (nothing
  // applied, no keyframe detection), the third searches and finds the camera.
  const auto [stats_3, first_move_3_m, error_3_m] = run(VisionOptions().relocalize_max_score_px, 3, 3);
  for (int i : {1, 2}) {
    EXPECT_TRUE(stats_3[i].relocalize_waiting) << i;
    EXPECT_EQ(stats_3[i].features_used(), 0) << i;
    EXPECT_EQ(stats_3[i].stage_ms[kStageCorners], 0) << i;
  }
  EXPECT_TRUE(stats_3[3].relocalized);
  EXPECT_LT(error_3_m, 0.8);
}

// Issue 19, nineteenth session: at 83 s the backpack looks over grass at a few far façades. A pose
// declared lost there relocalised by the chamfer score of that thin outline, metres from where GPS
// and the gyro had held it. A thin view (min_view_points) waits instead, applying nothing.
TEST_F(VisionTest, AThinViewDoesNotRelocalise) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const PinholeIntrinsics& k = camera.intrinsics;
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  const sim::SimImage thin = sim_camera.Frame(2490, 83.0);
  const Rigid3d truth = sim_camera.PoseAt(83.0);
  const Rigid3d start = Off(truth, {0, 0, 0.3}, {0.8, -0.6, 0});
  ASSERT_LT(CampusTracker(k).VisiblePoints(truth).size(), static_cast<size_t>(VisionOptions().min_view_points)) << "the view is thin";
  auto first_frame = [&](int min_view_points) {
    VisionOptions options;
    options.min_view_points = min_view_points;
    PoseEkf ekf;
    const VisionFrameStats stats = FirstFrame(options, thin, start, 1.0, 1 * kDeg, ekf);
    EXPECT_TRUE(ekf.covariance().allFinite());
    return std::make_pair(stats, (ekf.world_from_camera().translation - start.translation).norm());
  };
  const auto [stats, moved_m] = first_frame(VisionOptions().min_view_points);
  EXPECT_TRUE(stats.thin_view);
  EXPECT_TRUE(stats.relocalize_waiting);
  EXPECT_FALSE(stats.relocalized);
  EXPECT_EQ(stats.features_used(), 0);
  EXPECT_LT(moved_m, 1e-9) << "nothing applied while waiting";
  const auto [stats_off, moved_off_m] = first_frame(0);
  EXPECT_FALSE(stats_off.thin_view);
  EXPECT_FALSE(stats_off.relocalize_waiting);
  EXPECT_GT(stats_off.features_used(), 0) << "without the rule the thin frame is searched and its matches applied";
  EXPECT_GT(moved_off_m, 0.01);
}

// Issue 19, eighth session: a GPS height 1.2 m low, taken on far façades as a pitch, left the pose
// low and pitched. A carried camera's height above the static model's ground (carrier_height_m)
// lifts it on the first frame. A filter under the ground finds no ground below and applies nothing.
TEST_F(VisionTest, ACarriedCameraIsHeldAtItsHeightAboveTheGround) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  auto run = [&](double carrier_height_m, double dz_m, double position_sigma_m = 0.6) {
    VisionOptions options;
    options.carrier_height_m = carrier_height_m;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, Rigid3d(SO3Exp(Eigen::Vector3d(0.3 * kDeg, 0, 0)) * truth.rotation, truth.translation + Eigen::Vector3d(0.2, -0.2, dz_m)), position_sigma_m,
                   1 * kDeg);
    const VisionFrameStats stats = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    EXPECT_TRUE(ekf.covariance().allFinite());
    // The same frame again at the same filter time (dt = 0): the height is applied once per time.
    EXPECT_FALSE(vision.Update(frame.bgr.data(), frame.width, frame.height, ekf).height_applied);
    return std::make_pair(stats.height_applied, std::abs(ekf.world_from_camera().translation.z() - truth.translation.z()));
  };
  const auto [applied, error_m] = run(camera.path->height_m, -1.2);
  const auto [applied_off, error_off_m] = run(0, -1.2);
  EXPECT_TRUE(applied);
  EXPECT_FALSE(applied_off);
  EXPECT_LT(error_m, 0.25);
  EXPECT_LT(error_m, 0.5 * error_off_m) << "without the carried height the first frame stays " << error_off_m << " m off";
  // A filter under the terrain (a GPS outage at start-up: only the inertial height, metres off,
  // and a position sigma of tens of metres) finds the ground above it and is lifted onto it; one
  // as sure of its height as a fix makes it is not pulled 6 m by one frame (the chi-square gate).
  const auto [applied_under, error_under_m] = run(camera.path->height_m, -6.0, 30.0);
  EXPECT_TRUE(applied_under) << "the ground above a filter under the terrain";
  EXPECT_LT(error_under_m, 0.3);
  const auto [applied_sure, error_sure_m] = run(camera.path->height_m, -6.0);
  EXPECT_FALSE(applied_sure) << "gated";
  EXPECT_GT(error_sure_m, 1.0);
}

// Issue 19, sixth session: a keyframe on which the model's outline lies nowhere (here the frame
// upside down) applies nothing, and says so; the pose keeps its prediction. With relocalisation on,
// the search does not move the filter to such a fit either.
TEST_F(VisionTest, AFrameTheModelFitsNowhereAppliesNothing) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  auto [elsewhere, truth] = BackpackAt4s();
  cv::Mat image(elsewhere.height, elsewhere.width, CV_8UC3, elsewhere.bgr.data());
  cv::flip(image.clone(), image, -1);
  VisionTracker vision = CampusTracker(camera.intrinsics);
  PoseEkf ekf;
  ekf.Initialize(0, truth, 0.3, 1 * kDeg);
  const VisionFrameStats stats = vision.Update(elsewhere.bgr.data(), elsewhere.width, elsewhere.height, ekf);
  EXPECT_TRUE(stats.unfit);
  EXPECT_FALSE(stats.relocalized);
  EXPECT_EQ(stats.features_used(), 0);
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 1e-9);
  EXPECT_TRUE(ekf.covariance().allFinite());
}

// Issue 19, tenth session: a wall foot's corner (a known point below the camera) is found where
// terrain texture, kerbs and objects meet the wall, 0.6-0.7 px above the true foot at every depth,
// so it weighs foot_variance_scale times less than a wall top. The same keyframe's matches leave the
// pose less certain with the feet weighed down, and nothing changes when the scale is 1.
TEST_F(VisionTest, WallFeetWeighLessThanWallTops) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = Off(truth, {0.2, -0.2, 0.1}, {0.2, -0.1, 0});
  auto run = [&](double foot_scale) {
    VisionOptions options;
    options.foot_variance_scale = foot_scale;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.3, 1 * kDeg);
    const VisionFrameStats stats = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    int feet = 0;
    for (const auto& [p, uv] : stats.point_matches) feet += p.z() < truth.translation.z();
    EXPECT_TRUE(ekf.covariance().allFinite());
    Eigen::Matrix<double, 6, 6> pose_covariance;  // position and orientation, the filter's own
    const StateMatrix& P = ekf.covariance();
    pose_covariance << P.block<3, 3>(kPos, kPos), P.block<3, 3>(kPos, kRot), P.block<3, 3>(kRot, kPos), P.block<3, 3>(kRot, kRot);
    return std::make_tuple(stats.points_used, feet, pose_covariance);
  };
  const auto [used_1, feet_1, p_1] = run(1.0);
  const auto [used_4, feet_4, p_4] = run(4.0);
  const auto [used_1b, feet_1b, p_1b] = run(1.0);
  EXPECT_GE(feet_1, 3) << "the frame shows wall feet";
  EXPECT_EQ(used_1, used_4);
  EXPECT_EQ(feet_1, feet_4);
  // Less information from the feet: the posterior covariance is larger (positive semi-definite
  // difference, and a larger trace), and the same scale twice gives the same filter.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> difference(p_4 - p_1);
  EXPECT_GT(difference.eigenvalues().minCoeff(), -1e-12);
  const double position_4 = p_4.topLeftCorner<3, 3>().trace(), position_1 = p_1.topLeftCorner<3, 3>().trace();
  EXPECT_GT(position_4, 1.02 * position_1);
  EXPECT_LT((p_1b - p_1).norm(), 1e-12);
}

// ... and along their KLT tracks between keyframes (issue 19, thirteenth session: the track's copy
// dropped the keyframe match's variance scale, so on every tracked frame a foot weighed as much as
// a top). The same frame twice, the second tracked: with feet at 4x the variance the tracked frame
// shrinks the position covariance less than at 1x.
TEST_F(VisionTest, WallFeetWeighLessAlongTheirTracksToo) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = Off(truth, {0.05, -0.05, 0.02}, {0.05, -0.1, 0.05});
  auto tracked_shrink = [&](double foot_scale) {
    VisionOptions options;
    options.foot_variance_scale = foot_scale;
    options.lock_frames = 1;  // tracked from the second frame on
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.3, 1 * kDeg);
    const VisionFrameStats key = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    EXPECT_TRUE(key.keyframe);
    const double before = ekf.covariance().block<3, 3>(kPos, kPos).trace();
    const VisionFrameStats tracked = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    EXPECT_FALSE(tracked.keyframe);
    int feet = 0;
    for (const auto& [p, uv] : tracked.point_matches) feet += p.z() < truth.translation.z();
    EXPECT_GE(feet, 3) << "the tracked frame follows wall feet";
    return (before - ekf.covariance().block<3, 3>(kPos, kPos).trace()) / before;
  };
  const double shrink_1 = tracked_shrink(1.0), shrink_4 = tracked_shrink(4.0);
  EXPECT_GT(shrink_1, 0.0);
  EXPECT_LT(shrink_4, 0.9 * shrink_1) << "shrink at 1x " << shrink_1 << ", at 4x " << shrink_4;
}

// Issue 19, fifteenth session: point_bias_gain learns each known point's misfit from its post-fit
// keyframe residuals once the lock holds, and point_bias_weight_px weighs a point down by it. The
// same frame seen again and again, every frame a keyframe, from the true pose: a corner's detection
// error is then the same every time, its whole misfit. No point is at half weight before it has
// three learned residuals; after, those whose corner is found 0.5 px or more off per axis are, and
// none with the weight off.
TEST_F(VisionTest, AKnownPointsMisfitIsLearnedAndWeighsItDown) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  auto weighted = [&](double weight_px) {
    VisionOptions options;
    options.lock_frames = 1;
    options.keyframe_interval = 1;
    options.point_bias_gain = 0.3;
    options.point_bias_weight_px = weight_px;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, truth, 0.05, 0.1 * kDeg);
    std::vector<int> counts;
    for (int i = 0; i < 8; ++i) {
      ekf.Predict((i + 1) * 33'333'333);
      const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
      EXPECT_TRUE(s.keyframe) << i;
      EXPECT_GT(s.points_used, 5) << i;
      counts.push_back(s.misfit_weighted);
    }
    return std::make_pair(counts, ekf.world_from_camera());
  };
  const auto [on, on_pose] = weighted(0.5);
  const auto [off, off_pose] = weighted(0);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(on[i], 0) << "keyframe " << i << ": no point has three residuals yet";
  EXPECT_GT(on.back(), 0);
  for (int c : off) EXPECT_EQ(c, 0);
  EXPECT_NE(on_pose.translation, off_pose.translation) << "the weight changes the estimate";
  EXPECT_LT((on_pose.translation - truth.translation).norm(), 0.3);
}

// Issue 19, fourteenth session: corner_bias_px moves each known corner's measurement back out of
// its wedge, by the option's length, on the keyframe and along the KLT track: a wall foot's (its
// wall above it) down; a wall top's never down, and up where its wall edge below outweighs a roof
// edge above (an eaves corner whose hip rises behind it moves along the eaves).
TEST_F(VisionTest, CornerBiasMovesMeasurementsOutOfTheirWedge) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [frame, truth] = BackpackAt4s();
  const Rigid3d start = Off(truth, {0.05, -0.05, 0.02}, {0.05, -0.1, 0.05});
  auto matches = [&](double bias) {
    VisionOptions options;
    options.corner_bias_px = bias;
    options.lock_frames = 1;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.3, 1 * kDeg);
    const VisionFrameStats key = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    EXPECT_TRUE(key.keyframe);
    const VisionFrameStats tracked = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    EXPECT_FALSE(tracked.keyframe);
    return std::make_pair(key.point_matches, tracked.point_matches);
  };
  const auto [key0, tracked0] = matches(0.0);
  const auto [key4, tracked4] = matches(0.4);
  auto check = [&](const auto& plain, const auto& moved, const char* what) {
    SCOPED_TRACE(what);
    int common = 0, by_length = 0, tops_up = 0, tops_down = 0, tops = 0, feet_down = 0, feet = 0;
    for (const auto& [p, uv] : moved) {
      for (const auto& [q, uv0] : plain) {
        if ((p - q).norm() > 1e-9) continue;
        ++common;
        const Eigen::Vector2d d = uv - uv0;
        by_length += std::abs(d.norm() - 0.4) < 0.02;
        // The campus's ground rolls by a metre or two: a foot may lie a little above the eye.
        if (p.z() > truth.translation.z() + 3) {
          ++tops;
          tops_up += d.y() < -0.1;
          tops_down += d.y() > 0.02;
        } else if (p.z() < truth.translation.z() + 1.5) {
          ++feet;
          feet_down += d.y() > 0.1;
        }
      }
    }
    EXPECT_GE(common, 10);
    EXPECT_GE(by_length, common * 9 / 10);
    EXPECT_GE(tops, 3);
    EXPECT_GE(feet, 3);
    EXPECT_GE(tops_up, tops / 2);
    EXPECT_EQ(tops_down, 0);
    EXPECT_EQ(feet_down, feet);
  };
  check(key0, key4, "keyframe");
  check(tracked0, tracked4, "tracked");
}

// Issue 19, tenth session: a frame whose left half a near object covers fits nowhere as a whole,
// but its right half does. Once the lock has held (local_fit_after_lock_s), the right half's
// features still correct the pose and none is taken from the covered half; judged as a whole
// (local_fit_px 0), or with a lock just formed, the frame applies nothing.
TEST_F(VisionTest, AHalfCoveredFrameUsesTheFeaturesWhoseOutlineFits) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [clear, truth] = BackpackAt4s();
  sim::SimImage covered = clear;
  cv::Mat image(covered.height, covered.width, CV_8UC3, covered.bgr.data());
  image(cv::Rect(0, 0, covered.width / 2, covered.height)).setTo(cv::Scalar(40, 90, 200));  // a bus side, no edges
  const Rigid3d start = Off(truth, {0.05, -0.1, 0.05}, {0.05, -0.05, 0.02});
  const std::vector<Eigen::Vector3d> visible = CampusTracker(camera.intrinsics).VisiblePoints(truth);
  struct Case {
    double local_fit_px, after_lock_s;
    bool applies;
  };
  for (const Case& c : {Case{0.0, 0.0, false}, Case{2.0, 2.0, false}, Case{2.0, 0.0, true}}) {
    SCOPED_TRACE(testing::Message() << c.local_fit_px << " px, " << c.after_lock_s << " s");
    VisionOptions options;
    options.local_fit_px = c.local_fit_px;
    options.local_fit_after_lock_s = c.after_lock_s;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, start, 0.1, 0.2 * kDeg);
    for (int i = 0; i <= options.lock_frames; ++i) (void)vision.Update(clear.bgr.data(), clear.width, clear.height, ekf);  // the lock forms
    const Rigid3d locked = ekf.world_from_camera();
    const VisionFrameStats stats = vision.Update(covered.bgr.data(), covered.width, covered.height, ekf);
    if (!c.applies) {
      EXPECT_TRUE(stats.unfit);
      EXPECT_FALSE(stats.local_fit);
      EXPECT_EQ(stats.features_used(), 0);
      EXPECT_TRUE(ekf.world_from_camera().translation.isApprox(locked.translation));
      continue;
    }
    EXPECT_FALSE(stats.unfit);
    EXPECT_TRUE(stats.local_fit);
    EXPECT_GE(stats.points_used + stats.lines_used, 4);
    for (const auto& [point, uv] : stats.point_matches) EXPECT_GE(uv.x(), covered.width / 2 - 10) << "a match in the covered half";
    EXPECT_LT(MedianMisregistration(camera.intrinsics, truth, ekf.world_from_camera(), visible), 1.0)
        << "from " << MedianMisregistration(camera.intrinsics, truth, locked, visible) << " px";
  }
}

// Issue 19, seventeenth session: once locked, the coarse alignment searches only as far as the
// filter's pose can be off (locked_search_sigmas projected sigmas + locked_search_floor_px). A frame
// whose edges lie 30 px from the prediction while the filter is sure of its pose to a pixel (here
// the frame shifted; on the walk at 82.5 s a lens occluder's and a passer-by's edges) is not laid
// 30 px over; with the full search (0: off) it is.
TEST_F(VisionTest, ALockedAlignmentSearchesOnlyAsFarAsThePoseCanBeOff) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const auto [clear, truth] = BackpackAt4s();
  sim::SimImage shifted = clear;
  {
    cv::Mat image(shifted.height, shifted.width, CV_8UC3, shifted.bgr.data()), moved;
    cv::warpAffine(image, moved, cv::Matx23d(1, 0, 30, 0, 1, 0), image.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    moved.copyTo(image);
  }
  for (const double sigmas : {4.0, 0.0}) {
    SCOPED_TRACE(testing::Message() << "locked_search_sigmas " << sigmas);
    VisionOptions options;
    options.locked_search_sigmas = sigmas;
    VisionTracker vision = CampusTracker(camera.intrinsics, options);
    PoseEkf ekf;
    ekf.Initialize(0, Off(truth, {0.05, -0.1, 0.05}, {0.05, -0.05, 0.02}), 0.1, 0.2 * kDeg);
    for (int i = 0; i <= options.lock_frames; ++i) (void)vision.Update(clear.bgr.data(), clear.width, clear.height, ekf);  // the lock forms
    const VisionFrameStats s = vision.Update(shifted.bgr.data(), shifted.width, shifted.height, ekf);
    ASSERT_TRUE(s.keyframe);
    if (sigmas > 0) {
      EXPECT_LE(s.coarse_offset_px.norm(), options.locked_search_floor_px + 4.0) << s.coarse_offset_px.transpose();
    } else {
      EXPECT_NEAR(s.coarse_offset_px.x(), 30, 2.0) << "the full search finds the shift";
    }
  }
}

// Issue 19: between keyframes the known features follow by KLT from the predicted pose and keep
// the pose registered; a frame without features changes nothing; a frame bumped by 5° (its
// matches all disagree with the prediction) does not pull the pose, and the next frame re-locks.
TEST_F(VisionTest, VideoRateTrackingHoldsTheLockAndRefusesABlankAndABumpedFrame) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const PinholeIntrinsics& k = camera.intrinsics;
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  VisionOptions options;
  options.keyframe_interval = 10;
  options.lock_frames = 3;  // full matching on the first three frames, then tracking
  options.lock_sigma_px = 4;  // no AHRS here: the constant-velocity prediction alone is uncertain by ~2 px
  VisionTracker vision = CampusTracker(k, options);
  PoseEkf ekf;
  const int first = 120;
  const Rigid3d start = sim_camera.PoseAt(first / 30.0);
  ekf.Initialize(static_cast<int64_t>(std::llround(first * 1e9 / 30)),
                 Rigid3d(SO3Exp(Eigen::Vector3d(0.3 * kDeg, -0.4 * kDeg, 0.2 * kDeg)) * start.rotation, start.translation + Eigen::Vector3d(0.2, -0.1, 0)),
                 0.5, 1 * kDeg);
  int keyframes = 0, tracked_frames = 0;
  auto step = [&](int f, sim::SimImage& frame) {
    EXPECT_TRUE(ekf.Predict(static_cast<int64_t>(std::llround(f * 1e9 / 30))).accepted());
    const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    keyframes += s.keyframe;
    if (!s.keyframe) {
      ++tracked_frames;
      EXPECT_GE(s.known_tracked, options.min_tracked_known) << f;
      EXPECT_EQ(s.stage_ms[kStageCorners], 0) << "no full-image corner detection between keyframes, frame " << f;
      EXPECT_EQ(s.stage_ms[kStageSegments], 0) << f;
    }
    return s;
  };
  for (int f = first; f < first + 14; ++f) {
    sim::SimImage frame = sim_camera.Frame(f, f / 30.0);
    step(f, frame);
    const Rigid3d truth = sim_camera.PoseAt(f / 30.0);
    EXPECT_LT(MedianMisregistration(k, truth, ekf.world_from_camera(), vision.VisiblePoints(truth)), 1.5) << f;
  }
  EXPECT_LE(keyframes, 5);  // frames 0-2 (lock), then every 10th
  EXPECT_GE(tracked_frames, 9);

  // A frame with no features (lens cap): nothing is applied, nothing becomes NaN.
  int f = first + 14;
  sim::SimImage blank = sim_camera.Frame(f, f / 30.0);
  std::fill(blank.bgr.begin(), blank.bgr.end(), 90);
  const Rigid3d before_blank = ekf.world_from_camera();
  const VisionFrameStats b = step(f, blank);
  EXPECT_EQ(b.features_used(), 0);
  EXPECT_TRUE(ekf.covariance().allFinite());
  EXPECT_LT((ekf.world_from_camera().translation - before_blank.translation).norm(), 0.1);  // prediction only

  // A frame bumped by 5° in pitch (rotation-only warp): the matches all disagree; the pose stays.
  ++f;
  sim::SimImage bumped = sim_camera.Frame(f, f / 30.0);
  {
    cv::Mat view(bumped.height, bumped.width, CV_8UC3, bumped.bgr.data()), warped;
    const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
    cv::Matx33d R;
    cv::Rodrigues(cv::Vec3d(-5 * kDeg, 0, 0), R);
    cv::warpPerspective(view, warped, K * R * K.inv(), view.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    warped.copyTo(view);
  }
  const Rigid3d prior = [&] {
    PoseEkf copy = ekf;
    copy.Predict(static_cast<int64_t>(std::llround(f * 1e9 / 30)));
    return copy.world_from_camera();
  }();
  const VisionFrameStats bump = step(f, bumped);
  EXPECT_LT(AngleBetweenDeg(ekf.world_from_camera().rotation, prior.rotation), 0.5) << "the bumped frame pulled the pose";
  EXPECT_GT(bump.rejected_gate + (bump.keyframe ? 1 : 0), 0);
  // The next, unbumped frames re-lock: the first within 2 px (the refused frame left the pose to the
  // prediction; 1.71 px with the Fast Line Detector, 1.43 with LSD), by the third under 1 px (0.33,
  // LSD 0.60), and it holds.
  for (int after = 1; after <= 6; ++after) {
    ++f;
    sim::SimImage frame = sim_camera.Frame(f, f / 30.0);
    step(f, frame);
    const Rigid3d truth = sim_camera.PoseAt(f / 30.0);
    EXPECT_LT(MedianMisregistration(k, truth, ekf.world_from_camera(), vision.VisiblePoints(truth)), after < 3 ? 2.0 : 1.0) << after;
  }
}

// Issue 19: unknown features followed frame to frame by KLT accumulate each step's error, and the
// joint filter takes their sightings as independent. Re-matching each against its patch on the
// last keyframe (unknown_from_keyframe) bounds the drift. Against the truth: each track's first
// pixel is cast onto the static mesh from the true pose, and the hit projected with the true pose
// of every later frame (the filter is held at the truth so only tracking differs). The median over
// tracks of their pixel error 40-60 frames after their start (movers, which the mesh lacks, and
// a track's first-pixel error are in both runs).
TEST_F(VisionTest, UnknownFeaturesReMatchedOnTheKeyframeDriftLessThanChainedFrameToFrame) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const PinholeIntrinsics& k = camera.intrinsics;
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  const TriangleMesh mesh = scene::BuildStaticMesh(scenario_->world, 2.0);
  const MeshBvh bvh(mesh);
  const int first = 90, frames = 70;
  std::vector<sim::SimImage> images;
  for (int f = first; f < first + frames; ++f) images.push_back(sim_camera.Frame(f, f / 30.0));
  auto drift = [&](bool from_keyframe) {
    VisionOptions options;
    options.lock_frames = 3;
    options.lock_sigma_px = 4;
    options.use_new_points = true;  // tracked, not used by the pose
    options.unknown_from_keyframe = from_keyframe;
    VisionTracker vision(CampusFeatureMap(scenario_->world), mesh, k, options);
    std::map<int64_t, std::pair<int, Eigen::Vector3d>> start;  // track id -> (frame, mesh point)
    std::vector<double> errors;
    for (int i = 0; i < frames; ++i) {
      const Rigid3d truth = sim_camera.PoseAt((first + i) / 30.0);
      PoseEkf ekf;
      ekf.Initialize(static_cast<int64_t>(std::llround((first + i) * 1e9 / 30)), truth, 0.02, 0.05 * kDeg);
      const VisionFrameStats s = vision.Update(images[i].bgr.data(), images[i].width, images[i].height, ekf);
      for (const auto& [id, uv] : s.unknown_tracks) {
        const auto it = start.find(id);
        if (it == start.end()) {
          const Eigen::Vector3d ray = truth.rotation * PixelRay(k, uv);
          if (const auto hit = bvh.Raycast(truth.translation, ray.normalized())) start[id] = {i, truth.translation + ray.normalized() * hit->distance_m};
          continue;
        }
        const int age = i - it->second.first;
        const auto truth_uv = ProjectToPixel(k, truth.Inverse() * it->second.second);
        if (age >= 40 && truth_uv) errors.push_back((uv - *truth_uv).norm());
      }
    }
    std::sort(errors.begin(), errors.end());
    return std::make_pair(errors.empty() ? 1e9 : errors[errors.size() / 2], errors.size());
  };
  const auto [chained, chained_n] = drift(false);
  const auto [keyed, keyed_n] = drift(true);
  EXPECT_GE(chained_n, 50u);
  EXPECT_GE(keyed_n, 50u);
  EXPECT_LT(keyed, 0.8 * chained) << "keyframe-matched " << keyed << " px (" << keyed_n << " sightings), chained " << chained << " px (" << chained_n << ")";
}

// Issue 19: innovations larger than the run's usual (here: tracked frames whose halves move apart by
// 8 px, which no pose explains)
// scale the reported covariance up; the filter's own covariance is untouched, and steady frames
// bring the scale back to 1.
TEST_F(VisionTest, LargerInnovationsThanUsualScaleTheReportedCovariance) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const PinholeIntrinsics& k = camera.intrinsics;
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  VisionOptions options;
  options.lock_frames = 3;
  options.lock_sigma_px = 4;
  // The 4 px shifts below would otherwise end every tracked feature as slid off its corner
  // (TrackedFeaturesThatSlidOffTheirCornerAreRefused): this test is about the innovations of
  // features that are applied.
  options.tracked_max_innovation_px = 0;
  VisionTracker vision = CampusTracker(k, options);
  PoseEkf ekf;
  const int first = 120;
  ekf.Initialize(static_cast<int64_t>(std::llround(first * 1e9 / 30)), sim_camera.PoseAt(first / 30.0), 0.3, 0.5 * kDeg);
  std::vector<double> nis, scale;
  for (int f = first; f < first + 34; ++f) {
    sim::SimImage frame = sim_camera.Frame(f, f / 30.0);
    if (f >= first + 25 && f < first + 28) {  // three frames between keyframes: the left half 4 px down, the right half 4 px up
      cv::Mat view(frame.height, frame.width, CV_8UC3, frame.bgr.data()), down, up;
      cv::warpAffine(view, down, cv::Matx23d(1, 0, 0, 0, 1, 4), view.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
      cv::warpAffine(view, up, cv::Matx23d(1, 0, 0, 0, 1, -4), view.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
      down(cv::Rect(0, 0, frame.width / 2, frame.height)).copyTo(view(cv::Rect(0, 0, frame.width / 2, frame.height)));
      up(cv::Rect(frame.width / 2, 0, frame.width - frame.width / 2, frame.height)).copyTo(view(cv::Rect(frame.width / 2, 0, frame.width - frame.width / 2, frame.height)));
    }
    ekf.Predict(static_cast<int64_t>(std::llround(f * 1e9 / 30)));
    const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    ASSERT_GE(s.nis, 0) << f;
    nis.push_back(s.nis);
    scale.push_back(s.reported_scale);
    EXPECT_EQ(s.reported_scale, ekf.reported_scale());
    const Matrix6d own = [&] {
      Matrix6d c;
      c << ekf.covariance().block<3, 3>(kPos, kPos), ekf.covariance().block<3, 3>(kPos, kRot), ekf.covariance().block<3, 3>(kRot, kPos),
          ekf.covariance().block<3, 3>(kRot, kRot);
      return c;
    }();
    EXPECT_GE(ekf.PoseCovariance()(0, 0), s.reported_scale * own(0, 0) * (1 - 1e-12)) << f;
  }
  const double steady_nis = *std::max_element(nis.begin() + 10, nis.begin() + 25);
  EXPECT_GT(nis[25], 2 * steady_nis) << "the shifted frame's innovations";
  // (Tracked features at tracked_sigma_px 0.6 leave the frames' NIS noisier than at 1.0, and the
  // 1.2 px pixel sigma of the fifteenth session more than the 1.5 before: up to 17 % of scale while
  // the frames agree. The shift was 3 px each way at 1.5 px.)
  EXPECT_LT(*std::max_element(scale.begin() + 10, scale.begin() + 25), 1.25) << "barely a scale while the frames agree";
  EXPECT_GT(*std::max_element(scale.begin() + 25, scale.begin() + 29), 1.5);
  EXPECT_EQ(*std::min_element(scale.begin() + 29, scale.begin() + 34), 1.0) << "back to the filter's own covariance";
}

// Issue 19, seventh session: a tracked known feature whose KLT track slid off its corner (onto
// another corner, or a mover's edge) is refused by its distance from the prediction, not only by the
// chi-square gate, which the pose's own uncertainty widens. Two tracked frames with the left half
// of the image moved 7 px right: with tracked_max_innovation_px = 4 its tracks are refused and
// end, and the pose stays; off, nothing is counted. (On the untouched frames a few tracks are
// refused too: the ones that slid by themselves.)
TEST_F(VisionTest, TrackedFeaturesThatSlidOffTheirCornerAreRefused) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const PinholeIntrinsics& k = camera.intrinsics;
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  for (const double max_innovation : {4.0, 0.0}) {
    VisionOptions options;
    options.lock_frames = 3;
    options.lock_sigma_px = 4;
    options.tracked_max_innovation_px = max_innovation;
    VisionTracker vision = CampusTracker(k, options);
    PoseEkf ekf;
    const int first = 120;
    ekf.Initialize(static_cast<int64_t>(std::llround(first * 1e9 / 30)), sim_camera.PoseAt(first / 30.0), 0.3, 0.5 * kDeg);
    int refused = 0, known_before = 0, other = 0;  // refused on the slid frames, tracked before them, refused elsewhere
    double worst_after = 0;
    for (int f = first; f < first + 22; ++f) {
      sim::SimImage frame = sim_camera.Frame(f, f / 30.0);
      const bool slid = f == first + 14 || f == first + 15;  // tracked frames (keyframes at +0..2, then every 10th)
      if (slid) {
        cv::Mat view(frame.height, frame.width, CV_8UC3, frame.bgr.data()), moved;
        cv::warpAffine(view, moved, cv::Matx23d(1, 0, 7, 0, 1, 0), view.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
        moved(cv::Rect(0, 0, frame.width / 2, frame.height)).copyTo(view(cv::Rect(0, 0, frame.width / 2, frame.height)));
      }
      ekf.Predict(static_cast<int64_t>(std::llround(f * 1e9 / 30)));
      const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
      if (slid) {
        ASSERT_FALSE(s.keyframe) << f;
        refused += s.rejected_tracked_jump;
        if (f == first + 14) known_before = s.known_tracked;
      } else {
        other += s.rejected_tracked_jump;
      }
      const Rigid3d truth = sim_camera.PoseAt(f / 30.0);
      if (f >= first + 14) worst_after = std::max(worst_after, MedianMisregistration(k, truth, ekf.world_from_camera(), vision.VisiblePoints(truth)));
    }
    std::printf("limit %.0f px: %d of %d tracks refused on the slid frames, %d on the other 20 frames, worst median %.2f px after\n", max_innovation,
                refused, known_before, other, worst_after);
    if (max_innovation > 0) {
      EXPECT_GE(refused, std::max(2, known_before / 4)) << "the left half's tracks";
      EXPECT_LT(worst_after, 1.5) << "the slid tracks pulled the pose";
    } else {
      EXPECT_EQ(refused + other, 0);
    }
  }
  VisionOptions bad;
  bad.tracked_max_innovation_px = -1;
  EXPECT_THAT(bad.Check(), ::testing::HasSubstr("tracked_max_innovation_px"));
}

// Every field VisionOptions::Check validates, set out of range one at a time: Check names it (the
// agent's and the bench's error message), and the defaults pass.
TEST(VisionOptions, CheckNamesTheBadField) {
  EXPECT_EQ(VisionOptions().Check(), "");
  const double nan = std::nan(""), inf = std::numeric_limits<double>::infinity();
  const std::vector<std::pair<std::string, std::function<void(VisionOptions&)>>> bad = {
      {"max_features", [](VisionOptions& o) { o.max_features = -1; }},
      {"search_radius_px", [](VisionOptions& o) { o.search_radius_px = 0; }},
      {"max_new_points", [](VisionOptions& o) { o.max_new_points = -1; }},
      {"max_state_points", [](VisionOptions& o) { o.max_state_points = -1; }},
      {"new_point_sigma_m", [](VisionOptions& o) { o.new_point_sigma_m = 0; }},
      {"new_point_inverse_depth_sigma", [](VisionOptions& o) { o.new_point_inverse_depth_sigma = 0; }},
      {"new_point_min_observations", [](VisionOptions& o) { o.new_point_min_observations = 0; }},
      {"keyframe_interval", [](VisionOptions& o) { o.keyframe_interval = 0; }},
      {"min_tracked_known", [](VisionOptions& o) { o.min_tracked_known = -1; }},
      {"lock_frames", [](VisionOptions& o) { o.lock_frames = -1; }},
      {"acquisition_roll_search_deg", [](VisionOptions& o) { o.acquisition_roll_search_deg = 45; }},
      {"lock_alignment_px", [](VisionOptions& o) { o.lock_alignment_px = -1; }},
      {"max_alignment_score_px", [nan](VisionOptions& o) { o.max_alignment_score_px = nan; }},
      {"acquisition_coarse_passes", [](VisionOptions& o) { o.acquisition_coarse_passes = 0; }},
      {"relocalize_extent_m", [](VisionOptions& o) { o.relocalize_extent_m = 21 * o.relocalize_step_m; }},
      {"acquisition_heading_search_deg", [](VisionOptions& o) { o.acquisition_heading_search_deg = 200; }},
      {"acquisition_heading_search_deg", [](VisionOptions& o) { o.acquisition_heading_step_deg = 0; }},
      {"reorient_sigma_deg", [](VisionOptions& o) { o.reorient_sigma_deg = 0; }},
      {"relocalize_distinct_px", [](VisionOptions& o) { o.relocalize_distinct_px = -0.1; }},
      {"relocalize_max_score_px", [](VisionOptions& o) { o.relocalize_max_score_px = -1; }},
      {"relocalize_max_score_px", [nan](VisionOptions& o) { o.relocalize_max_score_px = nan; }},
      {"relocalize_retry_frames", [](VisionOptions& o) { o.relocalize_retry_frames = 0; }},
      {"lost_frames", [](VisionOptions& o) { o.lost_frames = -1; }},
      {"carrier_height_m", [](VisionOptions& o) { o.carrier_height_m = -1.7; }},
      {"carrier_height_sigma_m", [](VisionOptions& o) { o.carrier_height_sigma_m = 0; }},
      {"feature_point_bias_near_px", [](VisionOptions& o) { o.feature_point_bias_near_px = -1; }},
      {"tracked_sigma_px", [](VisionOptions& o) { o.tracked_sigma_px = -1; }},
      {"robust_residual_px", [](VisionOptions& o) { o.robust_residual_px = -1; }},
      {"robust_residual_px", [inf](VisionOptions& o) { o.robust_residual_px = inf; }},
      {"feature_class_bias_px", [nan](VisionOptions& o) { o.feature_class_bias_px = nan; }},
      {"foot_variance_scale", [](VisionOptions& o) { o.foot_variance_scale = 0.5; }},
      {"corners_on_edges", [](VisionOptions& o) { o.corners_on_edges = 3; }},
      {"corner_window_px", [](VisionOptions& o) { o.corner_window_px = 0; }},
      {"corner_bias_px", [nan](VisionOptions& o) { o.corner_bias_px = nan; }},
      {"point_bias_gain", [](VisionOptions& o) { o.point_bias_gain = 1.5; }},
      {"point_bias_weight_px", [nan](VisionOptions& o) { o.point_bias_weight_px = nan; }},
      {"local_fit_px", [](VisionOptions& o) { o.local_fit_px = -1; }},
      {"local_fit_after_lock_s", [nan](VisionOptions& o) { o.local_fit_after_lock_s = nan; }},
      {"tracked_max_innovation_px", [](VisionOptions& o) { o.tracked_max_innovation_px = -1; }},
      {"landmark_sigma_px", [](VisionOptions& o) { o.landmark_sigma_px = -1; }},
      {"landmark_bias_px", [nan](VisionOptions& o) { o.landmark_bias_px = nan; }},
      {"join_depth_sigma_scale", [](VisionOptions& o) { o.join_depth_sigma_scale = 0; }},
      {"new_point_depth_sigma_ratio", [inf](VisionOptions& o) { o.new_point_depth_sigma_ratio = inf; }},
      {"join_bearing_drift_px", [](VisionOptions& o) { o.join_bearing_drift_px = -1; }},
      {"join_model_depth_tolerance", [](VisionOptions& o) { o.join_model_depth_tolerance = -1; }},
      {"weak_lock_gated_share", [](VisionOptions& o) { o.weak_lock_gated_share = 1.5; }},
      {"lock_sigma_px", [](VisionOptions& o) { o.lock_sigma_px = 0; }},
      {"visibility_cache_m", [](VisionOptions& o) { o.visibility_cache_m = -1; }},
      {"locked_search_sigmas", [](VisionOptions& o) { o.locked_search_sigmas = -1; }},
      {"locked_search_floor_px", [nan](VisionOptions& o) { o.locked_search_floor_px = nan; }},
      {"line_ambiguity_ratio", [](VisionOptions& o) { o.line_ambiguity_ratio = 1.5; }},
      {"line_max_overhang_px", [](VisionOptions& o) { o.line_max_overhang_px = -1; }},
      {"line_max_overhang_share", [](VisionOptions& o) { o.line_max_overhang_share = -0.1; }},
      {"min_view_points", [](VisionOptions& o) { o.min_view_points = -1; }},
      {"relocalize_min_outline_share", [](VisionOptions& o) { o.relocalize_min_outline_share = 1.5; }},
      {"relocalize_extent_sigmas", [](VisionOptions& o) { o.relocalize_extent_sigmas = -1; }},
      {"relocalize_max_extent_m", [](VisionOptions& o) { o.relocalize_max_extent_m = 1e9; }},
      {"nis_short_gain", [](VisionOptions& o) { o.nis_short_gain = 2; }},
      {"nis_long_gain", [](VisionOptions& o) { o.nis_long_gain = 0; }},
      {"nis_scale_cap", [](VisionOptions& o) { o.nis_scale_cap = 0.5; }},
      {"klt_window_px", [](VisionOptions& o) { o.klt_window_px = 3; }},
      {"klt_levels", [](VisionOptions& o) { o.klt_levels = 7; }},
      {"grid_cell_px", [](VisionOptions& o) { o.grid_cell_px = 4; }},
      {"grid_min_tracks", [](VisionOptions& o) { o.grid_min_tracks = 0; }},
      {"detect_level", [](VisionOptions& o) { o.detect_level = 7; }},
  };
  for (const auto& [field, set] : bad) {
    VisionOptions o;
    set(o);
    EXPECT_THAT(o.Check(), ::testing::HasSubstr(field)) << field;
  }
}

// Issue 19, twentieth session: after a GPS outage the inertial position is metres off and its
// sigma tens of metres; the +-3 m grid then moved the pose to the best fit within its reach, 5 m
// off. With relocalize_extent_sigmas the grid spans the prior's uncertainty (at most
// relocalize_max_extent_m).
// Issue 19, twenty-first session: a position moved under a locked tracker from outside (the GPS
// re-anchor, PoseFilterOptions::gps_reanchor_s) is a loss for vision: its lock and tracks belong to
// the old position, so its next frame searches positions around the new one.
TEST_F(VisionTest, APositionMovedUnderALockIsSearchedAgain) {
  const auto [frame, truth] = BackpackAt4s();
  VisionTracker vision = CampusTracker(scenario_->world.FindCamera("backpack")->intrinsics, VisionOptions());
  PoseEkf ekf;
  ekf.Initialize(0, truth, 0.3, 1 * kDeg);
  for (int i = 0; i < 20; ++i) {
    const VisionFrameStats s = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
    ASSERT_FALSE(s.relocalized && i > 0) << "frame " << i << ": a held lock searched";
  }
  ASSERT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.3);
  ekf.MovePosition(truth.translation + Eigen::Vector3d(2.5, -1.5, 0), 3.0);
  const VisionFrameStats moved = vision.Update(frame.bgr.data(), frame.width, frame.height, ekf);
  EXPECT_TRUE(moved.keyframe);
  EXPECT_TRUE(moved.relocalized) << "the moved position was not searched";
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.6);
}

TEST_F(VisionTest, AnUncertainPriorIsSearchedOverItsUncertainty) {
  const auto [frame, truth] = BackpackAt4s();
  for (const Eigen::Vector3d& off : {Eigen::Vector3d(6.5, -3.0, 0), Eigen::Vector3d(-4.0, -6.0, 0)}) {
    auto first_frame = [&](double extent_sigmas) {
      VisionOptions options;
      options.relocalize_extent_sigmas = extent_sigmas;
      PoseEkf ekf;
      const VisionFrameStats stats = FirstFrame(options, frame, Off(truth, {0, 0, 0.3}, off), 30.0, 1 * kDeg, ekf);
      EXPECT_TRUE(ekf.covariance().allFinite());
      return std::make_pair(stats.relocalized, (ekf.world_from_camera().translation - truth.translation).head<2>().norm());
    };
    const auto [moved, error_m] = first_frame(2);
    const auto [moved_fixed, error_fixed_m] = first_frame(0);  // (7.2 m off, stayed; 2.4 m off, moved)
    EXPECT_TRUE(moved) << "start " << off.transpose();
    EXPECT_LT(error_m, 1.0) << "start " << off.transpose();
    EXPECT_GT(error_fixed_m, 2.0) << "the +-3 m grid cannot reach it; start " << off.transpose();
  }
}

}  // namespace
}  // namespace ave::pose

namespace ave::pose {
namespace {

// The feature map is the geometry the simulator renders: just below each visible eaves corner
// (ideal camera) lies its building, just above it something else.
TEST_F(VisionTest, EavesCornersSitOnTheRenderedBuildingCorners) {
  for (const bool distorted : {false, true}) {
  scene::CameraSpec camera = *scenario_->world.FindCamera("backpack");
  if (!distorted) camera.intrinsics.distortion = {};
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, {}, scenario_->seed);
  const double t = 1.0;
  const sim::SimImage frame = sim_camera.Frame(30, t);
  const Rigid3d truth = sim_camera.PoseAt(t);
  const FeatureMap map = CampusFeatureMap(scenario_->world);
  VisionTracker vision(map, scene::BuildStaticMesh(scenario_->world, 2.0), camera.intrinsics);
  int checked = 0, below_is_building = 0;
  for (const Eigen::Vector3d& p : vision.VisiblePoints(truth)) {
    auto uv = ProjectToPixel(camera.intrinsics, truth.Inverse() * p);
    if (distorted) {  // where the lens puts it (OpenCV's model)
      const Eigen::Vector3d c = truth.Inverse() * p;
      std::vector<cv::Point2d> out;
      const cv::Matx33d K(camera.intrinsics.fx, 0, camera.intrinsics.cx, 0, camera.intrinsics.fy, camera.intrinsics.cy, 0, 0, 1);
      cv::projectPoints(std::vector<cv::Point3d>{{c.x(), c.y(), c.z()}}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K,
                        std::vector<double>(camera.intrinsics.distortion.begin(), camera.intrinsics.distortion.end()), out);
      uv = Eigen::Vector2d(out[0].x, out[0].y);
    }
    const int u = static_cast<int>(std::lround(uv->x())), v = static_cast<int>(std::lround(uv->y()));
    if (v < 4 || v + 4 >= frame.height) continue;
    const bool eaves = p.z() > scenario_->world.TerrainHeight(p.x(), p.y()) + 1;  // a wall's top or a roof's vertex, not a foot
    if (!eaves) continue;
    ++checked;
    const uint32_t below = frame.object_id[frame.Index(u, v + 3)];
    below_is_building += sim::IsBuildingId(below);
  }
  EXPECT_GT(checked, 3);
  EXPECT_GE(below_is_building * 10, checked * 8);
  }
}

// Issue 19, nineteenth session: a relocalisation position from which the model shows under half
// the outline it shows from the filter's (relocalize_min_outline_share) is not scored. At 56 s the
// backpack looks across the road at a few façades; from 2.5 m off, positions whose view loses most
// of them scored best on their thin outline's low chamfer distance and took the pose 2-3 m the
// wrong way. (Not every frame gains: probing 16 frames of 50-88 s from 8 starts 2.5 m off each,
// the rule changed where the pose ended on 11 of 128, nearer the truth on 7 and farther on 4, all
// four at 58 s; with the thin-view rules it halved the walk's 80-90 s p95.)
TEST_F(VisionTest, ARelocalisationPositionShowingLittleOfTheOutlineIsNotTaken) {
  const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
  const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
  const sim::SimImage frame = sim_camera.Frame(1680, 56.0);
  const Rigid3d truth = sim_camera.PoseAt(56.0);
  for (const Eigen::Vector3d& off : {Eigen::Vector3d(1.77, -1.77, 0), Eigen::Vector3d(-1.77, -1.77, 0)}) {
    auto first_frame = [&](double share) {
      VisionOptions options;
      options.min_view_points = 0;
      options.relocalize_min_outline_share = share;
      PoseEkf ekf;
      const VisionFrameStats stats = FirstFrame(options, frame, Off(truth, {0, 0, 0.3}, off), 1.0, 1 * kDeg, ekf);
      EXPECT_TRUE(ekf.covariance().allFinite());
      EXPECT_TRUE(stats.relocalized);
      return std::make_pair(stats.relocalize_thin_outlines, (ekf.world_from_camera().translation - truth.translation).norm());
    };
    const auto [refused, error_m] = first_frame(VisionOptions().relocalize_min_outline_share);
    const auto [refused_off, error_off_m] = first_frame(0);
    EXPECT_GT(refused, 0) << "start " << off.transpose();
    EXPECT_EQ(refused_off, 0);
    EXPECT_LT(error_m, 1.0) << "start " << off.transpose();
    EXPECT_GT(error_off_m, 1.5) << "without the rule the thin outline wins; start " << off.transpose();
  }
}

}  // namespace
}  // namespace ave::pose
