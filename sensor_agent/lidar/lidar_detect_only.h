#pragma once
// `ave-agent --source pcap:F|udp:P|sim:S#LIDAR --detect-only --out tracks.jsonl`: sweeps through a
// SweepTracker without a server (issue 16). One JSON object per revolution,
//   {"frame":N,"t":seconds,"tracks":[{"id":..,"x":..,"y":..}, ...]}
// (confirmed tracks only; x, y in metres in the tracker's ground frame; t = the sweep's t_ns in
// seconds: scenario time for the simulator, the capture clock for pcap/udp), then the caller
// prints the summary {"frames":..,"distinct_tracks":..,"fps":..} (fps = sweeps per wall second,
// source and tracker together).
#include <cstdint>
#include <ostream>
#include <string>

#include "absl/status/statusor.h"
#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar {

struct LidarDetectOnlySummary {
  int64_t frames = 0;
  int64_t distinct_tracks = 0;
  double seconds = 0;  // wall time
  int64_t skipped_packets = 0;  // live sources: bad datagrams dropped (logged, the first ten)
  std::string ToJson() const;
};

std::string SweepTracksJson(int64_t frame, int64_t t_ns, const FootTracks& tracks);

// Runs until the source ends (OutOfRange) or max_sweeps (0 = no limit). A source or tracker error
// ends the run with that error, after every record before it has been written; except that a
// live source's bad datagram (DataLoss) is logged and skipped.
absl::StatusOr<LidarDetectOnlySummary> RunLidarDetectOnly(LidarSource& source, const SweepTracker& tracker, std::ostream& out,
                                                          int64_t max_sweeps = 0);

}  // namespace ave::lidar
