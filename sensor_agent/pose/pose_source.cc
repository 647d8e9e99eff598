#include "sensor_agent/pose/pose_source.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "model_store/common/log.h"
#include "sensor_agent/sim/gps_imu.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::pose {
namespace {

class FusedPoseSource final : public FrameSource {
 public:
  FusedPoseSource(std::unique_ptr<FrameSource> inner, PoseMode mode, PoseTracker tracker, std::unique_ptr<VisionTracker> vision)
      : inner_(std::move(inner)), mode_(mode), tracker_(std::move(tracker)), vision_(std::move(vision)) {}

  absl::StatusOr<CapturedFrame> Next() override {
    absl::StatusOr<CapturedFrame> frame = inner_->Next();
    if (!frame.ok()) return frame;
    const int64_t t_ns = static_cast<int64_t>(std::llround(frame->scene_time_s * 1e9));
    PoseSample sample = tracker_.Advance(t_ns);
    if (tracker_.stats().gps_reanchored != reanchored_) {  // rare events a field technician reads in the log
      reanchored_ = tracker_.stats().gps_reanchored;
      AVE_LOG(WARNING) << "pose: every GPS fix for " << tracker_.filter().options().gps_reanchor_s << " s lay more than "
                       << tracker_.filter().options().gps_reanchor_min_m << " m from the pose: re-anchored to the GPS at t="
                       << frame->scene_time_s << " s";
    }
    if (sample.valid && vision_) {
      const VisionFrameStats s = vision_->Update(frame->bgr.data(), frame->width, frame->height, tracker_.filter());
      if (s.relocks > 0) AVE_LOG(WARNING) << "pose: vision lost its lock at t=" << frame->scene_time_s << " s; searching";
      if (s.relocalized) AVE_LOG(INFO) << "pose: vision found the camera again at t=" << frame->scene_time_s << " s";
      sample = tracker_.Current();
    }
    frame->world_from_camera.reset();
    frame->pose_covariance.clear();
    if (sample.valid) {
      frame->world_from_camera = sample.world_from_camera;
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) frame->pose_covariance.push_back(sample.covariance(r, c));
    }
    return frame;
  }
  PinholeIntrinsics intrinsics() const override { return inner_->intrinsics(); }
  std::string description() const override { return inner_->description() + ", pose " + PoseModeName(mode_); }
  bool live() const override { return inner_->live(); }
  int64_t drop_outs() const override { return inner_->drop_outs(); }
  int64_t reconnects() const override { return inner_->reconnects(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  PoseMode mode_;
  PoseTracker tracker_;
  std::unique_ptr<VisionTracker> vision_;
  int64_t reanchored_ = 0;
};

}  // namespace

absl::StatusOr<std::unique_ptr<FrameSource>> WithFusedPose(std::unique_ptr<FrameSource> inner, const std::string& sim_spec,
                                                           const PoseSourceOptions& options) {
  if (options.mode == PoseMode::kTruth) return inner;
  if (const std::string why = options.filter.Check(); !why.empty()) return absl::InvalidArgumentError("pose filter: " + why);
  const size_t hash = sim_spec.find('#');
  if (sim_spec.rfind("sim:", 0) != 0 || hash == std::string::npos) {
    return absl::InvalidArgumentError(absl::StrCat("--pose-mode ", PoseModeName(options.mode), " needs a sim:SCENARIO#CAMERA source, got '",
                                                   sim_spec, "'"));
  }
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(sim_spec.substr(4, hash - 4));
  if (!scenario.ok()) return scenario.status();
  const std::string camera_id = sim_spec.substr(hash + 1);
  const scene::CameraSpec* camera = scenario->world.FindCamera(camera_id);
  if (!camera) return absl::NotFoundError(absl::StrCat(scenario->label, ": no camera '", camera_id, "'"));
  SensorLog log;
  if (!options.log_dir.empty()) {
    absl::StatusOr<SensorLog> read = ReadSensorLog(options.log_dir, scenario->world.origin);
    if (!read.ok()) return read.status();
    log = std::move(*read);
  } else {
    sim::GpsImuSpec spec;
    for (const sim::GpsImuSpec& g : scenario->gps_imu)
      if (g.camera_id == camera_id) spec = g;
    spec.camera_id = camera_id;
    spec.duration_s = options.simulate_s;
    if (const std::string why = spec.Check(); !why.empty()) return absl::InvalidArgumentError("gps/imu simulation: " + why);
    log = FromSimulation(sim::SimulateGpsImu(scenario->world, *camera, spec, scenario->effects, scenario->seed));
  }
  std::unique_ptr<VisionTracker> vision;
  if (options.mode == PoseMode::kGpsImuVision) {
    VisionOptions vision_options = options.vision;
    if (options.carrier_height_m >= 0) {
      vision_options.carrier_height_m = options.carrier_height_m;
    } else if (camera->path) {
      vision_options.carrier_height_m = camera->path->height_m;
    }
    if (const std::string why = vision_options.Check(); !why.empty()) return absl::InvalidArgumentError("vision: " + why);
    vision = std::make_unique<VisionTracker>(CampusFeatureMap(scenario->world), scene::BuildStaticMesh(scenario->world, 2.0),
                                             camera->intrinsics, vision_options);
  }
  return std::make_unique<FusedPoseSource>(std::move(inner), options.mode, PoseTracker(std::move(log), options.filter), std::move(vision));
}

}  // namespace ave::pose
