#pragma once
// Foreground segmentation steps of the agent's moving-object detector (seed AVE §6): the
// histogram threshold on a difference image, morphological noise removal and two-pass
// 4-connected component labelling. Plain byte images (row-major, no padding) so the header stays
// free of OpenCV; the morphology uses OpenCV inside segment.cc.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace ave::detect {

// A connected foreground region: inclusive pixel bounds and its pixel count.
struct Component {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int area = 0;
  int width() const { return x1 - x0 + 1; }
  int height() const { return y1 - y0 + 1; }
};

// The threshold that keeps the `top_fraction` largest differences (histogram over 256 levels),
// never below `floor`: a quiet scene gives `floor`, not its noise's top 5 %. Empty input: floor.
// `at_or_above_floor`, when given, receives how many differences reach `floor`.
int HistogramThreshold(const uint8_t* difference, size_t count, double top_fraction, int floor,
                       size_t* at_or_above_floor = nullptr);

// mask[i] = 255 where difference[i] >= threshold, else 0; returns the foreground count.
size_t ApplyThreshold(const uint8_t* difference, size_t count, int threshold, uint8_t* mask);

// Morphological noise removal in place: opening (3x3) drops speckles, closing (`close_size`
// square, odd, 1 = none) fills small gaps inside a silhouette. Images under 3x3 are left alone.
void RemoveNoise(uint8_t* mask, int width, int height, int close_size);

// Two-pass 4-connected labelling with union-find (first pass: provisional labels, equivalences and
// per-label bounds and areas, merged into their roots; second pass, only when `labels` is asked
// for: resolved labels per pixel). `labels`, when
// given, receives 0 for background and 1 + component index for foreground pixels. Components
// under `min_area` pixels are dropped (their pixels labelled 0). Order: by first pixel in raster
// order.
std::vector<Component> LabelComponents(const uint8_t* mask, int width, int height, int min_area,
                                       std::vector<int32_t>* labels = nullptr);

}  // namespace ave::detect
