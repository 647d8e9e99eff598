#pragma once
// Test-only: a cheap synthetic camera — flat 64x48 frames whose grey level changes every frame,
// stamped by `clock` (default: the wall clock), with a fixed pose. For streaming and fault tests
// that need frames, not pictures.
#include <functional>
#include <string>
#include <utility>

#include "model_store/common/log.h"
#include "sensor_agent/source/frame_source.h"

namespace ave::fixtures {

class FakeSource : public FrameSource {
 public:
  explicit FakeSource(std::function<int64_t()> clock = NowNs) : clock_(std::move(clock)) {}
  absl::StatusOr<CapturedFrame> Next() override {
    CapturedFrame f;
    f.capture_time_ns = clock_();
    f.width = 64;
    f.height = 48;
    f.bgr.assign(64 * 48 * 3, static_cast<uint8_t>(n_++ * 7));
    f.world_from_camera = LookAt({0, 0, 10}, {10, 0, 0});
    return f;
  }
  PinholeIntrinsics intrinsics() const override { return PinholeIntrinsics::FromFov(64, 48, 60); }
  std::string description() const override { return "fake"; }
  bool live() const override { return false; }

 private:
  std::function<int64_t()> clock_;
  int n_ = 0;
};

}  // namespace ave::fixtures
