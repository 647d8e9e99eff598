#pragma once
// Camera intrinsics from chessboard images by Zhang's method (AVE §5.1: "Our camera is calibrated
// by using the method described in Zhang (2000)"), through OpenCV's findChessboardCorners,
// cornerSubPix and calibrateCamera. OpenCV stays in calibrate.cc.
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"

namespace ave::calib {

struct BoardSpec {
  int cols = 0, rows = 0;  // inner corners per row and per column
  double square_m = 0;     // side of one square
  std::string Check() const;
};

// "9x6" -> cols 9, rows 6; false otherwise.
bool ParseBoardSize(const std::string& text, int& cols, int& rows);

struct CalibrationResult {
  PinholeIntrinsics intrinsics;  // fx fy cx cy and k1 k2 p1 p2 k3
  int images_given = 0;
  int images_used = 0;                  // the board was found
  std::vector<std::string> skipped;     // "path: why" for each image not used
  double rms_px = 0;                    // RMS reprojection error over all corners
  double max_tilt_spread_deg = 0;       // largest angle between two views' board normals
};

// Files matching a glob pattern ("DIR/*.jpg"), sorted.
std::vector<std::string> GlobFiles(const std::string& pattern);

// Refuses sets that cannot constrain the model: fewer than `min_views` (default 3) usable
// images, images of different sizes, or all boards parallel to each other (normals within
// `min_tilt_spread_deg`, default 5°: Zhang's degenerate configuration).
absl::StatusOr<CalibrationResult> CalibrateFromImages(const std::vector<std::string>& paths, const BoardSpec& board,
                                                      int min_views = 3, double min_tilt_spread_deg = 5);

// The one-line JSON summary ave-calibrate prints.
std::string SummaryJson(const CalibrationResult& r, const std::string& out_path);

}  // namespace ave::calib
