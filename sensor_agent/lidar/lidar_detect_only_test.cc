// The LiDAR --detect-only loop (issue 16) over a real pcap source, with a tracker written here.
#include "sensor_agent/lidar/lidar_detect_only.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "sensor_agent/lidar/velodyne_test_packets.h"

namespace ave::lidar {
namespace {

using testing::EmptyBlocks;
using testing::MakePacket;

// Four HDL-32E turns (three packets each, 10° a block); each block has one return at 3 m.
std::string WriteCapture(const std::string& name, size_t truncate_to = std::string::npos) {
  testing::TestPcapWriter w;
  for (int p = 0; p < 12; ++p) {
    auto blocks = EmptyBlocks((p % 3) * 12000, 1000);
    for (auto& b : blocks) b.channels[15] = {1500, 9};
    w.Udp(MakePacket(blocks, 0x37, 0x21), 2'000'000'000LL + p * 33'333'333LL);
  }
  const std::string path = absl::StrCat(::testing::TempDir(), "/lidar_detect_", name, "_", ::getpid(), ".pcap");
  EXPECT_TRUE(w.Write(path, truncate_to));
  return path;
}

// (Record times are whole microseconds in a classic pcap: packet 7 at 2.199999998 s reads 2.199999.)
// A tracker that sees one person per sweep at (points, sweep index), id 7 unconfirmed in the first sweep.
SweepTracker CountingTracker() {
  auto calls = std::make_shared<int>(0);
  return [calls](const LidarSweep& sweep) -> absl::StatusOr<FootTracks> {
    FootTracks t;
    t.t_ns = sweep.t_ns;
    FootTrack a;
    a.id = 7;
    a.xy_m = Eigen::Vector2d(static_cast<double>(sweep.points.size()), *calls);
    a.confirmed = *calls > 0;
    t.tracks.push_back(a);
    if (*calls == 2) t.tracks.push_back(FootTrack{.id = 9, .xy_m = Eigen::Vector2d(-1.5, 2.25), .confirmed = true});
    ++*calls;
    return t;
  };
}

TEST(LidarDetectOnly, WritesOneRecordPerRevolutionThenTheSummary) {
  auto source = OpenLidarSource("pcap:" + WriteCapture("ok"), {});
  ASSERT_TRUE(source.ok()) << source.status();
  std::ostringstream out;
  absl::StatusOr<LidarDetectOnlySummary> summary = RunLidarDetectOnly(**source, CountingTracker(), out);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 4);
  EXPECT_EQ(summary->distinct_tracks, 2);
  const std::vector<std::string> lines = absl::StrSplit(out.str(), '\n', absl::SkipEmpty());
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0], "{\"frame\":0,\"t\":2.000000,\"tracks\":[]}");
  EXPECT_EQ(lines[2], "{\"frame\":2,\"t\":2.199999,\"tracks\":[{\"id\":7,\"x\":36.000,\"y\":2.000},{\"id\":9,\"x\":-1.500,\"y\":2.250}]}");
  EXPECT_THAT(summary->ToJson(), ::testing::MatchesRegex("\\{\"frames\":4,\"distinct_tracks\":2,\"fps\":[0-9.]+\\}"));
}

TEST(LidarDetectOnly, ASourceErrorEndsTheRunAfterTheRecordsBeforeIt) {
  const size_t record = 16 + 42 + 1206;
  auto source = OpenLidarSource("pcap:" + WriteCapture("cut", 24 + 7 * record + 100), {});
  ASSERT_TRUE(source.ok());
  std::ostringstream out;
  absl::StatusOr<LidarDetectOnlySummary> summary = RunLidarDetectOnly(**source, CountingTracker(), out);
  EXPECT_THAT(std::string(summary.status().message()), ::testing::HasSubstr("after sweep 3: "));
  EXPECT_THAT(std::string(summary.status().message()), ::testing::HasSubstr("packet 8: record truncated"));
  const std::vector<std::string> lines = absl::StrSplit(out.str(), '\n', absl::SkipEmpty());
  EXPECT_EQ(lines.size(), 3u);
}

TEST(LidarDetectOnly, TrackerErrorIsNamed) {
  auto source = OpenLidarSource("pcap:" + WriteCapture("tracker"), {});
  ASSERT_TRUE(source.ok());
  std::ostringstream out;
  SweepTracker failing = [](const LidarSweep&) -> absl::StatusOr<FootTracks> { return absl::InternalError("boom"); };
  EXPECT_EQ(RunLidarDetectOnly(**source, failing, out).status().message(), "tracker: sweep 0: boom");
}

TEST(LidarDetectOnly, ALiveSourceSkipsABadDatagramAndGoesOn) {
  auto source = OpenLidarSource("udp:127.0.0.1:0", {.udp_idle_timeout_s = 30});
  ASSERT_TRUE(source.ok()) << source.status();
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>((*source)->bound_port()));
  ::inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  std::vector<std::string> datagrams = {std::string(64, '\x7F')};
  for (int p = 0; p < 4; ++p) {
    auto blocks = EmptyBlocks((p % 3) * 12000, 1000);
    for (auto& b : blocks) b.channels[15] = {1500, 9};
    datagrams.push_back(MakePacket(blocks, 0x37, 0x21));
  }
  for (const std::string& d : datagrams) {
    ASSERT_EQ(::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to)), static_cast<ssize_t>(d.size()));
  }
  std::ostringstream out;
  absl::StatusOr<LidarDetectOnlySummary> summary = RunLidarDetectOnly(**source, CountingTracker(), out, 1);
  ::close(fd);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 1);
  EXPECT_EQ(summary->skipped_packets, 1);
}

}  // namespace
}  // namespace ave::lidar
