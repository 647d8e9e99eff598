// ave-bench sim: generates `seconds` of video of one scenario camera at `fps` on one core through
// the simulator's camera pipeline with every camera effect the scenario names (applied to this
// camera), and prints the time of each stage (render, and each effect on its own) against real
// time, next to a peer measured in the same run on the same frames:
//   camera_noise       vs cv::randn + cv::add        (OpenCV's Gaussian noise)
//   illumination       vs cv::Mat::convertTo(gain)   (OpenCV's per-pixel scale)
//   jpeg_artefacts     vs cv::imencode alone         (what the agent's streamer pays anyway)
//   rolling_occlusion  vs cv::rectangle fill of the same width
//   waving_vegetation  (renderer side: swaying the crowns, timed inside the render) vs the render
#include <sched.h>
#include <time.h>

#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/bench/bench.h"

namespace ave::bench {

void UseOneCore() {
  cv::setNumThreads(1);
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (sched_getaffinity(0, sizeof(allowed), &allowed) != 0) return;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &allowed)) {
      cpu_set_t one;
      CPU_ZERO(&one);
      CPU_SET(cpu, &one);
      sched_setaffinity(0, sizeof(one), &one);
      return;
    }
  }
}

namespace {

struct SimOptions {
  std::string scenario = "campus";
  std::string camera = "cam1";
  double seconds = 10;
  double fps = 15;
  bool reuse_static_layer = true;  // RendererOptions::reuse_static_layer (issue 19)
};

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double Seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

int RunSim(const SimOptions& o) {
  UseOneCore();
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench: " << scenario.status().message() << "\n";
    return 1;
  }
  const scene::CameraSpec* camera = scenario->world.FindCamera(o.camera);
  if (!camera) {
    std::cerr << "ave-bench: " << scenario->label << ": no camera '" << o.camera << "'\n";
    return 1;
  }
  // Every camera effect the scenario names, on this camera (per-camera limits ignored here).
  sim::EffectSet effects;
  for (sim::EffectKind k : {sim::EffectKind::kCameraNoise, sim::EffectKind::kIllumination, sim::EffectKind::kJpegArtefacts,
                            sim::EffectKind::kRollingOcclusion, sim::EffectKind::kWavingVegetation}) {
    if (const sim::EffectParams* p = scenario->effects.Find(k)) {
      effects.Enable(k, *p);
    }
  }
  const int frames = std::max(1, static_cast<int>(std::lround(o.seconds * o.fps)));
  sim::RendererOptions renderer_options;
  renderer_options.reuse_static_layer = o.reuse_static_layer;
  const sim::SimulatedCamera pipeline(scenario->world, *camera, effects, scenario->seed, renderer_options);
  double frame_cpu_s = 0;  // thread CPU time of Frame() (the wall-time stages below suffer from a loaded machine)

  std::map<std::string, double> stage;  // seconds summed over frames
  std::vector<std::string> order;
  std::map<std::string, double> peer;
  sim::ResetEvaluations();
  const auto start = std::chrono::steady_clock::now();
  for (int f = 0; f < frames; ++f) {
    const double t_s = f / o.fps;
    const double cpu_start = ThreadCpuSeconds();
    sim::SimImage image = pipeline.Frame(f, t_s);
    frame_cpu_s += ThreadCpuSeconds() - cpu_start;
    for (const auto& st : pipeline.last_timings()) {
      if (!stage.count(st.stage)) order.push_back(st.stage);
      stage[st.stage] += st.seconds;
    }
    // Peers on the same (final) frame.
    cv::Mat bgr(image.height, image.width, CV_8UC3, image.bgr.data());
    if (const auto* p = effects.Find(sim::EffectKind::kCameraNoise)) {
      const auto a = std::chrono::steady_clock::now();
      cv::Mat noise(bgr.size(), CV_16SC3), out;
      cv::randn(noise, 0, p->Get("sigma", 2.0));
      cv::add(bgr, noise, out, cv::noArray(), CV_8UC3);
      peer["camera_noise"] += Seconds(a, std::chrono::steady_clock::now());
    }
    if (const auto* p = effects.Find(sim::EffectKind::kIllumination)) {
      const auto a = std::chrono::steady_clock::now();
      cv::Mat out;
      bgr.convertTo(out, CV_8UC3, sim::IlluminationGain(*p, scenario->seed, t_s));
      peer["illumination"] += Seconds(a, std::chrono::steady_clock::now());
    }
    if (const auto* p = effects.Find(sim::EffectKind::kJpegArtefacts)) {
      const auto a = std::chrono::steady_clock::now();
      std::vector<uint8_t> jpeg;
      cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, static_cast<int>(p->Get("quality", 70))});
      peer["jpeg_artefacts"] += Seconds(a, std::chrono::steady_clock::now());
    }
    if (const auto* p = effects.Find(sim::EffectKind::kRollingOcclusion)) {
      const auto a = std::chrono::steady_clock::now();
      cv::Mat copy = bgr.clone();
      const int w = static_cast<int>(p->Get("width_frac", 0.2) * image.width);
      cv::rectangle(copy, cv::Rect(image.width / 2 - w / 2, 0, w, image.height), cv::Scalar(40, 40, 45), cv::FILLED);
      peer["rolling_occlusion"] += Seconds(a, std::chrono::steady_clock::now());
    }
  }
  const double total = Seconds(start, std::chrono::steady_clock::now());
  const double peer_total = [&] {
    double s = 0;
    for (const auto& [k, v] : peer) s += v;
    return s;
  }();
  const double pipeline_total = total - peer_total;

  const double video_s = frames / o.fps;
  std::printf("ave-bench sim: scenario %s, camera %s (%dx%d), %d frames = %.2f s of video at %.1f fps, one core\n",
              scenario->name.c_str(), o.camera.c_str(), camera->intrinsics.width, camera->intrinsics.height, frames, video_s, o.fps);
  std::printf("%-20s %12s %12s %14s   %s\n", "stage", "ms/frame", "total s", "x real time", "peer (same frames)");
  auto row = [&](const std::string& name, double seconds, const std::string& peer_text) {
    std::printf("%-20s %12.2f %12.3f %14.4f   %s\n", name.c_str(), 1e3 * seconds / frames, seconds, seconds / video_s, peer_text.c_str());
  };
  for (const std::string& name : order) {
    std::string peer_text;
    if (peer.count(name)) {
      char buf[128];
      std::snprintf(buf, sizeof(buf), "%.2f ms/frame (%s)", 1e3 * peer[name] / frames,
                    name == "camera_noise" ? "cv::randn+add" : name == "illumination" ? "convertTo" : name == "jpeg_artefacts" ? "imencode only" : "cv::rectangle");
      peer_text = buf;
    }
    if (name == "waving_vegetation") peer_text = "inside the render; compare with render";
    row(name, stage[name], peer_text);
  }
  row("pipeline total", pipeline_total, "");
  std::printf("pipeline thread CPU: %.2f ms/frame (static layer reuse %s)\n", 1e3 * frame_cpu_s / frames, o.reuse_static_layer ? "on" : "off");
  const bool faster = pipeline_total < video_s;
  std::printf("pipeline: %.3f s for %.2f s of video: %.2fx real time (%s)\n", pipeline_total, video_s, pipeline_total / video_s,
              faster ? "faster than real time" : "SLOWER than real time");
  // One-line JSON summary.
  std::printf("{\"bench\":\"sim\",\"scenario\":\"%s\",\"camera\":\"%s\",\"frames\":%d,\"video_s\":%.3f,\"pipeline_s\":%.4f,\"real_time_ratio\":%.4f",
              scenario->name.c_str(), o.camera.c_str(), frames, video_s, pipeline_total, pipeline_total / video_s);
  for (const std::string& name : order) std::printf(",\"%s_ms\":%.3f", name.c_str(), 1e3 * stage[name] / frames);
  for (const auto& [name, v] : peer) std::printf(",\"peer_%s_ms\":%.3f", name.c_str(), 1e3 * v / frames);
  std::printf(",\"frame_cpu_ms\":%.3f,\"reuse_static_layer\":%s", 1e3 * frame_cpu_s / frames, o.reuse_static_layer ? "true" : "false");
  std::printf(",\"faster_than_real_time\":%s}\n", faster ? "true" : "false");
  return 0;
}

}  // namespace

Runner AddSimBench(CLI::App& sub) {
  auto options = std::make_shared<SimOptions>();
  sub.add_option("--scenario", options->scenario, "bundled scenario or .yaml path")->capture_default_str();
  sub.add_option("--camera", options->camera, "camera id")->capture_default_str();
  sub.add_option("--seconds", options->seconds, "seconds of video")->capture_default_str()->check(ave::cli::Range(0.01, 3600.0));
  sub.add_option("--fps", options->fps, "frames per second")->capture_default_str()->check(ave::cli::Range(0.1, 240.0));
  sub.add_option("--reuse-static-layer", options->reuse_static_layer,
                 "a fixed camera keeps the static scene's raster and shading between frames (issue 19)")
      ->capture_default_str();
  return [options] { return RunSim(*options); };
}

}  // namespace ave::bench
