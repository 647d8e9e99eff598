#include "tests/truth/terrain_score.h"

#include <algorithm>
#include <cmath>

namespace ave::model::testing {

TerrainScore ScoreTerrain(const HeightGrid& grid, const scene::SyntheticCampus& site, const Eigen::Vector3d& cloud_origin,
                          const std::vector<uint8_t>& point_class, const std::vector<uint8_t>& truth_class) {
  TerrainScore score;
  const Eigen::Vector3d shift = cloud_origin - site.origin;  // grid-local + shift = site-local
  double se_all = 0, se_open = 0, se_b = 0;
  size_t n_open = 0, n_b = 0;
  for (int r = 0; r < grid.rows && grid.dtm.size() == grid.CellCount(); ++r) {
    for (int c = 0; c < grid.cols; ++c) {
      const Eigen::Vector2d p = grid.CellCenter(c, r) + shift.head<2>();
      if (std::abs(p.x()) > site.half_extent_m - 1 || std::abs(p.y()) > site.half_extent_m - 1) continue;
      const double e = grid.dtm[grid.Index(c, r)] + shift.z() - site.TerrainHeight(p.x(), p.y());
      se_all += e * e;
      ++score.cells;
      if (site.BuildingAt(p.x(), p.y()) >= 0) {
        se_b += e * e, ++n_b;
      } else {
        se_open += e * e, ++n_open;
      }
    }
  }
  score.rmse_all_m = std::sqrt(se_all / std::max<size_t>(score.cells, 1));
  score.rmse_open_m = std::sqrt(se_open / std::max<size_t>(n_open, 1));
  score.rmse_under_buildings_m = std::sqrt(se_b / std::max<size_t>(n_b, 1));
  const size_t n = std::min(point_class.size(), truth_class.size());
  size_t right = 0;
  for (size_t i = 0; i < n; ++i) right += (point_class[i] == 2) == (truth_class[i] == 2);
  score.ground_accuracy = static_cast<double>(right) / std::max<size_t>(n, 1);
  return score;
}

}  // namespace ave::model::testing
