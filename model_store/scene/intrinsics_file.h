#pragma once
// The intrinsics file `ave-calibrate` writes and `ave-agent --intrinsics` / `ave-admin
// add-camera --intrinsics` read (docs/POSE.md): strict YAML with the scenario camera's field
// names, so a calibration can be pasted into a scenario file:
//   width: 640
//   height: 480
//   fx: 500.1
//   fy: 499.8
//   cx: 319.6
//   cy: 239.4
//   distortion: [k1, k2, p1, p2, k3]   # Brown-Conrady, OpenCV order
//   rms_px: 0.21                        # optional, informational
//   images_used: 14                     # optional, informational
// Unknown keys are errors ("cam.yaml:3: intrinsics.fxx: unknown key (did you mean fx?)").
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"

namespace ave::calib {

absl::StatusOr<PinholeIntrinsics> ReadIntrinsicsFile(const std::string& path);
absl::StatusOr<PinholeIntrinsics> ParseIntrinsicsYaml(const std::string& text, const std::string& label);
// `rms_px` < 0 and `images_used` < 0 are left out.
absl::Status WriteIntrinsicsFile(const std::string& path, const PinholeIntrinsics& k, double rms_px = -1, int images_used = -1);

}  // namespace ave::calib
