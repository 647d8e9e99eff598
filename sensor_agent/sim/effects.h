#pragma once
// The simulator's effects catalogue (MISSION standing demand 3: simulate only the effects a scene
// calls for). A scenario names effects with parameters; every effect is a separate piece of code
// that runs only when named. Each effect implementation calls CountEvaluation(kind) once per
// evaluation *inside* its own body, so a test can prove that an effect not named was never run.
#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace ave::sim {

enum class EffectKind : int {
  // GPS
  kGpsNoise = 0,
  kGpsMultipath,
  kGpsDropout,
  // inertial
  kImuNoise,
  kGyroDrift,
  kMagneticDisturbance,
  // camera
  kCameraNoise,
  kIllumination,
  kJpegArtefacts,
  kRollingOcclusion,
  kWavingVegetation,  // images and LiDAR
  kPixelArea,         // camera: each pixel integrates its area (renderer side)
  // LiDAR
  kLidarRangeNoise,
  kLidarRingPattern,
  kLidarMissingReturns,
  kLidarIntensityByMaterial,
  kCount
};

inline constexpr int kEffectCount = static_cast<int>(EffectKind::kCount);
// pixel_area's `samples` (per image axis) ranges over 1..kMaxPixelAreaSamples.
inline constexpr int kMaxPixelAreaSamples = 5;

// Scenario names: "gps_noise", "gps_multipath", ... (snake case of the enumerator).
const char* EffectName(EffectKind kind);
std::optional<EffectKind> EffectFromName(const std::string& name);
std::vector<std::string> AllEffectNames();

// Named numeric parameters of one effect, e.g. {"sigma_m": 0.05}.
struct EffectParams {
  std::map<std::string, double> values;
  double Get(const std::string& key, double fallback) const {
    auto it = values.find(key);
    return it == values.end() ? fallback : it->second;
  }
};

// The effects a scenario names. Copyable; lookups are cheap.
class EffectSet {
 public:
  void Enable(EffectKind kind, EffectParams params = {});
  bool Has(EffectKind kind) const { return enabled_[static_cast<int>(kind)]; }
  // The effect's parameters, or nullptr when the scenario does not name it.
  const EffectParams* Find(EffectKind kind) const { return Has(kind) ? &params_[static_cast<int>(kind)] : nullptr; }
  bool empty() const;

 private:
  std::array<bool, kEffectCount> enabled_{};
  std::array<EffectParams, kEffectCount> params_{};
};

// Process-wide evaluation counters, one per effect (relaxed atomics: tests and ave-bench read them).
void CountEvaluation(EffectKind kind, uint64_t n = 1);
uint64_t Evaluations(EffectKind kind);
void ResetEvaluations();

}  // namespace ave::sim
