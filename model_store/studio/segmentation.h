#pragma once
// Foreground segmentation against a background plate, with shadow removal by the brightness /
// chromaticity distortion test of Horprasert, Harwood and Davis (ICCV FRAME-RATE workshop 1999;
// i4D ref [4]). Per pixel, with I the image colour and E the background colour (RGB vectors):
//   brightness distortion  alpha = (I . E) / (E . E)      (1 = as bright as the background)
//   chromaticity distortion CD   = |I - alpha E|          (levels; 0 = same hue as the background)
// A pixel differing from E by less than min_difference is background; one with a small CD and
// alpha in [min_shadow_brightness, max_shadow_brightness] is a shadow (or highlight) on the
// background, so background too when remove_shadows; anything else is foreground.
#include "absl/status/statusor.h"

#include "model_store/studio/studio_types.h"

namespace ave::studio {

struct SegmentationOptions {
  double min_difference = 30;           // |I - E| (levels, 0..441) below which a pixel is background
  bool remove_shadows = true;
  double max_chroma_distortion = 12;    // levels: a shadow keeps the background's hue
  double min_shadow_brightness = 0.3;   // alpha below this is too dark for a shadow: foreground
  double max_shadow_brightness = 1.25;  // alpha above 1: a highlight, treated like a shadow
  int open_radius_px = 1;               // morphological opening (speckle), 0 = none
  int close_radius_px = 1;              // then closing (pin holes), 0 = none
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// The foreground mask of `image` against `background` (same size). When `shadow` is given it
// receives 255 where a pixel was removed as shadow. `camera` names the camera in errors.
absl::StatusOr<Mask> SegmentForeground(const Image& image, const Image& background, const SegmentationOptions& options,
                                       const std::string& camera, Mask* shadow = nullptr);

// A background plate estimated as the per-pixel, per-channel median of frames of one camera
// (for captures without an empty-studio plate; the actor must not stand still).
absl::StatusOr<Image> MedianBackground(const std::vector<Image>& frames, const std::string& camera);

// Intersection over union of two masks' foregrounds (1 when both are empty).
double MaskIoU(const Mask& a, const Mask& b);

}  // namespace ave::studio
