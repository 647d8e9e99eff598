#include "sensor_agent/lidar_track/sequence_post.h"

#include <algorithm>
#include <limits>

#include <Eigen/Core>

#include "sensor_agent/lidar_track/assignment.h"

namespace ave::lidar_track {

std::string PostProcessOptions::Check() const {
  if (!(max_gap_s >= 0) || !(link_radius_m >= 0) || !(link_radius_per_s >= 0) || !(max_speed_mps > 0)) {
    return "max_gap_s, link_radius_m, link_radius_per_s >= 0 and max_speed_mps > 0";
  }
  if (min_track_sweeps < 0) return "min_track_sweeps: must be >= 0";
  return "";
}

namespace {

struct Tracklet {
  uint32_t id = 0;
  std::vector<int> sweeps;                // measured sweeps, increasing
  std::vector<lidar::FootTrack> samples;  // same order
  int next = -1, prev = -1;
};

}  // namespace

PostProcessed BridgeAndPrune(const std::vector<lidar::FootTracks>& online, const PostProcessOptions& o) {
  PostProcessed out;
  out.tracks.resize(online.size());
  std::map<uint32_t, int> index_of;
  std::vector<Tracklet> tl;
  for (size_t f = 0; f < online.size(); ++f) {
    for (const lidar::FootTrack& t : online[f].tracks) {
      if (!t.confirmed || t.missed_frames != 0) continue;
      auto [it, inserted] = index_of.emplace(t.id, static_cast<int>(tl.size()));
      if (inserted) tl.push_back(Tracklet{t.id, {}, {}});
      tl[it->second].sweeps.push_back(static_cast<int>(f));
      tl[it->second].samples.push_back(t);
    }
  }
  const int n = static_cast<int>(tl.size());
  auto time_s = [&](int sweep) { return online[sweep].t_ns * 1e-9; };
  // Ends x starts.
  Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(n, n, std::numeric_limits<double>::infinity());
  for (int a = 0; a < n; ++a) {
    const lidar::FootTrack& end = tl[a].samples.back();
    const double t_end = time_s(tl[a].sweeps.back());
    for (int b = 0; b < n; ++b) {
      if (a == b) continue;
      const double gap = time_s(tl[b].sweeps.front()) - t_end;
      if (!(gap > 0) || gap > o.max_gap_s) continue;
      const lidar::FootTrack& start = tl[b].samples.front();
      const double jump = (start.xy_m - end.xy_m).norm();
      if (jump / gap > o.max_speed_mps) continue;
      const double err = (start.xy_m - (end.xy_m + gap * end.velocity_mps)).norm();
      if (err > o.link_radius_m + o.link_radius_per_s * gap) continue;
      cost(a, b) = err;
    }
  }
  const Assignment links = SolveAssignment(cost);
  for (int a = 0; a < n; ++a) {
    const int b = links.col_of_row[a];
    if (b < 0) continue;
    tl[a].next = b;
    tl[b].prev = a;
    ++out.links;
  }
  // Chains from their heads (a link always goes forward in time, so there are no cycles).
  for (int head = 0; head < n; ++head) {
    if (tl[head].prev >= 0) continue;
    int measured = 0;
    for (int k = head; k >= 0; k = tl[k].next) measured += static_cast<int>(tl[k].sweeps.size());
    const bool keep = measured >= o.min_track_sweeps;
    const uint32_t id = keep ? tl[head].id : 0;
    if (!keep) ++out.removed_tracks;
    for (int k = head; k >= 0; k = tl[k].next) {
      out.id_map[tl[k].id] = id;
      if (!keep) continue;
      for (size_t s = 0; s < tl[k].sweeps.size(); ++s) {
        lidar::FootTrack t = tl[k].samples[s];
        t.id = id;
        out.tracks[tl[k].sweeps[s]].push_back(t);
      }
      const int nx = tl[k].next;
      if (nx < 0) continue;
      const int f0 = tl[k].sweeps.back(), f1 = tl[nx].sweeps.front();
      const lidar::FootTrack& a = tl[k].samples.back();
      const lidar::FootTrack& b = tl[nx].samples.front();
      const double span = time_s(f1) - time_s(f0);
      for (int f = f0 + 1; f < f1; ++f) {
        const double u = span > 0 ? (time_s(f) - time_s(f0)) / span : 0.5;
        lidar::FootTrack t = a;
        t.id = id;
        t.xy_m = (1 - u) * a.xy_m + u * b.xy_m;
        t.velocity_mps = span > 0 ? Eigen::Vector2d((b.xy_m - a.xy_m) / span) : a.velocity_mps;
        t.missed_frames = f - f0;
        out.tracks[f].push_back(t);
      }
    }
  }
  for (auto& frame : out.tracks) {
    std::sort(frame.begin(), frame.end(), [](const lidar::FootTrack& x, const lidar::FootTrack& y) { return x.id < y.id; });
  }
  return out;
}

}  // namespace ave::lidar_track
