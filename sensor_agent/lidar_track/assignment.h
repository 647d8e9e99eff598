#pragma once
// Optimal one-to-one assignment on a gated cost matrix (i4D §3.2's data assignment; issue 16:
// optimal, not greedy). Shortest augmenting paths with potentials (the Hungarian method in the
// Jonker-Volgenant formulation), O(n^2 m) for an n x m matrix, n <= m after an internal transpose.
//
// Forbidden pairs (outside a gate) are +inf (or NaN, treated the same). The solver first maximises
// the number of allowed pairs, then minimises their total cost among such assignments; rows and
// columns without an allowed partner stay unassigned (-1). Ties are broken deterministically
// (lowest column first).
#include <vector>

#include <Eigen/Core>

namespace ave::lidar_track {

struct Assignment {
  std::vector<int> col_of_row;  // -1: unassigned
  std::vector<int> row_of_col;  // -1: unassigned
  double total_cost = 0;        // over assigned (allowed) pairs
};

Assignment SolveAssignment(const Eigen::MatrixXd& cost);

}  // namespace ave::lidar_track
