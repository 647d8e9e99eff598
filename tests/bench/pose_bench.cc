// ave-bench pose: registration error of the backpack camera's pose (AVE §5.1, issue 5). Simulates
// the camera, GPS and inertial streams of a moving scenario camera with every effect the scenario
// names, runs the pose filter in each mode (GPS+inertial only; GPS+inertial+vision with 10, 25,
// 50, 100 features), projects the static model's known points with each mode's pose and with the
// true pose, and reports the misregistration in pixels (median, p95, max) next to the time per
// frame (thread CPU time on one core). Issue 19: the front end's stage table, the knobs of the
// video-rate front end (keyframe interval, visibility cache, detection level) with the accuracy
// each costs, NEES of the pose against the chi-square 95 % band, rejection reasons, and two
// scenario variants (a bus covering half the image, a camera bumped by 5°). Peers in the same run:
// cv::solvePnP (iterative, from the GPS+inertial pose) and cv::solvePnPRansac on the same
// known-point matches, frame by frame. Also: how many pixels 1° of orientation error is.
#include <algorithm>
#include <array>
#include <functional>
#include <limits>
#include <map>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/common/cpu_clock.h"
#include "model_store/geometry/bvh.h"
#include "sensor_agent/pose/pose_inputs.h"
#include "sensor_agent/pose/so3.h"
#include "sensor_agent/pose/vision.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/footage.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

using Clock = ThreadCpuClock;  // CPU time: the machine is shared, wall time is inflated by others
double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }
using WallClock = std::chrono::steady_clock;

struct PoseBenchOptions {
  std::string scenario = "campus";
  std::string camera = "backpack";
  double seconds = 10;
  std::vector<int> features = {0, 10, 25, 50, 100};
  std::vector<std::string> rows;  // run only these rows (JSON keys); empty: all
  std::string png = "pose_bench.png";
  bool lines = true, new_points = true;
  double ahrs_correlation_s = pose::PoseFilterOptions{}.orientation_correlation_s;
  double gps_correlation_s = pose::PoseFilterOptions{}.gps_correlation_s;  // issue 19 (pose19e)
  double gps_min_sigma_m = pose::PoseFilterOptions{}.gps_min_sigma_m;
  double locked_search_sigmas = pose::VisionOptions{}.locked_search_sigmas;  // issue 19, seventeenth session
  double line_ambiguity_ratio = pose::VisionOptions{}.line_ambiguity_ratio;
  double line_max_overhang_px = pose::VisionOptions{}.line_max_overhang_px;  // issue 19, eighteenth session
  int min_view_points = pose::VisionOptions{}.min_view_points;               // issue 19, nineteenth session
  double relocalize_min_outline_share = pose::VisionOptions{}.relocalize_min_outline_share;
  double gate_chi2_2dof = pose::PoseFilterOptions{}.gate_chi2_2dof;  // issue 19, seventh session
  double pixel_sigma_px = pose::PoseFilterOptions{}.pixel_sigma_px;
  double tracked_sigma_px = pose::VisionOptions{}.tracked_sigma_px;
  double tracked_max_innovation_px = pose::VisionOptions{}.tracked_max_innovation_px;
  double gps_bias_sigma_m = pose::PoseFilterOptions{}.gps_bias_sigma_m;  // issue 19: multipath as a consider bias
  double gps_reanchor_s = pose::PoseFilterOptions{}.gps_reanchor_s;      // issue 19, twenty-first session
  double gps_reanchor_sigma_m = pose::PoseFilterOptions{}.gps_reanchor_sigma_m;
  double gps_reanchor_min_m = pose::PoseFilterOptions{}.gps_reanchor_min_m;
  double gps_reanchor_orientation_sigma_deg = pose::PoseFilterOptions{}.gps_reanchor_orientation_sigma_deg;
  int seed = 0;  // added to the scenario's seed: another draw of every noise (GPS, IMU, camera)
  int seeds = 1;  // > 1: Monte Carlo over seeds seed .. seed + seeds - 1 (RunPoseSeeds)
  double start_s = 0;         // scene time of the first frame (the filter runs GPS + inertial from 0)
  double start_spread_s = 0;  // Monte Carlo: draw i starts at start_s + i * this (other places; issue 19, eleventh session)
  double roll_search_deg = pose::VisionOptions{}.acquisition_roll_search_deg;  // issue 19, sixth session
  int acquisition_passes = pose::VisionOptions{}.acquisition_coarse_passes;
  double lock_alignment_px = pose::VisionOptions{}.lock_alignment_px;
  double max_alignment_score_px = pose::VisionOptions{}.max_alignment_score_px;
  double relocalize_extent_m = pose::VisionOptions{}.relocalize_extent_m;
  double relocalize_extent_sigmas = pose::VisionOptions{}.relocalize_extent_sigmas;  // issue 19, twentieth session
  double relocalize_max_extent_m = pose::VisionOptions{}.relocalize_max_extent_m;
  double heading_search_deg = pose::VisionOptions{}.acquisition_heading_search_deg;  // issue 19, eighteenth session
  double relocalize_step_m = pose::VisionOptions{}.relocalize_step_m;
  double relocalize_distinct_px = pose::VisionOptions{}.relocalize_distinct_px;
  double relocalize_max_score_px = pose::VisionOptions{}.relocalize_max_score_px;  // issue 19, eleventh session
  int relocalize_retry_frames = pose::VisionOptions{}.relocalize_retry_frames;
  double gyro_correlation_s = pose::PoseFilterOptions{}.gyro_correlation_s;  // issue 19
  double ahrs_sigma_deg = pose::PoseFilterOptions{}.orientation_sigma_deg;
  double ahrs_heading_sigma_deg = pose::PoseFilterOptions{}.heading_sigma_deg;  // issue 19, eighteenth session
  double gravity_window_s = pose::PoseFilterOptions{}.gravity_window_s;          // issue 19, eighteenth session
  double acquiring_sigma_px = pose::VisionOptions{}.acquiring_sigma_px;  // issue 19
  double gyro_sigma_rad_s = pose::PoseFilterOptions{}.gyro_sigma_rad_s;
  bool gyro_bias = pose::PoseFilterOptions{}.estimate_gyro_bias;  // issue 19: the bias in the state
  double accel_noise_m_s2 = pose::PoseFilterOptions{}.accel_noise_m_s2;  // issue 19, fifteenth session
  double point_bias_gain = pose::VisionOptions{}.point_bias_gain;
  double point_bias_weight_px = pose::VisionOptions{}.point_bias_weight_px;
  double angular_accel_noise_rad_s2 = pose::PoseFilterOptions{}.angular_accel_noise_rad_s2;
  double acquisition_sigma_m = pose::VisionOptions{}.acquisition_position_sigma_m;  // issue 19
  double acquisition_sigma_deg = pose::VisionOptions{}.acquisition_orientation_sigma_deg;
  double feature_bias_px = pose::VisionOptions{}.feature_bias_px;
  double feature_point_bias_px = pose::VisionOptions{}.feature_point_bias_px;  // issue 19 (pose19e)
  double feature_point_bias_near_px = pose::VisionOptions{}.feature_point_bias_near_px;  // issue 19, eighth session
  double acquisition_association_px = pose::VisionOptions{}.acquisition_association_px;
  // Issue 19, eighth session: the carried camera's height above the ground (VisionOptions::
  // carrier_height_m); < 0: the camera path's own (the backpack walker's 1.7 m), 0: off.
  double carrier_height_m = -1;
  double carrier_height_sigma_m = pose::VisionOptions{}.carrier_height_sigma_m;
  double carrier_height_correlation_s = pose::VisionOptions{}.carrier_height_correlation_s;
  double nis_short_gain = pose::VisionOptions{}.nis_short_gain;
  double landmark_bias_px = pose::VisionOptions{}.landmark_bias_px;  // issue 19: reported covariance follows the innovations
  // Issue 19, twelfth session: the joint mode's own noise and size, for its sweep.
  double landmark_sigma_px = pose::VisionOptions{}.landmark_sigma_px;
  int max_state_points = pose::VisionOptions{}.max_state_points;
  double join_depth_sigma_scale = pose::VisionOptions{}.join_depth_sigma_scale;
  std::string segments = pose::VisionOptions{}.segment_detector == pose::SegmentDetector::kLsd ? "lsd" : "fld";  // issue 19
  double feature_shared_bias_px = pose::VisionOptions{}.feature_shared_bias_px;
  double feature_class_bias_px = pose::VisionOptions{}.feature_class_bias_px;  // issue 19, ninth session
  double foot_variance_scale = pose::VisionOptions{}.foot_variance_scale;      // issue 19, tenth session
  int corners_on_edges = pose::VisionOptions{}.corners_on_edges;              // issue 19, thirteenth session
  int corner_window_px = pose::VisionOptions{}.corner_window_px;              // issue 19, fourteenth session
  double corner_bias_px = pose::VisionOptions{}.corner_bias_px;               // issue 19, fourteenth session
  double local_fit_px = pose::VisionOptions{}.local_fit_px;                    // issue 19, tenth session
  double robust_residual_px = pose::VisionOptions{}.robust_residual_px;
  double gyro_bias_sigma_rad_s = pose::PoseFilterOptions{}.gyro_bias_sigma_rad_s;
  bool knobs = true;     // the front end's knobs at 50 features
  bool variants = true;  // the bus and bump scenario variants (need --seconds >= 7.2)
  bool consistency_knobs = true;  // the filter's noise model (pixel sigma, process noise) against NEES
  std::string nees_csv;  // per-frame NEES diagnostics of every row (issue 19: which axes, where)
  // > 0: every frame JPEG-encoded at this quality and decoded before the pose sees it, as the
  // agent's pre-rendered footage delivers frames (issue 19, session rate19); 0: the render as is.
  int footage_jpeg_quality = 0;
  // >= 1: the pixel_area effect with this many samples per axis whatever the scenario names (1:
  // one sample at each pixel's centre); 0: as the scenario names it.
  int pixel_area = 0;
  std::string match_csv;     // every known-point match of every frame against its true projection (issue 19, seventh session)
  std::string landmark_csv;  // every unknown feature that joined the state, with what it sits on (issue 19, session pose19j)
};

struct Spread {
  double median = 0, p95 = 0, max = 0;
};
Spread SpreadOf(std::vector<double> v) {
  Spread s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))]; };
  return {at(0.5), at(0.95), v.back()};
}

// A scene event of a scenario variant: the frames it changes and the windows compared.
struct Event {
  std::string name;          // "bus", "bump"
  double start_s = 0, end_s = 0;
  double before_s = 1, after_s = 1;  // windows before the start and after the end
};

struct Row {
  std::string mode;
  int features = 0;
  std::string knob;          // what differs from the default front end ("" for the default)
  std::string key;           // JSON key
  std::vector<double> errors_px;         // every visible model point of every frame
  std::vector<double> frame_median_px;   // per frame, for the plot
  std::vector<double> frame_t_s;         // ... and its time from the first frame
  std::vector<size_t> frame_errors_end;  // per frame, errors_px.size() after it (a window's slice)
  std::vector<double> frame_ms;          // per frame, CPU ms (filter + vision)
  double filter_ms = 0, detect_ms = 0, update_ms = 0, used = 0;
  int frames = 0;
  int matches = 0, matches_within_2px = 0;  // known-point matches and those within 2 px of the true projection
  std::vector<double> match_error_key_px, match_error_tracked_px;  // their distance from the truth, keyframes / tracked frames
  // Signed match residuals (observed - true projection, px; |r| <= 3 px) summed per kind: [keyframe/tracked][foot/eaves]
  // (issue 19: are the vision measurements biased?).
  std::array<std::array<std::array<double, 3>, 2>, 2> residual_sum{};  // (sum u, sum v, count)
  // Per known point (its model position): its matches' residuals within 3 px, to split each
  // point's error into the part that persists over its sightings (the point's mean) and the part
  // that varies (issue 19, seventh session: what VisionOptions::feature_point_bias_px stands for).
  struct PointResiduals {
    double n = 0, u = 0, v = 0, uu = 0, vv = 0, depth = 0;
  };
  std::map<std::tuple<double, double, double>, PointResiduals> point_residuals;
  int matches_beyond_3px = 0;
  std::array<double, pose::kVisionStageCount> stage_ms{};
  int keyframes = 0, weak_locks = 0, relocks = 0, unfit = 0, relocalized = 0, relocalize_waiting = 0, reoriented = 0, thin_views = 0;
  int64_t rejected_gate = 0, rejected_behind = 0, rejected_not_finite = 0, klt_lost = 0, unknown_dropped = 0, rejected_tracked_jump = 0, rejected_structure = 0, rejected_ambiguous = 0, rejected_overhang = 0;
  int nees_frames = 0, nees_in_band = 0, nees_below = 0, nees_above = 0;
  // Unknown features joining the state (joint mode), against the static mesh's point on the true
  // ray through the same pixel: 3D error (m) and 3-dof NEES of their estimate.
  std::vector<double> landmark_error_m, landmark_nees;
  int landmarks_joined = 0;
  double landmarks_in_state = 0;
  std::array<int, 7> joined_on{};  // joined landmarks by what they sit on (LandmarkOn)
  int64_t landmarks_refused = 0;   // converged features the joining tests refused (per feature and frame)
  double nees_sum = 0;
  std::vector<double> nees;  // per frame
  std::vector<double> nees_at_frame;  // by frame index, NaN where the pose had no sample (Monte Carlo NEES over draws)
  const Event* event = nullptr;
  std::vector<double> before_px, during_px, after_px;  // per-point errors in the event's windows
  double TotalMs() const { return (filter_ms + detect_ms + update_ms) / std::max(1, frames); }
};

// What an unknown feature at frame pixel `px` sits on, from the simulator's class mask: a mover or a
// tree when any pixel of its 3x3 neighbourhood shows one (a corner lies on an outline; the lens's rolling occluder first), else the
// centre pixel's class (issue 19, session pose19j).
enum LandmarkOn : int { kOnBuilding = 0, kOnGround, kOnObject, kOnTree, kOnMover, kOnOccluder, kOnOther, kOnCount };
static_assert(kOnCount == std::tuple_size<decltype(Row::joined_on)>::value);
constexpr std::array<const char*, kOnCount> kOnNames = {"building", "ground", "static object", "tree", "person/vehicle", "lens occluder", "other"};
int LandmarkOnClass(const sim::SimImage& im, const Eigen::Vector2d& px) {
  const int u0 = static_cast<int>(std::lround(px.x())), v0 = static_cast<int>(std::lround(px.y()));
  if (im.class_id.empty() || u0 < 0 || v0 < 0 || u0 >= im.width || v0 >= im.height) return kOnOther;
  bool mover = false, tree = false, occluder = false;
  for (int dv = -1; dv <= 1; ++dv)
    for (int du = -1; du <= 1; ++du) {
      const int u = std::clamp(u0 + du, 0, im.width - 1), v = std::clamp(v0 + dv, 0, im.height - 1);
      const auto c = static_cast<sim::PixelClass>(im.class_id[im.Index(u, v)]);
      mover |= c == sim::PixelClass::kPerson || c == sim::PixelClass::kVehicle;
      tree |= c == sim::PixelClass::kVegetation;
      occluder |= c == sim::PixelClass::kOccluder;
    }
  if (occluder) return kOnOccluder;
  if (mover) return kOnMover;
  if (tree) return kOnTree;
  switch (static_cast<sim::PixelClass>(im.class_id[im.Index(u0, v0)])) {
    case sim::PixelClass::kWall:
    case sim::PixelClass::kRoof: return kOnBuilding;
    case sim::PixelClass::kTerrain:
    case sim::PixelClass::kRoad: return kOnGround;
    case sim::PixelClass::kStaticObject: return kOnObject;
    default: return kOnOther;
  }
}

// NEES of the 6-dof pose (position m, world rotation vector rad) against its covariance; inside
// the two-sided chi-square(6) 95 % band [1.237, 14.449].
constexpr double kNeesLow = 1.2373, kNeesHigh = 14.4494;
double PoseNees(const Rigid3d& truth, const pose::PoseSample& estimate) {
  Eigen::Matrix<double, 6, 1> e;
  e << truth.translation - estimate.world_from_camera.translation, pose::SO3Log(truth.rotation * estimate.world_from_camera.rotation.conjugate());
  const Eigen::LDLT<pose::Matrix6d> ldlt(estimate.covariance);
  return ldlt.info() == Eigen::Success ? e.dot(ldlt.solve(e)) : std::numeric_limits<double>::infinity();
}

// Scenario variants (issue 19): a bus covering the left half of the image, driving across it for
// three seconds; a camera bumped by 5° (pitch) for 0.2 s, as a rotation-only warp of the frame
// (the AHRS on the carrier does not see it). Each returns the changed frame or false.
cv::Mat BusTexture() {
  cv::Mat bus(420, 2400, CV_8UC3, cv::Scalar(40, 90, 200));
  cv::RNG rng(19);
  for (int x = 20; x < bus.cols - 80; x += 110) {  // windows with sharp corners, people behind some
    cv::rectangle(bus, cv::Rect(x, 40, 90, 150), cv::Scalar(60, 50, 40), cv::FILLED);
    if (rng.uniform(0, 2)) cv::circle(bus, {x + rng.uniform(20, 70), 120}, 18, cv::Scalar(rng.uniform(0, 255), 150, 120), cv::FILLED);
  }
  for (int i = 0; i < 60; ++i) {  // advertising and dirt: more corners to track
    const cv::Point a(rng.uniform(0, bus.cols), rng.uniform(220, 400));
    cv::rectangle(bus, a, a + cv::Point(rng.uniform(10, 60), rng.uniform(5, 30)),
                  cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255)), cv::FILLED);
  }
  return bus;
}

bool ApplyEvent(const Event& e, const cv::Mat& bus, const PinholeIntrinsics& k, int frame, double t_s, sim::SimImage& image, Rigid3d& truth) {
  if (t_s < e.start_s || t_s >= e.end_s) return false;
  cv::Mat view(image.height, image.width, CV_8UC3, image.bgr.data());
  if (e.name == "bus") {
    const int shift = (frame * 12) % (bus.cols - image.width / 2);
    const int top = image.height - bus.rows;
    bus(cv::Rect(shift, std::max(0, -top), image.width / 2, std::min(bus.rows, image.height))).copyTo(view(cv::Rect(0, std::max(0, top), image.width / 2, std::min(bus.rows, image.height))));
    return true;
  }
  const Eigen::Quaterniond bump = pose::SO3Exp(Eigen::Vector3d(5 * 3.14159265358979323846 / 180, 0, 0));
  const Eigen::Matrix3d K = (Eigen::Matrix3d() << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1).finished();
  const Eigen::Matrix3d H = K * bump.conjugate().toRotationMatrix() * K.inverse();  // old pixel -> bumped pixel
  cv::Mat Hcv;
  cv::eigen2cv(H, Hcv);
  cv::Mat warped;
  cv::warpPerspective(view, warped, Hcv, view.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  warped.copyTo(view);
  truth = Rigid3d((truth.rotation * bump).normalized(), truth.translation);
  return true;
}

// Pixel distances between each model point projected with `estimate` and with `truth`; a point
// behind the estimated camera counts as the image diagonal.
void Misregistration(const PinholeIntrinsics& k, const Rigid3d& truth, const Rigid3d& estimate, const std::vector<Eigen::Vector3d>& points,
                     std::vector<double>& out, std::vector<double>* frame_median) {
  std::vector<double> frame;
  const Rigid3d truth_inv = truth.Inverse(), est_inv = estimate.Inverse();
  for (const Eigen::Vector3d& p : points) {
    const auto a = ProjectToPixel(k, truth_inv * p, 0.1), b = ProjectToPixel(k, est_inv * p, 0.1);
    if (!a) continue;
    frame.push_back(b ? (*a - *b).norm() : std::hypot(k.width, k.height));
  }
  out.insert(out.end(), frame.begin(), frame.end());
  if (frame_median) frame_median->push_back(frame.empty() ? 0 : SpreadOf(frame).median);
}

std::string RowName(const Row& r) {
  if (r.features == 0 || r.mode.rfind("gps-imu-vision", 0) != 0) return r.mode;
  return r.mode + " " + std::to_string(r.features) + (r.knob.empty() ? "" : ", " + r.knob);
}

void Plot(const std::vector<Row>& all_rows, const std::string& path, double seconds) {
  // The sweep, the issue-5 front end, unknown features, variants and peers; the knob rows only in the tables.
  std::vector<Row> rows;
  for (const Row& r : all_rows) {
    if (r.knob.empty() || r.key.find("every_frame") != std::string::npos || r.key.find("unknown_50") != std::string::npos ||
        r.key.find("joint") != std::string::npos || r.event)
      rows.push_back(r);
  }
  // The two plots on top, the legend below them (over the left plot it hid the points).
  const int w = 1200, h = 520, pad = 60, legend_rows = static_cast<int>(rows.size());
  cv::Mat img(h + 18 * legend_rows + 10, w, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar palette[] = {{60, 60, 200},  {40, 150, 40}, {200, 120, 30}, {160, 40, 160}, {30, 160, 200}, {90, 90, 90},
                                {20, 20, 20},   {0, 90, 255},  {255, 0, 150}, {0, 200, 120}, {120, 60, 0},  {150, 150, 0}};
  auto log_y = [&](double px, int top, int bottom) {
    const double lo = std::log10(0.1), hi = std::log10(300.0);
    const double t = (std::log10(std::clamp(px, 0.1, 300.0)) - lo) / (hi - lo);
    return static_cast<int>(bottom - t * (bottom - top));
  };
  auto axes = [&](int x0, int x1, const std::string& title, const std::string& xlabel) {
    cv::rectangle(img, {x0, pad}, {x1, h - pad}, cv::Scalar(0, 0, 0), 1);
    for (double px : {0.1, 1.0, 2.0, 5.0, 10.0, 100.0}) {
      const int y = log_y(px, pad, h - pad);
      cv::line(img, {x0, y}, {x1, y}, cv::Scalar(220, 220, 220), 1);
      std::ostringstream s;
      s << px;
      cv::putText(img, s.str(), {x0 - 40, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1);
    }
    cv::putText(img, title, {x0, pad - 25}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1);
    cv::putText(img, xlabel, {(x0 + x1) / 2 - 60, h - pad + 35}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1);
  };
  // Left: median (dot) and p95 (ring) misregistration against ms per frame.
  const int lx0 = pad + 10, lx1 = w / 2 - 20;
  double max_ms = 1;
  for (const Row& r : rows) max_ms = std::max(max_ms, r.TotalMs());
  axes(lx0, lx1, "misregistration px (log; dot median, ring p95) vs ms/frame", "ms per frame (one core)");
  for (int i = 0; i <= 4; ++i) {
    const int x = lx0 + i * (lx1 - lx0) / 4;
    cv::putText(img, std::to_string(static_cast<int>(std::round(max_ms * 1.1 * i / 4))), {x - 8, h - pad + 16},
                cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1);
  }
  // Right: per-frame median misregistration over time.
  const int rx0 = w / 2 + 50, rx1 = w - 20;
  axes(rx0, rx1, "per-frame median misregistration px (log) over time", "scene time (s)");
  for (int i = 0; i <= 5; ++i) {
    const int x = rx0 + i * (rx1 - rx0) / 5;
    std::ostringstream s;
    s << seconds * i / 5;
    cv::putText(img, s.str(), {x - 8, h - pad + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1);
  }
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const cv::Scalar c = palette[i % 12];
    const Spread s = SpreadOf(r.errors_px);
    const int x = lx0 + static_cast<int>(r.TotalMs() / (max_ms * 1.1) * (lx1 - lx0));
    cv::circle(img, {x, log_y(s.median, pad, h - pad)}, 5, c, cv::FILLED);
    cv::circle(img, {x, log_y(s.p95, pad, h - pad)}, 6, c, 2);
    const cv::Point legend(pad, h + 18 * static_cast<int>(i));
    cv::circle(img, legend + cv::Point(-10, -4), 4, c, cv::FILLED);
    cv::putText(img, RowName(r), legend, cv::FONT_HERSHEY_SIMPLEX, 0.4, c, 1);
    for (size_t f = 1; f < r.frame_median_px.size(); ++f) {
      const auto px = [&](size_t j) {
        return cv::Point(rx0 + static_cast<int>(j * (rx1 - rx0) / std::max<size_t>(1, r.frame_median_px.size() - 1)),
                         log_y(r.frame_median_px[j], pad, h - pad));
      };
      cv::line(img, px(f - 1), px(f), c, 1, cv::LINE_AA);
    }
  }
  cv::imwrite(path, img);
}

// Figures of one row of one run, for the Monte Carlo summary.
struct RowFigures {
  double median_px = 0, p95_px = 0, nees_in_band = -1, nees_mean = 0, ms_per_frame = 0;
  int nees_frames = 0, nees_below = 0, nees_above = 0;
  std::vector<double> nees_at_frame;  // by frame index (NaN: no sample)
  // Acquisition (issue 19, eighteenth session; a draw started later on the walk, --start-spread):
  // the time of the first frame within 2 px whose next second stays within 5 px (-1: never), and
  // the frames' median misregistration from then on (frames with no model point in view left out).
  double lock_s = -1, after_lock_median_px = 0, after_lock_p95_px = 0;
  // Each known point's mean match error against its true projection (10+ sightings within 3 px):
  // compared between draws, the part of the persisting errors the scenery decides (issue 19,
  // twentieth session).
  std::map<std::tuple<double, double, double>, Eigen::Vector2d> point_mean_px;
};

// RowFigures' acquisition figures from a row's per-frame medians.
void LockFigures(const std::vector<double>& frame_median_px, const std::vector<double>& frame_t_s, RowFigures& f) {
  std::vector<double> px, t;
  for (size_t i = 0; i < frame_median_px.size() && i < frame_t_s.size(); ++i)
    if (frame_median_px[i] > 0) px.push_back(frame_median_px[i]), t.push_back(frame_t_s[i]);
  constexpr size_t kSecond = 30;
  for (size_t i = 0; i + kSecond <= px.size(); ++i) {
    if (!(px[i] < 2) || !std::all_of(px.begin() + i, px.begin() + i + kSecond, [](double v) { return v < 5; })) continue;
    f.lock_s = t[i];
    const Spread after = SpreadOf(std::vector<double>(px.begin() + i, px.end()));
    f.after_lock_median_px = after.median, f.after_lock_p95_px = after.p95;
    return;
  }
}

// The chi-square quantile for probability p (0.025 or 0.975) and `dof` degrees of freedom, by the
// Wilson-Hilferty cube-root normal approximation (within 0.3 % of the exact value at 6 dof, closer
// above: the Monte Carlo NEES band has 6 x draws of them).
double ChiSquareQuantile(double p, double dof) {
  const double z = p < 0.5 ? -1.959964 : 1.959964, c = 2.0 / (9.0 * dof);
  return dof * std::pow(1 - c + z * std::sqrt(c), 3);
}

int RunPose(const PoseBenchOptions& o, std::map<std::string, RowFigures>* figures = nullptr) {
  UseOneCore();
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench pose: " << scenario.status().message() << "\n";
    return 1;
  }
  scenario->seed += static_cast<uint64_t>(o.seed);
  const scene::SyntheticCampus& world = scenario->world;
  const scene::CameraSpec* camera = world.FindCamera(o.camera);
  if (!camera || !camera->path) {
    std::cerr << "ave-bench pose: " << scenario->label << " has no moving camera '" << o.camera << "'\n";
    return 1;
  }
  const PinholeIntrinsics& k = camera->intrinsics;
  sim::GpsImuSpec spec;
  spec.camera_id = o.camera;
  for (const sim::GpsImuSpec& g : scenario->gps_imu)
    if (g.camera_id == o.camera) spec = g;
  spec.duration_s = o.start_s + o.seconds;
  const pose::SensorLog log = pose::FromSimulation(sim::SimulateGpsImu(world, *camera, spec, scenario->effects, scenario->seed));

  // Frames at the 30 Hz video rate (AVE §5), rendered once and shared by every mode.
  sim::EffectSet camera_effects = scenario->EffectsForCamera(o.camera);
  if (o.pixel_area >= 1) camera_effects.Enable(sim::EffectKind::kPixelArea, sim::EffectParams{{{"samples", double(o.pixel_area)}}});
  const sim::SimulatedCamera sim_camera(world, *camera, camera_effects, scenario->seed);
  const int n = static_cast<int>(std::floor(o.seconds * 30 + 1e-9)) + 1;
  // Every frame is kept for the modes to share: its colour, class and depth (8 bytes a pixel; the
  // object ids and the JPEG are dropped). A run longer than the free memory holds is refused here,
  // not killed by the kernel minutes later (120 s at 640x480: ~9 GB).
  const double frame_bytes = 8.0 * camera->intrinsics.width * camera->intrinsics.height;
  const double free_bytes = static_cast<double>(sysconf(_SC_AVPHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
  if (free_bytes > 0 && n * frame_bytes > 0.8 * free_bytes) {
    std::fprintf(stderr, "ave-bench pose: --seconds %g keeps %d frames, about %.1f GB, and %.1f GB of memory are free: run fewer seconds (--start picks where)\n",
                 o.seconds, n, n * frame_bytes / 1e9, free_bytes / 1e9);
    return 2;
  }
  std::vector<sim::SimImage> frames;
  frames.reserve(static_cast<size_t>(n));
  std::vector<Rigid3d> truth;
  const WallClock::time_point render_start = WallClock::now();
  for (int f = 0; f < n; ++f) {
    frames.push_back(sim_camera.Frame(f, o.start_s + f / 30.0));
    std::vector<uint32_t>().swap(frames.back().object_id);
    std::vector<uint8_t>().swap(frames.back().jpeg);
    truth.push_back(sim_camera.PoseAt(o.start_s + f / 30.0));
    if (o.footage_jpeg_quality > 0) {
      const std::vector<uint8_t> jpeg = sim::EncodeFrameJpeg(frames.back(), o.footage_jpeg_quality);
      const cv::Mat decoded = cv::imdecode(jpeg, cv::IMREAD_COLOR);
      frames.back().bgr.assign(decoded.data, decoded.data + decoded.total() * 3);
    }
  }
  const double render_ms = std::chrono::duration<double, std::milli>(WallClock::now() - render_start).count() / n;
  const TriangleMesh mesh = scene::BuildStaticMesh(world, 2.0);
  const MeshBvh bvh(mesh);
  const pose::FeatureMap map = pose::CampusFeatureMap(world);
  std::vector<std::vector<Eigen::Vector3d>> visible;
  {
    const pose::VisionTracker probe(map, mesh, k);
    for (const Rigid3d& t : truth) visible.push_back(probe.VisiblePoints(t));
  }
  size_t visible_total = 0;
  for (const auto& v : visible) visible_total += v.size();

  // The runs: the feature sweep with the video-rate front end (default options), then the knobs
  // of the front end at 50 features, unknown features correcting the pose, and the scenario
  // variants; the peers run on the default 50-feature run's matches.
  struct Run {
    int features = 0;
    std::string knob, key;
    std::function<void(pose::VisionOptions&)> tweak;
    const Event* event = nullptr;
    std::function<void(pose::PoseFilterOptions&)> filter_tweak = nullptr;
  };
  const Event bus{"bus", 3.0, 6.0}, bump{"bump", 5.0, 5.2};
  std::FILE* nees_csv = o.nees_csv.empty() ? nullptr : std::fopen(o.nees_csv.c_str(), "w");
  std::FILE* landmark_csv = o.landmark_csv.empty() ? nullptr : std::fopen(o.landmark_csv.c_str(), "w");
  if (landmark_csv) std::fprintf(landmark_csv, "row,t_s,id,on,observations,depth_m,true_depth_m,depth_sigma_m,u,v\n");
  std::FILE* match_csv = o.match_csv.empty() ? nullptr : std::fopen(o.match_csv.c_str(), "w");
  if (match_csv) std::fprintf(match_csv, "row,t_s,keyframe,x,y,z,depth_m,u,v,true_u,true_v\n");
  if (nees_csv) {
    std::fprintf(nees_csv, "row,t_s,keyframe,nees,nees_pos,nees_rot,dx,sx,dy,sy,dz,sz,dpitch,spitch,dyaw,syaw,droll,sroll,median_px,nis,reported_scale,nees_zpitch,rho_zpitch\n");
  }
  std::vector<Run> runs;
  for (int features : o.features) runs.push_back({features, "", features == 0 ? "gps_imu" : "gps_imu_vision_" + std::to_string(features), nullptr});
  auto add = [&](const std::string& knob, const std::string& key, std::function<void(pose::VisionOptions&)> tweak, const Event* e = nullptr) {
    runs.push_back({50, knob, "gps_imu_vision_50_" + key, std::move(tweak), e});
  };
  if (o.knobs) {
    add("full matching every frame (issue-5 front end)", "every_frame", [](pose::VisionOptions& v) { v.keyframe_interval = 1, v.visibility_cache_m = 0; });
    add("lines followed between keyframes (1D edge search)", "line_tracking", [](pose::VisionOptions& v) { v.track_lines = true; });
    add("tracked corners re-snapped by cornerSubPix", "resnap", [](pose::VisionOptions& v) { v.refine_tracked_corners = true; });
    add("tracking from the first frame (no lock wait)", "no_lock_wait", [](pose::VisionOptions& v) { v.lock_frames = 0; });
    add("tracked features at detection noise", "tracked_sigma_0", [](pose::VisionOptions& v) { v.tracked_sigma_px = 0; });
    add("keyframe every 5", "keyframe_5", [](pose::VisionOptions& v) { v.keyframe_interval = 5; });
    add("keyframe every 20", "keyframe_20", [](pose::VisionOptions& v) { v.keyframe_interval = 20; });
    add("no visibility cache", "no_visibility_cache", [](pose::VisionOptions& v) { v.visibility_cache_m = 0; });
    add("never declared lost", "never_lost", [](pose::VisionOptions& v) { v.lost_frames = 0; });
    add("unknown features tracked though unused (the default before issue 19's moonshot)", "unused_unknown", [](pose::VisionOptions& v) { v.use_new_points = true; });
  }
  if (o.consistency_knobs) {  // issue 19: the filter's noise model against NEES
    auto add_filter = [&](const std::string& knob, const std::string& key, std::function<void(pose::PoseFilterOptions&)> tweak,
                          std::function<void(pose::VisionOptions&)> vtweak = nullptr) {
      runs.push_back({50, knob, "gps_imu_vision_50_" + key, std::move(vtweak), nullptr, std::move(tweak)});
    };
    add_filter("pixel sigma 2.0 px", "pixel_sigma_2", [](pose::PoseFilterOptions& f) { f.pixel_sigma_px = 2.0; });
    add_filter("pixel sigma 1.5 px (before the fifteenth session)", "pixel_sigma_1_5", [](pose::PoseFilterOptions& f) { f.pixel_sigma_px = 1.5; });
    add_filter("no gyro bias in the state (before the fifteenth session)", "no_gyro_bias", [](pose::PoseFilterOptions& f) { f.estimate_gyro_bias = false; });
    add_filter("gyro bias in the state, prior widened by 1 m / 1 deg before the first frame", "gyro_bias_acquisition", nullptr,
               [](pose::VisionOptions& v) { v.acquisition_position_sigma_m = 1.0, v.acquisition_orientation_sigma_deg = 1.0; });
    add_filter("angular acceleration noise 3 rad/s2/sqrt(Hz)", "angular_accel_3", [](pose::PoseFilterOptions& f) { f.angular_accel_noise_rad_s2 = 3.0; });
    add_filter("acceleration noise 1 m/s2/sqrt(Hz) (before issue 19)", "accel_1", [](pose::PoseFilterOptions& f) { f.accel_noise_m_s2 = 1.0; });
    add_filter("acceleration noise 5 m/s2/sqrt(Hz)", "accel_5", [](pose::PoseFilterOptions& f) { f.accel_noise_m_s2 = 5.0; });
  }
  if (o.new_points) {
    runs.push_back({50, "unknown points also correcting the pose (no cross-covariances, issue 5)", "gps_imu_vision_unknown_50",
                    [](pose::VisionOptions& v) { v.new_points_in_pose = true; }});
    runs.push_back({50, "unknown points in the state, cross-covariances kept", "gps_imu_vision_joint_50",
                    [](pose::VisionOptions& v) { v.joint_new_points = true; }});
    runs.push_back({50, "unknown points in the state, tracked frame to frame only (before issue 19 part 3)", "gps_imu_vision_joint_50_frame_to_frame",
                    [](pose::VisionOptions& v) {
                      v.joint_new_points = true;
                      v.unknown_from_keyframe = false;
                    }});
    auto joint = [&](const std::string& knob, const std::string& key, std::function<void(pose::VisionOptions&)> tweak) {
      runs.push_back({50, "unknown points in the state, " + knob, "gps_imu_vision_joint_50_" + key, [tweak](pose::VisionOptions& v) {
                        v.joint_new_points = true;
                        tweak(v);
                      }});
    };
    // Session pose19j's joining tests, each taken back out, and all of them (the joint mode before it).
    joint("as before session pose19j (0.3 m sigma only, 15 in the state, no joining tests)", "before_pose19j", [](pose::VisionOptions& v) {
      v.new_point_depth_sigma_ratio = 0, v.max_state_points = 15, v.join_bearing_drift_px = 0, v.join_model_depth_tolerance = 0;
    });
    joint("no bearing-drift test", "no_bearing_test", [](pose::VisionOptions& v) { v.join_bearing_drift_px = 0; });
    joint("no static-model depth test", "no_model_test", [](pose::VisionOptions& v) { v.join_model_depth_tolerance = 0; });
    joint("no joining tests (relative depth sigma, 25 in the state)", "no_join_tests", [](pose::VisionOptions& v) {
      v.join_bearing_drift_px = 0, v.join_model_depth_tolerance = 0;
    });
    joint("0.3 m sigma only (no relative depth criterion)", "absolute_sigma", [](pose::VisionOptions& v) { v.new_point_depth_sigma_ratio = 0; });
    joint("15 in the state", "max_state_15", [](pose::VisionOptions& v) { v.max_state_points = 15; });
    joint("depth sigma not inflated at joining (before issue 19 part 3)", "depth_sigma_1", [](pose::VisionOptions& v) { v.join_depth_sigma_scale = 1; });
    joint("new tracks only while locked", "after_lock", [](pose::VisionOptions& v) { v.unknown_after_lock = true; });
    joint("joining at 0.5 m sigma (from 0.3)", "sigma_05", [](pose::VisionOptions& v) { v.new_point_sigma_m = 0.5; });
    joint("landmark sightings at 1.5 px extra noise (before issue 19's twelfth session)", "landmark_1_5px",
          [](pose::VisionOptions& v) { v.landmark_sigma_px = 1.5; });
    runs.push_back({50, "unknown points in the state, landmark sightings at 3 px extra noise", "gps_imu_vision_joint_50_landmark_3px",
                    [](pose::VisionOptions& v) {
                      v.joint_new_points = true;
                      v.landmark_sigma_px = 3.0;
                    }});
    runs.push_back({50, "unknown points in the state, joining after 15 sightings", "gps_imu_vision_joint_50_min15", [](pose::VisionOptions& v) {
                      v.joint_new_points = true;
                      v.new_point_min_observations = 15;
                    }});
  }
  const bool variants = o.variants && o.seconds >= 7.2;
  if (variants) {
    add("bus covering half the image 3-6 s", "bus", nullptr, &bus);
    add("camera bumped 5 deg at 5.0-5.2 s", "bump", nullptr, &bump);
  }
  if (!o.rows.empty()) {  // only the rows named (their JSON keys)
    std::erase_if(runs, [&](const Run& r) { return std::find(o.rows.begin(), o.rows.end(), r.key) == o.rows.end(); });
  }
  const cv::Mat bus_texture = BusTexture();

  std::vector<Row> rows;
  Row pnp{"peer: cv::solvePnP", 50}, ransac{"peer: cv::solvePnPRansac", 50};
  pnp.key = "peer__cv__solvePnP", ransac.key = "peer__cv__solvePnPRansac";
  int pnp_frames = 0, ransac_frames = 0;
  for (const Run& run : runs) {
    Row row{run.features == 0 ? "gps-imu" : "gps-imu-vision", run.features, run.knob, run.key};
    row.nees_at_frame.assign(n, std::numeric_limits<double>::quiet_NaN());
    row.event = run.event;
    pose::PoseFilterOptions fo;
    fo.orientation_correlation_s = o.ahrs_correlation_s;
    fo.gyro_correlation_s = o.gyro_correlation_s;
    fo.orientation_sigma_deg = o.ahrs_sigma_deg;
    fo.heading_sigma_deg = o.ahrs_heading_sigma_deg;
    fo.gravity_window_s = o.gravity_window_s;
    fo.gps_correlation_s = o.gps_correlation_s;
    fo.gps_min_sigma_m = o.gps_min_sigma_m;
    fo.gate_chi2_2dof = o.gate_chi2_2dof;
    fo.pixel_sigma_px = o.pixel_sigma_px;
    fo.gps_bias_sigma_m = o.gps_bias_sigma_m;
    fo.gps_reanchor_s = o.gps_reanchor_s;
    fo.gps_reanchor_sigma_m = o.gps_reanchor_sigma_m;
    fo.gps_reanchor_min_m = o.gps_reanchor_min_m;
    fo.gps_reanchor_orientation_sigma_deg = o.gps_reanchor_orientation_sigma_deg;
    fo.gyro_sigma_rad_s = o.gyro_sigma_rad_s;
    fo.estimate_gyro_bias = o.gyro_bias;
    fo.gyro_bias_sigma_rad_s = o.gyro_bias_sigma_rad_s;
    fo.accel_noise_m_s2 = o.accel_noise_m_s2;
    fo.angular_accel_noise_rad_s2 = o.angular_accel_noise_rad_s2;
    if (run.filter_tweak) run.filter_tweak(fo);
    pose::PoseTracker tracker(log, fo);
    int64_t gps_reanchored = 0;
    pose::VisionOptions vo;
    vo.max_features = run.features;
    vo.acquiring_sigma_px = o.acquiring_sigma_px;
    vo.acquisition_position_sigma_m = o.acquisition_sigma_m;
    vo.acquisition_coarse_passes = o.acquisition_passes;
    vo.lock_alignment_px = o.lock_alignment_px;
    vo.tracked_sigma_px = o.tracked_sigma_px;
    vo.tracked_max_innovation_px = o.tracked_max_innovation_px;
    vo.max_alignment_score_px = o.max_alignment_score_px;
    vo.locked_search_sigmas = o.locked_search_sigmas;
    vo.line_ambiguity_ratio = o.line_ambiguity_ratio;
    vo.line_max_overhang_px = o.line_max_overhang_px;
    vo.min_view_points = o.min_view_points;
    vo.relocalize_min_outline_share = o.relocalize_min_outline_share;
    vo.relocalize_extent_m = o.relocalize_extent_m;
    vo.relocalize_extent_sigmas = o.relocalize_extent_sigmas;
    vo.relocalize_max_extent_m = o.relocalize_max_extent_m;
    vo.acquisition_heading_search_deg = o.heading_search_deg;
    vo.relocalize_step_m = o.relocalize_step_m;
    vo.relocalize_distinct_px = o.relocalize_distinct_px;
    vo.relocalize_max_score_px = o.relocalize_max_score_px;
    vo.relocalize_retry_frames = o.relocalize_retry_frames;
    vo.acquisition_roll_search_deg = o.roll_search_deg;
    vo.acquisition_orientation_sigma_deg = o.acquisition_sigma_deg;
    vo.feature_bias_px = o.feature_bias_px;
    vo.feature_point_bias_px = o.feature_point_bias_px;
    vo.feature_point_bias_near_px = o.feature_point_bias_near_px;
    vo.acquisition_association_px = o.acquisition_association_px;
    vo.carrier_height_m = o.carrier_height_m < 0 ? camera->path->height_m : o.carrier_height_m;
    vo.carrier_height_sigma_m = o.carrier_height_sigma_m;
    vo.carrier_height_correlation_s = o.carrier_height_correlation_s;
    vo.nis_short_gain = o.nis_short_gain;
    vo.landmark_bias_px = o.landmark_bias_px;
    vo.landmark_sigma_px = o.landmark_sigma_px;
    vo.max_state_points = o.max_state_points;
    vo.join_depth_sigma_scale = o.join_depth_sigma_scale;
    vo.segment_detector = o.segments == "fld" ? pose::SegmentDetector::kFastLine : pose::SegmentDetector::kLsd;
    vo.feature_shared_bias_px = o.feature_shared_bias_px;
    vo.feature_class_bias_px = o.feature_class_bias_px;
    vo.foot_variance_scale = o.foot_variance_scale;
    vo.corners_on_edges = o.corners_on_edges;
    vo.corner_window_px = o.corner_window_px;
    vo.corner_bias_px = o.corner_bias_px;
    vo.point_bias_gain = o.point_bias_gain;
    vo.point_bias_weight_px = o.point_bias_weight_px;
    vo.local_fit_px = o.local_fit_px;
    vo.robust_residual_px = o.robust_residual_px;
    vo.use_lines = o.lines;
    if (run.tweak) run.tweak(vo);
    pose::VisionTracker vision(map, mesh, k, vo);
    const bool peer = run.features == 50 && run.key == "gps_imu_vision_50";
    for (int f = 0; f < n; ++f) {
      const double t_s = f / 30.0;
      const int64_t t_ns = static_cast<int64_t>(std::llround((o.start_s + f / 30.0) * 1e9));
      Rigid3d frame_truth = truth[f];
      const sim::SimImage* frame = &frames[f];
      sim::SimImage changed;
      if (run.event) {
        changed = frames[f];
        if (ApplyEvent(*run.event, bus_texture, k, f, t_s, changed, frame_truth)) frame = &changed;
      }
      const std::vector<Eigen::Vector3d> seen = frame_truth.translation == truth[f].translation && frame == &frames[f] ? visible[f] : vision.VisiblePoints(frame_truth);
      const Clock::time_point t0 = Clock::now();
      const pose::PoseSample prior = tracker.Advance(t_ns);
      const double filter_ms = MsSince(t0);
      row.filter_ms += filter_ms;
      if (!prior.valid) continue;
      double frame_ms = filter_ms;
      bool vision_keyframe = false;
      double frame_nis = -1, frame_scale = 1;
      if (run.features > 0) {
        const pose::VisionFrameStats s = vision.Update(frame->bgr.data(), frame->width, frame->height, tracker.filter());
        row.detect_ms += s.detect_ms;
        row.update_ms += s.update_ms;
        frame_ms += s.detect_ms + s.update_ms;
        row.used += s.features_used();
        for (int st = 0; st < pose::kVisionStageCount; ++st) row.stage_ms[st] += s.stage_ms[st];
        row.keyframes += s.keyframe;
        vision_keyframe = s.keyframe;
        frame_nis = s.nis;
        frame_scale = s.reported_scale;
        row.weak_locks += s.weak_lock;
        row.unfit += s.unfit;
        row.relocalized += s.relocalized;
        row.reoriented += s.reoriented_heading_deg != 0;
        if (s.reoriented_heading_deg != 0)  // rare: acquisition only
          std::fprintf(stderr, "%s t=%.2f s: heading searched, turned %+.0f deg\n", run.key.c_str(), o.start_s + t_s, s.reoriented_heading_deg);
        if (s.relocks > 0 || s.relocalized) {  // rare: a technician reading the run wants to see where the lock went
          const Rigid3d now = tracker.filter().world_from_camera();
          std::fprintf(stderr, "%s t=%.2f s: %s, now %.1f m and %.1f deg from the truth\n", run.key.c_str(), o.start_s + t_s,
                       s.relocalized ? "relocalised" : "declared lost", (now.translation - frame_truth.translation).norm(),
                       Eigen::AngleAxisd(now.rotation * frame_truth.rotation.conjugate()).angle() * 180 / 3.14159265358979323846);
        }
        row.relocalize_waiting += s.relocalize_waiting;
        row.thin_views += s.keyframe && s.thin_view;
        row.relocks += s.relocks;
        row.rejected_tracked_jump += s.rejected_tracked_jump;
        row.rejected_structure += s.rejected_structure;
        row.rejected_ambiguous += s.rejected_ambiguous;
        row.rejected_overhang += s.rejected_overhang;
        row.rejected_gate += s.rejected_gate, row.rejected_behind += s.rejected_behind, row.rejected_not_finite += s.rejected_not_finite;
        row.klt_lost += s.klt_lost, row.unknown_dropped += s.unknown_dropped;
        row.landmarks_in_state += s.landmarks_in_state;
        row.landmarks_refused += s.landmarks_refused;
        for (const auto& l : s.landmarks_joined) {
          ++row.landmarks_joined;
          const int on = LandmarkOnClass(*frame, l.px);
          ++row.joined_on[on];
          if (landmark_csv) {
            const Eigen::Vector3d c = frame_truth.Inverse() * l.point;
            const Eigen::Vector3d z_axis = frame_truth.rotation * Eigen::Vector3d::UnitZ();
            const int u = std::clamp(static_cast<int>(std::lround(l.px.x())), 0, frame->width - 1);
            const int v = std::clamp(static_cast<int>(std::lround(l.px.y())), 0, frame->height - 1);
            const double true_depth = frame->depth_m.empty() ? -1.0 : frame->depth_m[frame->Index(u, v)];
            std::fprintf(landmark_csv, "%s,%.4f,%lld,%s,%d,%.3f,%.3f,%.3f,%.1f,%.1f\n", run.key.c_str(), t_s, static_cast<long long>(l.id), kOnNames[on],
                         l.observations, c.z(), true_depth, std::sqrt(z_axis.dot(l.covariance * z_axis)), l.px.x(), l.px.y());
          }
          const Eigen::Vector3d ray = (frame_truth.rotation * PixelRay(k, l.uv)).normalized();
          const std::optional<RayHit> hit = bvh.Raycast(frame_truth.translation, ray);
          const Eigen::Vector3d c = frame_truth.Inverse() * l.point;
          // Only where the mesh is what was seen (not a person, a tree or the bus): the true point
          // within 1 m of the same depth along the ray.
          if (!hit) continue;
          const Eigen::Vector3d truth_point = frame_truth.translation + hit->distance_m * ray;
          if (std::abs((frame_truth.Inverse() * truth_point).z() - c.z()) > 0.25 * c.z() + 1.0) continue;
          const Eigen::Vector3d e = l.point - truth_point;
          row.landmark_error_m.push_back(e.norm());
          row.landmark_nees.push_back(e.dot(l.covariance.ldlt().solve(e)));
        }
        for (const auto& [p, uv] : s.point_matches) {
          const auto true_uv = ProjectToPixel(k, frame_truth.Inverse() * p, 0.1);
          ++row.matches;
          if (match_csv && true_uv)
            std::fprintf(match_csv, "%s,%.4f,%d,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f\n", run.key.c_str(), t_s, s.keyframe ? 1 : 0, p.x(), p.y(), p.z(),
                         (frame_truth.Inverse() * p).z(), uv.x(), uv.y(), true_uv->x(), true_uv->y());
          row.matches_within_2px += true_uv && (*true_uv - uv).norm() <= 2.0;
          if (true_uv) (s.keyframe ? row.match_error_key_px : row.match_error_tracked_px).push_back((*true_uv - uv).norm());
          row.matches_beyond_3px += true_uv && (uv - *true_uv).norm() > 3.0;
          if (true_uv && (uv - *true_uv).norm() <= 3.0) {
            Row::PointResiduals& pr = row.point_residuals[{p.x(), p.y(), p.z()}];
            const Eigen::Vector2d d = uv - *true_uv;
            pr.n += 1, pr.u += d.x(), pr.v += d.y(), pr.uu += d.x() * d.x(), pr.vv += d.y() * d.y();
            pr.depth += (frame_truth.Inverse() * p).z();
            const bool eaves = p.z() > frame_truth.translation.z();
            std::array<double, 3>& sum = row.residual_sum[s.keyframe ? 0 : 1][eaves ? 1 : 0];
            sum[0] += (uv - *true_uv).x(), sum[1] += (uv - *true_uv).y(), sum[2] += 1;
          }
        }
        if (peer) {  // the peers: per-frame PnP on the same known-point matches
          for (int method = 0; method < 2; ++method) {
            Row& peer_row = method == 0 ? pnp : ransac;
            Rigid3d pnp_pose = prior.world_from_camera;
            const Clock::time_point p0 = Clock::now();
            if (s.point_matches.size() >= 6) {
              std::vector<cv::Point3d> object;
              std::vector<cv::Point2d> image;
              for (const auto& [p, uv] : s.point_matches) {
                object.emplace_back(p.x(), p.y(), p.z());
                image.emplace_back(uv.x(), uv.y());
              }
              const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
              const Rigid3d cam_from_world = prior.world_from_camera.Inverse();
              cv::Mat rvec, tvec;
              cv::eigen2cv(Eigen::Vector3d(pose::SO3Log(cam_from_world.rotation)), rvec);
              cv::eigen2cv(Eigen::Vector3d(cam_from_world.translation), tvec);
              const bool ok = method == 0 ? cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE)
                                          : cv::solvePnPRansac(object, image, K, cv::noArray(), rvec, tvec, true, 100, 3.0f, 0.99, cv::noArray(),
                                                               cv::SOLVEPNP_ITERATIVE);
              if (ok) {
                Eigen::Vector3d r, t;
                cv::cv2eigen(rvec, r);
                cv::cv2eigen(tvec, t);
                pnp_pose = Rigid3d(pose::SO3Exp(r), t).Inverse();
                ++(method == 0 ? pnp_frames : ransac_frames);
              }
            }
            const double pnp_ms = MsSince(p0);
            peer_row.update_ms += pnp_ms;
            peer_row.detect_ms += s.detect_ms;
            peer_row.frame_ms.push_back(s.detect_ms + pnp_ms);
            ++peer_row.frames;
            Misregistration(k, frame_truth, pnp_pose, seen, peer_row.errors_px, &peer_row.frame_median_px);
          }
        }
      }
      ++row.frames;
      row.frame_ms.push_back(frame_ms);
      if (tracker.stats().gps_reanchored != gps_reanchored) {  // rare: the filter had gated the GPS out for a second
        gps_reanchored = tracker.stats().gps_reanchored;
        std::fprintf(stderr, "%s t=%.2f s: re-anchored to the GPS (%lld fixes gated so far), now %.1f m from the truth\n", run.key.c_str(),
                     o.start_s + t_s, static_cast<long long>(tracker.stats().gps_gated),
                     (tracker.filter().world_from_camera().translation - frame_truth.translation).norm());
      }
      const pose::PoseSample current = tracker.Current();
      Misregistration(k, frame_truth, current.world_from_camera, seen, row.errors_px, &row.frame_median_px);
      row.frame_t_s.push_back(t_s);
      row.frame_errors_end.push_back(row.errors_px.size());
      const double nees = PoseNees(frame_truth, current);
      if (nees_csv) {
        // Errors truth - estimate, position (world, m) and rotation vector in the *camera* frame
        // (x right, y down, z forward: pitch, yaw, roll), each with its sigma and the 3-dof NEES
        // of each block.
        const Eigen::Vector3d dp = frame_truth.translation - current.world_from_camera.translation;
        const Eigen::Vector3d dth_w = pose::SO3Log(frame_truth.rotation * current.world_from_camera.rotation.conjugate());
        const Eigen::Matrix3d r_cw = current.world_from_camera.rotation.toRotationMatrix().transpose();
        const Eigen::Vector3d dth_c = r_cw * dth_w;
        const Eigen::Matrix3d p_pos = current.covariance.topLeftCorner<3, 3>();
        const Eigen::Matrix3d p_rot_c = r_cw * current.covariance.bottomRightCorner<3, 3>() * r_cw.transpose();
        const double nees_pos = dp.dot(p_pos.ldlt().solve(dp)), nees_rot = dth_c.dot(p_rot_c.ldlt().solve(dth_c));
        std::fprintf(nees_csv, "%s,%.4f,%d,%.4f,%.4f,%.4f", run.key.c_str(), t_s, static_cast<int>(vision_keyframe), nees, nees_pos, nees_rot);
        for (int i = 0; i < 3; ++i) std::fprintf(nees_csv, ",%.5f,%.5f", dp[i], std::sqrt(p_pos(i, i)));
        for (int i = 0; i < 3; ++i) std::fprintf(nees_csv, ",%.6f,%.6f", dth_c[i], std::sqrt(p_rot_c(i, i)));
        // The height and the pitch together (issue 19: a draw's pitch error follows its height
        // error), with the correlation the filter reports between them.
        const Eigen::Vector3d c_z_rot = r_cw * current.covariance.block<3, 3>(0, 3).row(2).transpose();
        Eigen::Matrix2d p_zp;
        p_zp << p_pos(2, 2), c_z_rot[0], c_z_rot[0], p_rot_c(0, 0);
        const Eigen::Vector2d e_zp(dp[2], dth_c[0]);
        std::fprintf(nees_csv, ",%.4f,%.3f,%.3f,%.4f,%.4f\n", row.frame_median_px.empty() ? -1.0 : row.frame_median_px.back(), frame_nis, frame_scale,
                     e_zp.dot(p_zp.ldlt().solve(e_zp)), c_z_rot[0] / std::sqrt(p_zp(0, 0) * p_zp(1, 1)));
      }
      ++row.nees_frames;
      row.nees_in_band += nees >= kNeesLow && nees <= kNeesHigh;
      row.nees_below += nees < kNeesLow;
      row.nees.push_back(nees);
      row.nees_at_frame[f] = nees;
      row.nees_above += nees > kNeesHigh;
      row.nees_sum += std::min(nees, 1e6);
      if (run.event) {
        std::vector<double>* window = t_s >= run.event->start_s - run.event->before_s && t_s < run.event->start_s ? &row.before_px
                                      : t_s >= run.event->start_s && t_s < run.event->end_s                       ? &row.during_px
                                      : t_s >= run.event->end_s && t_s < run.event->end_s + run.event->after_s     ? &row.after_px
                                                                                                                  : nullptr;
        if (window) Misregistration(k, frame_truth, current.world_from_camera, seen, *window, nullptr);
      }
    }
    rows.push_back(std::move(row));
  }
  if (pnp.frames > 0) rows.push_back(pnp);
  if (ransac.frames > 0) rows.push_back(ransac);

  // AVE §5.1: "one degree of orientation-angle error results in over 10 pixels of alignment error".
  auto one_degree = [&](const PinholeIntrinsics& kk, const Eigen::Vector3d& axis) {
    std::vector<double> e;
    for (int f = 0; f < n; ++f) {
      Rigid3d turned = truth[f];
      turned.rotation = (truth[f].rotation * pose::SO3Exp(axis.normalized() * 3.14159265358979323846 / 180)).normalized();
      Misregistration(kk, truth[f], turned, visible[f], e, nullptr);
    }
    return SpreadOf(e).median;
  };
  PinholeIntrinsics k2 = k;  // the same lens on a 1280x960 sensor (the paper's MEGA-D class)
  k2.width *= 2, k2.height *= 2, k2.fx *= 2, k2.fy *= 2, k2.cx = k2.cx * 2 + 0.5, k2.cy = k2.cy * 2 + 0.5;
  const Eigen::Vector3d pitch = Eigen::Vector3d::UnitX(), yaw = Eigen::Vector3d::UnitY(), roll = Eigen::Vector3d::UnitZ();

  std::printf("ave-bench pose: %s camera %s, %d frames at 30 Hz (%.1f s), %zu model-point observations, render %.1f ms/frame\n",
              o.scenario.c_str(), o.camera.c_str(), n, o.seconds, visible_total, render_ms);
  std::printf("| mode | features used/frame | median px | p95 px | max px | point matches <= 2 px | NEES in 95 %% band | keyframes | filter ms | detect ms | EKF + unknown ms | total ms/frame | max frame ms |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  std::ostringstream json;
  json << "{\"bench\":\"pose\",\"scenario\":\"" << o.scenario << "\",\"camera\":\"" << o.camera << "\",\"seed\":" << o.seed << ",\"frames\":" << n
       << ",\"start_s\":" << o.start_s;
  double default_nees_in_band = -1;
  for (const Row& r : rows) {
    const Spread s = SpreadOf(r.errors_px);
    const double frames = std::max(1, r.frames);
    const std::string within = r.matches > 0 ? std::to_string(100 * r.matches_within_2px / r.matches) + " %" : "-";
    const double in_band = r.nees_frames > 0 ? static_cast<double>(r.nees_in_band) / r.nees_frames : -1;
    const double max_frame_ms = r.frame_ms.empty() ? 0 : *std::max_element(r.frame_ms.begin(), r.frame_ms.end());
    char nees[32] = "-", keyframes[32] = "-";
    if (in_band >= 0) std::snprintf(nees, sizeof(nees), "%.0f %%", 100 * in_band);
    if (r.features > 0 && r.nees_frames > 0) std::snprintf(keyframes, sizeof(keyframes), "%.0f %%", 100.0 * r.keyframes / frames);
    std::printf("| %s | %.1f | %.2f | %.2f | %.1f | %s | %s | %s | %.3f | %.2f | %.3f | %.2f | %.1f |\n", RowName(r).c_str(), r.used / frames, s.median,
                s.p95, s.max, within.c_str(), nees, keyframes, r.filter_ms / frames, r.detect_ms / frames, r.update_ms / frames, r.TotalMs(),
                max_frame_ms);
    if (r.key == "gps_imu_vision_50") default_nees_in_band = in_band;
    if (figures) {
      RowFigures& f = (*figures)[r.key] = {s.median, s.p95, in_band, r.nees_frames > 0 ? r.nees_sum / r.nees_frames : 0.0, r.TotalMs(), r.nees_frames,
                                           r.nees_below, r.nees_above, r.nees_at_frame};
      LockFigures(r.frame_median_px, r.frame_t_s, f);
      for (const auto& [point, q] : r.point_residuals)
        if (q.n >= 10) f.point_mean_px[point] = Eigen::Vector2d(q.u / q.n, q.v / q.n);
    }
    char buf[512];
    int len = std::snprintf(buf, sizeof(buf), ",\"%s\":{\"median_px\":%.3f,\"p95_px\":%.3f,\"max_px\":%.2f,\"update_ms\":%.4f,\"ms_per_frame\":%.3f",
                            r.key.c_str(), s.median, s.p95, s.max, r.update_ms / frames, r.TotalMs());
    if (in_band >= 0) len += std::snprintf(buf + len, sizeof(buf) - len, ",\"nees_in_band\":%.3f,\"nees_mean\":%.2f", in_band, r.nees_sum / r.nees_frames);
    if (r.event) {
      len += std::snprintf(buf + len, sizeof(buf) - len, ",\"before_median_px\":%.3f,\"during_median_px\":%.3f,\"after_median_px\":%.3f,\"after_p95_px\":%.3f",
                           SpreadOf(r.before_px).median, SpreadOf(r.during_px).median, SpreadOf(r.after_px).median, SpreadOf(r.after_px).p95);
    }
    json << buf << "}";
  }
  if (default_nees_in_band >= 0) json << ",\"nees_in_band\":" << default_nees_in_band;
  std::printf("PnP peers converged on %d (solvePnP) and %d (solvePnPRansac) of %d frames (GPS+inertial pose otherwise)\n", pnp_frames,
              ransac_frames, pnp.frames);

  // Stage table: thread CPU ms per frame of each front-end stage, per 50-feature configuration.
  std::vector<const Row*> staged;
  for (const Row& r : rows)
    if (r.features == 50 && r.mode == "gps-imu-vision" && !r.event && r.key.find("unknown") == std::string::npos &&
        r.key.find("joint") == std::string::npos)
      staged.push_back(&r);
  if (!staged.empty()) {
    std::printf("\nvision front end, CPU ms per frame by stage (one core):\n| stage |");
    for (const Row* r : staged) std::printf(" %s |", r->knob.empty() ? "default (keyframe every 10)" : r->knob.c_str());
    std::printf("\n| --- |");
    for (size_t i = 0; i < staged.size(); ++i) std::printf(" ---: |");
    std::printf("\n");
    for (int st = 0; st < pose::kVisionStageCount; ++st) {
      std::printf("| %s |", pose::VisionStageName(st));
      for (const Row* r : staged) std::printf(" %.2f |", r->stage_ms[st] / std::max(1, r->frames));
      std::printf("\n");
    }
    std::printf("| **total** |");
    for (const Row* r : staged) std::printf(" **%.2f** |", r->TotalMs());
    std::printf("\n");
  }
  std::printf("\nrejections over the run (features not applied, by reason):\n| mode | outside the gate | tracked, off the prediction | corner's edges not found | line's segment shared (ambiguous) | line's segment overhangs | behind the camera | not finite | KLT lost | unknown features dropped (gate) | weak-lock keyframes | declared lost | keyframes the model fits nowhere | relocalised | heading turned | waiting for a fit | thin-view keyframes |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const Row& r : rows) {
    if (r.features == 0 || r.mode != "gps-imu-vision") continue;
    std::printf("| %s | %lld | %lld | %lld | %lld | %lld | %lld | %lld | %lld | %lld | %d | %d | %d | %d | %d | %d | %d |\n", RowName(r).c_str(), static_cast<long long>(r.rejected_gate),
                static_cast<long long>(r.rejected_tracked_jump), static_cast<long long>(r.rejected_structure), static_cast<long long>(r.rejected_ambiguous),
                static_cast<long long>(r.rejected_overhang),
                static_cast<long long>(r.rejected_behind), static_cast<long long>(r.rejected_not_finite), static_cast<long long>(r.klt_lost),
                static_cast<long long>(r.unknown_dropped), r.weak_locks, r.relocks, r.unfit, r.relocalized, r.reoriented, r.relocalize_waiting, r.thin_views);
  }
  std::printf("\nNEES of the pose per frame against the chi2(6) 95 %% band [%.2f, %.2f] (below: the covariance is too large; above: too small),"
              " and unknown features joining the state vs the static mesh's point on the true ray:\n"
              "| mode | in band | below | above | mean NEES | median NEES | known-point match error vs truth, keyframes: median (p95) px | tracked: median (p95) px | landmarks in state (mean) | joined | with mesh truth | median error m | p95 error m | landmark NEES mean (3 dof) | landmark NEES <= 7.81 |\n"
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n", kNeesLow, kNeesHigh);
  for (const Row& r : rows) {
    if (r.nees_frames == 0) continue;
    const double f = r.nees_frames;
    double lm_nees = 0;
    int lm_in = 0;
    for (double x : r.landmark_nees) lm_nees += x / std::max<size_t>(1, r.landmark_nees.size()), lm_in += x <= 7.81;
    const Spread le = SpreadOf(r.landmark_error_m);
    const Spread mk = SpreadOf(r.match_error_key_px), mt = SpreadOf(r.match_error_tracked_px);
    std::printf("| %s | %.0f %% | %.0f %% | %.0f %% | %.1f | %.1f | %.2f (%.2f) | %.2f (%.2f) | %.1f | %d | %zu | %.2f | %.2f | %.1f | %.0f %% |\n", RowName(r).c_str(), 100 * r.nees_in_band / f,
                100 * r.nees_below / f, 100 * r.nees_above / f, r.nees_sum / f, SpreadOf(r.nees).median, mk.median, mk.p95, mt.median, mt.p95, r.landmarks_in_state / std::max(1, r.frames), r.landmarks_joined,
                r.landmark_error_m.size(), le.median, le.p95, lm_nees, r.landmark_nees.empty() ? 0.0 : 100.0 * lm_in / r.landmark_nees.size());
  }
  std::printf("\nunknown features that joined the state, by what they sit on (the simulator's class mask at their pixel; a mover or a tree"
              " anywhere in the 3x3 neighbourhood counts), and the joining tests' refusals (per feature and frame):\n| mode | refused | joined |");
  for (const char* name : kOnNames) std::printf(" %s |", name);
  std::printf("\n| --- | ---: | ---: |");
  for (size_t i = 0; i < kOnNames.size(); ++i) std::printf(" ---: |");
  std::printf("\n");
  for (const Row& r : rows) {
    if (r.landmarks_joined == 0) continue;
    std::printf("| %s | %lld | %d |", RowName(r).c_str(), static_cast<long long>(r.landmarks_refused), r.landmarks_joined);
    for (int c : r.joined_on) std::printf(" %d |", c);
    std::printf("\n");
  }
  std::printf("\nknown-point match residuals (observed - true projection, px, matches within 3 px): mean u, mean v (count)\n"
              "| mode | keyframes, wall feet | keyframes, eaves | tracked, wall feet | tracked, eaves |\n| --- | ---: | ---: | ---: | ---: |\n");
  for (const Row& r : rows) {
    if (r.features == 0 || r.mode != "gps-imu-vision") continue;
    std::printf("| %s |", RowName(r).c_str());
    for (int a = 0; a < 2; ++a)
      for (int b = 0; b < 2; ++b) {
        const std::array<double, 3>& q = r.residual_sum[a][b];
        const double c = std::max(1.0, q[2]);
        std::printf(" %+.3f, %+.3f (%.0f) |", q[0] / c, q[1] / c, q[2]);
      }
    std::printf("\n");
  }
  std::printf("\nknown-point match errors by the point's depth (matches within 3 px of the truth): RMS per axis of each point's mean error"
              " (persists over its sightings) and of the rest (varies), sightings-weighted; and the share of matches beyond 3 px\n"
              "| mode | depth | points | sightings | persisting px | varying px |\n| --- | --- | ---: | ---: | ---: | ---: |\n");
  for (const Row& r : rows) {
    if (r.features == 0 || r.mode != "gps-imu-vision" || r.point_residuals.empty()) continue;
    constexpr std::array<double, 4> kBands = {0, 60, 120, 1e9};
    for (size_t b = 0; b + 1 < kBands.size(); ++b) {
      double points = 0, n = 0, persisting = 0, varying = 0;
      for (const auto& [key, q] : r.point_residuals) {
        if (q.n < 10 || q.depth / q.n < kBands[b] || q.depth / q.n >= kBands[b + 1]) continue;  // ten sightings for a mean
        const double mu = q.u / q.n, mv = q.v / q.n;
        points += 1, n += q.n;
        persisting += q.n * (mu * mu + mv * mv) / 2;
        varying += (q.uu - q.n * mu * mu + q.vv - q.n * mv * mv) / 2;
      }
      if (n == 0) continue;
      std::printf("| %s | %s | %.0f | %.0f | %.2f | %.2f |\n", RowName(r).c_str(),
                  b + 2 < kBands.size() ? (std::to_string(static_cast<int>(kBands[b])) + "-" + std::to_string(static_cast<int>(kBands[b + 1])) + " m").c_str()
                                        : (std::to_string(static_cast<int>(kBands[b])) + " m and more").c_str(),
                  points, n, std::sqrt(persisting / n), std::sqrt(varying / n));
    }
    std::printf("| %s | matches beyond 3 px | | %d of %d | %.1f %% | |\n", RowName(r).c_str(), r.matches_beyond_3px, r.matches,
                100.0 * r.matches_beyond_3px / std::max(1, r.matches));
  }
  // A long run (the whole walk, issue 19's sixteenth session) by 10 s windows: where the lock
  // holds, where the view has no model point, where the NEES leaves the band.
  if (o.seconds >= 20) {
    std::printf("\nthe run by 10 s windows (scene time from --start): misregistration median px (p95), frames with no model point in view, NEES in the 95 %% band:\n");
    std::printf("| mode | window | median px (p95) | no point in view | NEES in band |\n| --- | --- | ---: | ---: | ---: |\n");
    for (const Row& r : rows) {
      if (!r.knob.empty() || r.event || r.frame_errors_end.empty()) continue;
      const size_t frames = r.frame_errors_end.size();
      for (size_t w0 = 0; w0 < frames; w0 += 300) {
        const size_t w1 = std::min(frames, w0 + 300);
        const size_t e0 = w0 == 0 ? 0 : r.frame_errors_end[w0 - 1], e1 = r.frame_errors_end[w1 - 1];
        const Spread spread = SpreadOf(std::vector<double>(r.errors_px.begin() + static_cast<std::ptrdiff_t>(e0), r.errors_px.begin() + static_cast<std::ptrdiff_t>(e1)));
        int blind = 0, in_band = 0, scored = 0;
        for (size_t f = w0; f < w1; ++f) {
          blind += r.frame_errors_end[f] == (f == 0 ? 0 : r.frame_errors_end[f - 1]);
          if (f < r.nees_at_frame.size() && std::isfinite(r.nees_at_frame[f])) ++scored, in_band += r.nees_at_frame[f] >= kNeesLow && r.nees_at_frame[f] <= kNeesHigh;
        }
        std::printf("| %s | %.0f-%.0f s | %.2f (%.2f) | %.0f %% | %s |\n", RowName(r).c_str(), o.start_s + w0 / 30.0, o.start_s + w1 / 30.0, spread.median, spread.p95,
                    100.0 * blind / static_cast<double>(w1 - w0), scored ? (std::to_string(static_cast<int>(std::lround(100.0 * in_band / scored))) + " %").c_str() : "-");
      }
    }
  }
  std::printf("\nscenario variants, misregistration median px (p95) in the windows around the event:\n| variant | 1 s before | during | 1 s after |\n| --- | ---: | ---: | ---: |\n");
  for (const Row& r : rows) {
    if (!r.event) continue;
    const Spread b = SpreadOf(r.before_px), d = SpreadOf(r.during_px), a = SpreadOf(r.after_px);
    std::printf("| %s | %.2f (%.2f) | %.2f (%.2f) | %.2f (%.2f) |\n", RowName(r).c_str(), b.median, b.p95, d.median, d.p95, a.median, a.p95);
  }
  const double p = one_degree(k, pitch), y = one_degree(k, yaw), r = one_degree(k, roll), p2 = one_degree(k2, pitch), y2 = one_degree(k2, yaw);
  // The filter alone with exactly 50 features (the campus shows ~27 at a time): 50 point updates
  // on a copy (coarse pass) and 50 on the filter (fine pass), as vision.cc does per frame.
  double ekf50_ms = 0;
  {
    pose::PoseEkf ekf;
    ekf.Initialize(0, truth[0], 0.3, 0.02);
    std::vector<std::pair<Eigen::Vector3d, Eigen::Vector2d>> features;
    for (int i = 0; i < 50; ++i) {
      const Eigen::Vector3d p = truth[0] * Eigen::Vector3d(-12 + 0.5 * i, -4 + 0.17 * (i % 9), 10 + i);
      features.emplace_back(p, *ProjectToPixel(k, truth[0].Inverse() * p) + Eigen::Vector2d(0.3 * (i % 3 - 1), 0.2 * (i % 5 - 2)));
    }
    constexpr int kRepeats = 200;
    const Clock::time_point t0 = Clock::now();
    for (int r = 0; r < kRepeats; ++r) {
      pose::PoseEkf coarse = ekf, fine = ekf;
      for (const auto& [p, uv] : features) coarse.UpdatePoint(k, p, uv);
      for (const auto& [p, uv] : features) fine.UpdatePoint(k, p, uv);
    }
    ekf50_ms = MsSince(t0) / kRepeats;
  }
  std::printf("EKF update with 50 point features (coarse + fine pass, 100 updates): %.3f ms per frame\n", ekf50_ms);
  std::printf("1 deg orientation error, median px over visible model points: %dx%d fx=%.0f: pitch %.2f yaw %.2f roll %.2f;"
              " %dx%d fx=%.0f: pitch %.2f yaw %.2f\n",
              k.width, k.height, k.fx, p, y, r, k2.width, k2.height, k2.fx, p2, y2);
  char buf[256];
  std::snprintf(buf, sizeof(buf), ",\"one_deg_px\":{\"pitch\":%.2f,\"yaw\":%.2f,\"roll\":%.2f,\"pitch_fx%.0f\":%.2f,\"yaw_fx%.0f\":%.2f}", p, y, r,
                k2.fx, p2, k2.fx, y2);
  json << buf << ",\"ekf_update_50_features_ms\":" << ekf50_ms << ",\"render_ms\":" << render_ms << ",\"png\":\"" << o.png << "\"}";
  if (nees_csv) std::fclose(nees_csv);
  if (landmark_csv) std::fclose(landmark_csv);
  if (match_csv) std::fclose(match_csv);
  if (!o.png.empty()) Plot(rows, o.png, o.seconds);
  std::cout << json.str() << std::endl;
  return 0;
}

// Monte Carlo over the scenario's noise (issue 19, sixth session): every figure above comes from
// one draw of the GPS, inertial and camera noise, and the acquisition that draw happens to give.
// The same rows on `seeds` draws (seed, seed + 1, ...), each run's own tables silenced, then one
// table per row over the draws: how often the pose holds, and NEES pooled over all frames.
// The Monte Carlo NEES test (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to
// Tracking and Navigation", 2001, §5.4.2): at every frame, the pose NEES averaged over the M draws
// that have it; for a consistent filter M times that average is chi-square with 6 M dof, so it lies
// in [q(0.025, 6M), q(0.975, 6M)] / M at 95 % of the frames. Unlike the per-frame share pooled over
// draws, it sees an error the draws share: the scenery is the same in every draw, and so is what
// it does to the detections (a corner found off its model point) at a given frame.
struct MonteCarloNees {
  int frames = 0, in_band = 0, below = 0, above = 0, draws = 0;
  double low = 0, high = 0;                   // the band at the full number of draws
  std::vector<std::array<double, 3>> seconds;  // per second of the run: mean ANEES, share in band, frames
  // Issue 19, twelfth session: the per-frame share in the chi2(6) band, pooled over the draws, once
  // every frame's NEES is divided by its second's mean ANEES / 6 (resp. the run's): what the best
  // covariance scale that varies per second (resp. one for the whole run) could reach. The rest of
  // the miss is the spread between draws and frames within a second, which no scale removes.
  double scaled_per_second_in_band = -1, scaled_per_run_in_band = -1;
  double Share(int count) const { return frames > 0 ? static_cast<double>(count) / frames : -1.0; }
};

MonteCarloNees MonteCarloNeesOf(const std::vector<std::map<std::string, RowFigures>>& runs, const std::string& key) {
  MonteCarloNees mc;
  size_t n = 0;
  for (const auto& run : runs) {
    const auto it = run.find(key);
    if (it != run.end()) n = std::max(n, it->second.nees_at_frame.size()), ++mc.draws;
  }
  mc.low = mc.draws > 0 ? ChiSquareQuantile(0.025, 6.0 * mc.draws) / mc.draws : 0;
  mc.high = mc.draws > 0 ? ChiSquareQuantile(0.975, 6.0 * mc.draws) / mc.draws : 0;
  for (size_t f = 0; f < n; ++f) {
    double sum = 0;
    int m = 0;
    for (const auto& run : runs) {
      const auto it = run.find(key);
      if (it == run.end() || f >= it->second.nees_at_frame.size() || !std::isfinite(it->second.nees_at_frame[f])) continue;
      sum += it->second.nees_at_frame[f], ++m;
    }
    if (m == 0) continue;
    const double anees = sum / m, low = ChiSquareQuantile(0.025, 6.0 * m) / m, high = ChiSquareQuantile(0.975, 6.0 * m) / m;
    ++mc.frames;
    mc.in_band += anees >= low && anees <= high, mc.below += anees < low, mc.above += anees > high;
    const size_t second = f / 30;
    if (mc.seconds.size() <= second) mc.seconds.resize(second + 1, {0, 0, 0});
    mc.seconds[second][0] += std::min(anees, 1e6), mc.seconds[second][1] += anees >= low && anees <= high, mc.seconds[second][2] += 1;
  }
  double run_sum = 0, run_frames = 0;
  for (const auto& sec : mc.seconds) run_sum += sec[0], run_frames += sec[2];
  const double low6 = ChiSquareQuantile(0.025, 6), high6 = ChiSquareQuantile(0.975, 6);
  double per_second = 0, per_run = 0, pooled = 0;
  for (const auto& run : runs) {
    const auto it = run.find(key);
    if (it == run.end()) continue;
    const std::vector<double>& nees = it->second.nees_at_frame;
    for (size_t f = 0; f < nees.size() && f / 30 < mc.seconds.size(); ++f) {
      const auto& sec = mc.seconds[f / 30];
      if (!std::isfinite(nees[f]) || sec[2] == 0 || !(sec[0] > 0) || !(run_sum > 0)) continue;
      const double by_second = 6 * nees[f] * sec[2] / sec[0], by_run = 6 * nees[f] * run_frames / run_sum;
      per_second += by_second >= low6 && by_second <= high6, per_run += by_run >= low6 && by_run <= high6, ++pooled;
    }
  }
  if (pooled > 0) mc.scaled_per_second_in_band = per_second / pooled, mc.scaled_per_run_in_band = per_run / pooled;
  return mc;
}

void PrintMonteCarloNees(const MonteCarloNees& mc) {
  if (mc.frames == 0) return;
  std::printf("Monte Carlo NEES (per frame, averaged over the %d draws, against the chi2(6 x %d) / %d 95 %% band [%.2f, %.2f]): in band %.1f %%"
              " of frames, below %.1f %%, above %.1f %%\n| second | mean ANEES | frames in band |\n| ---: | ---: | ---: |\n",
              mc.draws, mc.draws, mc.draws, mc.low, mc.high, 100 * mc.Share(mc.in_band), 100 * mc.Share(mc.below), 100 * mc.Share(mc.above));
  for (size_t i = 0; i < mc.seconds.size(); ++i) {
    const auto& s = mc.seconds[i];
    if (s[2] > 0) std::printf("| %zu-%zu | %.1f | %.0f %% |\n", i, i + 1, s[0] / s[2], 100 * s[1] / s[2]);
  }
  if (mc.scaled_per_second_in_band >= 0)
    std::printf("Best covariance scale: the frames' NEES in the chi2(6) band, pooled, with each second's mean ANEES scaled to 6: %.1f %%;"
                " with the run's: %.1f %% (the spread between draws within a second is left)\n",
                100 * mc.scaled_per_second_in_band, 100 * mc.scaled_per_run_in_band);
}

// The known points' persisting match errors compared between draws (issue 19, twentieth session):
// for every point with a mean error on two draws or more, how much of the spread of those means is
// common to the draws (the scenery's: the geometry and the light the detector sees) rather than
// the draw's own noise. Per image axis, 1 - (mean within-point variance between draws) / (mean
// squared error). Near 1: the draws share one draw of the scenery's errors, and a Monte Carlo over
// them cannot average those out.
struct SceneryShare {
  int points = 0;
  Eigen::Vector2d rms_px = Eigen::Vector2d::Zero(), share = Eigen::Vector2d::Constant(-1);
};
SceneryShare SceneryShareOf(const std::vector<std::map<std::string, RowFigures>>& runs, const std::string& key) {
  std::map<std::tuple<double, double, double>, std::vector<Eigen::Vector2d>> by_point;
  for (const auto& run : runs) {
    const auto it = run.find(key);
    if (it == run.end()) continue;
    for (const auto& [point, mean] : it->second.point_mean_px) by_point[point].push_back(mean);
  }
  SceneryShare out;
  Eigen::Vector2d within = Eigen::Vector2d::Zero(), total = Eigen::Vector2d::Zero();
  for (const auto& [point, means] : by_point) {
    if (means.size() < 2) continue;
    Eigen::Vector2d mu = Eigen::Vector2d::Zero(), w = Eigen::Vector2d::Zero(), t = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& m : means) mu += m / static_cast<double>(means.size());
    for (const Eigen::Vector2d& m : means) w += (m - mu).cwiseAbs2(), t += m.cwiseAbs2();
    within += w / static_cast<double>(means.size() - 1), total += t / static_cast<double>(means.size());
    ++out.points;
  }
  if (out.points == 0) return out;
  out.rms_px = (total / out.points).cwiseSqrt();
  for (int a = 0; a < 2; ++a) out.share[a] = total[a] > 0 ? 1 - within[a] / total[a] : -1;
  return out;
}

int RunPoseSeeds(const PoseBenchOptions& o) {
  PoseBenchOptions one = o;
  one.seeds = 1;
  one.png.clear();
  one.nees_csv.clear();
  one.landmark_csv.clear();
  one.match_csv.clear();
  one.knobs = one.variants = one.consistency_knobs = false;
  if (one.rows.empty()) one.rows = {"gps_imu_vision_50"};
  std::vector<std::map<std::string, RowFigures>> runs;
  for (int i = 0; i < o.seeds; ++i) {
    one.seed = o.seed + i;
    one.start_s = o.start_s + i * o.start_spread_s;
    std::fprintf(stderr, "ave-bench pose: seed %d (%d of %d)\n", one.seed, i + 1, o.seeds);
    std::fflush(stdout);
    const int saved = dup(STDOUT_FILENO), null = open("/dev/null", O_WRONLY);
    if (saved >= 0 && null >= 0) dup2(null, STDOUT_FILENO);
    std::map<std::string, RowFigures> figures;
    const int rc = RunPose(one, &figures);
    std::fflush(stdout);
    if (saved >= 0 && null >= 0) dup2(saved, STDOUT_FILENO);
    if (null >= 0) close(null);
    if (saved >= 0) close(saved);
    if (rc != 0) return rc;
    runs.push_back(std::move(figures));
  }
  std::printf("ave-bench pose: %s camera %s, %.1f s, Monte Carlo over %d draws of the noise (seeds %d-%d), starting at %.1f s + %.1f s per draw\n",
              o.scenario.c_str(), o.camera.c_str(), o.seconds, o.seeds, o.seed, o.seed + o.seeds - 1, o.start_s, o.start_spread_s);
  std::ostringstream json;
  json << "{\"bench\":\"pose_seeds\",\"scenario\":\"" << o.scenario << "\",\"camera\":\"" << o.camera << "\",\"seed\":" << o.seed << ",\"seeds\":" << o.seeds
       << ",\"start_s\":" << o.start_s << ",\"start_spread_s\":" << o.start_spread_s;
  for (const std::string& key : one.rows) {
    std::printf("\n%s: per draw (locked: the first frame within 2 px whose next second stays within 5 px; after it, the frames' median px)\n"
                "| seed | start s | median px | p95 px | NEES in band | mean NEES | ms/frame | locked after s | then median px | then p95 px |\n"
                "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
                key.c_str());
    std::vector<double> medians, p95s, ms, lock_times;
    int locked = 0;
    double in_band_frames = 0, frames = 0, below = 0, above = 0;
    double locked_frames = 0, locked_in_band = 0;  // the frames from each draw's lock on
    int held = 0;  // draws whose median misregistration stays <= 1 px
    for (size_t i = 0; i < runs.size(); ++i) {
      const auto it = runs[i].find(key);
      if (it == runs[i].end()) continue;
      const RowFigures& f = it->second;
      char lock[96] = "never | - | -";
      if (f.lock_s >= 0) std::snprintf(lock, sizeof(lock), "%.1f | %.2f | %.2f", f.lock_s, f.after_lock_median_px, f.after_lock_p95_px);
      std::printf("| %d | %.1f | %.2f | %.2f | %s | %.1f | %.2f | %s |\n", o.seed + static_cast<int>(i), o.start_s + i * o.start_spread_s, f.median_px, f.p95_px,
                  f.nees_in_band >= 0 ? (std::to_string(static_cast<int>(std::lround(100 * f.nees_in_band))) + " %").c_str() : "-", f.nees_mean,
                  f.ms_per_frame, lock);
      if (f.lock_s >= 0) ++locked, lock_times.push_back(f.lock_s);
      medians.push_back(f.median_px), p95s.push_back(f.p95_px), ms.push_back(f.ms_per_frame);
      held += f.median_px <= 1.0;
      if (f.nees_in_band >= 0) in_band_frames += f.nees_in_band * f.nees_frames, frames += f.nees_frames, below += f.nees_below, above += f.nees_above;
      for (size_t fi = f.lock_s >= 0 ? static_cast<size_t>(std::lround(f.lock_s * 30)) : f.nees_at_frame.size(); fi < f.nees_at_frame.size(); ++fi) {
        if (!std::isfinite(f.nees_at_frame[fi])) continue;
        locked_frames += 1, locked_in_band += f.nees_at_frame[fi] >= kNeesLow && f.nees_at_frame[fi] <= kNeesHigh;
      }
    }
    if (medians.empty()) continue;
    const Spread m = SpreadOf(medians), p = SpreadOf(p95s), t = SpreadOf(ms);
    const double pooled = frames > 0 ? in_band_frames / frames : -1;
    const MonteCarloNees mc = MonteCarloNeesOf(runs, key);
    std::printf("over the draws: median misregistration <= 1 px in %d of %zu; median px: median %.2f, worst %.2f; p95 px: median %.2f;"
                " NEES in band, all frames pooled: %.1f %% (below %.1f %%, above %.1f %%); ms/frame: median %.2f; locked in %d of %zu"
                " (median %.1f s after the start)\n",
                held, medians.size(), m.median, m.max, p.median, 100 * pooled, frames > 0 ? 100 * below / frames : 0.0,
                frames > 0 ? 100 * above / frames : 0.0, t.median, locked, medians.size(), lock_times.empty() ? -1.0 : SpreadOf(lock_times).median);
    PrintMonteCarloNees(mc);
    const double locked_pooled = locked_frames > 0 ? locked_in_band / locked_frames : -1;
    if (locked_frames > 0) std::printf("NEES in band from each draw's lock on, pooled: %.1f %% of %.0f frames\n", 100 * locked_pooled, locked_frames);
    const SceneryShare scenery = SceneryShareOf(runs, key);
    if (scenery.points > 0)
      std::printf("Known points' persisting match errors (%d points with a mean on 2+ draws): RMS %.2f / %.2f px (u / v), of which the draws share"
                  " %.0f %% / %.0f %% of the variance (the scenery's; the rest is each draw's noise)\n",
                  scenery.points, scenery.rms_px.x(), scenery.rms_px.y(), 100 * scenery.share.x(), 100 * scenery.share.y());
    char buf[1000];
    std::snprintf(buf, sizeof(buf), ",\"%s\":{\"draws\":%zu,\"held_1px\":%d,\"median_px_median\":%.3f,\"median_px_worst\":%.3f,\"p95_px_median\":%.3f,"
                  "\"nees_in_band_pooled\":%.3f,\"nees_below_pooled\":%.3f,\"nees_above_pooled\":%.3f,\"anees_in_band\":%.3f,\"anees_below\":%.3f,"
                  "\"anees_above\":%.3f,\"nees_in_band_scaled_per_second\":%.3f,\"nees_in_band_scaled_per_run\":%.3f,\"ms_per_frame_median\":%.3f,"
                  "\"locked\":%d,\"nees_in_band_locked_pooled\":%.3f,\"scenery_share_u\":%.3f,\"scenery_share_v\":%.3f}",
                  key.c_str(), medians.size(), held, m.median, m.max, p.median, pooled, frames > 0 ? below / frames : 0.0,
                  frames > 0 ? above / frames : 0.0, mc.Share(mc.in_band), mc.Share(mc.below), mc.Share(mc.above), mc.scaled_per_second_in_band,
                  mc.scaled_per_run_in_band, t.median, locked, locked_pooled, scenery.share.x(), scenery.share.y());
    json << buf;
  }
  json << "}";
  std::cout << json.str() << std::endl;
  return 0;
}

}  // namespace

Runner AddPoseBench(CLI::App& sub) {
  auto o = std::make_shared<PoseBenchOptions>();
  sub.add_option("--scenario", o->scenario, "bundled scenario name or .yaml path")->capture_default_str();
  sub.add_option("--camera", o->camera, "a moving camera of the scenario")->capture_default_str();
  sub.add_option("--seconds", o->seconds, "scene time simulated")->capture_default_str()->check(ave::cli::Range(0.5, 600.0));
  sub.add_option("--features", o->features, "vision features per frame to sweep (0 = GPS+inertial only)")->delimiter(',');
  sub.add_option("--lines", o->lines, "use known 3D line features")->capture_default_str();
  sub.add_option("--new-points", o->new_points, "add the rows where unknown point features are tracked, triangulated and correct the pose (joint and issue-5 modes)")
      ->capture_default_str();
  sub.add_option("--acquiring-sigma", o->acquiring_sigma_px, "extra pixel noise of full matchings until the lock holds (issue 19)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--gyro-sigma", o->gyro_sigma_rad_s, "gyro rate sigma, rad/s (PoseFilterOptions::gyro_sigma_rad_s)")
      ->capture_default_str()
      ->check(ave::cli::Range(1e-6, 10.0));
  sub.add_option("--gyro-bias", o->gyro_bias, "estimate the gyro bias in the filter state (issue 19; on since the fifteenth session, docs/POSE.md)")->capture_default_str();
  sub.add_option("--point-bias-gain", o->point_bias_gain, "learn each known point's persisting misfit from its keyframe residuals at this gain (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1.0));
  sub.add_option("--point-bias-weight", o->point_bias_weight_px, "weigh a point down by its learned misfit: variance x (1 + (misfit / this)^2), px (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--accel-noise", o->accel_noise_m_s2, "white acceleration noise, m/s2/sqrt(Hz) (PoseFilterOptions::accel_noise_m_s2)")
      ->capture_default_str()
      ->check(ave::cli::Range(1e-3, 100.0));
  sub.add_option("--angular-accel-noise", o->angular_accel_noise_rad_s2, "white angular acceleration noise, rad/s2/sqrt(Hz)")
      ->capture_default_str()
      ->check(ave::cli::Range(1e-3, 100.0));
  sub.add_option("--gyro-bias-sigma", o->gyro_bias_sigma_rad_s, "initial sigma of the gyro bias state, rad/s")
      ->capture_default_str()
      ->check(ave::cli::Range(1e-6, 1.0));
  sub.add_option("--acquisition-sigma-m", o->acquisition_sigma_m, "position sigma added before the first vision frame (issue 19; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--feature-bias-px", o->feature_bias_px,
                 "persisting detection bias the known features share, px: the orientation term of the reported covariance (issue 19; 0: off)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10.0));
  sub.add_option("--feature-point-bias-near-px", o->feature_point_bias_near_px,
                 "... its sigma for points within 60 m, rising to --feature-point-bias-px at 120 m (equal: one sigma at every depth)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--feature-point-bias-px", o->feature_point_bias_px,
                 "persisting detection bias of each known point, px, its effect on the pose followed exactly (issue 19, pose19e; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--segments", o->segments, "keyframe line segment detector: lsd (OpenCV's LSD) or fld (ximgproc's Fast Line Detector)")
      ->capture_default_str()
      ->check(CLI::IsMember({"lsd", "fld"}));
  sub.add_option("--rows", o->rows, "run only the rows with these JSON keys (e.g. gps_imu_vision_50,gps_imu_vision_joint_50; default: all)")
      ->delimiter(',');
  sub.add_option("--landmark-bias-px", o->landmark_bias_px, "persisting error of each landmark's sightings (joint mode), px, a consider bias (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--landmark-sigma-px", o->landmark_sigma_px, "extra noise of each landmark's sighting (joint mode), px")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--max-state-points", o->max_state_points, "unknown features in the filter's state at a time (joint mode)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 200));
  sub.add_option("--join-depth-sigma-scale", o->join_depth_sigma_scale, "a joining feature's depth sigma times this (joint mode)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.1, 10.0));
  sub.add_option("--nis-short-gain", o->nis_short_gain,
                 "running-mean gain of the frames' NIS whose ratio to the long mean scales the reported covariance (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1.0));
  sub.add_option("--acquisition-association-px", o->acquisition_association_px,
                 "sigma of each point's persisting association error until the lock holds, px (issue 19, pose19e; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--robust-residual-px", o->robust_residual_px,
                 "keyframes: a known point's match the fitted pose misses by r beyond this has its variance scaled by (r / this)^2 (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--feature-class-bias-px", o->feature_class_bias_px,
                 "sigma of a detection bias shared per class of known point (above / below the camera), px (issue 19, ninth session; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--local-fit-px", o->local_fit_px,
                 "on a keyframe that fits nowhere as a whole, features whose own outline lies within this mean edge distance are still matched (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 8.0));
  sub.add_option("--corners-on-edges", o->corners_on_edges,
                 "known corners measured where their model edges meet (issue 19, thirteenth session): 0 as detected, 1 moved where found, 2 also refused where not")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 2));
  sub.add_option("--corner-window", o->corner_window_px, "half size of cv::cornerSubPix's window for every corner, px (issue 19, fourteenth session)")
      ->capture_default_str()
      ->check(ave::cli::Range(1, 8));
  sub.add_option("--corner-bias", o->corner_bias_px, "move each known corner's measurement this far back out of its wedge, px (issue 19, fourteenth session; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 3.0));
  sub.add_option("--foot-variance-scale", o->foot_variance_scale,
                 "a wall foot's match (known point below the camera) gets this many times a wall top's pixel variance (issue 19, tenth session; 1: same)")
      ->capture_default_str()
      ->check(ave::cli::Range(1.0, 100.0));
  sub.add_option("--feature-shared-bias-px", o->feature_shared_bias_px,
                 "sigma of a detection bias every known point shares, px (issue 19, pose19e; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--acquisition-sigma-deg", o->acquisition_sigma_deg, "orientation sigma added before the first vision frame (issue 19; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 90.0));
  sub.add_option("--ahrs-heading-sigma", o->ahrs_heading_sigma_deg, "AHRS heading sigma about the vertical, deg (PoseFilterOptions::heading_sigma_deg; 0: --ahrs-sigma)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 180.0));
  sub.add_option("--gravity-window", o->gravity_window_s, "level the filter on the accelerometer's mean over windows this long, s (PoseFilterOptions::gravity_window_s; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 10.0));
  sub.add_option("--ahrs-sigma", o->ahrs_sigma_deg, "AHRS orientation sigma, deg (PoseFilterOptions::orientation_sigma_deg)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.01, 90.0));
  sub.add_option("--gyro-correlation", o->gyro_correlation_s, "seconds over which gyro errors (bias) are correlated (0: white, before issue 19's NEES fix)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 1e6));
  sub.add_option("--gps-correlation", o->gps_correlation_s, "seconds over which GPS errors (multipath) are correlated (0: white)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 1e6));
  sub.add_option("--seed", o->seed, "added to the scenario's seed: another draw of the GPS, inertial and camera noise (0: the scenario's own)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 1000000));
  sub.add_option("--start", o->start_s, "scene time of the first frame, s (the filter runs on GPS and inertial from 0 until then)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 3600.0));
  sub.add_option("--start-spread", o->start_spread_s,
                 "with --seeds: draw i starts --start + i x this seconds later, at another place of the path (the scenery's errors drawn too)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 600.0));
  sub.add_option("--seeds", o->seeds, "Monte Carlo: run the rows (default gps_imu_vision_50) on this many draws of the noise from --seed on, and summarise")
      ->capture_default_str()
      ->check(ave::cli::Range(1, 1000));
  sub.add_option("--roll-search-deg", o->roll_search_deg, "the acquisition's chamfer search turns the image up to +-this (VisionOptions::acquisition_roll_search_deg; 0: shift only)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 30.0));
  sub.add_option("--lock-alignment-px", o->lock_alignment_px, "a full matching counts towards the lock only when its coarse alignment moved the image by at most this, px (0: not checked)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--heading-search", o->heading_search_deg, "acquisition: search the heading up to +-this many degrees (VisionOptions::acquisition_heading_search_deg; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 180.0));
  sub.add_option("--relocalize-sigmas", o->relocalize_extent_sigmas,
                 "relocalisation: widen the grid to this many of the prior's horizontal sigmas (VisionOptions::relocalize_extent_sigmas; 0: fixed grid)");
  sub.add_option("--relocalize-max-m", o->relocalize_max_extent_m, "relocalisation: the widened grid's largest half-extent, m (VisionOptions::relocalize_max_extent_m)");
  sub.add_option("--relocalize-m", o->relocalize_extent_m, "relocalisation: horizontal grid half-extent around the filter's position, m (VisionOptions::relocalize_extent_m; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 20.0));
  sub.add_option("--relocalize-step-m", o->relocalize_step_m, "relocalisation: the grid's first step, then halved to 0.5 m around the best (VisionOptions::relocalize_step_m)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.05, 20.0));
  sub.add_option("--max-alignment-score-px", o->max_alignment_score_px, "a keyframe whose chamfer alignment scores worse than this applies nothing (VisionOptions::max_alignment_score_px; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--acquisition-passes", o->acquisition_passes, "coarse passes while acquiring (VisionOptions::acquisition_coarse_passes)")
      ->capture_default_str()
      ->check(ave::cli::Range(1, 10));
  sub.add_option("--relocalize-distinct", o->relocalize_distinct_px,
                 "relocalisation moves only when its best fit beats every fit farther than 1.5 steps by this, px (0: off)")
      ->capture_default_str();
  sub.add_option("--relocalize-max-score", o->relocalize_max_score_px,
                 "relocalisation is believed only where the best chamfer score is at most this, px; else nothing is applied and it searches again next frame (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--relocalize-retry-frames", o->relocalize_retry_frames, "while a relocalisation waits for a fit, it searches again every this many frames")
      ->capture_default_str()
      ->check(ave::cli::Range(1, 1000));
  sub.add_option("--carrier-height", o->carrier_height_m,
                 "the carried camera's height above the ground in m, applied every frame (VisionOptions::carrier_height_m; -1: the camera path's, 0: off)")
      ->capture_default_str();
  sub.add_option("--carrier-height-sigma", o->carrier_height_sigma_m, "its sigma in m (VisionOptions::carrier_height_sigma_m)")->capture_default_str();
  sub.add_option("--carrier-height-correlation", o->carrier_height_correlation_s, "seconds over which its error is correlated")->capture_default_str();
  sub.add_option("--gps-reanchor", o->gps_reanchor_s,
                 "seconds of GPS fixes all outside the gate after which a fix becomes the position (PoseFilterOptions::gps_reanchor_s; 0: off)");
  sub.add_option("--gps-reanchor-sigma", o->gps_reanchor_sigma_m, "the re-anchored position's sigma at least, m (PoseFilterOptions::gps_reanchor_sigma_m)");
  sub.add_option("--gps-reanchor-min", o->gps_reanchor_min_m, "... counting only fixes this far from the filter, m (PoseFilterOptions::gps_reanchor_min_m)");
  sub.add_option("--gps-reanchor-rot", o->gps_reanchor_orientation_sigma_deg,
                 "... adding this orientation sigma, deg (PoseFilterOptions::gps_reanchor_orientation_sigma_deg)");
  sub.add_option("--gps-bias-sigma", o->gps_bias_sigma_m, "GPS multipath as a persisting bias of every fix, sigma per axis in m, a consider term (0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--gate-chi2", o->gate_chi2_2dof, "vision gate per feature, chi-square with 2 dof (PoseFilterOptions::gate_chi2_2dof)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.1, 1e6));
  sub.add_option("--pixel-sigma", o->pixel_sigma_px, "vision point / line sigma, px (PoseFilterOptions::pixel_sigma_px)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.01, 100.0));
  sub.add_option("--tracked-sigma", o->tracked_sigma_px, "extra noise of a tracked (not re-detected) feature, px (VisionOptions::tracked_sigma_px)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--tracked-max-innovation", o->tracked_max_innovation_px,
                 "a tracked known feature this far (px) from the prediction is not applied and its track ends (VisionOptions::tracked_max_innovation_px; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--locked-search-sigmas", o->locked_search_sigmas,
                 "once locked, the coarse alignment searches this many projected pose sigmas plus 8 px (VisionOptions::locked_search_sigmas; 0: the full radius)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 100.0));
  sub.add_option("--line-ambiguity-ratio", o->line_ambiguity_ratio,
                 "a segment two model lines reach goes to the nearer only when at most this times the other's distance (VisionOptions::line_ambiguity_ratio; 0: to neither, 1: always the nearer)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1.0));
  sub.add_option("--min-view-points", o->min_view_points,
                 "a keyframe predicting fewer known points in view neither relocalises nor counts towards the loss (VisionOptions::min_view_points; 0: off)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 1000));
  sub.add_option("--relocalize-min-outline", o->relocalize_min_outline_share,
                 "a relocalisation candidate must show this share of the model outline the filter's position shows (VisionOptions::relocalize_min_outline_share; 0: any)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1.0));
  sub.add_option("--line-max-overhang", o->line_max_overhang_px,
                 "a segment reaching beyond a model line's image by more than this plus 20 % of its length is not that line (VisionOptions::line_max_overhang_px; 0: not checked)")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1000.0));
  sub.add_option("--gps-min-sigma", o->gps_min_sigma_m, "floor of the GPS fixes' sigma, m (PoseFilterOptions::gps_min_sigma_m)")
      ->capture_default_str()
      ->check(ave::cli::Range(1e-3, 100.0));
  sub.add_option("--ahrs-correlation", o->ahrs_correlation_s, "seconds over which AHRS errors are correlated (0: white, the issue-5 filter)")
      ->capture_default_str()
      ->check(ave::cli::Range(0, 1e6));
  sub.add_option("--consistency-knobs", o->consistency_knobs, "rows for the filter's noise model (pixel sigma, process noise) against NEES")->capture_default_str();
  sub.add_option("--knobs", o->knobs, "rows for the video-rate front end's knobs (keyframe interval, visibility cache, detection level)")
      ->capture_default_str();
  sub.add_option("--variants", o->variants, "rows for the bus and 5-degree-bump scenario variants (need --seconds >= 7.2)")->capture_default_str();
  sub.add_option("--nees-csv", o->nees_csv, "write per-frame NEES diagnostics of every row (axes, sigmas) to this CSV")
      ->check(ave::cli::WritableFile());
  sub.add_option("--footage-jpeg-quality", o->footage_jpeg_quality,
                 "JPEG-encode and decode every frame at this quality first, as ave-sim footage delivers them (0: off)")
      ->capture_default_str()->check(ave::cli::Range(0, 100));
  sub.add_option("--pixel-area", o->pixel_area,
                 "render each pixel as the mean of this many samples per axis (the pixel_area effect; 1: one sample at its centre; 0: as the scenario names it)")
      ->capture_default_str()->check(ave::cli::Range(0, sim::kMaxPixelAreaSamples));
  sub.add_option("--match-csv", o->match_csv, "write every known-point match of every row and frame with its true projection to this CSV")
      ->check(ave::cli::WritableFile());
  sub.add_option("--landmark-csv", o->landmark_csv, "write every unknown feature that joins the state (joint rows), with what it sits on, to this CSV")
      ->check(ave::cli::WritableFile());
  sub.add_option("--png", o->png, "plot to write (empty: none)")->capture_default_str()->check(ave::cli::WritableFile());
  return [o] { return o->seeds > 1 ? RunPoseSeeds(*o) : RunPose(*o); };
}

}  // namespace ave::bench
