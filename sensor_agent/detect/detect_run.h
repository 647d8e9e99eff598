#pragma once
// `ave-agent --detect-only`: detection and tracking on any FrameSource without a server, one JSON
// object per frame to a stream and a summary at the end.
#include <cstdint>
#include <ostream>
#include <string>

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

// Runs until the source ends (OutOfRange), `max_frames` (0 = no limit) or a read error (returned).
absl::StatusOr<DetectRunSummary> RunDetectOnly(FrameSource& source, const DetectorOptions& options, std::ostream& out,
                                               int64_t max_frames = 0);

}  // namespace ave::detect
