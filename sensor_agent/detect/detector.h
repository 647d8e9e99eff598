#pragma once
// The agent's moving-object detector and tracker (seed AVE §6, issue 6): grey conversion on a work
// image (frames wider than `work_width` are area-downsampled by an integer factor) plus, by
// default, a blue-red chroma plane at half the work resolution (`colour`), global gain
// compensation, a background model (background.h) over both, the larger of the two differences,
// the histogram threshold, morphological noise
// removal, two-pass 4-connected labelling with small regions dropped (segment.h) and pseudo-
// tracking by validation (tracker.h). Works on any BGR frame of any size (1x1 to 8K); all-black,
// all-white and suddenly re-lit frames give no tracks.
//
// A sudden global illumination change (more than `global_change_fraction` of the image over the
// threshold floor after gain compensation) resets the background to the current frame and drops
// every candidate and track (tags keep counting up), so no burst of false objects can persist for
// the validation time; objects that were tracked come back under new tags once they move.
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "sensor_agent/detect/background.h"
#include "sensor_agent/detect/tracker.h"

namespace ave::detect {

struct DetectorOptions {
  BackgroundKind background = BackgroundKind::kTimeAverage;
  double window_s = 10;          // longest averaging window of the background model
  double top_fraction = 0.05;    // histogram threshold: keep the top 5 % of differences ...
  int threshold_floor = 16;      // ... but never below this difference (6 |d| / sigma: 16 ~ 2.7 sigma)
  double min_area_fraction = 0.001;  // regions under 0.1 % of the image are dropped
  int close_size = 5;            // closing after the 3x3 opening (work pixels; 1 = none)
  // Frames wider are area-downsampled by ceil(width / work_width): 640x480 runs on 320x240, 1080p
  // on 320x180 (ave-bench detect: the same MOTA as full size at three times the speed).
  int work_width = 320;
  double global_change_fraction = 0.3;
  // The background model on the grey work image plus a chroma plane at half its resolution (the
  // blue-red opponent 128 + (B - R) / 2; difference = the larger of the two), not on grey alone:
  // a blue coat on green grass can have the grass's grey level. Gain compensation scales grey only.
  bool colour = true;
  TrackerOptions tracker;

  std::string Check() const;  // empty when usable, else names the field
};

// A validated track in full-frame pixels: corners clockwise from the top-left, origin at the
// top-left pixel's corner (the wire's Point2 convention).
struct Detection {
  uint32_t track_id = 0;
  std::array<std::array<float, 2>, 4> corners{};
  float score = 0;
};

struct DetectorStats {
  int64_t frames = 0;
  int64_t global_changes = 0;  // background resets after sudden scene-wide changes
  int regions = 0;             // regions kept in the last frame
  int threshold = 0;           // threshold used in the last frame
};

class Detector {
 public:
  // Throws std::invalid_argument with Check()'s reason for unusable options (programmer error).
  explicit Detector(DetectorOptions options = {});
  ~Detector();
  Detector(Detector&&) noexcept;
  Detector& operator=(Detector&&) noexcept;

  // One BGR frame (3 bytes per pixel, top row first) at t_s seconds. A frame of another size than
  // the last restarts the detector (new background). Empty or null frames give no tracks.
  std::vector<Detection> Process(const uint8_t* bgr, int width, int height, double t_s);

  // Delayed output: the boxes, in full-frame pixels, of the tracks validated by the last Process
  // call during their validation time (time of each frame, detection with the new id). A consumer
  // that holds its output for validate_s can add them to the frames where they were pending; the
  // live output never contains them.
  const std::vector<std::pair<double, Detection>>& backfill() const;

  // The last frame's foreground mask on the work image (0 / 255) and its size, for tests/plots.
  const std::vector<uint8_t>& foreground() const;
  int work_width() const;
  int work_height() const;
  const DetectorStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::detect
