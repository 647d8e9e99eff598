#include "model_store/terrain/terrain.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace ave::model {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Running min (or max) over a window of 2h+1 samples along a strided line: van Herk / Gil-Werman,
// three comparisons per sample whatever the window. Samples beyond the ends are ignored.
void MovingExtreme(float* line, int n, int h, bool take_min, std::vector<float>& g, std::vector<float>& r) {
  const int w = 2 * h + 1;
  const float pad = take_min ? kInf : -kInf;
  const int padded = n + 2 * h;
  const int blocks = (padded + w - 1) / w;
  g.assign(static_cast<size_t>(blocks) * w, pad);
  r.assign(g.size(), pad);
  auto pick = [take_min](float a, float b) { return take_min ? std::min(a, b) : std::max(a, b); };
  auto at = [&](int i) { return i >= h && i < n + h ? line[i - h] : pad; };
  for (int b = 0; b < blocks; ++b) {
    const int s = b * w;
    g[s] = at(s);
    for (int i = 1; i < w; ++i) g[s + i] = pick(g[s + i - 1], at(s + i));
    r[s + w - 1] = at(s + w - 1);
    for (int i = w - 2; i >= 0; --i) r[s + i] = pick(r[s + i + 1], at(s + i));
  }
  // Output i covers padded samples [i, i + w - 1].
  for (int i = 0; i < n; ++i) line[i] = pick(r[i], g[i + w - 1]);
}

// Separable square-window erosion / dilation of a cols x rows image in place. The vertical pass
// runs van Herk / Gil-Werman on whole rows at once, so memory is walked row by row.
void Morph(std::vector<float>& img, int cols, int rows, int h, bool take_min) {
  std::vector<float> g, r;
  for (int y = 0; y < rows; ++y) MovingExtreme(img.data() + static_cast<size_t>(y) * cols, cols, h, take_min, g, r);
  const int w = 2 * h + 1;
  const float pad = take_min ? kInf : -kInf;
  const int blocks = (rows + 2 * h + w - 1) / w;
  const size_t padded = static_cast<size_t>(blocks) * w;
  std::vector<float> fwd(padded * cols), bwd(padded * cols);
  auto in_row = [&](int i) -> const float* { return i >= h && i < rows + h ? img.data() + static_cast<size_t>(i - h) * cols : nullptr; };
  auto combine = [take_min, cols](float* dst, const float* a, const float* b) {
    if (take_min) {
      for (int x = 0; x < cols; ++x) dst[x] = std::min(a[x], b[x]);
    } else {
      for (int x = 0; x < cols; ++x) dst[x] = std::max(a[x], b[x]);
    }
  };
  auto load = [&](float* dst, int i) {
    if (const float* src = in_row(i)) {
      std::copy_n(src, cols, dst);
    } else {
      std::fill_n(dst, cols, pad);
    }
  };
  std::vector<float> tmp(cols);
  for (int b = 0; b < blocks; ++b) {
    const int s0 = b * w;
    load(&fwd[static_cast<size_t>(s0) * cols], s0);
    for (int i = 1; i < w; ++i) {
      load(tmp.data(), s0 + i);
      combine(&fwd[static_cast<size_t>(s0 + i) * cols], &fwd[static_cast<size_t>(s0 + i - 1) * cols], tmp.data());
    }
    load(&bwd[static_cast<size_t>(s0 + w - 1) * cols], s0 + w - 1);
    for (int i = w - 2; i >= 0; --i) {
      load(tmp.data(), s0 + i);
      combine(&bwd[static_cast<size_t>(s0 + i) * cols], &bwd[static_cast<size_t>(s0 + i + 1) * cols], tmp.data());
    }
  }
  for (int y = 0; y < rows; ++y) {
    combine(img.data() + static_cast<size_t>(y) * cols, &bwd[static_cast<size_t>(y) * cols], &fwd[static_cast<size_t>(y + w - 1) * cols]);
  }
}

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::string GroundFilterOptions::Check() const {
  if (!std::isfinite(max_window_m) || max_window_m <= 0 || max_window_m > 1000) return "max_window_m must be in (0, 1000]";
  if (!std::isfinite(slope) || slope < 0 || slope > 10) return "slope must be in [0, 10]";
  if (!std::isfinite(initial_threshold_m) || initial_threshold_m <= 0) return "initial_threshold_m must be > 0";
  if (!std::isfinite(max_threshold_m) || max_threshold_m < initial_threshold_m) return "max_threshold_m must be >= initial_threshold_m";
  if (!std::isfinite(point_threshold_m) || point_threshold_m <= 0) return "point_threshold_m must be > 0";
  if (fill_iterations < 0 || fill_iterations > 10000) return "fill_iterations must be in [0, 10000]";
  return {};
}

void MorphologicalOpening(std::vector<float>& values, int cols, int rows, int half_window) {
  Morph(values, cols, rows, half_window, /*take_min=*/true);
  for (float& v : values) {
    if (v == kInf) v = -kInf;  // no data in the window: ignored by the dilation
  }
  Morph(values, cols, rows, half_window, /*take_min=*/false);
  for (float& v : values) {
    if (v == -kInf) v = kInf;
  }
}

absl::StatusOr<HeightGrid> BuildHeightGrid(const PointCloud& cloud, double resolution_m, size_t max_cells) {
  if (!std::isfinite(resolution_m) || resolution_m <= 0) return absl::InvalidArgumentError("grid resolution must be finite and > 0 m");
  if (cloud.size() == 0) return absl::InvalidArgumentError("cannot grid an empty point cloud");
  Eigen::Vector2f lo = cloud.xyz[0].head<2>(), hi = lo;
  for (const Eigen::Vector3f& p : cloud.xyz) {
    lo = lo.cwiseMin(p.head<2>());
    hi = hi.cwiseMax(p.head<2>());
  }
  HeightGrid grid;
  grid.origin = cloud.origin;
  grid.resolution_m = resolution_m;
  // Cell edges on multiples of the resolution in the local frame, so grids of one site line up.
  grid.min_xy = (lo.cast<double>() / resolution_m).array().floor() * resolution_m;
  const double cols = std::floor((hi.x() - grid.min_xy.x()) / resolution_m) + 1;
  const double rows = std::floor((hi.y() - grid.min_xy.y()) / resolution_m) + 1;
  if (cols * rows > static_cast<double>(max_cells)) {
    return absl::InvalidArgumentError("a " + std::to_string(resolution_m) + " m grid over this cloud needs " +
                                      std::to_string(cols * rows) + " cells, above the limit of " + std::to_string(max_cells));
  }
  grid.cols = static_cast<int>(cols);
  grid.rows = static_cast<int>(rows);
  const size_t n = grid.CellCount();
  grid.zmin.assign(n, kInf);
  grid.zmax.assign(n, -kInf);
  grid.zmean.assign(n, 0.f);
  grid.znearest.assign(n, kNaN);
  grid.count.assign(n, 0);
  std::vector<float> nearest_d2(n, kInf);
  const double inv = 1.0 / resolution_m;
  const double x0 = grid.min_xy.x(), y0 = grid.min_xy.y();
  for (const Eigen::Vector3f& p : cloud.xyz) {
    const double fx = (p.x() - x0) * inv, fy = (p.y() - y0) * inv;
    const int c = std::min(static_cast<int>(fx), grid.cols - 1), r = std::min(static_cast<int>(fy), grid.rows - 1);
    const size_t i = static_cast<size_t>(r) * grid.cols + c;
    const float z = p.z();
    grid.zmin[i] = std::min(grid.zmin[i], z);
    grid.zmax[i] = std::max(grid.zmax[i], z);
    grid.zmean[i] += z;
    ++grid.count[i];
    const float dx = static_cast<float>(fx - c - 0.5), dy = static_cast<float>(fy - r - 0.5);
    const float d2 = dx * dx + dy * dy;
    if (d2 < nearest_d2[i]) {
      nearest_d2[i] = d2;
      grid.znearest[i] = z;
    }
  }
  for (size_t i = 0; i < n; ++i) {
    if (grid.count[i] == 0) {
      grid.zmin[i] = grid.zmax[i] = grid.zmean[i] = kNaN;
    } else {
      grid.zmean[i] /= static_cast<float>(grid.count[i]);
    }
  }
  return grid;
}

void FillHoles(std::vector<float>& values, int cols, int rows, int iterations) {
  const size_t n = static_cast<size_t>(cols) * rows;
  std::vector<uint8_t> hole(n);
  size_t holes = 0;
  for (size_t i = 0; i < n; ++i) holes += hole[i] = !std::isfinite(values[i]);
  if (holes == 0 || holes == n) return;
  // Pull: a pyramid of weighted means of the known cells; push: each hole takes the bilinear
  // value of the coarsest level that knows its neighbourhood.
  struct Level {
    int cols, rows;
    std::vector<float> sum, weight;
  };
  std::vector<Level> levels;
  levels.push_back({cols, rows, std::vector<float>(n, 0.f), std::vector<float>(n, 0.f)});
  for (size_t i = 0; i < n; ++i) {
    if (!hole[i]) {
      levels[0].sum[i] = values[i];
      levels[0].weight[i] = 1;
    }
  }
  while (levels.back().cols > 1 || levels.back().rows > 1) {
    const Level& f = levels.back();
    Level c{(f.cols + 1) / 2, (f.rows + 1) / 2, {}, {}};
    c.sum.assign(static_cast<size_t>(c.cols) * c.rows, 0.f);
    c.weight.assign(c.sum.size(), 0.f);
    for (int y = 0; y < f.rows; ++y) {
      for (int x = 0; x < f.cols; ++x) {
        const size_t fi = static_cast<size_t>(y) * f.cols + x, ci = static_cast<size_t>(y / 2) * c.cols + x / 2;
        c.sum[ci] += f.sum[fi];
        c.weight[ci] += f.weight[fi];
      }
    }
    levels.push_back(std::move(c));
  }
  for (Level& l : levels) {
    for (size_t i = 0; i < l.sum.size(); ++i) l.sum[i] = l.weight[i] > 0 ? l.sum[i] / l.weight[i] : kNaN;
  }
  // Push from coarse to fine: unknown cells sample the coarser level bilinearly (known parents only).
  for (int k = static_cast<int>(levels.size()) - 2; k >= 0; --k) {
    Level& f = levels[k];
    const Level& c = levels[k + 1];
    for (int y = 0; y < f.rows; ++y) {
      for (int x = 0; x < f.cols; ++x) {
        const size_t fi = static_cast<size_t>(y) * f.cols + x;
        if (std::isfinite(f.sum[fi])) continue;
        const double cx = std::clamp((x + 0.5) / 2 - 0.5, 0.0, c.cols - 1.0), cy = std::clamp((y + 0.5) / 2 - 0.5, 0.0, c.rows - 1.0);
        const int x0 = static_cast<int>(cx), y0 = static_cast<int>(cy);
        const int x1 = std::min(x0 + 1, c.cols - 1), y1 = std::min(y0 + 1, c.rows - 1);
        const double ax = cx - x0, ay = cy - y0;
        double s = 0, w = 0;
        const int xs[2] = {x0, x1}, ys[2] = {y0, y1};
        const double wx[2] = {1 - ax, ax}, wy[2] = {1 - ay, ay};
        for (int j = 0; j < 2; ++j) {
          for (int i = 0; i < 2; ++i) {
            const float v = c.sum[static_cast<size_t>(ys[j]) * c.cols + xs[i]];
            if (std::isfinite(v) && wx[i] * wy[j] > 0) {
              s += wx[i] * wy[j] * v;
              w += wx[i] * wy[j];
            }
          }
        }
        f.sum[fi] = w > 0 ? static_cast<float>(s / w) : c.sum[static_cast<size_t>(y / 2) * c.cols + x / 2];
      }
    }
  }
  for (size_t i = 0; i < n; ++i) {
    if (hole[i]) values[i] = levels[0].sum[i];
  }
  // Relax the filled cells towards a harmonic surface (known cells stay fixed).
  std::vector<uint32_t> hole_cells;
  hole_cells.reserve(holes);
  for (size_t i = 0; i < n; ++i) {
    if (hole[i]) hole_cells.push_back(static_cast<uint32_t>(i));
  }
  for (int it = 0; it < iterations; ++it) {
    for (uint32_t i : hole_cells) {
      const int x = static_cast<int>(i % cols), y = static_cast<int>(i / cols);
      float s = 0;
      int k = 0;
      if (x > 0) s += values[i - 1], ++k;
      if (x + 1 < cols) s += values[i + 1], ++k;
      if (y > 0) s += values[i - cols], ++k;
      if (y + 1 < rows) s += values[i + cols], ++k;
      values[i] = s / static_cast<float>(k);
    }
  }
}

absl::StatusOr<size_t> ClassifyGroundCells(HeightGrid& grid, const GroundFilterOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("ground filter: " + why);
  const size_t n = grid.CellCount();
  const int cols = grid.cols, rows = grid.rows;
  grid.cell_class.assign(n, CellClass::kEmpty);
  std::vector<uint8_t> object(n, 0);
  std::vector<float> surface(n);
  for (size_t i = 0; i < n; ++i) surface[i] = grid.count[i] ? grid.zmin[i] : kInf;
  // Windows 3, 5, 9, 17, ... cells (w_k = 2 * 2^k + 1), thresholds per Zhang et al. (2003) eq. 4.
  int previous_w = 1;
  for (int half = 1;; half *= 2) {
    const int w = 2 * half + 1;
    const double threshold = w <= 3 ? options.initial_threshold_m
                                    : std::min(options.max_threshold_m,
                                               options.initial_threshold_m + options.slope * (w - previous_w) * grid.resolution_m);
    std::vector<float> opened = surface;
    MorphologicalOpening(opened, cols, rows, half);
    for (size_t i = 0; i < n; ++i) {
      if (!grid.count[i]) continue;
      if (surface[i] - opened[i] > threshold) object[i] = 1;
      surface[i] = opened[i];
    }
    previous_w = w;
    if (w * grid.resolution_m >= options.max_window_m || (half > cols && half > rows)) break;
  }
  size_t ground = 0;
  grid.dtm.assign(n, kNaN);
  for (size_t i = 0; i < n; ++i) {
    if (!grid.count[i]) continue;
    grid.cell_class[i] = object[i] ? CellClass::kObject : CellClass::kGround;
    if (!object[i]) {
      grid.dtm[i] = grid.zmin[i];
      ++ground;
    }
  }
  if (ground == 0) return absl::FailedPreconditionError("no ground cell found: the cloud has no ground the filter can see");
  FillHoles(grid.dtm, cols, rows, options.fill_iterations);
  return ground;
}

float DtmAt(const HeightGrid& grid, double x, double y) {
  if (grid.dtm.size() != grid.CellCount() || grid.cols == 0) return kNaN;
  const double fx = std::clamp((x - grid.min_xy.x()) / grid.resolution_m - 0.5, 0.0, grid.cols - 1.0);
  const double fy = std::clamp((y - grid.min_xy.y()) / grid.resolution_m - 0.5, 0.0, grid.rows - 1.0);
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  const int x1 = std::min(x0 + 1, grid.cols - 1), y1 = std::min(y0 + 1, grid.rows - 1);
  const float ax = static_cast<float>(fx - x0), ay = static_cast<float>(fy - y0);
  const float* d = grid.dtm.data();
  const float top = d[grid.Index(x0, y0)] * (1 - ax) + d[grid.Index(x1, y0)] * ax;
  const float bottom = d[grid.Index(x0, y1)] * (1 - ax) + d[grid.Index(x1, y1)] * ax;
  return top * (1 - ay) + bottom * ay;
}

std::vector<uint8_t> ClassifyGroundPoints(const PointCloud& cloud, HeightGrid& grid, const GroundFilterOptions& options) {
  std::vector<uint8_t> cls(cloud.size(), 1);
  const size_t n = grid.CellCount();
  std::vector<float> sum(n, 0.f);
  std::vector<uint32_t> count(n, 0);
  const double inv = 1.0 / grid.resolution_m;
  for (size_t k = 0; k < cloud.size(); ++k) {
    const Eigen::Vector3f& p = cloud.xyz[k];
    const float ground = DtmAt(grid, p.x(), p.y());
    if (!(p.z() - ground <= options.point_threshold_m)) continue;
    cls[k] = 2;
    const int c = std::clamp(static_cast<int>((p.x() - grid.min_xy.x()) * inv), 0, grid.cols - 1);
    const int r = std::clamp(static_cast<int>((p.y() - grid.min_xy.y()) * inv), 0, grid.rows - 1);
    sum[grid.Index(c, r)] += p.z();
    ++count[grid.Index(c, r)];
  }
  for (size_t i = 0; i < n; ++i) grid.dtm[i] = count[i] ? sum[i] / static_cast<float>(count[i]) : kNaN;
  FillHoles(grid.dtm, grid.cols, grid.rows, options.fill_iterations);
  return cls;
}

absl::StatusOr<TerrainResult> BuildTerrain(const PointCloud& cloud, double resolution_m, const GroundFilterOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("ground filter: " + why);
  TerrainResult result;
  auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<HeightGrid> grid = BuildHeightGrid(cloud, resolution_m);
  if (!grid.ok()) return grid.status();
  result.grid = std::move(*grid);
  result.grid_seconds = SecondsSince(t0);
  t0 = std::chrono::steady_clock::now();
  absl::StatusOr<size_t> ground = ClassifyGroundCells(result.grid, options);
  if (!ground.ok()) return ground.status();
  result.ground_cells = *ground;
  result.point_class = ClassifyGroundPoints(cloud, result.grid, options);
  result.filter_seconds = SecondsSince(t0);
  return result;
}

}  // namespace ave::model
