#pragma once
// Sequence-level post-processing of the online tracks (i4D §3.2: "Temporary track discontinuities
// are bridged in a post-processing step, while short false tracks are removed based on their
// length"). Input: the online output of every sweep of a sequence. A track that ends (its last
// measured sweep) is linked to a track that starts within `max_gap_s` after it when the start lies
// near the end's constant-velocity prediction (within link_radius_m + link_radius_per_s * gap) and
// the implied speed is plausible; the links are chosen jointly by the optimal assignment (one
// successor per end, one predecessor per start, least prediction error). Linked tracks take the
// first one's id; the gap is filled by linear interpolation. Chains measured in fewer than
// `min_track_sweeps` sweeps are removed.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar_track {

struct PostProcessOptions {
  double max_gap_s = 4.0;
  double link_radius_m = 0.8;
  double link_radius_per_s = 0.5;
  double max_speed_mps = 3.0;
  int min_track_sweeps = 15;
  std::string Check() const;
};

struct PostProcessed {
  // Per input sweep: the tracks after linking and pruning (measured positions; interpolated ones
  // in gaps with missed_frames = the sweeps since the last measurement). Only confirmed tracks.
  std::vector<std::vector<lidar::FootTrack>> tracks;
  std::map<uint32_t, uint32_t> id_map;  // online id -> final id (0: removed as too short)
  int links = 0, removed_tracks = 0;
};

// `online`: one FootTracks per sweep, in time order (confirmed tracks with missed_frames == 0 are
// the measurements; the rest is ignored).
PostProcessed BridgeAndPrune(const std::vector<lidar::FootTracks>& online, const PostProcessOptions& options = {});

}  // namespace ave::lidar_track
