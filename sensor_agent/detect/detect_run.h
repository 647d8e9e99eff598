#pragma once
// `ave-agent --detect-only`: detection and tracking on any FrameSource without a server, one JSON
// object per frame to a stream and a summary at the end.
#include <cstdint>
#include <deque>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "sensor_agent/detect/detector.h"
#include "sensor_agent/source/frame_source.h"

namespace ave::detect {

struct DetectRunSummary {
  int64_t frames = 0;
  int64_t distinct_tracks = 0;
  double seconds = 0;         // wall time of the whole loop (capture + detection)
  double detect_seconds = 0;  // of which detection and tracking
  std::string ToJson() const;  // one line: frames, distinct_tracks, fps, detect_fps
};

// One frame as JSON: {"frame":N,"t":S,"tracks":[{"id":I,"box":[[x,y],[x,y],[x,y],[x,y]],"score":F}]}.
std::string FrameJson(int64_t frame, double t_s, const std::vector<Detection>& tracks);

// Near-online output (MOT "latency"): each frame's record is held `latency_s` seconds of source
// time before it is written, and the boxes of tracks validated meanwhile are written back into the
// held frames where they were pending (Detector::backfill(), same ids). With latency >=
// validate_s + tentative_gap_s every pending box is written back; validate_s (--detect-only's
// default) drops only those of a candidate that missed its last frames before validating; 0
// writes each frame at once (live).
class DelayedWriter {
 public:
  DelayedWriter(std::ostream& out, double latency_s) : out_(out), latency_s_(latency_s) {}
  // Adds the frame's record, writes the frames older than t_s - latency_s, then adds the back-fill
  // to the held frames with those times; back-fill older than t_s - latency_s is dropped.
  void Add(int64_t frame, double t_s, std::vector<Detection> tracks,
           const std::vector<std::pair<double, Detection>>& backfill);
  void Flush();  // writes every held frame
  int64_t backfilled() const { return backfilled_; }  // boxes written back so far

 private:
  struct Record {
    int64_t frame;
    double t_s;
    std::vector<Detection> tracks;
  };
  std::ostream& out_;
  double latency_s_;
  std::deque<Record> held_;
  int64_t backfilled_ = 0;
};

// Runs until the source ends (OutOfRange), `max_frames` (0 = no limit) or a read error (returned).
// `latency_s` > 0: near-online output through DelayedWriter (the summary does not change: the
// back-filled boxes carry ids the live output already has).
absl::StatusOr<DetectRunSummary> RunDetectOnly(FrameSource& source, const DetectorOptions& options, std::ostream& out,
                                               int64_t max_frames = 0, double latency_s = 0);

}  // namespace ave::detect
