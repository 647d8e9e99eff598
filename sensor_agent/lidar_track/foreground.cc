#include "sensor_agent/lidar_track/foreground.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace ave::lidar_track {

std::string ForegroundOptions::Check() const {
  if (cols < 8 || cols > 36000) return absl::StrCat("cols: ", cols, " is not in [8, 36000]");
  if (!(max_range_m > 0)) return "max_range_m: must be > 0";
  if (components < 1 || components > 8) return absl::StrCat("components: ", components, " is not in [1, 8]");
  if (!(learning_rate > 0 && learning_rate < 1)) return "learning_rate: must be in (0, 1)";
  if (!(foreground_learning_rate > 0 && foreground_learning_rate < 1)) return "foreground_learning_rate: must be in (0, 1)";
  if (!(revealed_learning_rate > 0 && revealed_learning_rate < 1)) return "revealed_learning_rate: must be in (0, 1)";
  if (warmup_sweeps < 0) return "warmup_sweeps: must be >= 0";
  if (!(match_sigmas > 0)) return "match_sigmas: must be > 0";
  if (!(min_sigma_m > 0) || !(init_sigma_m >= min_sigma_m)) return "min_sigma_m, init_sigma_m: need 0 < min_sigma_m <= init_sigma_m";
  if (!(background_weight > 0 && background_weight <= 1)) return "background_weight: must be in (0, 1]";
  if (mrf_iterations < 0 || mrf_iterations > 100) return "mrf_iterations: must be in [0, 100]";
  if (!(mrf_spatial >= 0) || !(mrf_temporal >= 0)) return "mrf_spatial, mrf_temporal: must be >= 0";
  if (!(max_background_cost > 0)) return "max_background_cost: must be > 0";
  if (!(window_m >= 0) || max_window_cols < 0 || window_rings < 0) return "window_m, max_window_cols, window_rings: must be >= 0";
  if (!(bg_tolerance_m >= 0)) return "bg_tolerance_m: must be >= 0";
  return "";
}

RangeForeground::RangeForeground(ForegroundOptions options) : options_(options) {}

void RangeForeground::Reset(int rings) {
  rings_ = rings;
  const size_t pixels = static_cast<size_t>(rings) * options_.cols;
  model_.assign(pixels * options_.components, Gauss{});
  n_background_.assign(pixels, 0);
  matched_.assign(pixels, -1);
  previous_labels_.assign(pixels, 0);
  has_previous_ = false;
  sweeps_learned_ = 0;
}

bool RangeForeground::MatchesBackground(int pixel, float range_m) const {
  const Gauss* g = &model_[static_cast<size_t>(pixel) * options_.components];
  const float seen_m = image_.range_m[pixel];
  for (int k = 0; k < n_background_[pixel]; ++k) {
    const float sigma = std::sqrt(g[k].var_m2);
    // The beam of that pixel passed through this surface in this sweep: it is not there now (a
    // ghost of someone who stood there, leaves swayed aside), so it explains nothing.
    if (seen_m > g[k].mean_m + options_.match_sigmas * sigma) continue;
    if (std::abs(range_m - g[k].mean_m) < std::max(options_.match_sigmas * sigma, options_.bg_tolerance_m)) return true;
  }
  return false;
}

void RangeForeground::ComputeDataTerms() {
  const size_t pixels = image_.range_m.size();
  const int K = options_.components;
  const float fg_cost = 0.5f * options_.match_sigmas * options_.match_sigmas;
  cost_bg_.assign(pixels, 0.f);
  cost_fg_.assign(pixels, 0.f);
  revealed_.assign(pixels, 0);
  for (size_t s = 0; s < pixels; ++s) {
    matched_[s] = -1;
    const float r = image_.range_m[s];
    if (r <= 0) {
      cost_fg_[s] = 1e6f;  // no return: cannot be a person
      continue;
    }
    const Gauss* g = &model_[s * K];
    float best_bg = options_.max_background_cost * 2;
    bool behind = false;
    for (int k = 0; k < K; ++k) {
      if (g[k].weight <= 0) continue;
      const float z = (g[k].mean_m - r) / std::sqrt(g[k].var_m2);  // > 0: in front of the component
      if (matched_[s] < 0 && std::abs(z) < options_.match_sigmas) matched_[s] = static_cast<int8_t>(k);
      if (k >= n_background_[s]) continue;
      best_bg = std::min(best_bg, z * z);
      behind = behind || z <= -options_.match_sigmas;
    }
    revealed_[s] = behind && matched_[s] < 0;
    if (sweeps_learned_ == 0 || behind) {
      // Nothing learned yet, or a return behind the background (a person walked away and
      // revealed what was behind, leaves swayed aside): a person is never behind the background.
      cost_fg_[s] = 1e6f;
      continue;
    }
    cost_bg_[s] = 0.5f * std::min(best_bg, 2 * options_.max_background_cost);
    cost_fg_[s] = fg_cost;
  }
}

void RangeForeground::RunMrf() {
  const size_t pixels = image_.range_m.size();
  labels_.assign(pixels, 0);
  for (size_t s = 0; s < pixels; ++s) labels_[s] = cost_fg_[s] < cost_bg_[s] ? 1 : 0;
  const int rings = image_.rings, cols = image_.cols;
  const float beta = options_.mrf_spatial, gamma = has_previous_ ? options_.mrf_temporal : 0.f;
  for (int it = 0; it < options_.mrf_iterations; ++it) {
    int changed = 0;
    for (int r = 0; r < rings; ++r) {
      for (int c = 0; c < cols; ++c) {
        const int s = r * cols + c;
        if (image_.range_m[s] <= 0) continue;
        int n = 2, fg = labels_[r * cols + (c == 0 ? cols - 1 : c - 1)] + labels_[r * cols + (c + 1 == cols ? 0 : c + 1)];
        if (r > 0) {
          ++n;
          fg += labels_[s - cols];
        }
        if (r + 1 < rings) {
          ++n;
          fg += labels_[s + cols];
        }
        const float prev = previous_labels_[s];
        const float e_bg = cost_bg_[s] + beta * fg + gamma * prev;
        const float e_fg = cost_fg_[s] + beta * (n - fg) + gamma * (1 - prev);
        const uint8_t l = e_fg < e_bg ? 1 : 0;
        changed += l != labels_[s];
        labels_[s] = l;
      }
    }
    if (changed == 0) break;
  }
}

std::vector<uint8_t> RangeForeground::ClassifyPoints(const lidar::LidarSweep& sweep) const {
  std::vector<uint8_t> fg(sweep.points.size(), 0);
  const int cols = image_.cols, rings = image_.rings;
  const double col_rad = 2 * std::numbers::pi / cols;
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    const int s = image_.pixel_of_point[i];
    if (s < 0 || !labels_[s]) continue;
    if (!options_.classify_3d) {
      fg[i] = 1;
      continue;
    }
    const float range = sweep.points[i].range_m;
    const int r0 = s / cols, c0 = s % cols;
    const int wc = std::min(options_.max_window_cols, static_cast<int>(std::ceil(std::atan2(options_.window_m, range) / col_rad)));
    bool background = false;
    for (int r = std::max(0, r0 - options_.window_rings); r <= std::min(rings - 1, r0 + options_.window_rings) && !background; ++r) {
      for (int dc = -wc; dc <= wc; ++dc) {
        int c = c0 + dc;
        if (c < 0) c += cols;
        if (c >= cols) c -= cols;
        if (MatchesBackground(r * cols + c, range)) {
          background = true;
          break;
        }
      }
    }
    fg[i] = background ? 0 : 1;
  }
  return fg;
}

absl::StatusOr<std::vector<uint8_t>> RangeForeground::Segment(const lidar::LidarSweep& sweep) {
  if (const std::string why = options_.Check(); !why.empty()) return absl::InvalidArgumentError("ForegroundOptions." + why);
  absl::StatusOr<RangeImage> image = BuildRangeImage(sweep, options_.cols, options_.max_range_m);
  if (!image.ok()) return image.status();
  if (image->rings != rings_) Reset(image->rings);
  image_ = std::move(*image);
  ComputeDataTerms();
  RunMrf();
  point_foreground_ = ClassifyPoints(sweep);
  return point_foreground_;
}

void RangeForeground::Learn(const std::vector<uint8_t>& frozen_point) {
  const int K = options_.components;
  const float alpha_all = sweeps_learned_ < options_.warmup_sweeps
                              ? std::max(options_.learning_rate, 1.f / static_cast<float>(sweeps_learned_ + 1))
                              : options_.learning_rate;
  const float min_var = options_.min_sigma_m * options_.min_sigma_m, init_var = options_.init_sigma_m * options_.init_sigma_m;
  const size_t pixels = image_.range_m.size();
  for (size_t s = 0; s < pixels; ++s) {
    const float r = image_.range_m[s];
    if (r <= 0) continue;
    const int32_t p = image_.nearest_point[s];
    if (!frozen_point.empty() && p >= 0 && static_cast<size_t>(p) < frozen_point.size() && frozen_point[p]) continue;
    Gauss* g = &model_[s * K];
    const int m = matched_[s];
    float alpha = revealed_[s] ? std::max(alpha_all, options_.revealed_learning_rate) : alpha_all;
    if (p >= 0 && point_foreground_[p]) alpha = options_.foreground_learning_rate;
    float total = 0;
    for (int k = 0; k < K; ++k) {
      g[k].weight *= (1 - alpha);
      if (k == m) {
        g[k].weight += alpha;
        const float rho = std::min(1.f, alpha / std::max(g[k].weight, alpha));
        const float d = r - g[k].mean_m;
        g[k].mean_m += rho * d;
        g[k].var_m2 = std::max(min_var, g[k].var_m2 + rho * (d * d - g[k].var_m2));
      }
      total += g[k].weight;
    }
    if (m < 0) {  // replace the least probable component
      Gauss& last = g[K - 1];
      total -= last.weight;
      last = Gauss{alpha, r, init_var};
      total += alpha;
    }
    for (int k = 0; k < K; ++k) g[k].weight /= total;
    // Keep the components sorted by weight / sigma (K is small: insertion sort).
    for (int k = 1; k < K; ++k) {
      for (int j = k; j > 0 && g[j].weight * g[j].weight / std::max(g[j].var_m2, 1e-12f) >
                                   g[j - 1].weight * g[j - 1].weight / std::max(g[j - 1].var_m2, 1e-12f);
           --j) {
        std::swap(g[j], g[j - 1]);
      }
    }
    float cum = 0;
    uint8_t nb = 0;
    while (nb < K && g[nb].weight > 0) {
      cum += g[nb].weight;
      ++nb;
      if (cum > options_.background_weight) break;
    }
    n_background_[s] = nb;
  }
  previous_labels_ = labels_;
  has_previous_ = true;
  ++sweeps_learned_;
}

}  // namespace ave::lidar_track
