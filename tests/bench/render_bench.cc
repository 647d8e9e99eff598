// ave-bench render: the viewer's renderer (viewer_client/render) on this machine's software
// renderer (Mesa llvmpipe, EGL surfaceless), issue 7:
//   1. frame time of the quad view (browse + three camera-locked views) at --width x --height
//      versus the number of projected cameras, with every camera still (shadow maps kept: the
//      per-camera cost must stay flat) and with one camera turning every frame (its shadow map
//      redone each frame);
//   2. frame time and visibility error versus shadow-map size: every projector shows pure magenta,
//      and each pixel of a full-size browse view is classified "projected" or not, against the
//      ray-cast truth (BVH, model_store/geometry/bvh.h) of whether some camera sees that surface
//      point. The ray cast is the peer: its CPU time for the same picture is printed beside the
//      render time, as a ratio.
// Times are wall clock per frame (readback included) and process CPU time per frame (all
// llvmpipe threads), since the machine is shared: frames/s = 1000 / wall ms.
#include <sys/resource.h>

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

#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"

namespace ave::bench {
namespace {

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
};

std::vector<int> ParseInts(const std::string& text) {
  std::vector<int> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) out.push_back(std::stoi(item));
  return out;
}

double CpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_stime.tv_sec + 1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
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

struct Timing {
  double wall_ms = 0, cpu_ms = 0;
  uint64_t shadow_renders = 0;
};

// Renders `frames` frames; `before_frame(f)` may change the inputs.
template <typename F>
Timing TimeFrames(viewer::Renderer& renderer, viewer::HeadlessContext& context, const std::vector<viewer::View>& views,
                  int frames, F before_frame) {
  const uint64_t shadows_before = renderer.stats().shadow_map_renders;
  const double cpu_start = CpuSeconds();
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
  t.cpu_ms = 1000 * (CpuSeconds() - cpu_start) / frames;
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

  // Part 1: quad view versus camera count.
  const std::vector<BenchCamera> cameras = MakeCameras(world, max_count, false);
  std::vector<viewer::Projector> all;
  for (const BenchCamera& c : cameras) all.push_back(MakeProjector(c));
  const std::array<viewer::Viewport, 4> quads = viewer::QuadLayout(o.width, o.height);
  PinholeIntrinsics browse_k;
  Rigid3d browse_pose;
  std::vector<viewer::View> views = {BrowseView(quads[0], world, &browse_k, &browse_pose)};
  std::vector<std::string> x_counts;
  Series still{"all cameras still: wall ms", cv::Scalar(200, 80, 0), {}},
      still_cpu{"all still: CPU ms (both cores)", cv::Scalar(200, 180, 120), {}},
      moving{"one camera turning: wall ms", cv::Scalar(0, 0, 200), {}};
  std::printf("\n| cameras projected | still: ms/frame (wall) | frames/s | CPU ms/frame | shadow maps redrawn | one turning: ms/frame | frames/s |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- |\n");
  {
    viewer::RendererOptions options;
    options.shadow_map_size = 1024;
    absl::StatusOr<std::unique_ptr<viewer::Renderer>> renderer = viewer::Renderer::Create(options);
    if (!renderer.ok() || !(*renderer)->SetStaticMesh(mesh).ok()) {
      std::cerr << "ave-bench render: renderer: " << renderer.status().message() << "\n";
      return 1;
    }
    viewer::Renderer& r = **renderer;
    for (int n : counts) {
      std::vector<viewer::Projector> some(all.begin(), all.begin() + n);
      if (!r.SetProjectors(some).ok()) return 1;
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
      TimeFrames(r, **context, views, 2, [](int) {});
      const Timing t_still = TimeFrames(r, **context, views, o.frames, [](int) {});
      Timing t_moving;
      if (n > 0) {
        t_moving = TimeFrames(r, **context, views, o.frames, [&](int f) {
          some[0] = MakeProjector(cameras[0], 0.002 * (f + 1));
          some[0].image_rgba = {};
          (void)r.SetProjectors(some);
        });
        some[0] = MakeProjector(cameras[0]);
        (void)r.SetProjectors(some);
      } else {
        t_moving = t_still;
      }
      std::printf("| %d | %.1f | %.1f | %.1f | %llu | %.1f | %.1f |\n", n, t_still.wall_ms, 1000 / t_still.wall_ms,
                  t_still.cpu_ms, static_cast<unsigned long long>(t_still.shadow_renders), t_moving.wall_ms,
                  1000 / t_moving.wall_ms);
      std::fflush(stdout);
      x_counts.push_back(std::to_string(n));
      still.y.push_back(t_still.wall_ms);
      still_cpu.y.push_back(t_still.cpu_ms);
      moving.y.push_back(t_moving.wall_ms);
    }
  }

  // Part 2: shadow-map size versus visibility error (full-size browse view, magenta video).
  const std::vector<BenchCamera> magenta = MakeCameras(world, o.shadow_cameras, true);
  std::vector<viewer::Projector> magenta_projectors;
  for (const BenchCamera& c : magenta) magenta_projectors.push_back(MakeProjector(c));
  const MeshBvh bvh(mesh);
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
    if (size == 1024) {
      cv::Mat shot(o.height, o.width, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
      cv::Mat bgr;
      cv::cvtColor(shot, bgr, cv::COLOR_RGBA2BGR);
      cv::imwrite("render_bench_visibility.png", bgr);
    }
    x_sizes.push_back(std::to_string(size));
    size_ms.y.push_back(t.wall_ms);
    size_error.y.push_back(100 * vis.error);
  }

  cv::Mat plot(420, 1200, CV_8UC3, cv::Scalar(255, 255, 255));
  DrawPanel(plot, {0, 0, 600, 420}, "quad view " + std::to_string(o.width) + "x" + std::to_string(o.height) + ": ms per frame vs cameras projected",
            x_counts, {still, still_cpu, moving}, "cameras projected");
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
  sub.add_option("--width", o->width, "framebuffer width (px)")->check(CLI::Range(64, 8192));
  sub.add_option("--height", o->height, "framebuffer height (px)")->check(CLI::Range(64, 8192));
  sub.add_option("--frames", o->frames, "timed frames per row")->check(CLI::Range(1, 1000));
  sub.add_option("--grid", o->grid_m, "terrain grid of the static mesh (m)")->check(CLI::Range(0.25, 50.0));
  sub.add_option("--counts", o->counts, "camera counts, comma-separated");
  sub.add_option("--shadow-sizes", o->shadow_sizes, "shadow-map sizes, comma-separated");
  sub.add_option("--shadow-cameras", o->shadow_cameras, "cameras in the shadow-size part")->check(CLI::Range(1, 64));
  sub.add_option("--truth-stride", o->truth_stride, "ray-cast every n-th pixel")->check(CLI::Range(1, 64));
  sub.add_option("--plot", o->plot, "PNG plot path");
  return [o] { return RunRender(*o); };
}

}  // namespace ave::bench
