// Detection and validated tracking (issue 6): labelling, threshold, every background model on a
// synthetic textured scene with a moving textured object, and the hard cases.
#include <cmath>
#include <cstdint>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/detect/detector.h"
#include "sensor_agent/detect/segment.h"

namespace ave::detect {
namespace {

uint8_t Hash(int x, int y, int salt) {
  uint32_t h = static_cast<uint32_t>(x) * 73856093u ^ static_cast<uint32_t>(y) * 19349663u ^ salt * 83492791u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  return static_cast<uint8_t>(h >> 24);
}

struct Object {
  double x, y;  // top-left corner (may be outside the image)
  int w, h;
  int salt = 7;  // texture
};

// A textured background (smooth blocks of 8 px plus +-2 noise per frame) with textured objects
// (may cross the border; later ones in front); `gain` scales everything.
std::vector<uint8_t> Scene(int w, int h, int frame, const std::vector<Object>& objects, double gain = 1.0) {
  std::vector<uint8_t> bgr(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double v = 60 + Hash(x / 8, y / 8, 1) / 3.0 + (Hash(x, y, frame) % 5) - 2;
      for (const Object& o : objects) {
        if (x >= o.x && x < o.x + o.w && y >= o.y && y < o.y + o.h) {
          v = 170 + (Hash(static_cast<int>(x - o.x) / 3, static_cast<int>(y - o.y) / 3, o.salt) % 60);
        }
      }
      const uint8_t g = static_cast<uint8_t>(std::clamp(v * gain, 0.0, 255.0));
      uint8_t* p = &bgr[(static_cast<size_t>(y) * w + x) * 3];
      p[0] = p[1] = p[2] = g;
    }
  }
  return bgr;
}

// One object at (ox, oy) of size ow x oh.
std::vector<uint8_t> Scene(int w, int h, int frame, double ox, double oy, int ow, int oh, double gain = 1.0) {
  return Scene(w, h, frame, std::vector<Object>{{ox, oy, ow, oh}}, gain);
}

TEST(LabelComponents, FourConnectedWithEquivalencesAndMinArea) {
  // Row-major 6x5: a U shape (labels merge in the first pass), a diagonal pair (not 4-connected),
  // a single pixel.
  const std::vector<uint8_t> mask = {
      1, 0, 1, 0, 0, 1,  //
      1, 0, 1, 0, 0, 0,  //
      1, 1, 1, 0, 0, 0,  //
      0, 0, 0, 1, 0, 0,  //
      0, 0, 0, 0, 1, 0,  //
  };
  std::vector<int32_t> labels;
  const std::vector<Component> all = LabelComponents(mask.data(), 6, 5, 1, &labels);
  ASSERT_EQ(all.size(), 4u);
  EXPECT_EQ(all[0].area, 7);
  EXPECT_EQ(all[0].x0, 0);
  EXPECT_EQ(all[0].x1, 2);
  EXPECT_EQ(all[0].y1, 2);
  EXPECT_EQ(labels[0], labels[2]);  // the U's two arms
  EXPECT_NE(labels[3 * 6 + 3], labels[4 * 6 + 4]);  // diagonal neighbours stay apart
  const std::vector<Component> big = LabelComponents(mask.data(), 6, 5, 2, &labels);
  ASSERT_EQ(big.size(), 1u);
  EXPECT_EQ(labels[5], 0);  // dropped pixels are background
}

TEST(LabelComponents, SpiralNeedsTransitiveMerges) {
  // A comb whose teeth join only at the bottom row: every tooth gets its own provisional label.
  const int w = 9, h = 4;
  std::vector<uint8_t> mask(w * h, 0);
  for (int x = 0; x < w; x += 2)
    for (int y = 0; y < h; ++y) mask[y * w + x] = 1;
  for (int x = 0; x < w; ++x) mask[(h - 1) * w + x] = 1;
  EXPECT_EQ(LabelComponents(mask.data(), w, h, 1).size(), 1u);
}

TEST(HistogramThreshold, KeepsTopFractionAboveFloor) {
  std::vector<uint8_t> d(1000);
  for (int i = 0; i < 1000; ++i) d[i] = static_cast<uint8_t>(i / 4);  // 0..249, 4 each
  const int t = HistogramThreshold(d.data(), d.size(), 0.05, 10);
  std::vector<uint8_t> mask(d.size());
  const size_t on = ApplyThreshold(d.data(), d.size(), t, mask.data());
  EXPECT_LE(on, 50u);
  EXPECT_GE(on, 46u);
  EXPECT_EQ(HistogramThreshold(d.data(), d.size(), 0.05, 245), 245);  // the floor wins
  std::vector<uint8_t> quiet(1000, 3);
  EXPECT_EQ(HistogramThreshold(quiet.data(), quiet.size(), 0.05, 16), 16);
}

DetectorOptions Small() {
  DetectorOptions o;
  o.window_s = 2;
  return o;
}

// Runs a 160x120 scene at 15 fps with an object moving right at 20 px/s from (x_start, 50);
// returns the detections per frame.
std::vector<std::vector<Detection>> RunMover(Detector& d, int frames, double x_start, int w = 160, int h = 120,
                                             int first_frame = 0) {
  std::vector<std::vector<Detection>> out;
  for (int f = first_frame; f < first_frame + frames; ++f) {
    const double t = f / 15.0;
    const auto img = Scene(w, h, f, x_start + 20 * t, 50, 12, 24);
    out.push_back(d.Process(img.data(), w, h, t));
  }
  return out;
}

class EveryBackground : public testing::TestWithParam<BackgroundKind> {};

TEST_P(EveryBackground, MovingObjectBecomesOneStableTrackAfterOneSecond) {
  DetectorOptions o = Small();
  o.background = GetParam();
  Detector d(o);
  // Background only for 2 s, then the object walks in.
  std::vector<std::vector<Detection>> quiet;
  for (int f = 0; f < 30; ++f) {
    const auto img = Scene(160, 120, f, -100, 0, 0, 0);
    EXPECT_TRUE(d.Process(img.data(), 160, 120, f / 15.0).empty()) << "frame " << f;
  }
  const auto seen = RunMover(d, 60, 20 - 20 * 2.0, 160, 120, 30);
  // Validation: nothing during the object's first second.
  for (int f = 0; f < 14; ++f) EXPECT_TRUE(seen[f].empty()) << "frame " << f;
  uint32_t id = 0;
  int tracked = 0;
  for (int f = 16; f < 60; ++f) {
    ASSERT_EQ(seen[f].size(), 1u) << "frame " << f;
    if (!id) id = seen[f][0].track_id;
    EXPECT_EQ(seen[f][0].track_id, id);
    const double t = (30 + f) / 15.0;
    const double x = 20 + 20 * (t - 2.0);
    EXPECT_NEAR(seen[f][0].corners[0][0], x, 3.0);
    EXPECT_NEAR(seen[f][0].corners[2][1], 74, 3.0);  // bottom edge: y 50 + 24
    ++tracked;
  }
  EXPECT_EQ(tracked, 44);
}

TEST(Detector, BackfillGivesAValidatedTracksPendingBoxesOnce) {
  Detector d(Small());
  for (int f = 0; f < 30; ++f) {
    const auto img = Scene(160, 120, f, -100, 0, 0, 0);
    d.Process(img.data(), 160, 120, f / 15.0);
    EXPECT_TRUE(d.backfill().empty());
  }
  int validated_at = -1;
  std::vector<std::pair<double, Detection>> backfill;
  for (int f = 30; f < 60; ++f) {
    const double t = f / 15.0;
    const auto img = Scene(160, 120, f, 20 * (t - 2.0), 50, 12, 24);
    const auto live = d.Process(img.data(), 160, 120, t);
    if (d.backfill().empty()) continue;
    EXPECT_EQ(validated_at, -1) << "back-filled twice";
    validated_at = f;
    backfill = d.backfill();
    ASSERT_EQ(live.size(), 1u);
    for (const auto& [bt, det] : backfill) {
      EXPECT_EQ(det.track_id, live[0].track_id);
      EXPECT_LT(bt, t);
      EXPECT_GE(bt, 2.0 - 1e-9);
      EXPECT_NEAR(det.corners[0][0], 20 * (bt - 2.0), 3.0);  // where the object was then
    }
  }
  ASSERT_GE(validated_at, 44);  // after one second
  EXPECT_GE(backfill.size(), 12u);  // the pending frames of that second
  EXPECT_LE(backfill.size(), 16u);
}

INSTANTIATE_TEST_SUITE_P(Detector, EveryBackground,
                         testing::Values(BackgroundKind::kTimeAverage, BackgroundKind::kGaussian,
                                         BackgroundKind::kMixture));

TEST(Detector, SuddenIlluminationChangeLeavesNoValidatedObjects) {
  Detector d(Small());
  for (int f = 0; f < 60; ++f) {
    // A patchy re-lighting at 2 s: half the image brightens by 60 %, the rest stays.
    std::vector<uint8_t> img = Scene(160, 120, f, -100, 0, 0, 0);
    if (f >= 30) {
      for (size_t i = 0; i < img.size() / 2; ++i) img[i] = static_cast<uint8_t>(std::min(255, img[i] * 8 / 5));
    }
    EXPECT_TRUE(d.Process(img.data(), 160, 120, f / 15.0).empty()) << "frame " << f;
  }
  EXPECT_GE(d.stats().global_changes, 1);
}

TEST(Detector, GlobalGainChangeIsCompensated) {
  Detector d(Small());
  for (int f = 0; f < 60; ++f) {
    const auto img = Scene(160, 120, f, -100, 0, 0, 0, f >= 30 ? 1.4 : 1.0);
    EXPECT_TRUE(d.Process(img.data(), 160, 120, f / 15.0).empty()) << "frame " << f;
  }
}

TEST(Detector, AllBlackAndAllWhiteFramesGiveNothing) {
  Detector d(Small());
  for (int f = 0; f < 40; ++f) {
    const std::vector<uint8_t> img(160 * 120 * 3, (f / 10) % 2 ? 255 : 0);
    EXPECT_TRUE(d.Process(img.data(), 160, 120, f / 15.0).empty()) << "frame " << f;
  }
}

TEST(Detector, TinyAndHugeFrames) {
  Detector d(Small());
  const uint8_t pixel[3] = {10, 20, 30};
  for (int f = 0; f < 20; ++f) EXPECT_TRUE(d.Process(pixel, 1, 1, f / 15.0).empty());
  EXPECT_TRUE(d.Process(nullptr, 0, 0, 2.0).empty());
  const int w = 7680, h = 4320;  // 8K
  std::vector<uint8_t> img(static_cast<size_t>(w) * h * 3, 90);
  for (int f = 0; f < 3; ++f) {
    // A bright square moving across: the work image is 320 wide (factor 24).
    for (int y = 2000; y < 2600; ++y)
      for (int x = 1000 + 300 * f; x < 1400 + 300 * f; ++x) img[(static_cast<size_t>(y) * w + x) * 3 + 1] = 250;
    EXPECT_TRUE(d.Process(img.data(), w, h, 3 + f / 15.0).empty());  // not validated within 0.2 s
  }
  EXPECT_EQ(d.work_width(), 320);
  EXPECT_EQ(d.work_height(), 180);
  EXPECT_GE(d.stats().regions, 1);
}

TEST(Detector, BoxTouchingTheBorderStaysInsideTheImage) {
  Detector d(Small());
  for (int f = 0; f < 30; ++f) {
    const auto img = Scene(160, 120, f, -100, 0, 0, 0);
    d.Process(img.data(), 160, 120, f / 15.0);
  }
  // Object half outside the right edge, moving slowly down.
  int seen = 0;
  for (int f = 30; f < 60; ++f) {
    const auto img = Scene(160, 120, f, 152, 20 + 0.5 * (f - 30), 16, 24);
    for (const Detection& det : d.Process(img.data(), 160, 120, f / 15.0)) {
      ++seen;
      for (const auto& c : det.corners) {
        EXPECT_GE(c[0], 0.f);
        EXPECT_LE(c[0], 160.f);
        EXPECT_GE(c[1], 0.f);
        EXPECT_LE(c[1], 120.f);
      }
      EXPECT_FLOAT_EQ(det.corners[1][0], 160.f);
    }
  }
  EXPECT_GE(seen, 10);
}

TEST(Detector, ObjectLeavingAndReenteringIsTrackedAgainWithANewTag) {
  Detector d(Small());
  auto run = [&](int f0, int f1, auto x_of_t) {
    std::vector<uint32_t> ids;
    for (int f = f0; f < f1; ++f) {
      const double t = f / 15.0;
      const auto img = Scene(160, 120, f, x_of_t(t), 50, 12, 24);
      for (const Detection& det : d.Process(img.data(), 160, 120, t)) ids.push_back(det.track_id);
    }
    return ids;
  };
  run(0, 30, [](double) { return -100.0; });
  const auto first = run(30, 90, [](double t) { return 20 + 25 * (t - 2); });   // exits right by t = 6
  const auto gone = run(90, 120, [](double) { return 400.0; });                // away 2 s
  const auto second = run(120, 180, [](double t) { return 140 - 25 * (t - 8); });  // walks back in
  ASSERT_FALSE(first.empty());
  EXPECT_TRUE(gone.empty());
  ASSERT_FALSE(second.empty());
  EXPECT_NE(first.front(), second.back());
  EXPECT_EQ(second.front(), second.back());
}

TEST(Detector, TwoTracksWhoseBlobsMergeKeepTheirIdsAndBoxes) {
  Detector d(Small());
  for (int f = 0; f < 30; ++f) {
    const auto img = Scene(160, 120, f, -100, 0, 0, 0);
    d.Process(img.data(), 160, 120, f / 15.0);
  }
  // A walks right and B left until they walk down side by side, 2 px apart (one blob after the
  // closing), from 4.5 s to the end; both keep walking down.
  auto a_x = [](double t) { return std::min(20 + 20 * (t - 2), 70.0); };
  auto b_x = [](double t) { return std::max(128 - 20 * (t - 2), 84.0); };
  auto y = [](double t) { return 30 + 8 * (t - 2); };
  uint32_t id_a = 0, id_b = 0;
  int merged_frames = 0;
  for (int f = 30; f < 120; ++f) {
    const double t = f / 15.0;
    const auto img = Scene(160, 120, f, {{a_x(t), y(t), 12, 24, 7}, {b_x(t), y(t) - 4, 12, 28, 11}});
    const auto seen = d.Process(img.data(), 160, 120, t);
    if (f < 60) continue;  // both validated after their first second
    ASSERT_EQ(seen.size(), 2u) << "frame " << f;
    const Detection& left = seen[0].corners[0][0] < seen[1].corners[0][0] ? seen[0] : seen[1];
    const Detection& right = &left == &seen[0] ? seen[1] : seen[0];
    if (!id_a) id_a = left.track_id, id_b = right.track_id;
    EXPECT_EQ(left.track_id, id_a) << "frame " << f;
    EXPECT_EQ(right.track_id, id_b) << "frame " << f;
    EXPECT_NEAR(left.corners[0][0], a_x(t), 3.0) << "frame " << f;
    EXPECT_NEAR(left.corners[2][0], a_x(t) + 12, 3.0) << "frame " << f;
    EXPECT_NEAR(right.corners[0][0], b_x(t), 3.0) << "frame " << f;
    EXPECT_NEAR(right.corners[2][0], b_x(t) + 12, 3.0) << "frame " << f;
    merged_frames += t >= 4.5 && d.stats().regions == 1;  // the two really are one blob
  }
  EXPECT_NE(id_a, id_b);
  EXPECT_GE(merged_frames, 45);
}

TEST(DetectorOptions, CheckNamesTheField) {
  DetectorOptions o;
  o.top_fraction = 0;
  EXPECT_THAT(o.Check(), testing::HasSubstr("top_fraction"));
  o = {};
  o.tracker.validate_s = -1;
  EXPECT_THAT(o.Check(), testing::HasSubstr("tracker.validate_s"));
  EXPECT_THROW(Detector{o}, std::invalid_argument);
}

}  // namespace
}  // namespace ave::detect
