#pragma once
// The rendered 4D interval as a video (issue 18): `ave-viewer --headless --replay-from T
// --replay-to T2 --video out.mkv` writes the frames it draws through OpenCV's VideoWriter
// (Motion-JPEG in MKV or AVI) at the recorded timing: video frame k shows the recorded instant
// from_ns + k / fps, the newest frame drawn at or before that instant. The viewer draws at its
// own pace (and the server replays at --replay-rate), so frames are repeated where the drawing
// lagged the recorded clock and skipped where it ran ahead; the video always lasts the interval,
// ceil((to_ns - from_ns) * fps) frames. OpenCV stays in replay_video.cc.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace ave::viewer {

// The number of frames of a video of [from_ns, to_ns) at `fps`.
int64_t ReplayVideoFrames(int64_t from_ns, int64_t to_ns, double fps);

class ReplayVideo {
 public:
  // `path` must end in .mkv or .avi; its folder must exist.
  static absl::StatusOr<std::unique_ptr<ReplayVideo>> Open(const std::string& path, int width, int height, double fps,
                                                           int64_t from_ns, int64_t to_ns);
  ~ReplayVideo();
  ReplayVideo(const ReplayVideo&) = delete;
  ReplayVideo& operator=(const ReplayVideo&) = delete;

  // A frame drawn (RGBA, top row first, the size given to Open) showing recorded time `replay_ns`
  // (0: the replay has not started, taken as from_ns). Writes the previous frame into every video
  // slot before `replay_ns`, then keeps this one for the next slots.
  absl::Status Add(const std::vector<uint8_t>& rgba, int64_t replay_ns);
  // Fills the slots left to the interval's end with the last frame and closes the file; the frames
  // written.
  absl::StatusOr<int64_t> Finish();
  int64_t frames_written() const { return written_; }

 private:
  ReplayVideo() = default;
  absl::Status WriteHeld();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string path_;
  int width_ = 0, height_ = 0;
  double fps_ = 10;
  int64_t from_ns_ = 0, to_ns_ = 0, total_ = 0, written_ = 0;
};

}  // namespace ave::viewer
