#pragma once
// Sensor inputs of the pose filter (AVE §5): GPS fixes and inertial (AHRS) orientation samples,
// from the simulator or from a recorded log, fused in time order and resampled to the video rate
// by PoseTracker so that every frame carries a time-stamped pose and covariance (docs/POSE.md).
//
// Log format: the simulator's gps.csv / imu.csv (docs/SIMULATOR_FORMATS.md, written by
// `ave-sim gps-imu`): world coordinates (~1e6 m) with 17 significant digits; the reader
// subtracts the site origin so the filter works in the local frame. Truth columns are optional.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/statusor.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/pose/pose_ekf.h"

namespace ave::sim {
struct GpsImuStreams;
}

namespace ave::pose {

struct GpsReading {
  int64_t t_ns = 0;
  bool valid = false;                                   // false: a dropout row (no fix)
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  // camera centre, local frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // reported (m^2); floored by the filter
};

struct ImuReading {
  int64_t t_ns = 0;
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  // AHRS world_from_camera
  Eigen::Vector3d gyro_rad_s = Eigen::Vector3d::Zero();             // body (camera) frame rate
  // Specific force in the camera frame (m/s^2; +9.81 up at rest), when the log has it: the
  // filter levels itself on its mean (PoseFilterOptions::gravity_window_s).
  std::optional<Eigen::Vector3d> accel_m_s2;
};

struct SensorLog {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates of the local zero
  std::vector<GpsReading> gps;
  std::vector<ImuReading> imu;
};

// Reads DIR/gps.csv and DIR/imu.csv. Positions are made local by subtracting `origin`. Errors name
// the file, line and column ("gps.csv:12: column x_m: not a number 'abc'").
absl::StatusOr<SensorLog> ReadSensorLog(const std::string& dir, const Eigen::Vector3d& origin);
// The simulator's streams (already local).
SensorLog FromSimulation(const sim::GpsImuStreams& streams);

enum class PoseMode : uint8_t { kTruth = 0, kGpsImu = 1, kGpsImuVision = 2 };
// "truth", "gps-imu", "gps-imu-vision"; nullopt otherwise.
std::optional<PoseMode> ParsePoseMode(const std::string& text);
const char* PoseModeName(PoseMode mode);

struct PoseSample {
  int64_t t_ns = 0;
  bool valid = false;  // false until the first GPS fix and orientation arrived
  Rigid3d world_from_camera;  // local frame
  Matrix6d covariance = Matrix6d::Zero();  // position (m), world rotation vector (rad)
};

struct TrackerStats {
  int64_t gps_used = 0, gps_dropouts = 0, gps_gated = 0;
  int64_t gps_reanchored = 0;  // the position taken from a fix after gps_reanchor_s of gated fixes
  int64_t imu_used = 0, imu_gated = 0;
  int64_t gravity_used = 0, gravity_gated = 0;  // accelerometer windows applied / outside the gate
  int64_t gravity_moving = 0;                   // windows skipped: the carrier sped up or turned
  int64_t time_rejected = 0;  // repeated or backwards time stamps, and samples older than the filter
  int64_t not_finite = 0;
};

// Feeds the readings to a PoseEkf in time order up to each requested time (AVE §5: "we
// synchronise and resample all these data streams at the 30 Hz video rate"). A reading whose time
// stamp does not increase within its own stream (dt = 0, repeated, backwards) is rejected and
// counted; the state is then unchanged.
class PoseTracker {
 public:
  explicit PoseTracker(SensorLog log, PoseFilterOptions options = {});

  // Processes every reading with t <= t_ns, then predicts to t_ns. Requested times must not go
  // backwards (a backwards request returns the last sample unchanged, counted in time_rejected).
  PoseSample Advance(int64_t t_ns);
  // The current estimate (after vision updates on the filter, for example).
  PoseSample Current() const;

  PoseEkf& filter() { return ekf_; }
  const TrackerStats& stats() const { return stats_; }
  const SensorLog& log() const { return log_; }

 private:
  void Apply(const GpsReading& g);
  void Apply(const ImuReading& s);

  SensorLog log_;
  PoseEkf ekf_;
  size_t next_gps_ = 0, next_imu_ = 0;
  int64_t last_gps_ns_ = INT64_MIN, last_imu_ns_ = INT64_MIN;
  int64_t last_valid_gps_ns_ = INT64_MIN;  // the last fix applied (PoseFilterOptions::gps_correlation_s)
  int64_t gated_since_ns_ = INT64_MIN;     // the first of the fixes gated in a row (gps_reanchor_s)
  int gated_in_row_ = 0;
  std::optional<GpsReading> first_fix_;
  std::optional<ImuReading> first_orientation_;
  // The accelerometer window being summed (PoseFilterOptions::gravity_window_s).
  Eigen::Vector3d accel_sum_ = Eigen::Vector3d::Zero(), gyro_sum_ = Eigen::Vector3d::Zero();
  int accel_count_ = 0;
  int64_t accel_start_ns_ = INT64_MIN, last_gravity_ns_ = INT64_MIN;
  void Level(const ImuReading& s);
  TrackerStats stats_;
};

}  // namespace ave::pose
