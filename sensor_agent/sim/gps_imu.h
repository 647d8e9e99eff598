#pragma once
// Simulated GPS and inertial streams of a camera carrier (AVE §5: GPS 2-10 cm at 2-5 Hz with
// dropouts, orientation 1-3° at up to 150 Hz, gyro drift corrected by gravity and magnetic north),
// with the true trajectory beside them. The truth is scene::CameraPoseAt of the carrier camera, so
// "body" below is the camera frame (OpenCV: x right, y down, z forward) and positions are the
// camera centre in the campus's local ENU frame (metres, z up).
//
// Effects, each only when the EffectSet names it (effects.h): gps_noise, gps_multipath,
// gps_dropout, imu_noise, gyro_drift, magnetic_disturbance. With no effects, every GPS fix equals
// the true position exactly and every IMU orientation the true orientation. Parameters are listed
// in docs/SIMULATOR_FORMATS.md.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include "absl/status/status.h"

#include "model_store/geometry/rigid3.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/sim/effects.h"

namespace ave::sim {

struct GpsImuSpec {
  std::string camera_id;     // the carrier camera (CameraSpec::id); informational here
  double gps_rate_hz = 5;    // fixes per second, > 0
  double imu_rate_hz = 150;  // samples per second, > 0
  double duration_s = 10;    // >= 0; 0 gives one sample of each stream at t = 0
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Standard gravity (m/s²), ENU: the accelerometer at rest reads +kGravity along world up.
inline constexpr double kGravity_m_s2 = 9.80665;
// Earth's field in the local ENU frame (microtesla): north and down, ~60° inclination.
inline const Eigen::Vector3d kEarthField_uT(0.0, 22.0, -42.0);

struct GpsFix {
  int64_t t_ns = 0;                                        // since the scenario start
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();    // measured, local ENU; meaningless when !valid
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();    // reported 1-sigma² (m²); zero with no GPS effects
  bool valid = false;  // false inside a dropout: position_m and covariance are then NaN
  Eigen::Vector3d true_position_m = Eigen::Vector3d::Zero();  // camera centre, local ENU
};

struct ImuSample {
  int64_t t_ns = 0;
  // Measured world_from_body orientation (an AHRS output: gyro integrated, corrected by gravity
  // and the magnetometer); with gyro_drift / magnetic_disturbance / imu_noise it deviates.
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d gyro_rad_s = Eigen::Vector3d::Zero();   // angular rate in the body frame
  Eigen::Vector3d accel_m_s2 = Eigen::Vector3d::Zero();   // specific force in the body frame (gravity included)
  Eigen::Vector3d magnetic = Eigen::Vector3d::Zero();     // field in the body frame, microtesla
  Eigen::Quaterniond true_orientation = Eigen::Quaterniond::Identity();  // world_from_body
};

struct GpsImuStreams {
  std::string camera_id;                               // the carrier (GpsImuSpec::camera_id)
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();    // world coordinates of the local zero (campus.origin)
  std::vector<GpsFix> gps;
  std::vector<ImuSample> imu;
  // True world_from_camera (local frame) at 30 Hz, the video rate poses are resampled to.
  std::vector<std::pair<int64_t, Rigid3d>> truth_at_video_rate;
};

// Deterministic for (campus, carrier, spec, effects, seed). An unusable spec (Check() non-empty)
// gives empty streams.
GpsImuStreams SimulateGpsImu(const scene::SyntheticCampus& campus, const scene::CameraSpec& carrier, const GpsImuSpec& spec,
                             const EffectSet& effects, uint64_t seed);

// Writes gps.csv, imu.csv and truth.csv into `out_dir` (created if missing); formats in
// docs/SIMULATOR_FORMATS.md. Positions are written in world coordinates (origin + local) with 17
// significant digits, so they read back exactly even at ~1e6 m.
absl::Status WriteGpsImu(const GpsImuStreams& streams, const std::string& out_dir);

}  // namespace ave::sim
