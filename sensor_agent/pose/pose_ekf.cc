#include "sensor_agent/pose/pose_ekf.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

constexpr double kMinDepth_m = 0.1;
constexpr size_t kMaxConsideredBiases = 256;  // per-feature biases whose sensitivities are kept (UpdatePoint's bias_id)

bool AllFinite(const auto& m) { return m.allFinite(); }

// Signed pixel distances of a, b from the image of the infinite 3D line seen from (p, q).
std::optional<Eigen::Vector2d> LineDistances(const PinholeIntrinsics& k, const Line3d& line, const Eigen::Vector2d& a,
                                             const Eigen::Vector2d& b, const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
  const Eigen::Vector3d d = line.direction.normalized();
  const Eigen::Vector3d rel = line.point - p;
  // Some of the line must lie in front of the camera: it runs towards or away from the view
  // direction, or (parallel to the image plane) its nearest point is in front.
  const Eigen::Vector3d nearest = q.conjugate() * (rel - rel.dot(d) * d);
  if (std::abs((q.conjugate() * d).z()) < 1e-6 && !(nearest.z() > kMinDepth_m)) return std::nullopt;
  const Eigen::Vector3d n = q.conjugate() * rel.cross(d);  // normal of the plane through the centre and the line
  // Image line l = K^-T n.
  const Eigen::Vector3d l(n.x() / k.fx, n.y() / k.fy, n.z() - n.x() * k.cx / k.fx - n.y() * k.cy / k.fy);
  const double norm = l.head<2>().norm();
  if (!(norm > 1e-12 * l.norm())) return std::nullopt;  // the line passes through the camera centre
  return Eigen::Vector2d((l.head<2>().dot(a) + l.z()) / norm, (l.head<2>().dot(b) + l.z()) / norm);
}

}  // namespace

std::string PoseFilterOptions::Check() const {
  auto positive = [](double x) { return std::isfinite(x) && x > 0; };
  if (!positive(accel_noise_m_s2)) return "accel_noise_m_s2 must be finite and > 0";
  if (!positive(angular_accel_noise_rad_s2)) return "angular_accel_noise_rad_s2 must be finite and > 0";
  if (!positive(gps_min_sigma_m)) return "gps_min_sigma_m must be finite and > 0";
  if (!positive(orientation_sigma_deg)) return "orientation_sigma_deg must be finite and > 0";
  if (!(std::isfinite(heading_sigma_deg) && heading_sigma_deg >= 0)) return "heading_sigma_deg must be finite and >= 0";
  if (!(std::isfinite(orientation_correlation_s) && orientation_correlation_s >= 0)) return "orientation_correlation_s must be finite and >= 0";
  if (!(std::isfinite(gyro_correlation_s) && gyro_correlation_s >= 0)) return "gyro_correlation_s must be finite and >= 0";
  if (!(std::isfinite(gps_correlation_s) && gps_correlation_s >= 0)) return "gps_correlation_s must be finite and >= 0";
  if (!(std::isfinite(gps_bias_sigma_m) && gps_bias_sigma_m >= 0)) return "gps_bias_sigma_m must be finite and >= 0";
  if (!(std::isfinite(gravity_window_s) && gravity_window_s >= 0)) return "gravity_window_s must be finite and >= 0";
  if (!positive(gravity_sigma_deg)) return "gravity_sigma_deg must be finite and > 0";
  if (!(std::isfinite(gravity_correlation_s) && gravity_correlation_s >= 0)) return "gravity_correlation_s must be finite and >= 0";
  if (!positive(gravity_tolerance_m_s2)) return "gravity_tolerance_m_s2 must be finite and > 0";
  if (!positive(gravity_max_rate_rad_s)) return "gravity_max_rate_rad_s must be finite and > 0";
  if (!positive(gyro_sigma_rad_s)) return "gyro_sigma_rad_s must be finite and > 0";
  if (!positive(gyro_bias_sigma_rad_s)) return "gyro_bias_sigma_rad_s must be finite and > 0";
  if (!(std::isfinite(gyro_bias_random_walk_rad_s_sqrt_s) && gyro_bias_random_walk_rad_s_sqrt_s >= 0)) {
    return "gyro_bias_random_walk_rad_s_sqrt_s must be finite and >= 0";
  }
  if (!(std::isfinite(gps_reanchor_s) && gps_reanchor_s >= 0)) return "gps_reanchor_s must be finite and >= 0";
  if (!(std::isfinite(gps_reanchor_sigma_m) && gps_reanchor_sigma_m >= 0) || !(std::isfinite(gps_reanchor_min_m) && gps_reanchor_min_m >= 0) ||
      !(std::isfinite(gps_reanchor_orientation_sigma_deg) && gps_reanchor_orientation_sigma_deg >= 0))
    return "gps_reanchor_sigma_m, gps_reanchor_min_m and gps_reanchor_orientation_sigma_deg must be finite and >= 0";
  if (!positive(pixel_sigma_px)) return "pixel_sigma_px must be finite and > 0";
  if (!positive(gate_chi2_3dof) || !positive(gate_chi2_2dof) || !positive(gate_chi2_1dof)) return "gate_chi2_* must be finite and > 0";
  if (!positive(max_predict_s)) return "max_predict_s must be finite and > 0";
  if (!positive(min_variance)) return "min_variance must be finite and > 0";
  return {};
}

const char* RejectionName(Rejection r) {
  switch (r) {
    case Rejection::kNone: return "accepted";
    case Rejection::kNotFinite: return "not finite";
    case Rejection::kGate: return "outside the Mahalanobis gate";
    case Rejection::kBehindCamera: return "behind the camera";
    case Rejection::kTimeNotIncreasing: return "time not increasing";
  }
  return "?";
}

PoseEkf::PoseEkf(PoseFilterOptions options) : options_(options) {}

void PoseEkf::Initialize(int64_t t_ns, const Rigid3d& world_from_camera, double position_sigma_m, double orientation_sigma_rad,
                         bool position_from_gps_fix, double heading_sigma_rad) {
  t_ns_ = t_ns;
  p_ = world_from_camera.translation;
  q_ = world_from_camera.rotation.normalized();
  v_.setZero();
  w_.setZero();
  b_.setZero();
  // Without the bias state (estimate_gyro_bias off) its variance sits at the floor and no
  // measurement couples to it, so it stays zero: the pre-issue-19 filter.
  const double bias_sigma = options_.estimate_gyro_bias ? options_.gyro_bias_sigma_rad_s : std::sqrt(options_.min_variance);
  StateVector sigma;
  sigma << Eigen::Vector3d::Constant(position_sigma_m), Eigen::Vector3d::Constant(1.0),
      Eigen::Vector3d::Constant(orientation_sigma_rad), Eigen::Vector3d::Constant(0.5), Eigen::Vector3d::Constant(bias_sigma);
  if (heading_sigma_rad > 0 && std::isfinite(heading_sigma_rad)) sigma(kRot + 2) = heading_sigma_rad;
  P_ = sigma.cwiseAbs2().asDiagonal();
  reported_scale_ = 1;
  // A position taken from a fix carries the fix's bias: error = truth - fix = -(noise + bias).
  gps_bias_sensitivity_.setZero();
  if (position_from_gps_fix) gps_bias_sensitivity_.block<3, 3>(kPos, 0) = -Eigen::Matrix3d::Identity();
  bias_ids_.clear();
  bias_sigma_px_.clear();
  bias_sensitivity_.resize(kErrorDim, 0);
  gps_bias_landmark_sensitivity_.setZero(landmarks_.size(), 3);
  bias_landmark_sensitivity_.resize(landmarks_.size(), 0);
  initialized_ = true;
}

UpdateResult PoseEkf::Predict(int64_t t_ns) {
  if (t_ns < t_ns_) return {Rejection::kTimeNotIncreasing, 0};
  double remaining = static_cast<double>(t_ns - t_ns_) * 1e-9;
  t_ns_ = t_ns;
  while (remaining > 0) {
    const double dt = std::min(remaining, options_.max_predict_s);
    remaining -= dt;
    p_ += v_ * dt;
    q_ = (SO3Exp(w_ * dt) * q_).normalized();
    // Error-state transition: dp += dv dt, dtheta += dw dt (first order in the world frame).
    StateMatrix F = StateMatrix::Identity();
    F.block<3, 3>(kPos, kVel).diagonal().setConstant(dt);
    F.block<3, 3>(kRot, kRate).diagonal().setConstant(dt);
    // White-noise-acceleration process: per axis q [dt^3/3 dt^2/2; dt^2/2 dt].
    StateMatrix Q = StateMatrix::Zero();
    const double qa = options_.accel_noise_m_s2 * options_.accel_noise_m_s2;
    const double qw = options_.angular_accel_noise_rad_s2 * options_.angular_accel_noise_rad_s2;
    for (auto [first, second, q] : {std::tuple{kPos, kVel, qa}, std::tuple{kRot, kRate, qw}}) {
      Q.block<3, 3>(first, first).diagonal().setConstant(q * dt * dt * dt / 3);
      Q.block<3, 3>(first, second).diagonal().setConstant(q * dt * dt / 2);
      Q.block<3, 3>(second, first).diagonal().setConstant(q * dt * dt / 2);
      Q.block<3, 3>(second, second).diagonal().setConstant(q * dt);
    }
    // The gyro bias: a random walk (identity transition).
    if (options_.estimate_gyro_bias) {
      const double rw = options_.gyro_bias_random_walk_rad_s_sqrt_s;
      Q.block<3, 3>(kGyroBias, kGyroBias).diagonal().setConstant(rw * rw * dt);
    }
    P_ = F * P_ * F.transpose() + Q;
    if (!landmark_ids_.empty()) cross_ = (F * cross_).eval();  // landmarks are static
    PropagateBiases(F);
    Condition();
  }
  return {};
}

template <int M>
UpdateResult PoseEkf::Correct(const Eigen::Matrix<double, M, 1>& innovation, const Eigen::Matrix<double, M, kErrorDim>& H,
                              const Eigen::Matrix<double, M, M>& R, double gate_chi2, const Eigen::Matrix<double, M, M>* gate_R,
                              const Eigen::Matrix<double, M, M>* noise_R) {
  if (!AllFinite(innovation) || !AllFinite(H) || !AllFinite(R)) return {Rejection::kNotFinite, 0};
  const Eigen::Matrix<double, kErrorDim, M> PHt = P_ * H.transpose();
  if (gate_R) {
    const Eigen::Matrix<double, M, M> gate_S = H * PHt + *gate_R;
    const Eigen::LDLT<Eigen::Matrix<double, M, M>> gate_ldlt(gate_S);
    if (gate_ldlt.info() != Eigen::Success || !(gate_ldlt.vectorD().array() > 0).all()) return {Rejection::kNotFinite, 0};
    const double gate_d2 = innovation.dot(gate_ldlt.solve(innovation));
    if (!std::isfinite(gate_d2)) return {Rejection::kNotFinite, 0};
    if (gate_d2 > gate_chi2) return {Rejection::kGate, gate_d2};
  }
  double reported_d2 = 0;  // the innovation's squared Mahalanobis distance at the gate's covariance
  const Eigen::Matrix<double, M, M> S = H * PHt + R;
  const Eigen::LDLT<Eigen::Matrix<double, M, M>> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().array() > 0).all()) return {Rejection::kNotFinite, 0};
  // S^-1 b (a scalar division for one row: GCC 12 warns falsely inside Eigen's 1x1 LDLT solve).
  auto solve = [&](const auto& b) {
    if constexpr (M == 1) {
      return (b / S(0, 0)).eval();
    } else {
      return ldlt.solve(b).eval();
    }
  };
  const double d2 = innovation.dot(solve(innovation));
  if (!std::isfinite(d2)) return {Rejection::kNotFinite, 0};
  reported_d2 = gate_R ? innovation.dot(Eigen::LDLT<Eigen::Matrix<double, M, M>>(H * PHt + *gate_R).solve(innovation)) : d2;
  if (!gate_R && d2 > gate_chi2) return {Rejection::kGate, d2};
  const Eigen::Matrix<double, kErrorDim, M> K = solve(PHt.transpose()).transpose();
  Eigen::Matrix<double, Eigen::Dynamic, M> KL(0, M);
  if (!landmark_ids_.empty()) {
    KL = solve((cross_.transpose() * H.transpose()).transpose()).transpose();
    CorrectLandmarks<M>(K, KL, S, innovation);
  }
  const StateMatrix I_KH = StateMatrix::Identity() - K * H;
  P_ = I_KH * P_ * I_KH.transpose() + K * (noise_R ? *noise_R : R) * K.transpose();  // Joseph form
  CorrectBiases<M>(K, KL, H * bias_sensitivity_, H * gps_bias_sensitivity_);
  Inject(K * innovation);
  Condition();
  return {Rejection::kNone, reported_d2};
}

void PoseEkf::Inject(const StateVector& dx) {
  p_ += dx.segment<3>(kPos);
  v_ += dx.segment<3>(kVel);
  const Eigen::Vector3d dtheta = dx.segment<3>(kRot);
  q_ = (SO3Exp(dtheta) * q_).normalized();
  w_ += dx.segment<3>(kRate);
  b_ += dx.segment<3>(kGyroBias);
  // Reset Jacobian of the world-frame orientation error: G = I - [dtheta/2]x (Solà, eq. 287).
  StateMatrix G = StateMatrix::Identity();
  G.block<3, 3>(kRot, kRot) -= 0.5 * Skew(dtheta);
  P_ = G * P_ * G.transpose();
  if (!landmark_ids_.empty()) cross_ = (G * cross_).eval();
  PropagateBiases(G);
}

void PoseEkf::PropagateBiases(const StateMatrix& transition) {
  if (options_.gps_bias_sigma_m > 0) gps_bias_sensitivity_ = (transition * gps_bias_sensitivity_).eval();
  if (bias_ids_.empty()) return;
  bias_sensitivity_ = (transition * bias_sensitivity_).eval();
}

// The error after an update with gain K is e - K (H e + noise + b_current), H e over the full
// state (pose and landmarks): every bias's sensitivity G goes to G - K H G, and the bias this
// measurement carries adds -K; the landmarks' rows alike with their gains KL.
template <int M>
void PoseEkf::CorrectBiases(const Eigen::Matrix<double, kErrorDim, M>& K, const Eigen::Matrix<double, Eigen::Dynamic, M>& KL,
                            const Eigen::Matrix<double, M, Eigen::Dynamic>& HGb, const Eigen::Matrix<double, M, 3>& HGg) {
  const bool landmarks = KL.rows() > 0 && KL.rows() == gps_bias_landmark_sensitivity_.rows();
  if (options_.gps_bias_sigma_m > 0) {
    gps_bias_sensitivity_ -= K * HGg;
    if (landmarks) gps_bias_landmark_sensitivity_ -= KL * HGg;
    if constexpr (M == 3) {
      if (applying_gps_) {  // this fix carries the bias
        gps_bias_sensitivity_ -= K;
        if (landmarks) gps_bias_landmark_sensitivity_ -= KL;
      }
    }
  }
  if (bias_ids_.empty()) return;
  bias_sensitivity_ -= K * HGb;
  if (landmarks) bias_landmark_sensitivity_ -= KL * HGb;
  if constexpr (M == 2) {
    for (const int c : current_biases_) {
      if (c < 0) continue;
      bias_sensitivity_.middleCols<2>(2 * c) -= K;
      if (landmarks) bias_landmark_sensitivity_.middleCols<2>(2 * c) -= KL;
    }
  }
}

StateMatrix PoseEkf::ConsideredBiasCovariance() const {
  StateMatrix c = StateMatrix::Zero();
  if (options_.gps_bias_sigma_m > 0) {
    c += options_.gps_bias_sigma_m * options_.gps_bias_sigma_m * gps_bias_sensitivity_ * gps_bias_sensitivity_.transpose();
  }
  for (size_t i = 0; i < bias_ids_.size(); ++i) {
    const auto g = bias_sensitivity_.middleCols<2>(2 * static_cast<Eigen::Index>(i));
    c += bias_sigma_px_[i] * bias_sigma_px_[i] * g * g.transpose();
  }
  return c;
}

template <int M>
void PoseEkf::CorrectLandmarks(const Eigen::Matrix<double, kErrorDim, M>& K, const Eigen::Matrix<double, Eigen::Dynamic, M>& KL,
                               const Eigen::Matrix<double, M, M>& S, const Eigen::Matrix<double, M, 1>& innovation) {
  cross_ -= K * S * KL.transpose();
  landmark_cov_ -= KL * S * KL.transpose();
  landmarks_ += KL * innovation;
}

void PoseEkf::InflatePose(double position_sigma_m, double orientation_sigma_rad) {
  if (!(std::isfinite(position_sigma_m) && std::isfinite(orientation_sigma_rad) && position_sigma_m >= 0 && orientation_sigma_rad >= 0)) return;
  for (int i = 0; i < 3; ++i) {
    P_(kPos + i, kPos + i) += position_sigma_m * position_sigma_m;
    P_(kRot + i, kRot + i) += orientation_sigma_rad * orientation_sigma_rad;
  }
}

void PoseEkf::MovePosition(const Eigen::Vector3d& position, double sigma_m) {
  if (!initialized_ || !position.allFinite() || !std::isfinite(sigma_m) || !(sigma_m > 0)) return;
  p_ = position;
  ForgetBlock(kPos, sigma_m);
  ++position_moves_;
}

// The three error states from `first` on start again at `sigma` each, uncorrelated with everything
// (the rest of the state, the landmarks, the consider terms' sensitivities).
void PoseEkf::ForgetBlock(int first, double sigma) {
  P_.block<3, kErrorDim>(first, 0).setZero();
  P_.block<kErrorDim, 3>(0, first).setZero();
  P_.block<3, 3>(first, first) = Eigen::Matrix3d::Identity() * (sigma * sigma);
  if (cross_.cols() > 0) cross_.block(first, 0, 3, cross_.cols()).setZero();
  gps_bias_sensitivity_.block<3, 3>(first, 0).setZero();
  if (bias_sensitivity_.cols() > 0) bias_sensitivity_.block(first, 0, 3, bias_sensitivity_.cols()).setZero();
}

void PoseEkf::MoveOrientation(const Eigen::Quaterniond& world_from_camera, double sigma_rad) {
  if (!initialized_ || !world_from_camera.coeffs().allFinite() || std::abs(world_from_camera.norm() - 1) > 1e-6 || !std::isfinite(sigma_rad) ||
      !(sigma_rad > 0)) {
    return;
  }
  q_ = world_from_camera.normalized();
  ForgetBlock(kRot, sigma_rad);
}

void PoseEkf::SetConsideredOrientation(const Eigen::Matrix3d& covariance) {
  if (!covariance.allFinite() || !covariance.isApprox(covariance.transpose(), 1e-9)) return;
  const Eigen::Matrix3d c = 0.5 * (covariance + covariance.transpose());
  if (Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(c, Eigen::EigenvaluesOnly).eigenvalues().minCoeff() < 0) return;
  considered_rot_ = c;
}

void PoseEkf::AppendLandmarkSensitivities(const Eigen::Matrix<double, 3, kErrorDim>& Jx) {
  const Eigen::Index n = gps_bias_landmark_sensitivity_.rows();
  gps_bias_landmark_sensitivity_.conservativeResize(n + 3, Eigen::NoChange);
  gps_bias_landmark_sensitivity_.bottomRows<3>() = Jx * gps_bias_sensitivity_;
  bias_landmark_sensitivity_.conservativeResize(n + 3, bias_sensitivity_.cols());
  bias_landmark_sensitivity_.bottomRows(3) = Jx * bias_sensitivity_;
}

int PoseEkf::LandmarkIndex(int64_t id) const {
  for (size_t i = 0; i < landmark_ids_.size(); ++i)
    if (landmark_ids_[i] == id) return static_cast<int>(i);
  return -1;
}

bool PoseEkf::AddLandmark(int64_t id, const Eigen::Vector3d& point_in_world, const Eigen::Matrix3d& covariance) {
  if (LandmarkIndex(id) >= 0 || !point_in_world.allFinite() || !covariance.allFinite()) return false;
  const Eigen::Matrix3d c = 0.5 * (covariance + covariance.transpose());
  if (Eigen::LLT<Eigen::Matrix3d>(c).info() != Eigen::Success) return false;
  const int n = static_cast<int>(landmark_ids_.size()) * 3;
  landmark_ids_.push_back(id);
  landmarks_.conservativeResize(n + 3);
  landmarks_.segment<3>(n) = point_in_world;
  cross_.conservativeResize(kErrorDim, n + 3);
  cross_.middleCols<3>(n).setZero();
  AppendLandmarkSensitivities(Eigen::Matrix<double, 3, kErrorDim>::Zero());  // independent of the pose and its biases
  Eigen::MatrixXd grown = Eigen::MatrixXd::Zero(n + 3, n + 3);
  grown.topLeftCorner(n, n) = landmark_cov_;
  grown.bottomRightCorner<3, 3>() = c;
  landmark_cov_ = std::move(grown);
  return true;
}

bool PoseEkf::AddLandmarkOnRay(int64_t id, const PinholeIntrinsics& k, const Eigen::Vector2d& uv, double depth_m, double depth_sigma_m,
                               double pixel_sigma_px) {
  if (LandmarkIndex(id) >= 0 || !uv.allFinite() || !(std::isfinite(depth_m) && depth_m > kMinDepth_m) ||
      !(std::isfinite(depth_sigma_m) && depth_sigma_m > 0) || !(std::isfinite(pixel_sigma_px) && pixel_sigma_px > 0)) {
    return false;
  }
  // x = p + R c, c = depth (m_x, m_y, 1), m = K^-1 uv. Under the world-frame orientation error
  // (R = Exp(dtheta) R): dx/dp = I, dx/ddtheta = -[R c]x, dx/duv = R depth diag(1/fx, 1/fy), dx/ddepth = R m.
  const Eigen::Matrix3d R = q_.toRotationMatrix();
  const Eigen::Vector3d m((uv.x() - k.cx) / k.fx, (uv.y() - k.cy) / k.fy, 1.0);
  const Eigen::Vector3d rc = R * (depth_m * m);
  const Eigen::Vector3d point = p_ + rc;
  Eigen::Matrix<double, 3, kErrorDim> Jx = Eigen::Matrix<double, 3, kErrorDim>::Zero();
  Jx.block<3, 3>(0, kPos).setIdentity();
  Jx.block<3, 3>(0, kRot) = -Skew(rc);
  Eigen::Matrix<double, 3, 2> Juv;
  Juv << R.col(0) * (depth_m / k.fx), R.col(1) * (depth_m / k.fy);
  const Eigen::Vector3d Jd = R * m;
  const Eigen::Matrix3d c = Jx * P_ * Jx.transpose() + pixel_sigma_px * pixel_sigma_px * Juv * Juv.transpose() +
                            depth_sigma_m * depth_sigma_m * Jd * Jd.transpose();
  const int n = static_cast<int>(landmark_ids_.size()) * 3;
  Eigen::MatrixXd with_others;  // 3 x 3N: covariance of the new point with the landmarks already in the state
  if (n > 0) with_others = Jx * cross_;
  landmark_ids_.push_back(id);
  landmarks_.conservativeResize(n + 3);
  landmarks_.segment<3>(n) = point;
  cross_.conservativeResize(kErrorDim, n + 3);
  cross_.middleCols<3>(n) = P_ * Jx.transpose();
  AppendLandmarkSensitivities(Jx);  // the point inherits the pose's error, biases included
  Eigen::MatrixXd grown(n + 3, n + 3);
  grown.topLeftCorner(n, n) = landmark_cov_;
  if (n > 0) {
    grown.bottomLeftCorner(3, n) = with_others;
    grown.topRightCorner(n, 3) = with_others.transpose();
  }
  grown.bottomRightCorner<3, 3>() = 0.5 * (c + c.transpose());
  landmark_cov_ = std::move(grown);
  return true;
}

Eigen::MatrixXd PoseEkf::FullCovariance() const {
  const int n = static_cast<int>(landmark_ids_.size()) * 3;
  Eigen::MatrixXd full(kErrorDim + n, kErrorDim + n);
  full.topLeftCorner<kErrorDim, kErrorDim>() = P_;
  if (n > 0) {
    full.topRightCorner(kErrorDim, n) = cross_;
    full.bottomLeftCorner(n, kErrorDim) = cross_.transpose();
    full.bottomRightCorner(n, n) = landmark_cov_;
  }
  return full;
}

void PoseEkf::RemoveLandmark(int64_t id) {
  const int i = LandmarkIndex(id);
  if (i < 0) return;
  const int n = static_cast<int>(landmark_ids_.size()) * 3, at = 3 * i, tail = n - at - 3;
  landmark_ids_.erase(landmark_ids_.begin() + i);
  Eigen::VectorXd l(n - 3);
  l << landmarks_.head(at), landmarks_.tail(tail);
  landmarks_ = std::move(l);
  Eigen::MatrixXd x(kErrorDim, n - 3);
  x << cross_.leftCols(at), cross_.rightCols(tail);
  cross_ = std::move(x);
  const auto drop_rows = [&](auto& m) {
    m.middleRows(at, tail) = m.bottomRows(tail).eval();
    m.conservativeResize(n - 3, Eigen::NoChange);
  };
  drop_rows(gps_bias_landmark_sensitivity_);
  drop_rows(bias_landmark_sensitivity_);
  Eigen::MatrixXd c(n - 3, n - 3);
  c.topLeftCorner(at, at) = landmark_cov_.topLeftCorner(at, at);
  c.topRightCorner(at, tail) = landmark_cov_.topRightCorner(at, tail);
  c.bottomLeftCorner(tail, at) = landmark_cov_.bottomLeftCorner(tail, at);
  c.bottomRightCorner(tail, tail) = landmark_cov_.bottomRightCorner(tail, tail);
  landmark_cov_ = std::move(c);
}

std::optional<std::pair<Eigen::Vector3d, Eigen::Matrix3d>> PoseEkf::Landmark(int64_t id) const {
  const int i = LandmarkIndex(id);
  if (i < 0) return std::nullopt;
  return std::make_pair(Eigen::Vector3d(landmarks_.segment<3>(3 * i)), Eigen::Matrix3d(landmark_cov_.block<3, 3>(3 * i, 3 * i)));
}

UpdateResult PoseEkf::UpdateLandmark(const PinholeIntrinsics& k, int64_t id, const Eigen::Vector2d& uv, double extra_variance_px2,
                                     PointBias bias) {
  const int i = LandmarkIndex(id);
  if (i < 0 || !uv.allFinite() || !std::isfinite(extra_variance_px2)) return {Rejection::kNotFinite, 0};
  Eigen::Matrix<double, 2, kErrorDim> Hp;
  const std::optional<Eigen::Vector2d> predicted = ProjectPoint(k, landmarks_.segment<3>(3 * i), &Hp);
  if (!predicted) return {Rejection::kBehindCamera, 0};
  const Eigen::Matrix<double, 2, 3> Hl = -Hp.block<2, 3>(0, kPos);  // d pixel / d point = - d pixel / d camera position
  const Eigen::Vector2d innovation = uv - *predicted;
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity() * (options_.pixel_sigma_px * options_.pixel_sigma_px + std::max(0.0, extra_variance_px2));
  // P H' for the pose rows and the landmark rows.
  const Eigen::Matrix<double, kErrorDim, 2> PHt = P_ * Hp.transpose() + cross_.middleCols<3>(3 * i) * Hl.transpose();
  const Eigen::Matrix<double, Eigen::Dynamic, 2> LHt = cross_.transpose() * Hp.transpose() + landmark_cov_.middleCols<3>(3 * i) * Hl.transpose();
  const Eigen::Matrix2d S = Hp * PHt + Hl * LHt.middleRows<3>(3 * i) + R;
  if (!innovation.allFinite() || !S.allFinite()) return {Rejection::kNotFinite, 0};
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().array() > 0).all()) return {Rejection::kNotFinite, 0};
  const double d2 = innovation.dot(ldlt.solve(innovation));
  if (!std::isfinite(d2)) return {Rejection::kNotFinite, 0};
  if (d2 > options_.gate_chi2_2dof) return {Rejection::kGate, d2};
  const Eigen::Matrix<double, kErrorDim, 2> K = ldlt.solve(PHt.transpose()).transpose();
  const Eigen::Matrix<double, Eigen::Dynamic, 2> KL = ldlt.solve(LHt.transpose()).transpose();
  P_ -= K * S * K.transpose();
  current_biases_ = {bias.id >= 0 && std::isfinite(bias.sigma_px) && bias.sigma_px > 0 ? BiasIndex(bias.id, bias.sigma_px) : -1, -1};
  // The sighting measures pose minus landmark: its sensitivity to the biases has both rows.
  Eigen::Matrix<double, 2, Eigen::Dynamic> HGb = Hp * bias_sensitivity_;
  if (HGb.cols() > 0) HGb += Hl * bias_landmark_sensitivity_.middleRows<3>(3 * i);
  const Eigen::Matrix<double, 2, 3> HGg = Hp * gps_bias_sensitivity_ + Hl * gps_bias_landmark_sensitivity_.middleRows<3>(3 * i);
  CorrectBiases<2>(K, KL, HGb, HGg);
  current_biases_ = {-1, -1};
  CorrectLandmarks<2>(K, KL, S, innovation);
  Inject(K * innovation);
  Condition();
  return {Rejection::kNone, d2};
}

void PoseEkf::Condition() {
  P_ = (0.5 * (P_ + P_.transpose())).eval();
  for (int i = 0; i < kErrorDim; ++i) P_(i, i) = std::max(P_(i, i), options_.min_variance);
  if (!landmark_ids_.empty()) {
    landmark_cov_ = (0.5 * (landmark_cov_ + landmark_cov_.transpose())).eval();
    for (Eigen::Index i = 0; i < landmark_cov_.rows(); ++i) landmark_cov_(i, i) = std::max(landmark_cov_(i, i), options_.min_variance);
  }
}

UpdateResult PoseEkf::UpdatePosition(const Eigen::Vector3d& position_m, const Eigen::Matrix3d& covariance) {
  Eigen::Matrix3d R = 0.5 * (covariance + covariance.transpose());
  const double floor = options_.gps_min_sigma_m * options_.gps_min_sigma_m;
  for (int i = 0; i < 3; ++i) R(i, i) = std::max(R(i, i), floor);
  Eigen::Matrix<double, 3, kErrorDim> H = Eigen::Matrix<double, 3, kErrorDim>::Zero();
  H.block<3, 3>(0, kPos).setIdentity();
  applying_gps_ = true;
  const UpdateResult r = Correct<3>(position_m - p_, H, R, options_.gate_chi2_3dof);
  applying_gps_ = false;
  return r;
}

UpdateResult PoseEkf::UpdateHeight(double z_m, double sigma_m) {
  if (!std::isfinite(z_m) || !std::isfinite(sigma_m) || !(sigma_m > 0)) return {Rejection::kNotFinite, 0};
  Eigen::Matrix<double, 1, kErrorDim> H = Eigen::Matrix<double, 1, kErrorDim>::Zero();
  H(0, kPos + 2) = 1;
  return Correct<1>(Eigen::Matrix<double, 1, 1>(z_m - p_.z()), H, Eigen::Matrix<double, 1, 1>(sigma_m * sigma_m), options_.gate_chi2_1dof);
}

UpdateResult PoseEkf::UpdateOrientation(const Eigen::Quaterniond& world_from_camera, double sigma_rad, double heading_sigma_rad) {
  if (!world_from_camera.coeffs().allFinite() || world_from_camera.norm() < 1e-6) return {Rejection::kNotFinite, 0};
  // Measured = Exp(dtheta) * q  =>  innovation = Log(measured * q^-1), world frame.
  const Eigen::Vector3d innovation = SO3Log(world_from_camera.normalized() * q_.conjugate());
  Eigen::Matrix<double, 3, kErrorDim> H = Eigen::Matrix<double, 3, kErrorDim>::Zero();
  H.block<3, 3>(0, kRot).setIdentity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity() * sigma_rad * sigma_rad;
  if (heading_sigma_rad > 0) R(2, 2) = heading_sigma_rad * heading_sigma_rad;
  return Correct<3>(innovation, H, R, options_.gate_chi2_3dof);
}

UpdateResult PoseEkf::UpdateGravity(const Eigen::Vector3d& up_in_camera, double sigma_rad) {
  if (!up_in_camera.allFinite() || !(up_in_camera.norm() > 0) || !std::isfinite(sigma_rad) || !(sigma_rad > 0)) return {Rejection::kNotFinite, 0};
  // With the true rotation Exp(dtheta) R: R' Exp(-dtheta) e_z ~ R' e_z + R' [e_z]x dtheta.
  const Eigen::Matrix3d Rt = q_.conjugate().toRotationMatrix();
  Eigen::Matrix<double, 3, kErrorDim> H = Eigen::Matrix<double, 3, kErrorDim>::Zero();
  H.block<3, 3>(0, kRot) = Rt * Skew(Eigen::Vector3d::UnitZ());
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity() * sigma_rad * sigma_rad;
  return Correct<3>(up_in_camera.normalized() - Rt * Eigen::Vector3d::UnitZ(), H, R, options_.gate_chi2_3dof);
}

UpdateResult PoseEkf::UpdateRate(const Eigen::Vector3d& rate_in_camera_rad_s, double sigma_rad_s) {
  if (!rate_in_camera_rad_s.allFinite()) return {Rejection::kNotFinite, 0};
  // The gyro measures the camera-frame rate plus its bias: z = R' w + b + noise. With the true
  // rotation Exp(dtheta) R: R' Exp(-dtheta) w ~ R' (w + [w]x dtheta), so dz/ddtheta = R' [w]x,
  // dz/dw = R', dz/db = I (issue 19: the bias is estimated against the attitude that vision and
  // the AHRS observe, instead of pinning the rate to the biased reading).
  const Eigen::Matrix3d Rt = q_.conjugate().toRotationMatrix();
  Eigen::Matrix<double, 3, kErrorDim> H = Eigen::Matrix<double, 3, kErrorDim>::Zero();
  H.block<3, 3>(0, kRot) = Rt * Skew(w_);
  H.block<3, 3>(0, kRate) = Rt;
  if (options_.estimate_gyro_bias) H.block<3, 3>(0, kGyroBias).setIdentity();
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity() * sigma_rad_s * sigma_rad_s;
  return Correct<3>(rate_in_camera_rad_s - (Rt * w_ + b_), H, R, options_.gate_chi2_3dof);
}

std::optional<Eigen::Vector2d> PoseEkf::ProjectPoint(const PinholeIntrinsics& k, const Eigen::Vector3d& point_in_world,
                                                     Eigen::Matrix<double, 2, kErrorDim>* jacobian) const {
  const Eigen::Vector3d rel = point_in_world - p_;
  const Eigen::Vector3d c = q_.conjugate() * rel;
  if (!(c.z() > kMinDepth_m) || !c.allFinite()) return std::nullopt;
  const double iz = 1.0 / c.z();
  const Eigen::Vector2d uv(k.fx * c.x() * iz + k.cx, k.fy * c.y() * iz + k.cy);
  if (jacobian) {
    Eigen::Matrix<double, 2, 3> dpi;
    dpi << k.fx * iz, 0, -k.fx * c.x() * iz * iz, 0, k.fy * iz, -k.fy * c.y() * iz * iz;
    const Eigen::Matrix3d Rt = q_.conjugate().toRotationMatrix();
    jacobian->setZero();
    jacobian->block<2, 3>(0, kPos) = -dpi * Rt;
    // c = R^T Exp(-dtheta) rel  =>  dc/ddtheta = R^T [rel]x.
    jacobian->block<2, 3>(0, kRot) = dpi * Rt * Skew(rel);
  }
  return uv;
}

int PoseEkf::BiasIndex(int64_t id, double sigma_px) {
  if (std::find(bias_ids_.begin(), bias_ids_.end(), id) == bias_ids_.end() && bias_ids_.size() >= kMaxConsideredBiases) {
    // Full: forget the bias the error depends on least (the updates since have shrunk its sensitivity).
    size_t weakest = 0;
    double least = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < bias_ids_.size(); ++i) {
      const double c = bias_sigma_px_[i] * bias_sigma_px_[i] * bias_sensitivity_.middleCols<2>(2 * static_cast<Eigen::Index>(i)).squaredNorm();
      if (c < least && std::find(current_biases_.begin(), current_biases_.end(), static_cast<int>(i)) == current_biases_.end()) least = c, weakest = i;
    }
    const Eigen::Index n = 2 * static_cast<Eigen::Index>(bias_ids_.size()), at = 2 * static_cast<Eigen::Index>(weakest);
    bias_sensitivity_.middleCols(at, n - at - 2) = bias_sensitivity_.rightCols(n - at - 2).eval();
    bias_sensitivity_.conservativeResize(Eigen::NoChange, n - 2);
    bias_landmark_sensitivity_.middleCols(at, n - at - 2) = bias_landmark_sensitivity_.rightCols(n - at - 2).eval();
    bias_landmark_sensitivity_.conservativeResize(Eigen::NoChange, n - 2);
    bias_ids_.erase(bias_ids_.begin() + static_cast<std::ptrdiff_t>(weakest));
    bias_sigma_px_.erase(bias_sigma_px_.begin() + static_cast<std::ptrdiff_t>(weakest));
    for (int& c : current_biases_) c -= c > static_cast<int>(weakest);
  }
  const auto found = std::find(bias_ids_.begin(), bias_ids_.end(), id);
  const int index = static_cast<int>(found - bias_ids_.begin());
  if (found == bias_ids_.end()) {  // a new bias: the error does not depend on it yet
    bias_ids_.push_back(id);
    bias_sigma_px_.push_back(sigma_px);
    bias_sensitivity_.conservativeResize(Eigen::NoChange, 2 * static_cast<Eigen::Index>(bias_ids_.size()));
    bias_sensitivity_.rightCols<2>().setZero();
    bias_landmark_sensitivity_.conservativeResize(landmarks_.size(), 2 * static_cast<Eigen::Index>(bias_ids_.size()));
    bias_landmark_sensitivity_.rightCols<2>().setZero();
  }
  bias_sigma_px_[index] = sigma_px;
  return index;
}

UpdateResult PoseEkf::UpdatePoint(const PinholeIntrinsics& k, const Eigen::Vector3d& point_in_world, const Eigen::Vector2d& uv,
                                  double extra_variance_px2, std::array<PointBias, 2> biases, double variance_scale, double gain_scale) {
  if (!uv.allFinite() || !point_in_world.allFinite() || !std::isfinite(extra_variance_px2) || !std::isfinite(variance_scale) ||
      !std::isfinite(gain_scale)) {
    return {Rejection::kNotFinite, 0};
  }
  Eigen::Matrix<double, 2, kErrorDim> H;
  const std::optional<Eigen::Vector2d> predicted = ProjectPoint(k, point_in_world, &H);
  if (!predicted) return {Rejection::kBehindCamera, 0};
  const double var = options_.pixel_sigma_px * options_.pixel_sigma_px + std::max(0.0, extra_variance_px2);
  current_biases_ = {-1, -1};
  for (size_t i = 0; i < biases.size(); ++i) {
    const PointBias& b = biases[i];
    if (b.id >= 0 && std::isfinite(b.sigma_px) && b.sigma_px > 0 && (i == 0 || b.id != biases[0].id)) current_biases_[i] = BiasIndex(b.id, b.sigma_px);
  }
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity() * var;
  const Eigen::Matrix2d scaled = R * std::max(1.0, variance_scale);
  const Eigen::Matrix2d for_gain = scaled * std::max(1.0, gain_scale);
  const UpdateResult r = gain_scale > 1       ? Correct<2>(uv - *predicted, H, for_gain, options_.gate_chi2_2dof, &R, &scaled)
                         : variance_scale > 1 ? Correct<2>(uv - *predicted, H, scaled, options_.gate_chi2_2dof, &R)
                                              : Correct<2>(uv - *predicted, H, R, options_.gate_chi2_2dof);
  current_biases_ = {-1, -1};
  return r;
}

std::optional<Eigen::Vector2d> PoseEkf::LineResidual(const PinholeIntrinsics& k, const Line3d& line, const Eigen::Vector2d& a,
                                                     const Eigen::Vector2d& b, Eigen::Matrix<double, 2, kErrorDim>* jacobian) const {
  const std::optional<Eigen::Vector2d> r = LineDistances(k, line, a, b, p_, q_);
  if (!r || !jacobian) return r;
  // Central differences over the six pose error components (position, world rotation vector):
  // twelve line evaluations, far below a millisecond.
  jacobian->setZero();
  constexpr double kStep = 1e-6;
  for (int i = 0; i < 6; ++i) {
    Eigen::Vector3d dp = Eigen::Vector3d::Zero(), dth = Eigen::Vector3d::Zero();
    (i < 3 ? dp : dth)(i % 3) = kStep;
    const auto plus = LineDistances(k, line, a, b, p_ + dp, SO3Exp(dth) * q_);
    const auto minus = LineDistances(k, line, a, b, p_ - dp, SO3Exp(-dth) * q_);
    if (!plus || !minus) return std::nullopt;
    jacobian->col(i < 3 ? kPos + i : kRot + i - 3) = (*plus - *minus) / (2 * kStep);
  }
  return r;
}

UpdateResult PoseEkf::UpdateLine(const PinholeIntrinsics& k, const Line3d& line, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                 double extra_variance_px2) {
  if (!a.allFinite() || !b.allFinite() || !line.point.allFinite() || !line.direction.allFinite() || line.direction.norm() < 1e-9) {
    return {Rejection::kNotFinite, 0};
  }
  Eigen::Matrix<double, 2, kErrorDim> H;
  const std::optional<Eigen::Vector2d> r = LineResidual(k, line, a, b, &H);
  if (!r) return {Rejection::kBehindCamera, 0};
  if (!std::isfinite(extra_variance_px2)) return {Rejection::kNotFinite, 0};
  const double var = options_.pixel_sigma_px * options_.pixel_sigma_px + std::max(0.0, extra_variance_px2);
  return Correct<2>(-*r, H, Eigen::Matrix2d::Identity() * var, options_.gate_chi2_2dof);
}

Matrix6d PoseEkf::PoseCovariance() const {
  Matrix6d c;
  c.topLeftCorner<3, 3>() = P_.block<3, 3>(kPos, kPos);
  c.topRightCorner<3, 3>() = P_.block<3, 3>(kPos, kRot);
  c.bottomLeftCorner<3, 3>() = P_.block<3, 3>(kRot, kPos);
  c.bottomRightCorner<3, 3>() = P_.block<3, 3>(kRot, kRot) + considered_rot_;
  if (!bias_ids_.empty() || options_.gps_bias_sigma_m > 0) {
    const StateMatrix b = ConsideredBiasCovariance();
    c.topLeftCorner<3, 3>() += b.block<3, 3>(kPos, kPos);
    c.topRightCorner<3, 3>() += b.block<3, 3>(kPos, kRot);
    c.bottomLeftCorner<3, 3>() += b.block<3, 3>(kRot, kPos);
    c.bottomRightCorner<3, 3>() += b.block<3, 3>(kRot, kRot);
  }
  return reported_scale_ * c;
}

}  // namespace ave::pose
