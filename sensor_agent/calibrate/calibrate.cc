#include "sensor_agent/calibrate/calibrate.h"

#include <glob.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "model_store/image/image_decode.h"

namespace ave::calib {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

// Board normal in the camera frame from the board-to-image homography with a rough K (focal length
// = image width, principal point at the centre): enough to tell parallel views from tilted ones.
cv::Vec3d BoardNormal(const std::vector<cv::Point2f>& board, const std::vector<cv::Point2f>& image, cv::Size size) {
  const cv::Mat H = cv::findHomography(board, image);
  if (H.empty()) return {0, 0, 0};
  const cv::Matx33d K(size.width, 0, 0.5 * size.width, 0, size.width, 0.5 * size.height, 0, 0, 1);
  const cv::Matx33d M = K.inv() * cv::Matx33d(H);
  const cv::Vec3d r1(M(0, 0), M(1, 0), M(2, 0)), r2(M(0, 1), M(1, 1), M(2, 1));
  const cv::Vec3d n = cv::normalize(cv::normalize(r1).cross(cv::normalize(r2)));
  return n[2] < 0 ? -n : n;
}

}  // namespace

std::string BoardSpec::Check() const {
  if (cols < 2 || rows < 2) return "the board needs at least 2x2 inner corners";
  if (cols == rows) return "a square board (COLS == ROWS) is ambiguous in orientation; use COLS != ROWS";
  if (!std::isfinite(square_m) || square_m <= 0) return "square size must be finite and > 0 metres";
  return {};
}

bool ParseBoardSize(const std::string& text, int& cols, int& rows) {
  std::stringstream ss(text);
  char x = 0;
  return (ss >> cols >> x >> rows) && (x == 'x' || x == 'X') && (ss >> std::ws).eof() && cols > 0 && rows > 0;
}

std::vector<std::string> GlobFiles(const std::string& pattern) {
  std::vector<std::string> out;
  glob_t g{};
  if (glob(pattern.c_str(), 0, nullptr, &g) == 0) {
    for (size_t i = 0; i < g.gl_pathc; ++i) out.emplace_back(g.gl_pathv[i]);
  }
  globfree(&g);
  std::sort(out.begin(), out.end());
  return out;
}

absl::StatusOr<CalibrationResult> CalibrateFromImages(const std::vector<std::string>& paths, const BoardSpec& board, int min_views,
                                                      double min_tilt_spread_deg) {
  if (const std::string why = board.Check(); !why.empty()) return absl::InvalidArgumentError(why);
  CalibrationResult result;
  result.images_given = static_cast<int>(paths.size());
  const cv::Size pattern(board.cols, board.rows);
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> object_2d;
  for (int r = 0; r < board.rows; ++r) {
    for (int c = 0; c < board.cols; ++c) {
      object.emplace_back(static_cast<float>(c * board.square_m), static_cast<float>(r * board.square_m), 0.f);
      object_2d.emplace_back(object.back().x, object.back().y);
    }
  }
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  std::vector<cv::Vec3d> normals;
  cv::Size size;
  for (const std::string& path : paths) {
    // Through the checked decoder (issue 14): JPEG or PNG, header size within limits, the reason kept.
    absl::StatusOr<cv::Mat> decoded = image::ReadImageFile(path, image::Channels::kGray);
    if (!decoded.ok()) {
      std::string why(decoded.status().message());
      if (why.rfind(path + ": ", 0) == 0) why = why.substr(path.size() + 2);
      result.skipped.push_back(absl::StrCat(path, ": not a readable image (", why, ")"));
      continue;
    }
    const cv::Mat gray = *std::move(decoded);
    if (size.area() > 0 && gray.size() != size) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": image size ", gray.cols, "x", gray.rows, " differs from the first image's ",
                                                     size.width, "x", size.height));
    }
    std::vector<cv::Point2f> corners;
    if (!cv::findChessboardCorners(gray, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
      result.skipped.push_back(absl::StrCat(path, ": no ", board.cols, "x", board.rows, " chessboard found"));
      continue;
    }
    size = gray.size();
    cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 1e-3));
    normals.push_back(BoardNormal(object_2d, corners, size));
    object_points.push_back(object);
    image_points.push_back(std::move(corners));
  }
  result.images_used = static_cast<int>(image_points.size());
  if (result.images_used < min_views) {
    return absl::InvalidArgumentError(absl::StrCat("too few views: the board was found in ", result.images_used, " of ", paths.size(),
                                                   " images; Zhang's method needs at least ", min_views, " views at different tilts"));
  }
  for (size_t i = 0; i < normals.size(); ++i) {
    for (size_t j = i + 1; j < normals.size(); ++j) {
      const double c = std::clamp(normals[i].dot(normals[j]), -1.0, 1.0);
      result.max_tilt_spread_deg = std::max(result.max_tilt_spread_deg, std::acos(c) * kRadToDeg);
    }
  }
  if (result.max_tilt_spread_deg < min_tilt_spread_deg) {
    char buf[160];
    std::snprintf(buf, sizeof(buf), "all %d views are parallel (board normals within %.2f deg of each other, need >= %.1f): tilt the board",
                  result.images_used, result.max_tilt_spread_deg, min_tilt_spread_deg);
    return absl::InvalidArgumentError(buf);
  }
  cv::Mat K, dist;
  std::vector<cv::Mat> rvecs, tvecs;
  result.rms_px = cv::calibrateCamera(object_points, image_points, size, K, dist, rvecs, tvecs);
  PinholeIntrinsics& k = result.intrinsics;
  k.width = size.width;
  k.height = size.height;
  k.fx = K.at<double>(0, 0);
  k.fy = K.at<double>(1, 1);
  k.cx = K.at<double>(0, 2);
  k.cy = K.at<double>(1, 2);
  for (int i = 0; i < 5 && i < static_cast<int>(dist.total()); ++i) k.distortion[i] = dist.at<double>(i);
  if (const std::string why = k.Check(); !why.empty()) return absl::InternalError("calibration gave unusable intrinsics: " + why);
  return result;
}

std::string SummaryJson(const CalibrationResult& r, const std::string& out_path) {
  const PinholeIntrinsics& k = r.intrinsics;
  char buf[768];
  std::snprintf(buf, sizeof(buf),
                "{\"images_given\":%d,\"images_used\":%d,\"image_size\":[%d,%d],\"fx\":%.4f,\"fy\":%.4f,\"cx\":%.4f,\"cy\":%.4f,"
                "\"distortion\":[%.6g,%.6g,%.6g,%.6g,%.6g],\"rms_px\":%.4f,\"tilt_spread_deg\":%.1f,\"out\":\"%s\"}",
                r.images_given, r.images_used, k.width, k.height, k.fx, k.fy, k.cx, k.cy, k.distortion[0], k.distortion[1], k.distortion[2],
                k.distortion[3], k.distortion[4], r.rms_px, r.max_tilt_spread_deg, out_path.c_str());
  return buf;
}

}  // namespace ave::calib
