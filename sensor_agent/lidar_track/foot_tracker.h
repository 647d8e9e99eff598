#pragma once
// Multi-target tracking of foot positions on the ground (i4D §3.2): per sweep, data assignment,
// Kalman correction and Kalman prediction. Constant-velocity state [x, y, vx, vy] per track;
// assignment by the optimal solver (assignment.h) on the negative log-likelihood d^2 + ln|S|,
// gated by the chi-square of the innovation and a distance cap. Births: an unassigned candidate
// starts a tentative track, confirmed after `confirm_hits` hits; a tentative track dies after
// `tentative_max_misses` misses (false positives: one-sweep flickers never confirm), a confirmed
// one after `max_misses` (it coasts on its prediction meanwhile). Candidates within
// `birth_exclusion_m` of a confirmed track start nothing (a person's body broken into two blobs).
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar_track {

struct FootTrackerOptions {
  double accel_sigma_mps2 = 1.0;      // white-noise acceleration of the constant-velocity model
  double measurement_sigma_m = 0.12;  // foot candidate noise
  double init_speed_sigma_mps = 1.2;  // velocity prior of a new track
  double gate_chi2 = 13.8;            // innovation d^2 (2 dof, 99.9 %)
  double gate_max_m = 1.5;            // and at most this far from the prediction
  int confirm_hits = 3;
  int tentative_max_misses = 1;
  int max_misses = 10;                // sweeps a confirmed track coasts
  double birth_exclusion_m = 0.6;
  double default_dt_s = 0.1;          // when sweep times do not advance
  std::string Check() const;
};

class FootTracker {
 public:
  explicit FootTracker(FootTrackerOptions options = {});

  // Predicts every track to t_ns, assigns the candidates, corrects, handles births and deaths.
  // Returns per candidate the id of the track it was assigned to (0: none or a new track's).
  std::vector<uint32_t> Update(int64_t t_ns, const std::vector<Eigen::Vector2d>& candidates_xy_m);
  // Positions of the confirmed tracks predicted to t_ns (split hints), without changing state.
  std::vector<Eigen::Vector2d> PredictConfirmed(int64_t t_ns) const;
  // Every live track (confirmed or not), by id.
  std::vector<lidar::FootTrack> Tracks() const;
  bool IsConfirmed(uint32_t id) const;

 private:
  struct Track {
    lidar::FootTrack out;
    Eigen::Vector4d x = Eigen::Vector4d::Zero();
    Eigen::Matrix4d P = Eigen::Matrix4d::Identity();
    int hits = 0;
  };
  double Dt(int64_t t_ns) const;
  void Predict(Track& track, double dt) const;

  FootTrackerOptions options_;
  std::vector<Track> tracks_;
  uint32_t next_id_ = 1;
  int64_t last_t_ns_ = 0;
  bool started_ = false;
};

}  // namespace ave::lidar_track
