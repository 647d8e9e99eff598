#include "sensor_agent/sim/gps_imu.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>

#include "sensor_agent/sim/lidar_common.h"

namespace ave::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kVideoRate_hz = 30;  // MISSION part B: poses are resampled to the video rate

// Independent random streams, so naming one effect never changes another's draws.
enum Stream : uint64_t {
  kGpsNoiseStream = 1,
  kMultipathStream,
  kDropoutStream,
  kImuNoiseStream,
  kGyroDriftStream,
  kMagneticStream,
};

Eigen::Vector3d Normal3(uint64_t seed, uint64_t stream, uint64_t index) {
  std::mt19937_64 rng(internal::MixSeed(seed, stream, index));
  std::normal_distribution<double> n(0, 1);
  const double x = n(rng), y = n(rng), z = n(rng);
  return {x, y, z};
}

// SO(3) exponential and logarithm with the small-angle (Taylor) branch, as Sophus does.
Eigen::Quaterniond ExpSO3(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const double theta = std::sqrt(theta2);
  double imag_factor, real;
  if (theta < 1e-8) {
    imag_factor = 0.5 - theta2 / 48.0;
    real = 1.0 - theta2 / 8.0;
  } else {
    imag_factor = std::sin(0.5 * theta) / theta;
    real = std::cos(0.5 * theta);
  }
  Eigen::Quaterniond q(real, imag_factor * w.x(), imag_factor * w.y(), imag_factor * w.z());
  return q.normalized();
}
Eigen::Vector3d LogSO3(Eigen::Quaterniond q) {
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1;  // shortest rotation
  const double n = q.vec().norm();
  if (n < 1e-8) return 2.0 / q.w() * (1.0 - n * n / (3.0 * q.w() * q.w())) * q.vec();
  return 2.0 * std::atan2(n, q.w()) / n * q.vec();
}

int64_t ToNs(double t_s) { return static_cast<int64_t>(std::llround(t_s * 1e9)); }

// Horizontal distance from (x, y) to the nearest building's main footprint (0 inside).
double DistanceToBuildings(const scene::SyntheticCampus& campus, const Eigen::Vector2d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& b : campus.buildings) {
    const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
    const Eigen::Vector2d d = p - b.center_m;
    const Eigen::Vector2d in_b(std::abs(c * d.x() + s * d.y()) - 0.5 * b.size_m.x(), std::abs(-s * d.x() + c * d.y()) - 0.5 * b.size_m.y());
    best = std::min(best, in_b.cwiseMax(0.0).norm());
  }
  return best;
}

// ---- GPS effects: each runs only when named, counts itself ----

// gps_noise: white noise per fix, sigma_m horizontal (default 0.05, AVE §5: 2-10 cm) and
// sigma_vertical_m (default 2 sigma_m) vertical; the fix reports that covariance.
void GpsNoise(const EffectParams& params, uint64_t seed, uint64_t k, GpsFix& fix) {
  CountEvaluation(EffectKind::kGpsNoise);
  const double sh = params.Get("sigma_m", 0.05), sv = params.Get("sigma_vertical_m", 2 * sh);
  const Eigen::Vector3d n = Normal3(seed, kGpsNoiseStream, k);
  fix.position_m += Eigen::Vector3d(sh * n.x(), sh * n.y(), sv * n.z());
  fix.covariance += Eigen::Vector3d(sh * sh, sh * sh, sv * sv).asDiagonal();
}

// gps_multipath: a slowly varying bias, first-order Gauss-Markov with time constant tau_s
// (default 30 s) and stationary sigma_m (default 0.3 m in the open), multiplied by near_factor
// (default 4) within near_m (default 20 m) of a building, fading linearly out to 2 near_m. The
// receiver does not know it: the covariance is not inflated. `state` carries the process.
void GpsMultipath(const EffectParams& params, const scene::SyntheticCampus& campus, uint64_t seed, uint64_t k, double dt_s,
                  Eigen::Vector3d& state, GpsFix& fix) {
  CountEvaluation(EffectKind::kGpsMultipath);
  const double tau = std::max(1e-3, params.Get("tau_s", 30.0)), sigma = params.Get("sigma_m", 0.3);
  const double phi = k == 0 ? 0.0 : std::exp(-dt_s / tau);
  const Eigen::Vector3d n = Normal3(seed, kMultipathStream, k);
  state = phi * state + sigma * std::sqrt(std::max(0.0, 1 - phi * phi)) * Eigen::Vector3d(n.x(), n.y(), 0.5 * n.z());
  const double near = std::max(1e-3, params.Get("near_m", 20.0));
  const double d = DistanceToBuildings(campus, fix.true_position_m.head<2>());
  const double w = std::clamp(2.0 - d / near, 0.0, 1.0);
  fix.position_m += (1.0 + (params.Get("near_factor", 4.0) - 1.0) * w) * state;
}

// gps_dropout: no fix inside [start_s, start_s + outage_s) (defaults 2 s and 30 s), and each
// other fix lost with `probability` (default 0).
bool GpsDropped(const EffectParams& params, uint64_t seed, uint64_t k, double t_s) {
  CountEvaluation(EffectKind::kGpsDropout);
  const double start = params.Get("start_s", 2.0), length = params.Get("outage_s", 30.0);
  if (t_s >= start && t_s < start + length) return true;
  std::mt19937_64 rng(internal::MixSeed(seed, kDropoutStream, k));
  return std::uniform_real_distribution<double>(0, 1)(rng) < params.Get("probability", 0.0);
}

// ---- inertial effects ----

// imu_noise: white noise on gyro (gyro_sigma_rad_s, default 0.002), accelerometer
// (accel_sigma_m_s2, default 0.02), magnetometer (mag_sigma_uT, default 0.5) and the AHRS
// orientation (orientation_sigma_deg, default 1; AVE §5: 1-3°).
void ImuNoise(const EffectParams& params, uint64_t seed, uint64_t k, ImuSample& s) {
  CountEvaluation(EffectKind::kImuNoise);
  s.gyro_rad_s += params.Get("gyro_sigma_rad_s", 0.002) * Normal3(seed, kImuNoiseStream * 8 + 0, k);
  s.accel_m_s2 += params.Get("accel_sigma_m_s2", 0.02) * Normal3(seed, kImuNoiseStream * 8 + 1, k);
  s.magnetic += params.Get("mag_sigma_uT", 0.5) * Normal3(seed, kImuNoiseStream * 8 + 2, k);
  const double sigma = params.Get("orientation_sigma_deg", 1.0) * kPi / 180;
  s.orientation = (s.orientation * ExpSO3(sigma * Normal3(seed, kImuNoiseStream * 8 + 3, k))).normalized();
}

// gyro_drift: a gyro bias starting at bias_rad_s (default 0.005 rad/s per axis, random sign)
// doing a random walk of random_walk_rad_s_sqrt_s (default 2e-4); the AHRS integrates it into an
// orientation error that gravity and magnetic north pull back with time constant
// correction_tau_s (default 20 s), so the error stays bounded near bias * tau.
void GyroDrift(const EffectParams& params, uint64_t seed, uint64_t k, double dt_s, Eigen::Vector3d& bias, Eigen::Vector3d& error,
               ImuSample& s) {
  CountEvaluation(EffectKind::kGyroDrift);
  if (k == 0) {
    const Eigen::Vector3d signs = Normal3(seed, kGyroDriftStream * 8, 0);
    const double b0 = params.Get("bias_rad_s", 0.005);
    bias = Eigen::Vector3d(signs.x() < 0 ? -b0 : b0, signs.y() < 0 ? -b0 : b0, signs.z() < 0 ? -b0 : b0);
  } else {
    bias += params.Get("random_walk_rad_s_sqrt_s", 2e-4) * std::sqrt(dt_s) * Normal3(seed, kGyroDriftStream * 8 + 1, k);
    const double tau = std::max(1e-3, params.Get("correction_tau_s", 20.0));
    error = std::exp(-dt_s / tau) * error + bias * dt_s;
  }
  s.gyro_rad_s += bias;
  s.orientation = (s.orientation * ExpSO3(error)).normalized();
}

// magnetic_disturbance: steel and wiring near buildings add a field of up to strength_uT
// (default 15 µT) within radius_m (default 15 m) of a building, fading linearly with distance,
// in a direction fixed per building; the AHRS heading follows the disturbed horizontal field.
void MagneticDisturbance(const EffectParams& params, const scene::SyntheticCampus& campus, uint64_t seed, ImuSample& s,
                         const Eigen::Vector3d& position_m) {
  CountEvaluation(EffectKind::kMagneticDisturbance);
  const double radius = std::max(1e-3, params.Get("radius_m", 15.0)), strength = params.Get("strength_uT", 15.0);
  Eigen::Vector3d disturbance = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    scene::SyntheticCampus one;
    one.buildings = {campus.buildings[i]};
    const double d = DistanceToBuildings(one, position_m.head<2>());
    if (d >= radius) continue;
    const Eigen::Vector3d dir = Normal3(seed, kMagneticStream, i).normalized();
    disturbance += strength * (1 - d / radius) * dir;
  }
  const Eigen::Vector3d field = kEarthField_uT + disturbance;
  const double heading_error = std::atan2(field.x(), field.y()) - std::atan2(kEarthField_uT.x(), kEarthField_uT.y());
  s.magnetic += s.true_orientation.conjugate() * disturbance;
  // A heading error turns the estimate about world up.
  s.orientation = (Eigen::Quaterniond(Eigen::AngleAxisd(-heading_error, Eigen::Vector3d::UnitZ())) * s.orientation).normalized();
}

}  // namespace

std::string GpsImuSpec::Check() const {
  if (!std::isfinite(gps_rate_hz) || gps_rate_hz <= 0 || gps_rate_hz > 100) return "gps_rate_hz must be in (0, 100]";
  if (!std::isfinite(imu_rate_hz) || imu_rate_hz <= 0 || imu_rate_hz > 2000) return "imu_rate_hz must be in (0, 2000]";
  if (!std::isfinite(duration_s) || duration_s < 0 || duration_s > 24 * 3600) return "duration_s must be in [0, 86400]";
  return {};
}

GpsImuStreams SimulateGpsImu(const scene::SyntheticCampus& campus, const scene::CameraSpec& carrier, const GpsImuSpec& spec,
                             const EffectSet& effects, uint64_t seed) {
  GpsImuStreams out;
  out.camera_id = spec.camera_id.empty() ? carrier.id : spec.camera_id;
  out.origin = campus.origin;
  if (!spec.Check().empty()) return out;
  auto pose = [&](double t) { return scene::CameraPoseAt(campus, carrier, t); };

  // GPS: the camera centre at each fix time.
  {
    const EffectParams* noise = effects.Find(EffectKind::kGpsNoise);
    const EffectParams* multipath = effects.Find(EffectKind::kGpsMultipath);
    const EffectParams* dropout = effects.Find(EffectKind::kGpsDropout);
    const int64_t n = static_cast<int64_t>(std::floor(spec.duration_s * spec.gps_rate_hz + 1e-9)) + 1;
    const double dt = 1.0 / spec.gps_rate_hz;
    Eigen::Vector3d multipath_state = Eigen::Vector3d::Zero();
    out.gps.reserve(n);
    for (int64_t k = 0; k < n; ++k) {
      const double t = k * dt;
      GpsFix fix;
      fix.t_ns = ToNs(t);
      fix.true_position_m = pose(t).translation;
      fix.position_m = fix.true_position_m;
      fix.valid = true;
      if (noise) GpsNoise(*noise, seed, k, fix);
      if (multipath) GpsMultipath(*multipath, campus, seed, k, dt, multipath_state, fix);
      if (dropout && GpsDropped(*dropout, seed, k, t)) {
        fix.valid = false;
        fix.position_m.setConstant(std::numeric_limits<double>::quiet_NaN());
        fix.covariance.setConstant(std::numeric_limits<double>::quiet_NaN());
      }
      out.gps.push_back(fix);
    }
  }

  // IMU: rates and specific force by finite differences of the analytic trajectory. The gyro
  // sample k is the mean body rate over [t_k - dt/2, t_k + dt/2] (sample 0: [0, dt/2]; so integrating the samples
  // reproduces the true orientation change exactly); the accelerometer the second difference of
  // position over ±dt, plus gravity, in the body frame.
  {
    const EffectParams* noise = effects.Find(EffectKind::kImuNoise);
    const EffectParams* drift = effects.Find(EffectKind::kGyroDrift);
    const EffectParams* magnetic = effects.Find(EffectKind::kMagneticDisturbance);
    const int64_t n = static_cast<int64_t>(std::floor(spec.duration_s * spec.imu_rate_hz + 1e-9)) + 1;
    const double dt = 1.0 / spec.imu_rate_hz;
    Eigen::Vector3d bias = Eigen::Vector3d::Zero(), error = Eigen::Vector3d::Zero();
    out.imu.reserve(n);
    for (int64_t k = 0; k < n; ++k) {
      const double t = k * dt;
      const Rigid3d now = pose(t);
      ImuSample s;
      s.t_ns = ToNs(t);
      s.true_orientation = now.rotation;
      s.orientation = now.rotation;
      // The run starts at t = 0: the first sample's window is [0, dt/2] and its acceleration the
      // forward difference. CameraPoseAt's ping-pong path turns round at t = 0, so a window
      // reaching back before it read the 180-degree turn (~470 rad/s: integrated from t = 0, the
      // gyro was then 1.57 rad off about the camera's y axis; issue 19).
      const double t_before = std::max(0.0, t - 0.5 * dt);
      const Eigen::Quaterniond before = pose(t_before).rotation, after = pose(t + 0.5 * dt).rotation;
      s.gyro_rad_s = LogSO3(before.conjugate() * after) / (t + 0.5 * dt - t_before);
      const Eigen::Vector3d accel_world =
          k == 0 ? Eigen::Vector3d((pose(t + 2 * dt).translation - 2 * pose(t + dt).translation + now.translation) / (dt * dt))
                 : Eigen::Vector3d((pose(t + dt).translation - 2 * now.translation + pose(t - dt).translation) / (dt * dt));
      s.accel_m_s2 = now.rotation.conjugate() * (accel_world + Eigen::Vector3d(0, 0, kGravity_m_s2));
      s.magnetic = now.rotation.conjugate() * kEarthField_uT;
      if (drift) GyroDrift(*drift, seed, k, dt, bias, error, s);
      if (magnetic) MagneticDisturbance(*magnetic, campus, seed, s, now.translation);
      if (noise) ImuNoise(*noise, seed, k, s);
      out.imu.push_back(s);
    }
  }

  const int64_t n_video = static_cast<int64_t>(std::floor(spec.duration_s * kVideoRate_hz + 1e-9)) + 1;
  out.truth_at_video_rate.reserve(n_video);
  for (int64_t k = 0; k < n_video; ++k) out.truth_at_video_rate.emplace_back(ToNs(k / kVideoRate_hz), pose(k / kVideoRate_hz));
  return out;
}

absl::Status WriteGpsImu(const GpsImuStreams& streams, const std::string& out_dir) {
  if (const std::string why = internal::MakeDirs(out_dir); !why.empty()) return absl::InternalError(why);
  std::ofstream gps(out_dir + "/gps.csv"), imu(out_dir + "/imu.csv"), truth(out_dir + "/truth.csv");
  if (!gps || !imu || !truth) return absl::InternalError("cannot write gps.csv / imu.csv / truth.csv into " + out_dir);
  char line[1024];
  const Eigen::Vector3d& o = streams.origin;
  gps << "t_ns,valid,x_m,y_m,z_m,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz,true_x_m,true_y_m,true_z_m\n";
  for (const GpsFix& f : streams.gps) {
    const Eigen::Vector3d p = f.position_m + o, t = f.true_position_m + o;
    const Eigen::Matrix3d& c = f.covariance;
    std::snprintf(line, sizeof(line), "%lld,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n",
                  static_cast<long long>(f.t_ns), f.valid ? 1 : 0, p.x(), p.y(), p.z(), c(0, 0), c(0, 1), c(0, 2), c(1, 1), c(1, 2),
                  c(2, 2), t.x(), t.y(), t.z());
    gps << line;
  }
  imu << "t_ns,qw,qx,qy,qz,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,mag_x_uT,mag_y_uT,mag_z_uT,"
         "true_qw,true_qx,true_qy,true_qz\n";
  for (const ImuSample& s : streams.imu) {
    const Eigen::Quaterniond& q = s.orientation;
    const Eigen::Quaterniond& tq = s.true_orientation;
    std::snprintf(line, sizeof(line),
                  "%lld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n",
                  static_cast<long long>(s.t_ns), q.w(), q.x(), q.y(), q.z(), s.gyro_rad_s.x(), s.gyro_rad_s.y(), s.gyro_rad_s.z(),
                  s.accel_m_s2.x(), s.accel_m_s2.y(), s.accel_m_s2.z(), s.magnetic.x(), s.magnetic.y(), s.magnetic.z(), tq.w(), tq.x(),
                  tq.y(), tq.z());
    imu << line;
  }
  truth << "t_ns,x_m,y_m,z_m,qw,qx,qy,qz\n";
  for (const auto& [t_ns, pose] : streams.truth_at_video_rate) {
    const Eigen::Vector3d p = pose.translation + o;
    const Eigen::Quaterniond& q = pose.rotation;
    std::snprintf(line, sizeof(line), "%lld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", static_cast<long long>(t_ns), p.x(), p.y(),
                  p.z(), q.w(), q.x(), q.y(), q.z());
    truth << line;
  }
  gps.flush();
  imu.flush();
  truth.flush();
  if (!gps || !imu || !truth) return absl::InternalError("write failed in " + out_dir);
  return absl::OkStatus();
}

}  // namespace ave::sim
