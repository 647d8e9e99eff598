#pragma once
// Vision stabilisation of the camera pose (AVE §5.1, issue 5): known 3D point features (building
// corners) and 3D line features (building edges) of the static model are projected with the
// filter's predicted pose and matched to corners and line segments detected with OpenCV in the
// frame, inside a search window around the prediction; a priori unknown point features are tracked
// (pyramidal KLT) and their 3D position estimated as tracking goes, each by its own small
// prediction-correction filter, and join the pose update once converged (docs/POSE.md).
// OpenCV stays inside vision.cc, vision_keyframe.cc and vision_impl.h (internal).
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/pose/pose_ekf.h"

namespace ave::pose {

// A 3D line feature with the model segment it comes from (the segment bounds where it is searched
// for; the measurement uses the infinite line).
struct LineFeature {
  Line3d line;
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();  // segment end points, local frame
  // A roof's own edge (a ridge, a hip, a gable's rake): matched and tracked like the others, but
  // left out of the chamfer alignment (with them, frames the model "fits nowhere" went from 0-4 to
  // 10-20 of a run's: a roof's shading against its walls is a faint edge). Kept in the
  // relocalisation's alone, two of 13 draws that relocalised 2-3 m off held (p95 4.8 -> 1.4 px), but
  // the single-frame test from a 13 px perturbation then ended 2.7 px off: left out there too.
  bool roof = false;
};

struct FeatureMap {
  std::vector<Eigen::Vector3d> points;  // local frame
  std::vector<LineFeature> lines;
};

// The wireframe of every rectangular building part as the campus meshes it: its corners at the
// ground and at the top of each wall, its roof's own vertices (gable apexes, hip ridge ends), its
// vertical edges, the tops of its walls (a shed's high wall at the roof's high edge, its side
// walls' tops sloping) and its roof's edges (rakes, hips, ridges; LineFeature::roof). Round parts
// contribute none. (Until issue 19's tenth session every part was a box at the eaves: a shed's
// high corners sat 1.5-2 m low and a gable end carried an eaves edge it does not have.)
FeatureMap CampusFeatureMap(const scene::SyntheticCampus& campus);

// The line segment detector of keyframes: OpenCV's LSD (Grompone von Gioi et al.) or the Fast Line
// Detector of opencv_contrib's ximgproc (Lee et al. 2014: Canny, then straight runs of edge pixels).
enum class SegmentDetector : uint8_t { kLsd, kFastLine };

struct VisionOptions {
  int max_features = 50;          // features used per frame (known points, then lines, then new points)
  double search_radius_px = 60;   // window around each prediction for the first (coarse) match
  double match_radius_px = 3;     // window after the coarse pass
  // Issue 19 (seventeenth session): once the lock has held, the coarse alignment searches only as far
  // as the filter's pose can be off: this many times its projected sigma at the predicted points,
  // plus locked_search_floor_px, at most search_radius_px. A shift beyond that is the model's
  // outline laid on something else (a lens occluder's edge, a person close by): on the walk at
  // 82.5 s it moved the image 20-60 px while the pose was 0.1 m right. Acquisition and the search
  // after a declared loss keep the full radius. 0: the full search_radius_px on every keyframe.
  double locked_search_sigmas = 4;
  double locked_search_floor_px = 8;
  // Issue 19 (seventeenth session): an image segment that two model lines' predictions both reach
  // goes to the nearer only when its distance is under this times the other's; else to neither
  // (a near line's image 4 px from a far one's took the far one's edge on the walk at 82.5 s).
  // 0: to neither.
  double line_ambiguity_ratio = 0.5;
  // Issue 19 (eighteenth session): a segment that reaches beyond a model line's predicted image by
  // more than line_max_overhang_px plus line_max_overhang_share of the image's length, at its two
  // ends together, is another straight edge (the lens occluder's side, a pole, a mover), not that
  // line; a shorter one may still be matched. The walk at 84.2 s: a 6 m building corner, 83 px in
  // the image, took a 140-158 px segment that drifted 18 px in 0.8 s. 0 px: not checked.
  double line_max_overhang_px = 8;
  double line_max_overhang_share = 0.2;
  bool use_lines = true;
  // Issue 19 (moonshot): the Fast Line Detector, its matched segments refined to sub-pixel, costs a
  // sixth of LSD (0.29 against 1.96 ms a frame) at the same accuracy (docs/BENCHMARKS.md, "Fast Line Detector").
  SegmentDetector segment_detector = SegmentDetector::kFastLine;
  // Track a priori unknown features and estimate their 3D structure even though neither
  // new_points_in_pose nor joint_new_points uses them (for their figures); either of those tracks
  // them anyway. Off by default since issue 19's moonshot: the known-only pose paid ~0.6 ms a frame
  // for features nothing used.
  bool use_new_points = false;
  // Let converged unknown features correct the pose too. Off by default: without the pose-point
  // cross-correlations (not kept here) their errors feed back into the pose, which then drifts
  // (ave-bench pose shows the row; docs/BENCHMARKS.md).
  bool new_points_in_pose = false;
  // Converged unknown features join the pose filter's state (PoseEkf::AddLandmark) and are from
  // then on estimated jointly with the pose, cross-covariances kept, up to max_state_points at a
  // time; their observations then correct the pose without the drift above (issue 19).
  bool joint_new_points = false;
  int max_state_points = 25;  // 15 until session pose19j (more landmarks pass its joining tests below)
  // A landmark's sightings share a persisting error (its KLT track's offset from the point repeats):
  // a consider bias of this sigma per landmark (PoseEkf::UpdateLandmark), as feature_point_bias_px
  // for known points. 0: none. At 1 px the joint mode's pose NEES in band goes 78 -> 80 % (10 s) and
  // 86 -> 89 % (20 s) with identical pixels (docs/BENCHMARKS.md, "NEES, this session").
  // 2.0 since the eighth session, calibrated over 13 draws (the pixels identical): the joint
  // mode's NEES in band pooled 84.3 % (1 px; above the band 13.1 %), 86.8 % (2 px), 86.5 (3 px).
  double landmark_bias_px = 2.0;
  // Extra noise of a landmark's sighting (a KLT track re-matched on its keyframe patch). 1.5 until
  // issue 19's twelfth session; the part of a track's error that persists is landmark_bias_px's
  // consider term, as for the known tracked features (tracked_sigma_px 0.6). Over 13 draws the joint
  // mode's median of the medians goes 0.506 -> 0.483 px (2.5 px: 0.527, 0.7 px: 0.479), NEES in
  // band pooled 84.1 -> 84.6 % (docs/BENCHMARKS.md, "Issue 19, twelfth session").
  double landmark_sigma_px = 1.0;
  // Unknown features seen on the last keyframe are re-matched by KLT against their keyframe patch
  // every frame (after the frame-to-frame step), so a track's error accumulates once per keyframe,
  // not once per frame (issue 19).
  bool unknown_from_keyframe = true;
  // The anchored filter's depth sigma is scaled by this when a feature joins the state: it takes its
  // frozen anchor pose as exact and its sightings as independent (issue 19: joined landmarks' 3-dof
  // NEES 8.7 at 1, 2.7 at 2; ave-bench pose).
  double join_depth_sigma_scale = 2;
  // New unknown-feature tracks only while the full matching holds the lock (lock_frames): their anchor
  // is the filter's pose at the first sighting, taken as exact. Off: better landmarks, no better pose.
  bool unknown_after_lock = false;
  int max_new_points = 150;       // tracked unknown features kept
  double new_point_sigma_m = 0.3; // an unknown feature is used for pose once its largest sigma is below this
  // ... or (joint mode, issue 19 session pose19j) once its depth sigma is below this share of its
  // depth: a far point on a facade reaches 0.3 m only after seconds (190 sightings at 30 m) while
  // its bearing is already a good orientation reference. 0: the absolute test alone.
  double new_point_depth_sigma_ratio = 0.1;
  // Joining tests (joint mode, session pose19j; docs/POSE.md "New features, session pose19j"): a
  // converged feature is refused when, seen from its anchor camera, its bearing has drifted more than
  // this from its first sighting (a static point's does not: a sliding track or a mover across the
  // epipolar lines; 0: off) ...
  double join_bearing_drift_px = 3;
  // ... or its depth differs from the static mesh's surface on the same ray by more than this share
  // of the mesh's depth (and 1 m), or the ray meets no surface (a mover along the epipolar lines
  // whose motion became a wrong depth, or a point that the model says would be hidden; 0: off).
  double join_model_depth_tolerance = 0.25;
  int new_point_min_observations = 5;  // ... and it has been seen this many times
  double new_point_prior_depth_m = 20;  // depth prior of a fresh unknown feature (anchored inverse depth 1/20 per m ...)
  double new_point_inverse_depth_sigma = 0.25;  // ... with this sigma (1/m): 2 sigma spans 1.8 m to infinity

  // Video-rate front end (issue 19). Between keyframes the known features matched on the last
  // keyframe are followed by KLT from the pose filter's prediction and update the filter directly;
  // the expensive model matching (corners + sub-pixel, segments, Canny + distance transforms,
  // chamfer/sky-line alignment, coarse and fine passes) runs only on keyframes.
  int keyframe_interval = 10;     // full model matching at least every N frames (1: every frame, the issue-5 front end)
  int lost_frames = 10;           // this many consecutive badly fitting full matches: the pose is lost, its covariance inflated
  double lost_orientation_sigma_deg = 1.0;  // ... by this orientation sigma (and 0.5 m of position sigma)
  int lock_frames = 15;           // tracking between keyframes only after this many consecutive well-fitting full matches
  // Extra noise of a tracked (not re-detected) feature: its error persists from frame to frame.
  // 1.5 until issue 19's seventh session. The persisting part is now feature_point_bias_px's
  // (consider term, below); the part that varies is 1.1-1.2 px per axis against the truth
  // (ave-bench pose, "known-point match errors by the point's depth"). 1.0 alone was better over 13
  // draws but lost the bus variant after the bus (45.9 px a second after): tracks that slid onto
  // the bus pulled the pose; with tracked_max_innovation_px (below) it holds (docs/BENCHMARKS.md,
  // "Issue 19, seventh session").
  // 0.6 since the eighth session: with the carried camera's height (carrier_height_m) holding the
  // height, 13 draws pooled NEES in band 89.8 % (1.0) -> 91.0 (0.8), 91.4 (0.6), 91.7 (0.4), and
  // the median of the draws' median px 0.69 -> 0.66, 0.65, 0.69: a track's error is mostly its
  // keyframe's corner error, which persists (the consider term), not new noise each frame.
  double tracked_sigma_px = 0.6;
  // A tracked known feature farther than this from its projection with the pose so far (the
  // prediction, updated by the frame's features before it) is not applied and its track ends
  // (VisionFrameStats::rejected_tracked_jump), whatever the chi-square gate says: a KLT track that
  // slid to another corner or onto a mover. Seventh session: tracks 5-18 px off their point passed
  // the gate, whose sigma the pose's own uncertainty widens. With tracked_sigma_px 1.0, over 13
  // draws: p95 within 1.6 px on 10 draws (5 before), median p95 1.74 -> 1.47 px, NEES in band 77 ->
  // 80 %; the bus variant's pose during the bus 8.08 -> 1.82 px median. 4 px: 6 draws, 79 %. 0: off.
  double tracked_max_innovation_px = 3;
  // Extra noise of the full matching's features until the lock holds (fewer than lock_frames good
  // fits in a row, issue 19): matched from an unconverged prediction, a frame's features share its
  // association error (the coarse offset), which independent 1.5 px noise does not cover.
  double acquiring_sigma_px = 0;
  // Acquisition (issue 19): before the first vision frame the pose rests on GPS and the AHRS, whose
  // errors are correlated over seconds (multipath ~1 m, AHRS drift ~1-2 deg) and so not in their
  // per-reading covariances; the first frame's matching would find the filter far more confident
  // than it is (NEES 160, and the surprise lands in the gyro bias). Before the first vision update
  // the pose covariance is widened by these sigmas. Off (0) by default: 1 m / 1 deg left the
  // first frames out of the 95 % band all the same (docs/POSE.md, "Gyro bias").
  double acquisition_position_sigma_m = 0;
  double acquisition_orientation_sigma_deg = 0;
  // While acquiring (until the first lock, and after the pose is declared lost) the coarse chamfer
  // search also turns the image about the principal point, up to +-this in steps of
  // acquisition_roll_step_deg (issue 19, sixth session: an AHRS roll error of 1.5 deg moves the
  // image edges 8 px, beyond the coarse match radius, and the lock formed on the central corners
  // alone with the roll left as it was). 0: off.
  double acquisition_roll_search_deg = 3;
  double acquisition_roll_step_deg = 0.5;
  // The heading search while acquiring (issue 19, eighteenth session). An AHRS's heading is good
  // to a few degrees only in a clean magnetic field: on the campus walk it is up to 22 deg off
  // beside buildings (magnetic disturbance, gyro drift), far beyond the coarse search's 60 px
  // (about 7 deg), and a pose started after ~16 s never locked. Before the first lock, whenever
  // relocalisation searches, the pose is also turned about the world's vertical in steps of
  // acquisition_heading_step_deg up to +-acquisition_heading_search_deg, each scored by the chamfer
  // alignment; the best turn that fits well and stands out (relocalize_max_score_px,
  // relocalize_margin_px, relocalize_distinct_px) is refined in halved steps to 1.5 deg, has the
  // positions searched around it too, and is taken when its best position fits better than the
  // best at the filter's own heading by relocalize_margin_px. The turned orientation gets sigma
  // reorient_sigma_deg per axis and no correlation with the rest. 0: off. Over 8 draws started at
  // 10-80 s, 7 lock against 2 (docs/BENCHMARKS.md, "Issue 19, eighteenth session").
  double acquisition_heading_search_deg = 30;
  double acquisition_heading_step_deg = 6;
  double reorient_sigma_deg = 3;
  // While acquiring, a full matching counts towards the lock (lock_frames) only when its coarse
  // alignment moved the image by at most this (px) and turned it by at most one
  // acquisition_roll_step_deg; otherwise towards lost_frames. A lock formed from a prediction the chamfer search had to move holds the
  // wrong corners (issue 19, sixth session). 0: not checked.
  double lock_alignment_px = 3;
  // A keyframe whose best chamfer alignment (ImageAlignment::score_px, the mean edge distance of the
  // model's outline, truncated at 8 px, plus the skyline's) is worse than this applies no feature:
  // the model's outline lies nowhere on the frame (a bus across half of it: 7-8 px; fitting frames
  // 2-6 px on the campus run). It counts as a bad fit, and relocalisation never moves to such a
  // fit. 0: off.
  double max_alignment_score_px = 6.5;
  // On a keyframe that fits nowhere as a whole, each known point and line is judged by its own
  // stretch of the outline (a line's samples; for a point, those within 16 px of it): where that
  // lies within this mean distance (px) of the frame's edges, it is still matched, and the
  // alignment is searched again from the fitting lines; the frame is unfit only when fewer than 4
  // fit (issue 19, tenth session: with the campus's true wireframe a bus across the left half
  // scores 8-9 px over the whole frame and the pose drifted to 11 px median while nothing was
  // applied; at 2 px: 1.58 px median, p95 2.70 during it, 0.56 after; at 3 px 1.28 / 2.03 / 0.54,
  // but a single half-covered frame then moved a locked pose 0.55 -> 1.18 px, a line along the
  // covering edge taken). 0: the whole frame only. Only once the lock has held
  // local_fit_after_lock_s: a lock formed metres off fits nowhere soon after and must be declared
  // lost, not held by the few features that still fit by chance.
  double local_fit_px = 2;
  double local_fit_after_lock_s = 2;
  // Coarse passes (match, update a copy) while acquiring: 1 = one, as on locked keyframes; more
  // re-match from the pose the last pass pulled (tried, not better: docs/POSE.md).
  int acquisition_coarse_passes = 1;
  // Relocalisation (issue 19, sixth session): on the first vision frame, and when the pose is
  // declared lost (lost_frames), the model's edges are aligned (ChamferAlign: shift and turn) from
  // positions on a horizontal grid of +-relocalize_extent_m in steps of relocalize_step_m, then half
  // steps around the best; the filter moves there (PoseEkf::MovePosition, sigma half a step) when
  // its chamfer score beats the filter's own position by relocalize_margin_px. GPS multipath near
  // buildings is 1-4 m in the campus run, and no image shift or turn undoes the parallax it leaves
  // on near façades, so the first matches took wrong corners that then held the pose. 0: off.
  double relocalize_extent_m = 3;
  double relocalize_step_m = 1;
  double relocalize_margin_px = 0.5;
  // A prior whose horizontal position sigma times relocalize_extent_sigmas exceeds
  // relocalize_extent_m (a GPS outage: the inertial position's sigma grows to tens of metres) is
  // searched over that half-extent instead, at most relocalize_max_extent_m, in steps of at least
  // a sixth of it (issue 19, twentieth session). The campus's GPS is out from 2 to 32 s: started
  // at 20 and 24 s the inertial prior was 8.7 and 6.5 m off at sigmas of 137 and 184 m, and the
  // +-3 m grid moved the pose 5 m off (8.1 / 35 and 0.84 / 10.8 px); at 2 sigmas (12 m) 0.47 / 1.18
  // and 0.48 / 3.19 px, the 30 s start's p95 26.8 -> 3.0 px. A prior within a fix's sigma keeps
  // the +-3 m grid (the walk and the first 10 s unchanged). A widened search scores up to 185
  // positions instead of 57.
  // 0: the fixed grid.
  double relocalize_extent_sigmas = 2;
  double relocalize_max_extent_m = 12;
  // ... and by this much the best fit farther than 1.5 steps from it (a flat score landscape: no
  // move; issue 19, eighth session). Draw 11 of 13 scored 5.3-7.8 px over the whole grid and moved
  // 2.6 m the wrong way: at 0.3 it stays (p95 13.9 -> 2.6 px) and no other draw changes; at 0.5 draw 8's
  // needed move is refused (p95 5.3 px), at 1.0 draw 5's too (lost). A thin margin: 0: off.
  double relocalize_distinct_px = 0.3;
  // ... and a relocalisation is believed only where the model's outline fits the frame well: the
  // best chamfer score over the grid (the filter's own position included) at most this (issue 19,
  // eleventh session). Over 13 draws the right first relocalisations scored 2.5-3.2 px; the two
  // wrong ones (a tree over the façades' tops, 3 m off) 4.6 and 5.2. A frame that fits nowhere this
  // well applies nothing, counts neither towards the lock nor the loss, and the search runs again
  // relocalize_retry_frames later (VisionFrameStats::relocalize_waiting). 0: off.
  double relocalize_max_score_px = 4;
  // ... and while it waits, the search (~250 ms on one core) runs again on every this many frames;
  // the frames between apply nothing and cost what a tracked frame costs. 1: every frame.
  int relocalize_retry_frames = 5;
  // A thin view (issue 19, nineteenth session): a keyframe whose pose predicts fewer known points
  // in view than this does not relocalise (it waits, as for relocalize_max_score_px); once the lock
  // holds, one that applied some matches does not count towards lost_frames (one that applied
  // nothing does); it may still count towards the lock. The walk at 80-90 s looks over grass at a
  // few far façades (1-12 points predicted): each loss declared there relocalised by the chamfer
  // score of that thin outline, 3-7 m and up to 22 deg away from a pose GPS and the gyro had held
  // within 1 m. 0: off.
  int min_view_points = 8;
  // ... and a relocalisation's candidate position must show at least this share of the model's
  // outline (edge samples) that the filter's own position shows: a thin outline's mean chamfer
  // distance is low by chance (the walk with the rules above: 80-90 s p95 46.8 -> 21.9 px). 0: any.
  double relocalize_min_outline_share = 0.5;
  // Persisting detection bias of the known features (issue 19, docs/POSE.md "NEES by cause"): a
  // rendered or real building corner is found 0.2-0.4 px off its model point the same way at every
  // keyframe and along every track, so no number of sightings averages it away, and the
  // vision-locked filter reported an orientation sigma below the error it leaves (roll 0.07 deg
  // sigma, 0.11 deg mean error). After a frame that applied features, the bias seen from the
  // camera is the reported pose covariance's consider term (PoseEkf::SetConsideredOrientation):
  // bias / fx about x (pitch), bias / fy about y (yaw), bias / (RMS radius of the frame's point
  // matches from the principal point) about the optical axis (roll). The estimate is unchanged.
  // 0: none. Flooring the filter's own covariance instead made the pose worse (0.523 / 1.565 px,
  // NEES in band 70 % at 0.2 px): the filter then follows each frame's white noise more.
  // 0.5 since issue 19, sixth session: over 13 draws of the noise NEES in band pooled 57 -> 62 %, the
  // scenario draw's mean NEES 8.4 -> 5.8 (chi2(6): 6); the corners' mean residuals against the
  // truth are 0.1-0.4 px per kind (feet, eaves; keyframe, tracked). 0.3 until pose19e, then 0.2.
  // 0.2 again since the seventh session: with feature_point_bias_px at its measured 1 px, 0.5 put
  // the roll's sigma 1.6x above its error (mean z^2 0.3-0.8 on every draw) and frames below the band.
  // 0 since the eighth session: with the carried height and tracked_sigma_px 0.6 the per-point term
  // covers the orientation too; 0.2 left frames below the band (13 draws pooled 91.4 -> 92.2 %,
  // below 5.8 -> 3.6 %; scenario draw 92 -> 94 % over 10 s, 83 -> 86 % over 20 s).
  double feature_bias_px = 0;
  // Issue 19, session pose19e: the same bias per known point, the effect on the pose followed
  // exactly. Each known point's detections carry a persisting pixel offset of this sigma per axis,
  // the same at every keyframe and along every track of that point; the filter keeps its error
  // state's sensitivity to every such offset through each update, prediction and reset
  // (PoseEkf::UpdatePoint's biases, a Schmidt consider analysis), and the reported covariance adds
  // its effect: on position as well as orientation, and only as much as the points actually seen
  // allow. The estimate is unchanged. The measured detection bias (0.2-0.4 px) has a part each
  // point has of its own and a part the points share (feet above, eaves below: an image-wide
  // pattern, which acts on the roll), so the 0.3 px is split evenly between this term and the
  // orientation term above (0.3 / sqrt(2) ~ 0.2 each). On the campus run this term alone gives 84.4 %
  // of frames in the NEES band, the orientation term alone at 0.2 px 87.4 %, both 87.7 %
  // (docs/BENCHMARKS.md, "NEES, session pose19e"). 0: none.
  // 1.0 since issue 19's seventh session: over every match of a run (ave-bench pose, "known-point
  // match errors by the point's depth"; --match-csv) each point's mean error against the truth is
  // 0.9-1.0 px RMS per axis (0.5 px for points nearer than 60 m, 0.9 px beyond 120 m, more with
  // the 10 % of matches 3-20 px off, which persist too): 0.2 px was the scenario draw's near corners.
  // Over 13 draws NEES in band pooled 68 -> 72 % (0.8 px), 77 % (1.0, with feature_bias_px 0.2 and acquisition_association_px 1), 78 % (1.2).
  // 0.8 since the tenth session: with the campus's true wireframe (the sheds' high corners, no
  // gable-end eaves) the persisting part is 0.44 px RMS per axis nearer than 60 m, 0.54 at 60-120 m
  // and 0.78 beyond; at 1.0 8.4 % of frames fell below the band (13 draws pooled 89.4 -> 90.3 %).
  // 0.6 since the thirteenth session: a wall foot's 4x variance now holds along its KLT track too
  // (it was dropped there), and at 0.8 the pose was over-covered (mean NEES 4.6; Monte Carlo NEES
  // 48.5 % in band, 48 % below). 13 draws, pooled / Monte Carlo: 0.8 93.0 / 48.5 %, 0.7 93.6 /
  // 55.5 %, 0.6 93.0 / 66.8 %, 0.5 92.0 / 63.2 % (docs/BENCHMARKS.md, "thirteenth session").
  // 0.4 since the fourteenth session: corner_bias_px takes out the part every corner shares (its
  // wedge's pull); with it at 0.4, 13 draws pooled / Monte Carlo: 0.6 91.7 / 49.8 % (49 % below),
  // 0.5 92.1 / 63.5 %, 0.4 92.3 / 68.1 %.
  double feature_point_bias_px = 0.4;
  // ... that sigma for points at most feature_point_near_m away, rising linearly to
  // feature_point_bias_px at twice that distance (issue 19, eighth session: over 13 draws the
  // persisting part is 0.48 px RMS per axis nearer than 60 m, 0.54 at 60-120 m, 0.89 beyond; the
  // near corners carry the position). Equal to feature_point_bias_px: one sigma at every depth,
  // the default: 0.5 near moved frames from below the band to above it (13 draws pooled 89.8 ->
  // 89.2 %: below 6.9 -> 4.8 %, above 3.3 -> 6.1 %).
  double feature_point_bias_near_px = 0.4;
  double feature_point_near_m = 60;
  // The acquisition's association errors (issue 19, session pose19e): until the lock holds
  // (lock_frames), the full matchings start from the GPS + AHRS prior, several pixels off, and a
  // point may be matched to the wrong corner, the same wrong one frame after frame (on the campus:
  // 8 of frame 0's 13 matches 2.6-6.5 px off). Each point's match then carries a persisting pixel
  // offset of this sigma in the reported covariance (a consider bias per point,
  // PoseEkf::UpdatePoint), until updates after the lock shrink it; the estimate is unchanged.
  // Session pose19e left it off (3 px put frames after the lock below the band, 88.0 %); with the
  // innovation-following covariance (nis_short_gain) and the Fast Line Detector, 3 px takes the
  // lock's frames into the band: 89 -> 90 % (10 s), 92 % either way (20 s), mean NEES 9.0 -> 7.1.
  // 1 since the seventh session: the lock now needs a coarse alignment that moved the image by at
  // most lock_alignment_px, so a lock's matches are rarely a corner off; at 3 px the lock's frames
  // were below the band on 10 of 13 draws (NEES 0.2-0.8 at 0.2-0.5 s).
  // 0.5 since the thirteenth session: the lock's first second was still below the band on most
  // draws (mean NEES 3.7). Over 13 draws NEES in band pooled 93.0 % (1 px) -> 93.4 % (0.5) and
  // 93.6 % (0), Monte Carlo 66.8 -> 67.1 % either way; the term models a real error, so half is kept.
  double acquisition_association_px = 0.5;
  // Carried camera (issue 19, eighth session): > 0, the camera rides this high above the ground
  // (a backpack or a helmet: the campus walker's 1.7 m), and every frame the filter's height is
  // measured as the static model's ground under its position (a ray cast straight down that hits
  // terrain or road; when nothing is below, the filter has sunk under the terrain on inertial
  // heights alone, and the terrain or road straight above is the ground) plus this, with carrier_height_sigma_m (gait, posture, the model's ground
  // error), the error correlated over carrier_height_correlation_s (a frame dt after the last
  // counts as dt / correlation of an independent one; the first at full weight). Far façades cannot
  // tell a height error from a pitch error, and GPS heights are 1-2 m off among buildings: without
  // this, draws of the noise whose first fix was low locked onto a pitched, lowered pose. 0: off
  // (a mast camera, a vehicle whose mount height is not known).
  double carrier_height_m = 0;
  double carrier_height_sigma_m = 0.1;
  double carrier_height_correlation_s = 2.0;
  // A detection bias every known point shares (one 2D pixel offset for all of them, every frame),
  // beside the per-point one above: a consider bias of this sigma per axis. 0: none.
  double feature_shared_bias_px = 0;
  // A detection bias per class of known point (issue 19, ninth session): one 2D pixel offset shared
  // by the points above the camera (eaves) and another by those below it (wall feet), a consider
  // bias of this sigma per axis each, in place of feature_shared_bias_px. 0: none (default: over 13
  // draws 0.25 px gives 92.8 % of frames in the NEES band against 92.3 %, but the Monte Carlo NEES
  // 56.8 % against 62.8 %; 0.5 px 92.2 % and 36.5 %, mostly below).
  double feature_class_bias_px = 0;
  // Robust weights on keyframes (issue 19, ninth session): a known point's match that the pose
  // fitted to all of the frame's matches still misses by r > this (px) has its pixel variance
  // scaled by (r / this)^2, on the keyframe and along its KLT track until the next (RobustScales;
  // the gate still tests at the unscaled variance). Only while the lock holds, and the trial fit's
  // prior widened, else a bus across the frame wins (bus variant p95 3.2 -> 33 px). On the campus
  // some corners are matched 1.5-4.5 px off their model points at every keyframe (a neighbouring
  // corner, a far building's blurred outline), near ones one way and far ones the other, which
  // moves the pose sideways and turns it on every draw at 2-4 s. Off (0) by default: over 13 draws
  // at 1.5 px the pixels are the same (0.65 / 1.31 px) and the Monte Carlo NEES 62.8 -> 67 % in
  // band; without the two safeguards 75 %, but not safe (docs/BENCHMARKS.md, "ninth session").
  double robust_residual_px = 0;
  // A wall foot's match (a known point below the camera: where a wall meets the terrain) is given
  // this many times the pixel variance of a wall top's, on the keyframe and along its KLT track
  // (issue 19, tenth session: over 13 draws 43 % of the feet's keyframe matches are more than 2 px
  // from the point's true projection, against 20 % of the tops': the terrain's texture, kerbs and
  // objects meet the wall there, and the corner found sits 0.6-0.7 px above the true foot). 1: the
  // same as the tops. At 4 (twice the sigma), over 13 draws the Monte Carlo NEES of 2-4 s comes into
  // the band (the scene-locked sideways error of every draw there shrinks) and the median of the
  // medians goes 0.53 -> 0.52 px (docs/BENCHMARKS.md, "tenth session").
  double foot_variance_scale = 4;
  // Known corners measured where their model edges meet in the frame (issue 19, thirteenth session;
  // internal::CornerOnEdges), not where the gradient corner detector put them: a blurred corner is
  // found inside its wedge (0.2-0.25 px at an eaves corner, 1.3-1.5 px at a far gable's apex), the
  // same way at every keyframe of every draw. 0: as detected; 1: a keyframe's matched corner is moved
  // to where two of its model edges meet, and kept as detected when fewer than two are found; 2: as 1,
  // but a corner whose edges are not found is refused (counted, rejected_structure). The move is
  // carried along the corner's KLT track. Off (0) by default: on the campus's frames it is worse
  // than the detector. Over 13 draws mode 1 gives 0.461 / 1.041 px (median of the medians / median
  // p95) against 0.488 / 1.075, but NEES in band pooled 89.7 against 93.0 %, and on draw 6's
  // keyframes the 199 (of 508) eaves corners it moved were 0.62 px from the truth against 0.50 as
  // detected (0.93 against 0.61 at the roofs' 4-edge vertices). The renderer samples each pixel once
  // at its centre (no anti-aliasing, no lens blur), so an edge near an image axis is a staircase on
  // the pixel grid and a line fitted over 10 px of it is off by up to half a pixel. Mode 2 refuses
  // every foot (the map gives a foot one edge, its vertical) and, on draw 6, 61 % of the eaves
  // corners: 0.448 / 1.169 px, NEES 74.1 %.
  // (docs/BENCHMARKS.md, "Issue 19, thirteenth session".)
  int corners_on_edges = 0;
  // Issue 19, fourteenth session: half size of cv::cornerSubPix's window (px) for every corner
  // (keyframe corners, tracked known corners, new corners). The window is 2 n + 1 px square.
  int corner_window_px = 4;
  // Issue 19, fourteenth session: a corner detector (goodFeaturesToTrack + cornerSubPix) finds an
  // L or Y junction on a blurred edge inside its wedge, by a fraction of a pixel. With this set,
  // a known corner's measurement is moved this far back out of its wedge, whose direction is the
  // sum of its model edges' projected directions (a foot's: up its wall), on the keyframe and
  // along its KLT track. 0: off. 0.4 since it came (issue 19, fourteenth session): over 13 draws
  // the known-feature row goes 0.488 / 1.075 -> 0.446 / 0.963 px (median of the medians / median
  // p95), the wall tops' mean offset in v +0.40 -> +0.16 px and the feet's -0.30 -> -0.08 px
  // (docs/BENCHMARKS.md, "Issue 19, fourteenth session"). The push of a synthetic blurred apex is
  // 0.29 px (CornerOnEdges.FindsABlurredApexWhereTheCornerDetectorDoesNot); the campus's wall tops
  // were found +0.40 px in v, into their wall. 0.55 since the fifteenth session, with the gyro's
  // bias in the filter's state: 13 draws 0.40 / 0.98 px at 0.4, 0.38 / 0.96 at 0.55.
  double corner_bias_px = 0.55;
  // A known point's persisting error learned from its own residuals (issue 19, fifteenth session).
  // Once the lock holds, every keyframe match the filter applied leaves a residual against the
  // updated pose; a running mean of it per point (this gain per keyframe; 0: off) is that point's
  // misfit, which persists while the view moves slowly. Its per-axis RMS, when above
  // PointBiasPx's sigma, becomes the point's consider sigma: a far corner matched 1.5 px off its
  // model point at every keyframe is then reported as such, not as 0.4 px. The estimate is
  // unchanged unless point_bias_weight_px is set too. Forgotten when the pose is declared lost.
  // Off: over 13 draws 0.2 moves frames from above the NEES band to below it (pooled 91.0 ->
  // 91.6 %, above 4.2 -> 1.5 %, below 4.8 -> 6.8 %; Monte Carlo 44.9 -> 34.9 %).
  double point_bias_gain = 0;
  // ... and the same learned misfit weighs the point down: its gain is computed at the pixel
  // variance times (1 + misfit^2 / point_bias_weight_px^2), misfit its per-axis RMS, while the
  // covariance is updated at the variance itself (PoseEkf::UpdatePoint's gain_scale; 0: off).
  // Off: over 13 draws (gain 0.2, 0.5 px) the known-feature row goes 0.39 / 0.96 -> 0.31 / 0.91 px,
  // but the pose is then over-covered in height and pitch and under-covered in yaw, and no
  // setting of the consider and pixel sigmas tried brings the NEES back (pooled 91.0 -> 77-84 %).
  double point_bias_weight_px = 0;
  // Issue 19: the reported covariance follows the innovations (covariance matching, Mehra 1972).
  // A persisting error (a feature found off its model point, an association) keeps each
  // innovation small, since the pose has moved to agree with it, but when the features in view
  // change or the camera turns, the innovations grow before the error shows. Each frame's mean
  // normalised innovation squared (NIS) of the applied features enters a short running mean (this
  // gain) and a long one (nis_long_gain); the reported pose covariance is scaled by short / long,
  // between 1 and nis_scale_cap (PoseEkf::SetReportedScale). The estimate is unchanged. 0: off.
  double nis_short_gain = 0.5;
  double nis_long_gain = 0.01;
  double nis_scale_cap = 3.0;
  int min_tracked_known = 8;      // fewer tracked known features than this: full matching now (weak lock)
  double weak_lock_gated_share = 0.25;
  double lock_sigma_px = 1.0;     // the pose's projected uncertainty at the tracked features above this (px, mean): full matching now  // more than this share of tracked known features outside the gate: full matching now
  double visibility_cache_m = 1.0;  // reuse per-feature ray-cast visibility while the camera stays this close (0: cast every time)
  bool track_lines = false;       // between keyframes, follow the keyframe's matched lines by 1D edge search (off: it locks onto window rows)
  bool refine_tracked_corners = false;  // re-snap tracked known corners with cornerSubPix every frame (drifts along edges: off)
  int klt_window_px = 15;         // KLT window (pyramid levels: klt_levels)
  int klt_levels = 2;
  int grid_cell_px = 80;          // new unknown-feature corners only in cells with fewer tracks than grid_min_tracks
  int grid_min_tracks = 3;
  int detect_level = 1;           // pyramid level new unknown-feature corners are detected on between keyframes (0: full size)

  std::string Check() const;
};

// Stages of the vision front end, timed in thread CPU time (VisionFrameStats::stage_ms).
enum VisionStage : int {
  kStageGray = 0,      // BGR -> grey
  kStageCorners,       // Shi-Tomasi corners + sub-pixel refinement (+ undistortion)
  kStageSegments,      // line segments (SegmentDetector) and the refinement of the matched ones
  kStageEdges,         // Canny + edge and skyline distance transforms
  kStageChamfer,       // coarse alignment search (chamfer + skyline)
  kStageKlt,           // pyramid + pyramidal Lucas-Kanade of known and unknown tracks
  kStageVisibility,    // predicting features and ray casting the static mesh for visibility
  kStageMatch,         // point / segment association
  kStageEkf,           // pose filter updates (both passes on keyframes)
  kStageUnknown,       // unknown-feature structure filters and new tracks
  kVisionStageCount
};
const char* VisionStageName(int stage);

struct VisionFrameStats {
  int points_predicted = 0;  // known points predicted visible
  int points_used = 0, lines_used = 0, new_points_used = 0;
  int new_points_tracked = 0, new_points_converged = 0;
  int rejected = 0;          // gated or behind the camera
  Eigen::Vector2d coarse_offset_px = Eigen::Vector2d::Zero();  // the coarse pass's image shift
  double coarse_rotation_rad = 0;  // ... and turn about the principal point (acquisition_roll_search_deg)
  double detect_ms = 0;      // corner/segment detection, KLT tracking, matching
  double update_ms = 0;      // EKF updates (both passes) and unknown-feature filters
  std::array<double, kVisionStageCount> stage_ms{};  // thread CPU ms per stage (detect_ms + update_ms in wall time)
  bool keyframe = false;     // full model matching ran on this frame
  double nis = -1;           // mean normalised innovation squared of the features applied (-1: none)
  double reported_scale = 1;  // the reported covariance's scale after this frame (VisionOptions::nis_short_gain)
  bool weak_lock = false;    // ... because the tracked known features disagreed with the prediction
  int relocks = 0;           // the pose was declared lost (lost_frames) and its covariance inflated
  bool relocalized = false;  // the position search moved the filter (relocalize_extent_m)
  double reoriented_heading_deg = 0;  // the heading search turned the pose about the vertical by this (acquisition_heading_search_deg)
  bool relocalize_waiting = false;  // ... found no position the model fits well (relocalize_max_score_px): nothing applied
  bool thin_view = false;           // a keyframe predicting fewer known points than min_view_points (no relocalisation; see there)
  int relocalize_thin_outlines = 0;  // relocalisation positions not scored: under relocalize_min_outline_share of the outline here
  bool unfit = false;        // a keyframe whose chamfer alignment fitted too badly to apply anything (max_alignment_score_px)
  bool local_fit = false;    // a keyframe that fitted nowhere as a whole, matched only where its features' outline fits (local_fit_px)
  int known_tracked = 0;     // known features followed by KLT into this frame
  int misfit_weighted = 0;   // keyframe matches at half weight or less for their point's learned misfit (point_bias_weight_px)
  // Why measurements did not update the pose (counted per feature).
  int rejected_gate = 0, rejected_behind = 0, rejected_not_finite = 0;
  int rejected_tracked_jump = 0;
  int rejected_ambiguous = 0;  // keyframe lines left unmatched: their segment was nearly as near another model line's image (line_ambiguity_ratio)
  int rejected_overhang = 0;   // keyframe lines whose longest segment reached beyond their image (line_max_overhang_px)
  int rejected_structure = 0;  // keyframe corners refused: their model edges not found (VisionOptions::corners_on_edges 2)
  bool height_applied = false;  // the carried camera's height above the ground was applied (carrier_height_m)
  int klt_lost = 0;          // tracks KLT lost (status 0 or left the image)
  int landmarks_in_state = 0;  // unknown features in the pose filter's state after this frame (joint mode)
  // Unknown features that joined the state on this frame: estimate, covariance, ideal pixel.
  struct JoinedLandmark {
    Eigen::Vector3d point;
    Eigen::Matrix3d covariance;
    Eigen::Vector2d uv;
    Eigen::Vector2d px = Eigen::Vector2d::Zero();  // the same in the (distorted) frame
    int64_t id = 0;                                // track id (unknown_tracks)
    int observations = 0;                          // sightings before it joined
  };
  std::vector<JoinedLandmark> landmarks_joined;
  int unknown_dropped = 0;   // unknown features whose observation fell outside their gate
  int landmarks_refused = 0;  // converged unknown features the joining tests kept out of the state (join_bearing_drift_px, join_model_depth_tolerance)
  // Every unknown-feature track after this frame: (track id, ideal pixel on this frame).
  std::vector<std::pair<int64_t, Eigen::Vector2d>> unknown_tracks;
  // The fine pass's known-point matches (model point, detected pixel), e.g. for a PnP peer.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector2d>> point_matches;
  // The keyframe's applied known-line matches: the model segment's end points and the image
  // segment's (ideal pixels), e.g. to check them against the truth.
  struct LineMatch {
    Eigen::Vector3d a, b;
    Eigen::Vector2d image_a, image_b;
  };
  std::vector<LineMatch> line_matches;
  int features_used() const { return points_used + lines_used + new_points_used; }
};

class VisionTracker {
 public:
  // `mesh` (local frame, the static model) decides which features the predicted camera can see.
  VisionTracker(FeatureMap map, const TriangleMesh& mesh, PinholeIntrinsics intrinsics, VisionOptions options = {});
  VisionTracker(VisionTracker&&) noexcept;
  VisionTracker& operator=(VisionTracker&&) noexcept;
  ~VisionTracker();

  // Measures one frame (BGR, top row first, the intrinsics' size) and updates `ekf`, already
  // predicted to the frame time.
  VisionFrameStats Update(const uint8_t* bgr, int width, int height, PoseEkf& ekf);

  // Model features the given pose sees (visible in the image, not hidden by the mesh).
  std::vector<Eigen::Vector3d> VisiblePoints(const Rigid3d& world_from_camera) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::pose
