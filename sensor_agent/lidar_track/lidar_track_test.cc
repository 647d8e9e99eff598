// Hard cases of the LiDAR people tracker (issue 16 part 5) on small synthetic sweeps (16 rings x
// 360 azimuth bins, generated here) and on the simulator (a tiny scenario that names
// waving_vegetation).
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <set>

#include <gtest/gtest.h>

#include "sensor_agent/lidar_track/lidar_track_truth.h"
#include "sensor_agent/lidar_track/people_tracker.h"
#include "sensor_agent/lidar_track/range_image.h"
#include "sensor_agent/lidar_track/sequence_post.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::lidar_track {
namespace {

using testing::SyntheticPerson;
using testing::SyntheticSite;

constexpr double kRate = 10;

LidarPeopleTrackerOptions SmallOptions() {
  LidarPeopleTrackerOptions o;
  o.foreground.cols = 360;
  return o;
}

SyntheticPerson Walker(uint32_t id, std::vector<std::pair<double, Eigen::Vector2d>> path) {
  SyntheticPerson p;
  p.id = id;
  p.path = std::move(path);
  return p;
}

// The confirmed track within `radius_m` of each person (by truth label), per sweep; 0 when none.
struct SiteRun {
  std::vector<lidar::FootTracks> online;
  std::vector<lidar::LidarSweep> sweeps;  // kept only when asked
  std::vector<std::map<uint32_t, uint32_t>> id_of_person;
  std::vector<double> recall;  // per sweep: foreground recall on people's points
  std::vector<double> world_error_m;  // matched tracks' world distance to truth
  int max_confirmed = 0;
};

std::map<uint32_t, uint32_t> MatchPeople(const lidar::LidarSweep& sweep, const std::vector<lidar::FootTrack>& tracks,
                                         const Rigid3d& world_from_ground, double radius_m, std::vector<double>* errors = nullptr) {
  std::map<uint32_t, uint32_t> out;
  for (const auto& [label, foot] : sweep.truth_feet_in_world) {
    double best = radius_m;
    uint32_t id = 0;
    for (const lidar::FootTrack& t : tracks) {
      if (!t.confirmed) continue;
      const Eigen::Vector3d w = world_from_ground * Eigen::Vector3d(t.xy_m.x(), t.xy_m.y(), 0);
      const double d = (w.head<2>() - foot.head<2>()).norm();
      if (d < best) best = d, id = t.id;
    }
    out[label] = id;
    if (errors && id) errors->push_back(best);
  }
  return out;
}

SiteRun RunSite(const SyntheticSite& site, double seconds, LidarPeopleTrackerOptions options = SmallOptions(), bool keep_sweeps = false) {
  LidarPeopleTracker tracker(options);
  SiteRun run;
  const int n = static_cast<int>(seconds * kRate);
  for (int f = 0; f < n; ++f) {
    const lidar::LidarSweep sweep = testing::MakeSyntheticSweep(site, f / kRate, 11);
    absl::StatusOr<lidar::FootTracks> out = tracker.Process(sweep);
    EXPECT_TRUE(out.ok()) << out.status();
    if (!out.ok()) break;
    int confirmed = 0;
    for (const auto& t : out->tracks) confirmed += t.confirmed;
    run.max_confirmed = std::max(run.max_confirmed, confirmed);
    run.id_of_person.push_back(MatchPeople(sweep, out->tracks, out->world_from_ground, 0.5, &run.world_error_m));
    testing::PointScores ps;
    ps.Add(sweep, tracker.last_foreground());
    run.recall.push_back(ps.tp + ps.fn ? ps.Recall() : -1);
    run.online.push_back(*out);
    if (keep_sweeps) run.sweeps.push_back(sweep);
  }
  return run;
}

uint32_t Label(uint32_t id) { return sim::kMoverIdBase + id; }

// Distinct non-zero ids a person had between two sweeps.
std::set<uint32_t> IdsOf(const SiteRun& run, uint32_t id, int from, int to) {
  std::set<uint32_t> ids;
  for (int f = from; f < to && f < static_cast<int>(run.id_of_person.size()); ++f) {
    const auto it = run.id_of_person[f].find(Label(id));
    if (it != run.id_of_person[f].end() && it->second) ids.insert(it->second);
  }
  return ids;
}

double TrackedShare(const SiteRun& run, uint32_t id, int from, int to) {
  int n = 0, tracked = 0;
  for (int f = from; f < to && f < static_cast<int>(run.id_of_person.size()); ++f, ++n) tracked += run.id_of_person[f].at(Label(id)) != 0;
  return n ? static_cast<double>(tracked) / n : 0;
}

TEST(RangeImage, UnusablePointsGetNoPixelAndTheNearestWins) {
  lidar::LidarSweep sweep;
  sweep.rings = 2;
  auto add = [&](float range, float az, uint16_t ring) {
    lidar::SweepPoint p;
    p.range_m = range;
    p.azimuth_rad = az;
    p.ring = ring;
    p.p_in_sensor = Eigen::Vector3f(0, std::isfinite(range) ? range : 1, 0);
    sweep.points.push_back(p);
  };
  add(0, 0, 0);                                          // range 0
  add(-1, 0.1f, 0);                                      // negative
  add(std::numeric_limits<float>::quiet_NaN(), 0.2f, 0);  // not a number
  add(130.5f, 0.3f, 1);                                  // beyond max range
  add(130, 0.3f, 1);                                     // at max range: usable
  add(5, 1, 1);
  add(4, 1, 1);  // same pixel, nearer
  absl::StatusOr<RangeImage> img = BuildRangeImage(sweep, 64, 130);
  ASSERT_TRUE(img.ok()) << img.status();
  for (int i = 0; i < 4; ++i) EXPECT_EQ(img->pixel_of_point[i], -1) << i;
  EXPECT_GE(img->pixel_of_point[4], 0);
  EXPECT_EQ(img->pixel_of_point[5], img->pixel_of_point[6]);
  EXPECT_EQ(img->nearest_point[img->pixel_of_point[5]], 6);
  EXPECT_FLOAT_EQ(img->range_m[img->pixel_of_point[5]], 4);
  int returns = 0;
  for (float r : img->range_m) returns += r > 0;
  EXPECT_EQ(returns, 2);  // everything else is "no return"

  sweep.points[2].ring = 2;
  absl::StatusOr<RangeImage> bad = BuildRangeImage(sweep, 64, 130);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("points[2].ring"), std::string::npos) << bad.status();
}

TEST(RangeImage, AzimuthWrapsIntoColumnZero) {
  const double two_pi = 2 * std::numbers::pi;
  EXPECT_EQ(AzimuthColumn(0, 360), 0);
  EXPECT_EQ(AzimuthColumn(static_cast<float>(two_pi), 360), 0);
  EXPECT_EQ(AzimuthColumn(static_cast<float>(two_pi - 1e-4), 360), 0);
  EXPECT_EQ(AzimuthColumn(-1e-4f, 360), 0);
  EXPECT_EQ(AzimuthColumn(static_cast<float>(-two_pi / 360), 360), 359);
  EXPECT_EQ(AzimuthColumn(static_cast<float>(std::numbers::pi), 360), 180);
  EXPECT_EQ(AzimuthColumn(std::numeric_limits<float>::quiet_NaN(), 360), 0);
}

TEST(RangeForeground, MrfRemovesAnIsolatedSpuriousReturnTheMixtureKeeps) {
  SyntheticSite site;
  for (const int iterations : {0, 2}) {
    ForegroundOptions o;
    o.cols = 360;
    o.mrf_iterations = iterations;
    RangeForeground fg(o);
    for (int f = 0; f < 15; ++f) {
      ASSERT_TRUE(fg.Segment(testing::MakeSyntheticSweep(site, f / kRate, 3)).ok());
      fg.Learn({});
    }
    lidar::LidarSweep sweep = testing::MakeSyntheticSweep(site, 1.5, 3);
    size_t spurious = 0;
    for (size_t i = 0; i < sweep.points.size(); ++i) {
      if (sweep.points[i].ring == 2 && sweep.points[i].range_m > 20) {
        spurious = i;
        break;
      }
    }
    lidar::SweepPoint& p = sweep.points[spurious];
    p.p_in_sensor *= 8.f / p.range_m;  // a lone return 8 m out in front of the wall
    p.range_m = 8;
    absl::StatusOr<std::vector<uint8_t>> labels = fg.Segment(sweep);
    ASSERT_TRUE(labels.ok()) << labels.status();
    int n = 0;
    for (uint8_t v : *labels) n += v;
    if (iterations == 0) {
      EXPECT_EQ((*labels)[spurious], 1) << "the mixture alone sees the outlier";
      EXPECT_EQ(n, 1);
    } else {
      EXPECT_EQ(n, 0) << "the MRF's spatial term outvotes a single outlying pixel";
    }
  }
}

TEST(LidarPeopleTracker, SweepWithoutForegroundGivesNoTracks) {
  SyntheticSite site;
  LidarPeopleTracker tracker(SmallOptions());
  for (int f = 0; f < 60; ++f) {
    const lidar::LidarSweep sweep = testing::MakeSyntheticSweep(site, f / kRate, 3);
    absl::StatusOr<lidar::FootTracks> out = tracker.Process(sweep);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_TRUE(out->tracks.empty()) << "sweep " << f;
    ASSERT_EQ(out->point_track_id.size(), sweep.points.size());
    for (uint32_t id : out->point_track_id) ASSERT_EQ(id, 0u);
  }
  // An empty sweep (every return dropped) is fine too.
  lidar::LidarSweep empty;
  empty.rings = 16;
  empty.t_ns = 7'000'000'000;
  absl::StatusOr<lidar::FootTracks> out = tracker.Process(empty);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_TRUE(out->tracks.empty());
}

TEST(LidarPeopleTracker, NoReturnsAndBadPointsAroundAPersonAreHarmless) {
  SyntheticSite site;
  site.wall_height_m = 0;  // no wall: every ray above the horizon is "no return"
  site.people = {Walker(1, {{0, {-6, 6}}, {10, {6, 6}}})};
  LidarPeopleTracker tracker(SmallOptions());
  int tracked = 0;
  for (int f = 0; f < 100; ++f) {
    lidar::LidarSweep sweep = testing::MakeSyntheticSweep(site, f / kRate, 5);
    for (float r : {0.f, -3.f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), 500.f}) {
      lidar::SweepPoint p;
      p.range_m = r;
      p.ring = 12;
      p.azimuth_rad = 0.3f;
      p.p_in_sensor = Eigen::Vector3f(0, 1, -1) * (std::isfinite(r) ? r : 1.f);
      sweep.points.push_back(p);
    }
    absl::StatusOr<lidar::FootTracks> out = tracker.Process(sweep);
    ASSERT_TRUE(out.ok()) << out.status();
    for (size_t i = sweep.points.size() - 5; i < sweep.points.size(); ++i) EXPECT_EQ(out->point_track_id[i], 0u);
    tracked += MatchPeople(sweep, out->tracks, out->world_from_ground, 0.4)[Label(1)] != 0;
  }
  EXPECT_GT(tracked, 80);  // all but the warm-up and the birth test
}

TEST(LidarPeopleTracker, PersonCrossingTheAzimuthWrapKeepsOneId) {
  SyntheticSite site;
  // Along y = 7 through x = 0: azimuth 0 (north, +y) is crossed at t = 5 s.
  site.people = {Walker(1, {{0, {-7, 7}}, {10, {7, 7}}})};
  const SiteRun run = RunSite(site, 10);
  EXPECT_EQ(IdsOf(run, 1, 25, 100).size(), 1u);
  EXPECT_GT(TrackedShare(run, 1, 25, 100), 0.95);
  EXPECT_EQ(run.max_confirmed, 1);
  // Its points carry its id on both sides of the wrap.
  const lidar::FootTracks& at_wrap = run.online[50];
  std::set<uint32_t> ids(at_wrap.point_track_id.begin(), at_wrap.point_track_id.end());
  ids.erase(0);
  EXPECT_EQ(ids.size(), 1u);
}

TEST(LidarPeopleTracker, ShoulderToShoulderWalkersKeepTheirIdsWhenTheyPart) {
  SyntheticSite site;
  // Walking away from the sensor side by side (both in view): from 3 m apart to 0.65 m between
  // centres (a hand's width between the bodies), together for 4 s, then parting again.
  site.people = {Walker(1, {{0, {-2.5, 3}}, {3, {-0.325, 5.5}}, {7, {-0.325, 10}}, {10, {-2, 12.5}}, {13, {-3.5, 14}}}),
                 Walker(2, {{0, {2.5, 3}}, {3, {0.325, 5.5}}, {7, {0.325, 10}}, {10, {2, 12.5}}, {13, {3.5, 14}}})};
  const SiteRun run = RunSite(site, 13);
  const std::set<uint32_t> a0 = IdsOf(run, 1, 20, 30), b0 = IdsOf(run, 2, 20, 30);
  ASSERT_EQ(a0.size(), 1u);
  ASSERT_EQ(b0.size(), 1u);
  EXPECT_NE(*a0.begin(), *b0.begin());
  // After parting, each has its own id back.
  EXPECT_EQ(IdsOf(run, 1, 110, 130), a0);
  EXPECT_EQ(IdsOf(run, 2, 110, 130), b0);
  // Together they stay tracked (the merged blob is split by the two predictions).
  EXPECT_GT(TrackedShare(run, 1, 30, 70), 0.8);
  EXPECT_GT(TrackedShare(run, 2, 30, 70), 0.8);
}

TEST(LidarPeopleTracker, PersonStandingStill30sNeitherMeltsNorIsLost) {
  SyntheticSite site;
  site.people = {Walker(1, {{0, {-6, 7}}, {3, {-2, 7}}, {33, {-2, 7}}, {36, {3, 7}}})};
  const SiteRun run = RunSite(site, 37);
  EXPECT_EQ(IdsOf(run, 1, 10, 370).size(), 1u);
  EXPECT_GT(TrackedShare(run, 1, 10, 370), 0.98);
  // Still foreground at the end of the 30 s.
  EXPECT_GT(run.recall[320], 0.7);
  // Without the tracker's feedback the plain mixture learns the person into the background.
  LidarPeopleTrackerOptions plain = SmallOptions();
  plain.freeze_background_under_tracks = false;
  const SiteRun melted = RunSite(site, 33, plain);
  EXPECT_LT(melted.recall[320], 0.3);
}

TEST(SequencePostProcessing, PersonOccludedFor2sIsBridgedWithItsId) {
  SyntheticSite site;
  site.sensor_height_m = 1.5;  // below the people's heads, or A's head would show above B
  // B walks in and stops 4 m in front of the sensor; A walks by 12 m out and spends about 2 s
  // entirely in B's shadow.
  site.people = {Walker(1, {{0, {-6, 12}}, {20, {6, 12}}}),               // 0.6 m/s at 12 m
                 Walker(2, {{0, {-3, 4}}, {3, {0, 4}}, {20, {0, 4}}})};  // then standing
  site.people[1].radius_m = 0.3;
  const SiteRun run = RunSite(site, 20, SmallOptions(), true);
  // How long A is really hidden (truth), and where.
  int hidden = 0, longest = 0, first_hidden = -1;
  for (size_t f = 0; f < run.sweeps.size(); ++f) {
    int pts = 0;
    for (const auto& p : run.sweeps[f].points) pts += p.truth_label == Label(1);
    hidden = pts == 0 ? hidden + 1 : 0;
    if (hidden > longest) longest = hidden, first_hidden = static_cast<int>(f) - hidden + 1;
  }
  ASSERT_GE(longest, 18) << "the scene should hide A for about 2 s";
  ASSERT_GT(first_hidden, 30);
  const int reappear = first_hidden + longest;
  const PostProcessed post = BridgeAndPrune(run.online);
  auto id_near = [&](int f) {
    return MatchPeople(run.sweeps[f], post.tracks[f], run.online[f].world_from_ground, 0.5)[Label(1)];
  };
  const uint32_t before = id_near(first_hidden - 5);
  const uint32_t after = id_near(std::min<int>(reappear + 15, run.sweeps.size() - 1));
  EXPECT_NE(before, 0u);
  EXPECT_EQ(before, after);
  // B is never confused with A.
  EXPECT_NE(MatchPeople(run.sweeps[first_hidden + 5], post.tracks[first_hidden + 5], run.online[0].world_from_ground, 0.5)[Label(2)],
            before);
}

TEST(SequencePostProcessing, ShortTracksAreRemovedLongOnesKept) {
  std::vector<lidar::FootTracks> seq(40);
  for (int f = 0; f < 40; ++f) {
    seq[f].t_ns = f * 100'000'000LL;
    lidar::FootTrack a;
    a.id = 1;
    a.confirmed = true;
    a.xy_m = {0.1 * f, 0};
    a.velocity_mps = {1, 0};
    seq[f].tracks.push_back(a);
    if (f >= 10 && f < 15) {
      lidar::FootTrack b = a;
      b.id = 2;
      b.xy_m = {5, 5};
      seq[f].tracks.push_back(b);
    }
  }
  const PostProcessed post = BridgeAndPrune(seq);
  EXPECT_EQ(post.id_map.at(1), 1u);
  EXPECT_EQ(post.id_map.at(2), 0u);
  EXPECT_EQ(post.removed_tracks, 1);
  for (const auto& frame : post.tracks) {
    ASSERT_EQ(frame.size(), 1u);
    EXPECT_EQ(frame[0].id, 1u);
  }
}

TEST(LidarPeopleTracker, TiltedSensorTracksInTheWorld) {
  SyntheticSite site;
  site.tilt_deg = 5;
  site.people = {Walker(1, {{0, {-5, 8}}, {10, {5, 6}}}), Walker(2, {{0, {7, -4}}, {10, {-2, -8}}})};
  const SiteRun run = RunSite(site, 10);
  ASSERT_FALSE(run.world_error_m.empty());
  double sum = 0;
  for (double e : run.world_error_m) sum += e;
  EXPECT_LT(sum / run.world_error_m.size(), 0.15);
  EXPECT_EQ(IdsOf(run, 1, 25, 100).size(), 1u);
  EXPECT_EQ(IdsOf(run, 2, 25, 100).size(), 1u);
  EXPECT_GT(TrackedShare(run, 1, 25, 100), 0.9);
  // The ground found in the sensor frame is tilted by 5 degrees, 2 m below.
  LidarPeopleTracker tracker(SmallOptions());
  ASSERT_TRUE(tracker.Process(testing::MakeSyntheticSweep(site, 0, 1)).ok());
  const double tilt = std::acos(tracker.ground()->normal_in_sensor.z()) * 180 / std::numbers::pi;
  EXPECT_NEAR(tilt, 5, 0.5);
  EXPECT_NEAR(tracker.ground()->d, 2, 0.05);
}

TEST(LidarPeopleTracker, SensorFarFromTheOriginKeepsCentimetres) {
  SyntheticSite site;
  site.world_from_site_m = Eigen::Vector3d(1.0e6, -2.0e6, 350);
  site.people = {Walker(1, {{0, {-5, 8}}, {10, {5, 6}}})};
  const SiteRun run = RunSite(site, 10);
  ASSERT_GT(run.world_error_m.size(), 80u);
  double sum = 0;
  for (double e : run.world_error_m) sum += e;
  EXPECT_LT(sum / run.world_error_m.size(), 0.15);
  EXPECT_EQ(IdsOf(run, 1, 25, 100).size(), 1u);
}

TEST(LidarPeopleTracker, BadOptionsAreNamed) {
  LidarPeopleTrackerOptions o = SmallOptions();
  o.foreground.components = 0;
  LidarPeopleTracker tracker(o);
  absl::StatusOr<lidar::FootTracks> out = tracker.Process(testing::MakeSyntheticSweep(SyntheticSite{}, 0, 1));
  ASSERT_FALSE(out.ok());
  EXPECT_NE(out.status().message().find("foreground.components"), std::string::npos) << out.status();
}

TEST(LidarPeopleTracker, WorksBehindTheSweepTrackerSeam) {
  SyntheticSite site;
  site.people = {Walker(1, {{0, {-5, 8}}, {5, {0, 8}}})};
  lidar::SweepTracker track = MakeSweepTracker(SmallOptions());
  int confirmed = 0;
  for (int f = 0; f < 30; ++f) {
    absl::StatusOr<lidar::FootTracks> out = track(testing::MakeSyntheticSweep(site, f / kRate, 2));
    ASSERT_TRUE(out.ok()) << out.status();
    for (const auto& t : out->tracks) confirmed += t.confirmed;
  }
  EXPECT_GT(confirmed, 8);
}

// The simulator: a small yard with swaying trees (waving_vegetation) and one walker. The trees
// must never become people; the walker must be tracked.
constexpr char kVegetationYard[] = R"(
name: vegetation-yard
seed: 5
terrain:
  half_extent_m: 30
  analytic: {amplitude_m: 0, tilt_x: 0, tilt_y: 0}
trees:
  - {position: [5, 4], trunk_height_m: 1.2, crown_radius_m: 2.0}
  - {position: [-6, 3], trunk_height_m: 1.0, crown_radius_m: 1.8}
  - {position: [2, -7], trunk_height_m: 1.5, crown_radius_m: 2.2}
people:
  - {id: 1, path: [[-8, -2], [8, -2]], speed_mps: 1.3}
sensors:
  rotating_lidar:
    - {id: l16, position: [0, 0], height_above_ground_m: 2.0, rate_hz: 10, rings: 16, azimuth_steps: 360, max_range_m: 40}
effects:
  - {name: waving_vegetation, params: {amplitude_m: 0.6, frequency_hz: 0.7}}
  - {name: lidar_range_noise, params: {sigma_m: 0.02}}
)";

TEST(LidarPeopleTracker, WavingVegetationInTheSimulatorNeverBecomesAPerson) {
  absl::StatusOr<sim::Scenario> sc = sim::LoadScenarioText(kVegetationYard, "vegetation-yard.yaml");
  ASSERT_TRUE(sc.ok()) << sc.status();
  ASSERT_TRUE(sc->effects.Find(sim::EffectKind::kWavingVegetation));
  const sim::RotatingLidarSpec& spec = sc->rotating_lidars.at(0);
  LidarPeopleTracker tracker(SmallOptions());
  std::set<uint32_t> confirmed_ids;
  int vegetation_points = 0, vegetation_fg = 0, tracked = 0;
  for (int f = 0; f < 80; ++f) {
    const lidar::LidarSweep sweep =
        testing::SweepFromSimFrame(sim::SimulateRotatingLidarFrame(sc->world, spec, sc->effects, sc->seed, f / kRate), spec);
    ASSERT_EQ(sweep.ring_elevation_rad.size(), 16u);
    absl::StatusOr<lidar::FootTracks> out = tracker.Process(sweep);
    ASSERT_TRUE(out.ok()) << out.status();
    for (const auto& t : out->tracks) {
      if (t.confirmed) confirmed_ids.insert(t.id);
    }
    tracked += MatchPeople(sweep, out->tracks, out->world_from_ground, 0.5)[Label(1)] != 0;
    if (f < 20) continue;
    for (size_t i = 0; i < sweep.points.size(); ++i) {
      if (sweep.points[i].truth_label != sim::kLidarVegetationId) continue;
      ++vegetation_points;
      vegetation_fg += tracker.last_foreground()[i];
      EXPECT_EQ(out->point_track_id[i], 0u) << "a tree point labelled as a person, sweep " << f;
    }
  }
  ASSERT_GT(vegetation_points, 1000);
  EXPECT_LT(static_cast<double>(vegetation_fg) / vegetation_points, 0.05);
  EXPECT_EQ(confirmed_ids.size(), 1u);  // the walker only
  EXPECT_GT(tracked, 60);
}

}  // namespace
}  // namespace ave::lidar_track
