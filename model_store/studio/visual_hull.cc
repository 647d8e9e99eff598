#include "model_store/studio/visual_hull.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace ave::studio {
namespace {

// One camera prepared for fast projection: camera_from_world as float rows, intrinsics, and the
// silhouette's integral image (sum of foreground pixels above and left of (u, v)).
struct Projector {
  Eigen::Matrix3f rotation;  // camera_from_world
  Eigen::Vector3f translation;
  float fx, fy, cx, cy;
  int width, height;
  const uint8_t* mask;
  std::vector<int32_t> integral;  // (width + 1) * (height + 1)

  int32_t Sum(int u0, int v0, int u1, int v1) const {  // inclusive pixel rectangle
    const int w = width + 1;
    return integral[static_cast<size_t>(v1 + 1) * w + u1 + 1] - integral[static_cast<size_t>(v0) * w + u1 + 1] -
           integral[static_cast<size_t>(v1 + 1) * w + u0] + integral[static_cast<size_t>(v0) * w + u0];
  }
};

constexpr float kNearM = 0.05f;

Projector MakeProjector(const StudioCameraModel& camera, const Mask& mask) {
  Projector p;
  const Rigid3d camera_from_world = camera.world_from_camera.Inverse();
  p.rotation = camera_from_world.rotation.toRotationMatrix().cast<float>();
  p.translation = camera_from_world.translation.cast<float>();
  const PinholeIntrinsics& k = camera.intrinsics;
  p.fx = static_cast<float>(k.fx);
  p.fy = static_cast<float>(k.fy);
  p.cx = static_cast<float>(k.cx);
  p.cy = static_cast<float>(k.cy);
  p.width = k.width;
  p.height = k.height;
  p.mask = mask.data.data();
  const int w = p.width + 1;
  p.integral.assign(static_cast<size_t>(w) * (p.height + 1), 0);
  for (int v = 0; v < p.height; ++v) {
    int32_t row = 0;
    for (int u = 0; u < p.width; ++u) {
      row += p.mask[static_cast<size_t>(v) * p.width + u] != 0;
      p.integral[static_cast<size_t>(v + 1) * w + u + 1] = p.integral[static_cast<size_t>(v) * w + u + 1] + row;
    }
  }
  return p;
}

enum class CellView { kUnseen, kBackground, kForeground, kMixed };

// How one camera sees an axis-aligned cube: by the pixel rectangle around its corners'
// projections (conservative: the cube's image lies inside it). Pixel u covers [u - 0.5, u + 0.5).
CellView ViewCell(const Projector& p, const Eigen::Vector3f& lo, float size) {
  float umin = 1e30f, umax = -1e30f, vmin = 1e30f, vmax = -1e30f;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3f corner = lo + size * Eigen::Vector3f(c & 1, (c >> 1) & 1, (c >> 2) & 1);
    const Eigen::Vector3f q = p.rotation * corner + p.translation;
    if (q.z() <= kNearM) return CellView::kMixed;  // straddles the camera's plane: decide lower down
    const float u = p.fx * q.x() / q.z() + p.cx, v = p.fy * q.y() / q.z() + p.cy;
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, v);
    vmax = std::max(vmax, v);
  }
  const int u0 = static_cast<int>(std::floor(umin + 0.5f)), u1 = static_cast<int>(std::floor(umax + 0.5f));
  const int v0 = static_cast<int>(std::floor(vmin + 0.5f)), v1 = static_cast<int>(std::floor(vmax + 0.5f));
  if (u1 < 0 || v1 < 0 || u0 >= p.width || v0 >= p.height) return CellView::kUnseen;
  const bool inside = u0 >= 0 && v0 >= 0 && u1 < p.width && v1 < p.height;
  const int cu0 = std::max(u0, 0), cv0 = std::max(v0, 0), cu1 = std::min(u1, p.width - 1), cv1 = std::min(v1, p.height - 1);
  const int32_t fg = p.Sum(cu0, cv0, cu1, cv1);
  const int32_t area = (cu1 - cu0 + 1) * (cv1 - cv0 + 1);
  if (fg == area) return inside ? CellView::kForeground : CellView::kMixed;  // all it shows is foreground
  if (fg == 0 && inside) return CellView::kBackground;
  return CellView::kMixed;
}

// How one camera sees a voxel centre.
CellView ViewPoint(const Projector& p, const Eigen::Vector3f& x) {
  const Eigen::Vector3f q = p.rotation * x + p.translation;
  if (q.z() <= kNearM) return CellView::kUnseen;
  const int u = static_cast<int>(std::floor(p.fx * q.x() / q.z() + p.cx + 0.5f));
  const int v = static_cast<int>(std::floor(p.fy * q.y() / q.z() + p.cy + 0.5f));
  if (u < 0 || v < 0 || u >= p.width || v >= p.height) return CellView::kUnseen;
  return p.mask[static_cast<size_t>(v) * p.width + u] ? CellView::kForeground : CellView::kBackground;
}

struct Carver {
  const std::vector<Projector>& cams;
  const HullOptions& o;
  int min_views;           // the effective minimum (min_views, min_view_fraction)
  Eigen::Vector3f origin;  // of the level-0 grid
  float voxel;
  Eigen::Vector3i limit;   // level-0 voxels per axis inside the bounds
  HullStats stats;
  std::vector<Eigen::Vector3i> full_cells;  // lower corner (voxels) and, in level_of, its level
  std::vector<int> full_levels;
  std::vector<Eigen::Vector3i> voxels;      // surviving finest voxels

  bool VoxelSurvives(const Eigen::Vector3i& v) {
    ++stats.voxels_tested;
    const Eigen::Vector3f centre = origin + voxel * (v.cast<float>() + Eigen::Vector3f::Constant(0.5f));
    int background = 0, seen = 0;
    for (const Projector& p : cams) {
      const CellView view = ViewPoint(p, centre);
      if (view == CellView::kUnseen) continue;
      ++seen;
      if (view == CellView::kBackground && ++background > o.max_background_votes) return false;
    }
    return seen >= min_views;
  }

  // Cell of 2^level voxels a side with lower corner `v` (voxels).
  void Visit(const Eigen::Vector3i& v, int level) {
    if ((v.array() >= limit.array()).any()) return;
    if (level == 0) {
      if (VoxelSurvives(v)) voxels.push_back(v);
      return;
    }
    ++stats.cells_tested;
    const int side = 1 << level;
    const Eigen::Vector3f lo = origin + voxel * v.cast<float>();
    int background = 0, unsure = 0, seen_whole = 0, unseen = 0;
    for (const Projector& p : cams) {
      switch (ViewCell(p, lo, voxel * side)) {
        case CellView::kUnseen:
          if (static_cast<int>(cams.size()) - ++unseen < min_views) return;  // outside the capture volume
          break;
        case CellView::kBackground: ++background; ++seen_whole; break;
        case CellView::kForeground: ++seen_whole; break;
        case CellView::kMixed: ++unsure; break;
      }
      if (background > o.max_background_votes) return;  // every voxel of it is carved
    }
    const bool within = ((v.array() + side) <= limit.array()).all();
    if (background + unsure <= o.max_background_votes && seen_whole >= min_views && within) {
      full_cells.push_back(v);  // every voxel of it survives
      full_levels.push_back(level);
      return;
    }
    const int half = side / 2;
    for (int c = 0; c < 8; ++c) Visit(v + half * Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1), level - 1);
  }
};

}  // namespace

std::string HullOptions::Check() const {
  if (!std::isfinite(voxel_m) || voxel_m <= 0.001 || voxel_m > 1) return "voxel_m must be in (0.001, 1]";
  if (max_background_votes < 0) return "max_background_votes must be >= 0";
  if (min_views < 1) return "min_views must be >= 1";
  if (!(min_view_fraction >= 0 && min_view_fraction <= 1)) return "min_view_fraction must be in [0, 1]";
  if (!std::isfinite(floor_z_m)) return "floor_z_m must be finite";
  if (!(bad_camera_fraction >= 0)) return "bad_camera_fraction must be >= 0";
  if (!bounds_m.isEmpty() && !(bounds_m.min().allFinite() && bounds_m.max().allFinite())) return "bounds_m must be finite";
  return {};
}

int64_t VoxelGrid::Count() const { return std::count(occupied.begin(), occupied.end(), uint8_t{1}); }

absl::StatusOr<Eigen::AlignedBox3d> BoundsFromCameras(const std::vector<StudioCameraModel>& cameras, double floor_z_m) {
  if (cameras.empty()) return absl::InvalidArgumentError("visual hull: no cameras");
  Eigen::AlignedBox3d box;
  for (const StudioCameraModel& c : cameras) box.extend(c.world_from_camera.translation);
  box.min().z() = floor_z_m;
  const Eigen::Vector3d extent = box.max() - box.min();
  constexpr double kFlatM = 0.1;
  static const char* kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!(extent[a] > kFlatM)) {
      return absl::InvalidArgumentError(std::string("visual hull: the ") + std::to_string(cameras.size()) +
                                        " camera centres span only " + std::to_string(extent[a]) + " m along " + kAxis[a] +
                                        " (collinear or coplanar cameras enclose no volume): give HullOptions.bounds_m");
    }
  }
  return box;
}

absl::StatusOr<VoxelGrid> CarveVisualHull(const std::vector<StudioCameraModel>& cameras, const std::vector<Mask>& silhouettes,
                                          const HullOptions& options, HullStats* stats) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("visual hull options: " + why);
  if (cameras.size() != silhouettes.size()) {
    return absl::InvalidArgumentError("visual hull: " + std::to_string(cameras.size()) + " cameras but " +
                                      std::to_string(silhouettes.size()) + " silhouettes");
  }
  std::vector<Projector> cams;
  for (size_t i = 0; i < cameras.size(); ++i) {
    const PinholeIntrinsics& k = cameras[i].intrinsics;
    if (const std::string why = k.Check(); !why.empty()) return absl::InvalidArgumentError("camera " + cameras[i].id + ": " + why);
    const Mask& m = silhouettes[i];
    if (m.width != k.width || m.height != k.height || m.data.size() != static_cast<size_t>(k.width) * k.height) {
      return absl::InvalidArgumentError("camera " + cameras[i].id + ": silhouette is " + std::to_string(m.width) + "x" +
                                        std::to_string(m.height) + ", the camera " + std::to_string(k.width) + "x" +
                                        std::to_string(k.height));
    }
    cams.push_back(MakeProjector(cameras[i], m));
  }
  Eigen::AlignedBox3d bounds = options.bounds_m;
  if (bounds.isEmpty()) {
    absl::StatusOr<Eigen::AlignedBox3d> b = BoundsFromCameras(cameras, options.floor_z_m);
    if (!b.ok()) return b.status();
    bounds = *b;
  }
  const Eigen::Vector3d extent = bounds.max() - bounds.min();
  const Eigen::Vector3d cells = (extent / options.voxel_m).array().ceil();
  if ((cells.array() < 1).any() || cells.prod() > 4e12) {
    return absl::InvalidArgumentError("visual hull: bounds of " + std::to_string(extent.x()) + " x " + std::to_string(extent.y()) + " x " +
                                      std::to_string(extent.z()) + " m at voxel " + std::to_string(options.voxel_m) + " m");
  }
  const int min_views =
      std::max(options.min_views, static_cast<int>(std::ceil(options.min_view_fraction * static_cast<double>(cams.size()) - 1e-9)));
  Carver carver{cams, options, min_views, bounds.min().cast<float>(), static_cast<float>(options.voxel_m), cells.cast<int>(), {}, {}, {}, {}};
  if (options.hierarchical) {
    // Top cells of at most ~0.4 m: a handful of thousand cells over a studio.
    int top = 0;
    while (top < 10 && options.voxel_m * (2 << top) <= 0.4) ++top;
    const int side = 1 << top;
    for (int z = 0; z < carver.limit.z(); z += side)
      for (int y = 0; y < carver.limit.y(); y += side)
        for (int x = 0; x < carver.limit.x(); x += side) carver.Visit({x, y, z}, top);
  } else {
    if (cells.prod() > 2e9) return absl::InvalidArgumentError("visual hull: flat carving of more than 2e9 voxels; use hierarchical");
    for (int z = 0; z < carver.limit.z(); ++z)
      for (int y = 0; y < carver.limit.y(); ++y)
        for (int x = 0; x < carver.limit.x(); ++x)
          if (carver.VoxelSurvives({x, y, z})) carver.voxels.push_back({x, y, z});
  }
  // The tight grid: the survivors' box, one empty voxel all round.
  Eigen::Vector3i lo = Eigen::Vector3i::Constant(INT32_MAX), hi = Eigen::Vector3i::Constant(INT32_MIN);
  for (const Eigen::Vector3i& v : carver.voxels) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  for (size_t i = 0; i < carver.full_cells.size(); ++i) {
    lo = lo.cwiseMin(carver.full_cells[i]);
    hi = hi.cwiseMax(carver.full_cells[i] + Eigen::Vector3i::Constant((1 << carver.full_levels[i]) - 1));
  }
  VoxelGrid grid;
  grid.voxel_m = options.voxel_m;
  if (lo.x() > hi.x()) {  // nothing survived
    lo = hi = (cells / 2).cast<int>();
    grid.origin_m = bounds.min() + options.voxel_m * (lo.cast<double>() - Eigen::Vector3d::Ones());
    grid.size = Eigen::Vector3i::Constant(3);
    grid.occupied.assign(27, 0);
  } else {
    grid.origin_m = bounds.min() + options.voxel_m * (lo.cast<double>() - Eigen::Vector3d::Ones());
    grid.size = hi - lo + Eigen::Vector3i::Constant(3);
    grid.occupied.assign(static_cast<size_t>(grid.size.x()) * grid.size.y() * grid.size.z(), 0);
    const Eigen::Vector3i shift = lo - Eigen::Vector3i::Ones();
    for (const Eigen::Vector3i& v : carver.voxels) {
      const Eigen::Vector3i g = v - shift;
      grid.occupied[grid.Index(g.x(), g.y(), g.z())] = 1;
    }
    for (size_t i = 0; i < carver.full_cells.size(); ++i) {
      const Eigen::Vector3i g = carver.full_cells[i] - shift;
      const int side = 1 << carver.full_levels[i];
      for (int z = 0; z < side; ++z)
        for (int y = 0; y < side; ++y)
          std::fill_n(grid.occupied.begin() + static_cast<std::ptrdiff_t>(grid.Index(g.x(), g.y() + y, g.z() + z)), side, uint8_t{1});
    }
  }
  // Strict pass, without the cameras that disagree with most of the survivors (a sample of
  // every 8th survivor decides), carving the survivors' box again hierarchically with no tolerance.
  if (options.max_background_votes > 0 && options.bad_camera_fraction <= 1 && grid.Count() > 0) {
    std::vector<int64_t> seen(cams.size(), 0), background(cams.size(), 0);
    for (int z = 0; z < grid.size.z(); z += 2)
      for (int y = 0; y < grid.size.y(); y += 2)
        for (int x = 0; x < grid.size.x(); x += 2) {
          if (!grid.occupied[grid.Index(x, y, z)]) continue;
          const Eigen::Vector3f centre = grid.Center(x, y, z).cast<float>();
          for (size_t c = 0; c < cams.size(); ++c) {
            const CellView view = ViewPoint(cams[c], centre);
            seen[c] += view != CellView::kUnseen;
            background[c] += view == CellView::kBackground;
          }
        }
    // At most max_background_votes cameras are dropped (the tolerance's budget), worst first.
    std::vector<std::pair<double, size_t>> share;
    for (size_t c = 0; c < cams.size(); ++c) {
      const double f = seen[c] > 0 ? static_cast<double>(background[c]) / static_cast<double>(seen[c]) : 0.0;
      if (f > options.bad_camera_fraction) share.emplace_back(-f, c);
    }
    std::sort(share.begin(), share.end());
    std::vector<bool> bad(cams.size(), false);
    for (size_t i = 0; i < share.size() && static_cast<int>(i) < options.max_background_votes; ++i) bad[share[i].second] = true;
    std::vector<StudioCameraModel> good_cameras;
    std::vector<Mask> good_masks;
    for (size_t c = 0; c < cams.size(); ++c) {
      if (bad[c]) {
        carver.stats.bad_cameras.push_back(cameras[c].id);
      } else {
        good_cameras.push_back(cameras[c]);
        good_masks.push_back(silhouettes[c]);
      }
    }
    HullOptions strict = options;  // the tolerant pass settled who sees enough; AND with it below
    strict.max_background_votes = 0;
    strict.min_views = 1;
    strict.min_view_fraction = 0;
    strict.bounds_m = Eigen::AlignedBox3d(grid.origin_m, grid.origin_m + options.voxel_m * grid.size.cast<double>());
    HullStats strict_stats;
    absl::StatusOr<VoxelGrid> refined = CarveVisualHull(good_cameras, good_masks, strict, &strict_stats);
    if (!refined.ok()) return refined.status();
    carver.stats.cells_tested += strict_stats.cells_tested;
    carver.stats.voxels_tested += strict_stats.voxels_tested;
    const Eigen::Vector3i offset = ((refined->origin_m - grid.origin_m) / options.voxel_m).array().round().cast<int>();
    for (int z = 0; z < refined->size.z(); ++z)
      for (int y = 0; y < refined->size.y(); ++y)
        for (int x = 0; x < refined->size.x(); ++x) {
          uint8_t& v = refined->occupied[refined->Index(x, y, z)];
          const Eigen::Vector3i g = Eigen::Vector3i(x, y, z) + offset;
          if (v && ((g.array() < 0).any() || (g.array() >= grid.size.array()).any() || !grid.occupied[grid.Index(g.x(), g.y(), g.z())])) v = 0;
        }
    grid = *std::move(refined);
  }
  if (stats) *stats = carver.stats;
  return grid;
}

}  // namespace ave::studio
