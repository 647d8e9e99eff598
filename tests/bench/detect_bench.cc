// ave-bench detect: moving-object detection and tracking on simulated campus video against the
// simulator's per-pixel object ids (issue 6, seed AVE §6 and §6.1).
//
// Every frame is rendered once (with the scenario's camera effects) and given, in this process and
// on one core, to each background model of the detector and to OpenCV's BackgroundSubtractorMOG2.
// Truth objects are the movers covering at least the detector's minimum region (0.1 % of the
// image) in the id mask; a hypothesis matches a truth box at IoU >= 0.3 (greedy by IoU). Two
// protocols are scored side by side (ScoreFrame): "all" counts exactly those; "visible" adds
// MOT-style ignore regions for smaller movers and for boxes under --min-visibility of their
// unoccluded, untruncated projection. A "+1s delay" row scores the default model's live boxes plus
// Detector::backfill() (validated tracks' pending boxes written back, as --detect-only's default
// hold of validate_s writes them). Reported
// per model: precision, recall, MOTA (1 - (FN + FP + IDSW) / GT), ID switches, the 3D error of the
// placed ground contact (fusion_server/core/placement.h with the true pose, against MoverAt) for
// pedestrians within 60 m, and frames per second (CPU time of the thread). MOG2 runs twice: apply()
// alone (the speed peer) and its mask through the same noise removal, labelling and tracker (the
// accuracy peer). A second table splits each method's misses and false positives (protocol
// "visible") by cause: the validation second, merged blobs, bad boxes, no track near (Breakdown).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/background_segm.hpp>

#include "fusion_server/core/placement.h"
#include "model_store/common/cpu_clock.h"
#include "sensor_agent/detect/detector.h"
#include "sensor_agent/detect/segment.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/sim_camera.h"
#include "tests/bench/bench.h"

namespace ave::bench {
namespace {

// Methods are timed in CPU time of this thread (the per-core cost: other processes on shared
// cores do not count).
using Clock = ThreadCpuClock;

struct DetectOptions {
  std::string scenario = "campus";
  std::string cameras = "cam1,cam2,cam3";
  double seconds = 40;
  double fps = 15;
  double max_error_range_m = 60;
  int hd_frames = 60;  // frames upscaled to 1920x1080 for the HD timing
  std::string png = "detect_bench.png";
  double min_visibility = 0.5;  // the "visible" protocol's ignore threshold
  int error_snapshots = 0;      // diagnosis: this many frames with errors drawn like the snapshot
  double snapshot_s = 20;  // the first camera's frame at this time is drawn with truth and tracks
  detect::DetectorOptions detector;  // the pipeline's settings (background swept over every model)
};

struct Box {
  double x0, y0, x1, y1;
};

double IoU(const Box& a, const Box& b) {
  const double ix = std::max(0.0, std::min(a.x1, b.x1) - std::max(a.x0, b.x0));
  const double iy = std::max(0.0, std::min(a.y1, b.y1) - std::max(a.y0, b.y0));
  const double inter = ix * iy;
  const double uni = (a.x1 - a.x0) * (a.y1 - a.y0) + (b.x1 - b.x0) * (b.y1 - b.y0) - inter;
  return uni > 0 ? inter / uni : 0;
}

struct Truth {
  uint32_t mover = 0;
  Box box;
  double visibility = 1;  // visible box area / projected unoccluded, untruncated box area
  bool small = false;     // fewer visible pixels than the detector's minimum region (0.1 % of the image)
  bool ignore = false;    // the "visible" protocol's ignore region: small or visibility < min_visibility
  double age_s = 1e9;     // since the mover became counted ("visible" protocol) in this camera, after >= kGoneS not
};

// A mover not counted this long (absent or an ignore region) starts a new visibility when counted again.
constexpr double kGoneS = 0.5;

// Where the errors are (--seconds runs print it per method, protocol "visible"): each miss and
// each false positive falls in exactly one class, tried in this order.
struct Breakdown {
  int64_t fn_validation = 0;  // within the first validate_s of the object's visibility (the 1 s rule)
  int64_t fn_merged = 0;      // a track box overlaps it (IoU >= 0.05) and another object too: merged blob
  int64_t fn_bad_box = 0;     // a track box overlaps it (IoU >= 0.05) but under 0.3, or lost the matching
  int64_t fn_no_track = 0;    // no track box near it (lost, coasting, occluded, never validated)
  int64_t fp_on_object = 0;   // overlaps a truth box (IoU >= 0.05): a fragment, a bad box or a merge
  int64_t fp_nothing = 0;     // on no object (ghost, waving tree, noise)
};

// Accuracy counters of one method over all cameras.
struct Score {
  std::string name;
  int64_t gt = 0, tp = 0, fp = 0, fn = 0, idsw = 0;
  int64_t ignored = 0;  // truth boxes in ignore regions (the "visible" protocol only)
  double seconds = 0;  // time in the method
  int64_t frames = 0;
  std::vector<double> errors_m;  // pedestrians within range
  std::map<std::pair<std::string, uint32_t>, uint32_t> last_match;  // (camera, mover) -> hyp id
  Breakdown why;  // filled with the "visible" protocol

  double Mota() const { return gt ? 1.0 - double(fn + fp + idsw) / gt : 0; }
  double Precision() const { return tp + fp ? double(tp) / (tp + fp) : 0; }
  double Recall() const { return gt ? double(tp) / gt : 0; }
  double Fps() const { return seconds > 0 ? frames / seconds : 0; }
  double Median() const { return Percentile(0.5); }
  double Percentile(double q) const {
    if (errors_m.empty()) return NAN;
    std::vector<double> e = errors_m;
    const size_t k = std::min(e.size() - 1, static_cast<size_t>(q * (e.size() - 1) + 0.5));
    std::nth_element(e.begin(), e.begin() + k, e.end());
    return e[k];
  }
};

struct FrameTruth {
  const std::string* camera;
  const std::vector<Truth>* truth;
  const sim::Scenario* scenario;
  const TerrainModel* terrain;
  const PinholeIntrinsics* intrinsics;
  Rigid3d pose;
  double t_s;
  double max_range_m;
  double validate_s;
};

// Scores one frame. With `use_ignore` (the "visible" protocol), truth boxes flagged `ignore` are
// MOT-style ignore regions: they take part in the matching, but a hypothesis matched to one is
// neither a true nor a false positive, and the box is not counted in GT nor as a miss. Without
// it (the "all" protocol, h6's) every box that is not `small` counts and small ones do not exist
// (a track on one is a false positive). The 3D error is collected only without it.
void ScoreFrame(Score& s, const FrameTruth& f, const std::vector<detect::Detection>& hyps, bool use_ignore) {
  std::vector<std::tuple<double, size_t, size_t>> pairs;
  std::vector<std::vector<double>> iou_of(hyps.size(), std::vector<double>(f.truth->size(), 0.0));  // [hyp][truth]
  for (size_t h = 0; h < hyps.size(); ++h) {
    const auto& c = hyps[h].corners;
    const Box hb{c[0][0], c[0][1], c[2][0], c[2][1]};
    for (size_t g = 0; g < f.truth->size(); ++g) {
      if (!use_ignore && (*f.truth)[g].small) continue;
      const double iou = iou_of[h][g] = IoU(hb, (*f.truth)[g].box);
      if (iou >= 0.3) pairs.emplace_back(iou, h, g);
    }
  }
  std::sort(pairs.begin(), pairs.end(), [](const auto& a, const auto& b) { return std::get<0>(a) > std::get<0>(b); });
  std::vector<char> hu(hyps.size(), 0), gu(f.truth->size(), 0);
  auto ignored = [&](size_t g) { return use_ignore && (*f.truth)[g].ignore; };
  for (const auto& [iou, h, g] : pairs) {
    if (hu[h] || gu[g]) continue;
    hu[h] = gu[g] = 1;
    if (ignored(g)) continue;
    ++s.tp;
    const Truth& t = (*f.truth)[g];
    auto [it, first] = s.last_match.try_emplace({*f.camera, t.mover}, hyps[h].track_id);
    if (!first && it->second != hyps[h].track_id) ++s.idsw;
    it->second = hyps[h].track_id;
    if (use_ignore) continue;
    // 3D error of the placed ground contact (pedestrians within range).
    const scene::Mover* mover = nullptr;
    for (const auto& m : f.scenario->world.movers) {
      if (m.id == t.mover) mover = &m;
    }
    if (!mover || mover->kind != scene::MoverKind::kPerson) continue;
    const scene::MoverState truth = scene::MoverAt(f.scenario->world, *mover, f.t_s);
    if ((truth.position_m - f.pose.translation).norm() > f.max_range_m) continue;
    const auto& c = hyps[h].corners;
    if (auto placed = PlaceBox(*f.terrain, *f.intrinsics, f.pose, nullptr, {c[0][0], c[0][1], c[2][0], c[2][1]})) {
      s.errors_m.push_back((placed->position - truth.position_m).norm());
    }
  }
  constexpr double kNear = 0.05;  // IoU at which a box is "on" an object for the breakdown
  auto overlaps = [&](size_t h) {
    int n = 0;
    for (size_t g = 0; g < gu.size(); ++g) n += iou_of[h][g] >= kNear;
    return n;
  };
  for (size_t h = 0; h < hu.size(); ++h) {
    if (hu[h]) continue;
    ++s.fp;
    ++(overlaps(h) ? s.why.fp_on_object : s.why.fp_nothing);
  }
  for (size_t g = 0; g < gu.size(); ++g) {
    if (!use_ignore && (*f.truth)[g].small) continue;
    if (ignored(g)) {
      ++s.ignored;
      continue;
    }
    ++s.gt;
    if (gu[g]) continue;
    ++s.fn;
    int64_t* why = &s.why.fn_no_track;
    for (size_t h = 0; h < hu.size(); ++h) {
      if (iou_of[h][g] < kNear) continue;
      why = overlaps(h) > 1 ? &s.why.fn_merged : &s.why.fn_bad_box;
      if (why == &s.why.fn_merged) break;
    }
    if ((*f.truth)[g].age_s < f.validate_s - 1e-9) why = &s.why.fn_validation;
    ++*why;
  }
}

// The pixel box of a mover's unoccluded, untruncated cuboid (the simulator renders movers inside
// it: sim_camera.cc AppendMover), or nullopt when a corner is behind the camera.
std::optional<Box> FullBox(const scene::SyntheticCampus& world, const scene::Mover& mover, const Rigid3d& world_from_camera,
                           const PinholeIntrinsics& intrinsics, double t_s) {
  const scene::MoverState st = scene::MoverAt(world, mover, t_s);
  const Eigen::Vector3d forward(std::cos(st.heading_rad), std::sin(st.heading_rad), 0), left(-forward.y(), forward.x(), 0);
  const Rigid3d camera_from_world = world_from_camera.Inverse();
  Box b{1e18, 1e18, -1e18, -1e18};
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d p = st.position_m + (k & 1 ? 0.5 : -0.5) * mover.size_m.y() * forward +
                              (k & 2 ? 0.5 : -0.5) * mover.size_m.x() * left + Eigen::Vector3d(0, 0, k & 4 ? mover.size_m.z() : 0);
    const auto uv = ProjectToPixel(intrinsics, camera_from_world * p, 0.1);
    if (!uv) return std::nullopt;
    b.x0 = std::min(b.x0, uv->x() + 0.5), b.y0 = std::min(b.y0, uv->y() + 0.5);  // pixel centres are integers
    b.x1 = std::max(b.x1, uv->x() + 0.5), b.y1 = std::max(b.y1, uv->y() + 0.5);
  }
  return b;
}

struct TruthProtocol {
  int min_area = 0;             // visible pixels: the detector's smallest region (0.1 % of the image)
  int min_pixels = 16;          // smaller movers are left out of both protocols (beyond ~110 m)
  double min_visibility = 0.5;  // the "visible" protocol ignores boxes less visible than this
};

std::vector<Truth> TruthBoxes(const sim::SimImage& image, const TruthProtocol& protocol, const scene::SyntheticCampus& world,
                              const Rigid3d& world_from_camera, const PinholeIntrinsics& intrinsics, double t_s) {
  const int min_area = protocol.min_area;
  std::map<uint32_t, std::pair<Box, int>> by_id;
  for (int v = 0; v < image.height; ++v) {
    for (int u = 0; u < image.width; ++u) {
      const uint32_t id = image.object_id[image.Index(u, v)];
      if (!sim::IsMoverId(id)) continue;
      auto [it, first] = by_id.try_emplace(id - sim::kMoverIdBase, std::make_pair(Box{double(u), double(v), u + 1.0, v + 1.0}, 0));
      Box& b = it->second.first;
      b.x0 = std::min<double>(b.x0, u), b.y0 = std::min<double>(b.y0, v);
      b.x1 = std::max<double>(b.x1, u + 1), b.y1 = std::max<double>(b.y1, v + 1);
      ++it->second.second;
    }
  }
  std::vector<Truth> out;
  for (const auto& [id, bc] : by_id) {
    if (bc.second < protocol.min_pixels) continue;
    Truth t{id, bc.first};
    t.small = bc.second < min_area;
    const Box& v = t.box;
    t.visibility = 0;  // a corner behind the camera: truncated
    for (const auto& m : world.movers) {
      if (m.id != id) continue;
      if (auto full = FullBox(world, m, world_from_camera, intrinsics, t_s)) {
        const double full_area = (full->x1 - full->x0) * (full->y1 - full->y0);
        t.visibility = full_area > 0 ? std::min(1.0, (v.x1 - v.x0) * (v.y1 - v.y0) / full_area) : 0;
      }
    }
    t.ignore = t.small || t.visibility < protocol.min_visibility;
    out.push_back(t);
  }
  return out;
}

// MOG2's mask through the detector's own noise removal, labelling and tracker.
class Mog2Tracker {
 public:
  Mog2Tracker() : mog_(cv::createBackgroundSubtractorMOG2()) {}
  cv::Ptr<cv::BackgroundSubtractorMOG2>& mog() { return mog_; }
  std::vector<detect::Detection> Track(const cv::Mat& mask_in, const cv::Mat& grey, double t_s) {
    cv::Mat mask;
    cv::threshold(mask_in, mask, 200, 255, cv::THRESH_BINARY);  // drop MOG2's shadow label (127)
    detect::RemoveNoise(mask.ptr<uint8_t>(), mask.cols, mask.rows, 5);
    const int min_area = static_cast<int>(std::ceil(0.001 * mask.total()));
    const auto regions = detect::LabelComponents(mask.ptr<uint8_t>(), mask.cols, mask.rows, min_area);
    std::vector<detect::Detection> out;
    for (const auto& b : tracker_.Update(regions, grey.ptr<uint8_t>(), grey.cols, grey.rows, t_s)) {
      const float x0 = float(b.x0), y0 = float(b.y0), x1 = float(b.x1), y1 = float(b.y1);
      out.push_back({b.id, {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}}, b.score});
    }
    return out;
  }

 private:
  cv::Ptr<cv::BackgroundSubtractorMOG2> mog_;
  detect::Tracker tracker_;
};

void Plot(const std::vector<Score>& scores, const std::vector<Score>& visible, double mog2_fps, double hd_fps,
          const std::string& path) {
  const int w = 1110, h = 440;
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar colors[] = {{60, 120, 220}, {30, 40, 150}, {60, 170, 60}, {200, 120, 40}};
  const char* metric_names[] = {"MOTA all", "MOTA visible", "precision", "recall"};
  auto text = [&](const std::string& s, int x, int y, double scale = 0.45, cv::Scalar c = {0, 0, 0}) {
    cv::putText(img, s, {x, y}, cv::FONT_HERSHEY_SIMPLEX, scale, c, 1, cv::LINE_AA);
  };
  // Left: accuracy per method (bars 0..1).
  const int left = 50, base = 370, top = 60, span = base - top;
  text("accuracy on campus (IoU >= 0.3)", left, 30, 0.55);
  for (int g = 0; g <= 4; ++g) {
    const int y = base - g * span / 4;
    cv::line(img, {left, y}, {left + 470, y}, {220, 220, 220});
    text(cv::format("%.2f", g / 4.0), 10, y + 4, 0.4);
  }
  for (size_t m = 0; m < scores.size(); ++m) {
    const double vals[] = {std::max(0.0, scores[m].Mota()), std::max(0.0, visible[m].Mota()), scores[m].Precision(),
                           scores[m].Recall()};
    const int x = left + 6 + static_cast<int>(m) * 66;
    for (int k = 0; k < 4; ++k) {
      const int bh = static_cast<int>(vals[k] * span);
      cv::rectangle(img, {x + k * 15, base - bh}, {x + k * 15 + 13, base}, colors[k], cv::FILLED);
    }
    text(scores[m].name, x - 4, base + 18 + 14 * (m % 2), 0.36);
  }
  for (int k = 0; k < 4; ++k) {
    cv::rectangle(img, {left + 10 + k * 115, 40}, {left + 22 + k * 115, 50}, colors[k], cv::FILLED);
    text(metric_names[k], left + 26 + k * 115, 50, 0.4);
  }
  // Right: frames per second on one core, 640x480 (log scale), plus MOG2 apply alone and HD.
  const int rl = 540;
  text("frames/s on one core (log scale)", rl, 30, 0.55);
  std::vector<std::pair<std::string, double>> bars;
  for (const Score& s : scores) bars.emplace_back(s.name, s.Fps());
  bars.emplace_back("MOG2 apply", mog2_fps);
  bars.emplace_back("avg 1080p", hd_fps);  // the default pipeline on 1920x1080 frames
  const double lo = 1, hi = 1e5;
  for (int d = 0; d <= 5; ++d) {
    const int y = base - d * span / 5;
    cv::line(img, {rl + 40, y}, {w - 20, y}, {220, 220, 220});
    text(cv::format("1e%d", d), rl, y + 4, 0.4);
  }
  for (size_t b = 0; b < bars.size(); ++b) {
    const double v = std::clamp(bars[b].second, lo, hi);
    const int bh = static_cast<int>(std::log10(v) / 5.0 * span);
    const int x = rl + 50 + static_cast<int>(b) * 52;
    cv::rectangle(img, {x, base - bh}, {x + 34, base}, b + 2 < bars.size() ? cv::Scalar(90, 90, 90) : cv::Scalar(40, 40, 200),
                  cv::FILLED);
    text(cv::format("%.0f", bars[b].second), x, base - bh - 5, 0.36);
    text(bars[b].first, x - 6, base + 18 + 14 * (b % 3), 0.34);
  }
  cv::imwrite(path, img);
}

// The frame with truth boxes (green, ignore regions yellow) and tracks (red, with ids), and the
// default model's mask.
void Snapshot(const sim::SimImage& image, const std::vector<Truth>& truth, const std::vector<detect::Detection>& hyps,
              const detect::Detector& detector, const std::string& png, const std::string& suffix = "_frame") {
  cv::Mat frame = cv::Mat(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data())).clone();
  for (const Truth& t : truth) {  // green; ignore regions of the visible protocol yellow
    cv::rectangle(frame, cv::Rect(cv::Point(t.box.x0, t.box.y0), cv::Point(t.box.x1, t.box.y1)),
                  t.ignore ? cv::Scalar(0, 220, 220) : cv::Scalar(0, 220, 0));
  }
  for (const auto& h : hyps) {
    const cv::Point a(h.corners[0][0], h.corners[0][1]), b(h.corners[2][0], h.corners[2][1]);
    cv::rectangle(frame, a, b, {0, 0, 255});
    cv::putText(frame, std::to_string(h.track_id), a + cv::Point(0, -2), cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 255});
  }
  cv::Mat mask(detector.work_height(), detector.work_width(), CV_8UC1, const_cast<uint8_t*>(detector.foreground().data()));
  cv::Mat mask_bgr;
  cv::cvtColor(mask, mask_bgr, cv::COLOR_GRAY2BGR);
  cv::resize(mask_bgr, mask_bgr, frame.size(), 0, 0, cv::INTER_NEAREST);
  cv::Mat both;
  cv::hconcat(frame, mask_bgr, both);
  const std::string path = png.substr(0, png.rfind('.')) + suffix + ".png";
  cv::imwrite(path, both);
  std::printf("snapshot: %s\n", path.c_str());
}

int RunDetect(const DetectOptions& o) {
  UseOneCore();
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(o.scenario);
  if (!scenario.ok()) {
    std::cerr << "ave-bench: " << scenario.status().message() << "\n";
    return 1;
  }
  std::vector<std::string> cameras;
  std::stringstream list(o.cameras);
  for (std::string id; std::getline(list, id, ',');) {
    if (!scenario->world.FindCamera(id)) {
      std::cerr << "ave-bench: " << scenario->label << ": no camera '" << id << "'\n";
      return 2;
    }
    cameras.push_back(id);
  }
  const TerrainModel terrain(scene::BuildStaticMesh(scenario->world, 1.0));
  const detect::BackgroundKind kinds[] = {detect::BackgroundKind::kTimeAverage, detect::BackgroundKind::kGaussian,
                                          detect::BackgroundKind::kMixture};
  // scores[m]: the "all" protocol (every mover with >= 0.1 % of the image visible); visible[m]:
  // the "visible" protocol (the same, with boxes under min_visibility as ignore regions).
  std::vector<Score> scores;
  for (auto k : kinds) scores.push_back({detect::BackgroundKindName(k)});
  scores.push_back({"average full"});  // the default model on a full-size work image
  scores.push_back({"average grey"});  // the default model on grey only (no colour planes)
  const size_t mog_index = scores.size();
  scores.push_back({"MOG2+tracker"});
  const size_t delayed_index = scores.size();
  scores.push_back({"average +1s delay"});  // the default model's delayed output, back-filled
  std::vector<Score> visible = scores;
  double mog2_apply_s = 0, hd_s = 0;
  int64_t hd_frames = 0;
  const int frames = static_cast<int>(o.seconds * o.fps);
  const int snapshot_frame = static_cast<int>(o.snapshot_s * o.fps);
  int error_snapshots = 0;
  auto score_both = [&](size_t m, const FrameTruth& ft, const std::vector<detect::Detection>& hyps) {
    ScoreFrame(scores[m], ft, hyps, false);
    ScoreFrame(visible[m], ft, hyps, true);
  };
  for (const std::string& cam_id : cameras) {
    const scene::CameraSpec& cam = *scenario->world.FindCamera(cam_id);
    const sim::SimulatedCamera pipeline(scenario->world, cam, scenario->EffectsForCamera(cam_id), scenario->seed);
    std::vector<detect::Detector> detectors;
    for (auto k : kinds) {
      detect::DetectorOptions d = o.detector;
      d.background = k;
      detectors.emplace_back(d);
    }
    detect::DetectorOptions full = o.detector;
    full.work_width = std::max(16, cam.intrinsics.width);
    detectors.emplace_back(full);
    detect::DetectorOptions grey = o.detector;
    grey.colour = false;
    detectors.emplace_back(grey);
    detect::Detector hd_detector(o.detector);
    Mog2Tracker mog2;
    const TruthProtocol protocol{
        static_cast<int>(std::ceil(o.detector.min_area_fraction * cam.intrinsics.width * cam.intrinsics.height)),
        16, o.min_visibility};
    // The whole video's truth and the default model's delayed output (live boxes plus the
    // back-filled boxes of tracks validated later), scored once the camera is done.
    std::vector<std::vector<Truth>> truths(frames);
    std::map<uint32_t, std::pair<double, double>> seen;  // mover -> (visibility start, last truth box) in s
    std::vector<std::vector<detect::Detection>> delayed(frames);
    auto frame_truth = [&](int f) {
      const double t_s = f / o.fps;
      return FrameTruth{&cam_id, &truths[f], &*scenario, &terrain, &cam.intrinsics, pipeline.PoseAt(t_s), t_s,
                        o.max_error_range_m, o.detector.tracker.validate_s};
    };
    // Frames are rendered in chunks, then each method runs over the whole chunk in turn (warm,
    // the same frames, states carried across chunks); scoring happens outside the timed calls.
    constexpr int kChunk = 60;
    for (int c0 = 0; c0 < frames; c0 += kChunk) {
      const int c1 = std::min(frames, c0 + kChunk);
      std::vector<sim::SimImage> images;
      std::vector<FrameTruth> fts;
      images.reserve(c1 - c0);
      for (int f = c0; f < c1; ++f) {
        const double t_s = f / o.fps;
        images.push_back(pipeline.Frame(f, t_s));
        truths[f] = TruthBoxes(images.back(), protocol, scenario->world, pipeline.PoseAt(t_s), cam.intrinsics, t_s);
        for (Truth& t : truths[f]) {
          if (t.ignore) continue;  // visibility: counted by the "visible" protocol
          auto [it, first] = seen.try_emplace(t.mover, t_s, t_s);
          if (t_s - it->second.second > kGoneS) it->second.first = t_s;
          it->second.second = t_s;
          t.age_s = t_s - it->second.first;
        }
        if (!(f == snapshot_frame && cam_id == cameras.front())) {
          images.back().object_id = {}, images.back().class_id = {}, images.back().depth_m = {};
        }
        fts.push_back(frame_truth(f));
      }
      std::vector<std::vector<detect::Detection>> hyps(c1 - c0);
      std::vector<std::pair<double, detect::Detection>> backfill;
      for (size_t m = 0; m < detectors.size(); ++m) {
        const auto t0 = Clock::now();
        for (int f = c0; f < c1; ++f) {
          const sim::SimImage& image = images[f - c0];
          hyps[f - c0] = detectors[m].Process(image.bgr.data(), image.width, image.height, f / o.fps);
          if (m == 0) {
            // What `ave-agent --detect-only --latency validate_s` writes: back-fill older than the
            // hold (a candidate that missed its last frames before validating) is dropped.
            for (const auto& entry : detectors[0].backfill()) {
              if (entry.first >= f / o.fps - o.detector.tracker.validate_s - 1e-6) backfill.push_back(entry);
            }
          }
          if (m == 0 && cam_id == cameras.front() && f == snapshot_frame) {
            Snapshot(image, truths[f], hyps[f - c0], detectors[0], o.png);
          }
          if (m == 0 && error_snapshots < o.error_snapshots && f >= snapshot_frame && f % 15 == 0) {
            Score one;  // diagnosis (--error-snapshots): frames with a false positive or a miss after validation
            ScoreFrame(one, fts[f - c0], hyps[f - c0], true);
            const Breakdown& w = one.why;
            if (one.fp + one.fn - w.fn_validation > 0) {
              Snapshot(image, truths[f], hyps[f - c0], detectors[0], o.png,
                       cv::format("_%s_f%d_fp%lld_fn%lld_merged%lld_badbox%lld_notrack%lld", cam_id.c_str(), f,
                                  static_cast<long long>(one.fp), static_cast<long long>(one.fn),
                                  static_cast<long long>(w.fn_merged), static_cast<long long>(w.fn_bad_box),
                                  static_cast<long long>(w.fn_no_track)));
              ++error_snapshots;
            }
          }
        }
        scores[m].seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        scores[m].frames += c1 - c0;
        for (int f = c0; f < c1; ++f) score_both(m, fts[f - c0], hyps[f - c0]);
        if (m == 0) {
          for (int f = c0; f < c1; ++f) delayed[f] = hyps[f - c0];
          for (const auto& [bt, det] : backfill) {
            const int f = static_cast<int>(std::lround(bt * o.fps));
            if (f >= 0 && f < frames) delayed[f].push_back(det);
          }
        }
      }
      std::vector<cv::Mat> masks(c1 - c0);
      const auto t0 = Clock::now();
      for (int f = c0; f < c1; ++f) {
        const sim::SimImage& image = images[f - c0];
        const cv::Mat bgr(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
        mog2.mog()->apply(bgr, masks[f - c0]);
      }
      const auto t1 = Clock::now();
      for (int f = c0; f < c1; ++f) {
        const sim::SimImage& image = images[f - c0];
        const cv::Mat bgr(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
        cv::Mat grey;
        cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
        hyps[f - c0] = mog2.Track(masks[f - c0], grey, f / o.fps);
      }
      const auto t2 = Clock::now();
      mog2_apply_s += std::chrono::duration<double>(t1 - t0).count();
      scores[mog_index].seconds += std::chrono::duration<double>(t2 - t0).count();
      scores[mog_index].frames += c1 - c0;
      for (int f = c0; f < c1; ++f) score_both(mog_index, fts[f - c0], hyps[f - c0]);
      for (int f = c0; f < c1 && f < o.hd_frames; ++f) {
        const sim::SimImage& image = images[f - c0];
        const cv::Mat bgr(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
        cv::Mat hd;
        cv::resize(bgr, hd, cv::Size(1920, 1080), 0, 0, cv::INTER_LINEAR);
        const auto h0 = Clock::now();
        hd_detector.Process(hd.ptr<uint8_t>(), hd.cols, hd.rows, f / o.fps);
        hd_s += std::chrono::duration<double>(Clock::now() - h0).count();
        ++hd_frames;
      }
    }
    for (int f = 0; f < frames; ++f) score_both(delayed_index, frame_truth(f), delayed[f]);
  }
  // The delayed output costs what the live one does (the same Process calls).
  scores[delayed_index].seconds = scores[0].seconds, scores[delayed_index].frames = scores[0].frames;
  const double mog2_fps = scores[mog_index].frames / std::max(mog2_apply_s, 1e-9);
  const double hd_fps = hd_frames / std::max(hd_s, 1e-9);
  std::printf("ave-bench detect: scenario %s, cameras %s, %d frames each (%.1f s at %.1f fps), one core, CPU time of the thread\n",
              scenario->name.c_str(), o.cameras.c_str(), frames, o.seconds, o.fps);
  std::printf("protocol all (h6's): truth = every mover with >= %.1f %% of the image visible, nothing ignored; "
              "protocol visible: the same truth, plus MOT-style ignore regions (a track on one is neither TP nor FP, "
              "a miss is not counted) for movers under %.1f %% of the image (>= 16 px) and for boxes under %.0f %% "
              "visible (box area / the unoccluded, untruncated cuboid's box area): %lld ignored boxes\n",
              100 * o.detector.min_area_fraction,
              100 * o.detector.min_area_fraction, 100 * o.min_visibility, static_cast<long long>(visible[0].ignored));
  std::printf("| method | GT all | precision | recall | MOTA all | ID sw. | GT visible | precision | recall | MOTA visible | ID sw. | 3D median m | 3D p90 m | n 3D | fps (640x480) | fps / MOG2 apply |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (size_t m = 0; m < scores.size(); ++m) {
    const Score& s = scores[m];
    const Score& v = visible[m];
    std::printf("| %s | %lld | %.3f | %.3f | %.3f | %lld | %lld | %.3f | %.3f | %.3f | %lld | %.3f | %.3f | %zu | %.0f | %.2f |\n",
                s.name.c_str(), static_cast<long long>(s.gt), s.Precision(), s.Recall(), s.Mota(),
                static_cast<long long>(s.idsw), static_cast<long long>(v.gt), v.Precision(), v.Recall(), v.Mota(),
                static_cast<long long>(v.idsw), s.Median(), s.Percentile(0.9), s.errors_m.size(), s.Fps(),
                s.Fps() / mog2_fps);
  }
  std::printf("| MOG2 apply alone | | | | | | | | | | | | | | %.0f | 1.00 |\n", mog2_fps);
  std::printf("\nwhere the errors are (protocol visible; shares of GT visible; first match wins, IoU >= 0.05 = on an object):\n");
  std::printf("| method | FN | in first %.1f s of visibility | merged with another object | bad box (IoU < 0.3) | no track near | FP | on an object | on nothing |\n",
              o.detector.tracker.validate_s);
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (const Score& v : visible) {
    const Breakdown& b = v.why;
    const double g = std::max<double>(1, v.gt);
    std::printf("| %s | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) | %lld (%.3f) |\n",
                v.name.c_str(), static_cast<long long>(v.fn), v.fn / g, static_cast<long long>(b.fn_validation),
                b.fn_validation / g, static_cast<long long>(b.fn_merged), b.fn_merged / g,
                static_cast<long long>(b.fn_bad_box), b.fn_bad_box / g, static_cast<long long>(b.fn_no_track),
                b.fn_no_track / g, static_cast<long long>(v.fp), v.fp / g, static_cast<long long>(b.fp_on_object),
                b.fp_on_object / g, static_cast<long long>(b.fp_nothing), b.fp_nothing / g);
  }
  std::printf("default pipeline at 1920x1080 (upscaled frames): %.1f fps over %lld frames\n", hd_fps,
              static_cast<long long>(hd_frames));
  Plot(scores, visible, mog2_fps, hd_fps, o.png);
  std::printf("plot: %s\n", o.png.c_str());
  const Score& d = scores.front();
  std::printf("{\"bench\":\"detect\",\"scenario\":\"%s\",\"frames_per_camera\":%d,\"mota\":%.4f,\"precision\":%.4f,"
              "\"recall\":%.4f,\"mota_visible\":%.4f,\"mota_delayed\":%.4f,\"mota_delayed_visible\":%.4f,\"id_switches\":%lld,"
              "\"median_3d_error_m\":%.4f,\"fps\":%.1f,\"mog2_fps\":%.1f,\"fps_ratio_vs_mog2\":%.2f,\"hd_fps\":%.1f}\n",
              scenario->name.c_str(), frames, d.Mota(), d.Precision(), d.Recall(), visible[0].Mota(), scores[delayed_index].Mota(),
              visible[delayed_index].Mota(), static_cast<long long>(d.idsw), d.Median(), d.Fps(), mog2_fps, d.Fps() / mog2_fps,
              hd_fps);
  return 0;
}

}  // namespace

Runner AddDetectBench(CLI::App& sub) {
  auto options = std::make_shared<DetectOptions>();
  sub.add_option("--scenario", options->scenario, "bundled scenario or .yaml path")->capture_default_str();
  sub.add_option("--cameras", options->cameras, "comma-separated camera ids")->capture_default_str();
  sub.add_option("--seconds", options->seconds, "video length per camera")->capture_default_str()->check(ave::cli::Range(1.0, 3600.0));
  sub.add_option("--fps", options->fps, "frames per second")->capture_default_str()->check(ave::cli::Range(1.0, 120.0));
  sub.add_option("--max-range", options->max_error_range_m, "3D error only for pedestrians within this range (m)")
      ->capture_default_str();
  sub.add_option("--hd-frames", options->hd_frames, "frames per camera timed at 1920x1080")->capture_default_str();
  sub.add_option("--png", options->png, "plot file")->capture_default_str()->check(ave::cli::WritableFile());
  sub.add_option("--min-visibility", options->min_visibility,
                 "visible protocol: truth boxes less visible than this (box area / unoccluded box area) are ignore regions")
      ->capture_default_str()
      ->check(ave::cli::Range(0.0, 1.0));
  detect::DetectorOptions& d = options->detector;
  sub.add_option("--window", d.window_s, "background averaging window (s)")->capture_default_str();
  sub.add_option("--top-fraction", d.top_fraction, "histogram threshold: fraction of differences kept")->capture_default_str();
  sub.add_option("--floor", d.threshold_floor, "threshold floor")->capture_default_str();
  sub.add_option("--min-area", d.min_area_fraction, "smallest region, fraction of the image (truth uses it too)")
      ->capture_default_str();
  sub.add_option("--close", d.close_size, "closing size (work pixels, odd)")->capture_default_str();
  sub.add_option("--work-width", d.work_width, "detector work image width")->capture_default_str();
  sub.add_option("--correlation", d.tracker.correlation_threshold, "tracker correlation threshold")->capture_default_str();
  sub.add_option("--validate", d.tracker.validate_s, "tracker validation time (s)")->capture_default_str();
  sub.add_option("--tentative-gap", d.tracker.tentative_gap_s, "tracker: gap a candidate may have and keep its age (s)")
      ->capture_default_str();
  sub.add_option("--coast", d.tracker.coast_s, "tracker: time a validated track survives unmatched (s)")->capture_default_str();
  sub.add_option("--split-age", d.tracker.split_min_age_s,
                 "tracker: split a region holding the predictions of objects at least this old (s; negative: never)")
      ->capture_default_str();
  sub.add_option("--error-snapshots", options->error_snapshots,
                 "draw up to N frames (every 15th from --snapshot on) with a false positive or a miss after the "
                 "validation second (visible protocol) to <png>_<camera>_f<frame>_fp<n>_fn<n>_<miss classes>.png; "
                 "times the default model with it")
      ->capture_default_str();
  sub.add_option("--snapshot", options->snapshot_s, "time (s) of the first camera's frame drawn to <png>_frame.png")
      ->capture_default_str();
  return [options] { return RunDetect(*options); };
}

}  // namespace ave::bench
