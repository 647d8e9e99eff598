// ave-bench model (issue 4): the static model from the simulated airborne LiDAR of a scenario,
// scored against the site's analytic truth, against what each setting costs.
//   ave-bench model [--scenario campus] [--resolutions 0.25,0.5,1,2] [--scale 1,3,10] [--png model_bench.png]
// Prints (markdown) per grid resolution and per ground-filter setting: terrain RMSE (all cells,
// open ground, under buildings), ground classification accuracy per point, building precision /
// recall, roof-type accuracy, main-part parameter errors, wall time per stage and peak memory;
// the grey opening next to OpenCV's morphologyEx on the same image (ratio); and gridding + ground
// classification throughput at 1, 3 and 10 million points on one core. Writes a PNG plot.
#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/common/cpu_clock.h"
#include "model_store/lidar/las.h"
#include "model_store/pipeline/static_model.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"
#include "tests/truth/survey_truth.h"
#include "tests/truth/terrain_score.h"

namespace ave::bench {
namespace {

struct Options {
  std::string scenario = "campus";
  std::string resolutions = "0.25,0.5,1,2";
  std::string scale = "1,3,10";
  std::string png = "model_bench.png";
  uint64_t seed = 1;
  bool no_buildings = false;
};

std::vector<double> ParseList(const std::string& text) {
  std::vector<double> out;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) out.push_back(std::stod(item));
  return out;
}

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
// CPU seconds of this thread: the per-core cost, unaffected by other processes on a shared machine.
double CpuNow() { return ThreadCpuSeconds(); }

// Peak resident memory since the last reset (Linux: /proc/self/clear_refs "5" resets VmHWM).
long ReadStatusKb(const char* key) {
  std::ifstream f("/proc/self/status");
  for (std::string line; std::getline(f, line);) {
    if (line.rfind(key, 0) == 0) return std::stol(line.substr(std::strlen(key)));
  }
  return -1;
}
struct MemoryProbe {
  long start_kb;
  MemoryProbe() {
    std::ofstream("/proc/self/clear_refs") << "5";
    start_kb = ReadStatusKb("VmRSS:");
  }
  double PeakDeltaMb() const { return (ReadStatusKb("VmHWM:") - start_kb) / 1024.0; }
};

struct Row {
  std::string label;
  double resolution_m = 0;
  model::GroundFilterOptions ground;
  double grid_s = 0, filter_s = 0, buildings_s = 0, mesh_s = 0, cpu_s = 0, peak_mb = 0;
  double rmse_all = 0, rmse_open = 0, rmse_under_buildings = 0, ground_accuracy = 0;
  size_t triangles = 0;
  model::testing::BuildingScore buildings;
  bool have_buildings = false;
};

Row Evaluate(const std::string& label, const model::PointCloud& cloud, const std::vector<uint8_t>& truth,
             const scene::SyntheticCampus& site, model::StaticModelOptions options, bool buildings) {
  options.extract_buildings = buildings;
  Row row;
  row.label = label;
  row.resolution_m = options.resolution_m;
  row.ground = options.ground;
  MemoryProbe memory;
  const double cpu0 = CpuNow();
  absl::StatusOr<model::StaticModel> m = model::BuildStaticModel(cloud, options);
  row.cpu_s = CpuNow() - cpu0;
  row.peak_mb = memory.PeakDeltaMb();
  if (!m.ok()) {
    std::cerr << "ave-bench model: " << label << ": " << m.status().message() << "\n";
    return row;
  }
  if (buildings && m->building_grid_m != options.resolution_m && m->building_grid_m > 0) {
    char note[48];
    std::snprintf(note, sizeof(note), " (buildings at %.2g m)", m->building_grid_m);
    row.label += note;
  }
  row.grid_s = m->grid_seconds;
  row.filter_s = m->filter_seconds;
  row.buildings_s = m->buildings_seconds;
  row.mesh_s = m->mesh_seconds;
  row.triangles = m->mesh.TriangleCount();
  const model::testing::TerrainScore terrain = model::testing::ScoreTerrain(m->terrain.grid, site, cloud.origin, m->point_class, truth);
  row.ground_accuracy = terrain.ground_accuracy;
  row.rmse_all = terrain.rmse_all_m;
  row.rmse_open = terrain.rmse_open_m;
  row.rmse_under_buildings = terrain.rmse_under_buildings_m;
  row.have_buildings = buildings;
  if (row.have_buildings) row.buildings = model::testing::ScoreBuildings(site, cloud.origin, m->buildings);
  return row;
}

void PrintRows(const std::vector<Row>& rows) {
  std::printf("| setting | res m | slope | window m | thr m | grid s | ground s | bldg s | mesh s | CPU s | peak MB | RMSE all m | RMSE open m | RMSE under bldg m | ground acc %% | bldg P | bldg R | roof acc | centre err m | size err m | eave err m | yaw err deg | triangles |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    std::printf("| %s | %.2f | %.2f | %.0f | %.2f | %.3f | %.3f | %.3f | %.3f | %.3f | %.1f | %.3f | %.3f | %.3f | %.2f |", r.label.c_str(), r.resolution_m,
                r.ground.slope, r.ground.max_window_m, r.ground.point_threshold_m, r.grid_s, r.filter_s, r.buildings_s, r.mesh_s, r.cpu_s, r.peak_mb,
                r.rmse_all, r.rmse_open, r.rmse_under_buildings, 100 * r.ground_accuracy);
    if (r.have_buildings) {
      const auto& b = r.buildings;
      std::printf(" %.3f | %.3f | %.3f | %.2f | %.2f | %.2f | %.1f |", b.precision, b.recall, b.roof_accuracy, b.center_err_m_mean,
                  b.size_err_m_mean, b.eave_err_m_mean, b.yaw_err_deg_mean);
    } else {
      std::printf(" - | - | - | - | - | - | - |");
    }
    std::printf(" %zu |\n", r.triangles);
  }
}

// Copies of the cloud in one row along x (tile pitch = its extent + 1 m) until `n` points: no
// empty grid area, so the cost measured is that of a survey `n` points large.
model::PointCloud TileCloud(const model::PointCloud& base, size_t n) {
  Eigen::Vector3f lo = base.xyz[0], hi = lo;
  for (const auto& p : base.xyz) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Eigen::Vector2f pitch = (hi - lo).head<2>() + Eigen::Vector2f::Ones();
  model::PointCloud out;
  out.origin = base.origin;
  out.xyz.reserve(n);
  for (size_t k = 0; out.xyz.size() < n; ++k) {
    const Eigen::Vector3f offset(pitch.x() * k, 0, 0);
    for (size_t i = 0; i < base.size() && out.xyz.size() < n; ++i) out.xyz.push_back(base.xyz[i] + offset);
  }
  return out;
}

// --- plot ---
struct Series {
  std::string name;
  cv::Scalar color;
  std::vector<cv::Point2d> points;
  std::vector<std::string> labels;  // optional, one per point
  bool lines = true;                 // false: unordered settings, markers only
};
void DrawPanel(cv::Mat& img, cv::Rect area, const std::string& title, const std::string& xlabel, const std::string& ylabel,
               const std::vector<Series>& series, bool log_x) {
  cv::rectangle(img, area, cv::Scalar(200, 200, 200));
  double x0 = 1e300, x1 = -1e300, y0 = 0, y1 = -1e300;
  auto fx = [log_x](double x) { return log_x ? std::log10(x) : x; };
  for (const Series& s : series) {
    for (const auto& p : s.points) x0 = std::min(x0, fx(p.x)), x1 = std::max(x1, fx(p.x)), y1 = std::max(y1, p.y);
  }
  if (!(x1 > x0)) x1 = x0 + 1;
  if (!(y1 > y0)) y1 = y0 + 1;
  const double pad_x = 0.08 * (x1 - x0);
  x0 -= pad_x, x1 += pad_x, y1 *= 1.1;
  const cv::Rect plot(area.x + 60, area.y + 48, area.width - 80, area.height - 100);
  auto to_px = [&](cv::Point2d p) {
    return cv::Point(static_cast<int>(plot.x + (fx(p.x) - x0) / (x1 - x0) * plot.width),
                     static_cast<int>(plot.y + plot.height - (p.y - y0) / (y1 - y0) * plot.height));
  };
  cv::rectangle(img, plot, cv::Scalar(0, 0, 0));
  cv::putText(img, title, {area.x + 10, area.y + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  cv::putText(img, xlabel, {plot.x + plot.width / 2 - 60, plot.y + plot.height + 40}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  cv::putText(img, ylabel, {area.x + 5, plot.y - 8}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  for (int i = 0; i <= 4; ++i) {
    const double yv = y0 + (y1 - y0) * i / 4, xv = x0 + (x1 - x0) * i / 4;
    char label[32];
    std::snprintf(label, sizeof(label), "%.3g", yv);
    const int py = plot.y + plot.height - plot.height * i / 4;
    cv::putText(img, label, {area.x + 5, py + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    std::snprintf(label, sizeof(label), "%.3g", log_x ? std::pow(10, xv) : xv);
    cv::putText(img, label, {plot.x + plot.width * i / 4 - 12, plot.y + plot.height + 15}, cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  int legend_y = plot.y + 15;
  for (const Series& s : series) {
    for (size_t i = 0; i < s.points.size(); ++i) {
      cv::circle(img, to_px(s.points[i]), 4, s.color, cv::FILLED, cv::LINE_AA);
      if (i > 0 && s.lines) cv::line(img, to_px(s.points[i - 1]), to_px(s.points[i]), s.color, 2, cv::LINE_AA);
      if (i < s.labels.size()) {
        cv::putText(img, s.labels[i], to_px(s.points[i]) + cv::Point(6, -6), cv::FONT_HERSHEY_SIMPLEX, 0.35, s.color, 1, cv::LINE_AA);
      }
    }
    cv::putText(img, s.name, {plot.x + plot.width - 190, legend_y}, cv::FONT_HERSHEY_SIMPLEX, 0.4, s.color, 1, cv::LINE_AA);
    legend_y += 16;
  }
}

int Run(const Options& o) {
  UseOneCore();
  // Large blocks straight from mmap and back on free, so peak RSS measures each run alone (the
  // peer comparison below switches this off again: it would charge page faults to every call).
  mallopt(M_MMAP_THRESHOLD, 64 * 1024);
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench model: " << scenario.status().message() << "\n";
    return 1;
  }
  const scene::SyntheticCampus& site = scenario->world;
  const sim::AirborneLidarSpec spec = scenario->airborne_lidar.value_or(sim::AirborneLidarSpec{});
  const std::string las = (std::filesystem::temp_directory_path() / ("ave-bench-model-" + std::to_string(::getpid()) + ".las")).string();
  double t = Now();
  if (absl::Status s = sim::SimulateAirborneLidar(site, spec, scenario->effects, o.seed, las); !s.ok()) {
    std::cerr << "ave-bench model: " << s.message() << "\n";
    return 1;
  }
  const double sim_s = Now() - t;
  t = Now();
  absl::StatusOr<model::PointCloud> cloud = model::ReadLas(las);
  const double read_s = Now() - t;
  std::filesystem::remove(las);
  if (!cloud.ok()) {
    std::cerr << "ave-bench model: " << cloud.status().message() << "\n";
    return 1;
  }
  const std::vector<uint8_t> truth = cloud->classification;
  std::printf("## ave-bench model: scenario %s, %zu points (spacing %.2f m), simulated in %.2f s, LAS read in %.3f s (%.1f M points/s)\n\n",
              o.scenario.c_str(), cloud->size(), spec.point_spacing_m, sim_s, read_s, cloud->size() / read_s / 1e6);

  std::vector<Row> by_resolution, by_filter;
  for (double res : ParseList(o.resolutions)) {
    model::StaticModelOptions options;
    options.resolution_m = res;
    by_resolution.push_back(Evaluate("res " + std::to_string(res).substr(0, 4), *cloud, truth, site, options, !o.no_buildings));
  }
  std::printf("### Grid resolution (default ground filter)\n\n");
  PrintRows(by_resolution);
  struct FilterCase {
    const char* label;
    double slope, window, threshold;
  };
  const model::GroundFilterOptions d;
  for (const FilterCase& f : {FilterCase{"default", d.slope, d.max_window_m, d.point_threshold_m}, FilterCase{"slope 0.05", 0.05, d.max_window_m, d.point_threshold_m},
                              FilterCase{"slope 1.0", 1.0, d.max_window_m, d.point_threshold_m}, FilterCase{"window 10 m", d.slope, 10, d.point_threshold_m},
                              FilterCase{"window 80 m", d.slope, 80, d.point_threshold_m}, FilterCase{"threshold 0.1 m", d.slope, d.max_window_m, 0.1},
                              FilterCase{"threshold 0.5 m", d.slope, d.max_window_m, 0.5}}) {
    model::StaticModelOptions options;
    options.ground.slope = f.slope;
    options.ground.max_window_m = f.window;
    options.ground.point_threshold_m = f.threshold;
    by_filter.push_back(Evaluate(f.label, *cloud, truth, site, options, false));
  }
  std::printf("\n### Ground filter at 0.5 m (terrain only)\n\n");
  PrintRows(by_filter);

  // Peer: the grey opening next to OpenCV's morphologyEx on the same zmin image.
  mallopt(M_MMAP_THRESHOLD, 256 * 1024 * 1024);
  absl::StatusOr<model::HeightGrid> grid = model::BuildHeightGrid(*cloud, 0.5);
  if (grid.ok()) {
    std::vector<float> zmin = grid->zmin;
    float top = -1e30f;
    for (float& v : zmin) top = std::isfinite(v) ? std::max(top, v) : top;
    for (float& v : zmin) v = std::isfinite(v) ? v : top;  // no empty cells: both sides see one image
    std::printf("\n### Grey opening vs OpenCV morphologyEx(MORPH_OPEN), %dx%d float image, one core\n\n| window cells | ours CPU ms | OpenCV CPU ms | ours / OpenCV | max |diff| m |\n|---|---|---|---|---|\n",
                grid->cols, grid->rows);
    for (int half : {1, 4, 16, 32}) {
      std::vector<float> ours = zmin;
      cv::Mat theirs;
      const cv::Mat src(grid->rows, grid->cols, CV_32F, zmin.data());
      const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * half + 1, 2 * half + 1));
      double ours_s = 1e9, cv_s = 1e9;
      for (int rep = 0; rep < 3; ++rep) {
        ours = zmin;
        t = CpuNow();
        model::MorphologicalOpening(ours, grid->cols, grid->rows, half);
        ours_s = std::min(ours_s, CpuNow() - t);
        t = CpuNow();
        cv::morphologyEx(src, theirs, cv::MORPH_OPEN, kernel, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
        cv_s = std::min(cv_s, CpuNow() - t);
      }
      double diff = 0;
      for (int r = 0; r < grid->rows; ++r) {
        for (int c = 0; c < grid->cols; ++c) diff = std::max(diff, std::abs(static_cast<double>(ours[grid->Index(c, r)]) - theirs.at<float>(r, c)));
      }
      std::printf("| %d | %.2f | %.2f | %.2f | %.3g |\n", 2 * half + 1, ours_s * 1e3, cv_s * 1e3, ours_s / cv_s, diff);
    }
  }

  // Throughput: gridding + ground classification (cells and points) at 1, 3, 10 M points.
  struct Scale {
    double mpoints, seconds, grid_s, filter_s, peak_mb;
  };
  std::vector<Scale> scaling;
  mallopt(M_MMAP_THRESHOLD, 64 * 1024);
  std::printf("\n### Gridding + ground classification at 0.5 m, one core (cloud tiled side by side)\n\n| points | grid s (wall) | ground s (wall) | total CPU s | M points/s (CPU) | peak MB | raw MB (30 B LAS records) | peak / raw | peak / xyz (12 B) |\n|---|---|---|---|---|---|---|---|---|\n");
  for (double mp : ParseList(o.scale)) {
    const size_t n = static_cast<size_t>(mp * 1e6);
    model::PointCloud big = TileCloud(*cloud, n);
    MemoryProbe memory;
    const double cpu0 = CpuNow();
    absl::StatusOr<model::TerrainResult> r = model::BuildTerrain(big, 0.5, model::GroundFilterOptions{});
    const double cpu = CpuNow() - cpu0;
    const double peak = memory.PeakDeltaMb();
    if (!r.ok()) continue;
    scaling.push_back({mp, cpu, r->grid_seconds, r->filter_seconds, peak});
    std::printf("| %.0f M | %.3f | %.3f | %.3f | %.2f | %.0f | %.0f | %.2f | %.2f |\n", mp, r->grid_seconds, r->filter_seconds, cpu, n / cpu / 1e6, peak,
                n * 30 / 1048576.0, peak / (n * 30 / 1048576.0), peak / (n * 12 / 1048576.0));
  }

  // Plot: accuracy vs time per resolution, and cost vs points.
  cv::Mat img(520, 1500, CV_8UC3, cv::Scalar(255, 255, 255));
  Series rmse{"terrain RMSE (m)", cv::Scalar(200, 60, 0), {}}, ground_err{"ground error (%/10)", cv::Scalar(0, 120, 0), {}},
      precision{"1 - building P", cv::Scalar(0, 0, 200), {}}, recall{"1 - building R", cv::Scalar(160, 0, 160), {}}, mem{"peak MB / 100", cv::Scalar(0, 140, 200), {}};
  for (const Row& r : by_resolution) {
    const double s = r.cpu_s;
    rmse.points.emplace_back(s, r.rmse_all);
    char label[16];
    std::snprintf(label, sizeof(label), "%.2g m", r.resolution_m);
    mem.labels.push_back(label);
    ground_err.points.emplace_back(s, (1 - r.ground_accuracy) * 10);
    mem.points.emplace_back(s, r.peak_mb / 100);
    if (r.have_buildings) {
      precision.points.emplace_back(s, 1 - r.buildings.precision);
      recall.points.emplace_back(s, 1 - r.buildings.recall);
    }
  }
  DrawPanel(img, {0, 0, 500, 520}, "grid resolution: error vs CPU time (labels: resolution)", "CPU s, one core (log)", "error",
            {rmse, ground_err, precision, recall, mem}, true);
  Series filter_rmse{"terrain RMSE (m)", cv::Scalar(200, 60, 0), {}}, filter_ground{"ground error (%/10)", cv::Scalar(0, 120, 0), {}};
  for (const Row& r : by_filter) {
    filter_rmse.points.emplace_back(r.cpu_s, r.rmse_all);
    filter_rmse.labels.push_back(r.label);
    filter_ground.points.emplace_back(r.cpu_s, (1 - r.ground_accuracy) * 10);
  }
  filter_rmse.lines = filter_ground.lines = false;
  std::vector<Series> filter_series = {filter_rmse, filter_ground};
  DrawPanel(img, {500, 0, 500, 520}, "ground filter settings at 0.5 m: error vs CPU time", "CPU s (terrain + mesh)", "error", filter_series, false);
  Series time_s{"grid + ground CPU s", cv::Scalar(200, 60, 0), {}}, peak_gb{"peak GB", cv::Scalar(0, 140, 200), {}};
  for (const Scale& s : scaling) {
    time_s.points.emplace_back(s.mpoints, s.seconds);
    peak_gb.points.emplace_back(s.mpoints, s.peak_mb / 1024);
  }
  DrawPanel(img, {1000, 0, 500, 520}, "grid + ground cost vs cloud size (one core)", "million points", "s / GB", {time_s, peak_gb}, false);
  if (!o.png.empty()) {
    cv::imwrite(o.png, img);
    std::printf("\nplot: %s\n", o.png.c_str());
  }
  return 0;
}

}  // namespace

Runner AddModelBench(CLI::App& sub) {
  auto o = std::make_shared<Options>();
  sub.add_option("--scenario", o->scenario, "scenario name or file (its airborne_lidar spec and effects)");
  sub.add_option("--resolutions", o->resolutions, "grid resolutions to sweep (m, comma-separated)");
  sub.add_option("--scale", o->scale, "cloud sizes for the throughput table (million points, comma-separated)");
  sub.add_option("--png", o->png, "plot file (empty: none)")->check(ave::cli::WritableFile());
  sub.add_option("--seed", o->seed, "simulation seed");
  sub.add_flag("--no-buildings", o->no_buildings, "skip building extraction and scoring");
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
