// Keyframes of the vision front end (VisionTracker::Update, step 3b): full matching of the static
// model's known points and lines, coarse to fine, with the acquisition (relocalisation, the
// chamfer alignment of the model's edges) and the lock's bookkeeping. Split from vision.cc.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/fast_line_detector.hpp>

#include "sensor_agent/pose/vision_impl.h"

namespace ave::pose {
namespace {

using namespace internal;  // NOLINT: the front end's own helpers
constexpr double kDegToRad = 3.14159265358979323846 / 180;

}  // namespace

// Relocalisation (VisionOptions::relocalize_extent_m): the chamfer alignment (shift and turn) of
// the model's edges from positions on a horizontal grid around the filter's; the filter moves to
// the best one when it fits clearly better than where it is. kWaiting (nothing moved) when even the
// best fit is poor: a wrong position can then score best by chance (a tree over the façades' tops).
VisionTracker::Impl::Relocation VisionTracker::Impl::Relocalize(PoseEkf& ekf, const cv::Mat& edge_distance, const cv::Mat& skyline_distance,
                                                                double roll_search, double roll_step, double* best_score) {
  const Eigen::Vector2d centre(k.cx, k.cy);
  const Eigen::Vector3d here = ekf.world_from_camera().translation;
  // A position from which the model shows less than relocalize_min_outline_share of the outline it
  // shows from the filter's is not a candidate: the mean chamfer distance of a thin outline is low by
  // chance.
  size_t outline_here = 0;
  auto fit = [&](const Eigen::Vector3d& position) {
    PoseEkf moved = ekf;
    moved.MovePosition(position, options.relocalize_step_m);
    std::vector<Eigen::Vector2d> samples, sky_samples;
    EdgeSamples(moved, samples, sky_samples);
    if (position == here) outline_here = samples.size();
    if (static_cast<double>(samples.size()) < options.relocalize_min_outline_share * static_cast<double>(outline_here)) {
      ++relocalize_thin_outlines;
      return std::numeric_limits<double>::infinity();
    }
    // (A 4 px first grid: the distance transform is smooth, truncated at 8 px.)
    return ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, options.search_radius_px, centre, roll_search, roll_step, 4).score_px;
  };
  const double at_here = fit(here);
  double best = at_here;
  Eigen::Vector3d best_position = here;
  std::vector<std::pair<Eigen::Vector3d, double>> grid = {{here, at_here}};
  // The grid: +-relocalize_extent_m, wider where the prior's horizontal sigma says the position
  // may lie farther (relocalize_extent_sigmas), with no more than 13 x 13 positions.
  double extent = options.relocalize_extent_m, grid_step = options.relocalize_step_m;
  if (options.relocalize_extent_sigmas > 0) {
    const Eigen::Matrix3d p = ekf.covariance().block<3, 3>(kPos, kPos);
    // A NaN variance (a broken filter) keeps the fixed grid: `var > 0` is false for it, where
    // std::min(max, NaN) would have returned the widest grid.
    const double var = 0.5 * (p(0, 0) + p(1, 1));
    const double wanted = var > 0 ? std::min(options.relocalize_max_extent_m, options.relocalize_extent_sigmas * std::sqrt(var)) : 0.0;
    if (wanted > extent) extent = wanted, grid_step = std::max(grid_step, extent / 6);
  }
  const int n = static_cast<int>(std::floor(extent / grid_step + 1e-9));
  for (int i = -n; i <= n; ++i) {
    for (int j = -n; j <= n; ++j) {
      if (i == 0 && j == 0) continue;
      const Eigen::Vector3d position = here + grid_step * Eigen::Vector3d(i, j, 0);
      const double score = fit(position);
      grid.emplace_back(position, score);
      if (score < best) best = score, best_position = position;
    }
  }
  // Then halved steps around the best, down to kFinest_m. (Heights were tried too, 0.5 m steps
  // within +-1.5 m: 8 of 13 draws held instead of 12; on far façades a pitch mimics a height,
  // and the chamfer score cannot tell them apart.)
  constexpr double kFinest_m = 0.5;
  double step = grid_step;
  while (step > kFinest_m + 1e-9) {
    step = std::max(kFinest_m, 0.5 * step);
    const Eigen::Vector3d around = best_position;
    for (int i = -1; i <= 1; ++i) {
      for (int j = -1; j <= 1; ++j) {
        if (i == 0 && j == 0) continue;
        const Eigen::Vector3d position = around + step * Eigen::Vector3d(i, j, 0);
        const double score = fit(position);
        if (score < best) best = score, best_position = position;
      }
    }
  }
  if (best_score) *best_score = best;
  if (options.relocalize_max_score_px > 0 && !(best <= options.relocalize_max_score_px)) return Relocation::kWaiting;
  if (!(best < at_here - options.relocalize_margin_px) || (options.max_alignment_score_px > 0 && best > options.max_alignment_score_px))
    return Relocation::kStayed;
  if (options.relocalize_distinct_px > 0) {
    double elsewhere = std::numeric_limits<double>::infinity();
    for (const auto& [position, score] : grid)
      if ((position - best_position).norm() > 1.5 * grid_step) elsewhere = std::min(elsewhere, score);
    if (!(best < elsewhere - options.relocalize_distinct_px)) return Relocation::kStayed;
  }
  ekf.MovePosition(best_position, step);
  // The move forgot what the filter knew of its position, the carried camera's height included
  // (draw 5 of 13: 1.2 m low again, taken as a 1 deg pitch): that measurement again, at full weight.
  last_height_ns = INT64_MIN;
  (void)ApplyCarrierHeight(ekf);
  return Relocation::kMoved;
}

// The heading search (issue 19, eighteenth session; VisionOptions::acquisition_heading_search_deg):
// the filter's pose turned about the world's vertical through the camera in steps of
// acquisition_heading_step_deg, each scored by the chamfer alignment as relocalisation scores
// positions. The best turn (degrees) when it fits well (relocalize_max_score_px), beats the
// filter's own heading by relocalize_margin_px and every heading more than a step and a half from
// it by relocalize_distinct_px; nullopt otherwise.
std::optional<double> VisionTracker::Impl::HeadingCandidate(const PoseEkf& ekf, const cv::Mat& edge_distance, const cv::Mat& skyline_distance,
                                                            double roll_search, double roll_step) {
  if (!(options.acquisition_heading_search_deg > 0)) return std::nullopt;
  const Eigen::Vector2d centre(k.cx, k.cy);
  const int n = static_cast<int>(std::floor(options.acquisition_heading_search_deg / options.acquisition_heading_step_deg + 1e-9));
  std::vector<double> scores(2 * n + 1);
  for (int i = -n; i <= n; ++i) {
    const PoseEkf moved = Turned(ekf, i * options.acquisition_heading_step_deg);
    std::vector<Eigen::Vector2d> samples, sky_samples;
    EdgeSamples(moved, samples, sky_samples);
    scores[i + n] = ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, options.search_radius_px, centre, roll_search, roll_step, 4).score_px;
  }
  const int best = static_cast<int>(std::min_element(scores.begin(), scores.end()) - scores.begin()) - n;
  double elsewhere = std::numeric_limits<double>::infinity();
  for (int i = -n; i <= n; ++i)
    if (std::abs(i - best) >= 2) elsewhere = std::min(elsewhere, scores[i + n]);
  const double at_best = scores[best + n];
  if (best == 0 || !(at_best < scores[n] - options.relocalize_margin_px) || !(at_best < elsewhere - options.relocalize_distinct_px) ||
      (options.relocalize_max_score_px > 0 && !(at_best <= options.relocalize_max_score_px))) {
    return std::nullopt;
  }
  // Then halved steps around the best, each scored with the image shift limited to what the step
  // leaves (twice its image motion at the principal point): with the full 60 px shift, headings
  // 6 deg apart score alike (the walk at 65.7 s: -12 deg scored 1.96 px, the right -18 to -21 deg
  // 2.61), and the pose locked 8 deg off.
  double heading = best * options.acquisition_heading_step_deg;
  for (double step = 0.5 * options.acquisition_heading_step_deg; step >= 1.0 - 1e-9; step *= 0.5) {
    const double radius = std::max(4.0, 2 * k.fx * std::tan(step * kDegToRad));
    double best_score = std::numeric_limits<double>::infinity(), best_heading = heading;
    for (int i = -1; i <= 1; ++i) {
      const PoseEkf moved = Turned(ekf, heading + i * step);
      std::vector<Eigen::Vector2d> samples, sky_samples;
      EdgeSamples(moved, samples, sky_samples);
      const double score = ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, radius, centre, roll_search, roll_step, 2).score_px;
      if (score < best_score) best_score = score, best_heading = heading + i * step;
    }
    heading = best_heading;
  }
  return heading;
}

// A copy of the filter turned by `degrees` about the world's vertical through the camera, its
// orientation sigma reorient_sigma_deg and uncorrelated (PoseEkf::MoveOrientation).
PoseEkf VisionTracker::Impl::Turned(const PoseEkf& ekf, double degrees) const {
  PoseEkf turned = ekf;
  if (degrees == 0) return turned;
  const Eigen::Quaterniond q = ekf.world_from_camera().rotation;
  turned.MoveOrientation((Eigen::Quaterniond(Eigen::AngleAxisd(degrees * kDegToRad, Eigen::Vector3d::UnitZ())) * q).normalized(),
                         options.reorient_sigma_deg * kDegToRad);
  return turned;
}

// Known points the filter's pose predicts visible: (map index, predicted pixel).
// Corners against the sky come first: nothing else nearby looks like them, while wall feet sit
// among objects, people and ground texture.
std::vector<std::pair<int, Eigen::Vector2d>> VisionTracker::Impl::PredictPoints(const PoseEkf& ekf) {
  std::vector<std::pair<int, Eigen::Vector2d>> skyline, other;
  const Eigen::Vector3d centre = ekf.world_from_camera().translation;
  RefreshCache(centre);
  for (size_t i = 0; i < map.points.size(); ++i) {
    const std::optional<Eigen::Vector2d> uv = ekf.ProjectPoint(k, map.points[i]);
    if (!uv || !InImage(k, *uv, kBorder_px) || !PointSeen(static_cast<int>(i), centre)) continue;
    (PointSky(static_cast<int>(i), centre) ? skyline : other).emplace_back(static_cast<int>(i), *uv);
  }
  skyline.insert(skyline.end(), other.begin(), other.end());
  return skyline;
}

// Sampled frame pixels of the predicted model edges, and those on the skyline (the model point
// itself is seen and nothing is seen just above it), for the chamfer search.
void VisionTracker::Impl::EdgeSamples(const PoseEkf& ekf, std::vector<Eigen::Vector2d>& samples, std::vector<Eigen::Vector2d>& sky_samples,
                                      std::vector<int>* sample_lines, std::vector<int>* sky_lines) {
  const Eigen::Vector3d centre = ekf.world_from_camera().translation;
  RefreshCache(centre);
  for (size_t li = 0; li < map.lines.size(); ++li) {
    const LineFeature& f = map.lines[li];
    const auto a = ekf.ProjectPoint(k, f.a), b = ekf.ProjectPoint(k, f.b);
    if (!a || !b || f.roof || !LineMidSeen(static_cast<int>(li), centre)) continue;
    const int steps = static_cast<int>(std::min(2000.0, (*b - *a).norm() / kEdgeSample_px));
    const bool horizontal = std::abs(f.line.direction.z()) < 0.5;
    std::vector<uint8_t>& sky = line_sky_samples[li];
    if (horizontal && static_cast<int>(sky.size()) != steps + 1) sky.assign(steps + 1, 2);  // 2: not cast yet
    for (int i = 0; i <= steps; ++i) {
      const double s = steps == 0 ? 0.0 : static_cast<double>(i) / steps;
      const Eigen::Vector2d p = ToFrame(*a + (*b - *a) * s);
      if (!InImage(k, p, 1)) continue;
      samples.push_back(p);
      if (sample_lines) sample_lines->push_back(static_cast<int>(li));
      if (!horizontal) continue;
      if (sky[i] == 2) {
        const Eigen::Vector3d x = f.a + (f.b - f.a) * s;
        sky[i] = Visible(centre, x) && SkyAbove(centre, x);
      }
      if (sky[i]) {
        sky_samples.push_back(p);
        if (sky_lines) sky_lines->push_back(static_cast<int>(li));
      }
    }
  }
}

// The longest detected segment along the predicted image of line feature `f` (its index and the
// mean distance of its ends from the predicted line) that does not reach beyond that image by more
// than line_max_overhang_px + line_max_overhang_share x its length; nullopt if none. *overhang is
// set when a longer segment was refused for reaching beyond.
std::optional<VisionTracker::Impl::LineCandidate> VisionTracker::Impl::MatchLine(const PoseEkf& ekf, const LineFeature& f,
                                                                                 const std::vector<Segment>& segments, bool* overhang) const {
  const std::optional<Eigen::Vector2d> pa = ekf.ProjectPoint(k, f.a), pb = ekf.ProjectPoint(k, f.b);
  if (!pa || !pb || (*pb - *pa).norm() < kMinSegment_px) return std::nullopt;
  const Eigen::Vector2d dir = (*pb - *pa).normalized();
  const double length = (*pb - *pa).norm();
  const Eigen::Vector2d normal(-dir.y(), dir.x());
  std::optional<LineCandidate> best;
  double best_length = 0;
  for (size_t i = 0; i < segments.size(); ++i) {
    const Segment& s = segments[i];
    const Eigen::Vector2d sd = s.b - s.a;
    const double sl = sd.norm();
    if (sl < kMinSegment_px || sl <= best_length) continue;
    if (std::abs(normal.dot(sd)) / sl > std::sin(kMaxAngle_rad)) continue;
    const double da = std::abs(normal.dot(s.a - *pa)), db = std::abs(normal.dot(s.b - *pa));
    if (da > options.match_radius_px || db > options.match_radius_px) continue;
    const double ta = dir.dot(s.a - *pa), tb = dir.dot(s.b - *pa);
    if (std::max(ta, tb) < 0 || std::min(ta, tb) > length) continue;  // beside the model segment
    const double beyond = std::max(0.0, -std::min(ta, tb)) + std::max(0.0, std::max(ta, tb) - length);
    if (options.line_max_overhang_px > 0 && beyond > options.line_max_overhang_px + options.line_max_overhang_share * length) {
      if (overhang) *overhang = true;
      continue;
    }
    best = LineCandidate{static_cast<int>(i), 0.5 * (da + db)};
    best_length = sl;
  }
  return best;
}

// Two model lines whose images lie a few pixels apart and parallel (a near roof edge in front of a
// far one) can both take the one segment detected there: one of them then measures the other's
// edge, a persisting error of the gap (the walk at 82.5 s: a line 38 m away matched 4 px off, on
// every keyframe for a second, pulled the pose 0.4 m and 0.3 deg, and the slide that followed ended
// 10 m off). A shared segment goes to the line it lies nearest only when that one is clearly
// nearer (distance at most line_ambiguity_ratio times the next's); otherwise to none. Counted per
// line left without it (VisionFrameStats::rejected_ambiguous).
void VisionTracker::Impl::ResolveSharedSegments(std::vector<std::optional<LineCandidate>>& candidates, Frame& f) const {
  std::unordered_map<int, std::vector<size_t>> claims;
  for (size_t i = 0; i < candidates.size(); ++i)
    if (candidates[i]) claims[candidates[i]->segment].push_back(i);
  for (auto& [segment, lines] : claims) {
    if (lines.size() < 2) continue;
    std::sort(lines.begin(), lines.end(), [&](size_t a, size_t b) { return candidates[a]->distance_px < candidates[b]->distance_px; });
    // Strictly nearer: two lines whose images coincide (both at distance 0) are a tie, not a choice.
    const bool clear = candidates[lines[0]]->distance_px < options.line_ambiguity_ratio * candidates[lines[1]]->distance_px;
    for (size_t j = clear ? 1 : 0; j < lines.size(); ++j) {
      candidates[lines[j]].reset();
      ++f.stats.rejected_ambiguous;
    }
  }
}

// The Fast Line Detector fits its segments to Canny's whole-pixel edges; a matched one is moved
// onto the sub-pixel intensity step along it (SearchEdge at 16 places, a Huber line fit), as LSD's
// refinement does for its own. Unchanged when too little of it is found.
Segment VisionTracker::Impl::RefineSegment(const cv::Mat& gray, const Segment& s) const {
  constexpr int kSamples = 16;
  const Eigen::Vector2d dir = (s.b - s.a).normalized(), normal(-dir.y(), dir.x());
  std::vector<Eigen::Vector2d> samples;
  for (int i = 0; i < kSamples; ++i) samples.push_back(ToFrame(s.a + (s.b - s.a) * ((i + 0.5) / kSamples)));
  const std::vector<cv::Point2f> found = ToIdeal(SearchEdge(gray, samples, normal, 1.5, 12.0));
  if (found.size() < kSamples / 2) return s;
  cv::Vec4f fit;
  cv::fitLine(found, fit, cv::DIST_HUBER, 0, 0.01, 0.01);
  const Eigen::Vector2d d(fit[0], fit[1]), o(fit[2], fit[3]);
  if (std::abs(d.dot(dir)) < std::cos(kMaxAngle_rad)) return s;
  return {o + d * d.dot(s.a - o), o + d * d.dot(s.b - o)};
}

// 3b. Keyframe: full model matching, coarse to fine. The corners and segments detected here are
// matched to the model's points and lines; the corners also seed new unknown tracks (step 4).
void VisionTracker::Impl::UpdateKeyframe(PoseEkf& ekf, Frame& f) {
  frames_since_keyframe = 0;
  // A relocalisation waiting for a frame the model fits well searches only every
  // relocalize_retry_frames: the frames between apply nothing (and skip the keyframe's detection).
  if (relocalize && relocalize_wait > 0) {
    --relocalize_wait;
    f.stats.relocalize_waiting = true;
    f.budget = 0;
    return;
  }
  DetectCorners(f);
  const std::vector<Segment> segments = DetectSegments(f);
  // While acquiring (before the first lock, and after the pose was declared lost) the search turns
  // the image too: the AHRS's roll error is not a shift. Once locked, a frame that disagrees (a bus
  // covering half of it) must not pull the pose, and a turn fitted to the bus's edges would.
  const bool acquiring = !locked_once;
  const bool turn = acquiring;
  // Coarse pass on a copy of the filter: the image offset that lays the predicted model edges on
  // the frame's edges (chamfer), then points matched within a few pixels of prediction + offset;
  // the copy's updated pose re-predicts everything for the fine pass.
  const ImageAlignment alignment = AlignModelEdges(ekf, f, turn);
  const PoseEkf coarse = CoarsePass(ekf, f, alignment, turn);
  FinePass(ekf, f, coarse, segments);
  UpdateLock(ekf, f, alignment, acquiring);
  LearnMisfits(ekf, f);
  f.timer.Lap(kStageEkf);
}

// Each applied keyframe match's residual against the updated pose, into its point's running mean,
// while the lock holds (VisionOptions::point_bias_gain). A pose declared lost forgets them all:
// residuals from a wrong lock say nothing of the points.
void VisionTracker::Impl::LearnMisfits(const PoseEkf& ekf, const Frame& f) {
  if (!(options.point_bias_gain > 0)) return;
  if (misfit_mean.size() != map.points.size()) misfit_mean.assign(map.points.size(), Eigen::Vector2d::Zero()), misfit_count.assign(map.points.size(), 0);
  if (f.stats.relocks > 0) {
    std::fill(misfit_mean.begin(), misfit_mean.end(), Eigen::Vector2d::Zero());
    std::fill(misfit_count.begin(), misfit_count.end(), 0);
    return;
  }
  if (!locked_once || good_full_matches < options.lock_frames) return;
  for (const auto& [index, uv] : f.applied_points) {
    const std::optional<Eigen::Vector2d> projected = ekf.ProjectPoint(k, map.points[index]);
    if (!projected) continue;
    const Eigen::Vector2d r = uv - *projected;
    misfit_mean[index] = misfit_count[index] == 0 ? r : Eigen::Vector2d(misfit_mean[index] + options.point_bias_gain * (r - misfit_mean[index]));
    ++misfit_count[index];
  }
}

// Keyframe corners: detected and refined to sub-pixel in the frame (KLT and new tracks start
// there), and their ideal pixels, where the filter measures.
void VisionTracker::Impl::DetectCorners(Frame& f) const {
  cv::goodFeaturesToTrack(f.gray, f.frame_corners, 1500, 0.005, 3);
  if (!f.frame_corners.empty()) {
    cv::cornerSubPix(f.gray, f.frame_corners, cv::Size(options.corner_window_px, options.corner_window_px), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 20, 0.03));
  }
  f.corners = ToIdeal(f.frame_corners);  // where the filter measures
  f.timer.Lap(kStageCorners);
}

// Keyframe line segments (VisionOptions::use_lines; SegmentDetector: the Fast Line Detector or
// LSD), their end points in ideal pixels; none when lines are off.
std::vector<Segment> VisionTracker::Impl::DetectSegments(Frame& f) {
  std::vector<Segment> segments;
  if (options.use_lines) {
    std::vector<cv::Vec4f> lines;
    if (options.segment_detector == SegmentDetector::kFastLine) {
      if (!fast_lines) fast_lines = cv::ximgproc::createFastLineDetector(static_cast<int>(kMinSegment_px));
      fast_lines->detect(f.gray, lines);
    } else {
      cv::createLineSegmentDetector(cv::LSD_REFINE_STD)->detect(f.gray, lines);
    }
    std::vector<cv::Point2f> ends;
    for (const cv::Vec4f& l : lines) ends.insert(ends.end(), {cv::Point2f(l[0], l[1]), cv::Point2f(l[2], l[3])});
    ends = ToIdeal(ends);
    for (size_t i = 0; i + 1 < ends.size(); i += 2) {
      segments.push_back({Eigen::Vector2d(ends[i].x, ends[i].y), Eigen::Vector2d(ends[i + 1].x, ends[i + 1].y)});
    }
  }
  f.timer.Lap(kStageSegments);
  return segments;
}

// The coarse alignment: the frame's edge distance transforms, the relocalisation search when one is
// due (first frame, lost), the known points predicted from the filter's pose (f.predicted), and the
// image motion (shift; and turn when `turn`) that best lays the predicted model edges on the
// frame's edges.
ImageAlignment VisionTracker::Impl::AlignModelEdges(PoseEkf& ekf, Frame& f, bool turn) {
  cv::Mat edge_distance, skyline_distance;
  EdgeDistances(f.gray, edge_distance, skyline_distance);
  f.timer.Lap(kStageEdges);
  const Eigen::Vector2d centre(k.cx, k.cy);
  const double roll_search = options.acquisition_roll_search_deg * kDegToRad, roll_step = options.acquisition_roll_step_deg * kDegToRad;
  const bool search = relocalize && options.relocalize_extent_m > 0;
  if (search && options.min_view_points > 0 && static_cast<int>(PredictPoints(ekf).size()) < options.min_view_points) {
    // Too few model features in view for the chamfer score to tell positions apart: wait.
    f.stats.relocalize_waiting = true;
    relocalize_wait = options.relocalize_retry_frames - 1;
  } else if (search) {
    relocalize_thin_outlines = 0;
    // Before the first lock the heading may be what is off (an AHRS beside a building): a heading
    // that fits at the filter's position is searched, and the positions around it too; it is taken
    // when its best position fits better than the best at the filter's heading (a wrong position
    // can make up for a wrong heading where few features are in view: the walk at 65 s moved
    // 11 m with the heading left 20 deg off). Once vision has held the orientation the gyro keeps
    // it within the coarse search's reach.
    const std::optional<double> turn = ever_locked ? std::nullopt : HeadingCandidate(ekf, edge_distance, skyline_distance, roll_search, roll_step);
    Relocation r;
    if (turn) {
      PoseEkf turned = Turned(ekf, *turn), stayed = ekf;
      double turned_score = 0, stayed_score = 0;
      const Relocation r_turned = Relocalize(turned, edge_distance, skyline_distance, roll_search, roll_step, &turned_score);
      const Relocation r_stayed = Relocalize(stayed, edge_distance, skyline_distance, roll_search, roll_step, &stayed_score);
      const bool take = turned_score < stayed_score - options.relocalize_margin_px;
      ekf = take ? turned : stayed;
      r = take ? r_turned : r_stayed;
      if (take) f.stats.reoriented_heading_deg = *turn;
    } else {
      r = Relocalize(ekf, edge_distance, skyline_distance, roll_search, roll_step);
    }
    f.stats.relocalized = r == Relocation::kMoved;
    f.stats.relocalize_thin_outlines = relocalize_thin_outlines;
    f.stats.relocalize_waiting = r == Relocation::kWaiting;
    relocalize = f.stats.relocalize_waiting;  // searched again relocalize_retry_frames later
    relocalize_wait = f.stats.relocalize_waiting ? options.relocalize_retry_frames - 1 : 0;
    f.timer.Lap(kStageChamfer);
  }
  f.predicted = PredictPoints(ekf);
  f.stats.points_predicted = static_cast<int>(f.predicted.size());
  f.stats.thin_view = options.min_view_points > 0 && f.stats.points_predicted < options.min_view_points;
  std::vector<Eigen::Vector2d> samples, sky_samples;
  std::vector<int> sample_lines, sky_lines;
  EdgeSamples(ekf, samples, sky_samples, &sample_lines, &sky_lines);
  f.timer.Lap(kStageVisibility);
  const double radius = AlignmentSearchRadius(ekf, f);
  ImageAlignment alignment = ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, radius, centre, turn ? roll_search : 0.0, roll_step);
  // Where the outline fits nowhere as a whole but does around some features (a bus across half of
  // the frame), only those are matched, and the alignment is searched again from their edges. Only
  // once the lock has held local_fit_after_lock_s: a lock formed 2 m off on the first frames fits
  // nowhere a second later, and must then be declared lost, not held by the features that still fit
  // by chance (13 draws: one ended 11 px off).
  const bool mature = locked_once && static_cast<double>(ekf.time_ns() - lock_since_ns) * 1e-9 >= options.local_fit_after_lock_s;
  if (mature && LocalFit(f, edge_distance, samples, sky_samples, sample_lines, sky_lines, alignment)) {
    alignment = ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, radius, centre, turn ? roll_search : 0.0, roll_step);
  }
  DropUnfit(f, f.predicted);
  // Nowhere does the model's outline lie on this frame's edges (a bus across half of it): the
  // frame's matches would be guesses, so none is applied, and the frame counts as a bad fit.
  // (A frame with too few model edges in view to score, +infinity, is not called unfit: its known
  // corners still go through the gate.)
  f.stats.unfit = options.max_alignment_score_px > 0 && std::isfinite(alignment.score_px) && alignment.score_px > options.max_alignment_score_px;
  if (f.stats.unfit || f.stats.relocalize_waiting) f.budget = 0;
  f.stats.coarse_offset_px = alignment.offset;
  f.stats.coarse_rotation_rad = alignment.rotation_rad;
  f.timer.Lap(kStageChamfer);
  return alignment;
}

// On a keyframe the model's outline fits nowhere as a whole (max_alignment_score_px): each known
// point and line judged by its own stretch of the outline placed by `alignment`, the mean truncated
// edge distance of a line's samples, and of the samples within kLocal_px of a point's prediction
// (local_fit_px). True when at least kMinFit of them fit: the others are left out of the frame's
// matching (Frame::point_unfit, line_unfit) and `samples` / `sky_samples` keep the fitting lines'.
bool VisionTracker::Impl::LocalFit(Frame& f, const cv::Mat& edge_distance, std::vector<Eigen::Vector2d>& samples,
                                   std::vector<Eigen::Vector2d>& sky_samples, const std::vector<int>& sample_lines,
                                   const std::vector<int>& sky_lines, const ImageAlignment& alignment) const {
  f.point_unfit.clear();
  f.line_unfit.clear();
  const double limit = options.local_fit_px;
  if (!(limit > 0) || !(options.max_alignment_score_px > 0) || !std::isfinite(alignment.score_px) ||
      !(alignment.score_px > options.max_alignment_score_px)) {
    return false;
  }
  constexpr double kLocal_px = 16;
  constexpr int kMinSamples = 5, kMinFit = 4;
  const Eigen::Vector2d centre(k.cx, k.cy);
  std::vector<Eigen::Vector2d> placed(samples.size());
  std::vector<float> distance(samples.size());
  std::vector<double> line_sum(map.lines.size(), 0);
  std::vector<int> line_count(map.lines.size(), 0);
  for (size_t i = 0; i < samples.size(); ++i) {
    placed[i] = alignment.Apply(samples[i], centre);
    const int x = static_cast<int>(std::lround(placed[i].x())), y = static_cast<int>(std::lround(placed[i].y()));
    const bool inside = x >= 0 && y >= 0 && x < edge_distance.cols && y < edge_distance.rows;
    distance[i] = inside ? std::min(edge_distance.at<float>(y, x), static_cast<float>(kChamferCap_px)) : static_cast<float>(kChamferCap_px);
    line_sum[sample_lines[i]] += distance[i];
    ++line_count[sample_lines[i]];
  }
  int fit = 0;
  f.line_unfit.assign(map.lines.size(), true);
  for (size_t li = 0; li < map.lines.size(); ++li) {
    f.line_unfit[li] = line_count[li] < kMinSamples || line_sum[li] / line_count[li] > limit;
    fit += !f.line_unfit[li];
  }
  // Points not predicted on the coarse pass count as unfit: nothing says their outline is there.
  f.point_unfit.assign(map.points.size(), true);
  for (const auto& [index, uv] : f.predicted) {
    const Eigen::Vector2d p = alignment.Apply(ToFrame(uv), centre);
    double sum = 0;
    int n = 0;
    for (size_t i = 0; i < placed.size(); ++i) {
      if ((placed[i] - p).squaredNorm() > kLocal_px * kLocal_px) continue;
      sum += distance[i];
      ++n;
    }
    f.point_unfit[index] = n < kMinSamples || sum / n > limit;
    fit += !f.point_unfit[index];
  }
  if (fit < kMinFit) {
    f.point_unfit.clear();
    f.line_unfit.clear();
    return false;
  }
  std::vector<Eigen::Vector2d> kept, kept_sky;
  for (size_t i = 0; i < samples.size(); ++i)
    if (!f.line_unfit[sample_lines[i]]) kept.push_back(samples[i]);
  for (size_t i = 0; i < sky_samples.size(); ++i)
    if (!f.line_unfit[sky_lines[i]]) kept_sky.push_back(sky_samples[i]);
  samples.swap(kept);
  sky_samples.swap(kept_sky);
  f.stats.local_fit = true;
  return true;
}

void VisionTracker::Impl::DropUnfit(const Frame& f, std::vector<std::pair<int, Eigen::Vector2d>>& predicted) const {
  if (f.point_unfit.empty()) return;
  std::erase_if(predicted, [&](const auto& p) { return f.point_unfit[p.first]; });
}

// The coarse pass proper: the predicted points moved by the alignment and matched within
// kCoarseMatch_px, applied to a copy of the filter, whose pose is returned for the fine pass.
PoseEkf VisionTracker::Impl::CoarsePass(const PoseEkf& ekf, Frame& f, const ImageAlignment& alignment, bool turn) {
  const Eigen::Vector2d centre(k.cx, k.cy);
  std::vector<std::pair<int, Eigen::Vector2d>> moved = f.predicted;
  for (auto& [index, uv] : moved) uv = alignment.Apply(uv, centre);
  const std::vector<std::pair<int, int>> coarse_matches = MatchPoints(moved, f.corners, Eigen::Vector2d::Zero(), kCoarseMatch_px);
  f.timer.Lap(kStageMatch);
  PoseEkf coarse = ekf;
  for (const auto& [index, j] : coarse_matches) {
    (void)coarse.UpdatePoint(k, map.points[index], Eigen::Vector2d(f.corners[j].x, f.corners[j].y));
  }
  // Until the lock holds: the coarse pass again from the coarse pose (matched within the coarse
  // radius, applied to a fresh copy of the filter), as the pose that the first matches pulled
  // brings more of the image's corners within reach (iterated re-linearisation).
  for (int pass = 1; turn && pass < options.acquisition_coarse_passes; ++pass) {
    std::vector<std::pair<int, Eigen::Vector2d>> predicted = PredictPoints(coarse);
    DropUnfit(f, predicted);
    const std::vector<std::pair<int, int>> again = MatchPoints(predicted, f.corners, Eigen::Vector2d::Zero(), kCoarseMatch_px);
    coarse = ekf;
    for (const auto& [index, j] : again) (void)coarse.UpdatePoint(k, map.points[index], Eigen::Vector2d(f.corners[j].x, f.corners[j].y));
  }
  f.timer.Lap(kStageEkf);
  return coarse;
}

// Fine pass on the filter itself: known points, then lines, then converged unknown points.
// Everything is predicted again from the coarse pose (f.predicted, then also the new tracks' grid)
// and matched within match_radius_px.
void VisionTracker::Impl::FinePass(PoseEkf& ekf, Frame& f, const PoseEkf& coarse, const std::vector<Segment>& segments) {
  f.predicted = PredictPoints(coarse);
  DropUnfit(f, f.predicted);
  std::vector<bool> seen_lines(map.lines.size(), false);
  if (options.use_lines) {
    const Eigen::Vector3d centre = coarse.world_from_camera().translation;
    for (size_t i = 0; i < map.lines.size(); ++i) {
      seen_lines[i] = LineSeen(static_cast<int>(i), centre);
      if (!f.line_unfit.empty() && f.line_unfit[i]) seen_lines[i] = false;
    }
  }
  f.timer.Lap(kStageVisibility);
  const std::vector<std::pair<int, int>> matches = MatchPoints(f.predicted, f.corners, Eigen::Vector2d::Zero(), options.match_radius_px);
  std::vector<std::optional<LineCandidate>> candidates(map.lines.size());
  for (size_t i = 0; i < map.lines.size(); ++i) {
    if (!seen_lines[i]) continue;
    bool overhang = false;
    candidates[i] = MatchLine(coarse, map.lines[i], segments, &overhang);
    f.stats.rejected_overhang += overhang && !candidates[i];
  }
  ResolveSharedSegments(candidates, f);
  std::vector<std::optional<Segment>> line_matches(map.lines.size());
  for (size_t i = 0; i < map.lines.size(); ++i) {
    if (!candidates[i]) continue;
    line_matches[i] = segments[candidates[i]->segment];
    if (options.segment_detector == SegmentDetector::kFastLine) line_matches[i] = RefineSegment(f.gray, *line_matches[i]);
  }
  f.timer.Lap(kStageMatch);
  ApplyFineMatches(ekf, f, matches, line_matches);
}

// Robust weights of a keyframe's point matches (VisionOptions::robust_residual_px): a trial copy of
// the filter takes them all (within the frame's budget), and a match its pose still misses by r
// beyond c has its pixel variance scaled by (r / c)^2 (a Cauchy-like weight, one reweighting step
// of iteratively reweighted least squares). A corner matched to the wrong structure a few pixels
// off, or found off its model point at every keyframe, passes the gate once the pose has moved
// towards it; this keeps it from pulling the pose as much as the matches that agree. 1 each when off.
std::vector<double> VisionTracker::Impl::RobustScales(const PoseEkf& ekf, const Frame& f, const std::vector<std::pair<int, int>>& matches,
                                                      double acquiring_var) const {
  std::vector<double> scale(matches.size(), 1.0);
  const double c = options.robust_residual_px;
  // Only while the lock holds: while acquiring, and after frames that fitted nowhere (a bus across
  // half of the frame), the fitted pose may be the wrong one, and weights taken from it would
  // favour the matches that agree with it (the bus variant: 3.2 -> 33 px p95).
  if (!(c > 0) || matches.size() < 4 || good_full_matches < options.lock_frames) return scale;
  // The trial fit is the frame's own: its prior widened (0.5 m, 0.5 deg), so that a pose the filter
  // is sure of but which is off (just after a disturbance) does not make the matches that would
  // pull it back look like the outliers.
  PoseEkf trial = ekf;
  trial.InflatePose(0.5, 0.5 * kDegToRad);
  const size_t n = std::min(matches.size(), static_cast<size_t>(std::max(0, f.budget)));
  for (size_t m = 0; m < n; ++m) {
    const auto& [index, j] = matches[m];
    (void)trial.UpdatePoint(k, map.points[index], Eigen::Vector2d(f.corners[j].x, f.corners[j].y), acquiring_var);
  }
  for (size_t m = 0; m < matches.size(); ++m) {
    const auto& [index, j] = matches[m];
    const std::optional<Eigen::Vector2d> uv = trial.ProjectPoint(k, map.points[index]);
    if (!uv) continue;
    const double r = (*uv - Eigen::Vector2d(f.corners[j].x, f.corners[j].y)).norm();
    if (r > c) scale[m] = (r / c) * (r / c);
  }
  return scale;
}

// Where known point `index`'s model edges meet in the keyframe (VisionOptions::corners_on_edges),
// searched from detected corner `corner`: ideal pixels; nullopt when fewer than two edges are found.
// An edge's direction is its projection with the filter's pose; edges shorter than 15 px in the
// image are not searched.
std::optional<Eigen::Vector2d> VisionTracker::Impl::CornerWhereEdgesMeet(const PoseEkf& ekf, const Frame& f, int index, int corner) const {
  constexpr int kSamples = 10;
  const Eigen::Vector3d& p = map.points[index];
  const std::optional<Eigen::Vector2d> at = ekf.ProjectPoint(k, p);
  if (!at) return std::nullopt;
  const Eigen::Vector2d at_frame = ToFrame(*at);
  std::vector<Eigen::Vector2d> directions;
  for (const Eigen::Vector3d& edge : point_edges[index]) {
    const std::optional<Eigen::Vector2d> end = ekf.ProjectPoint(k, p + edge);
    if (end && (*end - *at).norm() < 3.0 + kSamples + 2) continue;
    // The direction from a point near the corner (the far end may be behind the camera).
    const std::optional<Eigen::Vector2d> near = ekf.ProjectPoint(k, p + edge * std::min(1.0, 0.5 / edge.norm()));
    if (!near || (*near - *at).norm() < 1e-6) continue;
    const Eigen::Vector2d d = (ToFrame(*at + (*near - *at).normalized() * 5.0) - at_frame).normalized();
    directions.push_back(d);
  }
  if (directions.size() < 2) return std::nullopt;
  const Eigen::Vector2d seed(f.frame_corners[corner].x, f.frame_corners[corner].y);
  const std::optional<Eigen::Vector2d> met = CornerOnEdges(f.gray, seed, directions, kSamples, 2.0, 8.0, 3.0);
  if (!met) return std::nullopt;
  const std::vector<cv::Point2f> ideal = ToIdeal({cv::Point2f(static_cast<float>(met->x()), static_cast<float>(met->y()))});
  return Eigen::Vector2d(ideal[0].x, ideal[0].y);
}

std::optional<Eigen::Vector2d> VisionTracker::Impl::WedgeDirection(const PoseEkf& ekf, int index) const {
  const Eigen::Vector3d& p = map.points[index];
  const std::optional<Eigen::Vector2d> at = ekf.ProjectPoint(k, p);
  if (!at) return std::nullopt;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  int n = 0;
  for (const Eigen::Vector3d& edge : point_edges[index]) {
    const std::optional<Eigen::Vector2d> near = ekf.ProjectPoint(k, p + edge * std::min(1.0, 0.5 / edge.norm()));
    if (!near || (*near - *at).norm() < 1e-6) continue;
    sum += (*near - *at).normalized();
    ++n;
  }
  if (n == 0 || sum.norm() < 0.3) return std::nullopt;
  return sum.normalized();
}

// The fine pass's updates of the filter, points then lines, within the frame's budget; the
// accepted ones are followed by KLT (points) and edge search (lines) until the next keyframe.
void VisionTracker::Impl::ApplyFineMatches(PoseEkf& ekf, Frame& f, const std::vector<std::pair<int, int>>& matches,
                                           const std::vector<std::optional<Segment>>& line_matches) {
  known.clear();
  const double acquiring_var = good_full_matches < options.lock_frames ? options.acquiring_sigma_px * options.acquiring_sigma_px : 0.0;
  // Until the lock holds, a point's match may be the wrong corner, and the same wrong one on the
  // next acquiring frames (each is matched from the pose the last one pulled): a persisting
  // association error per point (acquisition_association_px), ids after the shared one.
  const bool acquiring_association = good_full_matches < options.lock_frames && options.acquisition_association_px > 0;
  std::vector<double> scale = RobustScales(ekf, f, matches, acquiring_var);
  for (size_t m = 0; m < matches.size(); ++m) {
    const auto& [index, j] = matches[m];
    if (map.points[index].z() < ekf.world_from_camera().translation.z()) scale[m] *= options.foot_variance_scale;
    Eigen::Vector2d uv(f.corners[j].x, f.corners[j].y);
    if (options.corners_on_edges > 0) {
      const std::optional<Eigen::Vector2d> met = CornerWhereEdgesMeet(ekf, f, index, j);
      if (met) {
        uv = *met;
      } else if (options.corners_on_edges >= 2) {
        ++f.stats.rejected_structure;
        continue;
      }
    }
    if (options.corner_bias_px > 0 && uv == Eigen::Vector2d(f.corners[j].x, f.corners[j].y)) {
      if (const std::optional<Eigen::Vector2d> into = WedgeDirection(ekf, index)) uv -= options.corner_bias_px * *into;
    }
    const Eigen::Vector2d correction = uv - Eigen::Vector2d(f.corners[j].x, f.corners[j].y);
    f.stats.point_matches.emplace_back(map.points[index], uv);
    if (f.budget <= 0) continue;
    --f.budget;
    const PointBias second = acquiring_association
                                 ? PointBias{static_cast<int64_t>(map.points.size()) + 2 + index, options.acquisition_association_px}
                                 : SharedBias(index, ekf.world_from_camera().translation);
    const UpdateResult r =
        ekf.UpdatePoint(k, map.points[index], uv, acquiring_var, {{{BiasId(index), PointBiasPx(index, ekf.world_from_camera().translation)}, second}}, scale[m],
                        MisfitGainScale(index));
    Count(r, f.stats.points_used, f.stats);
    if (r.accepted()) {
      f.stats.misfit_weighted += MisfitGainScale(index) >= 2;
      known.push_back({index, f.frame_corners[j], f.frame_corners[j], scale[m], MisfitGainScale(index), correction});
      f.applied_points.emplace_back(index, uv);
    }
  }
  known_lines.clear();
  for (size_t i = 0; i < line_matches.size() && f.budget > 0; ++i) {
    if (!line_matches[i]) continue;
    --f.budget;
    const UpdateResult r = ekf.UpdateLine(k, map.lines[i].line, line_matches[i]->a, line_matches[i]->b, acquiring_var);
    Count(r, f.stats.lines_used, f.stats);
    if (r.accepted()) {
      known_lines.push_back(static_cast<int>(i));
      f.stats.line_matches.push_back({map.lines[i].a, map.lines[i].b, line_matches[i]->a, line_matches[i]->b});
    }
  }
}

// The lock after a keyframe: good and bad full matchings counted (lock_frames, lost_frames); after
// lost_frames bad ones in a row the pose is declared lost, its covariance widened and the next
// keyframe relocalises.
void VisionTracker::Impl::UpdateLock(PoseEkf& ekf, Frame& f, const ImageAlignment& alignment, bool acquiring) {
  // A frame still waiting for a position the model fits (relocalize_max_score_px) applied nothing
  // and says nothing of the lock: counting it as lost would inflate the pose every lost_frames.
  if (f.stats.relocalize_waiting) return;
  // The lock: enough features applied and few rejected; tracking resumes after lock_frames of these.
  const int applied = f.stats.points_used + f.stats.lines_used, tried = applied + f.stats.rejected;
  // ... and the model's edges lay down on the frame's where the filter predicts them: a coarse
  // alignment that had to move the image means the matches were taken from a pose that was off,
  // and a lock formed there holds a wrong association (issue 19, sixth session).
  // (A turn of one search step, 0.5 deg, is the prediction's ordinary roll error without an AHRS.)
  const bool aligned = !acquiring || !(options.lock_alignment_px > 0) ||
                       (alignment.offset.norm() <= options.lock_alignment_px &&
                        std::abs(alignment.rotation_rad) <= options.acquisition_roll_step_deg * kDegToRad + 1e-9);
  const bool good = applied >= options.min_tracked_known && f.stats.rejected <= options.weak_lock_gated_share * tried && aligned;
  // Once the lock holds, a thin view whose few matches the gate took cannot show it lost: a few far
  // façades over grass hold the pose. One that applied nothing counts: a blind stretch (the walk at
  // 63-65 s, nothing in view) leaves the pose to drift, and the view that returns needs the search.
  // (Before the first lock thin views count too: a prior 17 deg off may predict grass where the
  // camera sees façades.)
  if (!good && f.stats.thin_view && locked_once && applied > 0) return;
  good_full_matches = good ? good_full_matches + 1 : 0;
  bad_full_matches = good ? 0 : bad_full_matches + 1;
  if (!locked_once && good_full_matches >= options.lock_frames) lock_since_ns = ekf.time_ns();
  locked_once = locked_once || good_full_matches >= options.lock_frames;
  ever_locked = ever_locked || locked_once;
  if (options.lost_frames > 0 && bad_full_matches >= options.lost_frames) {
    ekf.InflatePose(0.5, options.lost_orientation_sigma_deg * 3.14159265358979323846 / 180);
    bad_full_matches = 0;
    relocalize = true;
    locked_once = false;
    ++f.stats.relocks;
  }
}

}  // namespace ave::pose
