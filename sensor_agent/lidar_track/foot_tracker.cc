#include "sensor_agent/lidar_track/foot_tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>

#include "sensor_agent/lidar_track/assignment.h"

namespace ave::lidar_track {

std::string FootTrackerOptions::Check() const {
  if (!(accel_sigma_mps2 > 0) || !(measurement_sigma_m > 0) || !(init_speed_sigma_mps > 0)) {
    return "accel_sigma_mps2, measurement_sigma_m, init_speed_sigma_mps: must be > 0";
  }
  if (!(gate_chi2 > 0) || !(gate_max_m > 0)) return "gate_chi2, gate_max_m: must be > 0";
  if (confirm_hits < 1 || tentative_max_misses < 0 || max_misses < 0) return "confirm_hits >= 1, misses >= 0";
  if (!(default_dt_s > 0)) return "default_dt_s: must be > 0";
  return "";
}

FootTracker::FootTracker(FootTrackerOptions options) : options_(options) {}

double FootTracker::Dt(int64_t t_ns) const {
  if (!started_) return options_.default_dt_s;
  const double dt = (t_ns - last_t_ns_) * 1e-9;
  return dt > 0 && dt < 5 ? dt : options_.default_dt_s;
}

void FootTracker::Predict(Track& tr, double dt) const {
  Eigen::Matrix4d F = Eigen::Matrix4d::Identity();
  F(0, 2) = F(1, 3) = dt;
  const double q = options_.accel_sigma_mps2 * options_.accel_sigma_mps2;
  Eigen::Matrix4d Q = Eigen::Matrix4d::Zero();
  const double dt2 = dt * dt, dt3 = dt2 * dt, dt4 = dt3 * dt;
  for (int a = 0; a < 2; ++a) {
    Q(a, a) = dt4 / 4 * q;
    Q(a, a + 2) = Q(a + 2, a) = dt3 / 2 * q;
    Q(a + 2, a + 2) = dt2 * q;
  }
  tr.x = F * tr.x;
  tr.P = F * tr.P * F.transpose() + Q;
  tr.P = 0.5 * (tr.P + tr.P.transpose());
}

std::vector<Eigen::Vector2d> FootTracker::PredictConfirmed(int64_t t_ns) const {
  std::vector<Eigen::Vector2d> out;
  const double dt = Dt(t_ns);
  for (const Track& tr : tracks_) {
    if (tr.out.confirmed) out.push_back(tr.x.head<2>() + dt * tr.x.tail<2>());
  }
  return out;
}

std::vector<uint32_t> FootTracker::Update(int64_t t_ns, const std::vector<Eigen::Vector2d>& z) {
  const double dt = Dt(t_ns);
  started_ = true;
  last_t_ns_ = t_ns;
  for (Track& tr : tracks_) Predict(tr, dt);
  const double r2 = options_.measurement_sigma_m * options_.measurement_sigma_m;
  const Eigen::Matrix2d R = r2 * Eigen::Matrix2d::Identity();
  const int nt = static_cast<int>(tracks_.size()), nz = static_cast<int>(z.size());
  Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(nt, nz, std::numeric_limits<double>::infinity());
  for (int i = 0; i < nt; ++i) {
    const Track& tr = tracks_[i];
    const Eigen::Matrix2d S = tr.P.topLeftCorner<2, 2>() + R;
    const Eigen::LDLT<Eigen::Matrix2d> ldlt(S);
    const double log_det = std::log(S.determinant());
    for (int j = 0; j < nz; ++j) {
      if (!z[j].allFinite()) continue;
      const Eigen::Vector2d nu = z[j] - tr.x.head<2>();
      const double d2 = nu.dot(ldlt.solve(nu));
      if (d2 > options_.gate_chi2 || nu.norm() > options_.gate_max_m) continue;
      // Confirmed tracks take precedence over tentative ones for a contested candidate.
      cost(i, j) = d2 + log_det + (tr.out.confirmed ? 0 : 4);
    }
  }
  const Assignment a = SolveAssignment(cost);
  std::vector<uint32_t> id_of(nz, 0);
  for (int i = 0; i < nt; ++i) {
    Track& tr = tracks_[i];
    ++tr.out.age_frames;
    const int j = a.col_of_row[i];
    if (j < 0) {
      ++tr.out.missed_frames;
      continue;
    }
    // Kalman correction, Joseph form.
    Eigen::Matrix<double, 2, 4> H = Eigen::Matrix<double, 2, 4>::Zero();
    H(0, 0) = H(1, 1) = 1;
    const Eigen::Matrix2d S = H * tr.P * H.transpose() + R;
    const Eigen::Matrix<double, 4, 2> K = tr.P * H.transpose() * S.ldlt().solve(Eigen::Matrix2d::Identity());
    tr.x += K * (z[j] - H * tr.x);
    const Eigen::Matrix4d IKH = Eigen::Matrix4d::Identity() - K * H;
    tr.P = IKH * tr.P * IKH.transpose() + K * R * K.transpose();
    tr.P = 0.5 * (tr.P + tr.P.transpose());
    tr.out.missed_frames = 0;
    ++tr.hits;
    if (tr.hits >= options_.confirm_hits) tr.out.confirmed = true;
    id_of[j] = tr.out.id;
  }
  // Deaths.
  tracks_.erase(std::remove_if(tracks_.begin(), tracks_.end(),
                               [&](const Track& tr) {
                                 return tr.out.missed_frames > (tr.out.confirmed ? options_.max_misses : options_.tentative_max_misses);
                               }),
                tracks_.end());
  // Births from unassigned candidates away from confirmed tracks.
  for (int j = 0; j < nz; ++j) {
    if (a.row_of_col[j] >= 0 || !z[j].allFinite()) continue;
    bool near_confirmed = false;
    for (const Track& tr : tracks_) {
      if (tr.out.confirmed && (tr.x.head<2>() - z[j]).norm() < options_.birth_exclusion_m) near_confirmed = true;
    }
    if (near_confirmed) continue;
    Track tr;
    tr.out.id = next_id_++;
    tr.x << z[j], 0, 0;
    tr.P = Eigen::Matrix4d::Zero();
    tr.P(0, 0) = tr.P(1, 1) = r2;
    tr.P(2, 2) = tr.P(3, 3) = options_.init_speed_sigma_mps * options_.init_speed_sigma_mps;
    tr.hits = 1;
    tr.out.confirmed = options_.confirm_hits <= 1;
    tracks_.push_back(tr);
  }
  return id_of;
}

std::vector<lidar::FootTrack> FootTracker::Tracks() const {
  std::vector<lidar::FootTrack> out;
  out.reserve(tracks_.size());
  for (const Track& tr : tracks_) {
    lidar::FootTrack t = tr.out;
    t.xy_m = tr.x.head<2>();
    t.velocity_mps = tr.x.tail<2>();
    t.covariance_m2 = tr.P.topLeftCorner<2, 2>();
    out.push_back(t);
  }
  std::sort(out.begin(), out.end(), [](const lidar::FootTrack& a, const lidar::FootTrack& b) { return a.id < b.id; });
  return out;
}

bool FootTracker::IsConfirmed(uint32_t id) const {
  for (const Track& tr : tracks_) {
    if (tr.out.id == id) return tr.out.confirmed;
  }
  return false;
}

}  // namespace ave::lidar_track
