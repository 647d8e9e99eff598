// ave-bench lidar (issue 16): LiDAR people detection and tracking (sensor_agent/lidar_track, i4D
// §3.1-3.2) on the simulated rotating LiDAR against the simulator's truth, on one core.
//
// Every sweep is simulated once and given, in this process, to each configuration of the chain:
//   MoG            the per-pixel mixture alone (no MRF, no 3D point step)
//   MoG+3D         the mixture and the 3D point classification
//   MoG+MRF(k)+3D  the dynamic MRF with k ICM iterations (k = 2 is the default chain)
//   MOG2 peer      OpenCV's BackgroundSubtractorMOG2 on the same range image (ranges in dm), its
//                  mask given to the same ground-lattice detector and tracker
// Scored per configuration: foreground precision / recall per point (truth: the point's label is a
// mover's), CLEAR-MOT (MOTA, MOTP in metres, ID switches, fragmentations, mostly-tracked share)
// online and after the sequence post-processing (bridging, short tracks removed), and CPU ms per
// sweep of this thread. A person counts in a sweep when it has >= 10 points there (MotOptions).
// Then the HDL-64E-class cost: the default chain on sweeps of 2048 azimuth steps x 64 rings.
// Writes a PNG (top view of the crowd's tracks vs truth; MOTA vs ms per sweep) and ends with one
// JSON line of the default chain's figures on the courtyard.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/background_segm.hpp>

#include "model_store/common/cpu_clock.h"
#include "sensor_agent/lidar_track/lidar_track_truth.h"
#include "sensor_agent/lidar_track/people_tracker.h"
#include "sensor_agent/lidar_track/range_image.h"
#include "sensor_agent/lidar_track/sequence_post.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/sim_camera.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

using lidar_track::LidarPeopleTracker;
using lidar_track::LidarPeopleTrackerOptions;
namespace lt = lidar_track::testing;

struct LidarBenchOptions {
  std::string scenario = "courtyard";
  double seconds = 30;
  double crowd_seconds = 30;
  double skip_seconds = 2;  // the mixture's warm-up: not scored
  std::vector<int> mrf_iterations = {1, 2, 5};
  int hdl_sweeps = 30;
  double window_m = lidar_track::ForegroundOptions{}.window_m;
  double bg_tolerance_m = lidar_track::ForegroundOptions{}.bg_tolerance_m;
  int window_rings = lidar_track::ForegroundOptions{}.window_rings;
  std::string png = "lidar_bench.png";
};

struct Config {
  std::string name;
  LidarPeopleTrackerOptions options;
  bool mog2_peer = false;
  bool is_default = false;
};

// One configuration's run over a scenario.
struct ConfigRun {
  Config config;
  std::unique_ptr<LidarPeopleTracker> tracker;
  cv::Ptr<cv::BackgroundSubtractorMOG2> mog2;
  std::vector<lidar::FootTracks> online;  // point ids dropped
  lt::PointScores points;
  double cpu_s = 0, fg_cpu_s = 0;
  int sweeps = 0;
};

struct Row {
  std::string name;
  bool bridged = false, is_default = false, peer = false;
  double precision = 0, recall = 0, ms = 0, fg_ms = 0;
  lt::MotScores mot;
};

std::vector<Config> Configs(const LidarBenchOptions& o, int cols) {
  std::vector<Config> out;
  LidarPeopleTrackerOptions base;
  base.foreground.cols = cols;
  base.foreground.window_m = static_cast<float>(o.window_m);
  base.foreground.bg_tolerance_m = static_cast<float>(o.bg_tolerance_m);
  base.foreground.window_rings = o.window_rings;
  Config mog{"MoG", base};
  mog.options.foreground.mrf_iterations = 0;
  mog.options.foreground.classify_3d = false;
  out.push_back(mog);
  Config mog3d{"MoG+3D", base};
  mog3d.options.foreground.mrf_iterations = 0;
  out.push_back(mog3d);
  for (int k : o.mrf_iterations) {
    Config c{"MoG+MRF(" + std::to_string(k) + ")+3D", base};
    c.options.foreground.mrf_iterations = k;
    c.is_default = k == LidarPeopleTrackerOptions{}.foreground.mrf_iterations;
    if (c.is_default) c.name += " default";
    out.push_back(c);
  }
  Config peer{"MOG2 peer", base};
  peer.mog2_peer = true;
  out.push_back(peer);
  return out;
}

// Per point: foreground when its pixel is foreground in OpenCV MOG2's mask of the range image.
std::vector<uint8_t> Mog2Foreground(ConfigRun& run, const lidar::LidarSweep& sweep, int cols) {
  absl::StatusOr<lidar_track::RangeImage> img = lidar_track::BuildRangeImage(sweep, cols, 130);
  std::vector<uint8_t> fg(sweep.points.size(), 0);
  if (!img.ok()) return fg;
  cv::Mat range(img->rings, img->cols, CV_32F);
  for (int i = 0; i < img->rings * img->cols; ++i) range.at<float>(i / img->cols, i % img->cols) = img->range_m[i] * 10;
  cv::Mat mask;
  run.mog2->apply(range, mask);
  for (size_t i = 0; i < fg.size(); ++i) {
    const int s = img->pixel_of_point[i];
    if (s >= 0) fg[i] = mask.at<uint8_t>(s / img->cols, s % img->cols) > 0;
  }
  return fg;
}

// The parts of a sweep the scores need: its time, truth feet and the movers' points.
lidar::LidarSweep TruthOnly(const lidar::LidarSweep& sweep) {
  lidar::LidarSweep t;
  t.t_ns = sweep.t_ns;
  t.rings = sweep.rings;
  t.truth_feet_in_world = sweep.truth_feet_in_world;
  for (const lidar::SweepPoint& p : sweep.points) {
    if (sim::IsMoverId(p.truth_label)) t.points.push_back(p);
  }
  return t;
}

struct ScenarioResult {
  std::string name;
  int sweeps = 0, skip = 0, points_per_sweep = 0, people = 0;
  double sweep_ms = 100;
  std::vector<Row> rows;
  std::vector<lidar::LidarSweep> truth;
  std::vector<std::vector<lidar::FootTrack>> default_bridged;  // for the plot
  Rigid3d world_from_ground;
  double post_ms = 0;
};

absl::StatusOr<ScenarioResult> RunScenario(const sim::Scenario& sc, const std::string& name, double seconds,
                                           const LidarBenchOptions& o) {
  if (sc.rotating_lidars.empty()) return absl::InvalidArgumentError(sc.label + ": no rotating_lidar sensor");
  const sim::RotatingLidarSpec& spec = sc.rotating_lidars.front();
  ScenarioResult res;
  res.name = name;
  res.sweep_ms = 1000 / spec.rate_hz;
  std::vector<ConfigRun> runs;
  for (const Config& c : Configs(o, spec.azimuth_steps)) {
    ConfigRun r;
    r.config = c;
    r.tracker = std::make_unique<LidarPeopleTracker>(c.options);
    if (c.mog2_peer) r.mog2 = cv::createBackgroundSubtractorMOG2(500, 16, false);
    runs.push_back(std::move(r));
  }
  const int n = std::max(1, static_cast<int>(seconds * spec.rate_hz));
  const int skip = std::min(n - 1, static_cast<int>(o.skip_seconds * spec.rate_hz));
  res.skip = skip;
  const auto t_sim = std::chrono::steady_clock::now();
  double sim_s = 0;
  for (int f = 0; f < n; ++f) {
    const auto t0 = std::chrono::steady_clock::now();
    const lidar::LidarSweep sweep =
        lt::SweepFromSimFrame(sim::SimulateRotatingLidarFrame(sc.world, spec, sc.effects, sc.seed, f / spec.rate_hz), spec);
    sim_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    res.points_per_sweep = std::max(res.points_per_sweep, static_cast<int>(sweep.points.size()));
    for (ConfigRun& r : runs) {
      absl::StatusOr<lidar::FootTracks> out;
      const double c0 = ThreadCpuSeconds();
      std::vector<uint8_t> fg;
      if (r.config.mog2_peer) {
        fg = Mog2Foreground(r, sweep, spec.azimuth_steps);
        r.fg_cpu_s += ThreadCpuSeconds() - c0;
        out = r.tracker->ProcessWithForeground(sweep, fg);
      } else {
        out = r.tracker->Process(sweep);
        r.fg_cpu_s += r.tracker->last_times().foreground_s;
      }
      r.cpu_s += ThreadCpuSeconds() - c0;
      if (!out.ok()) return absl::InternalError(r.config.name + ": " + std::string(out.status().message()));
      if (f >= skip) r.points.Add(sweep, r.tracker->last_foreground());
      out->point_track_id.clear();
      out->point_track_id.shrink_to_fit();
      r.online.push_back(std::move(*out));
      ++r.sweeps;
    }
    res.truth.push_back(TruthOnly(sweep));
    if (f % 50 == 0) {
      std::fprintf(stderr, "  %s: sweep %d / %d (%.0f s)\n", name.c_str(), f, n,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - t_sim).count());
    }
  }
  std::printf("%s: simulated %d sweeps (%d points each at most) in %.1f s (not counted)\n", name.c_str(), n, res.points_per_sweep, sim_s);
  res.sweeps = n;
  for (ConfigRun& r : runs) {
    for (int bridged = 0; bridged < 2; ++bridged) {
      Row row;
      row.name = r.config.name + (bridged ? " +bridging" : "");
      row.bridged = bridged;
      row.is_default = r.config.is_default;
      row.peer = r.config.mog2_peer;
      row.precision = r.points.Precision();
      row.recall = r.points.Recall();
      row.ms = 1000 * r.cpu_s / r.sweeps;
      row.fg_ms = 1000 * r.fg_cpu_s / r.sweeps;
      lt::MotEvaluator eval;
      if (!bridged) {
        for (int f = skip; f < n; ++f) {
          std::vector<lidar::FootTrack> confirmed;
          for (const auto& t : r.online[f].tracks) {
            if (t.confirmed) confirmed.push_back(t);
          }
          eval.Add(res.truth[f], confirmed, r.online[f].world_from_ground);
        }
      } else {
        const double c0 = ThreadCpuSeconds();
        const lidar_track::PostProcessed post = lidar_track::BridgeAndPrune(r.online);
        if (r.config.is_default) res.post_ms = 1000 * (ThreadCpuSeconds() - c0);
        for (int f = skip; f < n; ++f) eval.Add(res.truth[f], post.tracks[f], r.online[f].world_from_ground);
        if (r.config.is_default) {
          res.default_bridged = post.tracks;
          res.world_from_ground = r.online.back().world_from_ground;
        }
      }
      row.mot = eval.Scores();
      res.people = std::max(res.people, row.mot.people);
      res.rows.push_back(row);
    }
  }
  return res;
}

void PrintTable(const ScenarioResult& r) {
  std::printf("\n%s: %d sweeps at %.0f Hz (the first %d, warm-up, not scored), %d people seen, up to %d points per sweep; "
              "post-processing of the whole sequence: %.1f ms\n",
              r.name.c_str(), r.sweeps, 1000 / r.sweep_ms, r.skip, r.people, r.points_per_sweep, r.post_ms);
  std::printf("| chain | fg precision | fg recall | MOTA | MOTP m | ID switches | per person-min | fragmentations | mostly tracked | "
              "fg ms | ms per sweep | x real time |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& w : r.rows) {
    std::printf("| %s | %.3f | %.3f | %.3f | %.3f | %d | %.2f | %d | %.2f | %.2f | %.2f | %.1f |\n", w.name.c_str(), w.precision, w.recall,
                w.mot.mota, w.mot.motp_m, w.mot.id_switches, w.mot.id_switches_per_person_minute, w.mot.fragmentations,
                w.mot.mostly_tracked_share, w.fg_ms, w.ms, r.sweep_ms / std::max(1e-6, w.ms));
  }
}

// HDL-64E-class cost: the default chain on 2048 x 64 sweeps (simulated first, then timed).
struct HdlCost {
  int points = 0, sweeps = 0;
  double ms = 0, fg_ms = 0, blobs_ms = 0, track_ms = 0, learn_ms = 0;
};
absl::StatusOr<HdlCost> RunHdl(const sim::Scenario& sc, int sweeps) {
  sim::RotatingLidarSpec spec = sc.rotating_lidars.front();
  spec.azimuth_steps = 2048;
  LidarPeopleTrackerOptions opt;
  opt.foreground.cols = 2048;
  LidarPeopleTracker tracker(opt);
  HdlCost c;
  const int warm = 12;  // past the mixture's warm-up
  for (int f = 0; f < warm + sweeps; ++f) {
    const lidar::LidarSweep sweep =
        lt::SweepFromSimFrame(sim::SimulateRotatingLidarFrame(sc.world, spec, sc.effects, sc.seed, f / spec.rate_hz), spec);
    c.points = std::max(c.points, static_cast<int>(sweep.points.size()));
    const double c0 = ThreadCpuSeconds();
    absl::StatusOr<lidar::FootTracks> out = tracker.Process(sweep);
    const double dt = ThreadCpuSeconds() - c0;
    if (!out.ok()) return out.status();
    if (f < warm) continue;
    ++c.sweeps;
    c.ms += 1000 * dt;
    const auto& t = tracker.last_times();
    c.fg_ms += 1000 * t.foreground_s, c.blobs_ms += 1000 * t.blobs_s, c.track_ms += 1000 * t.tracking_s, c.learn_ms += 1000 * t.learn_s;
  }
  for (double* v : {&c.ms, &c.fg_ms, &c.blobs_ms, &c.track_ms, &c.learn_ms}) *v /= std::max(1, c.sweeps);
  return c;
}

cv::Scalar IdColour(uint32_t id) {
  const int h = static_cast<int>((id * 47) % 180);
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(h, 220, 220)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  const cv::Vec3b v = bgr.at<cv::Vec3b>(0, 0);
  return cv::Scalar(v[0], v[1], v[2]);
}

void WritePng(const ScenarioResult& top, const std::vector<const ScenarioResult*>& all, const std::string& path) {
  const int w = 1500, h = 760, panel = 700;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  // Left: top view, truth (grey) and the default chain's bridged tracks (a colour per id).
  const double half = 24, scale = (panel - 40) / (2 * half);
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(20 + static_cast<int>((p.x() + half) * scale), 40 + static_cast<int>((half - p.y()) * scale));
  };
  std::map<uint32_t, Eigen::Vector2d> last_truth, last_track;
  for (size_t f = 0; f < top.truth.size(); ++f) {
    for (const auto& [label, p] : top.truth[f].truth_feet_in_world) {
      const Eigen::Vector2d q = p.head<2>();
      if (last_truth.count(label) && (last_truth[label] - q).norm() < 1) cv::line(img, px(last_truth[label]), px(q), cv::Scalar(215, 215, 215), 4);
      last_truth[label] = q;
    }
    for (const lidar::FootTrack& t : top.default_bridged[f]) {
      const Eigen::Vector2d q = (top.world_from_ground * Eigen::Vector3d(t.xy_m.x(), t.xy_m.y(), 0)).head<2>();
      if (last_track.count(t.id) && (last_track[t.id] - q).norm() < 1) cv::line(img, px(last_track[t.id]), px(q), IdColour(t.id), 2);
      last_track[t.id] = q;
    }
  }
  const Eigen::Vector3d sensor = top.world_from_ground.translation;
  cv::drawMarker(img, px(sensor.head<2>()), cv::Scalar(0, 0, 0), cv::MARKER_STAR, 14, 2);
  cv::putText(img, top.name + ": truth (grey) vs tracks after bridging (colour = id), sensor *", {20, 25}, cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0));
  // Right: MOTA vs ms per sweep, both scenarios, online (circle) and bridged (square).
  const int x0 = panel + 90, x1 = w - 30, y0 = 60, y1 = h - 90;
  double max_ms = 1;
  for (const ScenarioResult* r : all) {
    for (const Row& row : r->rows) max_ms = std::max(max_ms, row.ms);
  }
  max_ms *= 1.15;
  const double min_mota = 0.8;  // lower points sit on the axis
  auto pp = [&](double ms, double mota) {
    return cv::Point(x0 + static_cast<int>(ms / max_ms * (x1 - x0)),
                     y1 - static_cast<int>((std::max(mota, min_mota) - min_mota) / (1 - min_mota) * (y1 - y0)));
  };
  cv::rectangle(img, {x0, y0}, {x1, y1}, cv::Scalar(0, 0, 0));
  for (int k = 0; k <= 5; ++k) {
    const double m = min_mota + k * (1 - min_mota) / 5;
    cv::putText(img, cv::format("%.2f", m), {x0 - 40, pp(0, m).y + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0));
    cv::line(img, {x0, pp(0, m).y}, {x1, pp(0, m).y}, cv::Scalar(230, 230, 230));
    const double ms = max_ms * k / 5;
    cv::putText(img, cv::format("%.1f", ms), {pp(ms, 0).x - 8, y1 + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0));
  }
  cv::putText(img, "MOTA", {x0 - 60, y0 - 15}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0));
  cv::putText(img, "ms per sweep, one core (10 Hz sweep = 100 ms)", {x0 + 100, y1 + 45}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0));
  const cv::Scalar scen_col[2] = {cv::Scalar(200, 90, 30), cv::Scalar(30, 120, 220)};
  for (size_t s = 0; s < all.size(); ++s) {
    int label_y = 0;
    for (const Row& row : all[s]->rows) {
      const cv::Point p = pp(row.ms, row.mot.mota);
      const cv::Scalar col = row.peer ? cv::Scalar(60, 60, 60) : scen_col[s % 2];
      if (row.bridged) {
        cv::rectangle(img, p - cv::Point(5, 5), p + cv::Point(5, 5), col, row.is_default ? cv::FILLED : 1);
      } else {
        cv::circle(img, p, 5, col, row.is_default ? cv::FILLED : 1);
      }
      if (!row.bridged) {
        cv::putText(img, row.name, p + cv::Point(8, 4 + 12 * (label_y++ % 2)), cv::FONT_HERSHEY_SIMPLEX, 0.35, col);
      }
    }
    cv::putText(img, all[s]->name, {x0 + 10, y0 + 20 + 18 * static_cast<int>(s)}, cv::FONT_HERSHEY_SIMPLEX, 0.5, scen_col[s % 2]);
  }
  cv::putText(img, "circle: online, square: after bridging; filled: default chain; grey: OpenCV MOG2 peer", {x0 + 10, y1 - 12},
              cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0));
  cv::imwrite(path, img);
}

int RunLidar(const LidarBenchOptions& o) {
  UseOneCore();
  absl::StatusOr<sim::Scenario> sc = sim::LoadScenario(o.scenario);
  if (!sc.ok()) {
    std::cerr << "ave-bench lidar: " << sc.status().message() << "\n";
    return 1;
  }
  std::vector<ScenarioResult> results;
  absl::StatusOr<ScenarioResult> base = RunScenario(*sc, sc->name, o.seconds, o);
  if (!base.ok()) {
    std::cerr << "ave-bench lidar: " << base.status().message() << "\n";
    return 1;
  }
  results.push_back(std::move(*base));
  if (o.crowd_seconds > 0) {
    absl::StatusOr<ScenarioResult> crowd = RunScenario(lt::CrowdedCourtyard(*sc), sc->name + "-crowd", o.crowd_seconds, o);
    if (!crowd.ok()) {
      std::cerr << "ave-bench lidar: " << crowd.status().message() << "\n";
      return 1;
    }
    results.push_back(std::move(*crowd));
  }
  for (const ScenarioResult& r : results) PrintTable(r);
  HdlCost hdl;
  if (o.hdl_sweeps > 0) {
    absl::StatusOr<HdlCost> c = RunHdl(*sc, o.hdl_sweeps);
    if (!c.ok()) {
      std::cerr << "ave-bench lidar: " << c.status().message() << "\n";
      return 1;
    }
    hdl = *c;
    std::printf("\nHDL-64E class (%s, 2048 azimuth steps x 64 rings, %d points per sweep, %d sweeps after warm-up), default chain:\n"
                "| stage | ms per sweep |\n|---|---|\n| range image + MoG + MRF + 3D | %.2f |\n| ground lattice + blobs | %.2f |\n"
                "| tracking + labels | %.2f |\n| background learning | %.2f |\n| whole chain | %.2f |\n",
                sc->name.c_str(), hdl.points, hdl.sweeps, hdl.fg_ms, hdl.blobs_ms, hdl.track_ms, hdl.learn_ms, hdl.ms);
  }
  std::vector<const ScenarioResult*> all;
  for (const ScenarioResult& r : results) all.push_back(&r);
  const ScenarioResult& plot = results.back();
  WritePng(plot, all, o.png);
  std::printf("\nwrote %s\n", o.png.c_str());
  // Summary: the default chain, online, on the first scenario (and bridged / crowd beside it).
  auto find = [](const ScenarioResult& r, bool bridged) -> const Row* {
    for (const Row& w : r.rows) {
      if (w.is_default && w.bridged == bridged) return &w;
    }
    return nullptr;
  };
  const Row* d = find(results.front(), false);
  const Row* db = find(results.front(), true);
  if (!d || !db) return 1;
  std::printf("{\"scenario\": \"%s\", \"mota\": %.4f, \"motp_m\": %.4f, \"id_switches\": %d, \"id_switches_per_person_minute\": %.3f, "
              "\"mota_bridged\": %.4f, \"id_switches_bridged\": %d, \"fg_precision\": %.4f, \"fg_recall\": %.4f, "
              "\"ms_per_frame\": %.3f, \"realtime_factor\": %.2f",
              results.front().name.c_str(), d->mot.mota, d->mot.motp_m, d->mot.id_switches, d->mot.id_switches_per_person_minute,
              db->mot.mota, db->mot.id_switches, d->precision, d->recall, d->ms, results.front().sweep_ms / std::max(1e-6, d->ms));
  if (results.size() > 1) {
    const Row* c = find(results.back(), false);
    const Row* cb = find(results.back(), true);
    if (c && cb) std::printf(", \"crowd_mota\": %.4f, \"crowd_mota_bridged\": %.4f, \"crowd_id_switches\": %d", c->mot.mota, cb->mot.mota, c->mot.id_switches);
  }
  if (hdl.sweeps > 0) std::printf(", \"hdl64_2048_points\": %d, \"hdl64_2048_ms_per_frame\": %.3f", hdl.points, hdl.ms);
  std::printf("}\n");
  return 0;
}

}  // namespace

Runner AddLidarBench(CLI::App& sub) {
  auto options = std::make_shared<LidarBenchOptions>();
  sub.add_option("--scenario", options->scenario, "bundled scenario or .yaml path with a rotating_lidar")->capture_default_str();
  sub.add_option("--seconds", options->seconds, "simulated seconds of the scenario")->capture_default_str()->check(CLI::Range(0.5, 600.0));
  sub.add_option("--crowd-seconds", options->crowd_seconds, "seconds of the crowded variant (0: skip)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 600.0));
  sub.add_option("--skip-seconds", options->skip_seconds, "warm-up seconds left out of the scores")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 60.0));
  sub.add_option("--mrf-iterations", options->mrf_iterations, "ICM iteration counts to compare, comma-separated")
      ->delimiter(',')
      ->capture_default_str()
      ->check(CLI::Range(1, 50));
  sub.add_option("--hdl-sweeps", options->hdl_sweeps, "timed sweeps at 2048 azimuth steps (0: skip)")
      ->capture_default_str()
      ->check(CLI::Range(0, 600));
  sub.add_option("--window-m", options->window_m, "3D point step: neighbourhood half-width (every chain)")->capture_default_str();
  sub.add_option("--bg-tolerance-m", options->bg_tolerance_m, "3D point step: range tolerance (every chain)")->capture_default_str();
  sub.add_option("--window-rings", options->window_rings, "3D point step: rings above and below (every chain)")->capture_default_str();
  sub.add_option("--png", options->png, "plot to write")->capture_default_str()->check(ave::cli::WritableFile());
  return [options] { return RunLidar(*options); };
}

}  // namespace ave::bench
