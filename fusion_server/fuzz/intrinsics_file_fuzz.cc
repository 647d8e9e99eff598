// libFuzzer target: the intrinsics YAML that `ave-calibrate` writes and `ave-agent --intrinsics`
// and `ave-admin add-camera --intrinsics` read (model_store/scene/intrinsics_file.h). Issue 14
// listed it as not fuzzed. An accepted file must describe a usable camera (Check() empty, every
// number finite) and survive a write and read back unchanged.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "model_store/scene/intrinsics_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::PinholeIntrinsics> k = ave::calib::ParseIntrinsicsYaml(text, "fuzz.yaml");
  if (!k.ok()) {
    if (k.status().message().empty()) __builtin_trap();
    return 0;
  }
  if (!k->Check().empty()) __builtin_trap();
  for (double v : {k->fx, k->fy, k->cx, k->cy}) {
    if (!std::isfinite(v)) __builtin_trap();
  }
  for (double d : k->distortion) {
    if (!std::isfinite(d)) __builtin_trap();
  }
  static const std::string path = "/tmp/ave_fuzz_intrinsics_" + std::to_string(::getpid()) + ".yaml";
  if (!ave::calib::WriteIntrinsicsFile(path, *k).ok()) __builtin_trap();
  absl::StatusOr<ave::PinholeIntrinsics> back = ave::calib::ReadIntrinsicsFile(path);
  if (!back.ok() || back->width != k->width || back->height != k->height || back->fx != k->fx ||
      back->fy != k->fy || back->cx != k->cx || back->cy != k->cy || back->distortion != k->distortion) {
    __builtin_trap();
  }
  return 0;
}
