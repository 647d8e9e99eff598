// The hard cases of issue 17 for avatars on tracks: a track that stops, reverses, jumps 10 m,
// two avatars crossing, a one-frame sequence.
#include "fusion_server/core/avatar_assign.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "fusion_server/core/scene_state.h"

namespace ave {
namespace {

constexpr int64_t kStepNs = 100'000'000;  // 10 Hz updates
constexpr double kDt = 0.1;

double AngleDiff(double a, double b) { return std::abs(std::remainder(a - b, 2.0 * M_PI)); }

AvatarAssigner MakeAssigner() {
  AvatarAssigner a;
  a.SetSequences({{"walk", 3, 12, 1.4}});
  return a;
}

TEST(AvatarAssign, WalkingStraight_HeadingFollowsTravelAndPhaseIsDistanceOverStride) {
  AvatarAssigner a = MakeAssigner();
  AvatarPose pose;
  for (int i = 0; i <= 50; ++i) pose = a.Update(7, {2.0, 1.4 * kDt * i}, i * kStepNs);
  EXPECT_EQ(pose.sequence, "walk");
  EXPECT_EQ(pose.sequence_version, 3);
  EXPECT_LT(AngleDiff(pose.heading_rad, M_PI / 2), 0.01);
  EXPECT_GT(pose.walked_m, 6.5);  // 7 m less the first update or two while speed builds up
  EXPECT_LE(pose.walked_m, 7.0 + 1e-9);
  EXPECT_NEAR(pose.phase_cycles, std::fmod(pose.walked_m / 1.4, 1.0), 1e-9);
  EXPECT_EQ(pose.placement, 0u);
}

TEST(AvatarAssign, TrackStops_AvatarStandsWithoutHeadingFlipOrSpin) {
  AvatarAssigner a = MakeAssigner();
  int i = 0;
  for (; i <= 30; ++i) a.Update(1, {1.4 * kDt * i, 0.0}, i * kStepNs);
  const Eigen::Vector2d stop(1.4 * kDt * 30, 0.0);
  std::mt19937 rng(17);
  std::normal_distribution<double> jitter_m(0.0, 0.02);  // a fused position standing still
  double phase_after_settling = -1;
  for (int k = 0; k < 100; ++k, ++i) {
    const AvatarPose& pose = a.Update(1, stop + Eigen::Vector2d(jitter_m(rng), jitter_m(rng)), i * kStepNs);
    ASSERT_LT(AngleDiff(pose.heading_rad, 0.0), 0.15) << "update " << k << " after stopping";
    if (k == 20) phase_after_settling = pose.phase_cycles;
    if (k > 20) {
      ASSERT_EQ(pose.phase_cycles, phase_after_settling) << "legs move while standing, update " << k;
    }
  }
}

TEST(AvatarAssign, TrackReverses_TurnsRoundAtBoundedRateAndEndsFacingBack) {
  AvatarAssignOptions options;
  AvatarAssigner a(options);
  a.SetSequences({{"walk", 1, 12, 1.4}});
  double x = 0, previous = 0;
  for (int i = 0; i <= 60; ++i) {
    x += (i <= 30 ? 1.4 : -1.4) * kDt;
    const AvatarPose& pose = a.Update(1, {x, 0.0}, i * kStepNs);
    if (i > 0) {
      ASSERT_LE(AngleDiff(pose.heading_rad, previous), options.max_turn_rate_radps * kDt + 1e-9) << i;
    }
    if (i == 30) {
      EXPECT_LT(AngleDiff(pose.heading_rad, 0.0), 0.01);
    }
    previous = pose.heading_rad;
  }
  EXPECT_LT(AngleDiff(previous, M_PI), 0.05);
  EXPECT_EQ(a.Find(1)->placement, 0u);
}

TEST(AvatarAssign, TrackJumps10m_AvatarIsRePlacedNotWalkedThere) {
  AvatarAssigner a = MakeAssigner();
  int i = 0;
  for (; i <= 20; ++i) a.Update(1, {1.4 * kDt * i, 0.0}, i * kStepNs);
  const AvatarPose before = *a.Find(1);
  const AvatarPose& after = a.Update(1, {1.4 * kDt * 20, 10.0}, i++ * kStepNs);
  EXPECT_EQ(after.placement, before.placement + 1);
  EXPECT_EQ(after.walked_m, before.walked_m);
  EXPECT_EQ(after.phase_cycles, before.phase_cycles);
  EXPECT_EQ(after.heading_rad, before.heading_rad);  // no turn towards the jump (+y)
  // Walking on from the new place resumes from rest: the jump left no velocity behind.
  const AvatarPose& next = a.Update(1, {1.4 * kDt * 21, 10.0}, i * kStepNs);
  EXPECT_LT(AngleDiff(next.heading_rad, 0.0), 1e-9);
  EXPECT_EQ(next.walked_m, before.walked_m);  // one step from rest is below walking speed
}

TEST(AvatarAssign, TwoAvatarsCrossing_EachKeepsItsOwnHeadingAndPhase) {
  AvatarAssigner a = MakeAssigner();
  for (int i = 0; i <= 80; ++i) {
    const double s = -5.0 + 1.25 * kDt * i;  // both pass the origin at i = 40
    const AvatarPose east = a.Update(10, {s, 0.0}, i * kStepNs, 0.0);
    const AvatarPose north = a.Update(11, {0.0, s}, i * kStepNs, M_PI / 2);
    ASSERT_LT(AngleDiff(east.heading_rad, 0.0), 1e-9) << i;
    ASSERT_LT(AngleDiff(north.heading_rad, M_PI / 2), 1e-9) << i;
    ASSERT_EQ(east.phase_cycles, north.phase_cycles) << i;  // same speed, same distance
  }
  EXPECT_EQ(a.size(), 2u);
  a.Retain({11});
  EXPECT_EQ(a.Find(10), nullptr);
  EXPECT_NE(a.Find(11), nullptr);
}

TEST(AvatarAssign, OneFrameSequence_PhaseStaysZeroAndFrameIsZero) {
  AvatarAssigner a;
  a.SetSequences({{"statue", 1, 1, 0.0}});
  for (int i = 0; i <= 30; ++i) {
    const AvatarPose& pose = a.Update(1, {1.4 * kDt * i, 0.0}, i * kStepNs);
    ASSERT_EQ(pose.phase_cycles, 0.0);
    ASSERT_EQ(AvatarFrameAt(pose.phase_cycles, 1), 0);
  }
  EXPECT_LT(AngleDiff(a.Find(1)->heading_rad, 0.0), 1e-9);  // still turns to face travel
}

TEST(AvatarAssign, SequenceByIdIsStableAndNoneStoredMeansNone) {
  AvatarAssigner a;
  EXPECT_EQ(a.Update(1, {0, 0}, 0).sequence, "");
  a.SetSequences({{"b", 2, 10, 1.2}, {"a", 1, 10, 1.4}});
  EXPECT_EQ(a.Find(1)->sequence, "b");  // sorted by name: 1 % 2 -> "b"
  EXPECT_EQ(a.Update(2, {0, 0}, 0).sequence, "a");
  a.SetSequences({{"b", 5, 10, 1.2}, {"c", 6, 10, 1.2}, {"a", 1, 10, 1.4}});
  EXPECT_EQ(a.Find(1)->sequence, "b");  // kept, with the new version
  EXPECT_EQ(a.Find(1)->sequence_version, 5);
  EXPECT_EQ(a.Find(2)->sequence, "a");
}

TEST(AvatarAssign, FrameAtWrapsAnyPhaseIntoTheSequence) {
  EXPECT_EQ(AvatarFrameAt(0.0, 12), 0);
  EXPECT_EQ(AvatarFrameAt(0.999999, 12), 11);
  EXPECT_EQ(AvatarFrameAt(1.5, 12), 6);
  EXPECT_EQ(AvatarFrameAt(-0.25, 12), 9);
  EXPECT_EQ(AvatarFrameAt(std::nan(""), 12), 0);
  EXPECT_EQ(AvatarFrameAt(0.7, 0), 0);
}

TEST(AvatarAssign, OptionsCheckNamesTheField) {
  AvatarAssignOptions o;
  EXPECT_EQ(o.Check(), "");
  o.jump_m = 0;
  EXPECT_NE(o.Check().find("jump_m"), std::string::npos);
  o = {};
  o.standing_speed_mps = std::nan("");
  EXPECT_NE(o.Check().find("standing_speed_mps"), std::string::npos);
}

// Through the real SceneState: a LiDAR foot track walking north gets the stored sequence, its
// heading and phase on the wire; before any sequence is stored it gets none.
TEST(AvatarAssign, SceneState_WalkingPersonCarriesItsAvatarOnTheWire) {
  SceneState state;
  CameraEntry lidar;
  lidar.id = "hdl";
  lidar.kind = SensorKind::kRotatingLidar;
  state.UpsertCamera(lidar);
  const uint64_t session = state.StreamOpened("hdl");
  const int64_t t0 = 1'000'000'000'000;
  auto sweep = [&](int f) {
    auto s = std::make_shared<v1::LidarSweepFrame>();
    s->set_sequence(f + 1);
    s->set_capture_time_ns(t0 + f * kStepNs);
    v1::FootTrack* t = s->add_tracks();
    t->set_track_id(3);
    t->mutable_position()->set_x(4.0);
    t->mutable_position()->set_y(-3.0 + 1.4 * kDt * f);
    for (float c : {0.01f, 0.0f, 0.01f}) t->add_covariance(c);
    return s;
  };
  ASSERT_TRUE(state.AcceptLidarSweep("hdl", sweep(0), t0, session).ok());
  ViewerCursor cursor;
  v1::SceneUpdate update = state.BuildUpdate({}, false, t0, cursor);
  ASSERT_EQ(update.objects_size(), 1);
  EXPECT_EQ(update.objects(0).avatar_sequence(), "");  // nothing stored yet: box/cylinder only
  state.SetAvatarSequences({{"walk", 4, 12, 1.4}});
  for (int f = 1; f <= 30; ++f) ASSERT_TRUE(state.AcceptLidarSweep("hdl", sweep(f), t0 + f * kStepNs, session).ok());
  update = state.BuildUpdate({}, false, t0 + 30 * kStepNs, cursor);
  ASSERT_EQ(update.objects_size(), 1);
  const v1::DynamicObject& o = update.objects(0);
  EXPECT_EQ(o.kind(), 1u);  // person
  EXPECT_EQ(o.avatar_sequence(), "walk");
  EXPECT_EQ(o.avatar_sequence_version(), 4u);
  EXPECT_LT(AngleDiff(o.avatar_heading_rad(), M_PI / 2), 0.05);
  EXPECT_GT(o.avatar_phase_cycles(), 0.0f);
  EXPECT_LT(o.avatar_phase_cycles(), 1.0f);
  EXPECT_EQ(o.avatar_placement(), 0u);
}

}  // namespace
}  // namespace ave
