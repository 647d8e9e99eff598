#pragma once
// Foreground-background separation on a rotating multi-beam LiDAR's range image (i4D §3.1 and its
// reference [2], Benedek, Molnár, Szirányi: "A dynamic MRF model for foreground detection on range
// data sequences of rotating multi-beam lidar").
//
//   1. Range image (range_image.h): rings x azimuth bins, the nearest return per pixel.
//   2. Per-pixel mixture of K Gaussians on range (Stauffer-Grimson): the components ordered by
//      weight / sigma, the first ones whose weights sum past `background_weight` are background. A
//      pixel without a return ("no return": sky, beyond max range, a dropped echo) cannot hold a
//      person; it is background and its model is left as it is. A return in a pixel whose model has
//      never seen one (something in front of the sky) is foreground evidence. A return behind the
//      background (what a person walking away reveals, leaves swaying aside) is background: a person
//      is always in front; such pixels learn at `revealed_learning_rate`, so ghosts fade quickly.
//   3. Dynamic MRF on the image lattice: data term from the mixture (background: half the squared
//      normalised distance to the nearest background component, capped; foreground: half the squared
//      matching threshold), a Potts term between 4-neighbours (the azimuth wraps) and a temporal
//      term tying each pixel to its label in the previous sweep. Solved by `mrf_iterations` ICM
//      sweeps (0: the mixture alone).
//   4. 3D point classification: every point of a foreground pixel (a pixel may hold several) is
//      checked against the background components of the pixels around it, in a window of
//      `window_m` at the point's range: a point within max(match_sigmas sigma, bg_tolerance_m) of
//      one of them is background. This removes quantisation artefacts at object edges and swaying
//      tree crowns (the leaves land in a neighbouring bin whose model knows them).
//
// Learning happens after the sweep is tracked (Learn): pixels whose point is foreground learn
// slowly, pixels whose point belongs to a confirmed person are not learned at all, so a person standing still does not melt into the background (tracker
// feedback; docs/LIDAR.md says why this rather than the MRF's temporal term alone).
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar_track/range_image.h"

namespace ave::lidar_track {

struct ForegroundOptions {
  int cols = 1024;              // azimuth bins of the range image (the HDL-64E's firings per turn at 10 Hz: ~2048)
  float max_range_m = 130;      // returns beyond are unusable
  // Mixture of Gaussians on range (Stauffer-Grimson).
  int components = 3;           // K, [1, 8]
  float learning_rate = 0.005f; // alpha per sweep
  // The first sweeps learn at 1 / (n + 1) (a running mean). Kept short: while the rate is high, a
  // slow walker's leading edge is learned before the next sweep and the person is never detected.
  int warmup_sweeps = 10;
  float revealed_learning_rate = 0.05f;  // alpha where a return lies behind the background (revealed)
  // alpha where the point was classified foreground (and is no confirmed person's): slow, so a
  // person is not learned during the first sweeps' fast start, yet a new static object sinks in.
  float foreground_learning_rate = 0.0005f;
  float match_sigmas = 2.5f;    // a range matches a component within this many sigmas
  float min_sigma_m = 0.06f;    // floor of a component's sigma (range noise, ring pattern)
  float init_sigma_m = 0.3f;    // sigma of a new component
  float background_weight = 0.7f;  // T: weight share the background components cover
  // Dynamic MRF.
  int mrf_iterations = 2;       // ICM sweeps; 0 = the mixture's decision alone
  float mrf_spatial = 0.9f;     // Potts cost per disagreeing 4-neighbour
  float mrf_temporal = 0.9f;    // cost of a label that differs from the previous sweep's
  // Cap of the background data term: beyond it a range is "surely not background" whatever its
  // distance, so that 3-4 background neighbours can outvote a single outlying return.
  float max_background_cost = 5;
  // 3D point classification.
  bool classify_3d = true;
  float window_m = 0.05f;       // half-width of the neighbourhood, metres at the point's range
  int max_window_cols = 8;
  int window_rings = 1;
  float bg_tolerance_m = 0.2f;
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

class RangeForeground {
 public:
  explicit RangeForeground(ForegroundOptions options = {});

  // Per point of the sweep: 1 = foreground, 0 = background or unusable. The range image, the pixel
  // labels and the matched components stay for Learn. The model resets when the ring count changes.
  absl::StatusOr<std::vector<uint8_t>> Segment(const lidar::LidarSweep& sweep);
  // Updates the mixture with the last segmented sweep; a pixel whose nearest point has
  // frozen_point[i] != 0 is not learned (empty: learn every pixel).
  void Learn(const std::vector<uint8_t>& frozen_point);

  const RangeImage& image() const { return image_; }
  const std::vector<uint8_t>& pixel_labels() const { return labels_; }  // after the MRF, 1 = foreground
  const ForegroundOptions& options() const { return options_; }
  int64_t sweeps_learned() const { return sweeps_learned_; }

 private:
  struct Gauss {
    float weight = 0, mean_m = 0, var_m2 = 0;
  };
  void Reset(int rings);
  void ComputeDataTerms();
  void RunMrf();
  std::vector<uint8_t> ClassifyPoints(const lidar::LidarSweep& sweep) const;
  bool MatchesBackground(int pixel, float range_m) const;

  ForegroundOptions options_;
  int rings_ = 0;
  int64_t sweeps_learned_ = 0;
  RangeImage image_;
  std::vector<Gauss> model_;          // pixels x K, per pixel sorted by weight / sigma
  std::vector<uint8_t> n_background_; // per pixel: the first n components are background
  std::vector<int8_t> matched_;       // per pixel: matched component of this sweep, -1 none
  std::vector<uint8_t> revealed_;     // per pixel: the return lies behind every background component
  std::vector<float> cost_bg_, cost_fg_;
  std::vector<uint8_t> labels_, previous_labels_;
  std::vector<uint8_t> point_foreground_;  // the last Segment's result
  bool has_previous_ = false;
};

}  // namespace ave::lidar_track
