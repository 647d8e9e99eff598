#include "model_store/studio/segmentation.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace ave::studio {

std::string SegmentationOptions::Check() const {
  if (!std::isfinite(min_difference) || min_difference < 0) return "min_difference must be finite and >= 0";
  if (!std::isfinite(max_chroma_distortion) || max_chroma_distortion < 0) return "max_chroma_distortion must be finite and >= 0";
  if (!(min_shadow_brightness >= 0 && min_shadow_brightness < max_shadow_brightness && std::isfinite(max_shadow_brightness))) {
    return "min_shadow_brightness must be >= 0 and below max_shadow_brightness";
  }
  if (open_radius_px < 0 || open_radius_px > 10) return "open_radius_px must be in [0, 10]";
  if (close_radius_px < 0 || close_radius_px > 10) return "close_radius_px must be in [0, 10]";
  return {};
}

absl::StatusOr<Mask> SegmentForeground(const Image& image, const Image& background, const SegmentationOptions& options,
                                       const std::string& camera, Mask* shadow) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("segmentation options: " + why);
  const size_t n = static_cast<size_t>(image.width) * image.height;
  if (image.width <= 0 || image.height <= 0 || image.bgr.size() != 3 * n) {
    return absl::InvalidArgumentError("camera " + camera + ": image is empty or not width * height * 3 bytes");
  }
  if (background.width != image.width || background.height != image.height || background.bgr.size() != 3 * n) {
    return absl::InvalidArgumentError("camera " + camera + ": background is " + std::to_string(background.width) + "x" +
                                      std::to_string(background.height) + ", image is " + std::to_string(image.width) + "x" +
                                      std::to_string(image.height));
  }
  Mask mask{image.width, image.height, std::vector<uint8_t>(n, 0)};
  if (shadow) *shadow = Mask{image.width, image.height, std::vector<uint8_t>(n, 0)};
  const double min_d2 = options.min_difference * options.min_difference;
  const double max_cd2 = options.max_chroma_distortion * options.max_chroma_distortion;
  for (size_t i = 0; i < n; ++i) {
    const double ib = image.bgr[3 * i], ig = image.bgr[3 * i + 1], ir = image.bgr[3 * i + 2];
    const double eb = background.bgr[3 * i], eg = background.bgr[3 * i + 1], er = background.bgr[3 * i + 2];
    const double db = ib - eb, dg = ig - eg, dr = ir - er;
    if (db * db + dg * dg + dr * dr < min_d2) continue;
    if (options.remove_shadows) {
      const double ee = std::max(eb * eb + eg * eg + er * er, 1.0);
      const double alpha = (ib * eb + ig * eg + ir * er) / ee;
      const double cb = ib - alpha * eb, cg = ig - alpha * eg, cr = ir - alpha * er;
      if (alpha >= options.min_shadow_brightness && alpha <= options.max_shadow_brightness &&
          cb * cb + cg * cg + cr * cr <= max_cd2) {
        if (shadow) shadow->data[i] = 255;
        continue;
      }
    }
    mask.data[i] = 255;
  }
  cv::Mat m(mask.height, mask.width, CV_8UC1, mask.data.data());
  if (options.open_radius_px > 0) {
    const int k = 2 * options.open_radius_px + 1;
    cv::morphologyEx(m, m, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k}));
  }
  if (options.close_radius_px > 0) {
    const int k = 2 * options.close_radius_px + 1;
    cv::morphologyEx(m, m, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k}));
  }
  return mask;
}

absl::StatusOr<Image> MedianBackground(const std::vector<Image>& frames, const std::string& camera) {
  if (frames.empty()) return absl::InvalidArgumentError("camera " + camera + ": no frames to take a median background from");
  const Image& first = frames.front();
  for (size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].width != first.width || frames[f].height != first.height ||
        frames[f].bgr.size() != static_cast<size_t>(first.width) * first.height * 3) {
      return absl::InvalidArgumentError("camera " + camera + ": frame " + std::to_string(f) + " differs in size from frame 0");
    }
  }
  Image out{first.width, first.height, std::vector<uint8_t>(first.bgr.size())};
  std::vector<uint8_t> values(frames.size());
  for (size_t i = 0; i < out.bgr.size(); ++i) {
    for (size_t f = 0; f < frames.size(); ++f) values[f] = frames[f].bgr[i];
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    out.bgr[i] = values[values.size() / 2];
  }
  return out;
}

double MaskIoU(const Mask& a, const Mask& b) {
  size_t inter = 0, uni = 0;
  const size_t n = std::min(a.data.size(), b.data.size());
  for (size_t i = 0; i < n; ++i) {
    const bool x = a.data[i] != 0, y = b.data[i] != 0;
    inter += x && y;
    uni += x || y;
  }
  for (size_t i = n; i < a.data.size(); ++i) uni += a.data[i] != 0;
  for (size_t i = n; i < b.data.size(); ++i) uni += b.data[i] != 0;
  return uni == 0 ? 1.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

}  // namespace ave::studio
