#include "sensor_agent/sim/scenario.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string Rejection(const std::string& text) {
  auto s = LoadScenarioText(text, "bad.yaml");
  EXPECT_FALSE(s.ok()) << "accepted:\n" << text;
  return s.ok() ? std::string() : std::string(s.status().message());
}

TEST(Scenario, BundledScenariosLoadWithTheirSensorsAndEffects) {
  auto campus = LoadScenario("campus");
  ASSERT_TRUE(campus.ok()) << campus.status();
  EXPECT_EQ(campus->name, "campus");
  EXPECT_NE(campus->seed, 0u);
  for (EffectKind k : {EffectKind::kCameraNoise, EffectKind::kIllumination, EffectKind::kJpegArtefacts, EffectKind::kRollingOcclusion,
                       EffectKind::kWavingVegetation, EffectKind::kGpsNoise, EffectKind::kGpsMultipath, EffectKind::kGpsDropout,
                       EffectKind::kImuNoise, EffectKind::kGyroDrift, EffectKind::kMagneticDisturbance}) {
    EXPECT_TRUE(campus->effects.Has(k)) << EffectName(k);
  }
  EXPECT_FALSE(campus->effects.Has(EffectKind::kLidarRangeNoise)) << "a campus camera scene does not name LiDAR effects";
  ASSERT_EQ(campus->gps_imu.size(), 1u);
  EXPECT_EQ(campus->gps_imu[0].camera_id, "backpack");
  EXPECT_EQ(campus->gps_imu[0].imu_rate_hz, 150);
  ASSERT_TRUE(campus->airborne_lidar.has_value());
  EXPECT_EQ(campus->EffectsForCamera("cam1").Has(EffectKind::kRollingOcclusion), false);
  EXPECT_EQ(campus->EffectsForCamera("backpack").Has(EffectKind::kRollingOcclusion), true);
  EXPECT_DOUBLE_EQ(campus->EffectsForCamera("cam1").Find(EffectKind::kCameraNoise)->Get("sigma", 0), 2.0);

  auto courtyard = LoadScenario("courtyard");
  ASSERT_TRUE(courtyard.ok()) << courtyard.status();
  ASSERT_EQ(courtyard->rotating_lidars.size(), 1u);
  EXPECT_EQ(courtyard->rotating_lidars[0].id, "hdl64");
  EXPECT_EQ(courtyard->rotating_lidars[0].rings, 64);
  EXPECT_NEAR(courtyard->rotating_lidars[0].position_m.z(), courtyard->world.TerrainHeight(-2, -3) + 2.0, 1e-12);
  EXPECT_GE(courtyard->world.movers.size(), 10u);
  EXPECT_GE(courtyard->world.trees.size(), 1u);
  EXPECT_TRUE(courtyard->effects.Has(EffectKind::kLidarRingPattern));

  auto studio = LoadScenario("studio");
  ASSERT_TRUE(studio.ok()) << studio.status();
  ASSERT_TRUE(studio->studio.has_value());
  EXPECT_EQ(studio->studio->cameras, 13);
  EXPECT_TRUE(studio->studio->overhead);
  EXPECT_EQ(studio->studio->actor, StudioActor::kBody);  // a person's body unless `actor: boxes`

  auto minimal = LoadScenario("minimal");
  ASSERT_TRUE(minimal.ok()) << minimal.status();
  EXPECT_TRUE(minimal->effects.empty());
}

TEST(ScenarioBadInput, UnknownEffectIsRejectedWithLineAndField) {
  const std::string msg = Rejection(R"(name: t
effects:
  - {name: camera_noise}
  - {name: fog, params: {density: 0.1}}
)");
  EXPECT_THAT(msg, StartsWith("bad.yaml:4: effects[1].name: unknown effect 'fog'"));
  EXPECT_THAT(msg, HasSubstr("camera_noise"));
  EXPECT_THAT(Rejection("name: t\neffects: [camera_noise, fog]\n"), StartsWith("bad.yaml:2: effects[1].name: unknown effect 'fog'"));
}

TEST(ScenarioBadInput, TypoedEffectParameterSuggestsTheRightOne) {
  EXPECT_THAT(Rejection("name: t\neffects:\n  - {name: camera_noise, params: {sigmaa: 2}}\n"),
              StartsWith("bad.yaml:3: effects[0].params.sigmaa: unknown key; did you mean 'sigma'?"));
  EXPECT_THAT(Rejection("name: t\neffects:\n  - {name: camera_noise}\n  - {name: camera_noise}\n"),
              StartsWith("bad.yaml:4: effects[1].name: effect 'camera_noise' is named twice"));
  EXPECT_THAT(Rejection("name: t\neffects:\n  - {name: camera_noise, params: {sigma: -1}}\n"),
              StartsWith("bad.yaml:3: effects[0].params.sigma: must be > 0"));
  for (const char* samples : {"2.5", "0", "6"})
    EXPECT_THAT(Rejection(std::string("name: t\neffects:\n  - {name: pixel_area, params: {samples: ") + samples + "}}\n"),
                StartsWith("bad.yaml:3: effects[0].params.samples: must be a whole number of samples per axis from 1 to 5"))
        << samples;
}

TEST(ScenarioBadInput, NegativeSensorRatesAreRejected) {
  EXPECT_EQ(Rejection(R"(name: t
cameras:
  - {id: c1, position: [0, -20], look_at: [0, 0]}
sensors:
  gps_imu:
    - camera: c1
      gps_rate_hz: -5
)"),
            "bad.yaml:7: sensors.gps_imu[0].gps_rate_hz: must be > 0");
  EXPECT_EQ(Rejection("name: t\nsensors:\n  rotating_lidar:\n    - {id: l, position: [0, 0], rate_hz: -10}\n"),
            "bad.yaml:4: sensors.rotating_lidar[0].rate_hz: must be > 0");
  EXPECT_EQ(Rejection("name: t\nsensors:\n  studio: {fps: 0}\n"), "bad.yaml:3: sensors.studio.fps: must be > 0");
  EXPECT_EQ(Rejection("name: t\nsensors:\n  studio: {actor: robot}\n"), "bad.yaml:3: sensors.studio.actor: must be body or boxes, not 'robot'");
}

TEST(ScenarioBadInput, SensorMistakesNameTheirField) {
  EXPECT_THAT(Rejection("name: t\nsensors:\n  gps_imu:\n    - {camera: ghost}\n"),
              StartsWith("bad.yaml:4: sensors.gps_imu[0].camera: no camera 'ghost'"));
  EXPECT_THAT(Rejection("name: t\nsensors:\n  rotating_lidr: []\n"),
              StartsWith("bad.yaml:3: sensors.rotating_lidr: unknown key; did you mean 'rotating_lidar'?"));
  EXPECT_THAT(Rejection("name: t\nbuildings:\n  - {id: b, position: [0, 0], size: [10, 10], height_m: 5}\nsensors:\n  rotating_lidar:\n    - {id: l, position: [1, 1]}\n"),
              StartsWith("bad.yaml:6: sensors.rotating_lidar[0].position: the LiDAR is inside building 'b'"));
  EXPECT_THAT(Rejection("name: t\nseed: -3\n"), StartsWith("bad.yaml:2: seed: must be a whole number"));
  EXPECT_THAT(Rejection("name: t\neffects:\n  - {name: camera_noise, cameras: [nope]}\n"),
              StartsWith("bad.yaml:3: effects[0].cameras[0]: no camera 'nope'"));
}

TEST(ScenarioBadInput, SceneErrorsComeThroughWithTheFileName) {
  auto s = LoadScenarioText("name: t\npeople:\n  - {path: []}\n", "my.yaml");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.status().message()), StartsWith("my.yaml:3: people[0].path: is empty"));
  auto missing = LoadScenario("/no/such/scenario.yaml");
  EXPECT_FALSE(missing.ok());
}

}  // namespace
}  // namespace ave::sim
