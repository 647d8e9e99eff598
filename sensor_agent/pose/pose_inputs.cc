#include "sensor_agent/pose/pose_inputs.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "sensor_agent/sim/gps_imu.h"

namespace ave::pose {
namespace {

// A CSV file with a header naming its columns; rows are read by column name.
class CsvReader {
 public:
  static absl::StatusOr<CsvReader> Open(const std::string& path, const std::string& label, const std::vector<std::string>& required) {
    CsvReader r;
    r.label_ = label;
    r.in_.open(path);
    if (!r.in_) return absl::NotFoundError(absl::StrCat(label, ": cannot open ", path));
    std::string header;
    if (!std::getline(r.in_, header)) return absl::InvalidArgumentError(absl::StrCat(label, ":1: empty file (no header)"));
    const std::vector<std::string> names = absl::StrSplit(header, ',');
    for (size_t i = 0; i < names.size(); ++i) r.columns_[names[i]] = i;
    for (const std::string& name : required) {
      if (!r.columns_.count(name)) return absl::InvalidArgumentError(absl::StrCat(label, ":1: header lacks column ", name));
    }
    r.line_ = 1;
    return r;
  }
  bool Has(const std::string& column) const { return columns_.count(column) > 0; }
  // False at the end of the file; blank lines are skipped.
  bool NextRow() {
    std::string text;
    while (std::getline(in_, text)) {
      ++line_;
      if (text.empty() || text == "\r") continue;
      fields_ = absl::StrSplit(text, ',');
      return true;
    }
    return false;
  }
  absl::StatusOr<double> Get(const std::string& column) const { return Parse<double>(column, "a number"); }
  absl::StatusOr<int64_t> GetInt(const std::string& column) const { return Parse<int64_t>(column, "an integer"); }
  absl::Status Error(const std::string& column, const std::string& why) const {
    return absl::InvalidArgumentError(absl::StrCat(label_, ":", line_, ": column ", column, ": ", why));
  }

 private:
  // The field of `column` on the current line as a T; `what` names T in the error.
  template <typename T>
  absl::StatusOr<T> Parse(const std::string& column, const char* what) const {
    const size_t i = columns_.at(column);
    if (i >= fields_.size()) return Error(column, "missing field");
    const std::string& f = fields_[i];
    T value{};
    const auto [end, ec] = std::from_chars(f.data(), f.data() + f.size(), value);
    if (ec != std::errc() || end != f.data() + f.size()) {
      return Error(column, absl::StrCat("not ", what, " '", f, "'"));
    }
    if constexpr (std::is_floating_point_v<T>) {
      if (!std::isfinite(value)) return Error(column, absl::StrCat("not finite '", f, "'"));
    }
    return value;
  }

  std::string label_;
  std::ifstream in_;
  std::map<std::string, size_t> columns_;
  std::vector<std::string> fields_;
  int64_t line_ = 0;
};

// Reads the named columns of the current row into `out` (in order); the first failure wins.
absl::Status GetAll(const CsvReader& csv, const std::vector<std::string>& columns, double* out) {
  for (size_t i = 0; i < columns.size(); ++i) {
    absl::StatusOr<double> v = csv.Get(columns[i]);
    if (!v.ok()) return v.status();
    out[i] = *v;
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SensorLog> ReadSensorLog(const std::string& dir, const Eigen::Vector3d& origin) {
  SensorLog log;
  log.origin = origin;
  const std::vector<std::string> gps_cols = {"x_m", "y_m", "z_m", "cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"};
  std::vector<std::string> required = gps_cols;
  required.insert(required.begin(), {"t_ns", "valid"});
  absl::StatusOr<CsvReader> gps = CsvReader::Open(dir + "/gps.csv", "gps.csv", required);
  if (!gps.ok()) return gps.status();
  while (gps->NextRow()) {
    GpsReading g;
    absl::StatusOr<int64_t> t = gps->GetInt("t_ns"), valid = gps->GetInt("valid");
    if (!t.ok()) return t.status();
    if (!valid.ok()) return valid.status();
    if (*valid != 0 && *valid != 1) return gps->Error("valid", "must be 0 or 1");
    g.t_ns = *t;
    g.valid = *valid == 1;
    if (g.valid) {
      double v[9];
      if (absl::Status s = GetAll(*gps, gps_cols, v); !s.ok()) return s;
      g.position_m = Eigen::Vector3d(v[0], v[1], v[2]) - origin;
      g.covariance << v[3], v[4], v[5], v[4], v[6], v[7], v[5], v[7], v[8];
    }
    log.gps.push_back(g);
  }
  const std::vector<std::string> imu_cols = {"qw", "qx", "qy", "qz", "gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"};
  required = imu_cols;
  required.insert(required.begin(), "t_ns");
  absl::StatusOr<CsvReader> imu = CsvReader::Open(dir + "/imu.csv", "imu.csv", required);
  if (!imu.ok()) return imu.status();
  // The accelerometer's columns are optional (older logs lack them); all three or none.
  const std::vector<std::string> accel_cols = {"accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"};
  const int accel_present = static_cast<int>(std::count_if(accel_cols.begin(), accel_cols.end(), [&](const std::string& c) { return imu->Has(c); }));
  if (accel_present != 0 && accel_present != 3) return absl::InvalidArgumentError("imu.csv:1: header has some of accel_x_m_s2, accel_y_m_s2, accel_z_m_s2 but not all");
  const bool has_accel = accel_present == 3;
  while (imu->NextRow()) {
    ImuReading s;
    absl::StatusOr<int64_t> t = imu->GetInt("t_ns");
    if (!t.ok()) return t.status();
    double v[7];
    if (absl::Status st = GetAll(*imu, imu_cols, v); !st.ok()) return st;
    const Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
    if (std::abs(q.norm() - 1.0) > 1e-3) return imu->Error("qw", "orientation quaternion is not unit");
    s.t_ns = *t;
    s.orientation = q.normalized();
    s.gyro_rad_s = Eigen::Vector3d(v[4], v[5], v[6]);
    if (has_accel) {
      double a[3];
      if (absl::Status st = GetAll(*imu, accel_cols, a); !st.ok()) return st;
      s.accel_m_s2 = Eigen::Vector3d(a[0], a[1], a[2]);
    }
    log.imu.push_back(s);
  }
  return log;
}

SensorLog FromSimulation(const sim::GpsImuStreams& streams) {
  SensorLog log;
  log.origin = streams.origin;
  for (const sim::GpsFix& f : streams.gps) log.gps.push_back({f.t_ns, f.valid, f.position_m, f.covariance});
  for (const sim::ImuSample& s : streams.imu) log.imu.push_back({s.t_ns, s.orientation, s.gyro_rad_s, s.accel_m_s2});
  return log;
}

std::optional<PoseMode> ParsePoseMode(const std::string& text) {
  for (PoseMode m : {PoseMode::kTruth, PoseMode::kGpsImu, PoseMode::kGpsImuVision}) {
    if (text == PoseModeName(m)) return m;
  }
  return std::nullopt;
}

const char* PoseModeName(PoseMode mode) {
  switch (mode) {
    case PoseMode::kTruth: return "truth";
    case PoseMode::kGpsImu: return "gps-imu";
    case PoseMode::kGpsImuVision: return "gps-imu-vision";
  }
  return "?";
}

PoseTracker::PoseTracker(SensorLog log, PoseFilterOptions options) : log_(std::move(log)), ekf_(options) {}

void PoseTracker::Apply(const GpsReading& g) {
  if (g.t_ns <= last_gps_ns_) {
    ++stats_.time_rejected;
    return;
  }
  const int64_t previous_ns = last_valid_gps_ns_;
  last_gps_ns_ = g.t_ns;
  if (!g.valid) {
    ++stats_.gps_dropouts;
    return;
  }
  if (!ekf_.initialized()) {
    first_fix_ = g;
    if (!first_orientation_) return;
    const double sigma = std::sqrt(std::max(g.covariance.trace() / 3, ekf_.options().gps_min_sigma_m * ekf_.options().gps_min_sigma_m));
    ekf_.Initialize(g.t_ns, Rigid3d(first_orientation_->orientation, g.position_m), sigma,
                    ekf_.options().orientation_sigma_deg * 3.14159265358979323846 / 180, /*position_from_gps_fix=*/true,
                    ekf_.options().heading_sigma_deg * 3.14159265358979323846 / 180);
    last_valid_gps_ns_ = g.t_ns;
    ++stats_.gps_used;
    return;
  }
  if (!ekf_.Predict(g.t_ns).accepted()) {
    ++stats_.time_rejected;
    return;
  }
  // Correlated GPS error (multipath): a fix dt after the last counts as dt / correlation of an independent one.
  const PoseFilterOptions& o = ekf_.options();
  const double dt_s = previous_ns == INT64_MIN ? o.gps_correlation_s : static_cast<double>(g.t_ns - previous_ns) * 1e-9;
  const double inflation = o.gps_correlation_s > dt_s ? o.gps_correlation_s / dt_s : 1.0;
  Eigen::Matrix3d covariance = g.covariance;
  const double floor = o.gps_min_sigma_m * o.gps_min_sigma_m;
  for (int i = 0; i < 3; ++i) covariance(i, i) = std::max(covariance(i, i), floor);
  const UpdateResult r = ekf_.UpdatePosition(g.position_m, inflation * covariance);
  last_valid_gps_ns_ = g.t_ns;
  stats_.gps_used += r.accepted();
  stats_.gps_gated += r.rejection == Rejection::kGate;
  const bool far_off = (g.position_m - ekf_.world_from_camera().translation).norm() >= o.gps_reanchor_min_m;
  if (r.rejection != Rejection::kGate || !far_off) {
    gated_in_row_ = 0;
  } else {
    if (gated_in_row_++ == 0) gated_since_ns_ = g.t_ns;
    if (o.gps_reanchor_s > 0 && gated_in_row_ >= 3 && static_cast<double>(g.t_ns - gated_since_ns_) * 1e-9 >= o.gps_reanchor_s) {
      // Every fix for gps_reanchor_s disagreed by more than gps_reanchor_min_m: the filter is off,
      // not the receiver. The fix becomes the position, at gps_reanchor_sigma_m at least (its own
      // sigma and the multipath the fixes share, when larger), and the orientation is widened.
      const double sigma = std::max(o.gps_reanchor_sigma_m, std::sqrt(covariance.diagonal().maxCoeff() + o.gps_bias_sigma_m * o.gps_bias_sigma_m));
      ekf_.MovePosition(g.position_m, sigma);
      ekf_.InflatePose(0, o.gps_reanchor_orientation_sigma_deg * 3.14159265358979323846 / 180);
      ++stats_.gps_reanchored;
      gated_in_row_ = 0;
    }
  }
  stats_.not_finite += r.rejection == Rejection::kNotFinite;
}

void PoseTracker::Apply(const ImuReading& s) {
  if (s.t_ns <= last_imu_ns_) {
    ++stats_.time_rejected;
    return;
  }
  const int64_t previous_ns = last_imu_ns_;
  last_imu_ns_ = s.t_ns;
  if (!ekf_.initialized()) {
    first_orientation_ = s;
    if (first_fix_) {
      GpsReading fix = *first_fix_;
      first_fix_.reset();
      last_gps_ns_ = INT64_MIN;
      fix.t_ns = std::max(fix.t_ns, s.t_ns);
      Apply(fix);
    }
    return;
  }
  if (!ekf_.Predict(s.t_ns).accepted()) {
    ++stats_.time_rejected;
    return;
  }
  const PoseFilterOptions& o = ekf_.options();
  // Correlated AHRS error: a reading dt after the last counts as dt / correlation of an independent one.
  const double dt_s = previous_ns == INT64_MIN ? o.orientation_correlation_s : static_cast<double>(s.t_ns - previous_ns) * 1e-9;
  const double inflation = o.orientation_correlation_s > dt_s ? std::sqrt(o.orientation_correlation_s / dt_s) : 1.0;
  const UpdateResult r = ekf_.UpdateOrientation(s.orientation, inflation * o.orientation_sigma_deg * 3.14159265358979323846 / 180,
                                                 inflation * o.heading_sigma_deg * 3.14159265358979323846 / 180);
  // The gyro's bias is correlated too (PoseFilterOptions::gyro_correlation_s).
  const double gyro_dt_s = previous_ns == INT64_MIN ? o.gyro_correlation_s : dt_s;
  const double gyro_inflation = o.gyro_correlation_s > gyro_dt_s ? std::sqrt(o.gyro_correlation_s / gyro_dt_s) : 1.0;
  (void)ekf_.UpdateRate(s.gyro_rad_s, gyro_inflation * o.gyro_sigma_rad_s);
  Level(s);
  stats_.imu_used += r.accepted();
  stats_.imu_gated += r.rejection == Rejection::kGate;
  stats_.not_finite += r.rejection == Rejection::kNotFinite;
}

// The accelerometer's mean over a window as the world's up (PoseFilterOptions::gravity_window_s),
// when the carrier neither sped up nor turned in it.
void PoseTracker::Level(const ImuReading& s) {
  const PoseFilterOptions& o = ekf_.options();
  if (!(o.gravity_window_s > 0) || !s.accel_m_s2 || !s.accel_m_s2->allFinite()) return;
  if (accel_count_ == 0) accel_start_ns_ = s.t_ns;
  accel_sum_ += *s.accel_m_s2;
  gyro_sum_ += s.gyro_rad_s;
  ++accel_count_;
  const double span_s = static_cast<double>(s.t_ns - accel_start_ns_) * 1e-9;
  if (span_s < o.gravity_window_s) return;
  const Eigen::Vector3d mean = accel_sum_ / accel_count_, rate = gyro_sum_ / accel_count_;
  accel_sum_.setZero();
  gyro_sum_.setZero();
  accel_count_ = 0;
  constexpr double kG = 9.80665;
  if (std::abs(mean.norm() - kG) > o.gravity_tolerance_m_s2 || rate.norm() > o.gravity_max_rate_rad_s) {
    ++stats_.gravity_moving;
    return;
  }
  // Correlated error (gait, accelerometer bias): a window dt after the last applied counts as
  // dt / gravity_correlation_s of an independent one.
  const double dt_s = last_gravity_ns_ == INT64_MIN ? o.gravity_correlation_s : static_cast<double>(s.t_ns - last_gravity_ns_) * 1e-9;
  const double inflation = o.gravity_correlation_s > dt_s ? std::sqrt(o.gravity_correlation_s / dt_s) : 1.0;
  const UpdateResult r = ekf_.UpdateGravity(mean, inflation * o.gravity_sigma_deg * 3.14159265358979323846 / 180);
  last_gravity_ns_ = s.t_ns;
  stats_.gravity_used += r.accepted();
  stats_.gravity_gated += r.rejection == Rejection::kGate;
}

PoseSample PoseTracker::Advance(int64_t t_ns) {
  if (ekf_.initialized() && t_ns < ekf_.time_ns()) {
    ++stats_.time_rejected;
    return Current();
  }
  while (true) {
    const bool gps_next = next_gps_ < log_.gps.size() && log_.gps[next_gps_].t_ns <= t_ns;
    const bool imu_next = next_imu_ < log_.imu.size() && log_.imu[next_imu_].t_ns <= t_ns;
    if (!gps_next && !imu_next) break;
    if (gps_next && (!imu_next || log_.gps[next_gps_].t_ns <= log_.imu[next_imu_].t_ns)) {
      Apply(log_.gps[next_gps_++]);
    } else {
      Apply(log_.imu[next_imu_++]);
    }
  }
  if (ekf_.initialized()) (void)ekf_.Predict(t_ns);
  PoseSample s = Current();
  s.t_ns = t_ns;
  return s;
}

PoseSample PoseTracker::Current() const {
  PoseSample s;
  s.t_ns = ekf_.time_ns();
  s.valid = ekf_.initialized();
  if (s.valid) {
    s.world_from_camera = ekf_.world_from_camera();
    s.covariance = ekf_.PoseCovariance();
  }
  return s;
}

}  // namespace ave::pose
