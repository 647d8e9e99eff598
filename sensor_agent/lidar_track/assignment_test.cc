#include "sensor_agent/lidar_track/assignment.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

namespace ave::lidar_track {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Brute force: most allowed pairs, then least cost (rows <= cols, small).
std::pair<int, double> BruteForce(const Eigen::MatrixXd& c) {
  std::vector<int> cols(c.cols());
  std::iota(cols.begin(), cols.end(), 0);
  int best_n = -1;
  double best_cost = kInf;
  do {
    int n = 0;
    double cost = 0;
    for (int r = 0; r < c.rows(); ++r) {
      if (std::isfinite(c(r, cols[r]))) ++n, cost += c(r, cols[r]);
    }
    if (n > best_n || (n == best_n && cost < best_cost - 1e-12)) best_n = n, best_cost = cost;
  } while (std::next_permutation(cols.begin(), cols.end()));
  return {best_n, best_cost};
}

TEST(Assignment, EmptyMatricesAssignNothing) {
  for (const auto& [r, c] : {std::pair{0, 0}, std::pair{0, 3}, std::pair{4, 0}}) {
    const Assignment a = SolveAssignment(Eigen::MatrixXd(r, c));
    EXPECT_EQ(a.col_of_row.size(), static_cast<size_t>(r));
    EXPECT_EQ(a.row_of_col.size(), static_cast<size_t>(c));
    EXPECT_EQ(std::count(a.col_of_row.begin(), a.col_of_row.end(), -1), r);
    EXPECT_EQ(a.total_cost, 0);
  }
}

TEST(Assignment, AllForbiddenRowStaysUnassigned) {
  Eigen::MatrixXd c(3, 3);
  c << 1, 2, 3, kInf, kInf, kInf, 3, 1, 2;
  const Assignment a = SolveAssignment(c);
  EXPECT_EQ(a.col_of_row[1], -1);
  EXPECT_EQ(a.col_of_row[0], 0);
  EXPECT_EQ(a.col_of_row[2], 1);
  EXPECT_DOUBLE_EQ(a.total_cost, 2);
  const Assignment none = SolveAssignment(Eigen::MatrixXd::Constant(2, 3, kInf));
  EXPECT_EQ(none.col_of_row, std::vector<int>({-1, -1}));
  EXPECT_EQ(none.row_of_col, std::vector<int>({-1, -1, -1}));
}

TEST(Assignment, NanIsForbidden) {
  Eigen::MatrixXd c(2, 2);
  c << std::nan(""), 1, 1, std::nan("");
  const Assignment a = SolveAssignment(c);
  EXPECT_EQ(a.col_of_row, std::vector<int>({1, 0}));
}

TEST(Assignment, TiesGiveAFullDeterministicMatching) {
  const Eigen::MatrixXd c = Eigen::MatrixXd::Constant(4, 4, 2.5);
  const Assignment a = SolveAssignment(c);
  const Assignment b = SolveAssignment(c);
  EXPECT_EQ(a.col_of_row, b.col_of_row);
  std::vector<int> cols = a.col_of_row;
  std::sort(cols.begin(), cols.end());
  EXPECT_EQ(cols, std::vector<int>({0, 1, 2, 3}));
  EXPECT_DOUBLE_EQ(a.total_cost, 10);
}

TEST(Assignment, PrefersMorePairsOverCheaperFewer) {
  // Greedy takes (0,0) at cost 0 and leaves row 1 without a partner; optimal pairs both.
  Eigen::MatrixXd c(2, 2);
  c << 0, 5, 1, kInf;
  const Assignment a = SolveAssignment(c);
  EXPECT_EQ(a.col_of_row, std::vector<int>({1, 0}));
  EXPECT_DOUBLE_EQ(a.total_cost, 6);
}

TEST(Assignment, MatchesBruteForceOnRandomGatedMatrices) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3, 10);
  std::bernoulli_distribution gate(0.35);
  for (int trial = 0; trial < 300; ++trial) {
    const int rows = 1 + trial % 5, cols = 1 + (trial / 5) % 6;
    Eigen::MatrixXd c(rows, cols);
    for (int r = 0; r < rows; ++r) {
      for (int k = 0; k < cols; ++k) c(r, k) = gate(rng) ? kInf : std::round(u(rng));
    }
    const Assignment a = SolveAssignment(c);
    int n = 0;
    for (int r = 0; r < rows; ++r) {
      if (a.col_of_row[r] >= 0) {
        ++n;
        EXPECT_EQ(a.row_of_col[a.col_of_row[r]], r);
        EXPECT_TRUE(std::isfinite(c(r, a.col_of_row[r])));
      }
    }
    const auto [bn, bc] = rows <= cols ? BruteForce(c) : BruteForce(c.transpose());
    ASSERT_EQ(n, bn) << "trial " << trial;
    EXPECT_NEAR(a.total_cost, bc, 1e-9) << "trial " << trial;
  }
}

}  // namespace
}  // namespace ave::lidar_track
