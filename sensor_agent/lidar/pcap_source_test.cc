// pcap: and udp: sources (issue 16): captures and datagrams synthesised here, and the simulator's
// own velodyne.pcap decoded against its native frames.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar/pcap_reader.h"
#include "sensor_agent/lidar/velodyne_test_packets.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::lidar {
namespace {

using testing::EmptyBlocks;
using testing::MakePacket;
using testing::TestPcapWriter;
using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

std::string TempDir(const std::string& name) {
  const std::string dir = absl::StrCat(::testing::TempDir(), "/lidar_io_", name, "_", ::getpid());
  std::filesystem::create_directories(dir);
  return dir;
}

// VLP-16 packets of `revolutions` turns at 10° a block (36 blocks, 3 packets a turn); every block
// has laser 0 at 2 m + block index · 2 cm (first firing) and laser 1 at 5 m (second firing).
std::vector<std::string> Vlp16Revolutions(int revolutions) {
  std::vector<std::string> packets;
  for (int p = 0; p < 3 * revolutions; ++p) {
    auto blocks = EmptyBlocks((p % 3) * 12000, 1000);
    for (int b = 0; b < 12; ++b) {
      blocks[b].channels[0] = {static_cast<uint16_t>(1000 + 10 * ((p % 3) * 12 + b)), 50};
      blocks[b].channels[17] = {2500, 60};
    }
    packets.push_back(MakePacket(blocks, 0x37, 0x22));
  }
  return packets;
}

std::vector<LidarSweep> DrainOk(LidarSource& source, absl::Status* end = nullptr) {
  std::vector<LidarSweep> sweeps;
  for (;;) {
    absl::StatusOr<LidarSweep> s = source.Next();
    if (!s.ok()) {
      if (end) *end = s.status();
      return sweeps;
    }
    sweeps.push_back(*std::move(s));
  }
}

TEST(PcapLidarSource, BothByteOrdersAndNanosecondCapturesDecodeAlikeSkippingOtherTraffic) {
  const std::string dir = TempDir("orders");
  std::vector<std::vector<LidarSweep>> decoded;
  for (testing::PcapOptions o : {testing::PcapOptions{false, false}, {true, false}, {false, true}, {true, true}}) {
    TestPcapWriter w(o);
    w.Udp(std::string(512, '\x01'), 1'000'000'000, 8308);  // a position packet
    std::string arp(12, '\xFF');
    arp += "\x08\x06";
    arp += std::string(28, '\0');
    w.Raw(arp, 1'000'000'000);
    int64_t t_ns = 1'700'000'000'000'000'000 + 1000;
    for (const std::string& p : Vlp16Revolutions(3)) w.Udp(p, t_ns += 33'000'000);
    const std::string path = absl::StrCat(dir, "/c", o.big_endian, o.nanoseconds, ".pcap");
    ASSERT_TRUE(w.Write(path));
    auto source = OpenLidarSource("pcap:" + path, {});
    ASSERT_TRUE(source.ok()) << source.status();
    EXPECT_FALSE((*source)->live());
    absl::Status end;
    decoded.push_back(DrainOk(**source, &end));
    EXPECT_TRUE(absl::IsOutOfRange(end)) << end;
  }
  for (const auto& sweeps : decoded) {
    ASSERT_EQ(sweeps.size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
      ASSERT_EQ(sweeps[i].points.size(), 72u);
      EXPECT_EQ(sweeps[i].t_ns, decoded[0][i].t_ns);
      for (size_t k = 0; k < 72; ++k) EXPECT_EQ(sweeps[i].points[k].p_in_sensor, decoded[0][i].points[k].p_in_sensor);
    }
  }
  EXPECT_EQ(decoded[0][1].t_ns, 1'700'000'000'000'000'000 + 1000 + 4 * 33'000'000);
}

TEST(PcapLidarSource, TruncatedFileKeepsTheSweepsBeforeAndNamesThePacket) {
  const std::string dir = TempDir("truncated");
  TestPcapWriter w;
  w.Udp(std::string(512, '\x01'), 0, 8308);  // record 1
  int64_t t_ns = 0;
  const auto packets = Vlp16Revolutions(4);  // records 2..13; revolution 3 is records 8..10
  for (const std::string& p : packets) w.Udp(p, t_ns += 33'000'000);
  const std::string path = dir + "/cut.pcap";
  const size_t record_bytes = 16 + 42 + 1206;
  ASSERT_TRUE(w.Write(path, 24 + (16 + 42 + 512) + 7 * record_bytes + 600));  // inside record 9
  auto source = OpenLidarSource("pcap:" + path, {});
  ASSERT_TRUE(source.ok()) << source.status();
  absl::Status end;
  const std::vector<LidarSweep> sweeps = DrainOk(**source, &end);
  ASSERT_EQ(sweeps.size(), 3u) << "two whole revolutions, then what packet 8 held";
  EXPECT_EQ(sweeps[0].points.size(), 72u);
  EXPECT_EQ(sweeps[1].points.size(), 72u);
  EXPECT_EQ(sweeps[2].points.size(), 24u);
  EXPECT_EQ(end.code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(std::string(end.message()), HasSubstr(path + ": packet 9: record truncated (584 of 1248 bytes)"));
}

TEST(PcapLidarSource, CaptureInMemoryDecodesAsTheFileDoesAndNamesItsPackets) {
  const std::string dir = TempDir("memory");
  TestPcapWriter w({.big_endian = true, .nanoseconds = true});
  int64_t t_ns = 1'700'000'000'000'000'000;
  for (const std::string& p : Vlp16Revolutions(2)) w.Udp(p, t_ns += 33'000'000);
  const std::string path = dir + "/c.pcap";
  ASSERT_TRUE(w.Write(path));
  auto from_file = OpenLidarSource("pcap:" + path, {});
  ASSERT_TRUE(from_file.ok()) << from_file.status();
  const std::vector<LidarSweep> file_sweeps = DrainOk(**from_file);

  auto reader = PcapReader::FromBytes(w.bytes(), "mem.pcap");
  ASSERT_TRUE(reader.ok()) << reader.status();
  auto from_memory = OpenPcapLidarSource(*std::move(reader), {});
  ASSERT_TRUE(from_memory.ok()) << from_memory.status();
  EXPECT_EQ((*from_memory)->description(), "pcap:mem.pcap");
  absl::Status end;
  const std::vector<LidarSweep> memory_sweeps = DrainOk(**from_memory, &end);
  EXPECT_TRUE(absl::IsOutOfRange(end)) << end;
  ASSERT_EQ(memory_sweeps.size(), 2u);
  ASSERT_EQ(file_sweeps.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(memory_sweeps[i].t_ns, file_sweeps[i].t_ns);
    ASSERT_EQ(memory_sweeps[i].points.size(), file_sweeps[i].points.size());
    for (size_t k = 0; k < file_sweeps[i].points.size(); ++k) {
      EXPECT_EQ(memory_sweeps[i].points[k].p_in_sensor, file_sweeps[i].points[k].p_in_sensor);
    }
  }

  // Cut inside the fourth record: the first revolution, what packet 3 held, then packet 4 named.
  auto cut = PcapReader::FromBytes(w.bytes().substr(0, 24 + 3 * (16 + 42 + 1206) + 100), "mem.pcap");
  ASSERT_TRUE(cut.ok()) << cut.status();
  auto cut_source = OpenPcapLidarSource(*std::move(cut), {});
  ASSERT_TRUE(cut_source.ok()) << cut_source.status();
  const std::vector<LidarSweep> cut_sweeps = DrainOk(**cut_source, &end);
  EXPECT_EQ(cut_sweeps.size(), 1u);
  EXPECT_THAT(std::string(end.message()), HasSubstr("mem.pcap: packet 4: record truncated"));

  auto empty = PcapReader::FromBytes("", "empty.pcap");
  ASSERT_FALSE(empty.ok());
  EXPECT_THAT(std::string(empty.status().message()), HasSubstr("empty.pcap: global header: 0 of 24 bytes"));
}

TEST(PcapLidarSource, CorruptedHdl64PacketNamesFilePacketBlockAndFlag) {
  const std::string dir = TempDir("corrupt");
  TestPcapWriter w;
  for (int p = 0; p < 40; ++p) {
    auto blocks = EmptyBlocks(0, 0);
    for (int b = 0; b < 12; ++b) {
      blocks[b].flag = b % 2 ? 0xDDFF : 0xEEFF;
      blocks[b].azimuth_cdeg = static_cast<uint16_t>(((p * 6 + b / 2) * 1000) % 36000);
      blocks[b].channels[3] = {5000, 1};
    }
    if (p == 30) blocks[5].flag = 0x1234;
    w.Udp(MakePacket(blocks, 0x37, 0x00), p * 1'000'000);
  }
  const std::string path = dir + "/bad.pcap";
  ASSERT_TRUE(w.Write(path));
  auto source = OpenLidarSource("pcap:" + path, {});
  ASSERT_TRUE(source.ok());
  absl::Status end;
  const std::vector<LidarSweep> sweeps = DrainOk(**source, &end);
  // 6 firings a packet, 36 a turn: packets 1-30 (records) hold five whole turns.
  ASSERT_EQ(sweeps.size(), 5u);
  for (const LidarSweep& s : sweeps) EXPECT_EQ(s.points.size(), 72u);
  EXPECT_EQ(sweeps[0].rings, 64);
  EXPECT_THAT(std::string(end.message()), HasSubstr(path + ": packet 31: block 5: flag 0x1234 is not 0xEEFF/0xDDFF"));
}

TEST(PcapLidarSource, ProductIdContradictingTheCalibrationFileIsNamed) {
  const std::string dir = TempDir("product");
  const std::string yaml = dir + "/vlp16.yaml";
  {
    std::FILE* f = std::fopen(yaml.c_str(), "w");
    std::fputs("lasers:\n", f);
    for (int i = 0; i < 16; ++i) std::fprintf(f, "- {laser_id: %d, vert_correction: %f}\n", i, (i - 8) * 0.03);
    std::fclose(f);
  }
  TestPcapWriter w;
  auto blocks = EmptyBlocks(0, 17);
  w.Udp(MakePacket(blocks, 0x37, 0x21), 0);
  ASSERT_TRUE(w.Write(dir + "/hdl32.pcap"));
  auto source = OpenLidarSource("pcap:" + dir + "/hdl32.pcap", {.calibration_file = yaml});
  ASSERT_TRUE(source.ok()) << source.status();
  const absl::StatusOr<LidarSweep> s = (*source)->Next();
  EXPECT_THAT(std::string(s.status().message()),
              HasSubstr("hdl32.pcap: packet 1: product id 0x21 (HDL-32E) does not match the calibration " + yaml + " (VLP-16, 16 lasers)"));
}

TEST(PcapLidarSource, RegisteredPoseFarFromTheOriginKeepsMillimetres) {
  const std::string dir = TempDir("far");
  TestPcapWriter w;
  auto blocks = EmptyBlocks(4500, 20);
  blocks[0].channels[2] = {25000, 80};  // laser 2 (-13°), 50 m, fired 4.6 µs after the block's 45°
  w.Udp(MakePacket(blocks), 0);
  ASSERT_TRUE(w.Write(dir + "/far.pcap"));
  const Rigid3d world_from_sensor(Eigen::Quaterniond(Eigen::AngleAxisd(5 * kPi / 180, Eigen::Vector3d::UnitX())),
                                  Eigen::Vector3d(1'000'000.123, -2'000'000.456, 31.5));
  auto source = OpenLidarSource("pcap:" + dir + "/far.pcap", {.world_from_sensor = world_from_sensor});
  ASSERT_TRUE(source.ok());
  absl::StatusOr<LidarSweep> s = (*source)->Next();
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->points.size(), 1u);
  ASSERT_TRUE(s->world_from_sensor.has_value());
  const double e = -13 * kPi / 180, a = (4500 + 20 * 2 * 2.304 / 110.592) / 100 * kPi / 180;
  const Eigen::Vector3d p_in_sensor(50 * std::cos(e) * std::sin(a), 50 * std::cos(e) * std::cos(a), 50 * std::sin(e));
  const Eigen::Vector3d want = world_from_sensor.rotation * p_in_sensor + world_from_sensor.translation;
  const Eigen::Vector3d got = *s->world_from_sensor * s->points[0].p_in_sensor.cast<double>();
  EXPECT_LT((got - want).norm(), 1e-3) << (got - want).transpose();
  // The tilt is applied: the point drops by ~50 m · sin(13° + ...) differently than level.
  EXPECT_GT(std::abs(got.z() - (world_from_sensor.translation.z() + p_in_sensor.z())), 1.0);
}

// The simulator's velodyne.pcap decodes to its native frames: same points, in the same order,
// ranges within the 2 mm distance unit (half of it, rounding), positions within it too where the
// azimuth steps fall on the packets' 0.01° grid (900 steps = 0.4°). Except swaying vegetation
// (courtyard's waving_vegetation): the sway moves a leaf point off its beam, which a packet, one
// range per beam, cannot say; its range and beam still match.
TEST(PcapLidarSource, SimulatorPcapEqualsItsNativeFrames) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("courtyard");
  ASSERT_TRUE(scenario.ok());
  ASSERT_FALSE(scenario->rotating_lidars.empty());
  sim::RotatingLidarSpec spec = scenario->rotating_lidars[0];
  spec.azimuth_steps = 900;
  const std::string dir = TempDir("simpcap");
  ASSERT_TRUE(sim::WriteRotatingLidar(scenario->world, spec, scenario->effects, scenario->seed, 0.2, dir).ok());
  auto source = OpenLidarSource("pcap:" + dir + "/velodyne.pcap", {.max_range_m = 121});
  ASSERT_TRUE(source.ok()) << source.status();
  absl::Status end;
  const std::vector<LidarSweep> sweeps = DrainOk(**source, &end);
  EXPECT_TRUE(absl::IsOutOfRange(end)) << end;
  ASSERT_EQ(sweeps.size(), 2u);
  for (int f = 0; f < 2; ++f) {
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%06d.bin", f);
    absl::StatusOr<sim::LidarFrame> native = sim::ReadRotatingLidarFrame(dir + name);
    ASSERT_TRUE(native.ok());
    const LidarSweep& s = sweeps[f];
    EXPECT_EQ(s.t_ns, native->t_ns);
    EXPECT_EQ(s.rings, 64);
    ASSERT_EQ(s.points.size(), native->points.size());
    ASSERT_GT(s.points.size(), 10000u);
    double worst_m = 0;
    size_t compared = 0;
    for (size_t i = 0; i < s.points.size(); ++i) {
      const sim::LidarPoint& n = native->points[i];
      const SweepPoint& p = s.points[i];
      ASSERT_EQ(p.ring, n.ring) << i;
      ASSERT_NEAR(p.range_m, n.range_m, 0.001 + 1e-5) << i;
      ASSERT_NEAR(p.azimuth_rad, n.azimuth_rad, 1e-5) << i;
      EXPECT_EQ(p.intensity, std::round(n.intensity)) << i;
      if (n.label == sim::kLidarVegetationId) continue;
      worst_m = std::max(worst_m, static_cast<double>((p.p_in_sensor - n.p_local).norm()));
      ++compared;
    }
    EXPECT_LT(worst_m, 0.002) << "frame " << f;
    EXPECT_GT(compared, s.points.size() / 2);
  }
}

TEST(UdpLidarSource, LoopbackPacketsBecomeSweepsAndABadDatagramIsNamed) {
  auto source = OpenLidarSource("udp:127.0.0.1:0", {.udp_idle_timeout_s = 30});
  ASSERT_TRUE(source.ok()) << source.status();
  EXPECT_TRUE((*source)->live());
  const int port = (*source)->bound_port();
  ASSERT_GT(port, 0);
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  ::inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  auto send = [&](const std::string& bytes) {
    ASSERT_EQ(::sendto(fd, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to)),
              static_cast<ssize_t>(bytes.size()));
  };
  const auto packets = Vlp16Revolutions(3);
  for (int i = 0; i < 6; ++i) send(packets[i]);
  send(std::string(100, '\0'));
  send(packets[6]);  // starts the third turn: completes the second
  absl::StatusOr<LidarSweep> first = (*source)->Next();
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(first->points.size(), 72u);
  absl::StatusOr<LidarSweep> bad = (*source)->Next();
  EXPECT_THAT(std::string(bad.status().message()), HasSubstr("packet 7: UDP payload of 100 bytes is not a 1206-byte"));
  absl::StatusOr<LidarSweep> second = (*source)->Next();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ(second->points.size(), 72u);
  ::close(fd);
}

}  // namespace
}  // namespace ave::lidar
