#pragma once
// Small fixtures shared by the fusion_server service tests (test-only header).
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "ave/v1/ave.pb.h"
#include "fusion_server/core/convert.h"

namespace ave::fixtures {

// A real, decodable JPEG of the given size.
inline std::string Jpeg(int w, int h) {
  std::vector<uchar> bytes;
  cv::imencode(".jpg", cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 200, 30)), bytes);
  return std::string(bytes.begin(), bytes.end());
}

// A valid 64x48 camera record looking along +x from 10 m up.
inline v1::Camera CameraRecord(const std::string& id) {
  v1::Camera c;
  c.set_id(id);
  c.set_name("Test " + id);
  *c.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
  *c.mutable_mounting_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
  c.set_enabled(true);
  return c;
}

}  // namespace ave::fixtures
