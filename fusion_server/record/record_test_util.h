#pragma once
// Test helpers for the recorder and replay tests: a temporary recording (store file + directory)
// and real JPEG frames that differ per frame.
#include <unistd.h>

#include <filesystem>
#include <memory>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ave/v1/ave.pb.h"
#include "fusion_server/record/recorder.h"
#include "model_store/db/store.h"

namespace ave::record::testing {

class TempRecording {
 public:
  TempRecording() {
    root_ = std::filesystem::temp_directory_path() /
            ("ave_record_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter_++));
    std::filesystem::remove_all(root_);
    std::filesystem::create_directories(root_);
    auto store = store::Store::Open(store_path());
    EXPECT_TRUE(store.ok()) << store.status();
    store_ = *std::move(store);
  }
  ~TempRecording() { std::filesystem::remove_all(root_); }
  std::string store_path() const { return (root_ / "ave.db").string(); }
  std::string dir() const { return (root_ / "rec").string(); }
  store::Store& store() { return *store_; }

 private:
  static inline int counter_ = 0;
  std::filesystem::path root_;
  std::unique_ptr<store::Store> store_;
};

// A 160x120 JPEG whose content depends on `k` (a moving bar), so every frame's bytes differ.
inline std::string TestJpeg(int k, int width = 160, int height = 120) {
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(40, 80, 120));
  cv::rectangle(image, cv::Rect((k * 7) % width, 0, 12, height), cv::Scalar(250, 250, 250), cv::FILLED);
  cv::putText(image, std::to_string(k), cv::Point(10, height / 2), cv::FONT_HERSHEY_SIMPLEX, 1.0, cv::Scalar(0, 0, 255));
  std::vector<uchar> bytes;
  cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, 80});
  return std::string(bytes.begin(), bytes.end());
}

inline std::shared_ptr<v1::SensorFrame> TestFrame(uint64_t sequence, int64_t capture_ns, const std::string& jpeg) {
  auto frame = std::make_shared<v1::SensorFrame>();
  frame->set_sequence(sequence);
  frame->set_capture_time_ns(capture_ns);
  frame->set_jpeg(jpeg);
  v1::Pose* pose = frame->mutable_pose();
  pose->mutable_orientation()->set_w(1);
  pose->mutable_position()->set_x(static_cast<double>(sequence));
  for (int i = 0; i < 36; ++i) pose->add_covariance(i % 7 == 0 ? 0.01 : 0.0);
  auto* box = frame->add_boxes();
  box->set_track_id(static_cast<uint32_t>(sequence));
  return frame;
}

}  // namespace ave::record::testing
