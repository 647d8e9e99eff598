#include "sensor_agent/lidar/lidar_detect_only.h"

#include <chrono>
#include <cstdio>
#include <set>

#include "absl/strings/str_cat.h"
#include "model_store/common/log.h"

namespace ave::lidar {

std::string LidarDetectOnlySummary::ToJson() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "{\"frames\":%lld,\"distinct_tracks\":%lld,\"fps\":%.2f}", static_cast<long long>(frames),
                static_cast<long long>(distinct_tracks), seconds > 0 ? frames / seconds : 0.0);
  return buf;
}

std::string SweepTracksJson(int64_t frame, int64_t t_ns, const FootTracks& tracks) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "{\"frame\":%lld,\"t\":%.6f,\"tracks\":[", static_cast<long long>(frame), t_ns * 1e-9);
  std::string s = buf;
  bool first = true;
  for (const FootTrack& t : tracks.tracks) {
    if (!t.confirmed) continue;
    std::snprintf(buf, sizeof buf, "%s{\"id\":%u,\"x\":%.3f,\"y\":%.3f}", first ? "" : ",", t.id, t.xy_m.x(), t.xy_m.y());
    s += buf;
    first = false;
  }
  return s + "]}";
}

absl::StatusOr<LidarDetectOnlySummary> RunLidarDetectOnly(LidarSource& source, const SweepTracker& tracker, std::ostream& out,
                                                          int64_t max_sweeps) {
  using Clock = std::chrono::steady_clock;
  LidarDetectOnlySummary summary;
  std::set<uint32_t> ids;
  const auto start = Clock::now();
  absl::Status error;
  while (max_sweeps <= 0 || summary.frames < max_sweeps) {
    absl::StatusOr<LidarSweep> sweep = source.Next();
    if (absl::IsOutOfRange(sweep.status())) break;
    if (absl::IsDataLoss(sweep.status()) && source.live()) {
      // A live stream drops the bad datagram and goes on; a file stops at its first bad packet.
      if (summary.skipped_packets++ < 10) AVE_LOG(WARNING) << sweep.status().message();
      continue;
    }
    if (!sweep.ok()) {
      error = absl::Status(sweep.status().code(), absl::StrCat(source.description(), ": after sweep ", summary.frames, ": ",
                                                               sweep.status().message()));
      break;
    }
    absl::StatusOr<FootTracks> tracks = tracker(*sweep);
    if (!tracks.ok()) {
      error = absl::Status(tracks.status().code(), absl::StrCat("tracker: sweep ", summary.frames, ": ", tracks.status().message()));
      break;
    }
    for (const FootTrack& t : tracks->tracks) {
      if (t.confirmed) ids.insert(t.id);
    }
    out << SweepTracksJson(summary.frames, sweep->t_ns, *tracks) << '\n';
    ++summary.frames;
  }
  out.flush();
  if (!error.ok()) return error;
  summary.distinct_tracks = static_cast<int64_t>(ids.size());
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

}  // namespace ave::lidar
