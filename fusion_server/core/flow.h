#pragma once
// Flow control (MISSION part G, issue 8): what the server asks of each sensor when the server or
// the viewers' links are saturated. Pure arithmetic over measured rates; the service feeds it.
#include <chrono>
#include <cstdint>
#include <deque>
#include <mutex>

namespace ave {

struct FlowOptions {
  float max_fps = 30;             // never ask for more than this (0 = no cap)
  uint32_t jpeg_quality = 0;      // quality asked when not saturated (0 = keep the sensor's)
  double max_ingest_fps = 0;      // server-wide frame budget, frames/s (0 = unlimited)
  double max_ingest_mbps = 0;     // server-wide byte budget, MB/s (0 = unlimited)
  double viewer_drop_ratio_high = 0.25;  // viewers skip more than this: their links are saturated
  uint32_t saturated_quality = 60;       // JPEG quality asked while the byte budget or links are saturated
};

struct FlowInputs {
  int active_streams = 0;
  double ingest_fps = 0;        // measured, all sensors, frames/s
  double ingest_mbps = 0;       // measured, MB/s
  double viewer_drop_ratio = 0;  // frames skipped for viewers / frames offered to viewers, last window
};

struct FlowDecision {
  float max_fps = 0;          // 0 = no limit
  uint32_t jpeg_quality = 0;  // 0 = keep yours
  bool saturated = false;
};

// Per-sensor fps = min(max_fps, max_ingest_fps / active_streams); JPEG quality drops to
// saturated_quality when the byte budget is exceeded; both halve/drop when viewers skip more than
// viewer_drop_ratio_high of the frames offered to them.
FlowDecision DecideFlow(const FlowOptions& options, const FlowInputs& in);

// Events and bytes in a sliding window (default 1 s), thread-safe. Rates are per second.
class RateWindow {
 public:
  using Clock = std::chrono::steady_clock;
  explicit RateWindow(std::chrono::milliseconds window = std::chrono::milliseconds(1000)) : window_(window) {}
  void Add(uint64_t bytes, Clock::time_point now = Clock::now());
  double EventsPerSecond(Clock::time_point now = Clock::now());
  double BytesPerSecond(Clock::time_point now = Clock::now());

 private:
  void TrimLocked(Clock::time_point now);
  std::chrono::milliseconds window_;
  std::mutex mu_;
  std::deque<std::pair<Clock::time_point, uint64_t>> events_;
  uint64_t bytes_ = 0;
};

}  // namespace ave
