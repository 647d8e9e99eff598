// ave-bench render: the viewer's renderer (viewer_client/render) on this machine's software
// renderer (Mesa llvmpipe, EGL surfaceless), issue 7:
//   1. frame time of the quad view (browse + three camera-locked views) at --width x --height
//      versus the number of projected cameras, with the view cache off ("before") and on, in the
//      same run: (a) every view and camera still, new video content in every camera each frame
//      and three people walking (as in a control room), (b) the same with the browse view flying
//      (it changes every frame), (c) one camera turning every frame (its shadow map redone);
//      then the difference between a cached and an exact picture of the same inputs;
//   2. frame time and visibility error versus shadow-map size: every projector shows pure magenta,
//      and each pixel of a full-size browse view is classified "projected" or not, against the
//      ray-cast truth (BVH, model_store/geometry/bvh.h) of whether some camera sees that surface
//      point. The ray cast is the peer: its CPU time for the same picture is printed beside the
//      render time, as a ratio.
// Times are wall clock per frame (readback included) and process CPU time per frame (all
// llvmpipe threads), since the machine is shared: frames/s = 1000 / wall ms.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/common/cpu_clock.h"
#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"

namespace ave::bench {
namespace {

constexpr int kWalkers = 3;

struct RenderBenchOptions {
  std::string scenario = "campus";
  int width = 1280;
  int height = 720;
  int frames = 10;
  double grid_m = 2.0;
  std::string counts = "0,1,3,8,16,50";
  std::string shadow_sizes = "512,1024,2048,4096";
  int shadow_cameras = 3;
  int truth_stride = 2;
  std::string plot = "render_bench.png";
  bool cache_only = false;  // skip the cache-off rows and the exact-vs-cached comparison (profiling)
  bool per_projector = false;  // RendererOptions::combined_live_passes off (the passes before h7f)
  double moving_scale = viewer::RendererOptions().moving_view_scale;
  int moving_cameras = viewer::RendererOptions().moving_view_cameras;
};

std::vector<int> ParseInts(const std::string& text) {
  std::vector<int> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) out.push_back(std::stoi(item));
  return out;
}


double Load1() {
  double load = 0;
  std::ifstream("/proc/loadavg") >> load;
  return load;
}

struct BenchCamera {
  std::string id;
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;
  std::vector<uint8_t> rgba;
};

// A gradient with a white 64 px grid (or plain magenta for the visibility part), RGBA.
std::vector<uint8_t> PatternImage(int w, int h, int index, bool magenta) {
  cv::Mat image(h, w, CV_8UC4, magenta ? cv::Scalar(255, 0, 255, 255) : cv::Scalar(0, 0, (53 * index) % 256, 255));
  if (!magenta) {
    std::vector<cv::Mat> channels;
    cv::split(image, channels);
    for (int u = 0; u < w; ++u) channels[0].col(u).setTo(255 * u / w);
    for (int v = 0; v < h; ++v) channels[1].row(v).setTo(255 * v / h);
    cv::merge(channels, image);
    for (int k = 0; k < std::max(w, h); k += 64) {
      cv::rectangle(image, cv::Rect(k, 0, 3, h), cv::Scalar::all(255), cv::FILLED);
      cv::rectangle(image, cv::Rect(0, k, w, 3), cv::Scalar::all(255), cv::FILLED);
    }
  }
  return std::vector<uint8_t>(image.data, image.data + image.total() * 4);
}

// The scenario's cameras, then seeded extra ones around the site looking at its ground.
std::vector<BenchCamera> MakeCameras(const scene::SyntheticCampus& world, int count, bool magenta) {
  std::vector<BenchCamera> cameras;
  for (const scene::CameraSpec& c : world.cameras) {
    if (static_cast<int>(cameras.size()) >= count) break;
    cameras.push_back({c.id, c.intrinsics, c.world_from_camera, {}});
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-1, 1);
  const double e = world.half_extent_m;
  while (static_cast<int>(cameras.size()) < count) {
    const size_t k = cameras.size();
    const double angle = 2 * M_PI * k / 47.0;
    const Eigen::Vector3d eye(0.7 * e * std::cos(angle), 0.7 * e * std::sin(angle), 8 + 4 * (k % 3));
    const Eigen::Vector3d target(0.4 * e * unit(rng), 0.4 * e * unit(rng), 0);
    cameras.push_back({"bench" + std::to_string(k), PinholeIntrinsics::FromFov(640, 480, 60), LookAt(eye, target), {}});
  }
  for (size_t k = 0; k < cameras.size(); ++k) {
    BenchCamera& c = cameras[k];
    c.rgba = PatternImage(c.intrinsics.width, c.intrinsics.height, static_cast<int>(k), magenta);
  }
  return cameras;
}

viewer::Projector MakeProjector(const BenchCamera& c, double extra_yaw_rad = 0) {
  viewer::Projector p;
  p.camera_id = c.id;
  Rigid3d pose = c.world_from_camera;
  pose.rotation = Eigen::AngleAxisd(extra_yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix() * pose.rotation;
  p.view = GlViewFromWorld(pose);
  p.projection = GlProjection(c.intrinsics, p.near_m, p.far_m);
  p.position = pose.translation;
  p.image_width = c.intrinsics.width;
  p.image_height = c.intrinsics.height;
  p.image_rgba = c.rgba;
  p.image_serial = 1;
  return p;
}

viewer::View BrowseView(const viewer::Viewport& viewport, const scene::SyntheticCampus& world, PinholeIntrinsics* k,
                        Rigid3d* pose) {
  *k = PinholeIntrinsics::FromFov(viewport.width, viewport.height, 70);
  const double e = world.half_extent_m;
  *pose = LookAt({-0.6 * e, -0.75 * e, 0.6 * e}, {0, 0, 0});
  viewer::View v;
  v.viewport = viewport;
  v.view = GlViewFromWorld(*pose);
  v.projection = GlProjection(*k, 0.5, 1000);
  return v;
}

// Where the scenario's first cameras look at the ground (their optical axis's first hit): people
// walk in small circles there, so they and the region they hide from the cameras are in view.
std::vector<Eigen::Vector3d> WalkCentres(const scene::SyntheticCampus& world, const MeshBvh& bvh) {
  std::vector<Eigen::Vector3d> centres;
  for (const scene::CameraSpec& c : world.cameras) {
    if (static_cast<int>(centres.size()) >= kWalkers) break;
    const Eigen::Vector3d axis = c.world_from_camera.rotation * Eigen::Vector3d::UnitZ();
    if (const std::optional<RayHit> hit = bvh.Raycast(c.world_from_camera.translation, axis)) {
      centres.push_back(c.world_from_camera.translation + hit->distance_m * axis);
    }
  }
  while (static_cast<int>(centres.size()) < kWalkers) centres.push_back(Eigen::Vector3d(2.0 * centres.size(), 0, 0));
  return centres;
}

// The walkers at step `step`: 1.8 m people going round 3 m circles, 0.15 m per step.
std::vector<viewer::DynamicModel> Walkers(const std::vector<Eigen::Vector3d>& centres, int step) {
  std::vector<viewer::DynamicModel> out;
  for (size_t k = 0; k < centres.size(); ++k) {
    const double a = 0.05 * step + 2.0 * k;
    viewer::DynamicModel m;
    m.base = centres[k] + 3.0 * Eigen::Vector3d(std::cos(a), std::sin(a), 0);
    m.heading_rad = a + M_PI / 2;
    m.size = Eigen::Vector3d(0.5, 0.5, 1.8);
    m.shape = viewer::ModelShape::kCylinder;
    out.push_back(m);
  }
  return out;
}

void WritePng(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height) {
  cv::Mat shot(height, width, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
  cv::Mat bgr;
  cv::cvtColor(shot, bgr, cv::COLOR_RGBA2BGR);
  if (!cv::imwrite(path, bgr)) std::cerr << "ave-bench render: cannot write " << path << "\n";
}

struct Timing {
  double wall_ms = 0, cpu_ms = 0;
  uint64_t shadow_renders = 0;
};

// Renders `frames` frames; `before_frame(f)` may change the inputs.
template <typename F>
Timing TimeFrames(viewer::Renderer& renderer, viewer::HeadlessContext& context, const std::vector<viewer::View>& views,
                  int frames, F before_frame) {
  const uint64_t shadows_before = renderer.stats().shadow_map_renders;
  const double cpu_start = ProcessCpuSeconds();
  const auto start = std::chrono::steady_clock::now();
  for (int f = 0; f < frames; ++f) {
    before_frame(f);
    context.BindFramebuffer();
    if (absl::Status s = renderer.Render(views, context.framebuffer_width(), context.framebuffer_height()); !s.ok()) {
      std::cerr << "ave-bench render: " << s.message() << "\n";
      std::exit(1);
    }
    (void)context.ReadPixels();  // waits for the frame
  }
  Timing t;
  t.wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() / frames;
  t.cpu_ms = 1000 * (ProcessCpuSeconds() - cpu_start) / frames;
  t.shadow_renders = renderer.stats().shadow_map_renders - shadows_before;
  return t;
}

// Fraction of pixels (of those showing the model) where "projected" differs from the ray-cast truth.
struct Visibility {
  double error = 0;
  double truth_ms = 0;
  int pixels = 0;
};

Visibility VisibilityError(const std::vector<uint8_t>& rgba, int width, const PinholeIntrinsics& k, const Rigid3d& pose,
                           const TriangleMesh& mesh, const MeshBvh& bvh, const std::vector<BenchCamera>& cameras,
                           int stride) {
  const auto start = std::chrono::steady_clock::now();
  int wrong = 0, total = 0;
  for (int v = 0; v < k.height; v += stride) {
    for (int u = 0; u < k.width; u += stride) {
      const Eigen::Vector3d ray = pose.rotation * PixelRay(k, Eigen::Vector2d(u, v));
      const std::optional<RayHit> hit = bvh.Raycast(pose.translation, ray);
      if (!hit) continue;
      const Eigen::Vector3d x = pose.translation + hit->distance_m * ray;
      const uint32_t* tri = &mesh.indices[3 * hit->triangle];
      const Eigen::Vector3d a = mesh.positions[tri[0]].cast<double>(), b = mesh.positions[tri[1]].cast<double>(),
                            c = mesh.positions[tri[2]].cast<double>();
      Eigen::Vector3d n = (b - a).cross(c - a).normalized();
      if (n.dot(ray) > 0) n = -n;
      bool seen = false;
      for (const BenchCamera& cam : cameras) {
        const Eigen::Vector3d to_cam = cam.world_from_camera.translation - x;
        if (n.dot(to_cam) <= 0) continue;
        const Eigen::Vector3d p_cam = cam.world_from_camera.Inverse() * x;
        if (p_cam.z() < 0.5 || p_cam.z() > 300) continue;
        const std::optional<Eigen::Vector2d> uv = ProjectToPixel(cam.intrinsics, p_cam);
        if (!uv || uv->x() < -0.5 || uv->y() < -0.5 || uv->x() > cam.intrinsics.width - 0.5 ||
            uv->y() > cam.intrinsics.height - 0.5) {
          continue;
        }
        const double d = to_cam.norm();
        const std::optional<RayHit> block = bvh.Raycast(cam.world_from_camera.translation, -to_cam);
        if (block && block->distance_m < d - 0.05) continue;
        seen = true;
        break;
      }
      const uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
      const bool projected = px[0] > 200 && px[1] < 60 && px[2] > 200;
      wrong += projected != seen;
      ++total;
    }
  }
  Visibility out;
  out.pixels = total;
  out.error = total > 0 ? static_cast<double>(wrong) / total : 0;
  out.truth_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() * stride *
                 stride;  // per full picture
  return out;
}

struct Series {
  std::string name;
  cv::Scalar color;
  std::vector<double> y;
};

// One panel: categorical x labels, several series, axis from 0 to the largest value.
void DrawPanel(cv::Mat& image, cv::Rect area, const std::string& title, const std::vector<std::string>& x_labels,
               const std::vector<Series>& series, const std::string& y_label) {
  const cv::Rect plot(area.x + 60, area.y + 30, area.width - 80, area.height - 80);
  cv::rectangle(image, plot, cv::Scalar(0, 0, 0), 1);
  cv::putText(image, title, {area.x + 10, area.y + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  double y_max = 1e-9;
  for (const Series& s : series) {
    for (double y : s.y) y_max = std::max(y_max, y);
  }
  y_max *= 1.1;
  const int n = static_cast<int>(x_labels.size());
  auto px = [&](int i, double y) {
    const double fx = n > 1 ? static_cast<double>(i) / (n - 1) : 0.5;
    return cv::Point(plot.x + static_cast<int>(fx * plot.width), plot.y + plot.height - static_cast<int>(y / y_max * plot.height));
  };
  for (int t = 0; t <= 4; ++t) {
    const double y = y_max * t / 4;
    const cv::Point p = px(0, y);
    cv::line(image, {plot.x, p.y}, {plot.x + plot.width, p.y}, cv::Scalar(220, 220, 220), 1);
    char text[32];
    std::snprintf(text, sizeof(text), y_max >= 20 ? "%.0f" : "%.2f", y);
    cv::putText(image, text, {area.x + 5, p.y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  for (int i = 0; i < n; ++i) {
    cv::putText(image, x_labels[i], {px(i, 0).x - 10, plot.y + plot.height + 16}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::putText(image, y_label, {plot.x, area.y + area.height - 20}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  for (size_t k = 0; k < series.size(); ++k) {
    const Series& s = series[k];
    for (size_t i = 0; i < s.y.size(); ++i) {
      cv::circle(image, px(static_cast<int>(i), s.y[i]), 3, s.color, cv::FILLED, cv::LINE_AA);
      if (i > 0) cv::line(image, px(static_cast<int>(i) - 1, s.y[i - 1]), px(static_cast<int>(i), s.y[i]), s.color, 2, cv::LINE_AA);
    }
    cv::putText(image, s.name, {plot.x + plot.width - 230, plot.y + 18 + 16 * static_cast<int>(k)}, cv::FONT_HERSHEY_SIMPLEX,
                0.4, s.color, 1, cv::LINE_AA);
  }
}

int RunRender(const RenderBenchOptions& o) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench render: " << scenario.status().message() << "\n";
    return 1;
  }
  const scene::SyntheticCampus& world = scenario->world;
  const TriangleMesh mesh = scene::BuildStaticMesh(world, o.grid_m);
  const std::vector<int> counts = ParseInts(o.counts), sizes = ParseInts(o.shadow_sizes);
  const int max_count = *std::max_element(counts.begin(), counts.end());
  if (max_count > viewer::kMaxProjectors) {
    std::cerr << "ave-bench render: --counts: at most " << viewer::kMaxProjectors << " cameras\n";
    return 2;
  }
  absl::StatusOr<std::unique_ptr<viewer::HeadlessContext>> context = viewer::CreateHeadlessContext(o.width, o.height);
  if (!context.ok()) {
    std::cerr << "ave-bench render: " << context.status().message() << "\n";
    return 1;
  }
  std::printf("renderer: %s\nscene: %s, %zu triangles (grid %.1f m); %dx%d; load average at start %.2f\n",
              (*context)->Description().c_str(), scenario->label.c_str(), mesh.indices.size() / 3, o.grid_m, o.width,
              o.height, Load1());

  // Part 1: quad view versus camera count, view cache off ("before") and on.
  const std::vector<BenchCamera> cameras = MakeCameras(world, max_count, false);
  std::vector<viewer::Projector> all;
  for (const BenchCamera& c : cameras) all.push_back(MakeProjector(c));
  // Each camera's second picture (inverted): live video alternates between the two every frame.
  std::vector<std::vector<uint8_t>> inverted;
  for (const BenchCamera& c : cameras) {
    inverted.push_back(c.rgba);
    for (size_t k = 0; k < inverted.back().size(); ++k) {
      if (k % 4 != 3) inverted.back()[k] = static_cast<uint8_t>(255 - inverted.back()[k]);
    }
  }
  const MeshBvh bvh(mesh);
  const std::vector<Eigen::Vector3d> walk_centres = WalkCentres(world, bvh);
  const std::array<viewer::Viewport, 4> quads = viewer::QuadLayout(o.width, o.height);
  PinholeIntrinsics browse_k;
  Rigid3d browse_pose;
  std::vector<viewer::View> views = {BrowseView(quads[0], world, &browse_k, &browse_pose)};
  std::vector<std::string> x_counts;
  Series still_off{"still, cache off: CPU ms", cv::Scalar(120, 120, 255), {}},
      still_on{"still, cache on: CPU ms", cv::Scalar(0, 0, 200), {}},
      empty_on{"still, nobody walking, cache on", cv::Scalar(0, 160, 0), {}},
      fly_off{"browse flying, cache off: CPU ms", cv::Scalar(255, 180, 120), {}},
      fly_on{"browse flying, cache on: CPU ms", cv::Scalar(200, 80, 0), {}};
  std::printf("\nStill: every view and camera still, new video in every camera each frame, %d people walking.\n"
              "Flying: the same with the browse view moving every frame. Turning: camera 0 turning, still views.\n",
              kWalkers);
  std::printf("\n| cameras | cache | still: CPU ms/frame | wall ms | frames/s | still, nobody walking: CPU ms | frames/s | flying: CPU ms/frame | wall ms | frames/s | turning: CPU ms | frames/s | shadow maps redrawn (still) | cache builds / hits / patches (still) |\n");
  std::printf("| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n");
  std::vector<std::unique_ptr<viewer::Renderer>> renderers;  // [0] cache off, [1] on
  for (bool cache : {false, true}) {
    if (!cache && o.cache_only) continue;
    viewer::RendererOptions options;
    options.shadow_map_size = 1024;
    options.view_cache = cache;
    options.combined_live_passes = !o.per_projector;
    options.moving_view_scale = o.moving_scale;
    options.moving_view_cameras = o.moving_cameras;
    absl::StatusOr<std::unique_ptr<viewer::Renderer>> renderer = viewer::Renderer::Create(options);
    if (!renderer.ok() || !(*renderer)->SetStaticMesh(mesh).ok()) {
      std::cerr << "ave-bench render: renderer: " << renderer.status().message() << "\n";
      return 1;
    }
    renderers.push_back(std::move(*renderer));
  }
  uint64_t serial = 1;
  int walk_step = 0;
  // New content in every camera and the walkers one step on: what changes in a still control room.
  auto live_frame = [&](viewer::Renderer& r, std::vector<viewer::Projector>& some) {
    ++serial;
    for (size_t k = 0; k < some.size(); ++k) {
      some[k].image_rgba = serial % 2 ? std::span<const uint8_t>(cameras[k].rgba) : std::span<const uint8_t>(inverted[k]);
      some[k].image_serial = serial;
    }
    (void)r.SetProjectors(some);
    (void)r.SetDynamicModels(Walkers(walk_centres, ++walk_step));
  };
  for (int n : counts) {
    std::vector<viewer::Projector> some(all.begin(), all.begin() + n);
    views.resize(1);
    for (int k = 0; k < 3; ++k) {
      if (k < n) {
        views.push_back(viewer::ViewLockedToProjector(some[k], quads[k + 1]));
      } else {
        viewer::View other = views[0];
        other.viewport = quads[k + 1];
        views.push_back(other);
      }
    }
    for (size_t c = 0; c < renderers.size(); ++c) {
      viewer::Renderer& r = *renderers[c];
      const bool cache_on = o.cache_only || c == 1;
      if (!r.SetProjectors(some).ok()) return 1;
      TimeFrames(r, **context, views, 2, [&](int) { live_frame(r, some); });
      const viewer::RenderStats before = r.stats();
      const Timing t_still = TimeFrames(r, **context, views, o.frames, [&](int) { live_frame(r, some); });
      const viewer::RenderStats after = r.stats();
      (void)r.SetDynamicModels({});
      const Timing t_empty = TimeFrames(r, **context, views, o.frames, [&](int) {
        live_frame(r, some);
        (void)r.SetDynamicModels({});
      });
      std::vector<viewer::View> flying = views;
      const Timing t_fly = TimeFrames(r, **context, flying, o.frames, [&](int f) {
        live_frame(r, some);
        Rigid3d pose = browse_pose;
        pose.translation += Eigen::Vector3d(0.5 * (f + 1), 0.3 * (f + 1), 0);
        flying[0].view = GlViewFromWorld(pose);
      });
      if (cache_on && n == std::min(3, max_count)) {  // the last flying frame: the browse view drawn reduced
        WritePng("render_bench_quad_flying.png", *(*context)->ReadPixels(), o.width, o.height);
      }
      Timing t_turn;
      if (n > 0) {
        t_turn = TimeFrames(r, **context, views, o.frames, [&](int f) {
          some[0] = MakeProjector(cameras[0], 0.002 * (f + 1));
          live_frame(r, some);
        });
        some[0] = MakeProjector(cameras[0]);
        (void)r.SetProjectors(some);
      } else {
        t_turn = t_still;
      }
      std::printf("| %d | %s | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %llu | %llu / %llu / %llu |\n",
                  n, cache_on ? "on" : "off", t_still.cpu_ms, t_still.wall_ms, 1000 / t_still.wall_ms, t_empty.cpu_ms,
                  1000 / t_empty.wall_ms, t_fly.cpu_ms, t_fly.wall_ms,
                  1000 / t_fly.wall_ms, t_turn.cpu_ms, 1000 / t_turn.wall_ms,
                  static_cast<unsigned long long>(t_still.shadow_renders),
                  static_cast<unsigned long long>(after.view_cache_builds - before.view_cache_builds),
                  static_cast<unsigned long long>(after.view_cache_hits - before.view_cache_hits),
                  static_cast<unsigned long long>(after.view_cache_patches - before.view_cache_patches));
      std::fflush(stdout);
      (cache_on ? still_on : still_off).y.push_back(t_still.cpu_ms);
      if (cache_on) empty_on.y.push_back(t_empty.cpu_ms);
      (cache_on ? fly_on : fly_off).y.push_back(t_fly.cpu_ms);
    }
    x_counts.push_back(std::to_string(n));
  }

  // Cached against exact: the same inputs (still views, walkers) into the uncached renderer and
  // cached ones keeping 4 (the default) and 8 entries per pixel.
  {
    viewer::RendererOptions options;
    options.shadow_map_size = 1024;
    options.view_cache_entries = 8;
    absl::StatusOr<std::unique_ptr<viewer::Renderer>> eight = viewer::Renderer::Create(options);
    if (!eight.ok() || !(*eight)->SetStaticMesh(mesh).ok()) {
      std::cerr << "ave-bench render: renderer: " << eight.status().message() << "\n";
      return 1;
    }
    renderers.push_back(std::move(*eight));
  }
  std::printf("\n| cameras | cached (4 entries) vs exact: mean abs difference (levels) | max | pixels > 2 levels | 8 entries: mean | max | pixels > 2 levels |\n");
  std::printf("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  std::vector<int> compared = {std::min(3, max_count)};
  if (max_count > 3) compared.push_back(max_count);
  if (o.cache_only) compared.clear();
  for (int n : compared) {
    if (n == 0) continue;
    std::vector<viewer::Projector> some(all.begin(), all.begin() + n);
    views.resize(1);
    for (int k = 0; k < 3; ++k) views.push_back(viewer::ViewLockedToProjector(some[k % std::max(1, n)], quads[k + 1]));
    std::vector<std::vector<uint8_t>> pictures;
    for (const std::unique_ptr<viewer::Renderer>& r : renderers) {
      for (viewer::Projector& p : some) p.image_serial = ++serial;
      (void)r->SetProjectors(some);
      (void)r->SetDynamicModels(Walkers(walk_centres, walk_step));
      TimeFrames(*r, **context, views, 3, [](int) {});  // the last frame is drawn from the cache
      pictures.push_back(*(*context)->ReadPixels());
    }
    std::printf("| %d", n);
    for (size_t c = 1; c < pictures.size(); ++c) {
      double sum = 0;
      int max_diff = 0;
      size_t over = 0;
      const size_t pixels = pictures[0].size() / 4;
      for (size_t k = 0; k < pixels; ++k) {
        int worst = 0;
        for (int ch = 0; ch < 3; ++ch) {
          const int d = std::abs(int(pictures[0][4 * k + ch]) - int(pictures[c][4 * k + ch]));
          sum += d;
          worst = std::max(worst, d);
        }
        max_diff = std::max(max_diff, worst);
        over += worst > 2;
      }
      std::printf(" | %.3f | %d | %.3f %%", sum / (3.0 * pixels), max_diff, 100.0 * over / pixels);
    }
    std::printf(" |\n");
    std::fflush(stdout);
    if (n == std::min(3, max_count)) WritePng("render_bench_quad.png", pictures[1], o.width, o.height);
    if (n == max_count) {
      WritePng("render_bench_quad_exact.png", pictures[0], o.width, o.height);
      WritePng("render_bench_quad_cached.png", pictures[1], o.width, o.height);
    }
  }
  renderers.clear();

  // Part 2: shadow-map size versus visibility error (full-size browse view, magenta video).
  const std::vector<BenchCamera> magenta = MakeCameras(world, o.shadow_cameras, true);
  std::vector<viewer::Projector> magenta_projectors;
  for (const BenchCamera& c : magenta) magenta_projectors.push_back(MakeProjector(c));
  std::vector<std::string> x_sizes;
  Series size_ms{"quad view ms/frame (wall)", cv::Scalar(200, 80, 0), {}};
  Series size_error{"visibility error, % of pixels", cv::Scalar(0, 0, 200), {}};
  std::printf("\n| shadow map | quad view ms/frame (%d cameras) | visibility error vs ray cast | browse view ms | ray-cast truth ms (1 core) | render / ray cast |\n",
              o.shadow_cameras);
  std::printf("| --- | --- | --- | --- | --- | --- |\n");
  for (int size : sizes) {
    viewer::RendererOptions options;
    options.shadow_map_size = size;
    options.display.sky = false;
    absl::StatusOr<std::unique_ptr<viewer::Renderer>> renderer = viewer::Renderer::Create(options);
    if (!renderer.ok() || !(*renderer)->SetStaticMesh(mesh).ok() || !(*renderer)->SetProjectors(magenta_projectors).ok()) {
      std::cerr << "ave-bench render: shadow size " << size << ": renderer failed\n";
      return 1;
    }
    viewer::Renderer& r = **renderer;
    std::vector<viewer::View> quad_views = {BrowseView(quads[0], world, &browse_k, &browse_pose)};
    for (int k = 0; k < 3; ++k) {
      quad_views.push_back(viewer::ViewLockedToProjector(magenta_projectors[k % magenta_projectors.size()], quads[k + 1]));
    }
    TimeFrames(r, **context, quad_views, 2, [](int) {});
    const Timing t = TimeFrames(r, **context, quad_views, o.frames, [](int) {});
    PinholeIntrinsics full_k;
    Rigid3d full_pose;
    const std::vector<viewer::View> full = {BrowseView({0, 0, o.width, o.height}, world, &full_k, &full_pose)};
    const Timing t_full = TimeFrames(r, **context, full, 3, [](int) {});
    const std::vector<uint8_t> rgba = *(*context)->ReadPixels();
    const Visibility vis = VisibilityError(rgba, o.width, full_k, full_pose, mesh, bvh, magenta, o.truth_stride);
    std::printf("| %d | %.1f | %.2f %% of %d pixels | %.1f | %.0f | %.3f |\n", size, t.wall_ms, 100 * vis.error, vis.pixels,
                t_full.wall_ms, vis.truth_ms, t_full.wall_ms / vis.truth_ms);
    std::fflush(stdout);
    if (size == 1024) WritePng("render_bench_visibility.png", rgba, o.width, o.height);
    x_sizes.push_back(std::to_string(size));
    size_ms.y.push_back(t.wall_ms);
    size_error.y.push_back(100 * vis.error);
  }

  cv::Mat plot(420, 1200, CV_8UC3, cv::Scalar(255, 255, 255));
  DrawPanel(plot, {0, 0, 600, 420}, "quad view " + std::to_string(o.width) + "x" + std::to_string(o.height) + ": CPU ms per frame vs cameras projected",
            x_counts, {still_off, still_on, empty_on, fly_off, fly_on}, "cameras projected");
  DrawPanel(plot, {600, 0, 300, 420}, "ms/frame vs shadow map", x_sizes, {size_ms}, "shadow map size (px)");
  DrawPanel(plot, {900, 0, 300, 420}, "visibility error %", x_sizes, {size_error}, "shadow map size (px)");
  if (!cv::imwrite(o.plot, plot)) {
    std::cerr << "ave-bench render: cannot write " << o.plot << "\n";
    return 1;
  }
  std::printf("\nplot: %s; load average at end %.2f\n", o.plot.c_str(), Load1());
  return 0;
}

}  // namespace

Runner AddRenderBench(CLI::App& sub) {
  auto o = std::make_shared<RenderBenchOptions>();
  sub.add_option("--scenario", o->scenario, "bundled scenario name or .yaml path");
  sub.add_option("--width", o->width, "framebuffer width (px)")->check(ave::cli::Range(64, 8192));
  sub.add_option("--height", o->height, "framebuffer height (px)")->check(ave::cli::Range(64, 8192));
  sub.add_option("--frames", o->frames, "timed frames per row")->check(ave::cli::Range(1, 1000));
  sub.add_option("--grid", o->grid_m, "terrain grid of the static mesh (m)")->check(ave::cli::Range(0.25, 50.0));
  sub.add_option("--counts", o->counts, "camera counts, comma-separated");
  sub.add_option("--shadow-sizes", o->shadow_sizes, "shadow-map sizes, comma-separated");
  sub.add_option("--shadow-cameras", o->shadow_cameras, "cameras in the shadow-size part")->check(ave::cli::Range(1, 64));
  sub.add_option("--truth-stride", o->truth_stride, "ray-cast every n-th pixel")->check(ave::cli::Range(1, 64));
  sub.add_option("--plot", o->plot, "PNG plot path")->check(ave::cli::WritableFile());
  sub.add_option("--moving-cameras", o->moving_cameras,
                 "RendererOptions::moving_view_cameras (a moving view seeing more is reduced further)")
      ->check(ave::cli::Range(1, 1000));
  sub.add_option("--moving-scale", o->moving_scale, "RendererOptions::moving_view_scale (1: moving views in full)")
      ->check(ave::cli::Range(1.0, 4.0));
  sub.add_flag("--per-projector", o->per_projector, "one pass per live projector (combined_live_passes off)");
  sub.add_flag("--cache-only", o->cache_only, "only the cache-on rows (no cache-off rows, no exact-vs-cached part)");
  return [o] { return RunRender(*o); };
}

}  // namespace ave::bench
