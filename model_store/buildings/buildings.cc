#include "model_store/buildings/buildings.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <map>
#include <numeric>

#include <opencv2/imgproc.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_format.h"
#include "model_store/buildings/roof_fit.h"

namespace ave::model {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using internal::PartRequest;

constexpr uint8_t kLasBuilding = 6;
constexpr uint8_t kLasHighVegetation = 5;
constexpr int kNeighbours4[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};

// Points bucketed by grid cell (counting sort), in the grid's local frame.
struct CellIndex {
  std::vector<uint32_t> start;  // CellCount() + 1 offsets into `order`
  std::vector<uint32_t> order;  // point indices
  Vector3d shift = Vector3d::Zero();  // cloud local -> grid local

  CellIndex(const PointCloud& cloud, const HeightGrid& grid) : start(grid.CellCount() + 1, 0) {
    shift = cloud.origin - grid.origin;
    std::vector<int64_t> cell_of(cloud.size(), -1);
    for (size_t i = 0; i < cloud.size(); ++i) {
      const Vector3d p = cloud.xyz[i].cast<double>() + shift;
      int c, r;
      if (!p.allFinite() || !grid.CellOf(p.x(), p.y(), &c, &r)) continue;
      cell_of[i] = static_cast<int64_t>(grid.Index(c, r));
      ++start[cell_of[i] + 1];
    }
    std::partial_sum(start.begin(), start.end(), start.begin());
    order.resize(start.back());
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < cloud.size(); ++i)
      if (cell_of[i] >= 0) order[fill[cell_of[i]]++] = static_cast<uint32_t>(i);
  }
  Vector3d Point(const PointCloud& cloud, uint32_t i) const { return cloud.xyz[i].cast<double>() + shift; }
};

bool HasStats(const HeightGrid& g) {
  return g.zmax.size() == g.CellCount() && g.count.size() == g.CellCount() && g.CellCount() > 0;
}
bool HasDtm(const HeightGrid& g) { return g.dtm.size() == g.CellCount() && g.CellCount() > 0; }

// Height of a cell's highest point above the bare earth; NaN for empty cells or no DTM.
double HeightAboveGround(const HeightGrid& g, size_t cell) {
  if (!HasDtm(g) || g.count[cell] == 0) return std::nan("");
  return static_cast<double>(g.zmax[cell]) - g.dtm[cell];
}

// Cells 4-connected to `seed` for which keep(cell) holds.
template <typename Keep>
std::vector<size_t> GrowRegion(const HeightGrid& g, size_t seed, std::vector<char>& visited, Keep keep) {
  std::vector<size_t> out;
  std::deque<size_t> queue{seed};
  visited[seed] = 1;
  while (!queue.empty()) {
    const size_t cell = queue.front();
    queue.pop_front();
    out.push_back(cell);
    const int col = static_cast<int>(cell % g.cols), row = static_cast<int>(cell / g.cols);
    for (const auto& d : kNeighbours4) {
      const int c = col + d[0], r = row + d[1];
      if (c < 0 || r < 0 || c >= g.cols || r >= g.rows) continue;
      const size_t n = g.Index(c, r);
      if (visited[n] || !keep(cell, n)) continue;
      visited[n] = 1;
      queue.push_back(n);
    }
  }
  return out;
}

Vector2d CenterOf(const HeightGrid& g, size_t cell) {
  return g.CellCenter(static_cast<int>(cell % g.cols), static_cast<int>(cell / g.cols));
}

// Column and row range (inclusive) of a set of cells: {c0, r0, c1, r1}.
std::array<int, 4> CellBounds(const HeightGrid& g, const std::vector<size_t>& cells) {
  std::array<int, 4> b{g.cols, g.rows, -1, -1};
  for (size_t cell : cells) {
    const int c = static_cast<int>(cell % g.cols), r = static_cast<int>(cell / g.cols);
    b[0] = std::min(b[0], c), b[1] = std::min(b[1], r), b[2] = std::max(b[2], c), b[3] = std::max(b[3], r);
  }
  return b;
}

// Median roughness of a blob: rms residual of the least-squares plane through each interior
// 3x3 block of highest points. Roofs are planar (or gently curved) so their median is small; tree
// crowns are lumpy and strongly curved at their size. Measured on blocks of about 0.5 m (several
// cells when the grid is finer, so empty cells between sparse points do not matter) and scaled to
// what a 0.5 m grid would show (curvature residuals grow with the block size squared), so one
// threshold serves every resolution.
constexpr double kRoughnessBlock_m = 0.5;
double MedianRoughness(const HeightGrid& g, const std::vector<size_t>& cells) {
  const int k = std::max(1, static_cast<int>(std::lround(kRoughnessBlock_m / g.resolution_m)));
  const auto [c0, r0, c1, r1] = CellBounds(g, cells);
  if (cells.empty()) return 0;
  const int bw = (c1 - c0) / k + 1, bh = (r1 - r0) / k + 1;
  std::vector<double> block(static_cast<size_t>(bw) * bh, std::nan(""));
  for (size_t cell : cells) {
    if (g.count[cell] == 0) continue;
    double& z = block[((cell / g.cols - r0) / k) * bw + (cell % g.cols - c0) / k];
    z = std::isnan(z) ? g.zmax[cell] : std::max(z, static_cast<double>(g.zmax[cell]));
  }
  std::vector<double> rough;
  for (int by = 1; by + 1 < bh; ++by)
    for (int bx = 1; bx + 1 < bw; ++bx) {
      double z[3][3];
      bool interior = true;
      for (int dy = -1; dy <= 1 && interior; ++dy)
        for (int dx = -1; dx <= 1 && interior; ++dx) {
          z[dy + 1][dx + 1] = block[(by + dy) * bw + bx + dx];
          interior = !std::isnan(z[dy + 1][dx + 1]);
        }
      if (!interior) continue;
      double mean = 0, sx = 0, sy = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) mean += z[dy + 1][dx + 1] / 9, sx += dx * z[dy + 1][dx + 1] / 6, sy += dy * z[dy + 1][dx + 1] / 6;
      double ss = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const double r = z[dy + 1][dx + 1] - (mean + sx * dx + sy * dy);
          ss += r * r;
        }
      rough.push_back(std::sqrt(ss / 9));
    }
  if (rough.empty()) return std::nan("");  // too small to have an interior block
  std::nth_element(rough.begin(), rough.begin() + rough.size() / 2, rough.end());
  const double block_m = k * g.resolution_m;
  return rough[rough.size() / 2] * (kRoughnessBlock_m * kRoughnessBlock_m) / (block_m * block_m);
}

// Signed area (counter-clockwise positive).
double PolygonArea(const std::vector<Vector2d>& poly) {
  double a2 = 0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vector2d& a = poly[i];
    const Vector2d& b = poly[(i + 1) % poly.size()];
    a2 += a.x() * b.y() - b.x() * a.y();
  }
  return 0.5 * a2;
}

// Outline of a set of cells: the outer contour through boundary cell centres, simplified to
// within one cell, counter-clockwise.
std::vector<Vector2d> OutlineOf(const HeightGrid& g, const std::vector<size_t>& cells) {
  const auto [c0, r0, c1, r1] = CellBounds(g, cells);
  if (cells.empty()) return {};
  cv::Mat mask = cv::Mat::zeros(r1 - r0 + 3, c1 - c0 + 3, CV_8U);
  for (size_t cell : cells) mask.at<uint8_t>(static_cast<int>(cell / g.cols) - r0 + 1, static_cast<int>(cell % g.cols) - c0 + 1) = 255;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  if (contours.empty()) return {};
  const auto& biggest = *std::max_element(contours.begin(), contours.end(), [](const auto& a, const auto& b) {
    return cv::contourArea(a) < cv::contourArea(b);
  });
  std::vector<cv::Point> simple;
  cv::approxPolyDP(biggest, simple, 1.0, true);
  std::vector<Vector2d> out;
  for (const auto& p : simple) out.push_back(g.CellCenter(p.x + c0 - 1, p.y + r0 - 1));
  if (PolygonArea(out) < 0) std::reverse(out.begin(), out.end());
  return out;
}

// The cells plus any holes they enclose (a dome standing on a flat roof leaves one).
std::vector<size_t> FillHoles(const HeightGrid& g, const std::vector<size_t>& cells) {
  const auto [c0, r0, c1, r1] = CellBounds(g, cells);
  const int w = c1 - c0 + 3, h = r1 - r0 + 3;
  std::vector<char> state(static_cast<size_t>(w) * h, 0);  // 1 in set, 2 reached from outside
  for (size_t cell : cells) state[(cell / g.cols - r0 + 1) * w + (cell % g.cols - c0 + 1)] = 1;
  std::deque<int> queue{0};
  state[0] = 2;
  while (!queue.empty()) {
    const int i = queue.front();
    queue.pop_front();
    for (const auto& d : kNeighbours4) {
      const int x = i % w + d[0], y = i / w + d[1];
      if (x < 0 || y < 0 || x >= w || y >= h || state[y * w + x]) continue;
      state[y * w + x] = 2;
      queue.push_back(y * w + x);
    }
  }
  std::vector<size_t> out = cells;
  for (int y = 1; y < h - 1; ++y)
    for (int x = 1; x < w - 1; ++x)
      if (state[y * w + x] == 0) out.push_back(g.Index(x + c0 - 1, y + r0 - 1));
  return out;
}

// Roof points of a set of cells: within 1 m of each cell's highest point (wall and overhang
// points below are left out) and above `min_z`.
std::vector<Vector3d> RoofPoints(const PointCloud& cloud, const HeightGrid& g, const CellIndex& index,
                                 const std::vector<size_t>& cells, double min_z) {
  std::vector<Vector3d> out;
  for (size_t cell : cells)
    for (uint32_t k = index.start[cell]; k < index.start[cell + 1]; ++k) {
      const Vector3d p = index.Point(cloud, index.order[k]);
      if (p.z() >= g.zmax[cell] - 1.0 && p.z() > min_z) out.push_back(p);
    }
  return out;
}

std::vector<Vector2d> Centers(const HeightGrid& g, const std::vector<size_t>& cells) {
  std::vector<Vector2d> out;
  out.reserve(cells.size());
  for (size_t cell : cells) out.push_back(CenterOf(g, cell));
  return out;
}

// Fits one primitive to the roof points of `cells` (holes filled for the footprint shape).
// `inlier_fraction`, when given, receives the share of roof points the trimmed fit kept: a low
// share means part of the roof belongs to another primitive even when the kept points fit well.
absl::StatusOr<BuildingPrimitive> FitCells(const PointCloud& cloud, const HeightGrid& g, const CellIndex& index,
                                           const std::vector<size_t>& cells, double base_z, double min_z,
                                           const PartRequest& request, double* inlier_fraction = nullptr) {
  const std::vector<Vector3d> roof = RoofPoints(cloud, g, index, cells, min_z);
  const std::vector<size_t> filled = FillHoles(g, cells);
  // Points up to two cells around the part: a ground filter may call mixed edge cells ground.
  std::vector<Vector3d> around;
  std::vector<char> seen(g.CellCount(), 0);
  for (size_t cell : filled) {
    const int col = static_cast<int>(cell % g.cols), row = static_cast<int>(cell / g.cols);
    for (int dy = -2; dy <= 2; ++dy)
      for (int dx = -2; dx <= 2; ++dx) {
        const int c = col + dx, r = row + dy;
        if (c < 0 || r < 0 || c >= g.cols || r >= g.rows || seen[g.Index(c, r)]) continue;
        const size_t n = g.Index(c, r);
        seen[n] = 1;
        for (uint32_t k = index.start[n]; k < index.start[n + 1]; ++k) {
          const Vector3d p = index.Point(cloud, index.order[k]);
          if (p.z() > min_z) around.push_back(p);
        }
      }
  }
  absl::StatusOr<BuildingPrimitive> part = internal::FitPart(roof, Centers(g, filled), g.resolution_m, base_z, request, &around);
  if (inlier_fraction) *inlier_fraction = part.ok() && !roof.empty() ? static_cast<double>(part->point_count) / roof.size() : 0.0;
  return part;
}

// Splits a building blob into roof regions at height steps, then merges neighbours whose union
// one primitive still fits (a dome's steep rim, a ridge): what stays apart are the parts of a
// multi-primitive building (AVE §4.1 "assembly of buildings from multiple primitives").
std::vector<std::vector<size_t>> SplitIntoParts(const PointCloud& cloud, const HeightGrid& g, const CellIndex& index,
                                                const std::vector<size_t>& cells, double base_z, double min_z,
                                                const BuildingOptions& o) {
  std::map<size_t, int> region_of;
  for (size_t cell : cells) region_of[cell] = -1;
  std::vector<std::vector<size_t>> regions;
  std::vector<char> visited(g.CellCount(), 0);
  std::vector<char> outside(g.CellCount(), 1);
  for (size_t cell : cells) outside[cell] = 0;
  for (size_t cell : cells) {
    if (visited[cell]) continue;
    regions.push_back(GrowRegion(g, cell, visited, [&](size_t a, size_t b) {
      // Empty cells (finer grid than the point spacing) join whichever region reaches them first.
      return !outside[b] && (g.count[a] == 0 || g.count[b] == 0 || std::abs(g.zmax[a] - g.zmax[b]) <= o.part_step_m);
    }));
    for (size_t c : regions.back()) region_of[c] = static_cast<int>(regions.size()) - 1;
  }
  auto shared_edges = [&](int a) {
    std::map<int, int> edges;
    for (size_t cell : regions[a]) {
      const int col = static_cast<int>(cell % g.cols), row = static_cast<int>(cell / g.cols);
      for (const auto& d : kNeighbours4) {
        const int c = col + d[0], r = row + d[1];
        if (c < 0 || r < 0 || c >= g.cols || r >= g.rows) continue;
        const auto it = region_of.find(g.Index(c, r));
        if (it != region_of.end() && it->second != a) ++edges[it->second];
      }
    }
    return edges;
  };
  auto merge = [&](int into, int from) {
    for (size_t c : regions[from]) region_of[c] = into;
    regions[into].insert(regions[into].end(), regions[from].begin(), regions[from].end());
    regions[from].clear();
  };
  const double cell_area = g.resolution_m * g.resolution_m;
  for (bool changed = true; changed;) {
    changed = false;
    // Smallest live region first.
    std::vector<int> live;
    for (int i = 0; i < static_cast<int>(regions.size()); ++i)
      if (!regions[i].empty()) live.push_back(i);
    if (live.size() < 2) break;
    std::sort(live.begin(), live.end(), [&](int a, int b) { return regions[a].size() < regions[b].size(); });
    for (int a : live) {
      const std::map<int, int> edges = shared_edges(a);
      if (edges.empty()) continue;
      const int b = std::max_element(edges.begin(), edges.end(), [](auto x, auto y) { return x.second < y.second; })->first;
      bool join = regions[a].size() * cell_area < o.min_part_area_m2;
      if (!join) {
        std::vector<size_t> both = regions[a];
        both.insert(both.end(), regions[b].begin(), regions[b].end());
        double kept = 0;
        const absl::StatusOr<BuildingPrimitive> fit = FitCells(cloud, g, index, both, base_z, min_z, {}, &kept);
        join = fit.ok() && fit->rms_m <= o.part_merge_rms_m && kept >= 0.95;
      }
      if (join) {
        merge(b, a);
        changed = true;
        break;
      }
    }
  }
  std::vector<std::vector<size_t>> out;
  for (auto& r : regions)
    if (!r.empty()) out.push_back(std::move(r));
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.size() > b.size(); });
  return out;
}

constexpr size_t kMaxParts = 8;

// Connected groups (at least min_part_area_m2) of a region's cells whose highest point stands
// more than part_step_m above the fitted part's roof.
std::vector<std::vector<size_t>> CellsAbove(const HeightGrid& g, const std::vector<size_t>& cells, const BuildingPrimitive& part,
                                            const BuildingOptions& o) {
  std::vector<char> up(g.CellCount(), 0), visited(g.CellCount(), 0);
  for (size_t c : cells) {
    const Vector2d p = CenterOf(g, c);
    const std::optional<double> roof = internal::PrimitiveRoofAt(part, p.x(), p.y());
    up[c] = roof && g.zmax[c] > *roof + o.part_step_m;
  }
  std::vector<std::vector<size_t>> out;
  for (size_t c : cells) {
    if (!up[c] || visited[c]) continue;
    std::vector<size_t> group = GrowRegion(g, c, visited, [&](size_t, size_t n) { return up[n] != 0; });
    if (group.size() * g.resolution_m * g.resolution_m >= o.min_part_area_m2 && group.size() < cells.size())
      out.push_back(std::move(group));
  }
  return out;
}

double MaxDtm(const HeightGrid& g, const std::vector<size_t>& cells) {
  double best = -1e300;
  for (size_t c : cells)
    if (std::isfinite(g.dtm[c])) best = std::max(best, static_cast<double>(g.dtm[c]));
  return best > -1e300 ? best : 0.0;
}

bool InsidePolygon(const std::vector<Vector2d>& poly, const Vector2d& p) {
  bool in = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Vector2d& a = poly[i];
    const Vector2d& b = poly[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) && p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) in = !in;
  }
  return in;
}


}  // namespace

const char* RoofTypeName(RoofType type) {
  switch (type) {
    case RoofType::kFlat: return "flat";
    case RoofType::kShed: return "shed";
    case RoofType::kGable: return "gable";
    case RoofType::kHip: return "hip";
    case RoofType::kDome: return "dome";
    case RoofType::kCylinder: return "cylinder";
  }
  return "unknown";
}

const char* PrimitiveTypeName(PrimitiveType type) {
  switch (type) {
    case PrimitiveType::kBox: return "box";
    case PrimitiveType::kWedge: return "wedge";
    case PrimitiveType::kCylinder: return "cylinder";
    case PrimitiveType::kSphere: return "sphere";
    case PrimitiveType::kPolyhedron: return "polyhedron";
  }
  return "unknown";
}

std::string BuildingOptions::Check() const {
  if (!(min_height_m > 0)) return "min_height_m must be > 0";
  if (!(min_area_m2 > 0)) return "min_area_m2 must be > 0";
  if (!(max_roughness_m > 0)) return "max_roughness_m must be > 0";
  if (!(small_blob_max_roughness_m > 0)) return "small_blob_max_roughness_m must be > 0";
  if (!(small_blob_area_m2 >= 0)) return "small_blob_area_m2 must be >= 0";
  if (!(part_step_m > 0)) return "part_step_m must be > 0";
  if (!(min_part_area_m2 >= 0)) return "min_part_area_m2 must be >= 0";
  if (!(part_merge_rms_m > 0)) return "part_merge_rms_m must be > 0";
  return "";
}

std::vector<BuildingRecord> ExtractBuildings(const PointCloud& cloud, const HeightGrid& grid, const BuildingOptions& options,
                                             std::vector<uint8_t>* point_class_out) {
  std::vector<BuildingRecord> out;
  if (point_class_out && point_class_out->size() != cloud.size()) point_class_out->assign(cloud.size(), 1);
  if (!HasStats(grid) || !HasDtm(grid) || !options.Check().empty()) return out;
  const CellIndex index(cloud, grid);
  // Candidates by height above the DTM alone, not by the filter's cell class: a ground filter
  // working on each cell's lowest point calls mixed cells at roof edges and crown rims ground, which
  // would shrink footprints and leave tree crowns without their lumpy rims.
  std::vector<char> candidate(grid.CellCount(), 0);
  for (size_t i = 0; i < grid.CellCount(); ++i) candidate[i] = HeightAboveGround(grid, i) > options.min_height_m;
  // Cells finer than the point spacing (more than 30 % of the cells empty) leave empty cells between
  // roof points: an empty cell with at least two candidate cells among its eight neighbours joins
  // them, so roofs stay connected. Not at coarser grids, where an empty strip is a real gap
  // between two buildings.
  size_t empty = 0;
  for (size_t i = 0; i < grid.CellCount(); ++i) empty += grid.count[i] == 0;
  std::vector<char> filled = candidate;
  for (int r = 1; r + 1 < grid.rows && empty > 0.3 * grid.CellCount(); ++r)
    for (int c = 1; c + 1 < grid.cols; ++c) {
      const size_t i = grid.Index(c, r);
      if (grid.count[i] != 0) continue;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) n += candidate[grid.Index(c + dx, r + dy)];
      filled[i] = n >= 2;
    }
  candidate.swap(filled);
  std::vector<char> visited(grid.CellCount(), 0);
  const double cell_area = grid.resolution_m * grid.resolution_m;
  for (size_t seed = 0; seed < grid.CellCount(); ++seed) {
    if (!candidate[seed] || visited[seed]) continue;
    const std::vector<size_t> blob = GrowRegion(grid, seed, visited, [&](size_t, size_t n) { return candidate[n] != 0; });
    if (blob.size() * cell_area < options.min_area_m2) continue;
    size_t points = 0, multi = 0;
    for (size_t c : blob)
      for (uint32_t k = index.start[c]; k < index.start[c + 1]; ++k) {
        ++points;
        if (cloud.number_of_returns.size() == cloud.size() && cloud.number_of_returns[index.order[k]] > 1) ++multi;
      }
    // Vegetation: lumpy, or small and curved like a crown (a lone dome under small_blob_area_m2
    // is read as a tree), or mostly multi-return pulses when the file has them.
    const double rough = MedianRoughness(grid, blob);
    const bool small = blob.size() * cell_area < options.small_blob_area_m2;
    // A small blob without a single interior block (cells coarser than a crown) cannot show its
    // shape: read as vegetation; a large one as a building.
    const bool vegetation = rough > options.max_roughness_m || (small && !(rough <= options.small_blob_max_roughness_m)) ||
                            (points > 0 && multi > options.max_multi_return_fraction * points);
    const double base_z = MaxDtm(grid, blob);
    const double min_z = base_z + 0.5 * options.min_height_m;
    auto label = [&](uint8_t code) {
      if (!point_class_out) return;
      for (size_t c : blob)
        for (uint32_t k = index.start[c]; k < index.start[c + 1]; ++k)
          if (index.Point(cloud, index.order[k]).z() > grid.dtm[c] + 0.5 * options.min_height_m) (*point_class_out)[index.order[k]] = code;
    };
    if (vegetation) {
      label(kLasHighVegetation);
      continue;
    }
    BuildingRecord rec;
    std::vector<std::vector<size_t>> regions = SplitIntoParts(cloud, grid, index, blob, base_z, min_z, options);
    for (size_t r = 0; r < regions.size() && r < kMaxParts; ++r) {
      absl::StatusOr<BuildingPrimitive> part = FitCells(cloud, grid, index, regions[r], base_z, min_z, {});
      if (!part.ok()) continue;
      // Cells standing well above this part's roof (a dome or tower on it) become parts of their own.
      std::vector<std::vector<size_t>> above = CellsAbove(grid, regions[r], *part, options);
      if (!above.empty()) {
        std::vector<char> moved(grid.CellCount(), 0);
        for (const auto& a : above)
          for (size_t c : a) moved[c] = 1;
        std::erase_if(regions[r], [&](size_t c) { return moved[c] != 0; });
        for (auto& a : above) regions.push_back(std::move(a));
        part = FitCells(cloud, grid, index, regions[r], base_z, min_z, {});
        if (!part.ok()) continue;
      }
      rec.parts.push_back(*std::move(part));
    }
    std::stable_sort(rec.parts.begin(), rec.parts.end(), [](const BuildingPrimitive& a, const BuildingPrimitive& b) {
      return a.size_m.prod() > b.size_m.prod();
    });
    if (rec.parts.empty()) continue;
    rec.id = static_cast<uint32_t>(out.size());
    rec.roof = rec.parts.front().roof;
    rec.footprint_m = OutlineOf(grid, blob);
    rec.area_m2 = blob.size() * cell_area;
    rec.point_count = static_cast<uint32_t>(points);
    label(kLasBuilding);
    out.push_back(std::move(rec));
  }
  return out;
}

absl::StatusOr<BuildingRecord> FitBuilding(const PointCloud& cloud, const HeightGrid& grid,
                                           const std::vector<Eigen::Vector2d>& footprint_m, PrimitiveType type, RoofType roof) {
  if (!HasStats(grid)) return absl::FailedPreconditionError("height grid has no cell statistics");
  for (const auto& v : footprint_m)
    if (!v.allFinite()) return absl::InvalidArgumentError("footprint has a non-finite vertex");
  const BuildingOptions defaults;
  const CellIndex index(cloud, grid);
  std::vector<size_t> cells;
  std::vector<Vector2d> polygon;
  if (footprint_m.size() == 1) {
    if (!HasDtm(grid)) return absl::FailedPreconditionError("a click needs the ground model (grid.dtm is empty)");
    int col, row;
    const Vector2d click = footprint_m.front();
    if (!grid.CellOf(click.x(), click.y(), &col, &row))
      return absl::InvalidArgumentError(absl::StrFormat("click (%.2f, %.2f) lies outside the grid", click.x(), click.y()));
    const size_t seed = grid.Index(col, row);
    const double h = HeightAboveGround(grid, seed);
    if (!(h > defaults.min_height_m))
      return absl::NotFoundError(absl::StrFormat("click (%.2f, %.2f) is not on a building: %.2f m above ground (need > %.1f)",
                                                 click.x(), click.y(), h, defaults.min_height_m));
    std::vector<char> visited(grid.CellCount(), 0);
    cells = GrowRegion(grid, seed, visited, [&](size_t, size_t n) { return HeightAboveGround(grid, n) > defaults.min_height_m; });
  } else if (footprint_m.size() >= 3) {
    polygon = footprint_m;
    if (PolygonArea(polygon) < 0) std::reverse(polygon.begin(), polygon.end());
    if (std::abs(PolygonArea(polygon)) < grid.resolution_m * grid.resolution_m)
      return absl::InvalidArgumentError("footprint polygon has no area (collinear or coincident vertices)");
    for (int r = 0; r < grid.rows; ++r)
      for (int c = 0; c < grid.cols; ++c)
        if (grid.count[grid.Index(c, r)] > 0 && InsidePolygon(polygon, grid.CellCenter(c, r))) cells.push_back(grid.Index(c, r));
    // A drawn footprint is rough ("mouse-click accuracy is not critical", AVE §4.1): with a ground
    // model, the building is the cells inside it that stand above the ground.
    if (HasDtm(grid)) {
      std::erase_if(cells, [&](size_t c) { return !(HeightAboveGround(grid, c) > defaults.min_height_m); });
      if (cells.empty()) return absl::NotFoundError(absl::StrFormat("nothing inside the footprint stands %.1f m above the ground", defaults.min_height_m));
    }
  } else {
    return absl::InvalidArgumentError(absl::StrFormat("footprint has %d vertices: give 1 (a click) or at least 3", footprint_m.size()));
  }
  if (cells.empty()) return absl::NotFoundError("no LiDAR points inside the footprint");
  double base_z = 0;
  if (HasDtm(grid)) {
    base_z = MaxDtm(grid, cells);
  } else {
    base_z = 1e300;
    for (size_t c : cells) base_z = std::min(base_z, static_cast<double>(grid.zmin[c]));
  }
  PartRequest request{type, std::nullopt};
  if ((type == PrimitiveType::kWedge && (roof == RoofType::kShed || roof == RoofType::kGable)) ||
      (type == PrimitiveType::kPolyhedron && roof != RoofType::kDome && roof != RoofType::kCylinder))
    request.roof = roof;
  const double min_z = base_z + (HasDtm(grid) ? 0.5 * defaults.min_height_m : 0.0);
  absl::StatusOr<BuildingPrimitive> part = FitCells(cloud, grid, index, cells, base_z, min_z, request);
  if (!part.ok()) return absl::Status(part.status().code(), "fit " + std::string(PrimitiveTypeName(type)) + ": " + std::string(part.status().message()));
  if (type == PrimitiveType::kPolyhedron && !polygon.empty() && part->roof == RoofType::kFlat) part->polygon_m = polygon;
  BuildingRecord rec;
  rec.parts.push_back(*std::move(part));
  rec.roof = rec.parts.front().roof;
  rec.footprint_m = polygon.empty() ? OutlineOf(grid, cells) : polygon;
  rec.area_m2 = cells.size() * grid.resolution_m * grid.resolution_m;
  for (size_t c : cells) rec.point_count += index.start[c + 1] - index.start[c];
  return rec;
}

}  // namespace ave::model
