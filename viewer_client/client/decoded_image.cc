#include "viewer_client/client/decoded_image.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/status/status.h"
#include "model_store/image/image_decode.h"

namespace ave::viewer {

absl::StatusOr<std::shared_ptr<const DecodedImage>> DecodeJpegFrame(const std::string& jpeg, int reduction) {
  absl::StatusOr<image::ImageHeader> header = image::PeekImageHeader(jpeg);
  if (header.ok() && header->format != image::ImageFormat::kJpeg) {
    return absl::InvalidArgumentError("a camera frame must be a JPEG, not a PNG");
  }
  absl::StatusOr<cv::Mat> bgr = image::DecodeImage(jpeg, image::Channels::kColor, reduction);
  if (!bgr.ok()) return bgr.status();
  auto image = std::make_shared<DecodedImage>();
  image->width = bgr->cols;
  image->height = bgr->rows;
  image->rgba.resize(size_t(bgr->cols) * bgr->rows * 4);
  cv::Mat rgba(bgr->rows, bgr->cols, CV_8UC4, image->rgba.data());
  cv::cvtColor(*bgr, rgba, cv::COLOR_BGR2RGBA);
  return std::shared_ptr<const DecodedImage>(std::move(image));
}

std::shared_ptr<const DecodedImage> DecodeJpeg(const std::string& jpeg, int reduction) {
  absl::StatusOr<std::shared_ptr<const DecodedImage>> image = DecodeJpegFrame(jpeg, reduction);
  return image.ok() ? *std::move(image) : nullptr;
}

}  // namespace ave::viewer
