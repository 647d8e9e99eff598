#pragma once
// The camera pose filter of AVE §5 / §5.1 (issue 5): an error-state EKF over position, velocity,
// orientation and angular velocity of the camera and the gyro's bias (docs/POSE.md).
//
// Nominal state (local ENU frame of the site, metres; the caller subtracts the site origin so the
// filter never sees ~1e6 m coordinates): position p, velocity v, orientation q = world_from_camera
// rotation (Hamilton, unit), angular velocity w (world frame, rad/s), gyro bias b (camera frame,
// rad/s; issue 19).
// Error state (15): [dp, dv, dtheta, dw, db]. Orientation is ERROR-STATE on the manifold: the true
// rotation is Exp(dtheta) * q with dtheta a world-frame rotation vector, estimated in the filter and
// folded into q after every update (then reset to zero with the reset Jacobian). The covariance's
// orientation block is therefore in radians about the world axes, as the wire Pose expects.
//
// Process model: constant velocity and constant angular velocity driven by white acceleration /
// angular acceleration noise; the gyro bias is a random walk. Measurement updates: GPS position,
// AHRS orientation, gyro rate (R' w + b + noise), and vision pixels (point features) and line
// distances (line features), each Mahalanobis-gated with a reason; updates in Joseph form; covariance symmetrised and its diagonal floored.
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"

namespace ave::pose {

// Error-state block offsets and dimension.
inline constexpr int kPos = 0, kVel = 3, kRot = 6, kRate = 9, kGyroBias = 12, kErrorDim = 15;

using StateMatrix = Eigen::Matrix<double, kErrorDim, kErrorDim>;
using StateVector = Eigen::Matrix<double, kErrorDim, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

struct PoseFilterOptions {
  // White acceleration PSD sqrt (m/s^2/sqrt(Hz)). Issue 19: 1.0 made the vision-locked filter
  // overconfident (NEES in band 60 %, all misses above the band): a walker's gait bobs and sways the
  // camera by more; 3.0 gives 82 % in band and a lower p95 (docs/BENCHMARKS.md, Pose).
  double accel_noise_m_s2 = 3.0;
  double angular_accel_noise_rad_s2 = 1.0;  // white angular acceleration (rad/s^2/sqrt(Hz))
  double gps_min_sigma_m = 0.3;         // floor of the GPS sigma: multipath is not in the reported covariance
  // The GPS error (multipath: a slowly varying offset, larger near buildings; the simulator's
  // gps_multipath is Gauss-Markov with a 30 s time constant) is correlated over about this long,
  // not white: a fix dt after the last applied one counts as dt / gps_correlation_s of an
  // independent one (sigma inflated by sqrt(correlation / dt)), as for the AHRS below. Issue 19,
  // session pose19e: white 5 Hz fixes average the multipath down to a position sigma of ~0.1 m
  // while it stays 0.3-0.6 m off (position out of the NEES band at 1.5-2.3 s). Off (0: white) by
  // default: 30 s lifts the vision row's NEES (88.7 % in band against 87.7 %) but the weaker GPS
  // makes the GPS + inertial pose worse (17.9 -> 23.5 px median) and the joint mode's too
  // (0.51 -> 0.53 px; docs/BENCHMARKS.md, "NEES, session pose19e").
  double gps_correlation_s = 0.0;
  // The GPS fixes' multipath as a persisting bias (issue 19 evening; docs/POSE.md): every fix
  // carries the same offset of this sigma per axis, which no number of fixes averages away. A Schmidt
  // consider term like the known corners' (UpdatePoint's biases): the filter keeps its error state's
  // sensitivity to that offset through every update, prediction and reset, and the reported
  // PoseCovariance() adds sigma^2 G G'. Gains, gates and the estimate are unchanged. 0: off.
  // 0.5 m (a receiver among buildings; the simulator's multipath is 0.3 m in the open, up to 1.2 m
  // beside a wall): the GPS + inertial row's NEES in band 54 -> 63 %, the vision rows unchanged to
  // slightly better (mean NEES 7.1 -> 6.9; docs/BENCHMARKS.md, "Issue 19, evening").
  double gps_bias_sigma_m = 0.5;
  // GPS re-anchoring (issue 19, twenty-first session): when every fix for this long (and at least
  // three) fell outside the gate, the filter is the one that is wrong, not the receiver: a vision
  // lock on the wrong façades reports a 0.1 m sigma while metres off, and then gates out every fix
  // that could bring it back (the campus walk started at 32 s, as the GPS returns: 6 s and 29 fixes
  // gated while 6-15 m off, until vision declared itself lost). The next gated fix then becomes the
  // position (PoseEkf::MovePosition, at the fix's sigma and gps_bias_sigma_m in quadrature), and
  // the measurements that follow, vision's relocalisation included, start from there. Counted
  // (TrackerStats::gps_reanchored). 0: off.
  double gps_reanchor_s = 1.0;
  double gps_reanchor_sigma_m = 3.0;  // ... the position's sigma then, at least (multipath beside walls reaches metres)
  // ... counting only fixes this far from the filter's position: multipath beside a wall puts
  // fixes 1.5-3.7 m off a right pose (the walk at 80-86 s: 1.6 m, gated; re-anchoring there made the
  // walk's p95 2.4 -> 4.9 px), so a disagreement is the filter's only beyond what it can explain.
  double gps_reanchor_min_m = 5.0;
  // ... and the orientation, which the wrong lock pulled too (the 32 s start: roll 2.0, yaw 1.7 deg
  // off), gets this much more sigma, as vision's own loss adds lost_orientation_sigma_deg: the AHRS
  // takes the tilt back before vision searches. At 1 or 2 deg the 32 s start's search finds the
  // camera (to 0.1 m); at 0, 3 or 5 deg it does not.
  double gps_reanchor_orientation_sigma_deg = 1.0;
  double orientation_sigma_deg = 2.0;   // AHRS orientation sigma (AVE §5: 1-3°); its tilt's when heading_sigma_deg is set
  // The AHRS heading's sigma (about the world's vertical), apart from its tilt's (issue 19,
  // eighteenth session). A magnetometer's heading beside steel and wiring is off by tens of
  // degrees (the campus walk: up to 22 deg with its field 15 uT disturbed), where the tilt rests
  // on gravity; at 2 deg the filter reported 2.2 deg while 20 deg off, and vision's acquisition
  // could not know to look further. 0: orientation_sigma_deg.
  double heading_sigma_deg = 10.0;
  // The AHRS error (gyro drift, magnetic disturbance) is correlated over about this long, not
  // white: readings closer together than this are not independent, so each is weighted as
  // dt / orientation_correlation_s of one (sigma inflated by sqrt(correlation / dt)). 0: white.
  // Without it, 150 readings a second make the filter ~12x overconfident in its orientation.
  // 20 s since issue 19's sixteenth session (1 s before): an AHRS's drift is pulled back by
  // gravity and north over tens of seconds (the simulator's gyro_drift: 20 s), and a magnetic
  // disturbance lasts as long as the building beside it. At 1 s the AHRS dragged a pose whose
  // vision had nothing to see to its own error within seconds (campus backpack, 59-65 s: 6 deg
  // of yaw and roll), and 2 of 3 draws of the 75 s walk then relocked 20 px off; at 20 s the pose
  // drifts 1.5 deg and relocks at once (docs/POSE.md, "The whole walk").
  double orientation_correlation_s = 20.0;
  // Gravity from the accelerometer (issue 19, eighteenth session): the mean specific force over a
  // window of gravity_window_s is the world's up in the camera frame when the carrier neither
  // speeds up nor turns (its magnitude within gravity_tolerance_m_s2 of 9.81, the mean gyro rate
  // under gravity_max_rate_rad_s), as an AHRS levels itself. It is applied with
  // gravity_sigma_deg, its error correlated over gravity_correlation_s (gait, an accelerometer
  // bias) like the AHRS's. The simulated AHRS's tilt drifts 5-12 deg within a minute on the campus
  // walk (gyro_drift); the accelerometer's does not. 0 window: off.
  double gravity_window_s = 0.5;
  double gravity_sigma_deg = 1.0;
  double gravity_correlation_s = 5.0;
  double gravity_tolerance_m_s2 = 0.3;
  double gravity_max_rate_rad_s = 0.3;
  // White gyro rate noise (rad/s; the simulator's imu_noise is 0.002, 0.02 kept from before issue
  // 19). The bias is a state of its own when estimate_gyro_bias is on (below), not noise.
  double gyro_sigma_rad_s = 0.02;
  // Issue 19: the gyro bias b is in the state. Initial sigma per axis: a consumer MEMS gyro's
  // turn-on bias is +-0.5 deg/s (~0.01 rad/s; the simulator's gyro_drift draws +-0.005).
  double gyro_bias_sigma_rad_s = 0.01;
  // Random walk of the bias (rad/s/sqrt(s)); the simulator's gyro_drift default is 2e-4.
  double gyro_bias_random_walk_rad_s_sqrt_s = 2e-4;
  // Before issue 19's bias state the bias was taken as noise correlated over this long (each
  // reading weighted as dt / gyro_correlation_s of an independent one). It made the pose worse
  // (0.70 px, NEES 60 %; the camera does not even turn on that run, docs/POSE.md); a knob, 0 = white.
  double gyro_correlation_s = 0.0;
  // Estimate the bias (3 random-walk states, coupled to the attitude through the gyro updates).
  // On since issue 19's fifteenth session. It was off: on the campus backpack run it once made the
  // vision-locked pose worse (0.79 px against 0.517), while the vision measurements still carried
  // biases that a drifting prior happened to counter. Without it the simulator's turn-on bias
  // (+-0.005 rad/s per axis, its sign drawn per run) moved the pitch by about +-1 mrad and the
  // height with it, in two groups of draws by the sign of the bias about the camera's x axis: the
  // "two groups" of the fourteenth session's height errors. With it, over 13 draws the known-feature
  // row goes 0.446 -> 0.39 px median (docs/POSE.md, "The gyro's bias decides the pitch").
  bool estimate_gyro_bias = true;
  // Vision point / line-distance sigma. 1.2 since issue 19's fifteenth session (1.5 before): with
  // the gyro's bias estimated the innovations' white part is smaller, and at 1.5 the pose was
  // over-covered (13 draws pooled NEES in band 89.2 %, 8.7 % below; 1.2: 91.0 %, 4.8 % below).
  double pixel_sigma_px = 1.2;
  double gate_chi2_3dof = 25.0;         // GPS / orientation gate (3 dof); chi2(3) p=1e-5 is 25.9
  double gate_chi2_2dof = 16.0;         // vision gate per feature (2 dof); chi2(2) p=3e-4
  double gate_chi2_1dof = 15.1;         // height gate (1 dof); chi2(1) p=1e-4
  double max_predict_s = 5.0;           // longer gaps are predicted in steps of this
  double min_variance = 1e-12;          // covariance diagonal floor

  std::string Check() const;  // empty when usable, else names the field
};

// Why a measurement did not change the state.
enum class Rejection : uint8_t { kNone = 0, kNotFinite, kGate, kBehindCamera, kTimeNotIncreasing };
const char* RejectionName(Rejection r);

struct UpdateResult {
  Rejection rejection = Rejection::kNone;
  double mahalanobis_sq = 0;  // innovation' S^-1 innovation (0 when not computed)
  bool accepted() const { return rejection == Rejection::kNone; }
};

// One 3D line of the static model: all points `point + s * direction` (local frame; direction
// unit). An observed segment is any part of it (AVE §5.1).
struct Line3d {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
};

// A persisting error of a pixel measurement (PoseEkf::UpdatePoint; issue 19, session pose19e): a 2D
// pixel offset of sigma_px per axis, the same in every measurement that names the same id (>= 0).
struct PointBias {
  int64_t id = -1;
  double sigma_px = 0;
};

class PoseEkf {
 public:
  explicit PoseEkf(PoseFilterOptions options = {});

  // Starts the filter at a pose with a diagonal 1-sigma: position (m), orientation (rad); velocity
  // and rate start at zero with sigma 1 m/s and 0.5 rad/s, the gyro bias at zero with
  // options().gyro_bias_sigma_rad_s.
  // `position_from_gps_fix`: the position is a GPS fix, so its error carries the fixes' persisting
  // bias (gps_bias_sigma_m).
  // heading_sigma_rad > 0: the orientation's sigma about the world's vertical (its z), when it
  // differs from the tilt's (an AHRS's magnetic heading); otherwise orientation_sigma_rad.
  void Initialize(int64_t t_ns, const Rigid3d& world_from_camera, double position_sigma_m, double orientation_sigma_rad,
                  bool position_from_gps_fix = false, double heading_sigma_rad = 0);
  bool initialized() const { return initialized_; }
  int64_t time_ns() const { return t_ns_; }
  // How many times MovePosition replaced the position: a user of the filter that sees the count
  // change under it (vision, after a GPS re-anchor) knows its picture of where the camera is went.
  int64_t position_moves() const { return position_moves_; }

  // Moves the state to t_ns (constant-velocity model). Rejected (state unchanged) when t_ns is
  // before the filter's time; dt = 0 is a no-op.
  UpdateResult Predict(int64_t t_ns);

  // Measurements at the filter's current time (call Predict first).
  UpdateResult UpdatePosition(const Eigen::Vector3d& position_m, const Eigen::Matrix3d& covariance);
  // heading_sigma_rad > 0: its sigma about the world's vertical (world z), when it differs from
  // the tilt's sigma_rad (an AHRS's magnetic heading against its gravity-levelled tilt).
  UpdateResult UpdateOrientation(const Eigen::Quaterniond& world_from_camera, double sigma_rad, double heading_sigma_rad = 0);
  // The world's up as the camera sees it (unit, camera frame; from the accelerometer's mean
  // specific force): z = R' e_z, sigma_rad per axis, gated at gate_chi2_3dof.
  UpdateResult UpdateGravity(const Eigen::Vector3d& up_in_camera, double sigma_rad);
  UpdateResult UpdateRate(const Eigen::Vector3d& rate_in_camera_rad_s, double sigma_rad_s);
  // The camera centre's height (local z, m) with its sigma: a carried camera's height above the
  // static model's ground (issue 19, eighth session; VisionOptions::carrier_height_m). Gated at
  // chi2(1) gate_chi2_1dof.
  UpdateResult UpdateHeight(double z_m, double sigma_m);
  // A known (or estimated) 3D point seen at pixel `uv`; `extra_variance_px2` adds the projected
  // uncertainty of an estimated point.
  //
  //
  // `biases` (issue 19, session pose19e): errors of this pixel that persist, each a 2D pixel offset
  // of sigma_px per axis, the same in every measurement that names the same id (id >= 0; -1:
  // none): a corner found off its model point the same way at every keyframe and along its track,
  // or an association error every feature of a frame shares. The filter's gain, gate, own
  // covariance and estimate are unchanged, but it keeps the sensitivity of its error state to each
  // such bias (Schmidt consider analysis: error = e + sum_id G_id b_id, G propagated by every
  // prediction, update and reset; the bias a measurement carries adds -K) and PoseCovariance()
  // reports P + sum_id sigma_id^2 G_id G_id', the covariance the filter's error has when such
  // errors are not independent from sighting to sighting. See ConsideredBiasCovariance().
  // `variance_scale` (>= 1; issue 19, ninth session): a robust weight, the pixel variance scaled
  // for the update only; the gate tests the innovation at the unscaled variance, so a down-weighted
  // match is refused exactly when an unweighted one would be.
  // `gain_scale` (>= 1; issue 19, fifteenth session): a weight on the gain alone. The gain is
  // computed at the (scaled) variance times gain_scale, but the covariance is updated (Joseph
  // form, valid for any gain) at the variance without it: the match is believed less, and the
  // filter's covariance says what such a gain leaves, not that the pixel is noisier. For an error
  // that persists (a point's learned misfit), whose size is a consider bias's, not white noise.
  UpdateResult UpdatePoint(const PinholeIntrinsics& k, const Eigen::Vector3d& point_in_world, const Eigen::Vector2d& uv,
                           double extra_variance_px2 = 0, std::array<PointBias, 2> biases = {}, double variance_scale = 1, double gain_scale = 1);
  // A 3D line seen as the image segment (a, b): residual = signed pixel distances of a and b from
  // the projected infinite line.
  UpdateResult UpdateLine(const PinholeIntrinsics& k, const Line3d& line, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                          double extra_variance_px2 = 0);

  // Adds (sigma)² to the position and orientation variances: the caller's evidence says the
  // filter is lost (e.g. vision has fitted badly for a while), so the next measurements may pull
  // it back instead of being gated. Negative or non-finite sigmas are ignored.
  void InflatePose(double position_sigma_m, double orientation_sigma_rad);
  // Relocalisation (issue 19, sixth session): the caller found the camera elsewhere (vision's
  // hypothesis search). The position becomes `position` with sigma_m per axis and no correlation
  // with the rest of the state (velocity, orientation, landmarks and the consider terms keep theirs).
  // Non-finite inputs or a sigma <= 0 change nothing.
  void MovePosition(const Eigen::Vector3d& position, double sigma_m);
  // Reorientation (issue 19, eighteenth session): the caller found the camera turned from the
  // filter's orientation (vision's acquisition: the vertical vanishing point, a heading search).
  // The orientation becomes `world_from_camera` with sigma_rad about each world axis and no
  // correlation with the rest of the state (the consider terms' orientation rows are cut too).
  // Non-finite inputs, a non-unit quaternion or a sigma <= 0 change nothing.
  void MoveOrientation(const Eigen::Quaterniond& world_from_camera, double sigma_rad);

  // Consider covariance of the orientation (world rotation vector, rad²; issue 19, docs/POSE.md
  // "NEES by cause"): an error every measurement of the pose shares and that no update can remove,
  // i.e. the known features' persisting detection bias. It is added to the *reported*
  // PoseCovariance() only: the filter's own covariance, gains and gates are unchanged, so is the
  // estimate (a Schmidt "consider" term for a bias the state cannot observe). The caller (vision)
  // sets it per frame; zero by default. Ignored unless finite, symmetric, positive semi-definite.
  void SetConsideredOrientation(const Eigen::Matrix3d& covariance);
  // Scale of the *reported* PoseCovariance() (>= 1; 1 by default): the caller's evidence that the
  // filter's own covariance is too small for now (VisionOptions::nis_short_gain: the recent
  // innovations are larger than usual). Gains, gates and the estimate are unchanged. Ignored unless
  // finite and >= 1.
  void SetReportedScale(double scale) {
    if (std::isfinite(scale) && scale >= 1) reported_scale_ = scale;
  }
  double reported_scale() const { return reported_scale_; }
  // The error state's covariance due to the per-feature biases of UpdatePoint (bias_id >= 0):
  // sum_id sigma_id^2 G_id G_id' (15 x 15; zero when none). Already included in PoseCovariance().
  StateMatrix ConsideredBiasCovariance() const;
  int considered_bias_count() const { return static_cast<int>(bias_ids_.size()); }

  // Estimated 3D points in the state (issue 19: "new features done right"): a point joins with its
  // own estimate and covariance, and from then on every update keeps its cross-covariances with
  // the pose, so its observations correct pose and point jointly (SLAM-style EKF; docs/POSE.md).
  // `id` is the caller's; returns false (nothing added) for a duplicate id or a covariance that is
  // not finite and positive definite.
  // Only for a point estimated independently of this filter's pose (it joins uncorrelated); a point
  // computed from the filter's own pose must use AddLandmarkOnRay, which keeps the cross terms.
  bool AddLandmark(int64_t id, const Eigen::Vector3d& point_in_world, const Eigen::Matrix3d& covariance);
  // A point initialised from the current pose (issue 19): seen at ideal pixel `uv` (sigma
  // `pixel_sigma_px`) at depth `depth_m` (camera z, sigma `depth_sigma_m`, estimated from the relative
  // motion and taken as independent of the pose). Its estimate p + R (K^-1 uv) depth is a function
  // of the pose estimate, so it joins with the pose's covariance propagated through that function
  // and with the cross-covariances J P (pose) and J P_pl (other landmarks); without them the pose
  // would learn from the point what the point learnt from the pose (overconfident, biased).
  bool AddLandmarkOnRay(int64_t id, const PinholeIntrinsics& k, const Eigen::Vector2d& uv, double depth_m, double depth_sigma_m,
                        double pixel_sigma_px);
  void RemoveLandmark(int64_t id);  // marginalises it out (no-op for an unknown id)
  bool HasLandmark(int64_t id) const { return LandmarkIndex(id) >= 0; }
  int landmark_count() const { return static_cast<int>(landmark_ids_.size()); }
  // Estimate and covariance of a landmark; nullopt for an unknown id.
  std::optional<std::pair<Eigen::Vector3d, Eigen::Matrix3d>> Landmark(int64_t id) const;
  // A landmark seen at pixel `uv`: updates pose and every landmark (2x(15+3N) Jacobian).
  // `extra_variance_px2` adds to the pixel noise (e.g. a KLT track whose error persists).
  // `bias`: a persisting error of this landmark's sightings (a KLT track's offset repeats), as
  // UpdatePoint's biases; the sensitivities are kept for the pose and the landmarks alike.
  UpdateResult UpdateLandmark(const PinholeIntrinsics& k, int64_t id, const Eigen::Vector2d& uv, double extra_variance_px2 = 0,
                              PointBias bias = {});
  // Covariance of the full state [error state (15: pose, rates, gyro bias), landmarks (3N)] (for tests and NEES).
  Eigen::MatrixXd FullCovariance() const;

  Rigid3d world_from_camera() const { return Rigid3d(q_, p_); }
  const Eigen::Vector3d& velocity() const { return v_; }
  const Eigen::Vector3d& angular_velocity() const { return w_; }
  const Eigen::Vector3d& gyro_bias() const { return b_; }  // camera frame, rad/s
  const StateMatrix& covariance() const { return P_; }
  // (position, rotation-vector error) block, row-major order of the wire Pose.
  Matrix6d PoseCovariance() const;
  const PoseFilterOptions& options() const { return options_; }

  // Predicted pixel of a world point and its 2x15 Jacobian (exposed for tests); nullopt behind the camera.
  std::optional<Eigen::Vector2d> ProjectPoint(const PinholeIntrinsics& k, const Eigen::Vector3d& point_in_world,
                                              Eigen::Matrix<double, 2, kErrorDim>* jacobian = nullptr) const;
  // Signed distances of a, b from the projected line (pixels); nullopt when the line does not
  // project (behind the camera or through its centre).
  std::optional<Eigen::Vector2d> LineResidual(const PinholeIntrinsics& k, const Line3d& line, const Eigen::Vector2d& a,
                                              const Eigen::Vector2d& b, Eigen::Matrix<double, 2, kErrorDim>* jacobian = nullptr) const;

 private:
  template <int M>
  // `gate_R`: the measurement covariance the gate tests with (nullptr: R). `noise_R`: the one the
  // covariance is updated with (nullptr: R, the one the gain is computed with).
  UpdateResult Correct(const Eigen::Matrix<double, M, 1>& innovation, const Eigen::Matrix<double, M, kErrorDim>& H,
                       const Eigen::Matrix<double, M, M>& R, double gate_chi2, const Eigen::Matrix<double, M, M>* gate_R = nullptr,
                       const Eigen::Matrix<double, M, M>* noise_R = nullptr);
  void Inject(const StateVector& dx);
  void Condition();
  int LandmarkIndex(int64_t id) const;
  // The landmark part of a correction with gains K (error state, 15xM) and KL (landmarks, 3NxM) and
  // innovation covariance S: P_pl -= K S KL', P_ll -= KL S KL', landmarks += KL innovation.
  template <int M>
  void CorrectLandmarks(const Eigen::Matrix<double, kErrorDim, M>& K, const Eigen::Matrix<double, Eigen::Dynamic, M>& KL,
                        const Eigen::Matrix<double, M, M>& S, const Eigen::Matrix<double, M, 1>& innovation);

  PoseFilterOptions options_;
  bool initialized_ = false;
  int64_t t_ns_ = 0;
  int64_t position_moves_ = 0;
  Eigen::Vector3d p_ = Eigen::Vector3d::Zero(), v_ = Eigen::Vector3d::Zero(), w_ = Eigen::Vector3d::Zero(), b_ = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  StateMatrix P_ = StateMatrix::Identity();
  // Landmarks: ids, stacked positions (3N), pose-landmark cross-covariance (15 x 3N) and landmark
  // covariance (3N x 3N). Empty unless AddLandmark was called: the pose-only filter pays nothing.
  std::vector<int64_t> landmark_ids_;
  Eigen::VectorXd landmarks_;
  Eigen::MatrixXd cross_, landmark_cov_;
  Eigen::Matrix3d considered_rot_ = Eigen::Matrix3d::Zero();  // SetConsideredOrientation
  double reported_scale_ = 1;  // SetReportedScale
  // Per-feature persisting biases (UpdatePoint's bias_id): ids, their sigmas (px) and the error
  // state's sensitivity to each, two columns per bias (u, v); empty unless used. The landmarks'
  // rows are kept apart (below); the reported covariance reads the pose's.
  void PropagateBiases(const StateMatrix& transition);  // G = transition * G
  void ForgetBlock(int first, double sigma);            // MovePosition / MoveOrientation
  // `KL`: the landmarks' gains (0 rows without landmarks); `HGb`, `HGg`: the measurement's
  // sensitivity to the per-feature and GPS biases before this update (H times the full state's
  // sensitivities, landmark rows included).
  template <int M>
  void CorrectBiases(const Eigen::Matrix<double, kErrorDim, M>& K, const Eigen::Matrix<double, Eigen::Dynamic, M>& KL,
                     const Eigen::Matrix<double, M, Eigen::Dynamic>& HGb, const Eigen::Matrix<double, M, 3>& HGg);
  Eigen::Matrix<double, kErrorDim, 3> gps_bias_sensitivity_ = Eigen::Matrix<double, kErrorDim, 3>::Zero();  // gps_bias_sigma_m
  bool applying_gps_ = false;  // the update in progress is a fix (UpdatePosition)
  std::vector<int64_t> bias_ids_;
  std::vector<double> bias_sigma_px_;
  Eigen::Matrix<double, kErrorDim, Eigen::Dynamic> bias_sensitivity_;
  std::array<int, 2> current_biases_ = {-1, -1};  // column pairs of the biases the point update in progress carries (-1: none)
  int BiasIndex(int64_t id, double sigma_px);  // the column pair of bias `id`, added (zero sensitivity) when new
  // The landmarks' rows of the same sensitivities (3N x 3 and 3N x 2B; issue 19, twelfth session).
  // A landmark placed from the pose (AddLandmarkOnRay) carries the pose's error, biases included:
  // its rows start as J G. Its sightings then measure pose minus landmark, in which that shared
  // part cancels, so they cannot shrink the pose's bias covariance; without these rows they did
  // (the joint mode's pose under-covered 2-3 s after its first landmarks joined, mean NEES 14).
  Eigen::Matrix<double, Eigen::Dynamic, 3> gps_bias_landmark_sensitivity_;
  Eigen::MatrixXd bias_landmark_sensitivity_;
  void AppendLandmarkSensitivities(const Eigen::Matrix<double, 3, kErrorDim>& Jx);  // a new landmark's rows: Jx G
};

}  // namespace ave::pose
