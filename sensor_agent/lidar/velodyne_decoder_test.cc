// Velodyne packet decoding (issue 16): packets are synthesised here (velodyne_test_packets.h) with
// known returns, and the decoded points are compared with geometry computed independently.
#include "sensor_agent/lidar/velodyne_decoder.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/lidar/velodyne_test_packets.h"

namespace ave::lidar {
namespace {

using testing::EmptyBlocks;
using testing::MakePacket;
using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180;

Eigen::Vector3d Polar(double range_m, double elevation_deg, double azimuth_deg) {
  const double e = elevation_deg * kDeg, a = azimuth_deg * kDeg;
  return {range_m * std::cos(e) * std::sin(a), range_m * std::cos(e) * std::cos(a), range_m * std::sin(e)};
}

absl::Status Add(VelodyneDecoder& d, const std::string& packet, std::vector<LidarSweep>& done, int64_t t_ns = 0) {
  return d.Add(reinterpret_cast<const uint8_t*>(packet.data()), packet.size(), t_ns, done);
}

const SweepPoint* FindPoint(const LidarSweep& s, uint16_t ring, float range_m, uint8_t return_index = 0) {
  for (const SweepPoint& p : s.points) {
    if (p.ring == ring && std::abs(p.range_m - range_m) < 1e-4 && p.return_index == return_index) return &p;
  }
  return nullptr;
}

TEST(VelodyneDecoder, Vlp16PointsMatchPublishedAnglesAndInterpolatedSecondFiring) {
  auto blocks = EmptyBlocks(9000, 20);  // 90.00°, 0.2° per block (10 Hz)
  blocks[3].channels[0] = {5000, 10};   // laser 0 (-15°), first firing, 10 m
  blocks[3].channels[5] = {2500, 20};   // laser 5 (+5°), first firing, 5 m
  blocks[3].channels[16 + 7] = {10000, 30};  // laser 7 (+7°), second firing, 20 m
  blocks[11].channels[16 + 15] = {1234, 40}; // last block: the gap of the block before
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks, 0x37, 0x22), done).ok());
  EXPECT_EQ(d.model(), VelodyneModel::kVlp16);
  std::optional<LidarSweep> s = d.Flush();
  ASSERT_TRUE(s.has_value());
  ASSERT_EQ(s->points.size(), 4u);
  EXPECT_EQ(s->rings, 16);
  // Ring order: descending elevation (+15° is ring 0; laser 7 at +7° is ring 4, laser 5 at +5° ring 5,
  // laser 0 at -15° ring 15).
  auto az = [](int block_cdeg, int ch, int firing) { return (block_cdeg + 20.0 * (ch * 2.304 + firing * 55.296) / 110.592) / 100; };
  struct Want { uint16_t ring; float range; Eigen::Vector3d p; };
  for (const Want& w : {Want{15, 10.0f, Polar(10, -15, az(9060, 0, 0))}, Want{5, 5.0f, Polar(5, 5, az(9060, 5, 0))},
                        Want{4, 20.0f, Polar(20, 7, az(9060, 7, 1))}, Want{0, 2.468f, Polar(2.468, 15, az(9220, 15, 1))}}) {
    const SweepPoint* p = FindPoint(*s, w.ring, w.range);
    ASSERT_NE(p, nullptr) << "ring " << w.ring;
    EXPECT_LT((p->p_in_sensor.cast<double>() - w.p).norm(), 1e-3) << "ring " << w.ring << ": " << p->p_in_sensor.transpose();
  }
}

TEST(VelodyneDecoder, Hdl32ePointsMatchPublishedAngles) {
  auto blocks = EmptyBlocks(35000, 17);
  blocks[0].channels[0] = {5000, 1};    // -30.67°
  blocks[6].channels[31] = {30000, 2};  // +10.67°, 60 m
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks, 0x37, 0x21), done).ok());
  EXPECT_EQ(d.model(), VelodyneModel::kHdl32e);
  std::optional<LidarSweep> s = d.Flush();
  ASSERT_TRUE(s.has_value());
  ASSERT_EQ(s->points.size(), 2u);
  EXPECT_EQ(s->rings, 32);
  const SweepPoint* low = FindPoint(*s, 31, 10.0f);
  const SweepPoint* high = FindPoint(*s, 0, 60.0f);
  ASSERT_TRUE(low && high);
  EXPECT_LT((low->p_in_sensor.cast<double>() - Polar(10, -30.67, 350.00)).norm(), 1e-3);
  EXPECT_LT((high->p_in_sensor.cast<double>() - Polar(60, 10.67, 351.02)).norm(), 1e-3);
  EXPECT_NEAR(high->azimuth_rad, 351.02 * kDeg, 1e-5);
}

TEST(VelodyneDecoder, NoReturnZeroRangeAndBeyondMaximumAreDroppedNeverNaN) {
  auto blocks = EmptyBlocks(0, 20);
  blocks[0].channels[0] = {0, 200};       // no return
  blocks[0].channels[1] = {65535, 200};   // 131 m: beyond the VLP-16's 100 m
  blocks[0].channels[2] = {50001, 200};   // 100.002 m
  blocks[0].channels[3] = {49999, 200};   // 99.998 m: kept
  blocks[0].channels[4] = {1, 200};       // 2 mm: kept
  VelodyneCalibration cal = DefaultVelodyneCalibration(VelodyneModel::kVlp16);
  cal.lasers[5].dist_correction_m = -0.5;  // a near return the correction makes negative
  blocks[0].channels[5] = {100, 200};      // 0.2 m - 0.5 m
  VelodyneDecoder d({.calibration = cal});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks), done).ok());
  std::optional<LidarSweep> s = d.Flush();
  ASSERT_TRUE(s.has_value());
  ASSERT_EQ(s->points.size(), 2u);
  for (const SweepPoint& p : s->points) {
    EXPECT_TRUE(p.p_in_sensor.allFinite());
    EXPECT_GT(p.range_m, 0);
    EXPECT_LE(p.range_m, 100);
  }
}

TEST(VelodyneDecoder, WrapInsideAPacketCutsTheSweepThere) {
  auto blocks = EmptyBlocks(35800, 100);  // 358°, 359°, 0°, 1°, ...
  for (auto& b : blocks) b.channels[0] = {1000, 5};
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks, 0x37, 0x21), done, 42).ok());
  ASSERT_EQ(done.size(), 1u);
  ASSERT_EQ(done[0].points.size(), 2u);
  EXPECT_NEAR(done[0].points[1].azimuth_rad, 359 * kDeg, 1e-5);
  std::optional<LidarSweep> rest = d.Flush();
  ASSERT_TRUE(rest.has_value());
  ASSERT_EQ(rest->points.size(), 10u);
  EXPECT_NEAR(rest->points[0].azimuth_rad, 0, 1e-6);
  EXPECT_EQ(rest->t_ns, 42);
}

TEST(VelodyneDecoder, Vlp16WrapBetweenTheTwoFiringsOfABlock) {
  // Blocks at 359.50°, 359.70°, 359.90°, 0.10°, ...: block 2's second firing interpolates to 360° = 0°.
  auto blocks = EmptyBlocks(35950, 20);
  blocks[2].channels[0] = {1000, 1};   // first firing: the old revolution
  blocks[2].channels[16] = {2000, 1};  // second firing: the new one
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks), done).ok());
  ASSERT_EQ(done.size(), 1u);
  ASSERT_EQ(done[0].points.size(), 1u);
  EXPECT_FLOAT_EQ(done[0].points[0].range_m, 2.0f);
  std::optional<LidarSweep> rest = d.Flush();
  ASSERT_TRUE(rest.has_value());
  ASSERT_EQ(rest->points.size(), 1u);
  EXPECT_FLOAT_EQ(rest->points[0].range_m, 4.0f);
  EXPECT_LT(rest->points[0].azimuth_rad, 0.01 * kDeg);
}

TEST(VelodyneDecoder, DualReturnKeepsBothReturnsBrighterFirst) {
  auto blocks = EmptyBlocks(1000, 0);
  for (int b = 0; b < 12; b += 2) blocks[b].azimuth_cdeg = blocks[b + 1].azimuth_cdeg = static_cast<uint16_t>(1000 + b * 20);
  // Pair 0: last return 8 m dim, strongest 4 m bright -> two points, 4 m first.
  blocks[0].channels[2] = {4000, 30};
  blocks[1].channels[2] = {2000, 200};
  // Pair 1: a single return (both blocks the same) -> one point.
  blocks[2].channels[3] = {3000, 90};
  blocks[3].channels[3] = {3000, 90};
  // Pair 2: the last return is the strongest; the second block holds the second strongest.
  blocks[4].channels[4] = {5000, 220};
  blocks[5].channels[4] = {1500, 60};
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks, 0x39, 0x21), done).ok());
  std::optional<LidarSweep> s = d.Flush();
  ASSERT_TRUE(s.has_value());
  ASSERT_EQ(s->points.size(), 5u);
  auto check = [&](float range, uint8_t ri, float intensity) {
    int n = 0;
    for (const SweepPoint& p : s->points) {
      if (std::abs(p.range_m - range) < 1e-4) {
        ++n;
        EXPECT_EQ(p.return_index, ri) << range;
        EXPECT_EQ(p.intensity, intensity) << range;
      }
    }
    EXPECT_EQ(n, 1) << range;
  };
  check(4.0f, 0, 200);
  check(8.0f, 1, 30);
  check(6.0f, 0, 90);
  check(10.0f, 0, 220);
  check(3.0f, 1, 60);
}

TEST(VelodyneDecoder, BadBlockFlagIsRejectedNamingBlockAndFlag) {
  auto blocks = EmptyBlocks(0, 0);
  for (int b = 0; b < 12; ++b) blocks[b].flag = b % 2 ? 0xDDFF : 0xEEFF;
  blocks[5].flag = 0x1234;
  blocks[0].channels[0] = {1000, 1};
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  const absl::Status s = Add(d, MakePacket(blocks), done);
  EXPECT_THAT(std::string(s.message()), HasSubstr("block 5: flag 0x1234 is not 0xEEFF/0xDDFF"));
  EXPECT_FALSE(d.Flush().has_value()) << "nothing of a bad packet is decoded";
}

TEST(VelodyneDecoder, LowerBlockInAVlp16StreamIsRejected) {
  VelodyneDecoder d({});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(EmptyBlocks(0, 20)), done).ok());
  auto blocks = EmptyBlocks(240, 20);
  blocks[7].flag = 0xDDFF;
  EXPECT_THAT(std::string(Add(d, MakePacket(blocks), done).message()), HasSubstr("block 7: flag 0xDDFF is not 0xEEFF"));
}

TEST(VelodyneDecoder, LaserIdBeyondTheCalibrationIsRejected) {
  auto blocks = EmptyBlocks(100, 0);
  for (int b = 0; b < 12; ++b) blocks[b].flag = b % 2 ? 0xDDFF : 0xEEFF;
  blocks[3].channels[8] = {1000, 1};  // lower block: laser 40
  VelodyneDecoder d({.model = VelodyneModel::kHdl64e, .calibration = SimulatorVelodyneCalibration(32, 2, -24.8)});
  std::vector<LidarSweep> done;
  EXPECT_THAT(std::string(Add(d, MakePacket(blocks), done).message()), HasSubstr("block 3: laser 40 has a return"));
}

TEST(VelodyneDecoder, ProductIdThatContradictsTheCalibrationIsRejected) {
  VelodyneDecoder d({.calibration = DefaultVelodyneCalibration(VelodyneModel::kVlp16)});
  std::vector<LidarSweep> done;
  const absl::Status s = Add(d, MakePacket(EmptyBlocks(0, 17), 0x37, 0x21), done);
  EXPECT_THAT(std::string(s.message()), HasSubstr("product id 0x21 (HDL-32E) does not match the calibration built-in VLP-16"));
  VelodyneDecoder unknown({});
  EXPECT_THAT(std::string(Add(unknown, MakePacket(EmptyBlocks(0, 17), 0x37, 0x77), done).message()),
              HasSubstr("product id 0x77 is neither"));
}

TEST(VelodyneDecoder, ImpossibleFieldsAreRejected) {
  std::vector<LidarSweep> done;
  VelodyneDecoder a({});
  auto blocks = EmptyBlocks(0, 20);
  blocks[2].azimuth_cdeg = 36500;
  EXPECT_THAT(std::string(Add(a, MakePacket(blocks), done).message()), HasSubstr("block 2: azimuth 36500 is not below 36000"));
  VelodyneDecoder b({});
  EXPECT_THAT(std::string(Add(b, MakePacket(EmptyBlocks(0, 20), 0x41), done).message()), HasSubstr("return mode 0x41"));
  VelodyneDecoder c({});
  EXPECT_THAT(std::string(Add(c, std::string(1000, '\0'), done).message()), HasSubstr("1000 bytes is not a 1206-byte"));
}

TEST(VelodyneCalibration, DbXmlOffsetsAndCorrectionsGiveTheManualsGeometry) {
  std::string xml = "<boost_serialization><DB><distLSB_>0.2</distLSB_><points_><count>2</count>";
  for (int id : {1, 0}) {
    xml += "<item><px><id_>" + std::to_string(id) +
           "</id_><rotCorrection_>-5.0</rotCorrection_><vertCorrection_>" + (id ? "-7.5" : "1.5") +
           "</vertCorrection_><distCorrection_>111.0</distCorrection_><distCorrectionX_>118</distCorrectionX_>"
           "<vertOffsetCorrection_>20.0</vertOffsetCorrection_><horizOffsetCorrection_>2.6</horizOffsetCorrection_></px></item>";
  }
  xml += "</points_></DB></boost_serialization>";
  absl::StatusOr<VelodyneCalibration> cal = ParseVelodyneDbXml(xml, "db.xml");
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_EQ(cal->lasers.size(), 2u);
  EXPECT_NEAR(cal->lasers[1].vert_correction_rad, -7.5 * kDeg, 1e-12);
  EXPECT_NEAR(cal->lasers[0].dist_correction_m, 1.11, 1e-12);
  EXPECT_NEAR(cal->distance_resolution_m, 0.002, 1e-12);

  // Laser 1 at azimuth 30°: the HDL-64E S3 manual's formula written out here.
  auto blocks = EmptyBlocks(3000, 0);
  blocks[0].channels[1] = {5000, 9};
  VelodyneDecoder d({.model = VelodyneModel::kHdl64e, .calibration = *cal});
  std::vector<LidarSweep> done;
  ASSERT_TRUE(Add(d, MakePacket(blocks, 0x37, 0xA5), done).ok());
  std::optional<LidarSweep> s = d.Flush();
  ASSERT_TRUE(s && s->points.size() == 1);
  const double dist = 10.0 + 1.11, e = -7.5 * kDeg, a = (30 + 5) * kDeg, vo = 0.20, ho = 0.026;
  const double xy = dist * std::cos(e) - vo * std::sin(e);
  const Eigen::Vector3d want(xy * std::sin(a) - ho * std::cos(a), xy * std::cos(a) + ho * std::sin(a), dist * std::sin(e) + vo * std::cos(e));
  EXPECT_LT((s->points[0].p_in_sensor.cast<double>() - want).norm(), 1e-4);
  EXPECT_EQ(s->points[0].ring, 1);  // -7.5° is below 1.5°
}

TEST(VelodyneCalibration, RosYamlIsReadAndBadLaserIdsNamed) {
  const std::string yaml =
      "lasers:\n"
      "- {dist_correction: 0.01, laser_id: 1, rot_correction: 0.1, vert_correction: -0.2, vert_offset_correction: 0.02, horiz_offset_correction: 0.0}\n"
      "- {dist_correction: 0.0, laser_id: 0, rot_correction: 0.0, vert_correction: 0.1}\n"
      "num_lasers: 2\n"
      "distance_resolution: 0.002\n";
  absl::StatusOr<VelodyneCalibration> cal = ParseVelodyneYaml(yaml, "cal.yaml");
  ASSERT_TRUE(cal.ok()) << cal.status();
  EXPECT_NEAR(cal->lasers[1].rot_correction_rad, 0.1, 1e-12);
  EXPECT_NEAR(cal->lasers[0].vert_correction_rad, 0.1, 1e-12);
  const std::string bad = "lasers:\n- {laser_id: 0, vert_correction: 0}\n- {laser_id: 70, vert_correction: 0}\n";
  EXPECT_THAT(std::string(ParseVelodyneYaml(bad, "cal.yaml").status().message()), HasSubstr("cal.yaml:3: lasers[1].laser_id: 70 is outside [0, 1]"));
  EXPECT_THAT(std::string(ParseVelodyneDbXml("<px><id_>0</id_></px>", "db.xml").status().message()),
              HasSubstr("db.xml: points_ item 0: missing rotCorrection_"));
}

}  // namespace
}  // namespace ave::lidar
