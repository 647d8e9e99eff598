#include "sensor_agent/lidar_track/assignment.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ave::lidar_track {
namespace {

// Minimum-cost assignment of every row of an n x m matrix (n <= m, all entries finite), 1-based
// potentials u, v and the column matching p (classical shortest augmenting path).
std::vector<int> SolveDense(const Eigen::MatrixXd& a) {
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(a.cols());
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u(n + 1, 0), v(m + 1, 0);
  std::vector<int> p(m + 1, 0), way(m + 1, 0);
  for (int i = 1; i <= n; ++i) {
    p[0] = i;
    int j0 = 0;
    std::vector<double> minv(m + 1, inf);
    std::vector<char> used(m + 1, 0);
    do {
      used[j0] = 1;
      const int i0 = p[j0];
      double delta = inf;
      int j1 = 0;
      for (int j = 1; j <= m; ++j) {
        if (used[j]) continue;
        const double cur = a(i0 - 1, j - 1) - u[i0] - v[j];
        if (cur < minv[j]) {
          minv[j] = cur;
          way[j] = j0;
        }
        if (minv[j] < delta) {
          delta = minv[j];
          j1 = j;
        }
      }
      for (int j = 0; j <= m; ++j) {
        if (used[j]) {
          u[p[j]] += delta;
          v[j] -= delta;
        } else {
          minv[j] -= delta;
        }
      }
      j0 = j1;
    } while (p[j0] != 0);
    do {
      const int j1 = way[j0];
      p[j0] = p[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<int> col_of_row(n, -1);
  for (int j = 1; j <= m; ++j) {
    if (p[j] != 0) col_of_row[p[j] - 1] = j - 1;
  }
  return col_of_row;
}

}  // namespace

Assignment SolveAssignment(const Eigen::MatrixXd& cost) {
  Assignment out;
  const int rows = static_cast<int>(cost.rows()), cols = static_cast<int>(cost.cols());
  out.col_of_row.assign(rows, -1);
  out.row_of_col.assign(cols, -1);
  if (rows == 0 || cols == 0) return out;
  // Forbidden pairs get a cost larger than any sum of allowed ones, so the count of forbidden
  // pairs used is minimised first; they are dropped afterwards.
  double max_abs = 0;
  bool any_allowed = false;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const double x = cost(r, c);
      if (std::isfinite(x)) {
        max_abs = std::max(max_abs, std::abs(x));
        any_allowed = true;
      }
    }
  }
  if (!any_allowed) return out;
  const double big = (max_abs + 1) * (std::min(rows, cols) + 1) * 2;
  const bool transpose = rows > cols;
  Eigen::MatrixXd a = transpose ? Eigen::MatrixXd(cost.transpose()) : cost;
  for (Eigen::Index r = 0; r < a.rows(); ++r) {
    for (Eigen::Index c = 0; c < a.cols(); ++c) {
      if (!std::isfinite(a(r, c))) a(r, c) = big;
    }
  }
  const std::vector<int> match = SolveDense(a);
  for (int i = 0; i < static_cast<int>(match.size()); ++i) {
    const int j = match[i];
    if (j < 0) continue;
    const int r = transpose ? j : i, c = transpose ? i : j;
    if (!std::isfinite(cost(r, c))) continue;
    out.col_of_row[r] = c;
    out.row_of_col[c] = r;
    out.total_cost += cost(r, c);
  }
  return out;
}

}  // namespace ave::lidar_track
