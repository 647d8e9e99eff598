#pragma once
// What the camera and the LiDAR uplinks (agent_streamer.cc, lidar_streamer.cc) share about their
// link to the server: the channel's keepalive settings, which refusals are final, and a sleep that
// a stop request cuts short. Internal to sensor_agent/stream.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <random>
#include <thread>

#include <grpcpp/grpcpp.h>

namespace ave::stream_link {

using Clock = std::chrono::steady_clock;

// Sleeps up to `duration`, waking early when `stop` is set.
inline void SleepUnlessStopped(Clock::duration duration, const std::atomic<bool>& stop) {
  const auto until = Clock::now() + duration;
  while (!stop.load() && Clock::now() < until) {
    std::this_thread::sleep_for(std::min<Clock::duration>(until - Clock::now(), std::chrono::milliseconds(20)));
  }
}

// The next tick of a loop paced at `hz` after `next_tick`, seen at `now`: one period on. A loop
// late by at most `max_lag` keeps its schedule (the next ticks come sooner, so its average rate
// holds through a slow iteration, as a camera's clock does not wait for its reader); later than
// that, the schedule restarts from `now`.
inline Clock::time_point NextTick(Clock::time_point next_tick, double hz, Clock::time_point now,
                                  Clock::duration max_lag = Clock::duration::zero()) {
  next_tick += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
  return next_tick < now - max_lag ? now : next_tick;
}

// Paces a loop at `hz`: moves `next_tick` on (NextTick) and sleeps until it.
inline void PaceTo(Clock::time_point& next_tick, double hz, const std::atomic<bool>& stop,
                   Clock::duration max_lag = Clock::duration::zero()) {
  const Clock::time_point now = Clock::now();
  next_tick = NextTick(next_tick, hz, now, max_lag);
  if (next_tick > now) SleepUnlessStopped(next_tick - now, stop);
}

// Jittered exponential backoff: a random wait in [backoff/2, backoff] (the caller doubles it).
template <class Rng>
std::chrono::milliseconds JitteredWait(std::chrono::milliseconds backoff, Rng& rng) {
  std::uniform_int_distribution<int64_t> jitter(backoff.count() / 2, backoff.count());
  return std::chrono::milliseconds(jitter(rng));
}

// The server refused this sensor's credentials: retrying cannot help.
inline bool IsFatal(grpc::StatusCode code) {
  return code == grpc::StatusCode::UNAUTHENTICATED || code == grpc::StatusCode::PERMISSION_DENIED;
}

// HTTP/2 keepalive pings every `keepalive` (the server permits one every 0.5 s), even without
// calls, so a silent dead link is noticed in about two intervals; the connect attempt is bounded
// by twice the interval (RELIABILITY.md, "blocked link").
inline grpc::ChannelArguments SensorChannelArgs(std::chrono::milliseconds keepalive) {
  grpc::ChannelArguments args;
  const int keepalive_ms = static_cast<int>(keepalive.count());
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, keepalive_ms);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, keepalive_ms);
  args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 2 * keepalive_ms);  // also the connect timeout
  return args;
}

}  // namespace ave::stream_link
