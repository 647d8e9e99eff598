#include "sensor_agent/sim/effects.h"

namespace ave::sim {
namespace {

constexpr const char* kNames[kEffectCount] = {
    "gps_noise",         "gps_multipath",      "gps_dropout",           "imu_noise",
    "gyro_drift",        "magnetic_disturbance", "camera_noise",        "illumination",
    "jpeg_artefacts",    "rolling_occlusion",  "waving_vegetation",     "pixel_area",
    "lidar_range_noise",
    "lidar_ring_pattern", "lidar_missing_returns", "lidar_intensity_by_material",
};

std::array<std::atomic<uint64_t>, kEffectCount>& Counters() {
  static std::array<std::atomic<uint64_t>, kEffectCount> counters{};
  return counters;
}

}  // namespace

const char* EffectName(EffectKind kind) {
  const int i = static_cast<int>(kind);
  return i >= 0 && i < kEffectCount ? kNames[i] : "unknown";
}

std::optional<EffectKind> EffectFromName(const std::string& name) {
  for (int i = 0; i < kEffectCount; ++i)
    if (name == kNames[i]) return static_cast<EffectKind>(i);
  return std::nullopt;
}

std::vector<std::string> AllEffectNames() { return std::vector<std::string>(std::begin(kNames), std::end(kNames)); }

void EffectSet::Enable(EffectKind kind, EffectParams params) {
  enabled_[static_cast<int>(kind)] = true;
  params_[static_cast<int>(kind)] = std::move(params);
}

bool EffectSet::empty() const {
  for (bool e : enabled_)
    if (e) return false;
  return true;
}

void CountEvaluation(EffectKind kind, uint64_t n) { Counters()[static_cast<int>(kind)].fetch_add(n, std::memory_order_relaxed); }
uint64_t Evaluations(EffectKind kind) { return Counters()[static_cast<int>(kind)].load(std::memory_order_relaxed); }
void ResetEvaluations() {
  for (auto& c : Counters()) c.store(0, std::memory_order_relaxed);
}

}  // namespace ave::sim
