// ave-bench select (issue 7 item 5): data selection. A real FusionServer on loopback with N
// cameras (default 50) streaming JPEGs, and three viewers subscribed at once: one asking for
// everything (no view frusta, the peer), one looking at a single block (its browse view only), and
// one with the viewer's quad (the block view plus three views locked to cameras that see it).
// Reports per viewer the streams received of those registered, frames/s and kB/s, the cameras
// that ray-cast truth says see the views (selection must include them; the surplus is the
// conservative test's cost), and the server's cost per update with and without the frustum test.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fusion_server/core/scene_state.h"
#include "tests/bench/bench.h"
#include "tests/select_site.h"
#include "viewer_client/client/scene_client.h"

namespace ave::bench {
namespace {

struct Options {
  int cameras = 50;
  double fps = 5;
  double seconds = 6;
  double block_x = -60, block_y = -55;
  std::string plot = "select_bench.png";
};

struct Row {
  std::string name;
  size_t views = 0;
  size_t truth = 0;  // cameras that see a surface point of the views (ray cast)
  size_t streams = 0;
  double frames_per_s = 0, kbytes_per_s = 0;
};

// Microseconds per SceneState::BuildUpdate for `cameras` cameras with a frame each, with the given
// selection views (empty: no selection).
double BuildUpdateMicros(const std::vector<select_site::GridCamera>& cameras, const std::vector<ConvexVolume>& views,
                         double floor_z) {
  SceneState state;
  for (const auto& cam : cameras) {
    state.UpsertCamera({.id = cam.id, .name = cam.id, .intrinsics = cam.intrinsics, .mounting_pose = cam.world_from_camera});
  }
  const int rounds = 400;
  ViewerCursor cursor;
  cursor.views = views;
  cursor.selection_floor_z = floor_z;
  const auto t0 = std::chrono::steady_clock::now();
  for (int r = 0; r < rounds; ++r) {
    for (const auto& cam : cameras) {
      auto f = std::make_shared<v1::SensorFrame>();
      f->set_sequence(r + 1);
      f->set_jpeg("x");
      (void)state.AcceptFrame(cam.id, f, r);
    }
    (void)state.BuildUpdate({}, true, r, cursor);
  }
  return std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count() / rounds;
}

void Plot(const std::vector<Row>& rows, int cameras, const std::string& path) {
  cv::Mat image(420, 760, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar colors[] = {{90, 90, 90}, {60, 140, 230}, {40, 170, 70}};
  auto panel = [&](int x0, const std::string& title, auto value, double max, const std::string& unit) {
    const cv::Rect plot(x0 + 50, 65, 290, 285);
    cv::putText(image, title, {x0 + 50, 30}, cv::FONT_HERSHEY_SIMPLEX, 0.55, {0, 0, 0}, 1, cv::LINE_AA);
    cv::rectangle(image, plot, {0, 0, 0}, 1);
    for (int k = 0; k <= 4; ++k) {
      const int y = plot.y + plot.height - k * plot.height / 4;
      cv::line(image, {plot.x, y}, {plot.x + plot.width, y}, {225, 225, 225}, 1);
      char label[32];
      std::snprintf(label, sizeof label, "%.0f", max * k / 4);
      cv::putText(image, label, {x0 + 5, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0}, 1, cv::LINE_AA);
    }
    const int bar_w = plot.width / int(rows.size()) - 20;
    for (size_t i = 0; i < rows.size(); ++i) {
      const double v = value(rows[i]);
      const int h = static_cast<int>(std::min(1.0, v / max) * plot.height);
      const int x = plot.x + 10 + int(i) * (bar_w + 20);
      cv::rectangle(image, cv::Rect(x, plot.y + plot.height - h, bar_w, h), colors[i % 3], cv::FILLED);
      char label[32];
      std::snprintf(label, sizeof label, "%.0f%s", v, unit.c_str());
      cv::putText(image, label, {x + 4, plot.y + plot.height - h - 6}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1, cv::LINE_AA);
      cv::putText(image, rows[i].name, {x + 2, plot.y + plot.height + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1, cv::LINE_AA);
    }
  };
  double max_kb = 1;
  for (const Row& r : rows) max_kb = std::max(max_kb, r.kbytes_per_s);
  panel(0, "streams received of " + std::to_string(cameras) + " registered", [](const Row& r) { return double(r.streams); },
        double(cameras), "");
  panel(380, "JPEG kB/s received", [](const Row& r) { return r.kbytes_per_s; }, 1.1 * max_kb, "");
  cv::putText(image, "ave-bench select: one viewer each, all subscribed at once", {50, 400}, cv::FONT_HERSHEY_SIMPLEX, 0.45,
              {80, 80, 80}, 1, cv::LINE_AA);
  cv::imwrite(path, image);
}

int Run(const Options& o) {
  auto site = select_site::Site::Start("ave_select_bench", o.cameras);
  if (!site.ok()) {
    std::cerr << "ave-bench select: " << site.status().message() << "\n";
    return 1;
  }
  viewer::SceneClient all((*site)->channel(), select_site::kViewer, "all");
  absl::StatusOr<TriangleMesh> mesh = all.FetchStaticModel();
  if (!mesh.ok()) {
    std::cerr << "ave-bench select: " << mesh.status().message() << "\n";
    return 1;
  }
  const MeshBvh bvh(*mesh);
  const auto& cams = (*site)->cameras();
  const viewer::View block = select_site::BlockView((*site)->campus(), o.block_x, o.block_y);
  const std::set<std::string> truth_block = select_site::CamerasSeenInView(bvh, cams, block, 600);
  // The quad: the block view plus three views locked to cameras that see the block.
  std::vector<viewer::View> quad = {block};
  for (const auto& cam : cams) {
    if (quad.size() == 4) break;
    if (!truth_block.count(cam.id)) continue;
    viewer::Projector p;
    p.camera_id = cam.id;
    p.view = GlViewFromWorld(cam.world_from_camera);
    p.projection = GlProjection(cam.intrinsics, 0.5, 600);
    quad.push_back(viewer::ViewLockedToProjector(p, {0, 0, 640, 360}));
  }
  std::set<std::string> truth_quad;
  for (const auto& v : quad)
    for (const auto& id : select_site::CamerasSeenInView(bvh, cams, v, 600)) truth_quad.insert(id);

  viewer::SceneClient one_block((*site)->channel(), select_site::kViewer, "block");
  viewer::SceneClient quad_client((*site)->channel(), select_site::kViewer, "quad");
  one_block.SetViews(viewer::SelectionOf({block}));
  quad_client.SetViews(viewer::SelectionOf(quad));
  (*site)->StartStreaming(o.fps);
  for (auto* c : {&all, &one_block, &quad_client}) c->Start({});
  std::this_thread::sleep_for(std::chrono::seconds(1));  // warm up: every stream open, first frames out
  auto counts = [](viewer::SceneClient& c) {
    std::map<std::string, uint64_t> m;
    for (const auto& cam : c.Snapshot()) m[cam.id] = cam.jpegs_received;
    return m;
  };
  std::vector<viewer::SceneClient*> clients = {&all, &one_block, &quad_client};
  std::vector<std::map<std::string, uint64_t>> before;
  std::vector<uint64_t> bytes_before;
  for (auto* c : clients) {
    before.push_back(counts(*c));
    bytes_before.push_back(c->jpeg_bytes_received());
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(int64_t(o.seconds * 1000)));
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<Row> rows = {{.name = "all (peer)", .views = 0, .truth = size_t(o.cameras)},
                           {.name = "one block", .views = 1, .truth = truth_block.size()},
                           {.name = "quad", .views = quad.size(), .truth = truth_quad.size()}};
  for (size_t i = 0; i < clients.size(); ++i) {
    uint64_t frames = 0;
    for (const auto& [id, n] : counts(*clients[i])) {
      frames += n - before[i][id];
      rows[i].streams += n > before[i][id];
    }
    rows[i].frames_per_s = frames / elapsed;
    rows[i].kbytes_per_s = (clients[i]->jpeg_bytes_received() - bytes_before[i]) / elapsed / 1e3;
  }
  for (auto* c : clients) c->Stop();
  (*site)->StopStreaming();

  // Server cost: BuildUpdate for all cameras, without views and with the quad's four.
  const double floor_z = [&] {
    double z = 1e300;
    for (const auto& p : mesh->positions) z = std::min<double>(z, p.z());
    return z - 0.01;
  }();
  std::vector<ConvexVolume> volumes;
  for (const auto& v : quad) volumes.push_back(*FrustumFromClip(v.projection * v.view, kDefaultSelectionDepthM, floor_z));
  const double us_plain = BuildUpdateMicros(cams, {}, floor_z);
  const double us_select = BuildUpdateMicros(cams, volumes, floor_z);

  std::printf("ave-bench select: %d cameras at %.1f fps (%dx%d JPEG), %.1f s measured\n", o.cameras, o.fps,
              cams[0].intrinsics.width, cams[0].intrinsics.height, elapsed);
  std::printf("| viewer | view frusta | cameras that see the views (ray cast) | streams received / registered | frames/s | JPEG kB/s |\n");
  std::printf("| --- | --- | --- | --- | --- | --- |\n");
  for (const Row& r : rows) {
    std::printf("| %s | %zu | %zu | %zu / %d | %.1f | %.0f |\n", r.name.c_str(), r.views, r.truth, r.streams, o.cameras,
                r.frames_per_s, r.kbytes_per_s);
  }
  std::printf("server BuildUpdate, %d cameras: %.1f us without selection, %.1f us with 4 view frusta (x%.2f)\n",
              o.cameras, us_plain, us_select, us_select / us_plain);
  Plot(rows, o.cameras, o.plot);
  std::printf("plot: %s\n", o.plot.c_str());
  site->reset();
  return 0;
}

}  // namespace

Runner AddSelectBench(CLI::App& sub) {
  auto o = std::make_shared<Options>();
  sub.add_option("--cameras", o->cameras, "cameras registered and streaming")->capture_default_str()->check(ave::cli::Range(4, 400));
  sub.add_option("--fps", o->fps, "frames per second per camera")->capture_default_str()->check(ave::cli::Range(0.5, 60.0));
  sub.add_option("--seconds", o->seconds, "measured time")->capture_default_str()->check(ave::cli::Range(1.0, 600.0));
  sub.add_option("--block-x", o->block_x, "the block looked at, x (m, site frame)")->capture_default_str();
  sub.add_option("--block-y", o->block_y, "the block looked at, y (m)")->capture_default_str();
  sub.add_option("--plot", o->plot, "PNG bar chart")->capture_default_str()->check(ave::cli::WritableFile());
  return [o] { return Run(*o); };
}

}  // namespace ave::bench
