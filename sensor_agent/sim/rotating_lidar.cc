#include "sensor_agent/sim/rotating_lidar.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "sensor_agent/sim/lidar_common.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::sim {
namespace {

using internal::LabelledMesh;
using internal::LidarHit;

constexpr double kPi = 3.14159265358979323846;
constexpr char kFrameMagic[8] = {'A', 'V', 'E', 'L', 'I', 'D', 'R', '1'};
constexpr size_t kFrameHeaderBytes = 8 + 4 + 8 + 4 + 4;  // magic, version, t_ns, point count, record bytes
constexpr size_t kFrameRecordBytes = 30;

// One random stream per (seed, frame time): effects draw from it in a fixed order.
std::mt19937_64 FrameRng(uint64_t seed, int64_t t_ns) { return std::mt19937_64(internal::MixSeed(seed, 0x11DA5, t_ns)); }

// ---- effects: each runs only when named, counts itself ----

// lidar_range_noise: zero-mean Gaussian along the ray, sigma_m (default 0.02 m, HDL-64E spec).
double RangeNoise(const EffectParams& params, std::mt19937_64& rng) {
  CountEvaluation(EffectKind::kLidarRangeNoise);
  std::normal_distribution<double> n(0, params.Get("sigma_m", 0.02));
  return n(rng);
}

// lidar_ring_pattern: each laser has a fixed range bias (bias_sigma_m, default 0.03) and
// intensity gain (gain_sigma, default 0.15) drawn once per sensor (seed), not per frame: the
// banded look of an uncalibrated multi-beam sensor.
void RingPattern(const EffectParams& params, uint64_t seed, int ring, double& range_m, double& intensity) {
  CountEvaluation(EffectKind::kLidarRingPattern);
  std::mt19937_64 rng(internal::MixSeed(seed, 0x5106, ring));
  std::normal_distribution<double> n(0, 1);
  range_m += params.Get("bias_sigma_m", 0.03) * n(rng);
  intensity *= std::max(0.0, 1 + params.Get("gain_sigma", 0.15) * n(rng));
}

// lidar_missing_returns: a return is lost with `probability` (default 0.03), and always when the
// beam meets the surface more grazing than `grazing_deg` from the surface plane (default 3°).
bool ReturnIsMissing(const EffectParams& params, std::mt19937_64& rng, double cos_incidence) {
  CountEvaluation(EffectKind::kLidarMissingReturns);
  std::uniform_real_distribution<double> u(0, 1);
  const bool dropped = u(rng) < params.Get("probability", 0.03);
  const double grazing = std::sin(params.Get("grazing_deg", 3.0) * kPi / 180);
  return dropped || cos_incidence < grazing;
}

// lidar_intensity_by_material: reflectivity by material times the cosine of incidence, with a
// range fall-off normalised at 10 m (scale, default 1).
double IntensityByMaterial(const EffectParams& params, const LidarHit& hit, double cos_incidence) {
  CountEvaluation(EffectKind::kLidarIntensityByMaterial);
  const double falloff = std::min(1.0, 10.0 / std::max(hit.distance_m, 1.0));
  return params.Get("scale", 1.0) * internal::MaterialReflectivity(hit.material, hit.label) * (0.3 + 0.7 * cos_incidence) *
         (0.5 + 0.5 * falloff);
}

// waving_vegetation: leaves sway horizontally with amplitude_m (default 0.15 m at 5 m above the
// sensor-independent ground) at frequency_hz (default 0.5), phase varying over the canopy.
Eigen::Vector3d VegetationSway(const EffectParams& params, const scene::SyntheticCampus& campus, const Eigen::Vector3d& p, double t_s) {
  CountEvaluation(EffectKind::kWavingVegetation);
  const double above = std::max(0.0, p.z() - campus.TerrainHeight(p.x(), p.y()));
  const double amplitude = params.Get("amplitude_m", 0.15) * std::min(2.0, above / 5.0);
  const double phase = 0.7 * p.x() + 0.45 * p.y();
  const double w = 2 * kPi * params.Get("frequency_hz", 0.5) * t_s;
  return amplitude * Eigen::Vector3d(std::sin(w + phase), 0.6 * std::sin(1.3 * w + 2 * phase), 0);
}

double RingElevation(const RotatingLidarSpec& spec, int ring) {
  if (spec.rings == 1) return spec.fov_up_deg * kPi / 180;
  return (spec.fov_up_deg - ring * (spec.fov_up_deg - spec.fov_down_deg) / (spec.rings - 1)) * kPi / 180;
}

// `enu_from_sensor` tilts the sensor (rays are cast along enu_from_sensor * d; points stay in the
// sensor frame); identity for the spec's level sensor.
LidarFrame SimulateFrame(const scene::SyntheticCampus& campus, const LabelledMesh& static_mesh, const RotatingLidarSpec& spec,
                         const EffectSet& effects, uint64_t seed, double t_s,
                         const Eigen::Matrix3d& enu_from_sensor = Eigen::Matrix3d::Identity()) {
  LidarFrame frame;
  frame.t_ns = static_cast<int64_t>(std::llround(t_s * 1e9));
  const LabelledMesh movers = internal::BuildMoverLidarMesh(campus, t_s);
  std::mt19937_64 rng = FrameRng(seed, frame.t_ns);
  const EffectParams* range_noise = effects.Find(EffectKind::kLidarRangeNoise);
  const EffectParams* ring_pattern = effects.Find(EffectKind::kLidarRingPattern);
  const EffectParams* missing = effects.Find(EffectKind::kLidarMissingReturns);
  const EffectParams* by_material = effects.Find(EffectKind::kLidarIntensityByMaterial);
  const EffectParams* waving = effects.Find(EffectKind::kWavingVegetation);

  std::vector<double> sin_el(spec.rings), cos_el(spec.rings);
  for (int r = 0; r < spec.rings; ++r) {
    sin_el[r] = std::sin(RingElevation(spec, r));
    cos_el[r] = std::cos(RingElevation(spec, r));
  }
  frame.points.reserve(static_cast<size_t>(spec.rings) * spec.azimuth_steps / 2);
  for (int c = 0; c < spec.azimuth_steps; ++c) {
    const double az = 2 * kPi * c / spec.azimuth_steps;
    const double sa = std::sin(az), ca = std::cos(az);
    for (int r = 0; r < spec.rings; ++r) {
      const Eigen::Vector3d d(cos_el[r] * sa, cos_el[r] * ca, sin_el[r]);
      const Eigen::Vector3d d_in_enu = enu_from_sensor * d;
      const std::optional<LidarHit> hit = internal::CastLidarRay(&static_mesh, &movers, spec.position_m, d_in_enu, spec.max_range_m);
      if (!hit) continue;
      const double cos_incidence = std::abs(hit->normal.dot(d_in_enu));
      if (missing && ReturnIsMissing(*missing, rng, cos_incidence)) continue;
      Eigen::Vector3d p_local = d * hit->distance_m;
      if (waving && hit->label == kLidarVegetationId) {
        p_local += enu_from_sensor.transpose() * VegetationSway(*waving, campus, spec.position_m + enu_from_sensor * p_local, t_s);
      }
      double range = p_local.norm();
      double intensity = by_material ? IntensityByMaterial(*by_material, *hit, cos_incidence) : 100.0;
      if (ring_pattern) RingPattern(*ring_pattern, seed, r, range, intensity);
      if (range_noise) range += RangeNoise(*range_noise, rng);
      if (!(range > 0) || range > spec.max_range_m) continue;
      const Eigen::Vector3d dir = p_local.normalized();
      LidarPoint point;
      point.p_local = (dir * range).cast<float>();
      point.range_m = static_cast<float>(range);
      point.intensity = static_cast<float>(std::clamp(intensity, 0.0, 255.0));
      point.ring = static_cast<uint16_t>(r);
      point.azimuth_rad = static_cast<float>(az);
      point.label = hit->label;
      frame.points.push_back(point);
    }
  }
  for (const scene::Mover& mover : campus.movers) {
    if (mover.kind != scene::MoverKind::kPerson) continue;
    const scene::MoverState state = scene::MoverAt(campus, mover, t_s);
    if (!state.position_m.allFinite() || (state.position_m - spec.position_m).norm() > spec.max_range_m) continue;
    frame.pedestrian_feet.emplace_back(kMoverIdBase + mover.id, state.position_m);
  }
  return frame;
}

std::string EncodeFrame(const LidarFrame& frame) {
  std::string out;
  out.reserve(kFrameHeaderBytes + kFrameRecordBytes * frame.points.size());
  out.append(kFrameMagic, 8);
  internal::PutU32(out, 1);
  internal::PutU64(out, static_cast<uint64_t>(frame.t_ns));
  internal::PutU32(out, static_cast<uint32_t>(frame.points.size()));
  internal::PutU32(out, kFrameRecordBytes);
  for (const LidarPoint& p : frame.points) {
    internal::PutF32(out, p.p_local.x());
    internal::PutF32(out, p.p_local.y());
    internal::PutF32(out, p.p_local.z());
    internal::PutF32(out, p.range_m);
    internal::PutF32(out, p.intensity);
    internal::PutU16(out, p.ring);
    internal::PutF32(out, p.azimuth_rad);
    internal::PutU32(out, p.label);
  }
  return out;
}

// ---- Velodyne HDL-64E-style pcap (1206-byte payloads: 12 blocks of 100 bytes, then 6) ----

constexpr int kBlocksPerPacket = 12;
constexpr int kLasersPerBlock = 32;

void PutU16BigEndian(std::string& out, uint16_t v) {
  out.push_back(static_cast<char>(v >> 8));
  out.push_back(static_cast<char>(v & 0xFF));
}

class PcapWriter {
 public:
  explicit PcapWriter(std::ofstream& out) : out_(out) {
    std::string h;
    internal::PutU32(h, 0xA1B2C3D4u);  // microsecond timestamps, written little-endian
    internal::PutU16(h, 2);
    internal::PutU16(h, 4);
    internal::PutI32(h, 0);
    internal::PutU32(h, 0);
    internal::PutU32(h, 65535);
    internal::PutU32(h, 1);  // LINKTYPE_ETHERNET
    out_.write(h.data(), static_cast<std::streamsize>(h.size()));
  }

  // Wraps a 1206-byte payload into Ethernet / IPv4 / UDP (192.168.1.201:2368 -> broadcast:2368).
  void Packet(const std::string& payload, int64_t t_us) {
    std::string ip;
    ip.push_back(0x45);
    ip.push_back(0);
    PutU16BigEndian(ip, static_cast<uint16_t>(20 + 8 + payload.size()));
    PutU16BigEndian(ip, ip_id_++);
    PutU16BigEndian(ip, 0x4000);  // don't fragment
    ip.push_back(64);             // TTL
    ip.push_back(17);             // UDP
    PutU16BigEndian(ip, 0);       // checksum, filled below
    for (int b : {192, 168, 1, 201, 255, 255, 255, 255}) ip.push_back(static_cast<char>(b));
    uint32_t sum = 0;
    for (size_t i = 0; i < 20; i += 2) sum += (static_cast<uint8_t>(ip[i]) << 8) | static_cast<uint8_t>(ip[i + 1]);
    while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
    const uint16_t checksum = static_cast<uint16_t>(~sum);
    ip[10] = static_cast<char>(checksum >> 8);
    ip[11] = static_cast<char>(checksum & 0xFF);

    std::string frame;
    for (int b : {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x60, 0x76, 0x88, 0x00, 0x00, 0x00}) frame.push_back(static_cast<char>(b));
    PutU16BigEndian(frame, 0x0800);
    frame += ip;
    PutU16BigEndian(frame, 2368);
    PutU16BigEndian(frame, 2368);
    PutU16BigEndian(frame, static_cast<uint16_t>(8 + payload.size()));
    PutU16BigEndian(frame, 0);  // UDP checksum: none
    frame += payload;

    std::string rec;
    internal::PutU32(rec, static_cast<uint32_t>(t_us / 1'000'000));
    internal::PutU32(rec, static_cast<uint32_t>(t_us % 1'000'000));
    internal::PutU32(rec, static_cast<uint32_t>(frame.size()));
    internal::PutU32(rec, static_cast<uint32_t>(frame.size()));
    out_.write(rec.data(), static_cast<std::streamsize>(rec.size()));
    out_.write(frame.data(), static_cast<std::streamsize>(frame.size()));
  }

 private:
  std::ofstream& out_;
  uint16_t ip_id_ = 0;
};

// Packs one frame's returns into HDL-64E-style packets. Each firing (azimuth step) takes
// ceil(rings / 32) blocks: lasers 0-31 in an upper block (0xEEFF), 32-63 in a lower block (0xDDFF),
// both with the same azimuth. A laser without a return has distance 0. Blocks run on across
// packets; the last packet of a frame is padded with empty blocks repeating the last azimuth.
void WriteFramePackets(PcapWriter& pcap, const RotatingLidarSpec& spec, const LidarFrame& frame, std::string& payload, int& blocks) {
  const int per_firing = (spec.rings + kLasersPerBlock - 1) / kLasersPerBlock;
  std::vector<uint16_t> distance(static_cast<size_t>(spec.rings) * spec.azimuth_steps, 0);
  std::vector<uint8_t> intensity(distance.size(), 0);
  for (const LidarPoint& p : frame.points) {
    const int c = static_cast<int>(std::lround(p.azimuth_rad / (2 * kPi) * spec.azimuth_steps)) % spec.azimuth_steps;
    const size_t i = static_cast<size_t>(c) * spec.rings + p.ring;
    distance[i] = static_cast<uint16_t>(std::clamp<long>(std::lround(p.range_m / 0.002), 1, 65535));
    intensity[i] = static_cast<uint8_t>(std::clamp<long>(std::lround(p.intensity), 0, 255));
  }
  const double step_s = 1.0 / (spec.rate_hz * spec.azimuth_steps);
  int64_t packet_t_us = frame.t_ns / 1000;
  auto flush = [&]() {
    // GPS timestamp: microseconds past the hour of the packet's first firing; two factory bytes.
    internal::PutU32(payload, static_cast<uint32_t>(packet_t_us % 3'600'000'000LL));
    internal::PutU8(payload, 0x37);  // strongest return
    internal::PutU8(payload, 0x22);
    pcap.Packet(payload, packet_t_us);
    payload.clear();
    blocks = 0;
  };
  uint16_t azimuth = 0;
  for (int c = 0; c < spec.azimuth_steps; ++c) {
    azimuth = static_cast<uint16_t>(std::lround(36000.0 * c / spec.azimuth_steps) % 36000);
    for (int b = 0; b < per_firing; ++b) {
      if (blocks == 0) packet_t_us = frame.t_ns / 1000 + static_cast<int64_t>(std::llround(c * step_s * 1e6));
      internal::PutU16(payload, b == 0 ? 0xEEFF : 0xDDFF);
      internal::PutU16(payload, azimuth);
      for (int l = 0; l < kLasersPerBlock; ++l) {
        const int ring = b * kLasersPerBlock + l;
        const size_t i = static_cast<size_t>(c) * spec.rings + ring;
        internal::PutU16(payload, ring < spec.rings ? distance[i] : 0);
        internal::PutU8(payload, ring < spec.rings ? intensity[i] : 0);
      }
      if (++blocks == kBlocksPerPacket) flush();
    }
  }
  // Pad so that every frame starts in a fresh packet.
  while (blocks > 0) {
    internal::PutU16(payload, (blocks % per_firing) == 0 ? 0xEEFF : 0xDDFF);
    internal::PutU16(payload, azimuth);
    for (int l = 0; l < kLasersPerBlock; ++l) {
      internal::PutU16(payload, 0);
      internal::PutU8(payload, 0);
    }
    if (++blocks == kBlocksPerPacket) flush();
  }
}

}  // namespace

std::string RotatingLidarSpec::Check() const {
  if (!position_m.allFinite()) return "position_m must be finite";
  if (!std::isfinite(rate_hz) || rate_hz <= 0 || rate_hz > 50) return "rate_hz must be in (0, 50]";
  if (rings < 1 || rings > 64) return "rings must be in [1, 64]";
  if (!std::isfinite(fov_up_deg) || !std::isfinite(fov_down_deg) || fov_up_deg > 89 || fov_down_deg < -89 ||
      (rings > 1 && !(fov_down_deg < fov_up_deg))) {
    return "fov_down_deg must be below fov_up_deg, both within [-89, 89]";
  }
  if (azimuth_steps < 16 || azimuth_steps > 36000) return "azimuth_steps must be in [16, 36000]";
  if (!std::isfinite(max_range_m) || max_range_m <= 0 || max_range_m > 130) return "max_range_m must be in (0, 130]";
  return {};
}

LidarFrame SimulateRotatingLidarFrame(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec, const EffectSet& effects,
                                      uint64_t seed, double t_s) {
  if (!spec.Check().empty() || !std::isfinite(t_s)) return {};
  const LabelledMesh static_mesh = internal::BuildStaticLidarMesh(campus, internal::kLidarTerrainResolution_m);
  return SimulateFrame(campus, static_mesh, spec, effects, seed, t_s);
}

struct RotatingLidarSimulator::Impl {
  const scene::SyntheticCampus& campus;
  RotatingLidarSpec spec;
  EffectSet effects;
  uint64_t seed;
  Eigen::Matrix3d enu_from_sensor;
  LabelledMesh static_mesh;
};

RotatingLidarSimulator::RotatingLidarSimulator(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec,
                                               const EffectSet& effects, uint64_t seed, const Eigen::Matrix3d& enu_from_sensor)
    : impl_(std::make_unique<Impl>(Impl{campus, spec, effects, seed, enu_from_sensor,
                                        spec.Check().empty() ? internal::BuildStaticLidarMesh(campus, internal::kLidarTerrainResolution_m)
                                                             : LabelledMesh{}})) {}

RotatingLidarSimulator::~RotatingLidarSimulator() = default;

LidarFrame RotatingLidarSimulator::Frame(double t_s) const {
  if (!impl_->spec.Check().empty() || !std::isfinite(t_s)) return {};
  return SimulateFrame(impl_->campus, impl_->static_mesh, impl_->spec, impl_->effects, impl_->seed, t_s, impl_->enu_from_sensor);
}

const RotatingLidarSpec& RotatingLidarSimulator::spec() const { return impl_->spec; }

absl::Status WriteRotatingLidar(const scene::SyntheticCampus& campus, const RotatingLidarSpec& spec, const EffectSet& effects,
                                uint64_t seed, double duration_s, const std::string& out_dir) {
  if (const std::string why = spec.Check(); !why.empty()) return absl::InvalidArgumentError("rotating lidar '" + spec.id + "': " + why);
  if (!std::isfinite(duration_s) || duration_s < 0 || duration_s > 3600) {
    return absl::InvalidArgumentError("rotating lidar '" + spec.id + "': duration_s must be in [0, 3600]");
  }
  if (const std::string why = internal::MakeDirs(out_dir); !why.empty()) return absl::InternalError(why);
  const int frames = std::max(1, static_cast<int>(std::floor(duration_s * spec.rate_hz + 1e-9)));
  const LabelledMesh static_mesh = internal::BuildStaticLidarMesh(campus, internal::kLidarTerrainResolution_m);

  std::ofstream pcap_file(out_dir + "/velodyne.pcap", std::ios::binary);
  std::ofstream index(out_dir + "/frames.csv");
  std::ofstream feet(out_dir + "/pedestrians.csv");
  if (!pcap_file || !index || !feet) return absl::InternalError("cannot write into " + out_dir);
  PcapWriter pcap(pcap_file);
  index << "frame,t_ns,file,points\n";
  feet << "frame,t_ns,label,mover_id,x_m,y_m,z_m\n";
  std::string payload;
  int blocks = 0;
  for (int f = 0; f < frames; ++f) {
    const double t_s = f / spec.rate_hz;
    const LidarFrame frame = SimulateFrame(campus, static_mesh, spec, effects, seed, t_s);
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06d.bin", f);
    const std::string bytes = EncodeFrame(frame);
    std::ofstream out(out_dir + "/" + name, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) return absl::InternalError("cannot write " + out_dir + "/" + name);
    index << f << ',' << frame.t_ns << ',' << name << ',' << frame.points.size() << '\n';
    char line[160];
    for (const auto& [label, p] : frame.pedestrian_feet) {
      std::snprintf(line, sizeof(line), "%d,%lld,%u,%u,%.6f,%.6f,%.6f\n", f, static_cast<long long>(frame.t_ns), label,
                    label - kMoverIdBase, p.x(), p.y(), p.z());
      feet << line;
    }
    WriteFramePackets(pcap, spec, frame, payload, blocks);
  }
  if (!pcap_file || !index || !feet) return absl::InternalError("write failed in " + out_dir);
  return absl::OkStatus();
}

absl::StatusOr<LidarFrame> ReadRotatingLidarFrame(const std::string& path) {
  absl::StatusOr<std::string> read = internal::ReadWholeFile(path);
  if (!read.ok()) return read.status();
  const std::string& bytes = *read;
  if (bytes.size() < kFrameHeaderBytes || bytes.compare(0, 8, std::string(kFrameMagic, 8)) != 0) {
    return absl::InvalidArgumentError(path + ": not an AVELIDR1 frame");
  }
  const char* p = bytes.data();
  if (internal::GetU32(p + 8) != 1) return absl::InvalidArgumentError(path + ": unsupported version");
  LidarFrame frame;
  frame.t_ns = static_cast<int64_t>(internal::GetU64(p + 12));
  const uint32_t count = internal::GetU32(p + 20);
  const uint32_t record = internal::GetU32(p + 24);
  if (record != kFrameRecordBytes || bytes.size() != kFrameHeaderBytes + static_cast<size_t>(count) * record) {
    return absl::InvalidArgumentError(path + ": size does not match the point count");
  }
  frame.points.resize(count);
  for (uint32_t i = 0; i < count; ++i) {
    const char* r = p + kFrameHeaderBytes + static_cast<size_t>(i) * record;
    LidarPoint& pt = frame.points[i];
    pt.p_local = Eigen::Vector3f(internal::GetF32(r), internal::GetF32(r + 4), internal::GetF32(r + 8));
    pt.range_m = internal::GetF32(r + 12);
    pt.intensity = internal::GetF32(r + 16);
    pt.ring = internal::GetU16(r + 20);
    pt.azimuth_rad = internal::GetF32(r + 22);
    pt.label = internal::GetU32(r + 26);
    if (!pt.p_local.allFinite() || !std::isfinite(pt.range_m)) {
      return absl::InvalidArgumentError(path + ": point " + std::to_string(i) + " is not finite");
    }
  }
  return frame;
}

}  // namespace ave::sim
