#include "sensor_agent/detect/detector.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sensor_agent/detect/segment.h"

namespace ave::detect {

std::string DetectorOptions::Check() const {
  if (!(window_s > 0 && window_s < 1e5)) return "window_s must be in (0, 1e5)";
  if (!(top_fraction > 0 && top_fraction <= 1)) return "top_fraction must be in (0, 1]";
  if (threshold_floor < 1 || threshold_floor > 255) return "threshold_floor must be in [1, 255]";
  if (!(min_area_fraction >= 0 && min_area_fraction < 1)) return "min_area_fraction must be in [0, 1)";
  if (close_size < 1 || close_size > 31 || close_size % 2 == 0) return "close_size must be odd in [1, 31]";
  if (work_width < 16) return "work_width must be >= 16";
  if (!(global_change_fraction > 0 && global_change_fraction <= 1)) return "global_change_fraction must be in (0, 1]";
  if (std::string why = tracker.Check(); !why.empty()) return "tracker." + why;
  return "";
}

struct Detector::Impl {
  DetectorOptions options;
  Tracker tracker;
  std::unique_ptr<BackgroundModel> model;
  int width = 0, height = 0;  // full frame
  int factor = 1;
  int ww = 0, wh = 0;         // work image
  bool colour = false;        // the background model sees grey plus a half-resolution chroma plane
  int cw = 0, ch = 0;         // chroma plane (colour only): one sample per 2x2 work pixels
  cv::Mat grey_full, grey;    // grey: the work image (in colour, the head of `samples`)
  std::vector<uint8_t> difference, mask, previous_mask;
  std::vector<uint8_t> samples, sample_difference, sample_mask;  // grey then chroma (colour only)
  bool has_previous = false;
  double last_t = 0;
  DetectorStats stats;
  std::vector<std::pair<double, Detection>> backfill;

  explicit Impl(DetectorOptions o) : options(o), tracker(o.tracker) {}

  void Restart(int w, int h, double t_s) {
    width = w, height = h;
    factor = std::max(1, (w + options.work_width - 1) / options.work_width);
    ww = std::max(1, w / factor);
    wh = std::max(1, h / factor);
    const size_t n = static_cast<size_t>(ww) * wh;
    colour = options.colour && ww >= 2 && wh >= 2;
    cw = colour ? ww / 2 : 0, ch = colour ? wh / 2 : 0;
    const size_t total = n + static_cast<size_t>(cw) * ch;
    difference.assign(n, 0);
    mask.assign(n, 0);
    previous_mask.assign(n, 0);
    samples.assign(colour ? total : 0, 0);
    sample_difference.assign(colour ? total : 0, 0);
    sample_mask.assign(colour ? total : 0, 0);
    grey = colour ? cv::Mat(wh, ww, CV_8UC1, samples.data()) : cv::Mat();
    has_previous = false;
    // Frames per window at the rate seen so far is unknown here: assume 15 fps until re-derived.
    model = MakeBackgroundModel(options.background, colour ? total : n, std::max(1, static_cast<int>(options.window_s * 15)));
    tracker.Clear();
    last_t = t_s;
  }

  void MakeWorkImage(const uint8_t* bgr) {
    const cv::Mat frame(height, width, CV_8UC3, const_cast<uint8_t*>(bgr));
    if (colour) {
      // The chroma plane: the blue-red opponent 128 + (B - R) / 2, point-sampled at the centre of
      // each 2x2 block of work pixels (camera chroma is smooth: JPEG and Bayer sample it coarsely).
      const int step = 2 * factor;
      uint8_t* c = samples.data() + difference.size();
      for (int y = 0; y < ch; ++y) {
        const uint8_t* p = bgr + (static_cast<size_t>(y * step + factor) * width + factor) * 3;
        for (int x = 0; x < cw; ++x, p += 3 * step) *c++ = static_cast<uint8_t>((p[0] - p[2] + 256) >> 1);
      }
    }
    if (factor == 1) {
      cv::cvtColor(frame, grey, cv::COLOR_BGR2GRAY);
      return;
    }
    cv::cvtColor(frame, grey_full, cv::COLOR_BGR2GRAY);
    const cv::Rect roi(0, 0, std::min(width, ww * factor), std::min(height, wh * factor));
    cv::resize(grey_full(roi), grey, cv::Size(ww, wh), 0, 0, cv::INTER_AREA);
  }

  // A work-image box as a full-frame detection.
  Detection ToFrame(const TrackBox& b) const {
    const float s = static_cast<float>(factor);
    const float x0 = std::clamp(static_cast<float>(b.x0) * s, 0.f, static_cast<float>(width));
    const float x1 = std::clamp(static_cast<float>(b.x1) * s, 0.f, static_cast<float>(width));
    const float y0 = std::clamp(static_cast<float>(b.y0) * s, 0.f, static_cast<float>(height));
    const float y1 = std::clamp(static_cast<float>(b.y1) * s, 0.f, static_cast<float>(height));
    return {b.id, {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}}, b.score};
  }

  // Global gain compensation: scale the frame so its mean level matches the background's (slow
  // illumination drift, auto exposure). Near-black frames are left alone.
  void CompensateGain() {
    const double background_level = model->MeanLevel(grey.total());
    uint64_t sum = 0;  // integer: exact, and no floating-point dependency chain
    size_t n = 0;
    const uint8_t* g = grey.ptr<uint8_t>();  // continuous: the first plane or the grey work image
    const size_t total = grey.total();
    for (size_t i = 0; i < total; i += 7, ++n) sum += g[i];  // the background's subsample
    const double frame_level = n ? static_cast<double>(sum) / static_cast<double>(n) : 0;
    if (background_level <= 0 || frame_level < 4) return;
    const double gain = std::clamp(background_level / frame_level, 0.25, 4.0);
    if (std::fabs(gain - 1) > 0.01) grey.convertTo(grey, -1, gain);  // in place: stays in `samples`
  }

  // The background difference of this frame (in colour, per pixel the larger of the grey and the
  // chroma differences).
  void Difference(bool use_previous) {
    const size_t n = difference.size();
    if (!colour) {
      model->Apply(grey.ptr<uint8_t>(), use_previous ? previous_mask.data() : nullptr, difference.data());
      return;
    }
    if (use_previous) {
      std::copy(previous_mask.begin(), previous_mask.end(), sample_mask.begin());
      uint8_t* cm = sample_mask.data() + n;
      for (int y = 0; y < ch; ++y) {
        for (int x = 0; x < cw; ++x) *cm++ = previous_mask[static_cast<size_t>(2 * y) * ww + 2 * x];
      }
    }
    model->Apply(samples.data(), use_previous ? sample_mask.data() : nullptr, sample_difference.data());
    for (int y = 0; y < wh; ++y) {
      const uint8_t* dg = sample_difference.data() + static_cast<size_t>(y) * ww;
      const uint8_t* dc = sample_difference.data() + n + static_cast<size_t>(std::min(y / 2, ch - 1)) * cw;
      uint8_t* out = difference.data() + static_cast<size_t>(y) * ww;
      const int paired = 2 * cw;  // columns with their own chroma sample; an odd last one reuses cw - 1
      for (int x = 0; x < paired; ++x) out[x] = std::max(dg[x], dc[x >> 1]);
      for (int x = paired; x < ww; ++x) out[x] = std::max(dg[x], dc[cw - 1]);
    }
  }
};

Detector::Detector(DetectorOptions options) {
  if (std::string why = options.Check(); !why.empty()) throw std::invalid_argument("DetectorOptions: " + why);
  impl_ = std::make_unique<Impl>(options);
}
Detector::~Detector() = default;
Detector::Detector(Detector&&) noexcept = default;
Detector& Detector::operator=(Detector&&) noexcept = default;

const std::vector<uint8_t>& Detector::foreground() const { return impl_->mask; }
int Detector::work_width() const { return impl_->ww; }
int Detector::work_height() const { return impl_->wh; }
const DetectorStats& Detector::stats() const { return impl_->stats; }
const std::vector<std::pair<double, Detection>>& Detector::backfill() const { return impl_->backfill; }

std::vector<Detection> Detector::Process(const uint8_t* bgr, int width, int height, double t_s) {
  Impl& m = *impl_;
  m.backfill.clear();
  if (!bgr || width <= 0 || height <= 0) return {};
  if (width != m.width || height != m.height || !m.model) m.Restart(width, height, t_s);
  ++m.stats.frames;
  m.MakeWorkImage(bgr);
  m.CompensateGain();
  const size_t n = static_cast<size_t>(m.ww) * m.wh;
  const uint8_t* grey = m.grey.ptr<uint8_t>();
  m.Difference(m.has_previous);
  const DetectorOptions& o = m.options;
  // A scene-wide change (lights switched, camera knocked): start the background again.
  size_t over_floor = 0;
  m.stats.threshold = HistogramThreshold(m.difference.data(), n, o.top_fraction, o.threshold_floor, &over_floor);
  if (static_cast<double>(over_floor) > o.global_change_fraction * static_cast<double>(n)) {
    ++m.stats.global_changes;
    m.model->Reset();
    m.Difference(false);
    m.tracker.Clear();
    std::fill(m.mask.begin(), m.mask.end(), 0);
    m.has_previous = false;
    m.stats.regions = 0;
    return {};
  }
  ApplyThreshold(m.difference.data(), n, m.stats.threshold, m.mask.data());
  RemoveNoise(m.mask.data(), m.ww, m.wh, o.close_size);
  const int min_area = std::max(1, static_cast<int>(std::ceil(o.min_area_fraction * static_cast<double>(n))));
  const std::vector<Component> regions = LabelComponents(m.mask.data(), m.ww, m.wh, min_area);
  m.stats.regions = static_cast<int>(regions.size());
  m.previous_mask = m.mask;
  m.has_previous = true;
  m.last_t = t_s;
  std::vector<Detection> out;
  for (const TrackBox& b : m.tracker.Update(regions, grey, m.ww, m.wh, t_s, m.mask.data())) out.push_back(m.ToFrame(b));
  m.backfill.clear();
  for (const auto& [bt, b] : m.tracker.backfill()) m.backfill.emplace_back(bt, m.ToFrame(b));
  return out;
}

}  // namespace ave::detect
