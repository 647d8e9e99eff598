#include "model_store/avatar/walk_cycle.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <Eigen/Geometry>

namespace ave::avatar {
namespace {

// Mean distance from each of `a` to its nearest in `b`, through a hash grid of `b`.
double MeanNearest(const std::vector<Eigen::Vector3f>& a, const std::vector<Eigen::Vector3f>& b) {
  if (a.empty() || b.empty()) return std::numeric_limits<double>::infinity();
  static constexpr float kCell = 0.05f;
  auto key = [](const Eigen::Vector3i& k) {
    return (static_cast<int64_t>(k.x()) + (1 << 20)) | ((static_cast<int64_t>(k.y()) + (1 << 20)) << 21) |
           ((static_cast<int64_t>(k.z()) + (1 << 20)) << 42);
  };
  auto cell = [](const Eigen::Vector3f& p) -> Eigen::Vector3i { return (p / kCell).array().floor().cast<int>().matrix(); };
  std::unordered_map<int64_t, std::vector<int>> grid;
  for (size_t i = 0; i < b.size(); ++i) grid[key(cell(b[i]))].push_back(static_cast<int>(i));
  double sum = 0;
  for (const Eigen::Vector3f& p : a) {
    const Eigen::Vector3i c = cell(p);
    float best = std::numeric_limits<float>::infinity();
    for (int r = 0; r < 40; ++r) {
      for (int z = -r; z <= r; ++z)
        for (int y = -r; y <= r; ++y)
          for (int x = -r; x <= r; ++x) {
            if (std::max({std::abs(x), std::abs(y), std::abs(z)}) != r) continue;
            const auto it = grid.find(key(c + Eigen::Vector3i(x, y, z)));
            if (it == grid.end()) continue;
            for (int i : it->second) best = std::min(best, (b[i] - p).squaredNorm());
          }
      if (std::isfinite(best) && std::sqrt(best) <= r * kCell) break;
    }
    sum += std::sqrt(best);
  }
  return sum / static_cast<double>(a.size());
}

// avatar_from_world for a root and heading: translate the root to the origin, turn the heading to +x.
Eigen::Affine3d AvatarFromWorld(const Eigen::Vector3d& root, double heading) {
  return Eigen::AngleAxisd(-heading, Eigen::Vector3d::UnitZ()) * Eigen::Translation3d(-root);
}

}  // namespace

std::string WalkCycleOptions::Check() const {
  if (!std::isfinite(min_cycle_s) || min_cycle_s < 0) return "min_cycle_s must be finite and >= 0";
  if (max_points < 10) return "max_points must be >= 10";
  if (heading_half_window < 1) return "heading_half_window must be >= 1";
  if (!std::isfinite(min_travel_m) || min_travel_m < 0) return "min_travel_m must be finite and >= 0";
  return {};
}

Eigen::Vector3d GroundCentroid(const AvatarFrame& frame) {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  double area = 0, z_min = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3f& p : frame.positions_m) z_min = std::min(z_min, static_cast<double>(p.z()));
  for (size_t t = 0; t + 2 < frame.indices.size(); t += 3) {
    const Eigen::Vector3d a = frame.positions_m[frame.indices[t]].cast<double>(), b = frame.positions_m[frame.indices[t + 1]].cast<double>(),
                          c = frame.positions_m[frame.indices[t + 2]].cast<double>();
    const double w = 0.5 * (b - a).cross(c - a).norm();
    sum += w * (a + b + c).head<2>() / 3.0;
    area += w;
  }
  if (area <= 0) return Eigen::Vector3d::Zero();
  return Eigen::Vector3d(sum.x() / area, sum.y() / area, std::isfinite(z_min) ? z_min : 0.0);
}

absl::StatusOr<WalkCycle> FindWalkCycle(const std::vector<AvatarFrame>& frames, const std::vector<Eigen::Vector3d>& roots_m,
                                        double frame_period_s, const std::string& name, const WalkCycleOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("walk cycle options: " + why);
  if (!(std::isfinite(frame_period_s) && frame_period_s > 0)) return absl::InvalidArgumentError("walk cycle: frame_period_s must be > 0");
  if (frames.empty()) return absl::InvalidArgumentError("walk cycle: no frames");
  if (roots_m.size() != frames.size()) {
    return absl::InvalidArgumentError("walk cycle: " + std::to_string(frames.size()) + " frames but " + std::to_string(roots_m.size()) + " roots");
  }
  const int n = static_cast<int>(frames.size());
  for (int f = 0; f < n; ++f) {
    if (!roots_m[f].allFinite()) return absl::InvalidArgumentError("walk cycle: root of frame " + std::to_string(f) + " is not finite");
  }
  WalkCycle out;
  out.sequence.name = name;
  out.sequence.frame_period_s = frame_period_s;
  // Heading per frame: the root's displacement over a window; frames that barely move keep the
  // heading of the nearest frame that does (0 when none moves: a statue faces +x as captured).
  out.heading_rad.assign(n, std::numeric_limits<double>::quiet_NaN());
  for (int f = 0; f < n; ++f) {
    const int a = std::max(0, f - options.heading_half_window), b = std::min(n - 1, f + options.heading_half_window);
    const Eigen::Vector2d d = (roots_m[b] - roots_m[a]).head<2>();
    if (d.norm() >= options.min_travel_m) out.heading_rad[f] = std::atan2(d.y(), d.x());
  }
  for (int pass = 0; pass < 2; ++pass) {  // fill gaps forwards, then backwards
    for (int k = 0; k < n; ++k) {
      const int f = pass == 0 ? k : n - 1 - k, prev = pass == 0 ? f - 1 : f + 1;
      if (std::isnan(out.heading_rad[f]) && prev >= 0 && prev < n && !std::isnan(out.heading_rad[prev])) out.heading_rad[f] = out.heading_rad[prev];
    }
  }
  for (double& h : out.heading_rad)
    if (std::isnan(h)) h = 0;
  auto to_avatar = [&](int f) {
    const Eigen::Affine3d m = AvatarFromWorld(roots_m[f], out.heading_rad[f]);
    AvatarFrame a = frames[f];
    for (Eigen::Vector3f& p : a.positions_m) p = (m * p.cast<double>()).cast<float>();
    for (Eigen::Vector3f& nrm : a.normals) nrm = (m.linear() * nrm.cast<double>()).cast<float>();
    return a;
  };
  if (n == 1) {  // a statue
    out.first = 0;
    out.end = 1;
    out.sequence.stride_m = 0;
    out.sequence.frames.push_back(to_avatar(0));
    return out;
  }
  const int min_span = std::max(1, static_cast<int>(std::ceil(options.min_cycle_s / frame_period_s - 1e-9)));
  if (n <= min_span) {
    return absl::InvalidArgumentError("walk cycle: " + std::to_string(n) + " frames, but the shortest cycle (" + std::to_string(options.min_cycle_s) +
                                      " s) needs " + std::to_string(min_span + 1));
  }
  // Each frame's thinned vertices in the avatar frame.
  std::vector<std::vector<Eigen::Vector3f>> points(n);
  for (int f = 0; f < n; ++f) {
    const AvatarFrame a = to_avatar(f);
    const size_t step = std::max<size_t>(1, a.positions_m.size() / options.max_points);
    for (size_t i = 0; i < a.positions_m.size(); i += step) points[f].push_back(a.positions_m[i]);
    if (points[f].empty()) return absl::InvalidArgumentError("walk cycle: frame " + std::to_string(f) + " has no vertices");
  }
  double best = std::numeric_limits<double>::infinity();
  for (int span = min_span; span < n; ++span) {  // shortest cycle first: ties keep the shorter loop
    for (int i = 0; i + span < n; ++i) {
      const int j = i + span;
      const double d = 0.5 * (MeanNearest(points[i], points[j]) + MeanNearest(points[j], points[i]));
      if (d < best - 1e-9) {
        best = d;
        out.first = i;
        out.end = j;
      }
    }
  }
  out.shape_difference_m = best;
  double stride = 0;
  for (int f = out.first; f < out.end; ++f) stride += (roots_m[f + 1] - roots_m[f]).head<2>().norm();
  out.sequence.stride_m = stride;
  for (int f = out.first; f < out.end; ++f) out.sequence.frames.push_back(to_avatar(f));
  return out;
}

}  // namespace ave::avatar
