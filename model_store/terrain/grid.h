#pragma once
// A regular height grid over a point cloud's local frame (MISSION part A, AVE §4.1): per-cell
// statistics of the points, then the ground filter's verdict and the bare-earth surface.
// Cell (col, row) covers [min_xy + (col, row) * resolution, + resolution) in local x (east), y
// (north); cells are stored row-major. Heights are metres relative to `origin`.
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace ave::model {

enum class CellClass : uint8_t { kEmpty = 0, kGround = 1, kObject = 2 };

struct HeightGrid {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates of the local zero
  Eigen::Vector2d min_xy = Eigen::Vector2d::Zero();  // local corner of cell (0, 0)
  double resolution_m = 0.5;
  int cols = 0, rows = 0;
  // Per-cell statistics of the points in the cell; NaN where the cell holds no point.
  std::vector<float> zmin, zmax, zmean, znearest;  // znearest: the point nearest the cell centre
  std::vector<uint32_t> count;
  // Filled by the ground filter: class per cell and the bare-earth height (DTM) everywhere,
  // holes filled from surrounding ground only (never from object cells).
  std::vector<CellClass> cell_class;
  std::vector<float> dtm;

  size_t CellCount() const { return static_cast<size_t>(cols) * static_cast<size_t>(rows); }
  size_t Index(int col, int row) const { return static_cast<size_t>(row) * cols + col; }
  Eigen::Vector2d CellCenter(int col, int row) const {
    return min_xy + Eigen::Vector2d((col + 0.5) * resolution_m, (row + 0.5) * resolution_m);
  }
  // The cell holding local (x, y), or false when outside the grid.
  bool CellOf(double x, double y, int* col, int* row) const {
    const double c = std::floor((x - min_xy.x()) / resolution_m), r = std::floor((y - min_xy.y()) / resolution_m);
    if (!(c >= 0 && r >= 0 && c < cols && r < rows)) return false;
    *col = static_cast<int>(c);
    *row = static_cast<int>(r);
    return true;
  }
};

}  // namespace ave::model
