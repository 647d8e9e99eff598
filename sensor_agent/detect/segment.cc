#include "sensor_agent/detect/segment.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace ave::detect {

int HistogramThreshold(const uint8_t* difference, size_t count, double top_fraction, int floor,
                       size_t* at_or_above_floor) {
  if (at_or_above_floor) *at_or_above_floor = 0;
  if (count == 0) return floor;
  // Four interleaved histograms keep the increments independent (no store-to-load stalls).
  std::array<std::array<uint32_t, 256>, 4> h{};
  size_t i = 0;
  for (; i + 4 <= count; i += 4) {
    ++h[0][difference[i]];
    ++h[1][difference[i + 1]];
    ++h[2][difference[i + 2]];
    ++h[3][difference[i + 3]];
  }
  for (; i < count; ++i) ++h[0][difference[i]];
  if (at_or_above_floor) {
    for (int level = std::max(floor, 0); level < 256; ++level) {
      *at_or_above_floor += size_t(h[0][level]) + h[1][level] + h[2][level] + h[3][level];
    }
  }
  const double keep = std::clamp(top_fraction, 0.0, 1.0) * static_cast<double>(count);
  double above = 0;
  int threshold = 256;
  for (int level = 255; level >= 0; --level) {
    const double n = double(h[0][level]) + h[1][level] + h[2][level] + h[3][level];
    if (above + n > keep) break;
    above += n;
    threshold = level;
  }
  return std::max(threshold, floor);
}

size_t ApplyThreshold(const uint8_t* difference, size_t count, int threshold, uint8_t* mask) {
  size_t on = 0;
  for (size_t i = 0; i < count; ++i) {
    const uint8_t m = difference[i] >= threshold ? 255 : 0;
    mask[i] = m;
    on += m & 1;
  }
  return on;
}

void RemoveNoise(uint8_t* mask, int width, int height, int close_size) {
  if (width < 3 || height < 3) return;
  cv::Mat m(height, width, CV_8UC1, mask);
  static const cv::Mat k3 = cv::getStructuringElement(cv::MORPH_RECT, {3, 3});
  cv::morphologyEx(m, m, cv::MORPH_OPEN, k3);
  if (close_size > 1) {
    cv::morphologyEx(m, m, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_RECT, {close_size, close_size}));
  }
}

namespace {

int32_t Find(std::vector<int32_t>& parent, int32_t a) {
  while (parent[a] != a) {
    parent[a] = parent[parent[a]];
    a = parent[a];
  }
  return a;
}

}  // namespace

std::vector<Component> LabelComponents(const uint8_t* mask, int width, int height, int min_area,
                                       std::vector<int32_t>* labels) {
  std::vector<Component> out;
  if (width <= 0 || height <= 0) return out;
  const size_t n = static_cast<size_t>(width) * height;
  thread_local std::vector<int32_t> provisional;
  provisional.assign(n, 0);
  std::vector<int32_t> parent{0};   // label 0 = background
  std::vector<Component> stats{{}};  // per provisional label, merged into roots below
  // First pass: provisional labels from the left and upper neighbours, equivalences by union,
  // bounds and areas per provisional label.
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = mask + static_cast<size_t>(y) * width;
    int32_t* lab = provisional.data() + static_cast<size_t>(y) * width;
    const int32_t* up = y > 0 ? lab - width : nullptr;
    for (int x = 0; x < width; ++x) {
      if (!row[x]) continue;
      const int32_t left = x > 0 ? lab[x - 1] : 0;
      const int32_t above = up ? up[x] : 0;
      int32_t l;
      if (!left && !above) {
        l = static_cast<int32_t>(parent.size());
        parent.push_back(l);
        stats.push_back({x, y, x, y, 0});
      } else if (left && above && left != above) {
        const int32_t a = Find(parent, left), b = Find(parent, above);
        l = std::min(a, b);
        parent[std::max(a, b)] = l;
      } else {
        l = left ? left : above;
      }
      lab[x] = l;
      Component& c = stats[l];
      c.x0 = std::min(c.x0, x);
      c.x1 = std::max(c.x1, x);
      c.y1 = y;
      ++c.area;
    }
  }
  // Merge each label's statistics into its root. A root is the smallest label of its set, created
  // at the set's first pixel in raster order, so ascending roots give raster order.
  std::vector<int32_t> index(parent.size(), 0);
  for (size_t l = 1; l < parent.size(); ++l) {
    const int32_t root = Find(parent, static_cast<int32_t>(l));
    parent[l] = root;
    if (root == static_cast<int32_t>(l)) continue;
    Component& r = stats[root];
    const Component& c = stats[l];
    r.x0 = std::min(r.x0, c.x0), r.x1 = std::max(r.x1, c.x1);
    r.y0 = std::min(r.y0, c.y0), r.y1 = std::max(r.y1, c.y1);
    r.area += c.area;
  }
  for (size_t l = 1; l < parent.size(); ++l) {
    if (parent[l] == static_cast<int32_t>(l) && stats[l].area >= min_area) {
      out.push_back(stats[l]);
      index[l] = static_cast<int32_t>(out.size());
    }
  }
  if (labels) {
    // Second pass (only when asked): resolved labels per pixel.
    labels->assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
      if (provisional[i]) (*labels)[i] = index[parent[provisional[i]]];
    }
  }
  return out;
}

}  // namespace ave::detect
