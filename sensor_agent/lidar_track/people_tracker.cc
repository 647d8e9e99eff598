#include "sensor_agent/lidar_track/people_tracker.h"

#include <ctime>

#include "absl/strings/str_cat.h"
#include "model_store/common/cpu_clock.h"

namespace ave::lidar_track {

std::string LidarPeopleTrackerOptions::Check() const {
  if (std::string why = foreground.Check(); !why.empty()) return "foreground." + why;
  if (std::string why = blobs.Check(); !why.empty()) return "blobs." + why;
  if (std::string why = tracker.Check(); !why.empty()) return "tracker." + why;
  if (ground_plane_in_sensor && !ground_plane_in_sensor->allFinite()) return "ground_plane_in_sensor: must be finite";
  if (!(ground_tolerance_m > 0) || !(ground_max_tilt_deg > 0 && ground_max_tilt_deg < 90)) {
    return "ground_tolerance_m > 0, ground_max_tilt_deg in (0, 90)";
  }
  return "";
}

LidarPeopleTracker::LidarPeopleTracker(LidarPeopleTrackerOptions options)
    : options_(options), segmenter_(options.foreground), tracker_(options.tracker) {}

absl::Status LidarPeopleTracker::EnsureGround(const lidar::LidarSweep& sweep) {
  if (ground_) return absl::OkStatus();
  absl::StatusOr<GroundFrame> g =
      options_.ground_plane_in_sensor
          ? GroundFrameFromPlane(options_.ground_plane_in_sensor->head<3>(), (*options_.ground_plane_in_sensor)[3])
          : FitGroundFrame(sweep, {}, options_.ground_tolerance_m, options_.ground_max_tilt_deg);
  if (!g.ok()) return g.status();
  ground_ = *g;
  return absl::OkStatus();
}

std::vector<uint8_t> LidarPeopleTracker::FrozenPoints(const lidar::LidarSweep& sweep, const lidar::FootTracks& tracks) const {
  std::vector<uint8_t> frozen(sweep.points.size(), 0);
  for (size_t i = 0; i < tracks.point_track_id.size(); ++i) frozen[i] = tracks.point_track_id[i] != 0;
  // Also everything within freeze_radius_m of a confirmed track, measured this sweep or coasting:
  // a person's feet (which the 3D step gives to the ground) and sweeps where the blob was missed
  // would otherwise be learned, and the background would creep up a standing person ring by ring.
  std::vector<Eigen::Vector2f> centres;
  for (const lidar::FootTrack& t : tracks.tracks) {
    if (t.confirmed) centres.push_back(t.xy_m.cast<float>());
  }
  if (centres.empty()) return frozen;
  const Eigen::Matrix3f R = ground_->ground_from_sensor.rotation.toRotationMatrix().cast<float>();
  const Eigen::Vector3f t = ground_->ground_from_sensor.translation.cast<float>();
  const float r2 = static_cast<float>(options_.freeze_radius_m * options_.freeze_radius_m);
  const float max_h = static_cast<float>(options_.blobs.label_max_height_m);
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    if (frozen[i] || !(sweep.points[i].range_m > 0)) continue;
    const Eigen::Vector3f q = R * sweep.points[i].p_in_sensor + t;
    if (!(q.z() < max_h)) continue;
    for (const Eigen::Vector2f& c : centres) {
      if ((q.head<2>() - c).squaredNorm() < r2) {
        frozen[i] = 1;
        break;
      }
    }
  }
  return frozen;
}

absl::StatusOr<lidar::FootTracks> LidarPeopleTracker::Process(const lidar::LidarSweep& sweep) {
  if (const std::string why = options_.Check(); !why.empty()) return absl::InvalidArgumentError("LidarPeopleTrackerOptions." + why);
  const double t0 = ThreadCpuSeconds();
  if (absl::Status s = EnsureGround(sweep); !s.ok()) return s;
  absl::StatusOr<std::vector<uint8_t>> fg = segmenter_.Segment(sweep);
  if (!fg.ok()) return fg.status();
  foreground_ = std::move(*fg);
  const double t1 = ThreadCpuSeconds();
  absl::StatusOr<lidar::FootTracks> out = Track(sweep);
  if (!out.ok()) return out;
  const double t2 = ThreadCpuSeconds();
  std::vector<uint8_t> frozen;
  if (options_.freeze_background_under_tracks) frozen = FrozenPoints(sweep, *out);
  segmenter_.Learn(frozen);
  times_.foreground_s += t1 - t0;
  times_.learn_s = ThreadCpuSeconds() - t2;
  return out;
}

absl::StatusOr<lidar::FootTracks> LidarPeopleTracker::ProcessWithForeground(const lidar::LidarSweep& sweep,
                                                                             const std::vector<uint8_t>& foreground) {
  if (const std::string why = options_.Check(); !why.empty()) return absl::InvalidArgumentError("LidarPeopleTrackerOptions." + why);
  if (foreground.size() != sweep.points.size()) {
    return absl::InvalidArgumentError(absl::StrCat("foreground: ", foreground.size(), " labels for ", sweep.points.size(), " points"));
  }
  if (absl::Status s = EnsureGround(sweep); !s.ok()) return s;
  foreground_ = foreground;
  times_ = {};
  return Track(sweep);
}

absl::StatusOr<lidar::FootTracks> LidarPeopleTracker::Track(const lidar::LidarSweep& sweep) {
  const double t0 = ThreadCpuSeconds();
  times_ = {};
  std::vector<Eigen::Vector2d> hints;
  if (options_.split_merged_blobs) hints = tracker_.PredictConfirmed(sweep.t_ns);
  const BlobDetection det = DetectFootBlobs(sweep, foreground_, *ground_, hints, options_.blobs);
  const double t1 = ThreadCpuSeconds();
  // Split parts that kept no points of their own are not measurements.
  std::vector<Eigen::Vector2d> candidates;
  std::vector<int> candidate_of_blob(det.blobs.size(), -1);
  const int min_part = std::max(1, options_.blobs.min_points / 2);
  for (size_t b = 0; b < det.blobs.size(); ++b) {
    if (det.blobs[b].points < min_part) continue;
    candidate_of_blob[b] = static_cast<int>(candidates.size());
    candidates.push_back(det.blobs[b].xy_m);
  }
  const std::vector<uint32_t> id_of = tracker_.Update(sweep.t_ns, candidates);
  lidar::FootTracks out;
  out.t_ns = sweep.t_ns;
  const Rigid3d world_from_sensor = sweep.world_from_sensor.value_or(Rigid3d());
  out.world_from_ground = world_from_sensor * ground_->ground_from_sensor.Inverse();
  out.tracks = tracker_.Tracks();
  out.point_track_id.assign(sweep.points.size(), 0);
  for (size_t i = 0; i < det.blob_of_point.size(); ++i) {
    const int b = det.blob_of_point[i];
    if (b < 0 || candidate_of_blob[b] < 0) continue;
    const uint32_t id = id_of[candidate_of_blob[b]];
    if (id != 0 && tracker_.IsConfirmed(id)) out.point_track_id[i] = id;
  }
  times_.blobs_s = t1 - t0;
  times_.tracking_s = ThreadCpuSeconds() - t1;
  return out;
}

lidar::SweepTracker MakeSweepTracker(LidarPeopleTrackerOptions options) {
  auto tracker = std::make_shared<LidarPeopleTracker>(std::move(options));
  return [tracker](const lidar::LidarSweep& sweep) { return tracker->Process(sweep); };
}

}  // namespace ave::lidar_track
