// ave-bench environment: the i4D static environment from a ground rotating LiDAR (i4D §3.3,
// model_store/environment) on one core: time per stage (background accumulation, RANSAC ground,
// vegetation, Hough walls, wall meshes) for a growing number of accumulated frames, with the
// accuracy each buys against the simulator's truth, next to peers measured in the same run on the
// same data:
//   RANSAC ground plane  vs a least-squares plane through every background point (Eigen PCA)
//   Hough walls stage    vs cv::HoughLinesP alone on the same occupancy image
// Writes a PNG: stacked ms per stage per frame count, with the accuracy under each bar.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/environment/environment.h"
#include "tests/bench/bench.h"
#include "tests/truth/environment_truth.h"

namespace ave::bench {
namespace {

struct EnvironmentBenchOptions {
  std::string scenario = "courtyard";
  std::vector<int> frames = {5, 10, 20, 40};
  double step_s = 0.1;
  int repeats = 3;
  std::string png = "environment_bench.png";
};

double Ms(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Median of `repeats` timings of fn (milliseconds).
template <typename Fn>
double MedianMs(int repeats, Fn fn) {
  std::vector<double> t;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    fn();
    t.push_back(Ms(t0));
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(std::abs(a.normalized().dot(b.normalized())), 0.0, 1.0)) * 180 / std::numbers::pi;
}

struct Row {
  int frames = 0;
  double accumulate_ms = 0, ransac_ms = 0, vegetation_ms = 0, hough_ms = 0, mesh_ms = 0;
  double lsq_ms = 0, houghp_ms = 0;
  double ransac_deg = 0, lsq_deg = 0;
  model::testing::EnvironmentScore score;
};

void WritePng(const std::vector<Row>& rows, const std::string& path) {
  const int w = 1060, h = 520, left = 90, bottom = 130, top = 40;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  double max_ms = 1;
  for (const Row& r : rows) max_ms = std::max(max_ms, r.accumulate_ms + r.ransac_ms + r.vegetation_ms + r.hough_ms + r.mesh_ms);
  const double scale = (h - bottom - top) / max_ms;
  const cv::Scalar colors[5] = {{200, 120, 40}, {60, 160, 60}, {40, 140, 220}, {160, 60, 160}, {90, 90, 90}};
  const char* names[5] = {"accumulate", "RANSAC ground", "vegetation", "Hough walls", "mesh"};
  const int bar = (w - left - 220) / static_cast<int>(rows.size());
  cv::line(img, {left, h - bottom}, {w - 210, h - bottom}, cv::Scalar(0, 0, 0));
  cv::line(img, {left, top}, {left, h - bottom}, cv::Scalar(0, 0, 0));
  for (int k = 0; k <= 4; ++k) {
    const double v = max_ms * k / 4;
    const int y = h - bottom - static_cast<int>(v * scale);
    cv::putText(img, cv::format("%.0f", v), {10, y + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0));
    cv::line(img, {left - 4, y}, {left, y}, cv::Scalar(0, 0, 0));
  }
  cv::putText(img, "ms (one core)", {5, top - 15}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0));
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const double parts[5] = {r.accumulate_ms, r.ransac_ms, r.vegetation_ms, r.hough_ms, r.mesh_ms};
    const int x0 = left + 20 + static_cast<int>(i) * bar, x1 = x0 + bar / 2;
    double y = h - bottom;
    for (int k = 0; k < 5; ++k) {
      const double y1 = y - parts[k] * scale;
      cv::rectangle(img, cv::Point(x0, static_cast<int>(y1)), cv::Point(x1, static_cast<int>(y)), colors[k], cv::FILLED);
      y = y1;
    }
    const int ty = h - bottom + 20;
    cv::putText(img, cv::format("%d frames", r.frames), {x0, ty}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0));
    cv::putText(img, cv::format("wall %.3f m", r.score.position_err_m_mean), {x0, ty + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0));
    cv::putText(img, cv::format("veg rm %.2f", r.score.overall_vegetation_removal_rate), {x0, ty + 38}, cv::FONT_HERSHEY_SIMPLEX, 0.42,
                cv::Scalar(0, 0, 0));
    cv::putText(img, cv::format("movers %d", r.score.mover_points), {x0, ty + 56}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0));
    cv::putText(img, cv::format("faces %d", r.score.faces_found), {x0, ty + 74}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0));
  }
  for (int k = 0; k < 5; ++k) {
    const int y = top + 5 + 20 * k;
    cv::rectangle(img, cv::Point(w - 190, y - 10), cv::Point(w - 175, y + 2), colors[k], cv::FILLED);
    cv::putText(img, names[k], {w - 168, y}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0));
  }
  cv::putText(img, "ave-bench environment: i4D environment from a rotating LiDAR, time per stage vs frames accumulated",
              {left, h - 10}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0));
  cv::imwrite(path, img);
}

int RunEnvironment(const EnvironmentBenchOptions& o) {
  UseOneCore();
  const int most = *std::max_element(o.frames.begin(), o.frames.end());
  const auto t_sim = std::chrono::steady_clock::now();
  absl::StatusOr<model::testing::LidarFrames> truth = model::testing::SimulateLidarFrames(o.scenario, most, o.step_s);
  if (!truth.ok()) {
    std::cerr << "ave-bench environment: " << truth.status().message() << "\n";
    return 1;
  }
  std::printf("simulated %d frames of %s in %.1f s (not counted below); %zu points in the first frame\n", most, o.scenario.c_str(),
              Ms(t_sim) / 1000, truth->frames.front().size());
  const model::EnvironmentOptions eo;
  std::vector<Row> rows;
  for (const int n : o.frames) {
    const std::vector<model::PointCloud> frames(truth->frames.begin(), truth->frames.begin() + n);
    Row r;
    r.frames = n;
    model::EnvironmentModel m;
    r.accumulate_ms = MedianMs(o.repeats, [&] { m.background = model::AccumulateBackground(frames, eo); });
    absl::StatusOr<model::GroundPlane> ground;
    r.ransac_ms = MedianMs(o.repeats, [&] { ground = model::FitGroundPlaneRansac(m.background.xyz, eo); });
    if (!ground.ok()) {
      std::cerr << "ave-bench environment: " << ground.status().message() << "\n";
      return 1;
    }
    m.ground = *ground;
    // Peer: the least-squares plane through every point (no outlier rejection).
    Eigen::Vector3d lsq_normal;
    r.lsq_ms = MedianMs(o.repeats, [&] { lsq_normal = model::FitPlaneLeastSquares(m.background.xyz).normal; });
    r.vegetation_ms = MedianMs(o.repeats, [&] { m.classes = model::ClassifyEnvironment(m.background, m.ground, eo); });
    r.hough_ms = MedianMs(o.repeats, [&] { m.walls = model::DetectWalls(m.background, m.classes, m.ground, eo); });
    // Peer: cv::HoughLinesP alone on the same occupancy image (the stage adds rasterising, merging
    // and the least-squares refit around it).
    model::OccupancyImage occ = model::RasteriseWallPoints(m.background, m.classes, m.ground, eo);
    if (!occ.pixels.empty()) {
      const cv::Mat image(occ.height, occ.width, CV_8U, occ.pixels.data());
      std::vector<cv::Vec4i> lines;
      r.houghp_ms = MedianMs(o.repeats, [&] {
        cv::HoughLinesP(image, lines, 1, std::numbers::pi / 360, eo.hough_votes, eo.min_wall_length_m / eo.hough_cell_m,
                        eo.max_wall_gap_m / eo.hough_cell_m);
      });
    }
    r.mesh_ms = MedianMs(o.repeats, [&] {
      m.mesh = TriangleMesh{};
      model::AppendWallMeshes(m.walls, m.mesh);
    });
    // Scored against the frames this row used (vegetation seen in them, not in all frames).
    const model::testing::LidarFrames used{truth->site, frames, truth->sensor_m};
    r.score = model::testing::ScoreEnvironment(used, m, eo.voxel_m);
    r.ransac_deg = AngleDeg(m.ground.normal, r.score.reference_ground_normal);
    r.lsq_deg = AngleDeg(lsq_normal, r.score.reference_ground_normal);
    rows.push_back(r);
  }
  const double frame_ms = 1000 * o.step_s;
  std::printf("\n| frames | background pts | accumulate ms | RANSAC ms (LSQ peer) | ground normal err deg RANSAC / LSQ | vegetation ms | "
              "Hough walls ms (HoughLinesP peer) | mesh ms | total ms | x real time | walls / faces | wall pos err m mean/max | "
              "wall angle err deg mean/max | veg removed (bg / overall) | false removal | movers left |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    const double total = r.accumulate_ms + r.ransac_ms + r.vegetation_ms + r.hough_ms + r.mesh_ms;
    const auto& s = r.score;
    std::printf("| %d | %d | %.1f | %.1f (%.1f, x%.1f) | %.3f / %.3f | %.1f | %.1f (%.1f, x%.1f) | %.3f | %.1f | %.2f | %d / %d | %.3f / %.3f | "
                "%.3f / %.3f | %.3f / %.3f | %.4f | %d |\n",
                r.frames, s.background_points, r.accumulate_ms, r.ransac_ms, r.lsq_ms, r.ransac_ms / std::max(1e-6, r.lsq_ms),
                r.ransac_deg, r.lsq_deg, r.vegetation_ms, r.hough_ms, r.houghp_ms, r.hough_ms / std::max(1e-6, r.houghp_ms), r.mesh_ms,
                total, total / (r.frames * frame_ms), s.walls, s.faces_found, s.position_err_m_mean, s.position_err_m_max,
                s.angle_err_deg_mean, s.angle_err_deg_max, s.vegetation_removal_rate, s.overall_vegetation_removal_rate,
                s.false_removal_rate, s.mover_points);
  }
  WritePng(rows, o.png);
  std::printf("\nwrote %s\n", o.png.c_str());
  return 0;
}

}  // namespace

Runner AddEnvironmentBench(CLI::App& sub) {
  auto options = std::make_shared<EnvironmentBenchOptions>();
  sub.add_option("--scenario", options->scenario, "bundled scenario or .yaml path with a rotating_lidar")->capture_default_str();
  sub.add_option("--frames", options->frames, "frame counts to accumulate (one row each), comma-separated")
      ->delimiter(',')
      ->capture_default_str()
      ->check(ave::cli::Range(1, 600));
  sub.add_option("--step", options->step_s, "seconds between frames")->capture_default_str()->check(ave::cli::Range(0.01, 10.0));
  sub.add_option("--repeats", options->repeats, "timings per stage (median kept)")->capture_default_str()->check(ave::cli::Range(1, 50));
  sub.add_option("--png", options->png, "plot to write")->capture_default_str()->check(ave::cli::WritableFile());
  return [options] { return RunEnvironment(*options); };
}

}  // namespace ave::bench
