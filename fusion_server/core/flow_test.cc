#include "fusion_server/core/flow.h"

#include <gtest/gtest.h>

namespace ave {
namespace {

TEST(Flow, Unsaturated_PassesTheConfiguredHint) {
  const FlowDecision d = DecideFlow({.max_fps = 30, .jpeg_quality = 0}, {.active_streams = 10, .ingest_fps = 150});
  EXPECT_FLOAT_EQ(d.max_fps, 30);
  EXPECT_EQ(d.jpeg_quality, 0u);
  EXPECT_FALSE(d.saturated);
}

TEST(Flow, FrameBudget_IsSharedBetweenStreams) {
  const FlowDecision d =
      DecideFlow({.max_fps = 30, .max_ingest_fps = 600}, {.active_streams = 100, .ingest_fps = 1000});
  EXPECT_FLOAT_EQ(d.max_fps, 6);
  EXPECT_TRUE(d.saturated);
}

TEST(Flow, ByteBudgetExceeded_LowersQuality) {
  const FlowDecision d = DecideFlow({.max_fps = 30, .max_ingest_mbps = 20, .saturated_quality = 55},
                                    {.active_streams = 50, .ingest_fps = 750, .ingest_mbps = 38});
  EXPECT_EQ(d.jpeg_quality, 55u);
  EXPECT_TRUE(d.saturated);
}

TEST(Flow, SlowViewers_HalveTheMeasuredRateButNeverBelowOneFps) {
  FlowDecision d = DecideFlow({.max_fps = 30}, {.active_streams = 10, .ingest_fps = 200, .viewer_drop_ratio = 0.5});
  EXPECT_FLOAT_EQ(d.max_fps, 10);
  d = DecideFlow({.max_fps = 30}, {.active_streams = 10, .ingest_fps = 5, .viewer_drop_ratio = 0.9});
  EXPECT_FLOAT_EQ(d.max_fps, 1);
}

TEST(Flow, RateWindow_ForgetsEventsOlderThanTheWindow) {
  RateWindow w(std::chrono::milliseconds(1000));
  const auto t0 = RateWindow::Clock::now();
  for (int i = 0; i < 10; ++i) w.Add(100, t0 + std::chrono::milliseconds(50 * i));
  EXPECT_DOUBLE_EQ(w.EventsPerSecond(t0 + std::chrono::milliseconds(500)), 10);
  EXPECT_DOUBLE_EQ(w.BytesPerSecond(t0 + std::chrono::milliseconds(500)), 1000);
  EXPECT_DOUBLE_EQ(w.EventsPerSecond(t0 + std::chrono::milliseconds(1300)), 4);  // events at 300..450 ms remain
  EXPECT_DOUBLE_EQ(w.EventsPerSecond(t0 + std::chrono::seconds(5)), 0);
}

}  // namespace
}  // namespace ave
