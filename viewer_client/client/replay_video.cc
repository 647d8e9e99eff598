#include "viewer_client/client/replay_video.h"

#include <cmath>
#include <filesystem>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace ave::viewer {

struct ReplayVideo::Impl {
  cv::VideoWriter writer;
  cv::Mat held_bgr;  // the newest frame drawn, not yet written for every slot it covers
};

int64_t ReplayVideoFrames(int64_t from_ns, int64_t to_ns, double fps) {
  if (to_ns <= from_ns || !(fps > 0)) return 0;
  return static_cast<int64_t>(std::ceil(static_cast<double>(to_ns - from_ns) * 1e-9 * fps - 1e-9));
}

absl::StatusOr<std::unique_ptr<ReplayVideo>> ReplayVideo::Open(const std::string& path, int width, int height,
                                                               double fps, int64_t from_ns, int64_t to_ns) {
  if (!absl::EndsWith(path, ".mkv") && !absl::EndsWith(path, ".avi")) {
    return absl::InvalidArgumentError(absl::StrCat("--video ", path, ": must end in .mkv or .avi (Motion-JPEG)"));
  }
  if (!(fps >= 1 && fps <= 120)) return absl::InvalidArgumentError(absl::StrCat("--video-fps ", fps, ": must be 1 .. 120"));
  if (to_ns <= from_ns) return absl::InvalidArgumentError("--video needs --replay-from before --replay-to");
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (!parent.empty() && !std::filesystem::is_directory(parent)) {
    return absl::NotFoundError(absl::StrCat("--video ", path, ": no folder ", parent.string()));
  }
  std::unique_ptr<ReplayVideo> video(new ReplayVideo);
  video->impl_ = std::make_unique<Impl>();
  if (!video->impl_->writer.open(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps, cv::Size(width, height))) {
    return absl::UnavailableError(absl::StrCat("--video ", path, ": OpenCV's VideoWriter could not open it (MJPG)"));
  }
  video->path_ = path;
  video->width_ = width;
  video->height_ = height;
  video->fps_ = fps;
  video->from_ns_ = from_ns;
  video->to_ns_ = to_ns;
  video->total_ = ReplayVideoFrames(from_ns, to_ns, fps);
  return video;
}

ReplayVideo::~ReplayVideo() = default;

absl::Status ReplayVideo::WriteHeld() {
  if (impl_->held_bgr.empty()) return absl::OkStatus();
  impl_->writer.write(impl_->held_bgr);
  ++written_;
  return absl::OkStatus();
}

absl::Status ReplayVideo::Add(const std::vector<uint8_t>& rgba, int64_t replay_ns) {
  if (rgba.size() != static_cast<size_t>(width_) * height_ * 4) {
    return absl::InvalidArgumentError(absl::StrCat("--video ", path_, ": a frame of ", rgba.size(), " bytes, not ",
                                                   width_, "x", height_, " RGBA"));
  }
  const int64_t t_ns = replay_ns > 0 ? replay_ns : from_ns_;
  // Slot k shows from_ns + k / fps: the held frame covers every slot before this frame's instant.
  auto slot_ns = [&](int64_t k) { return from_ns_ + static_cast<int64_t>(static_cast<double>(k) * 1e9 / fps_); };
  if (impl_->held_bgr.empty()) {
    cv::Mat first(height_, width_, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
    cv::cvtColor(first, impl_->held_bgr, cv::COLOR_RGBA2BGR);  // the first frame also covers the slots before it
  }
  while (written_ < total_ && slot_ns(written_) < t_ns) {
    if (absl::Status s = WriteHeld(); !s.ok()) return s;
  }
  cv::Mat frame(height_, width_, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
  cv::cvtColor(frame, impl_->held_bgr, cv::COLOR_RGBA2BGR);
  return absl::OkStatus();
}

absl::StatusOr<int64_t> ReplayVideo::Finish() {
  while (written_ < total_ && !impl_->held_bgr.empty()) {
    if (absl::Status s = WriteHeld(); !s.ok()) return s;
  }
  impl_->writer.release();
  if (written_ == 0) return absl::DataLossError(absl::StrCat("--video ", path_, ": no frame was drawn"));
  return written_;
}

}  // namespace ave::viewer
