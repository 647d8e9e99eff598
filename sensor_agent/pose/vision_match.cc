#include "sensor_agent/pose/vision_match.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Dense>

#include <opencv2/imgproc.hpp>

namespace ave::pose::internal {
namespace {

double MeanDistance(const cv::Mat& distance, const std::vector<Eigen::Vector2d>& samples, int dx, int dy) {
  double sum = 0;
  int n = 0;
  for (const Eigen::Vector2d& p : samples) {
    const int x = static_cast<int>(std::lround(p.x())) + dx, y = static_cast<int>(std::lround(p.y())) + dy;
    if (x < 0 || y < 0 || x >= distance.cols || y >= distance.rows) continue;
    sum += std::min(distance.at<float>(y, x), static_cast<float>(kChamferCap_px));
    ++n;
  }
  return n * 2 >= static_cast<int>(samples.size()) && n > 0 ? sum / n : kChamferCap_px;
}

}  // namespace

int Nearest(const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& uv, double radius) {
  int best = -1;
  double best_d2 = radius * radius;
  for (size_t j = 0; j < corners.size(); ++j) {
    const double dx = corners[j].x - uv.x(), dy = corners[j].y - uv.y();
    const double d2 = dx * dx + dy * dy;
    if (d2 <= best_d2) {
      best_d2 = d2;
      best = static_cast<int>(j);
    }
  }
  return best;
}

// Façades repeat horizontal edges (window rows) every few pixels, so the skyline term (model edges
// with sky above them against the frame's first edge from the top) breaks the tie.
Eigen::Vector2d ChamferOffset(const cv::Mat& edge_distance, const std::vector<Eigen::Vector2d>& samples, const cv::Mat& skyline_distance,
                              const std::vector<Eigen::Vector2d>& sky_samples, double radius, int coarse_step) {
  if (samples.size() < 10) return Eigen::Vector2d::Zero();
  const bool use_sky = sky_samples.size() >= 5;
  auto score = [&](int dx, int dy) {
    return MeanDistance(edge_distance, samples, dx, dy) + (use_sky ? MeanDistance(skyline_distance, sky_samples, dx, dy) : 0.0);
  };
  const int r = static_cast<int>(radius);
  int best_x = 0, best_y = 0;
  double best = score(0, 0);
  for (int step = std::max(1, coarse_step); step >= 1; step /= 2) {
    const int cx = best_x, cy = best_y, reach = step == std::max(1, coarse_step) ? r : 2 * step;
    for (int dy = cy - reach; dy <= cy + reach; dy += step) {
      for (int dx = cx - reach; dx <= cx + reach; dx += step) {
        const double v = score(dx, dy);
        if (v < best - 1e-9 || (std::abs(v - best) <= 1e-9 && dx * dx + dy * dy < best_x * best_x + best_y * best_y)) {
          best = v;
          best_x = dx;
          best_y = dy;
        }
      }
    }
  }
  return Eigen::Vector2d(best_x, best_y);
}

ImageAlignment ChamferAlign(const cv::Mat& edge_distance, const std::vector<Eigen::Vector2d>& samples, const cv::Mat& skyline_distance,
                            const std::vector<Eigen::Vector2d>& sky_samples, double radius, const Eigen::Vector2d& centre,
                            double max_rotation_rad, double rotation_step_rad, int coarse_step) {
  ImageAlignment best;
  best.offset = ChamferOffset(edge_distance, samples, skyline_distance, sky_samples, radius, coarse_step);
  // Too few of the model's edges in view to score a fit: no evidence, never a good fit (issue 19,
  // eighth session: a relocalisation candidate that saw nearly nothing scored 0 and won, 6 m off).
  if (samples.size() < 10) {
    best.score_px = std::numeric_limits<double>::infinity();
    return best;
  }
  const bool use_sky = sky_samples.size() >= 5;
  auto score = [&](const std::vector<Eigen::Vector2d>& edge, const std::vector<Eigen::Vector2d>& sky, int dx, int dy) {
    return MeanDistance(edge_distance, edge, dx, dy) + (use_sky ? MeanDistance(skyline_distance, sky, dx, dy) : 0.0);
  };
  const int bx = static_cast<int>(std::lround(best.offset.x())), by = static_cast<int>(std::lround(best.offset.y()));
  best.score_px = score(samples, sky_samples, bx, by);
  if (!(max_rotation_rad > 0) || !(rotation_step_rad > 0)) return best;
  constexpr double kTurnMargin_px = 0.5;
  const int steps = static_cast<int>(std::floor(max_rotation_rad / rotation_step_rad + 1e-9));
  std::vector<Eigen::Vector2d> edge(samples.size()), sky(sky_samples.size());
  constexpr int kReach = 8;
  ImageAlignment best_turn;
  best_turn.score_px = std::numeric_limits<double>::infinity();
  for (int i = -steps; i <= steps; ++i) {
    if (i == 0) continue;
    ImageAlignment turn;
    turn.rotation_rad = i * rotation_step_rad;
    turn.score_px = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < samples.size(); ++j) edge[j] = turn.Apply(samples[j], centre);
    for (size_t j = 0; j < sky_samples.size(); ++j) sky[j] = turn.Apply(sky_samples[j], centre);
    for (int step : {2, 1}) {
      const int cx = step == 2 ? bx : static_cast<int>(std::lround(turn.offset.x()));
      const int cy = step == 2 ? by : static_cast<int>(std::lround(turn.offset.y()));
      const int reach = step == 2 ? kReach : 1;
      for (int dy = cy - reach; dy <= cy + reach; dy += step) {
        for (int dx = cx - reach; dx <= cx + reach; dx += step) {
          const double v = score(edge, sky, dx, dy);
          if (v < turn.score_px) {
            turn.score_px = v;
            turn.offset = Eigen::Vector2d(dx, dy);
          }
        }
      }
    }
    // A turn must beat the unrotated alignment clearly (half a pixel of mean distance): at the
    // right pose, the chamfer scores of +-0.5 deg differ from the unturned one's by ~0.1-0.3 px.
    if (turn.score_px < best_turn.score_px) best_turn = turn;
  }
  return best_turn.score_px < best.score_px - kTurnMargin_px ? best_turn : best;
}

void EdgeDistances(const cv::Mat& gray, cv::Mat& edge_distance, cv::Mat& skyline_distance) {
  cv::Mat edges;
  cv::Canny(gray, edges, 60, 180);
  cv::distanceTransform(255 - edges, edge_distance, cv::DIST_L2, 3);
  cv::Mat skyline(edges.size(), CV_8U, cv::Scalar(255));
  for (int u = 0; u < edges.cols; ++u) {
    for (int v = 0; v < edges.rows; ++v) {
      if (edges.at<uint8_t>(v, u)) {
        skyline.at<uint8_t>(v, u) = 0;
        break;
      }
    }
  }
  cv::distanceTransform(skyline, skyline_distance, cv::DIST_L2, 3);
}

std::vector<std::pair<int, int>> MatchPoints(const std::vector<std::pair<int, Eigen::Vector2d>>& predicted,
                                             const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& offset, double radius) {
  std::vector<std::pair<int, int>> out;
  std::vector<int> owner(corners.size(), -1);
  for (const auto& [index, uv] : predicted) {
    const int j = Nearest(corners, uv + offset, radius);
    if (j < 0) continue;
    if (owner[j] >= 0) {  // two predictions claim one corner: keep neither
      out[owner[j]].second = -1;
      continue;
    }
    owner[j] = static_cast<int>(out.size());
    out.emplace_back(index, j);
  }
  std::erase_if(out, [](const auto& m) { return m.second < 0; });
  return out;
}

std::vector<cv::Point2f> SearchEdge(const cv::Mat& gray, const std::vector<Eigen::Vector2d>& samples, const Eigen::Vector2d& normal,
                                    double reach_px, double min_step) {
  std::vector<cv::Point2f> found;
  const int reach = static_cast<int>(std::ceil(reach_px));
  auto at = [&](const Eigen::Vector2d& p) {  // bilinear grey value; NaN outside
    const double x = p.x(), y = p.y();
    if (!(x >= 0 && y >= 0 && x < gray.cols - 1 && y < gray.rows - 1)) return std::numeric_limits<double>::quiet_NaN();
    const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
    const double fx = x - x0, fy = y - y0;
    const uint8_t* r0 = gray.ptr<uint8_t>(y0);
    const uint8_t* r1 = gray.ptr<uint8_t>(y0 + 1);
    return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  };
  std::vector<double> profile(2 * reach + 3);
  for (const Eigen::Vector2d& s : samples) {
    bool inside = true;
    for (int i = 0; i < static_cast<int>(profile.size()); ++i) {
      profile[i] = at(s + normal * (i - reach - 1));
      inside &= std::isfinite(profile[i]);
    }
    if (!inside) continue;
    int best = -1;
    double best_step = min_step;
    std::vector<double> step(2 * reach + 1);
    for (int i = 0; i <= 2 * reach; ++i) {  // step[i]: central difference at offset i - reach
      step[i] = 0.5 * std::abs(profile[i + 2] - profile[i]);
      if (step[i] > best_step) best_step = step[i], best = i;
    }
    if (best < 0) continue;
    double offset = best - reach;
    if (best > 0 && best < 2 * reach) {
      const double l = step[best - 1], c = step[best], r = step[best + 1], denom = l - 2 * c + r;
      if (denom < 0) offset += 0.5 * (l - r) / denom;
    }
    const Eigen::Vector2d p = s + normal * offset;
    found.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  return found;
}

std::optional<Eigen::Vector2d> CornerOnEdges(const cv::Mat& gray, const Eigen::Vector2d& seed, const std::vector<Eigen::Vector2d>& directions,
                                             int samples, double reach_px, double min_step, double max_move_px) {
  struct Edge {
    Eigen::Vector2d centre, direction;
  };
  std::vector<Edge> edges;
  const double cos_max = std::cos(10.0 * 3.14159265358979323846 / 180);
  for (const Eigen::Vector2d& d : directions) {
    std::vector<Eigen::Vector2d> along;
    for (int i = 0; i < samples; ++i) along.push_back(seed + d * (3.0 + i));
    const std::vector<cv::Point2f> found = SearchEdge(gray, along, Eigen::Vector2d(-d.y(), d.x()), reach_px, min_step);
    if (3 * static_cast<int>(found.size()) < 2 * samples) continue;
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const cv::Point2f& p : found) centre += Eigen::Vector2d(p.x, p.y);
    centre /= static_cast<double>(found.size());
    Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
    for (const cv::Point2f& p : found) {
      const Eigen::Vector2d r = Eigen::Vector2d(p.x, p.y) - centre;
      scatter += r * r.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter / static_cast<double>(found.size()));
    const Eigen::Vector2d direction = eig.eigenvectors().col(1);  // the larger eigenvalue's
    if (!(eig.eigenvalues()(0) <= 0.25) || std::abs(direction.dot(d)) < cos_max) continue;
    edges.push_back({centre, direction});
  }
  // The pair farthest from parallel, at least 20 deg apart (|sin| >= 0.342).
  double best_sin = 0.342;
  std::optional<Eigen::Vector2d> corner;
  for (size_t a = 0; a < edges.size(); ++a) {
    for (size_t b = a + 1; b < edges.size(); ++b) {
      const Eigen::Vector2d &ea = edges[a].direction, &eb = edges[b].direction;
      const double sin_ab = std::abs(ea.x() * eb.y() - ea.y() * eb.x());
      if (sin_ab < best_sin) continue;
      Eigen::Matrix2d A;
      A << ea, -eb;
      const Eigen::Vector2d st = A.inverse() * (edges[b].centre - edges[a].centre);
      best_sin = sin_ab;
      corner = edges[a].centre + ea * st.x();
    }
  }
  if (corner && (*corner - seed).norm() > max_move_px) return std::nullopt;
  return corner;
}

CellGrid::CellGrid(int width, int height, int cell_px)
    : width_(width), height_(height), cell_(std::max(1, cell_px)), cols_((width + cell_ - 1) / cell_), rows_((height + cell_ - 1) / cell_),
      count_(static_cast<size_t>(cols_) * rows_, 0) {}

void CellGrid::Add(double u, double v) {
  const int c = static_cast<int>(u) / cell_, r = static_cast<int>(v) / cell_;
  if (u >= 0 && v >= 0 && c < cols_ && r < rows_) ++count_[r * cols_ + c];
}

int CellGrid::Count(double u, double v) const {
  const int c = static_cast<int>(u) / cell_, r = static_cast<int>(v) / cell_;
  return u >= 0 && v >= 0 && c < cols_ && r < rows_ ? count_[r * cols_ + c] : 0;
}

cv::Mat CellGrid::ThinMask(int below, int scale) const {
  scale = std::max(1, scale);
  cv::Mat mask((height_ + scale - 1) / scale, (width_ + scale - 1) / scale, CV_8U, cv::Scalar(0));
  for (int r = 0; r < rows_; ++r) {
    for (int c = 0; c < cols_; ++c) {
      if (count_[r * cols_ + c] >= below) continue;
      const cv::Rect cell(c * cell_ / scale, r * cell_ / scale, (cell_ + scale - 1) / scale, (cell_ + scale - 1) / scale);
      mask(cell & cv::Rect(0, 0, mask.cols, mask.rows)).setTo(255);
    }
  }
  return mask;
}

}  // namespace ave::pose::internal
