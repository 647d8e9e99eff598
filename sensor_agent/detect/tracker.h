#pragma once
// Pseudo-tracking by validation (seed AVE §6): a foreground region becomes a track only after it
// has been matched in every frame for `validate_s`; matching between neighbouring frames is by
// normalised cross-correlation of small grey templates with a fixed threshold, inside a gate
// around the constant-velocity prediction. Validated tracks get tag numbers 1, 2, ... that never
// change and are never reused; a validated track that misses frames coasts for `coast_s`, a
// candidate may miss frames for `tentative_gap_s` (a fragmenting silhouette) and keep its age.
// Before matching, a region that holds the predictions of two or more established objects (two
// cars meeting on a crossing form one blob) is split between them (`split_min_age_s`).
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "sensor_agent/detect/segment.h"

namespace ave::detect {

struct TrackerOptions {
  double validate_s = 1.0;              // persistence before a region becomes a track (seed: 1 s)
  double correlation_threshold = 0.0;   // NCC of the 16x16 templates needed to match (ave-bench detect: 0.2, 0.3 and 0.5 lost recall)
  double coast_s = 1.0;                 // a validated track survives this long unmatched (ave-bench detect, 20 s: 0.5 -> 1.0 +0.02 MOTA, 2.0 no better)
  double tentative_gap_s = 0.2;         // a candidate may miss frames this long and still validate
  double gate = 1.0;                    // centre distance allowed, in predicted box diagonals
  // Merged blobs: a region that holds the predicted centres of two or more tracks or candidates
  // older than this, each predicted box under 0.8 of the region's, is split into those predicted
  // boxes (tightened to the foreground inside them) before matching (ave-bench detect: cars on the
  // crossing merged into one box; negative = never split).
  double split_min_age_s = 0.3;

  std::string Check() const;  // empty when usable, else names the field
};

// Boxes in the tracker's image (the detector's work image): edges in pixels, x0 <= x1 exclusive
// of nothing (x1 = last column + 1).
struct TrackBox {
  uint32_t id = 0;  // 0: not (yet) validated
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  float score = 0;  // correlation of the last match in [0, 1]
  bool matched = false;  // seen in this frame (false: coasting)
};

class Tracker {
 public:
  static constexpr int kTemplate = 16;

  explicit Tracker(TrackerOptions options = {});

  // One frame's regions (bounds in `grey`, a width x height image) at time t_s, and optionally the
  // foreground mask they came from (same size, non-zero = foreground; without it a split region's
  // parts are the predicted boxes clipped to the region). Returns the validated tracks matched in
  // this frame.
  std::vector<TrackBox> Update(const std::vector<Component>& regions, const uint8_t* grey, int width, int height,
                               double t_s, const uint8_t* mask = nullptr);
  // Drops every candidate and track (ids keep counting up).
  void Clear() {
    candidates_.clear();
    backfill_.clear();
  }
  // The boxes of the tracks validated in the last Update during their pending (validation) time,
  // with the time of each, oldest first per track: a delayed output can report them in the frames
  // where the region was seen but not yet a track. Empty when nothing was validated.
  const std::vector<std::pair<double, TrackBox>>& backfill() const { return backfill_; }
  uint32_t tracks_started() const { return next_id_ - 1; }

 private:
  struct Candidate {
    TrackBox box;
    double vx = 0, vy = 0;  // box-centre velocity, pixels per second
    double first_t = 0, last_t = 0;
    std::vector<float> templ;  // kTemplate^2, zero mean / unit norm (or flat, see Correlation)
    float mean = 0;
    bool flat = false;
    std::vector<std::pair<double, TrackBox>> pending;  // matched boxes before validation (time, box)
    TrackBox Predicted(double t_s) const;
  };

  // The regions with merged blobs split (see TrackerOptions::split_min_age_s).
  std::vector<Component> SplitMerged(const std::vector<Component>& regions, const uint8_t* mask, int width,
                                     double t_s) const;

  TrackerOptions options_;
  std::vector<Candidate> candidates_;
  std::vector<std::pair<double, TrackBox>> backfill_;
  uint32_t next_id_ = 1;
};

// Zero-mean unit-norm template of a region widened by a quarter of its size on every side
// (exposed for tests); `flat` when its spread is under three grey levels (noise).
void MakeTemplate(const uint8_t* grey, int width, int height, const Component& region, std::vector<float>& templ,
                  float& mean, bool& flat);

}  // namespace ave::detect
