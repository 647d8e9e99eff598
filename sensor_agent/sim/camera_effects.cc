#include "sensor_agent/sim/camera_effects.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace ave::sim {
namespace {

uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// xorshift64*: small, fast and the same on every platform (std:: distributions are not).
struct Rng {
  uint64_t state;
  explicit Rng(uint64_t seed) : state(SplitMix64(seed) | 1) {}
  uint64_t Next() {
    state ^= state >> 12;
    state ^= state << 25;
    state ^= state >> 27;
    return state * 0x2545f4914f6cdd1dull;
  }
  double Uniform() { return static_cast<double>(Next() >> 11) * (1.0 / 9007199254740992.0); }
};

// Inverse of the standard normal CDF (Acklam's rational approximation, |error| < 1.2e-9).
double NormalQuantile(double p) {
  static constexpr double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                                 1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static constexpr double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                                 6.680131188771972e+01,  -1.328068155288572e+01};
  static constexpr double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                                 -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static constexpr double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00};
  if (p < 0.02425) {
    const double q = std::sqrt(-2 * std::log(p));
    return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  }
  if (p > 1 - 0.02425) return -NormalQuantile(1 - p);
  const double q = p - 0.5, r = q * q;
  return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
         (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
}

// 4096 equiprobable standard-normal quantiles: indexing with 12 random bits draws N(0, 1)
// (discretised; the tails stop at +-3.6 sigma).
const std::array<double, 4096>& GaussianTable() {
  static const std::array<double, 4096> table = [] {
    std::array<double, 4096> t{};
    for (size_t i = 0; i < t.size(); ++i) t[i] = NormalQuantile((i + 0.5) / t.size());
    return t;
  }();
  return table;
}

double SmoothStep(double x) { return x * x * (3 - 2 * x); }

// Seeded value noise in time: knots every `spacing_s` with values in [-1, 1], C1 between.
double TimeNoise(uint64_t seed, double t_s, double spacing_s) {
  if (!std::isfinite(t_s)) t_s = 0;
  const double k = std::floor(t_s / spacing_s);
  const double f = t_s / spacing_s - k;
  auto knot = [&](double index) {
    return 2.0 * (static_cast<double>(SplitMix64(seed ^ static_cast<uint64_t>(static_cast<int64_t>(index))) >> 11) /
                  9007199254740992.0) - 1.0;
  };
  const double a = knot(k), b = knot(k + 1);
  return a + (b - a) * SmoothStep(f);
}

}  // namespace

uint64_t FrameSeed(uint64_t seed, int64_t frame_index) { return SplitMix64(seed ^ SplitMix64(static_cast<uint64_t>(frame_index))); }

void ApplyCameraNoise(const EffectParams& params, uint64_t frame_seed, SimImage& image) {
  CountEvaluation(EffectKind::kCameraNoise);
  const double sigma = std::clamp(params.Get("sigma", 2.0), 0.0, 100.0);
  std::array<int16_t, 4096> offsets;
  const auto& table = GaussianTable();
  for (size_t i = 0; i < offsets.size(); ++i) offsets[i] = static_cast<int16_t>(std::lround(sigma * table[i]));
  Rng rng(frame_seed ^ 0x6e6f697365ull);
  uint8_t* px = image.bgr.data();
  const size_t n = image.bgr.size();
  size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const uint64_t r = rng.Next();
    for (int k = 0; k < 4; ++k) {
      const int v = px[i + k] + offsets[(r >> (16 * k)) & 4095];
      px[i + k] = static_cast<uint8_t>(std::clamp(v, 0, 255));
    }
  }
  const uint64_t r = rng.Next();
  for (int k = 0; i < n; ++i, ++k) px[i] = static_cast<uint8_t>(std::clamp(px[i] + offsets[(r >> (16 * k)) & 4095], 0, 255));
}

double IlluminationGain(const EffectParams& params, uint64_t seed, double t_s) {
  const double amplitude = std::clamp(params.Get("amplitude", 0.15), 0.0, 0.9);
  const double period_s = std::max(params.Get("period_s", 20.0), 0.1);
  // Half a period between knots: clouds come and go about once per period.
  return 1.0 + amplitude * TimeNoise(seed ^ 0x636c6f756473ull, t_s, 0.5 * period_s);
}

void ApplyIllumination(const EffectParams& params, uint64_t seed, double t_s, SimImage& image) {
  CountEvaluation(EffectKind::kIllumination);
  const double gain = IlluminationGain(params, seed, t_s);
  std::array<uint8_t, 256> lut;
  for (int v = 0; v < 256; ++v) lut[v] = static_cast<uint8_t>(std::clamp(std::lround(v * gain), 0L, 255L));
  for (uint8_t& v : image.bgr) v = lut[v];
}

void ApplyJpegArtefacts(const EffectParams& params, SimImage& image) {
  CountEvaluation(EffectKind::kJpegArtefacts);
  if (image.width == 0) return;
  const int quality = static_cast<int>(std::clamp(params.Get("quality", 70.0), 1.0, 100.0));
  const cv::Mat bgr(image.height, image.width, CV_8UC3, image.bgr.data());
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality});
  const cv::Mat decoded = cv::imdecode(jpeg, cv::IMREAD_COLOR);
  if (decoded.size() == bgr.size() && decoded.type() == CV_8UC3 && decoded.isContinuous()) {
    std::copy(decoded.data, decoded.data + image.bgr.size(), image.bgr.begin());
    image.jpeg = std::move(jpeg);  // the camera's own bytes (pre-rendered footage keeps them)
  }
}

void ApplyRollingOcclusion(const EffectParams& params, uint64_t seed, double t_s, SimImage& image) {
  CountEvaluation(EffectKind::kRollingOcclusion);
  const double period_s = std::max(params.Get("period_s", 30.0), 0.1);
  const double duration_s = std::clamp(params.Get("duration_s", 3.0), 0.01, period_s);
  const double width_frac = std::clamp(params.Get("width_frac", 0.2), 0.01, 1.0);
  const double start_s = params.Get("start_s", 0.0);
  if (!std::isfinite(t_s) || image.width == 0) return;
  double tau = std::fmod(t_s - start_s, period_s);
  if (tau < 0) tau += period_s;
  if (tau >= duration_s) return;
  // A passer-by close to the lens: a dark band with rounded shoulders, crossing left to right.
  const double w = width_frac * image.width;
  const double centre = -0.5 * w + (tau / duration_s) * (image.width + w);
  const uint8_t tone = static_cast<uint8_t>(30 + (SplitMix64(seed + static_cast<uint64_t>(std::floor((t_s - start_s) / period_s))) & 31));
  for (int v = 0; v < image.height; ++v) {
    const double y = static_cast<double>(v) / image.height;
    const double half = y < 0.15 ? 0.25 * w : (y < 0.3 ? 0.5 * w * std::sqrt((y - 0.15) / 0.15 * 0.75 + 0.25) : 0.5 * w);
    const int u0 = std::max(0, static_cast<int>(std::ceil(centre - half))), u1 = std::min(image.width - 1, static_cast<int>(std::floor(centre + half)));
    for (int u = u0; u <= u1; ++u) {
      const size_t i = image.Index(u, v);
      const uint8_t shade = static_cast<uint8_t>(tone + (y < 0.15 ? 40 : 0) + static_cast<int>(10 * std::abs(u - centre) / std::max(half, 1.0)));
      image.bgr[3 * i] = shade;
      image.bgr[3 * i + 1] = shade;
      image.bgr[3 * i + 2] = static_cast<uint8_t>(std::min(255, shade + 8));
      image.object_id[i] = kOccluderId;
      if (!image.class_id.empty()) image.class_id[i] = static_cast<uint8_t>(PixelClass::kOccluder);
      image.depth_m[i] = 0.6f;
    }
  }
}

void SwayVegetation(const EffectParams& params, double t_s, const std::vector<Eigen::Vector3f>& rest,
                    const std::vector<SwayingCrown>& crowns, std::vector<Eigen::Vector3f>& positions) {
  CountEvaluation(EffectKind::kWavingVegetation);
  const double amplitude_m = std::clamp(params.Get("amplitude_m", 0.3), 0.0, 10.0);
  const double frequency_hz = std::clamp(params.Get("frequency_hz", 0.4), 0.0, 20.0);
  const double wind = params.Get("wind_deg", 30.0) * M_PI / 180;
  if (!std::isfinite(t_s)) t_s = 0;
  const Eigen::Vector3f along(static_cast<float>(std::cos(wind)), static_cast<float>(std::sin(wind)), 0.0f);
  const Eigen::Vector3f across(-along.y(), along.x(), 0.0f);
  // Phase wrapped in double before going to float, so huge times stay accurate.
  const double omega_t = std::fmod(2 * M_PI * frequency_hz * t_s, 2 * M_PI);
  for (const SwayingCrown& crown : crowns) {
    const float main = static_cast<float>(amplitude_m * std::sin(omega_t + crown.phase_rad));
    const float side = static_cast<float>(0.3 * amplitude_m * std::sin(1.7 * omega_t + 1.3 * crown.phase_rad));
    const Eigen::Vector3f offset = main * along + side * across;
    for (size_t i = crown.first_vertex; i < crown.end_vertex && i < rest.size(); ++i) {
      const float w = std::clamp((rest[i].z() - crown.bottom_z) / crown.height_m, 0.0f, 1.0f);
      positions[i] = rest[i] + (w * w) * offset;
    }
  }
}

// ---- The pipeline -----------------------------------------------------------------------------

struct SimulatedCamera::Impl {
  scene::SyntheticCampus campus;
  scene::CameraSpec camera;
  EffectSet effects;
  uint64_t seed = 0;
  std::unique_ptr<CampusRenderer> renderer;
  // Lens distortion: the ideal render is larger (padding) so every distorted pixel has a source;
  // map_x/map_y give the ideal pixel of each output pixel; nearest[i] the nearest ideal index.
  bool distorted = false;
  PinholeIntrinsics render_intrinsics;
  cv::Mat map_x, map_y;
  std::vector<int64_t> nearest;
  std::vector<uint8_t> read;  // per ideal pixel: 1 where the resampling reads it (shade_only_read_pixels)
  // pixel_area: samples per axis (1: off). The render, the lens's resampling and the masks work
  // on `sensor`, the camera's intrinsics `area` times finer, and the last step averages each
  // area x area block down to the camera's pixel: the lens bends the continuous image, and the
  // photosite integrates what lands on it.
  int area = 1;
  PinholeIntrinsics sensor;
  mutable std::vector<StageTime> timings;
};

namespace {

// `k` `s` times finer: fine pixel U's centre lies at coarse (U + 0.5) / s - 0.5, so
// the s x s fine pixels of coarse pixel u tile its area exactly.
PinholeIntrinsics FinerIntrinsics(const PinholeIntrinsics& k, int s) {
  PinholeIntrinsics f = k;
  if (s == 1) return f;
  f.width = k.width * s;
  f.height = k.height * s;
  f.fx = k.fx * s;
  f.fy = k.fy * s;
  f.cx = s * (k.cx + 0.5) - 0.5;
  f.cy = s * (k.cy + 0.5) - 0.5;
  return f;
}

}  // namespace

// The pixel_area effect: each of the width x height pixels is the mean of its s x s fine samples
// (cv::resize INTER_AREA, an exact box average at an integer factor); the truth layers (ids,
// classes, depths) are those of the centre sample (for an even s, the one just below and right of
// the centre, 0.5 / s px off).
SimImage AveragePixelArea(const SimImage& fine, int s, int width, int height) {
  CountEvaluation(EffectKind::kPixelArea);
  SimImage out;
  out.width = width;
  out.height = height;
  const size_t n = static_cast<size_t>(width) * height;
  out.bgr.resize(3 * n);
  const cv::Mat src(fine.height, fine.width, CV_8UC3, const_cast<uint8_t*>(fine.bgr.data()));
  cv::Mat dst(height, width, CV_8UC3, out.bgr.data());
  cv::resize(src, dst, dst.size(), 0, 0, cv::INTER_AREA);
  out.object_id.resize(n);
  out.class_id.resize(n);
  out.depth_m.resize(n);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t i = out.Index(u, v), c = fine.Index(u * s + s / 2, v * s + s / 2);
      out.object_id[i] = fine.object_id[c];
      out.class_id[i] = fine.class_id[c];
      out.depth_m[i] = fine.depth_m[c];
    }
  }
  return out;
}

SimulatedCamera::SimulatedCamera(const scene::SyntheticCampus& campus, const scene::CameraSpec& camera, const EffectSet& effects,
                                 uint64_t seed, RendererOptions renderer_options)
    : impl_(std::make_unique<Impl>()) {
  impl_->campus = campus;
  impl_->camera = camera;
  impl_->effects = effects;
  impl_->seed = seed;
  if (const EffectParams* p = effects.Find(EffectKind::kWavingVegetation)) renderer_options.waving_vegetation = *p;
  impl_->renderer = std::make_unique<CampusRenderer>(campus, renderer_options);
  if (const EffectParams* p = effects.Find(EffectKind::kPixelArea))
    impl_->area = std::clamp(static_cast<int>(std::lround(p->Get("samples", 3))), 1, kMaxPixelAreaSamples);
  impl_->sensor = FinerIntrinsics(camera.intrinsics, impl_->area);
  const PinholeIntrinsics& k = impl_->sensor;
  impl_->render_intrinsics = k;
  bool any = false;
  for (double d : k.distortion) any |= d != 0;
  if (any && k.Check().empty()) {
    impl_->distorted = true;
    // Ideal (undistorted) pixel of every output pixel: invert Brown-Conrady by fixed-point
    // iteration (as cv::undistortPoints does), 20 rounds.
    const auto& dist = k.distortion;  // k1 k2 p1 p2 k3
    std::vector<cv::Point2f> ideal;
    ideal.reserve(static_cast<size_t>(k.width) * k.height);
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const double xd = (u - k.cx) / k.fx, yd = (v - k.cy) / k.fy;
        double x = xd, y = yd;
        for (int it = 0; it < 20; ++it) {
          const double r2 = x * x + y * y;
          const double radial = 1 + r2 * (dist[0] + r2 * (dist[1] + r2 * dist[4]));
          const double dx = 2 * dist[2] * x * y + dist[3] * (r2 + 2 * x * x);
          const double dy = dist[2] * (r2 + 2 * y * y) + 2 * dist[3] * x * y;
          x = (xd - dx) / radial;
          y = (yd - dy) / radial;
        }
        ideal.emplace_back(static_cast<float>(k.fx * x + k.cx), static_cast<float>(k.fy * y + k.cy));
      }
    }
    float min_x = 0, min_y = 0, max_x = static_cast<float>(k.width - 1), max_y = static_cast<float>(k.height - 1);
    for (const auto& p : ideal) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
      min_x = std::min(min_x, p.x);
      min_y = std::min(min_y, p.y);
      max_x = std::max(max_x, p.x);
      max_y = std::max(max_y, p.y);
    }
    const int pad_l = static_cast<int>(std::ceil(-min_x)) + 1, pad_t = static_cast<int>(std::ceil(-min_y)) + 1;
    const int pad_r = static_cast<int>(std::ceil(max_x - (k.width - 1))) + 1, pad_b = static_cast<int>(std::ceil(max_y - (k.height - 1))) + 1;
    PinholeIntrinsics r = k;
    r.width = std::min(k.width + pad_l + pad_r, 4 * k.width);
    r.height = std::min(k.height + pad_t + pad_b, 4 * k.height);
    r.cx += pad_l;
    r.cy += pad_t;
    r.distortion = {};
    impl_->render_intrinsics = r;
    impl_->map_x.create(k.height, k.width, CV_32F);
    impl_->map_y.create(k.height, k.width, CV_32F);
    impl_->nearest.resize(ideal.size());
    for (size_t i = 0; i < ideal.size(); ++i) {
      const float x = ideal[i].x + pad_l, y = ideal[i].y + pad_t;
      impl_->map_x.at<float>(static_cast<int>(i)) = x;
      impl_->map_y.at<float>(static_cast<int>(i)) = y;
      const int u = static_cast<int>(std::lround(x)), v = static_cast<int>(std::lround(y));
      impl_->nearest[i] = (std::isfinite(x) && std::isfinite(y) && u >= 0 && v >= 0 && u < r.width && v < r.height)
                              ? static_cast<int64_t>(v) * r.width + u
                              : -1;
    }
    if (renderer_options.shade_only_read_pixels) {
      // cv::remap (INTER_LINEAR) reads the 2x2 neighbours of each map point after rounding it to
      // 1/32 px: mark floor(x - 1/32) .. floor(x + 1/32) + 1 (and rows alike), clamped as
      // BORDER_REPLICATE clamps; plus the nearest pixel for ids, classes and depths.
      impl_->read.assign(static_cast<size_t>(r.width) * r.height, 0);
      bool all_finite = true;
      for (size_t i = 0; i < ideal.size() && all_finite; ++i) {
        const double x = impl_->map_x.at<float>(static_cast<int>(i)), y = impl_->map_y.at<float>(static_cast<int>(i));
        if (!std::isfinite(x) || !std::isfinite(y)) {
          all_finite = false;
          break;
        }
        const int u0 = std::clamp(static_cast<int>(std::floor(x - 1.0 / 32)), 0, r.width - 1);
        const int u1 = std::clamp(static_cast<int>(std::floor(x + 1.0 / 32)) + 1, 0, r.width - 1);
        const int v0 = std::clamp(static_cast<int>(std::floor(y - 1.0 / 32)), 0, r.height - 1);
        const int v1 = std::clamp(static_cast<int>(std::floor(y + 1.0 / 32)) + 1, 0, r.height - 1);
        for (int v = v0; v <= v1; ++v)
          for (int u = u0; u <= u1; ++u) impl_->read[static_cast<size_t>(v) * r.width + u] = 1;
        if (impl_->nearest[i] >= 0) impl_->read[impl_->nearest[i]] = 1;
      }
      if (!all_finite) impl_->read.clear();  // shade everything
    }
  }
}

SimulatedCamera::SimulatedCamera(SimulatedCamera&&) noexcept = default;
SimulatedCamera& SimulatedCamera::operator=(SimulatedCamera&&) noexcept = default;
SimulatedCamera::~SimulatedCamera() = default;

const scene::CameraSpec& SimulatedCamera::camera() const { return impl_->camera; }
const std::vector<SimulatedCamera::StageTime>& SimulatedCamera::last_timings() const { return impl_->timings; }
Rigid3d SimulatedCamera::PoseAt(double t_s) const { return scene::CameraPoseAt(impl_->campus, impl_->camera, t_s); }

SimImage SimulatedCamera::Frame(int64_t frame_index, double t_s) const {
  const Impl& m = *impl_;
  m.timings.clear();
  auto clock = std::chrono::steady_clock::now();
  auto lap = [&](const char* stage) {
    const auto now = std::chrono::steady_clock::now();
    m.timings.push_back({stage, std::chrono::duration<double>(now - clock).count()});
    clock = now;
  };
  CampusRenderer::Stats stats;
  SimImage image = m.renderer->Render(m.render_intrinsics, PoseAt(t_s), t_s, &stats, m.read.empty() ? nullptr : &m.read);
  lap("render");
  if (m.effects.Has(EffectKind::kWavingVegetation)) {
    // Renderer side: reported apart from the render it happened inside.
    m.timings.back().seconds -= stats.waving_vegetation_s;
    m.timings.push_back({"waving_vegetation", stats.waving_vegetation_s});
  }
  if (image.width == 0) return image;
  const uint64_t frame_seed = FrameSeed(m.seed, frame_index);
  if (m.distorted) {
    const PinholeIntrinsics& k = m.sensor;
    SimImage out;
    out.width = k.width;
    out.height = k.height;
    out.bgr.resize(3 * static_cast<size_t>(k.width) * k.height);
    const cv::Mat src(image.height, image.width, CV_8UC3, image.bgr.data());
    cv::Mat dst(k.height, k.width, CV_8UC3, out.bgr.data());
    cv::remap(src, dst, m.map_x, m.map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const size_t n = m.nearest.size();
    out.object_id.assign(n, kSkyId);
    out.class_id.assign(n, static_cast<uint8_t>(PixelClass::kSky));
    out.depth_m.assign(n, std::numeric_limits<float>::infinity());
    for (size_t i = 0; i < n; ++i) {
      if (m.nearest[i] < 0) continue;
      out.object_id[i] = image.object_id[m.nearest[i]];
      out.class_id[i] = image.class_id[m.nearest[i]];
      out.depth_m[i] = image.depth_m[m.nearest[i]];
    }
    image = std::move(out);
    lap("lens_distortion");
  }
  if (m.area > 1) {
    image = AveragePixelArea(image, m.area, m.camera.intrinsics.width, m.camera.intrinsics.height);
    lap("pixel_area");
  }
  if (const EffectParams* p = m.effects.Find(EffectKind::kRollingOcclusion)) {
    ApplyRollingOcclusion(*p, m.seed, t_s, image);
    lap("rolling_occlusion");
  }
  if (const EffectParams* p = m.effects.Find(EffectKind::kIllumination)) {
    ApplyIllumination(*p, m.seed, t_s, image);
    lap("illumination");
  }
  if (const EffectParams* p = m.effects.Find(EffectKind::kCameraNoise)) {
    ApplyCameraNoise(*p, frame_seed, image);
    lap("camera_noise");
  }
  if (const EffectParams* p = m.effects.Find(EffectKind::kJpegArtefacts)) {
    ApplyJpegArtefacts(*p, image);
    lap("jpeg_artefacts");
  }
  return image;
}

}  // namespace ave::sim
