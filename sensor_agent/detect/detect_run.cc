#include "sensor_agent/detect/detect_run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>

#include "absl/strings/str_cat.h"

namespace ave::detect {

std::string DetectRunSummary::ToJson() const {
  char buf[256];
  std::snprintf(buf, sizeof buf, "{\"frames\":%lld,\"distinct_tracks\":%lld,\"fps\":%.2f,\"detect_fps\":%.2f}",
                static_cast<long long>(frames), static_cast<long long>(distinct_tracks),
                seconds > 0 ? frames / seconds : 0.0, detect_seconds > 0 ? frames / detect_seconds : 0.0);
  return buf;
}

std::string FrameJson(int64_t frame, double t_s, const std::vector<Detection>& tracks) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "{\"frame\":%lld,\"t\":%.4f,\"tracks\":[", static_cast<long long>(frame), t_s);
  std::string s = buf;
  for (size_t i = 0; i < tracks.size(); ++i) {
    const Detection& d = tracks[i];
    std::snprintf(buf, sizeof buf, "%s{\"id\":%u,\"box\":[[%.1f,%.1f],[%.1f,%.1f],[%.1f,%.1f],[%.1f,%.1f]],\"score\":%.3f}",
                  i ? "," : "", d.track_id, d.corners[0][0], d.corners[0][1], d.corners[1][0], d.corners[1][1],
                  d.corners[2][0], d.corners[2][1], d.corners[3][0], d.corners[3][1], d.score);
    s += buf;
  }
  return s + "]}";
}

void DelayedWriter::Add(int64_t frame, double t_s, std::vector<Detection> tracks,
                        const std::vector<std::pair<double, Detection>>& backfill) {
  held_.push_back({frame, t_s, std::move(tracks)});
  // Back-fill times are the t_s of earlier Process calls: they equal held records' times (the
  // tolerance is only a guard). A record exactly latency_s old is still held.
  constexpr double kSame = 1e-6;
  while (!held_.empty() && (latency_s_ <= 0 || held_.front().t_s < t_s - latency_s_ - kSame)) {
    out_ << FrameJson(held_.front().frame, held_.front().t_s, held_.front().tracks) << '\n';
    held_.pop_front();
  }
  for (const auto& [bt, det] : backfill) {
    for (auto it = held_.rbegin(); it != held_.rend(); ++it) {
      if (std::fabs(it->t_s - bt) > kSame) continue;
      it->tracks.push_back(det);
      ++backfilled_;
      break;
    }
  }
}

void DelayedWriter::Flush() {
  for (const Record& r : held_) out_ << FrameJson(r.frame, r.t_s, r.tracks) << '\n';
  held_.clear();
  out_.flush();
}

absl::StatusOr<DetectRunSummary> RunDetectOnly(FrameSource& source, const DetectorOptions& options, std::ostream& out,
                                               int64_t max_frames, double latency_s) {
  using Clock = std::chrono::steady_clock;
  static const std::vector<std::pair<double, Detection>> kNoBackfill;
  Detector detector(options);
  DelayedWriter writer(out, std::max(0.0, latency_s));
  DetectRunSummary summary;
  std::set<uint32_t> ids;
  const auto start = Clock::now();
  while (max_frames <= 0 || summary.frames < max_frames) {
    absl::StatusOr<CapturedFrame> frame = source.Next();
    if (absl::IsOutOfRange(frame.status())) break;
    if (!frame.ok()) {
      return absl::Status(frame.status().code(),
                          absl::StrCat(source.description(), ": frame ", summary.frames, ": ", frame.status().message()));
    }
    const auto t0 = Clock::now();
    const std::vector<Detection> tracks = detector.Process(frame->bgr.data(), frame->width, frame->height, frame->scene_time_s);
    summary.detect_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    for (const Detection& d : tracks) ids.insert(d.track_id);
    writer.Add(summary.frames, frame->scene_time_s, tracks, latency_s > 0 ? detector.backfill() : kNoBackfill);
    ++summary.frames;
  }
  writer.Flush();
  summary.distinct_tracks = static_cast<int64_t>(ids.size());
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

}  // namespace ave::detect
