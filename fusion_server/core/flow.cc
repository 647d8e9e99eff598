#include "fusion_server/core/flow.h"

#include <algorithm>

namespace ave {

FlowDecision DecideFlow(const FlowOptions& options, const FlowInputs& in) {
  FlowDecision d;
  d.max_fps = options.max_fps;
  d.jpeg_quality = options.jpeg_quality;
  if (options.max_ingest_fps > 0 && in.active_streams > 0) {
    const float share = static_cast<float>(options.max_ingest_fps / in.active_streams);
    d.max_fps = d.max_fps > 0 ? std::min(d.max_fps, share) : share;
    d.saturated |= in.ingest_fps > 0.95 * options.max_ingest_fps;
  }
  if (options.max_ingest_mbps > 0 && in.ingest_mbps > options.max_ingest_mbps) {
    d.jpeg_quality = options.saturated_quality;
    d.saturated = true;
  }
  if (in.viewer_drop_ratio > options.viewer_drop_ratio_high) {
    // Viewers cannot take what arrives: halve the rate actually measured per stream, lower quality.
    const float measured = in.active_streams > 0 ? static_cast<float>(in.ingest_fps / in.active_streams) : 0;
    const float halved = std::max(1.0f, measured / 2);
    d.max_fps = d.max_fps > 0 ? std::min(d.max_fps, halved) : halved;
    d.jpeg_quality = options.saturated_quality;
    d.saturated = true;
  }
  if (d.max_fps > 0) d.max_fps = std::max(d.max_fps, 1.0f);
  return d;
}

void RateWindow::TrimLocked(Clock::time_point now) {
  while (!events_.empty() && now - events_.front().first > window_) {
    bytes_ -= events_.front().second;
    events_.pop_front();
  }
}

void RateWindow::Add(uint64_t bytes, Clock::time_point now) {
  std::lock_guard lock(mu_);
  events_.emplace_back(now, bytes);
  bytes_ += bytes;
  TrimLocked(now);
}

double RateWindow::EventsPerSecond(Clock::time_point now) {
  std::lock_guard lock(mu_);
  TrimLocked(now);
  return events_.size() / std::chrono::duration<double>(window_).count();
}

double RateWindow::BytesPerSecond(Clock::time_point now) {
  std::lock_guard lock(mu_);
  TrimLocked(now);
  return bytes_ / std::chrono::duration<double>(window_).count();
}

}  // namespace ave
