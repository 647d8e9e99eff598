#include "sensor_agent/sim/footage.h"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "sensor_agent/sim/scenario.h"

namespace ave::sim {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// A small scenario with a walker and per-frame sensor noise (so frames differ by seed and index).
constexpr char kScenarioText[] = R"(name: footage_test
seed: 7
cameras:
  - {id: c, width: 96, height: 72, fov_deg: 70, position: [0, -20], height_above_ground_m: 4, look_at: [0, 5], fps: 10}
people:
  - {id: 1, path: [[-10, 0], [10, 0]], speed_mps: 1.4, color: [0.85, 0.15, 0.15]}
effects:
  - {name: camera_noise, params: {sigma: 2.0}}
)";

class FootageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("ave_footage_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    scenario_path_ = (dir_ / "scene.yaml").string();
    std::ofstream(scenario_path_) << kScenarioText;
    footage_path_ = (dir_ / "c.avfoot").string();
    absl::StatusOr<Scenario> scenario = LoadScenario(scenario_path_);
    ASSERT_TRUE(scenario.ok()) << scenario.status();
    scenario_ = std::move(*scenario);
    absl::StatusOr<FootageKey> key = MakeFootageKey(scenario_path_, "c", 10, 0.5, 80);
    ASSERT_TRUE(key.ok()) << key.status();
    key_ = *key;
  }
  void TearDown() override { fs::remove_all(dir_); }

  SimulatedCamera Camera(uint64_t seed) const {
    return SimulatedCamera(scenario_.world, *scenario_.world.FindCamera("c"), scenario_.EffectsForCamera("c"), seed);
  }
  std::vector<uint8_t> FileBytes() const {
    std::ifstream in(footage_path_, std::ios::binary);
    return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  void WriteBytes(const std::vector<uint8_t>& bytes) const {
    std::ofstream(footage_path_, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  }

  fs::path dir_;
  std::string scenario_path_, footage_path_;
  Scenario scenario_;
  FootageKey key_;
};

TEST_F(FootageTest, PlaysBackTheRenderedJpegBytesAtTheSameTimes) {
  const SimulatedCamera camera = Camera(scenario_.seed);
  ASSERT_TRUE(WriteFootage(footage_path_, key_, camera, 4).ok());
  absl::StatusOr<Footage> footage = Footage::Open(footage_path_, key_);
  ASSERT_TRUE(footage.ok()) << footage.status();
  ASSERT_EQ(footage->frames(), 4);
  for (int64_t k = 0; k < 4; ++k) {
    EXPECT_DOUBLE_EQ(footage->TimeOf(k), 0.5 + k / 10.0);
    const std::vector<uint8_t> rendered = EncodeFrameJpeg(camera.Frame(k, 0.5 + static_cast<double>(k) / 10.0), 80);
    ASSERT_FALSE(rendered.empty());
    EXPECT_EQ(footage->Jpeg(k), rendered) << "frame " << k;
  }
  EXPECT_NE(footage->Jpeg(0), footage->Jpeg(1)) << "per-frame noise: frames differ";
  EXPECT_TRUE(footage->Verify(camera).ok());
  // A good file is kept as it is.
  absl::StatusOr<EnsuredFootage> ensured = EnsureFootage(footage_path_, key_, camera, 4);
  ASSERT_TRUE(ensured.ok()) << ensured.status();
  EXPECT_FALSE(ensured->rendered);
  EXPECT_EQ(ensured->frames, 4);
  // Any quality opens it (the agent re-encodes); another quality asked is stale.
  FootageKey any = key_;
  any.jpeg_quality = 0;
  EXPECT_TRUE(Footage::Open(footage_path_, any).ok());
  FootageKey q90 = key_;
  q90.jpeg_quality = 90;
  EXPECT_THAT(Footage::Open(footage_path_, q90).status().message(), HasSubstr("JPEG quality 80, not 90"));
}

TEST_F(FootageTest, ThreadsRenderTheSameFileByteForByte) {
  const SimulatedCamera one = Camera(scenario_.seed), two = Camera(scenario_.seed), three = Camera(scenario_.seed);
  ASSERT_TRUE(WriteFootage(footage_path_, key_, one, 5).ok());
  const std::vector<uint8_t> single = FileBytes();
  ASSERT_TRUE(WriteFootage(footage_path_, key_, {&one, &two, &three}, 5).ok());
  EXPECT_EQ(FileBytes(), single);
  EXPECT_THAT(WriteFootage(footage_path_, key_, std::vector<const SimulatedCamera*>{}, 5).message(), HasSubstr("no camera"));
}

TEST_F(FootageTest, CorruptFileIsDetectedAndRerenderedWithALogLineNamingIt) {
  const SimulatedCamera camera = Camera(scenario_.seed);
  ASSERT_TRUE(WriteFootage(footage_path_, key_, camera, 3).ok());
  const std::vector<uint8_t> good = FileBytes();

  std::vector<uint8_t> flipped = good;
  flipped[flipped.size() - 10] ^= 0x40;  // inside the last frame's JPEG bytes
  WriteBytes(flipped);
  absl::Status status = Footage::Open(footage_path_, key_).status();
  EXPECT_TRUE(absl::IsDataLoss(status)) << status;
  EXPECT_THAT(status.message(), HasSubstr(footage_path_));
  EXPECT_THAT(status.message(), HasSubstr("frame 2's bytes do not match their checksum"));

  WriteBytes(std::vector<uint8_t>(good.begin(), good.end() - 100));  // truncated
  status = Footage::Open(footage_path_, key_).status();
  EXPECT_TRUE(absl::IsDataLoss(status)) << status;
  EXPECT_THAT(status.message(), HasSubstr("frame 2 lies outside the file"));

  WriteBytes({'n', 'o', 't', ' ', 'f', 'o', 'o', 't', 'a', 'g', 'e', '!'});
  status = Footage::Open(footage_path_, key_).status();
  EXPECT_THAT(status.message(), HasSubstr("not an AVEFOOT1 file"));

  EXPECT_TRUE(absl::IsNotFound(Footage::Open((dir_ / "none.avfoot").string(), key_).status()));

  WriteBytes(flipped);
  ::testing::internal::CaptureStderr();
  absl::StatusOr<EnsuredFootage> ensured = EnsureFootage(footage_path_, key_, camera, 3);
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(ensured.ok()) << ensured.status();
  EXPECT_TRUE(ensured->rendered);
  EXPECT_THAT(log, HasSubstr(footage_path_ + ": corrupt footage: frame 2's bytes do not match their checksum; re-rendering its 3 frames"));
  EXPECT_EQ(FileBytes(), good) << "re-rendered bit for bit";
}

TEST_F(FootageTest, StaleFileIsDetectedAndRerendered) {
  const SimulatedCamera camera = Camera(scenario_.seed);
  // Footage from "another simulator": the same key, frames that a fresh render no longer gives
  // (here: the noise of another seed).
  ASSERT_TRUE(WriteFootage(footage_path_, key_, Camera(scenario_.seed + 1), 3).ok());
  absl::StatusOr<Footage> footage = Footage::Open(footage_path_, key_);
  ASSERT_TRUE(footage.ok()) << footage.status();
  const absl::Status verified = footage->Verify(camera);
  EXPECT_TRUE(absl::IsFailedPrecondition(verified)) << verified;
  EXPECT_THAT(verified.message(), HasSubstr(footage_path_ + ": stale footage: frame 0 (t = 0.5 s) differs from a fresh render"));
  ::testing::internal::CaptureStderr();
  absl::StatusOr<EnsuredFootage> ensured = EnsureFootage(footage_path_, key_, camera, 3);
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(ensured.ok()) << ensured.status();
  EXPECT_TRUE(ensured->rendered);
  EXPECT_THAT(log, HasSubstr(footage_path_ + ": stale footage: frame 0"));
  footage = Footage::Open(footage_path_, key_);
  ASSERT_TRUE(footage.ok()) << footage.status();
  EXPECT_TRUE(footage->Verify(camera).ok());

  // Another key: each field named.
  FootageKey other = key_;
  other.fps = 30;
  EXPECT_THAT(Footage::Open(footage_path_, other).status().message(), HasSubstr("stale footage: fps 10, not 30"));
  other = key_;
  other.start_s = 0;
  EXPECT_THAT(Footage::Open(footage_path_, other).status().message(), HasSubstr("start 0.5 s, not 0 s"));
  other = key_;
  other.camera_id = "d";
  EXPECT_THAT(Footage::Open(footage_path_, other).status().message(), HasSubstr("camera 'c', not 'd'"));
  // An edited scenario file.
  std::ofstream(scenario_path_, std::ios::app) << "# an edit\n";
  absl::StatusOr<FootageKey> edited = MakeFootageKey(scenario_path_, "c", 10, 0.5, 80);
  ASSERT_TRUE(edited.ok());
  const absl::Status stale = Footage::Open(footage_path_, *edited).status();
  EXPECT_TRUE(absl::IsFailedPrecondition(stale)) << stale;
  EXPECT_THAT(stale.message(), HasSubstr("was edited since"));

  // Shorter than asked: rendered anew at the asked length.
  ::testing::internal::CaptureStderr();
  ensured = EnsureFootage(footage_path_, key_, camera, 5);
  EXPECT_THAT(::testing::internal::GetCapturedStderr(), HasSubstr("footage too short: 3 frames, 5 asked"));
  ASSERT_TRUE(ensured.ok());
  EXPECT_TRUE(ensured->rendered);
  EXPECT_EQ(Footage::Open(footage_path_, key_)->frames(), 5);
}

// A camera whose effects end in jpeg_artefacts delivers its own JPEG: footage keeps those bytes,
// at that effect's quality, and their decoding is exactly the live render (the pose front end
// sees the same pixels whether it renders or plays).
TEST_F(FootageTest, CameraWithJpegArtefactsKeepsItsOwnBytesThatDecodeToTheRender) {
  std::ofstream(scenario_path_, std::ios::app) << "  - {name: jpeg_artefacts, params: {quality: 65}}\n";
  absl::StatusOr<Scenario> scenario = LoadScenario(scenario_path_);
  ASSERT_TRUE(scenario.ok()) << scenario.status();
  absl::StatusOr<FootageKey> key = MakeFootageKey(scenario_path_, "c", 10, 0, 80);
  ASSERT_TRUE(key.ok()) << key.status();
  EXPECT_TRUE(key->camera_jpeg);
  EXPECT_EQ(key->jpeg_quality, 65) << "the camera's quality, not the one asked for other cameras";
  const SimulatedCamera camera(scenario->world, *scenario->world.FindCamera("c"), scenario->EffectsForCamera("c"), scenario->seed);
  ASSERT_TRUE(WriteFootage(footage_path_, *key, camera, 3).ok());
  absl::StatusOr<Footage> footage = Footage::Open(footage_path_, *key);
  ASSERT_TRUE(footage.ok()) << footage.status();
  EXPECT_TRUE(footage->Verify(camera).ok());
  for (int64_t k = 0; k < 3; ++k) {
    const SimImage live = camera.Frame(k, k / 10.0);
    EXPECT_EQ(footage->Jpeg(k), live.jpeg);
    const cv::Mat decoded = cv::imdecode(footage->Jpeg(k), cv::IMREAD_COLOR);
    ASSERT_EQ(decoded.total() * 3, live.bgr.size());
    EXPECT_TRUE(std::equal(live.bgr.begin(), live.bgr.end(), decoded.data)) << "frame " << k << " decodes to the render";
  }
  // The old key (no camera JPEG) no longer opens it: stale, named.
  EXPECT_THAT(Footage::Open(footage_path_, key_).status().message(), HasSubstr("stale footage"));
}

TEST_F(FootageTest, BadKeysAndCamerasAreRefusedByName) {
  EXPECT_THAT(MakeFootageKey(scenario_path_, "nope", 10, 0, 80).status().message(), HasSubstr("no camera 'nope'"));
  EXPECT_THAT(MakeFootageKey(scenario_path_, "c", 0, 0, 80).status().message(), HasSubstr("fps must be in (0, 1000]"));
  EXPECT_THAT(MakeFootageKey(scenario_path_, "c", 10, 0, 101).status().message(), HasSubstr("JPEG quality"));
  EXPECT_FALSE(MakeFootageKey((dir_ / "missing.yaml").string(), "c", 10, 0, 80).ok());
  EXPECT_THAT(WriteFootage(footage_path_, key_, Camera(1), 0).message(), HasSubstr("at least one frame"));
}

}  // namespace
}  // namespace ave::sim
