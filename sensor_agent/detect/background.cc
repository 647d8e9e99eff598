#include "sensor_agent/detect/background.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace ave::detect {

bool ParseBackgroundKind(const std::string& name, BackgroundKind& kind) {
  if (name == "average") kind = BackgroundKind::kTimeAverage;
  else if (name == "gaussian") kind = BackgroundKind::kGaussian;
  else if (name == "mixture") kind = BackgroundKind::kMixture;
  else return false;
  return true;
}

const char* BackgroundKindName(BackgroundKind kind) {
  switch (kind) {
    case BackgroundKind::kTimeAverage: return "average";
    case BackgroundKind::kGaussian: return "gaussian";
    case BackgroundKind::kMixture: return "mixture";
  }
  return "?";
}

namespace {

constexpr float kSlowForeground = 0.1f;  // learning-rate factor where the last frame was foreground
constexpr float kDistanceScale = 6.0f;   // difference = 6 |d| / sigma: 16 (the default floor) ~ 2.7 sigma

// Mean of a subsample of the first `count` values (every 7th: the global level, not the exact mean).
double MeanOf(const std::vector<float>& v, size_t count) {
  double s = 0;
  size_t n = 0;
  for (size_t i = 0; i < std::min(count, v.size()); i += 7, ++n) s += v[i];
  return n ? s / static_cast<double>(n) : 0;
}

// Shared frame counting: the variable-length window n = min(frames seen, window).
class Counted : public BackgroundModel {
 public:
  Counted(size_t pixels, int window) : pixels_(pixels), window_(std::max(1, window)), zeros_(pixels, 0) {}
  void Reset() override { frames_ = 0; }

 protected:
  // Learning rate for this frame, 1 / n.
  float NextRate() {
    frames_ = std::min(frames_ + 1, window_);
    return 1.0f / static_cast<float>(frames_);
  }
  // The previous foreground mask, or all-clear when there is none (keeps the loops branch-free).
  // During the first fifth of the window (bootstrap) learning is not selective: an object standing
  // in the first frame is averaged out as it walks away instead of leaving a ghost that the slow
  // foreground rate would keep for minutes.
  const uint8_t* Mask(const uint8_t* fg) const { return fg && frames_ >= window_ / 5 ? fg : zeros_.data(); }
  size_t pixels_;
  int window_;
  int frames_ = 0;
  std::vector<uint8_t> zeros_;
};

// The mean and the mean absolute deviation of the last n frames, both variable-length time
// averages (one distribution per pixel); difference = 6 |I - mean| / sigma with sigma = 1.25 MAD
// (a Gaussian's), floored at the sensor noise.
class TimeAverage final : public Counted {
 public:
  TimeAverage(size_t pixels, int window) : Counted(pixels, window), mean_(pixels, 0.f), mad_(pixels, 0.f) {}
  void Apply(const uint8_t* grey, const uint8_t* previous_foreground, uint8_t* difference) override {
    const uint8_t* fg = Mask(previous_foreground);
    const bool first = frames_ == 0;
    const float rate = NextRate();
    float* m = mean_.data();
    float* a = mad_.data();
    if (first) {
      for (size_t i = 0; i < pixels_; ++i) m[i] = grey[i], a[i] = kInitialMad;
      std::fill(difference, difference + pixels_, 0);
      return;
    }
    const float slow = rate * kSlowForeground;
    for (size_t i = 0; i < pixels_; ++i) {
      const float d = static_cast<float>(grey[i]) - m[i];
      const float ad = std::fabs(d);
      difference[i] = static_cast<uint8_t>(std::min(kDistanceScale * ad / std::max(1.25f * a[i], kMinSigma), 255.0f));
      const float r = fg[i] ? slow : rate;
      m[i] += r * d;
      a[i] += r * (ad - a[i]);
    }
  }
  double MeanLevel(size_t count) const override { return frames_ ? MeanOf(mean_, count) : 0; }

 private:
  static constexpr float kInitialMad = 5.f;  // ~6 grey levels sigma until the pixel has a history
  static constexpr float kMinSigma = 3.f;    // sensor noise floor
  std::vector<float> mean_, mad_;
};

// A running Gaussian (Pfinder): fixed learning rate 2 / window after the first frame, i.e.
// exponential forgetting, unlike the variable-length average.
class Gaussian final : public Counted {
 public:
  Gaussian(size_t pixels, int window) : Counted(pixels, window), mean_(pixels, 0.f), var_(pixels, 0.f) {}
  void Apply(const uint8_t* grey, const uint8_t* previous_foreground, uint8_t* difference) override {
    const uint8_t* fg = Mask(previous_foreground);
    const bool first = frames_ == 0;
    NextRate();
    const float rate = std::min(1.0f, 2.0f / static_cast<float>(window_));
    if (first) {
      for (size_t i = 0; i < pixels_; ++i) {
        mean_[i] = grey[i];
        var_[i] = kInitialVar;
      }
      std::fill(difference, difference + pixels_, 0);
      return;
    }
    const float slow = rate * kSlowForeground;
    for (size_t i = 0; i < pixels_; ++i) {
      const float d = static_cast<float>(grey[i]) - mean_[i];
      const float v = std::max(var_[i], kMinVar);
      difference[i] = static_cast<uint8_t>(std::min(kDistanceScale * std::fabs(d) / std::sqrt(v), 255.0f));
      const float r = fg[i] ? slow : rate;
      mean_[i] += r * d;
      var_[i] += r * (d * d - var_[i]);
    }
  }
  double MeanLevel(size_t count) const override { return frames_ ? MeanOf(mean_, count) : 0; }

 private:
  static constexpr float kInitialVar = 36.f;  // (6 grey levels)^2 until the pixel has a history
  static constexpr float kMinVar = 9.f;       // sensor noise floor: sigma >= 3 grey levels
  std::vector<float> mean_, var_;
};

// Stauffer-Grimson with K = 3: components sorted by weight / sigma; the first ones whose weights
// sum to kBackgroundWeight are background.
class Mixture final : public Counted {
 public:
  static constexpr int K = 3;
  Mixture(size_t pixels, int window) : Counted(pixels, window), px_(pixels) {}
  void Apply(const uint8_t* grey, const uint8_t* previous_foreground, uint8_t* difference) override {
    const uint8_t* fg = Mask(previous_foreground);
    const bool first = frames_ == 0;
    const float rate = NextRate();
    if (first) {
      for (size_t i = 0; i < pixels_; ++i) px_[i] = Pixel{{{1.f, 0.f, 0.f}}, {{float(grey[i]), 0.f, 0.f}}, {{kInitialVar, kInitialVar, kInitialVar}}};
      std::fill(difference, difference + pixels_, 0);
      return;
    }
    const float slow = rate * kSlowForeground;
    for (size_t i = 0; i < pixels_; ++i) {
      Pixel& p = px_[i];
      const float x = grey[i];
      // Background distance: nearest of the leading components covering kBackgroundWeight.
      float best = 1e9f, acc = 0;
      for (int k = 0; k < K && acc < kBackgroundWeight; ++k) {
        if (p.w[k] <= 0) break;
        best = std::min(best, std::fabs(x - p.mu[k]) / std::sqrt(std::max(p.var[k], kMinVar)));
        acc += p.w[k];
      }
      difference[i] = static_cast<uint8_t>(std::min(kDistanceScale * best, 255.0f));
      const float r = fg[i] ? slow : rate;
      int match = -1;
      for (int k = 0; k < K; ++k) {
        if (p.w[k] > 0 && std::fabs(x - p.mu[k]) < 2.5f * std::sqrt(std::max(p.var[k], kMinVar))) {
          match = k;
          break;
        }
      }
      for (int k = 0; k < K; ++k) p.w[k] *= (1 - r);
      if (match >= 0) {
        p.w[match] += r;
        const float d = x - p.mu[match];
        p.mu[match] += r * d;  // rho ~ alpha (the common simplification)
        p.var[match] += r * (d * d - p.var[match]);
      } else {
        p.w[K - 1] = r;  // replace the weakest component
        p.mu[K - 1] = x;
        p.var[K - 1] = kInitialVar;
        match = K - 1;
      }
      // Keep sorted by weight / sigma (insertion sort, K = 3).
      for (int k = match; k > 0 && Rank(p, k) > Rank(p, k - 1); --k) {
        std::swap(p.w[k], p.w[k - 1]);
        std::swap(p.mu[k], p.mu[k - 1]);
        std::swap(p.var[k], p.var[k - 1]);
      }
    }
  }
  double MeanLevel(size_t count) const override {
    if (!frames_) return 0;
    double s = 0;
    size_t n = 0;
    for (size_t i = 0; i < std::min(count, px_.size()); i += 7, ++n) s += px_[i].mu[0];
    return n ? s / static_cast<double>(n) : 0;
  }

 private:
  static constexpr float kInitialVar = 36.f;
  static constexpr float kMinVar = 9.f;
  static constexpr float kBackgroundWeight = 0.7f;
  struct Pixel {
    std::array<float, K> w, mu, var;
  };
  static float Rank(const Pixel& p, int k) { return p.w[k] / std::sqrt(std::max(p.var[k], kMinVar)); }
  std::vector<Pixel> px_;
};

}  // namespace

std::unique_ptr<BackgroundModel> MakeBackgroundModel(BackgroundKind kind, size_t pixels, int window_frames) {
  switch (kind) {
    case BackgroundKind::kGaussian: return std::make_unique<Gaussian>(pixels, window_frames);
    case BackgroundKind::kMixture: return std::make_unique<Mixture>(pixels, window_frames);
    case BackgroundKind::kTimeAverage: break;
  }
  return std::make_unique<TimeAverage>(pixels, window_frames);
}

}  // namespace ave::detect
