#include "sensor_agent/source/frame_source.h"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "sensor_agent/sim/footage.h"
#include "sensor_agent/sim/scenario.h"

namespace ave {
namespace {

using ::testing::HasSubstr;

TEST(OpenSource, SimulatedCampusCameraGivesFramesWithItsPose) {
  auto source = OpenSource("sim:campus#cam2", {.fps = 5});
  ASSERT_TRUE(source.ok()) << source.status();
  const PinholeIntrinsics k = (*source)->intrinsics();
  auto a = (*source)->Next();
  auto b = (*source)->Next();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->width, k.width);
  EXPECT_EQ(a->height, k.height);
  EXPECT_EQ(a->bgr.size(), size_t(k.width) * k.height * 3);
  ASSERT_TRUE(a->world_from_camera.has_value());
  EXPECT_NEAR(b->scene_time_s - a->scene_time_s, 0.2, 1e-12);
  EXPECT_GE(b->capture_time_ns, a->capture_time_ns);
  EXPECT_FALSE((*source)->live());
}

TEST(OpenSource, MovingScenarioCameraCarriesItsPathPose) {
  auto source = OpenSource("sim:campus#backpack", {.fps = 2});
  ASSERT_TRUE(source.ok()) << source.status();
  auto a = (*source)->Next();
  auto b = (*source)->Next();
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE(a->world_from_camera && b->world_from_camera);
  // The backpack walks at 1.4 m/s: half a second apart, 0.7 m further along.
  EXPECT_NEAR((b->world_from_camera->translation - a->world_from_camera->translation).head<2>().norm(), 0.7, 1e-6);
  EXPECT_NE(a->bgr, b->bgr);
}

TEST(OpenSource, ScenarioFilesAndOtherBundledScenarios) {
  auto courtyard = OpenSource("sim:courtyard#cam1", {.fps = 5});
  ASSERT_TRUE(courtyard.ok()) << courtyard.status();
  EXPECT_TRUE((*courtyard)->Next().ok());
  const std::string path = (std::filesystem::temp_directory_path() / "ave_source_scenario.yaml").string();
  {
    std::ofstream out(path);
    out << "name: tiny\ncameras:\n  - {id: c, width: 64, height: 48, position: [0, -10], height_above_ground_m: 2, look_at: [0, 0]}\n";
  }
  auto file = OpenSource("sim:" + path + "#c", {.fps = 5});
  ASSERT_TRUE(file.ok()) << file.status();
  auto frame = (*file)->Next();
  ASSERT_TRUE(frame.ok());
  EXPECT_EQ(frame->width, 64);
  {
    std::ofstream out(path);
    out << "name: tiny\ncameras:\n  - {id: c, fps: -1, position: [0, -10], look_at: [0, 0]}\n";
  }
  EXPECT_THAT(std::string(OpenSource("sim:" + path + "#c", {}).status().message()),
              HasSubstr("ave_source_scenario.yaml:3: cameras[0].fps: must be > 0"));
  std::filesystem::remove(path);
}

TEST(OpenSource, BadSpecsNameTheProblem) {
  EXPECT_THAT(std::string(OpenSource("sim:campus#nope", {}).status().message()), HasSubstr("no camera 'nope'"));
  EXPECT_THAT(std::string(OpenSource("sim:mars#cam1", {}).status().message()), HasSubstr("unknown scenario"));
  EXPECT_THAT(std::string(OpenSource("ftp://x", {}).status().message()), HasSubstr("unknown scheme"));
  EXPECT_THAT(std::string(OpenSource("file:/no/such/video.avi", {}).status().message()), HasSubstr("cannot open"));
  EXPECT_THAT(std::string(OpenSource("sim:campus#cam1", {.fps = 0}).status().message()), HasSubstr("fps"));
  // Issue 14: a device number past INT_MAX threw out of std::stoi (abort); a field of view out of
  // (0, 180) gave infinite or negative focal lengths.
  EXPECT_THAT(std::string(OpenSource("v4l2:99999999999999999999", {}).status().message()),
              HasSubstr("'v4l2:99999999999999999999': device number out of range"));
  for (double fov : {0.0, 180.0, -5.0, double{NAN}}) {
    EXPECT_THAT(std::string(OpenSource("sim:campus#cam1", {.default_fov_deg = fov}).status().message()), HasSubstr("--fov"))
        << fov;
  }
  // A file that is not a video: refused at open or ends after 0 frames, naming the source.
  const std::string junk = (std::filesystem::temp_directory_path() / "ave_source_junk.avi").string();
  std::ofstream(junk) << "this is not a video\n";
  auto source = OpenSource("file:" + junk, {});
  const absl::Status s = source.ok() ? (*source)->Next().status() : source.status();
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr(junk));
  std::filesystem::remove(junk);
}

TEST(OpenSource, VideoFileIsReadToItsEnd) {
  const std::string path = (std::filesystem::temp_directory_path() / "ave_source_test.avi").string();
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10, cv::Size(160, 120));
    ASSERT_TRUE(writer.isOpened());
    for (int i = 0; i < 7; ++i) writer.write(cv::Mat(120, 160, CV_8UC3, cv::Scalar(i * 30, 100, 200)));
  }
  auto source = OpenSource("file:" + path, {});
  ASSERT_TRUE(source.ok()) << source.status();
  int frames = 0;
  absl::StatusOr<CapturedFrame> f;
  while ((f = (*source)->Next()).ok()) {
    EXPECT_EQ(f->width, 160);
    EXPECT_EQ(f->height, 120);
    ++frames;
  }
  EXPECT_EQ(frames, 7);
  EXPECT_EQ(f.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_EQ((*source)->intrinsics().width, 160);
  std::filesystem::remove(path);
}

// Issue 19: a sim camera's pre-rendered footage is played at the scenario's times, as the JPEG
// bytes a camera delivers and their decoded image, with the scenario's true pose; past its end
// the source renders live, and a stale file is not played at all.
class FootageSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("ave_footage_source_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    scenario_ = (dir_ / "walk.yaml").string();
    std::ofstream(scenario_) << "name: walk\nseed: 3\ncameras:\n"
                                "  - {id: c, width: 80, height: 60, position: [0, -20], height_above_ground_m: 4, look_at: [0, 5]}\n"
                                "people:\n  - {id: 1, path: [[-10, 0], [10, 0]], speed_mps: 1.4}\n"
                                "effects:\n  - {name: camera_noise, params: {sigma: 2.0}}\n  - {name: jpeg_artefacts, params: {quality: 70}}\n";
    footage_ = (dir_ / "c.avfoot").string();
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  // Footage of `frames` frames at `fps` through the simulator itself.
  void MakeFootage(double fps, int frames) {
    absl::StatusOr<sim::Scenario> s = sim::LoadScenario(scenario_);
    ASSERT_TRUE(s.ok()) << s.status();
    absl::StatusOr<sim::FootageKey> key = sim::MakeFootageKey(scenario_, "c", fps, 0, 80);
    ASSERT_TRUE(key.ok()) << key.status();
    const sim::SimulatedCamera camera(s->world, *s->world.FindCamera("c"), s->EffectsForCamera("c"), s->seed);
    ASSERT_TRUE(sim::WriteFootage(footage_, *key, camera, frames).ok());
  }
  std::filesystem::path dir_;
  std::string scenario_, footage_;
};

TEST_F(FootageSourceTest, PlaysTheFootageAtTheScenarioTimesThenRendersLive) {
  MakeFootage(5, 3);
  absl::StatusOr<sim::Footage> footage = sim::Footage::Open(footage_, *sim::MakeFootageKey(scenario_, "c", 5, 0, 80));
  ASSERT_TRUE(footage.ok()) << footage.status();
  for (bool ahead : {false, true}) {
    auto played = OpenSource("sim:" + scenario_ + "#c", {.fps = 5, .sim_render_ahead = ahead, .sim_footage = footage_});
    auto live = OpenSource("sim:" + scenario_ + "#c", {.fps = 5});
    ASSERT_TRUE(played.ok() && live.ok()) << played.status();
    EXPECT_THAT((*played)->description(), HasSubstr("footage " + footage_ + ", 3 frames"));
    for (int k = 0; k < 5; ++k) {
      absl::StatusOr<CapturedFrame> p = (*played)->Next(), l = (*live)->Next();
      ASSERT_TRUE(p.ok() && l.ok()) << p.status();
      EXPECT_EQ(p->scene_time_s, l->scene_time_s);
      ASSERT_TRUE(p->world_from_camera && l->world_from_camera);
      EXPECT_TRUE(p->world_from_camera->translation == l->world_from_camera->translation) << "the truth is the scenario's";
      if (k < 3) {
        EXPECT_EQ(p->jpeg, footage->Jpeg(k)) << "frame " << k;
        EXPECT_EQ(p->jpeg_quality, 70) << "the camera's own JPEG (its jpeg_artefacts effect)";
        const cv::Mat decoded = cv::imdecode(p->jpeg, cv::IMREAD_COLOR);
        ASSERT_EQ(decoded.total() * 3, p->bgr.size());
        EXPECT_TRUE(std::equal(p->bgr.begin(), p->bgr.end(), decoded.data)) << "bgr is the decoded JPEG";
        EXPECT_EQ(p->bgr, l->bgr) << "which is the live render, bit for bit";
      } else {
        EXPECT_TRUE(p->jpeg.empty()) << "past the footage's end: rendered live";
        EXPECT_EQ(p->bgr, l->bgr);
      }
    }
  }
}

TEST_F(FootageSourceTest, StaleOrCorruptFootageIsLoggedByNameAndNotPlayed) {
  MakeFootage(5, 3);
  // Another frame rate than the footage's: every frame rendered live, the file named in the log.
  ::testing::internal::CaptureStderr();
  auto source = OpenSource("sim:" + scenario_ + "#c", {.fps = 10, .sim_footage = footage_});
  std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(source.ok()) << source.status();
  EXPECT_THAT(log, HasSubstr(footage_ + ": stale footage: fps 5, not 10; rendering every frame live"));
  absl::StatusOr<CapturedFrame> frame = (*source)->Next();
  ASSERT_TRUE(frame.ok());
  EXPECT_TRUE(frame->jpeg.empty());
  // A corrupt file (one byte changed in a frame).
  {
    std::fstream f(footage_, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(-5, std::ios::end);
    f.put('\x7f');
  }
  ::testing::internal::CaptureStderr();
  source = OpenSource("sim:" + scenario_ + "#c", {.fps = 5, .sim_footage = footage_});
  log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(source.ok());
  EXPECT_THAT(log, HasSubstr(footage_ + ": corrupt footage: frame 2"));
  EXPECT_TRUE((*source)->Next()->jpeg.empty());
  // A missing file: the same, the agent still streams.
  std::filesystem::remove(footage_);
  ::testing::internal::CaptureStderr();
  source = OpenSource("sim:" + scenario_ + "#c", {.fps = 5, .sim_footage = footage_});
  EXPECT_THAT(::testing::internal::GetCapturedStderr(), HasSubstr(footage_ + ": no footage file"));
  ASSERT_TRUE(source.ok());
}

}  // namespace
}  // namespace ave
