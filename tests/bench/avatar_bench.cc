// ave-bench avatars (issue 17, i4D §5): what walking avatars cost the viewer on this machine's
// software renderer (Mesa llvmpipe, EGL surfaceless). The campus static model, its first three
// cameras projecting video, one browse view at --width x --height looking at the walk area; N
// people walk straight lines through it (heading = direction of travel, phase = distance walked /
// stride), their positions and frames changing every frame. For N in --counts: ms per frame with
// the people as avatars (one instanced draw per sequence frame, into the G-buffer and the shadow
// maps) and, in the same run, as the cylinders the viewer draws without avatars (the peer).
// The sequence is the procedural test walker (model_store/avatar/procedural_avatar.h, 12 frames,
// 720 triangles a frame), or with --avseq the studio's reconstructed walk (`ave-studio`'s
// walk.avseq: tens of thousands of triangles a frame and a texture atlas each).
// Writes avatars_bench.png (the largest N) and ends with a one-line JSON summary.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#ifndef AVE_BENCH_NO_IMGCODECS
#include <opencv2/imgcodecs.hpp>
#endif
#include <opencv2/imgproc.hpp>

#include "model_store/avatar/avatar_blob.h"
#include "model_store/avatar/procedural_avatar.h"
#include "model_store/common/cpu_clock.h"
#include "model_store/geometry/camera.h"
#include "model_store/scene/campus.h"
#include "tests/bench/bench.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"

namespace ave::bench {
namespace {

struct AvatarBenchOptions {
  int width = 1280;
  int height = 720;
  int frames = 20;
  std::string counts = "0,1,10,100";
  int cameras = 3;
  std::string png = "avatars_bench.png";
  bool model_shadows = true;  // RendererOptions::dynamic_objects_cast_shadows
  bool view_cache = true;     // RendererOptions::view_cache
  std::string avseq;          // a walk.avseq to draw instead of the procedural walker
  bool cylinders = true;      // the cylinders peer
};

struct Walker {
  Eigen::Vector3d start;
  double heading_rad;
};

// N people spread over a 24 m square around `centre`, each on its own straight line.
std::vector<Walker> MakeWalkers(const scene::SyntheticCampus& world, const Eigen::Vector3d& centre, int n) {
  std::vector<Walker> out;
  const int side = std::max(1, static_cast<int>(std::ceil(std::sqrt(n))));
  for (int k = 0; k < n; ++k) {
    const double x = centre.x() - 12 + 24.0 * (k % side + 0.5) / side;
    const double y = centre.y() - 12 + 24.0 * (k / side + 0.5) / side;
    out.push_back({{x, y, world.TerrainHeight(x, y)}, 2.399963 * k});  // golden angle: every direction
  }
  return out;
}

// Walker k at time t_s: 1.3 m/s along its heading, back and forth over 6 m (turning at each end).
void Pose(const scene::SyntheticCampus& world, const Walker& w, double t_s, double stride_m, Eigen::Vector3d* base,
          double* heading, double* phase) {
  const double d = 1.3 * t_s;
  const double leg = std::fmod(d, 12.0);
  const double along = leg < 6 ? leg - 3 : 9 - leg;
  *heading = leg < 6 ? w.heading_rad : w.heading_rad + M_PI;
  *base = w.start + along * Eigen::Vector3d(std::cos(w.heading_rad), std::sin(w.heading_rad), 0);
  base->z() = world.TerrainHeight(base->x(), base->y());
  *phase = d / stride_m;
}

viewer::Projector MakeProjector(const scene::CameraSpec& c, const std::vector<uint8_t>& rgba) {
  viewer::Projector p;
  p.camera_id = c.id;
  p.view = GlViewFromWorld(c.world_from_camera);
  p.projection = GlProjection(c.intrinsics, p.near_m, p.far_m);
  p.position = c.world_from_camera.translation;
  p.image_width = c.intrinsics.width;
  p.image_height = c.intrinsics.height;
  p.image_rgba = rgba;
  p.image_serial = 1;
  return p;
}

// The renderer's RGBA pixels (top row first) as a PNG. ave-bench-avatars, the GPU machine's
// build, links no image codecs (they pull GDAL and ~150 MB of libraries): it says so instead.
void WritePng(const std::string& path, std::vector<uint8_t>& rgba, int w, int h) {
#ifdef AVE_BENCH_NO_IMGCODECS
  (void)rgba, (void)w, (void)h;
  std::fprintf(stderr, "ave-bench-avatars: built without PNG output, '%s' not written (use --png '')\n", path.c_str());
#else
  cv::Mat shot(h, w, CV_8UC4, rgba.data());
  cv::Mat bgr;
  cv::cvtColor(shot, bgr, cv::COLOR_RGBA2BGR);
  cv::imwrite(path, bgr);
#endif
}

std::vector<uint8_t> Gradient(int w, int h) {
  cv::Mat image(h, w, CV_8UC4, cv::Scalar(0, 0, 120, 255));
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) image.at<cv::Vec4b>(v, u) = cv::Vec4b(255 * u / w, 255 * v / h, 120, 255);
  return std::vector<uint8_t>(image.data, image.data + image.total() * 4);
}

struct Timing {
  double wall_ms = 0, cpu_ms = 0;
};

// out (MeasureViewerAvatarCost): the figures go there instead of the JSON summary.
int Run(const AvatarBenchOptions& o, ViewerAvatarCost* out = nullptr) {
  const scene::SyntheticCampus world = scene::BuiltinCampus();
  const TriangleMesh mesh = scene::BuildStaticMesh(world, 2.0);
  std::vector<int> counts;
  std::stringstream in(o.counts);
  for (std::string item; std::getline(in, item, ',');) counts.push_back(std::stoi(item));
  auto context = viewer::CreateHeadlessContext(o.width, o.height);
  if (!context.ok()) {
    std::cerr << "ave-bench avatars: " << context.status().message() << "\n";
    if (out) out->error = std::string(context.status().message());
    return 1;
  }
  viewer::RendererOptions renderer_options;
  renderer_options.dynamic_objects_cast_shadows = o.model_shadows;
  renderer_options.view_cache = o.view_cache;
  auto made = viewer::Renderer::Create(renderer_options);
  if (!made.ok()) {
    std::cerr << "ave-bench avatars: " << made.status().message() << "\n";
    if (out) out->error = std::string(made.status().message());
    return 1;
  }
  viewer::Renderer& r = **made;
  avatar::AvatarSequence walk;
  if (o.avseq.empty()) {
    walk = avatar::MakeProceduralWalk();
  } else {
    absl::StatusOr<avatar::AvatarSequence> read = avatar::ReadAvatarSequenceFile(o.avseq);
    if (!read.ok()) {
      std::fprintf(stderr, "ave-bench avatars: --avseq: %s\n", std::string(read.status().message()).c_str());
      return 1;
    }
    walk = std::move(*read);
  }
  size_t triangles = 0;
  for (const auto& f : walk.frames) triangles += f.indices.size() / 3;
  if (!r.SetStaticMesh(mesh).ok() || !r.SetAvatarSequence(walk).ok()) return 1;
  std::vector<std::vector<uint8_t>> images;
  std::vector<viewer::Projector> projectors;
  for (int k = 0; k < o.cameras && k < static_cast<int>(world.cameras.size()); ++k) {
    const scene::CameraSpec& c = world.cameras[k];
    images.push_back(Gradient(c.intrinsics.width, c.intrinsics.height));
  }
  for (int k = 0; k < static_cast<int>(images.size()); ++k) projectors.push_back(MakeProjector(world.cameras[k], images[k]));
  if (!r.SetProjectors(projectors).ok()) return 1;
  // The walk area: where the first camera's optical axis meets the ground plane (z = terrain).
  const scene::CameraSpec& first = world.cameras.front();
  const Eigen::Vector3d axis = first.world_from_camera.rotation * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d eye0 = first.world_from_camera.translation;
  const double t_hit = axis.z() < -1e-3 ? -(eye0.z() - world.TerrainHeight(eye0.x(), eye0.y())) / axis.z() : 20.0;
  Eigen::Vector3d centre = eye0 + t_hit * axis;
  centre.z() = world.TerrainHeight(centre.x(), centre.y());
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(o.width, o.height, 60);
  const Rigid3d pose = LookAt(centre + Eigen::Vector3d(-22, -26, 18), centre);
  viewer::View view;
  view.viewport = {0, 0, o.width, o.height};
  view.view = GlViewFromWorld(pose);
  view.projection = GlProjection(k, 0.5, 1000);
  view.draw_frustums = false;
  std::printf("renderer: %s\n%dx%d, campus %zu triangles, %zu cameras projecting; avatar '%s': %zu frames, %zu "
              "triangles in all (%.0f per frame)\n",
              (*context)->Description().c_str(), o.width, o.height, mesh.indices.size() / 3, projectors.size(),
              walk.name.c_str(), walk.frames.size(), triangles, static_cast<double>(triangles) / walk.frames.size());
  std::printf("%8s  %22s  %22s\n", "people", "avatars ms/frame", "cylinders ms/frame");
  std::printf("%8s  %10s %11s  %10s %11s\n", "", "wall", "cpu", "wall", "cpu");
  auto time_frames = [&](const std::vector<Walker>& people, bool avatars) {
    Timing t;
    for (int f = -3; f < o.frames; ++f) {  // 3 frames of warm-up
      if (f == 0) {
        t = {};
        t.cpu_ms = -1000 * ProcessCpuSeconds();
        t.wall_ms = -1000 * std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
      }
      const double time_s = 0.1 * (f + 3);
      std::vector<viewer::AvatarInstance> instances;
      std::vector<viewer::DynamicModel> models;
      for (const Walker& w : people) {
        Eigen::Vector3d base;
        double heading, phase;
        Pose(world, w, time_s, walk.stride_m, &base, &heading, &phase);
        if (avatars) {
          instances.push_back({walk.name, base, heading, phase});
        } else {
          viewer::DynamicModel m;
          m.base = base;
          m.heading_rad = heading;
          m.size = Eigen::Vector3d(0.5, 0.5, 1.75);
          m.shape = viewer::ModelShape::kCylinder;
          models.push_back(m);
        }
      }
      if (!r.SetAvatars(instances).ok() || !r.SetDynamicModels(models).ok()) std::exit(1);
      (*context)->BindFramebuffer();
      if (absl::Status s = r.Render({view}, o.width, o.height); !s.ok()) {
        std::cerr << "ave-bench avatars: " << s.message() << "\n";
        std::exit(1);
      }
      (void)(*context)->ReadPixels();  // waits for the frame
    }
    t.cpu_ms = (t.cpu_ms + 1000 * ProcessCpuSeconds()) / o.frames;
    t.wall_ms = (t.wall_ms + 1000 * std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count()) /
                o.frames;
    return t;
  };
  std::vector<Timing> with_avatars, with_cylinders;
  for (int n : counts) {
    const std::vector<Walker> people = MakeWalkers(world, centre, n);
    with_avatars.push_back(time_frames(people, true));
    if (n == *std::max_element(counts.begin(), counts.end()) && !o.png.empty()) {
      auto pixels = (*context)->ReadPixels();
      if (pixels.ok()) {
        WritePng(o.png, *pixels, o.width, o.height);
      }
    }
    with_cylinders.push_back(o.cylinders ? time_frames(people, false) : Timing{std::nan(""), std::nan("")});
    const Timing& a = with_avatars.back();
    const Timing& c = with_cylinders.back();
    std::printf("%8d  %10.2f %11.2f  %10.2f %11.2f\n", n, a.wall_ms, a.cpu_ms, c.wall_ms, c.cpu_ms);
    std::fflush(stdout);
  }
  // A close picture to check headings: the people's own textures (video off people, as the
  // privacy export draws them) and a trail 1.5 m behind each along its travel: the green nose
  // must point away from the trail.
  if (!o.png.empty()) {
    viewer::DisplayOptions display = r.options().display;
    display.video_on_people = false;
    std::vector<viewer::AvatarInstance> instances;
    std::vector<viewer::Polyline> trails;
    for (const Walker& w : MakeWalkers(world, centre, *std::max_element(counts.begin(), counts.end()))) {
      Eigen::Vector3d base, behind;
      double heading, phase, unused_heading, unused_phase;
      Pose(world, w, 2.0, walk.stride_m, &base, &heading, &phase);
      Pose(world, w, 2.0 - 1.5 / 1.3, walk.stride_m, &behind, &unused_heading, &unused_phase);
      instances.push_back({walk.name, base, heading, phase});
      trails.push_back({{behind + Eigen::Vector3d(0, 0, 0.05), base + Eigen::Vector3d(0, 0, 0.05)}, {1.0f, 1.0f, 0.0f}});
    }
    viewer::View close = view;
    close.view = GlViewFromWorld(LookAt(centre + Eigen::Vector3d(-6, -9, 7), centre + Eigen::Vector3d(0, 1, 0)));
    if (r.SetDisplayOptions(display).ok() && r.SetAvatars(instances).ok() && r.SetDynamicModels({}).ok() &&
        r.SetPaths(trails).ok()) {
      (*context)->BindFramebuffer();
      if (r.Render({close}, o.width, o.height).ok()) {
        auto pixels = (*context)->ReadPixels();
        const std::string path = o.png.substr(0, o.png.rfind('.')) + "_close.png";
        if (pixels.ok()) WritePng(path, *pixels, o.width, o.height);
      }
    }
  }
  auto at = [&](int n, const std::vector<Timing>& t, bool cpu = false) {
    for (size_t i = 0; i < counts.size(); ++i)
      if (counts[i] == n) return cpu ? t[i].cpu_ms : t[i].wall_ms;
    return std::nan("");
  };
  const double per_100 = at(100, with_avatars) - at(0, with_avatars);
  const double per_100_cylinders = at(100, with_cylinders) - at(0, with_cylinders);
  const double cpu_per_100 = at(100, with_avatars, true) - at(0, with_avatars, true);
  if (out) {
    out->ms_0 = at(0, with_avatars);
    out->ms_100 = at(100, with_avatars);
    out->cpu_ms_0 = at(0, with_avatars, true);
    out->cpu_ms_100 = at(100, with_avatars, true);
    out->sequence = walk.name;
    return 0;
  }
  std::printf("100 avatars cost %.2f ms per frame more than none (target <= 5 ms); 100 cylinders %.2f ms%s%s\n",
              per_100, per_100_cylinders, o.png.empty() ? "" : "; wrote ", o.png.c_str());
  std::printf("{\"bench\":\"avatars\",\"width\":%d,\"height\":%d,\"frames\":%d", o.width, o.height, o.frames);
  for (size_t i = 0; i < counts.size(); ++i) {
    std::printf(",\"ms_%d_avatars\":%s,\"ms_%d_cylinders\":%s", counts[i], JsonNumber(with_avatars[i].wall_ms).c_str(),
                counts[i], JsonNumber(with_cylinders[i].wall_ms).c_str());
  }
  // null where --counts lacks 0 or 100.
  std::printf(",\"viewer_ms_per_100_avatars\":%s,\"viewer_ms_per_100_cylinders\":%s,\"viewer_cpu_ms_per_100_avatars\":%s}\n",
              JsonNumber(per_100).c_str(), JsonNumber(per_100_cylinders).c_str(), JsonNumber(cpu_per_100).c_str());
  return 0;
}

}  // namespace

ViewerAvatarCost MeasureViewerAvatarCost(int frames) {
  AvatarBenchOptions o;
  o.frames = frames;
  o.counts = "0,100";
  o.png.clear();
  o.cylinders = false;
  ViewerAvatarCost cost;
  if (Run(o, &cost) != 0 && cost.error.empty()) cost.error = "ave-bench avatars failed";
  return cost;
}

Runner AddAvatarBench(CLI::App& sub) {
  auto o = std::make_shared<AvatarBenchOptions>();
  sub.add_option("--width", o->width, "framebuffer width")->capture_default_str()->check(CLI::Range(64, 8192));
  sub.add_option("--height", o->height, "framebuffer height")->capture_default_str()->check(CLI::Range(64, 8192));
  sub.add_option("--frames", o->frames, "timed frames per row")->capture_default_str()->check(CLI::Range(1, 100000));
  sub.add_option("--counts", o->counts, "numbers of people, comma separated")->capture_default_str();
  sub.add_option("--cameras", o->cameras, "campus cameras projecting video")->capture_default_str()->check(CLI::Range(0, 64));
  sub.add_option("--png", o->png, "picture of the largest count (empty: none)")->capture_default_str()->check(ave::cli::WritableFile());
  sub.add_option("--avseq", o->avseq, "draw this avatar sequence (ave-studio's walk.avseq) instead of the procedural walker")
      ->check(CLI::ExistingFile);
  sub.add_flag("!--no-model-shadows", o->model_shadows, "people cast no shadows in the projectors' shadow maps");
  sub.add_flag("!--no-view-cache", o->view_cache, "draw every frame exactly (RendererOptions::view_cache off)");
  // Not pinned to one core: llvmpipe's threads are the software GPU (as ave-bench render).
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
