#include "sensor_agent/lidar/velodyne_decoder.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "model_store/common/log.h"

namespace ave::lidar {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kBlocks = 12;
constexpr int kBlockBytes = 100;
constexpr int kChannels = 32;
constexpr uint16_t kUpperBlock = 0xEEFF;
constexpr uint16_t kLowerBlock = 0xDDFF;
constexpr uint8_t kStrongest = 0x37, kLast = 0x38, kDual = 0x39;
constexpr uint8_t kProductHdl32e = 0x21, kProductVlp16 = 0x22;
// VLP-16 firing timing (user manual, §9): a channel every 2.304 µs, a firing sequence every 55.296 µs.
constexpr double kVlp16ChannelUs = 2.304, kVlp16SequenceUs = 55.296;

uint16_t U16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }

std::string Hex(unsigned v, int digits) { return absl::StrFormat("0x%0*X", digits, v); }

std::string ProductName(uint8_t product) {
  if (product == kProductHdl32e) return "0x21 (HDL-32E)";
  if (product == kProductVlp16) return "0x22 (VLP-16)";
  return Hex(product, 2);
}

double DefaultMaxRange(VelodyneModel model) { return model == VelodyneModel::kHdl64e ? 120.0 : 100.0; }

}  // namespace

// Per 0.01° of azimuth; built once per process (576 KB), shared by every decoder.
const VelodyneDecoder::SinCosTable& VelodyneDecoder::Table() {
  static const SinCosTable table = [] {
    SinCosTable t;
    t.sin.resize(36000);
    t.cos.resize(36000);
    for (int i = 0; i < 36000; ++i) {
      t.sin[i] = std::sin(i * kPi / 18000);
      t.cos[i] = std::cos(i * kPi / 18000);
    }
    return t;
  }();
  return table;
}

VelodyneDecoder::VelodyneDecoder(VelodyneDecoderOptions options) : options_(std::move(options)), table_(&Table()) {}

absl::Status VelodyneDecoder::Configure(const uint8_t* payload) {
  bool lower = false;
  for (int b = 0; b < kBlocks; ++b) lower |= U16(payload + b * kBlockBytes) == kLowerBlock;
  const uint8_t product = payload[1205];
  VelodyneModel from_packet = VelodyneModel::kUnknown;
  if (lower) from_packet = VelodyneModel::kHdl64e;
  else if (product == kProductHdl32e) from_packet = VelodyneModel::kHdl32e;
  else if (product == kProductVlp16) from_packet = VelodyneModel::kVlp16;

  VelodyneModel model = options_.model;
  if (model == VelodyneModel::kUnknown && options_.calibration) model = options_.calibration->model;
  if (model == VelodyneModel::kUnknown) {
    if (from_packet == VelodyneModel::kUnknown) {
      return absl::InvalidArgumentError(absl::StrCat("product id ", Hex(product, 2),
                                                     " is neither 0x21 (HDL-32E) nor 0x22 (VLP-16), and no block is 0xDDFF (HDL-64E)"));
    }
    model = from_packet;
  } else if (model != VelodyneModel::kHdl64e && from_packet != model) {
    // The HDL-64E's last two bytes are status bytes: only the VLP-16 and HDL-32E name themselves.
    const std::string expected = options_.calibration && options_.calibration->model == model
                                     ? absl::StrCat("the calibration ", options_.calibration->source, " (", VelodyneModelName(model), ", ",
                                                    options_.calibration->lasers.size(), " lasers)")
                                     : absl::StrCat("the expected ", VelodyneModelName(model));
    return absl::InvalidArgumentError(absl::StrCat(lower ? "a 0xDDFF block (HDL-64E)" : "product id " + ProductName(product),
                                                   " does not match ", expected));
  }
  VelodyneCalibration calibration = options_.calibration ? *options_.calibration : DefaultVelodyneCalibration(model);
  if (options_.calibration && static_cast<int>(calibration.lasers.size()) < VelodyneLaserCount(model) && model != VelodyneModel::kHdl64e) {
    return absl::InvalidArgumentError(absl::StrCat("the calibration ", calibration.source, " has ", calibration.lasers.size(),
                                                   " lasers, the ", VelodyneModelName(model), " needs ", VelodyneLaserCount(model)));
  }
  if (const std::string why = calibration.Check(); !why.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("calibration ", calibration.source, ": ", why));
  }
  if (!options_.calibration && model == VelodyneModel::kHdl64e) {
    AVE_LOG(INFO) << "HDL-64E without a db.xml: using the simulator's layout (64 lasers, 2.0° to -24.8°, no offsets); "
                     "a real sensor needs its db.xml or YAML calibration";
  }
  model_ = model;
  product_ = product;
  calibration_ = std::move(calibration);
  max_range_m_ = options_.max_range_m > 0 ? options_.max_range_m : DefaultMaxRange(model_);
  const size_t n = calibration_.lasers.size();
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return calibration_.lasers[a].vert_correction_rad > calibration_.lasers[b].vert_correction_rad;
  });
  lasers_.resize(n);
  ring_elevation_rad_.resize(n);
  for (size_t ring = 0; ring < n; ++ring) {
    const LaserCalibration& l = calibration_.lasers[order[ring]];
    lasers_[order[ring]] = {std::cos(l.vert_correction_rad), std::sin(l.vert_correction_rad), std::cos(l.rot_correction_rad),
                            std::sin(l.rot_correction_rad), static_cast<uint16_t>(ring)};
    ring_elevation_rad_[ring] = static_cast<float>(l.vert_correction_rad);
  }
  return absl::OkStatus();
}

void VelodyneDecoder::StartSweep(int64_t t_ns) {
  const size_t reserve = sweep_ ? sweep_->points.size() : 0;
  sweep_.emplace();
  sweep_->t_ns = t_ns;
  sweep_->rings = static_cast<int>(lasers_.size());
  sweep_->ring_elevation_rad = ring_elevation_rad_;
  sweep_->points.reserve(reserve);
  firings_in_sweep_ = 0;
}

void VelodyneDecoder::Firing(double azimuth_cdeg, int64_t t_ns, std::vector<LidarSweep>& done) {
  azimuth_cdeg = std::fmod(azimuth_cdeg, 36000.0);
  if (!sweep_) {
    StartSweep(t_ns);
  } else if (firings_in_sweep_ > 0 && azimuth_cdeg < last_firing_cdeg_) {
    done.push_back(std::move(*sweep_));
    StartSweep(t_ns);
    sweep_->points.reserve(done.back().points.size());
  }
  last_firing_cdeg_ = azimuth_cdeg;
  ++firings_in_sweep_;
}

void VelodyneDecoder::Point(int laser, const FiringAzimuth& az, uint16_t raw, uint8_t intensity, uint8_t return_index) {
  if (raw == 0) return;  // no return
  const LaserCalibration& cal = calibration_.lasers[laser];
  const double d = raw * calibration_.distance_resolution_m + cal.dist_correction_m;
  if (!(d > 0) || d > max_range_m_) return;
  const LaserTable& t = lasers_[laser];
  // a = azimuth - rot_correction
  const double sin_a = az.sin * t.cos_rot - az.cos * t.sin_rot;
  const double cos_a = az.cos * t.cos_rot + az.sin * t.sin_rot;
  const double xy = d * t.cos_vert - cal.vert_offset_m * t.sin_vert;
  SweepPoint& p = sweep_->points.emplace_back();
  p.p_in_sensor = Eigen::Vector3f(static_cast<float>(xy * sin_a - cal.horiz_offset_m * cos_a),
                                  static_cast<float>(xy * cos_a + cal.horiz_offset_m * sin_a),
                                  static_cast<float>(d * t.sin_vert + cal.vert_offset_m * t.cos_vert));
  p.range_m = static_cast<float>(d);
  p.intensity = intensity;
  double a = az.rad - cal.rot_correction_rad;  // |rot_correction| <= 2π (Check)
  if (a < 0) a += 2 * kPi;
  if (a < 0) a += 2 * kPi;
  if (a >= 2 * kPi) a -= 2 * kPi;
  p.azimuth_rad = static_cast<float>(a);
  if (!(p.azimuth_rad < static_cast<float>(2 * kPi))) p.azimuth_rad = 0;
  p.ring = t.ring;
  p.return_index = return_index;
}

VelodyneDecoder::FiringAzimuth VelodyneDecoder::Azimuth(double azimuth_cdeg) const {
  if (azimuth_cdeg >= 36000) azimuth_cdeg -= 36000;
  FiringAzimuth az;
  az.rad = azimuth_cdeg * (kPi / 18000);
  const int whole = static_cast<int>(azimuth_cdeg);
  if (whole == azimuth_cdeg) {
    az.sin = table_->sin[whole];
    az.cos = table_->cos[whole];
  } else {
    az.sin = std::sin(az.rad);
    az.cos = std::cos(az.rad);
  }
  return az;
}

absl::Status VelodyneDecoder::Add(const uint8_t* payload, size_t size, int64_t t_ns, std::vector<LidarSweep>& done) {
  if (size != kVelodynePacketBytes) {
    return absl::InvalidArgumentError(absl::StrCat("UDP payload of ", size, " bytes is not a ", kVelodynePacketBytes,
                                                   "-byte Velodyne data packet"));
  }
  if (model_ == VelodyneModel::kUnknown) {
    if (absl::Status s = Configure(payload); !s.ok()) return s;
  }
  const bool hdl64 = model_ == VelodyneModel::kHdl64e;
  const uint8_t mode = payload[1204];
  bool dual = false;
  if (!hdl64) {
    if (payload[1205] != product_) {
      return absl::InvalidArgumentError(absl::StrCat("product id ", ProductName(payload[1205]), " in a ", VelodyneModelName(model_),
                                                     " stream (product id ", ProductName(product_), ")"));
    }
    if (mode != kStrongest && mode != kLast && mode != kDual) {
      return absl::InvalidArgumentError(absl::StrCat("return mode ", Hex(mode, 2), " is not 0x37 (strongest), 0x38 (last) or 0x39 (dual)"));
    }
    dual = mode == kDual;
  }
  // Validate the whole packet before decoding any of it.
  uint16_t azimuth[kBlocks];
  bool lower[kBlocks];
  const int lasers = static_cast<int>(lasers_.size());
  for (int b = 0; b < kBlocks; ++b) {
    const uint8_t* block = payload + b * kBlockBytes;
    const uint16_t flag = U16(block);
    azimuth[b] = U16(block + 2);
    lower[b] = flag == kLowerBlock;
    if (flag != kUpperBlock && !(hdl64 && flag == kLowerBlock)) {
      return absl::InvalidArgumentError(absl::StrCat("block ", b, ": flag ", Hex(flag, 4),
                                                     hdl64 ? " is not 0xEEFF/0xDDFF"
                                                           : absl::StrCat(" is not 0xEEFF (a ", VelodyneModelName(model_), " has upper blocks only)")));
    }
    if (azimuth[b] >= 36000) {
      return absl::InvalidArgumentError(absl::StrCat("block ", b, ": azimuth ", azimuth[b], " is not below 36000 (0.01°)"));
    }
    const int first_laser = lower[b] ? 32 : 0;
    const int used = model_ == VelodyneModel::kVlp16 ? 16 : kChannels;
    for (int c = 0; c < kChannels; ++c) {
      const int laser = first_laser + c % used;
      if (laser >= lasers && U16(block + 4 + 3 * c) != 0) {
        return absl::InvalidArgumentError(absl::StrCat("block ", b, ": laser ", laser, " has a return but the calibration ",
                                                       calibration_.source, " has ", lasers, " lasers"));
      }
    }
    if (dual && b % 2 == 1 && azimuth[b] != azimuth[b - 1]) {
      return absl::InvalidArgumentError(absl::StrCat("blocks ", b - 1, "/", b, ": a dual-return pair at azimuths ", azimuth[b - 1],
                                                     " and ", azimuth[b]));
    }
  }

  const int step = dual ? 2 : 1;
  for (int b = 0; b < kBlocks; b += step) {
    // In dual mode block b holds the last return, b + 1 the strongest (or second strongest).
    const uint8_t* blocks[2] = {payload + b * kBlockBytes, dual ? payload + (b + 1) * kBlockBytes : nullptr};
    auto emit = [&](int laser, int channel, const FiringAzimuth& az) {
      const uint16_t d0 = U16(blocks[0] + 4 + 3 * channel);
      const uint8_t i0 = blocks[0][6 + 3 * channel];
      if (!dual) {
        if (laser < lasers) Point(laser, az, d0, i0, 0);
        return;
      }
      const uint16_t d1 = U16(blocks[1] + 4 + 3 * channel);
      const uint8_t i1 = blocks[1][6 + 3 * channel];
      if (d0 == d1 && i0 == i1) {
        Point(laser, az, d1, i1, 0);
      } else if (d0 == 0 || d1 == 0) {
        Point(laser, az, d0 == 0 ? d1 : d0, d0 == 0 ? i1 : i0, 0);
      } else if (i0 > i1) {  // the last return is the brighter: the other block holds the second strongest
        Point(laser, az, d0, i0, 0);
        Point(laser, az, d1, i1, 1);
      } else {
        Point(laser, az, d1, i1, 0);
        Point(laser, az, d0, i0, 1);
      }
    };
    if (model_ == VelodyneModel::kVlp16) {
      double gap = last_vlp16_gap_cdeg_;
      if (b + step < kBlocks) {
        const int g = (azimuth[b + step] - azimuth[b] + 36000) % 36000;
        if (g > 0 && g < 1000) gap = last_vlp16_gap_cdeg_ = g;
      }
      for (int firing = 0; firing < 2; ++firing) {
        Firing(azimuth[b] + gap * firing * 0.5, t_ns, done);
        for (int ch = 0; ch < 16; ++ch) {
          emit(ch, firing * 16 + ch, Azimuth(azimuth[b] + gap * (ch * kVlp16ChannelUs + firing * kVlp16SequenceUs) / (2 * kVlp16SequenceUs)));
        }
      }
    } else {
      Firing(azimuth[b], t_ns, done);
      const int first_laser = lower[b] ? 32 : 0;
      const FiringAzimuth az = Azimuth(azimuth[b]);
      for (int c = 0; c < kChannels; ++c) emit(first_laser + c, c, az);
    }
  }
  return absl::OkStatus();
}

std::optional<LidarSweep> VelodyneDecoder::Flush() {
  if (!sweep_ || firings_in_sweep_ == 0) return std::nullopt;
  std::optional<LidarSweep> out = std::move(sweep_);
  sweep_.reset();
  firings_in_sweep_ = 0;
  last_firing_cdeg_ = -1;
  return out;
}

}  // namespace ave::lidar
