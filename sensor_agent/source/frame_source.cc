#include "sensor_agent/source/frame_source.h"

#include <chrono>
#include <future>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "model_store/common/log.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/footage.h"
#include "sensor_agent/sim/scenario.h"

namespace ave {
namespace {

int64_t WallNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// A scenario's camera through the simulator's camera pipeline: the scenario's effects for this
// camera, its true pose per frame (moving cameras walk their path). With a footage file, its
// frames are played instead of rendered while it lasts (issue 19).
class SimScenarioSource final : public FrameSource {
 public:
  // `scenario_name_or_path` as the spec names it (it keys the footage file).
  SimScenarioSource(const sim::Scenario& scenario, const std::string& scenario_name_or_path, const scene::CameraSpec& camera,
                    const SourceOptions& options)
      : scenario_name_(scenario.name),
        camera_(scenario.world, camera, scenario.EffectsForCamera(camera.id), scenario.seed),
        options_(options) {
    if (!options.sim_footage.empty()) footage_ = OpenFootage(options.sim_footage, scenario_name_or_path);
  }

  ~SimScenarioSource() override {
    if (ahead_.valid()) ahead_.wait();
  }

  absl::StatusOr<CapturedFrame> Next() override {
    if (!options_.sim_render_ahead) return Produce(index_++);
    absl::StatusOr<CapturedFrame> frame = ahead_.valid() ? ahead_.get() : Produce(index_++);
    // The next frame renders while the caller works on this one (one Frame() at a time).
    ahead_ = std::async(std::launch::async, [this, index = index_++] { return Produce(index); });
    return frame;
  }
  PinholeIntrinsics intrinsics() const override { return camera_.camera().intrinsics; }
  std::string description() const override {
    return "simulated " + scenario_name_ + " camera " + camera_.camera().id +
           (footage_ ? absl::StrCat(" (footage ", footage_->path(), ", ", footage_->frames(), " frames)") : "");
  }
  bool live() const override { return false; }


 private:
  // Opens and verifies `path` for this camera (two renders); nullopt, with a log line naming the
  // file and the reason, when it cannot be played.
  std::optional<sim::Footage> OpenFootage(const std::string& path, const std::string& scenario_name_or_path) const {
    const std::string& id = camera_.camera().id;
    // Quality 0: footage of any quality (the agent re-encodes when it asks for another).
    absl::StatusOr<sim::FootageKey> key = sim::MakeFootageKey(scenario_name_or_path, id, options_.fps, options_.sim_start_s, 0);
    absl::StatusOr<sim::Footage> footage = key.ok() ? sim::Footage::Open(path, *key) : key.status();
    const absl::Status ok = footage.ok() ? footage->Verify(camera_) : footage.status();
    if (!ok.ok()) {
      AVE_LOG(WARNING) << "camera '" << id << "': " << ok.message() << "; rendering every frame live (`ave-sim footage` makes the file anew)";
      return std::nullopt;
    }
    AVE_LOG(INFO) << "camera '" << id << "': playing footage " << path << ": " << footage->frames() << " frames, "
                  << footage->frames() / options_.fps << " s of scene time";
    return std::move(*footage);
  }

  absl::StatusOr<CapturedFrame> Produce(int64_t index) const {
    if (footage_ && index < footage_->frames()) return Play(index);
    if (footage_ && index == footage_->frames()) {
      AVE_LOG(INFO) << "camera '" << camera_.camera().id << "': footage " << footage_->path() << " ends after frame " << index - 1
                    << "; rendering live from t = " << footage_->TimeOf(index) << " s";
    }
    return Render(index);
  }

  absl::StatusOr<CapturedFrame> Render(int64_t index) const {
    CapturedFrame frame;
    frame.scene_time_s = options_.sim_start_s + static_cast<double>(index) / options_.fps;
    frame.capture_time_ns = WallNs();
    sim::SimImage image = camera_.Frame(index, frame.scene_time_s);
    if (image.width == 0) return absl::InternalError(absl::StrCat(description(), ": renders nothing"));
    frame.width = image.width;
    frame.height = image.height;
    frame.bgr = std::move(image.bgr);
    frame.world_from_camera = camera_.PoseAt(frame.scene_time_s);
    return frame;
  }

  // Frame `index` from the footage: the same scene time as Render's, the camera's JPEG bytes and
  // their decoded image (what an agent gets from a physical camera that sends JPEG).
  absl::StatusOr<CapturedFrame> Play(int64_t index) const {
    CapturedFrame frame;
    frame.scene_time_s = options_.sim_start_s + static_cast<double>(index) / options_.fps;
    frame.capture_time_ns = WallNs();
    frame.jpeg = footage_->Jpeg(index);
    frame.jpeg_quality = footage_->key().jpeg_quality;
    const cv::Mat image = cv::imdecode(frame.jpeg, cv::IMREAD_COLOR);
    const PinholeIntrinsics& k = camera_.camera().intrinsics;
    if (image.empty() || image.cols != k.width || image.rows != k.height || !image.isContinuous()) {
      return absl::DataLossError(absl::StrCat(footage_->path(), ": frame ", index, " does not decode to a ", k.width, "x", k.height, " image"));
    }
    frame.width = image.cols;
    frame.height = image.rows;
    frame.bgr.assign(image.data, image.data + image.total() * 3);
    frame.world_from_camera = camera_.PoseAt(frame.scene_time_s);
    return frame;
  }

  std::string scenario_name_;
  sim::SimulatedCamera camera_;
  SourceOptions options_;
  std::optional<sim::Footage> footage_;
  int64_t index_ = 0;
  std::future<absl::StatusOr<CapturedFrame>> ahead_;  // sim_render_ahead: the next frame
};

class VideoCaptureSource final : public FrameSource {
 public:
  VideoCaptureSource(std::string spec, std::unique_ptr<cv::VideoCapture> capture, bool live, bool network,
                     const SourceOptions& options)
      : spec_(std::move(spec)), capture_(std::move(capture)), live_(live), network_(network), options_(options) {}

  absl::StatusOr<CapturedFrame> Next() override {
    if (network_ && !capture_->isOpened()) {
      // Down since a drop-out: one reconnection attempt per call (the agent waits between calls).
      ++attempts_;
      const double down_s = (WallNs() - down_since_ns_) * 1e-9;
      if (!capture_->open(spec_, cv::CAP_FFMPEG) || !capture_->isOpened()) {
        capture_->release();
        return absl::UnavailableError(absl::StrFormat("%s: stream down for %.1f s after %d frames: reconnection attempt %d failed (cannot open)",
                                                      spec_, down_s, count_, attempts_));
      }
      reconnected_pending_ = true;
    }
    cv::Mat image;
    if (!capture_->read(image) || image.empty()) {
      if (!live_) return absl::OutOfRangeError(absl::StrCat(spec_, ": end of video after ", count_, " frames"));
      if (!network_) return absl::UnavailableError(absl::StrCat(spec_, ": read failed after ", count_, " frames"));
      // A drop-out (the server closed or cut the stream, the network failed): close it; the next
      // call reconnects. A reopened stream that fails before any frame is still the same drop-out.
      capture_->release();
      if (!reconnected_pending_) {
        ++drop_outs_;
        attempts_ = 0;
        down_since_ns_ = WallNs();
      }
      reconnected_pending_ = false;
      return absl::UnavailableError(absl::StrCat(spec_, ": stream dropped after ", count_, " frames (drop-out ", drop_outs_,
                                                 "); reconnecting"));
    }
    if (reconnected_pending_) {
      reconnected_pending_ = false;
      ++reconnects_;
    }
    if (image.channels() == 1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
    if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
    if (intrinsics_.width == 0) {
      intrinsics_ = options_.intrinsics.width > 0
                        ? options_.intrinsics
                        : PinholeIntrinsics::FromFov(image.cols, image.rows, options_.default_fov_deg);
    }
    if (image.cols != intrinsics_.width || image.rows != intrinsics_.height) {
      cv::resize(image, image, cv::Size(intrinsics_.width, intrinsics_.height), 0, 0, cv::INTER_AREA);
    }
    CapturedFrame frame;
    frame.capture_time_ns = WallNs();
    if (first_ns_ == 0) first_ns_ = frame.capture_time_ns;
    frame.scene_time_s = (frame.capture_time_ns - first_ns_) * 1e-9;
    if (!live_) {
      // A file: its own timeline (read faster or slower than real time, e.g. by --detect-only).
      const double pos_ms = capture_->get(cv::CAP_PROP_POS_MSEC);
      const double video_fps = capture_->get(cv::CAP_PROP_FPS);
      if (pos_ms > 0 || count_ == 0) frame.scene_time_s = pos_ms * 1e-3;
      else if (video_fps > 0) frame.scene_time_s = count_ / video_fps;
    }
    frame.width = image.cols;
    frame.height = image.rows;
    frame.bgr.assign(image.data, image.data + image.total() * 3);
    if (!image.isContinuous()) {
      frame.bgr.clear();
      for (int r = 0; r < image.rows; ++r) frame.bgr.insert(frame.bgr.end(), image.ptr(r), image.ptr(r) + image.cols * 3);
    }
    ++count_;
    return frame;
  }
  PinholeIntrinsics intrinsics() const override {
    if (intrinsics_.width > 0) return intrinsics_;
    if (options_.intrinsics.width > 0) return options_.intrinsics;
    const int w = static_cast<int>(capture_->get(cv::CAP_PROP_FRAME_WIDTH));
    const int h = static_cast<int>(capture_->get(cv::CAP_PROP_FRAME_HEIGHT));
    return PinholeIntrinsics::FromFov(std::max(w, 1), std::max(h, 1), options_.default_fov_deg);
  }
  std::string description() const override { return spec_; }
  bool live() const override { return live_; }
  int64_t drop_outs() const override { return drop_outs_; }
  int64_t reconnects() const override { return reconnects_; }

 private:
  std::string spec_;
  std::unique_ptr<cv::VideoCapture> capture_;
  bool live_;
  bool network_;  // rtsp://, http(s)://: reconnect after a drop-out
  int64_t drop_outs_ = 0;
  int64_t reconnects_ = 0;
  int attempts_ = 0;               // reconnection attempts since the last drop-out
  int64_t down_since_ns_ = 0;
  bool reconnected_pending_ = false;  // reopened; counts as a reconnect once a frame arrives
  SourceOptions options_;
  PinholeIntrinsics intrinsics_;
  int64_t count_ = 0;
  int64_t first_ns_ = 0;
};

bool StartsWith(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

}  // namespace

absl::StatusOr<std::unique_ptr<FrameSource>> OpenSource(const std::string& spec, const SourceOptions& options) {
  if (!(options.fps > 0 && options.fps <= 1000)) {
    return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': fps must be in (0, 1000]"));
  }
  if (!(options.default_fov_deg > 0 && options.default_fov_deg < 180)) {
    return absl::InvalidArgumentError(
        absl::StrCat("source '", spec, "': field of view (--fov) must be in (0, 180) degrees, not ", options.default_fov_deg));
  }
  if (options.intrinsics.width > 0) {
    if (const std::string why = options.intrinsics.Check(); !why.empty()) {
      return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': intrinsics.", why));
    }
  }
  if (StartsWith(spec, "sim:")) {
    const std::string rest = spec.substr(4);
    const size_t hash = rest.find('#');
    if (hash == std::string::npos) {
      return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': expected sim:SCENE#CAMERA"));
    }
    const std::string scene_name = rest.substr(0, hash), camera_id = rest.substr(hash + 1);
    absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(scene_name);
    if (!scenario.ok()) {
      return absl::Status(scenario.status().code(), absl::StrCat("source '", spec, "': unknown scenario: ", scenario.status().message()));
    }
    const scene::CameraSpec* camera = scenario->world.FindCamera(camera_id);
    if (!camera) {
      std::string known;
      for (const auto& c : scenario->world.cameras) known += (known.empty() ? "" : ", ") + c.id;
      return absl::NotFoundError(
          absl::StrCat("source '", spec, "': the ", scenario->name, " scenario has no camera '", camera_id, "' (cameras: ", known, ")"));
    }
    return std::unique_ptr<FrameSource>(new SimScenarioSource(*scenario, scene_name, *camera, options));
  }
  auto capture = std::make_unique<cv::VideoCapture>();
  bool live = true;
  bool network = false;
  bool opened = false;
  if (StartsWith(spec, "file:")) {
    live = false;
    opened = capture->open(spec.substr(5));
  } else if (StartsWith(spec, "rtsp://") || StartsWith(spec, "http://") || StartsWith(spec, "https://")) {
    network = true;
    opened = capture->open(spec, cv::CAP_FFMPEG);
  } else if (StartsWith(spec, "v4l2:")) {
    const std::string dev = spec.substr(5);
    const bool numeric = !dev.empty() && dev.find_first_not_of("0123456789") == std::string::npos;
    if (numeric && dev.size() > 4) {  // std::stoi would throw past INT_MAX; no machine has 10,000 devices
      return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': device number out of range (0..9999)"));
    }
    opened = numeric ? capture->open(std::stoi(dev), cv::CAP_V4L2) : capture->open(dev, cv::CAP_V4L2);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("source '", spec, "': unknown scheme (use sim:, file:, rtsp://, http(s)://, v4l2:)"));
  }
  if (!opened || !capture->isOpened()) {
    return absl::UnavailableError(absl::StrCat("source '", spec, "': cannot open"));
  }
  return std::unique_ptr<FrameSource>(new VideoCaptureSource(spec, std::move(capture), live, network, options));
}

}  // namespace ave
