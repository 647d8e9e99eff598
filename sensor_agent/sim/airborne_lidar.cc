#include "sensor_agent/sim/airborne_lidar.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "sensor_agent/sim/lidar_common.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::sim {
namespace {

using internal::LabelledMesh;
using internal::LidarHit;

constexpr double kPi = 3.14159265358979323846;
constexpr double kAircraftSpeed_mps = 60;
constexpr double kLineTurn_s = 90;        // between flight lines
constexpr double kSideOverlap = 0.2;      // of the swath
constexpr size_t kHeaderBytes = 375;
constexpr size_t kRecordBytes = 30;
constexpr double kScale = 0.001;          // millimetres

// ---- effects: each runs only when named, counts itself ----

// lidar_range_noise: Gaussian along the beam, sigma_m (default 0.05 m for an airborne system).
double RangeNoise(const EffectParams& params, std::mt19937_64& rng) {
  CountEvaluation(EffectKind::kLidarRangeNoise);
  return std::normal_distribution<double>(0, params.Get("sigma_m", 0.05))(rng);
}
// lidar_missing_returns: a pulse returns nothing with `probability` (default 0.02), e.g. off
// water or glass.
bool ReturnIsMissing(const EffectParams& params, std::mt19937_64& rng) {
  CountEvaluation(EffectKind::kLidarMissingReturns);
  return std::uniform_real_distribution<double>(0, 1)(rng) < params.Get("probability", 0.02);
}
// lidar_intensity_by_material: reflectivity by material and incidence, scaled to 16 bits.
double IntensityByMaterial(const EffectParams& params, const LidarHit& hit, double cos_incidence) {
  CountEvaluation(EffectKind::kLidarIntensityByMaterial);
  return params.Get("scale", 1.0) * internal::MaterialReflectivity(hit.material, hit.label) * (0.3 + 0.7 * cos_incidence) * 257.0;
}

uint8_t LasClass(uint32_t label) {
  if (label == kGroundId) return kLasGround;
  if (IsBuildingId(label)) return kLasBuilding;
  if (label == kLidarVegetationId) return kLasHighVegetation;
  return kLasUnclassified;
}

void PutFixed(std::string& out, const std::string& text, size_t width) {
  std::string s = text.substr(0, width);
  s.resize(width, '\0');
  out += s;
}

struct Record {
  Eigen::Vector3d p_local;
  uint16_t intensity;
  uint8_t classification;
  uint8_t user_data;
  int16_t scan_angle;  // 0.006°
  uint16_t point_source_id;
  bool scan_direction;
  bool edge;
  double gps_time;
};

}  // namespace

std::string AirborneLidarSpec::Check() const {
  if (!std::isfinite(altitude_m) || altitude_m <= 0 || altitude_m > 10000) return "altitude_m must be in (0, 10000]";
  if (!std::isfinite(swath_half_angle_deg) || swath_half_angle_deg <= 0 || swath_half_angle_deg >= 60) {
    return "swath_half_angle_deg must be in (0, 60)";
  }
  if (!std::isfinite(point_spacing_m) || point_spacing_m < 0.05 || point_spacing_m > 100) return "point_spacing_m must be in [0.05, 100]";
  return {};
}

absl::Status SimulateAirborneLidar(const scene::SyntheticCampus& campus, const AirborneLidarSpec& spec, const EffectSet& effects,
                                   uint64_t seed, const std::string& las_path) {
  if (const std::string why = spec.Check(); !why.empty()) return absl::InvalidArgumentError("airborne lidar: " + why);
  const double e = campus.half_extent_m;
  if (!(e > 0) || !campus.origin.allFinite()) return absl::InvalidArgumentError("airborne lidar: campus extent/origin unusable");
  double highest = campus.TerrainHeight(0, 0);
  for (const auto& b : campus.buildings) highest = std::max(highest, campus.BuildingTop(b));
  if (spec.altitude_m <= highest + 50) return absl::InvalidArgumentError("airborne lidar: altitude_m must clear the tallest building by 50 m");

  const LabelledMesh static_mesh = internal::BuildStaticLidarMesh(campus, internal::kLidarTerrainResolution_m);
  const EffectParams* range_noise = effects.Find(EffectKind::kLidarRangeNoise);
  const EffectParams* missing = effects.Find(EffectKind::kLidarMissingReturns);
  const EffectParams* by_material = effects.Find(EffectKind::kLidarIntensityByMaterial);

  // Flight lines along x, spaced so neighbouring swaths overlap by kSideOverlap on flat ground.
  const double half_swath = spec.altitude_m * std::tan(spec.swath_half_angle_deg * kPi / 180);
  const double line_spacing = 2 * half_swath * (1 - kSideOverlap);
  const int lines = std::max(1, static_cast<int>(std::ceil(2 * e / line_spacing)));
  const int across = std::max(2, static_cast<int>(std::ceil(2 * half_swath / spec.point_spacing_m)) + 1);
  const int along = std::max(1, static_cast<int>(std::floor(2 * e / spec.point_spacing_m)) + 1);
  const double scan_period_s = spec.point_spacing_m / kAircraftSpeed_mps;

  std::vector<Record> records;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  double line_start_s = 0;
  for (int line = 0; line < lines; ++line) {
    const double y_line = lines == 1 ? 0.0 : -e + (2 * e) * (line + 0.5) / lines;
    const bool eastward = line % 2 == 0;
    const LabelledMesh movers = internal::BuildMoverLidarMesh(campus, line_start_s);
    std::mt19937_64 rng(internal::MixSeed(seed, 0xA1B0, line));
    for (int s = 0; s < along; ++s) {
      const double x = eastward ? -e + s * spec.point_spacing_m : e - s * spec.point_spacing_m;
      const bool left_to_right = s % 2 == 0;  // an oscillating mirror: alternate sweep directions
      for (int a = 0; a < across; ++a) {
        const int i = left_to_right ? a : across - 1 - a;
        // Across-track offset on flat ground, uniform in metres; +y is left when flying east.
        const double offset = -half_swath + 2 * half_swath * i / (across - 1);
        if (std::abs(y_line + offset) > e + 2 * spec.point_spacing_m) continue;  // off the site's tile
        const double theta = std::atan2(offset, spec.altitude_m);
        const Eigen::Vector3d origin(x, y_line, spec.altitude_m);
        const Eigen::Vector3d d(0, std::sin(theta), -std::cos(theta));
        const double max_range = 2 * spec.altitude_m / std::cos(theta);
        const std::optional<LidarHit> hit = internal::CastLidarRay(&static_mesh, &movers, origin, d, max_range);
        if (!hit) continue;
        if (missing && ReturnIsMissing(*missing, rng)) continue;
        double range = hit->distance_m;
        if (range_noise) range += RangeNoise(*range_noise, rng);
        const Eigen::Vector3d p = origin + range * d;
        if (std::abs(p.x()) > e || std::abs(p.y()) > e) continue;  // keep the site's tile
        const double cos_incidence = std::abs(hit->normal.dot(d));
        Record r;
        r.p_local = p;
        r.intensity = static_cast<uint16_t>(std::clamp(by_material ? IntensityByMaterial(*by_material, *hit, cos_incidence) : 25700.0, 0.0, 65535.0));
        r.classification = LasClass(hit->label);
        r.user_data = static_cast<uint8_t>(std::min(line, 255));
        const double left_angle_deg = (eastward ? 1 : -1) * theta * 180 / kPi;
        r.scan_angle = static_cast<int16_t>(std::lround(-left_angle_deg / 0.006));
        r.point_source_id = IsBuildingId(hit->label) ? static_cast<uint16_t>(std::min<uint32_t>(hit->label - kBuildingIdBase + 1, 65535)) : 0;
        r.scan_direction = left_to_right;
        r.edge = a == across - 1;
        r.gps_time = line_start_s + s * scan_period_s + scan_period_s * a / across;
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
        records.push_back(r);
      }
    }
    line_start_s += along * scan_period_s + kLineTurn_s;
  }

  // Offsets: the origin rounded to whole metres, so local millimetres survive in the int32s.
  const Eigen::Vector3d offset = campus.origin.array().round();
  std::string out;
  out.reserve(kHeaderBytes + records.size() * kRecordBytes);
  out += "LASF";
  internal::PutU16(out, 0);       // file source id
  internal::PutU16(out, 0x0010);  // global encoding: WKT bit (required for formats 6-10); GPS week time
  out.append(16, '\0');           // project GUID
  internal::PutU8(out, 1);
  internal::PutU8(out, 4);
  PutFixed(out, "AVE SIMULATION", 32);
  PutFixed(out, "ave-sim airborne-lidar", 32);
  internal::PutU16(out, 1);     // creation day of year
  internal::PutU16(out, 2024);  // creation year: fixed, so files are reproducible
  internal::PutU16(out, kHeaderBytes);
  internal::PutU32(out, kHeaderBytes);  // offset to point data: no VLRs
  internal::PutU32(out, 0);             // number of VLRs
  internal::PutU8(out, 6);
  internal::PutU16(out, kRecordBytes);
  internal::PutU32(out, 0);  // legacy point count: 0 for formats 6-10
  for (int i = 0; i < 5; ++i) internal::PutU32(out, 0);
  for (int i = 0; i < 3; ++i) internal::PutF64(out, kScale);
  for (int i = 0; i < 3; ++i) internal::PutF64(out, offset[i]);
  const Eigen::Vector3d w_lo = records.empty() ? campus.origin : Eigen::Vector3d(lo + campus.origin);
  const Eigen::Vector3d w_hi = records.empty() ? campus.origin : Eigen::Vector3d(hi + campus.origin);
  auto quantised = [&](double world, int axis) { return offset[axis] + kScale * std::llround((world - offset[axis]) / kScale); };
  for (int i = 0; i < 3; ++i) {
    internal::PutF64(out, quantised(w_hi[i], i));
    internal::PutF64(out, quantised(w_lo[i], i));
  }
  internal::PutU64(out, 0);  // waveform data
  internal::PutU64(out, 0);  // first EVLR
  internal::PutU32(out, 0);  // EVLR count
  internal::PutU64(out, records.size());
  internal::PutU64(out, records.size());  // all first returns
  for (int i = 1; i < 15; ++i) internal::PutU64(out, 0);
  if (out.size() != kHeaderBytes) return absl::InternalError("LAS header is " + std::to_string(out.size()) + " bytes, not 375");

  for (const Record& r : records) {
    for (int i = 0; i < 3; ++i) {
      // World minus offset equals local plus (origin - offset): no large numbers are subtracted.
      const double v = (r.p_local[i] + (campus.origin[i] - offset[i])) / kScale;
      internal::PutI32(out, static_cast<int32_t>(std::llround(v)));
    }
    internal::PutU16(out, r.intensity);
    internal::PutU8(out, 0x11);  // return 1 of 1
    internal::PutU8(out, static_cast<uint8_t>((r.scan_direction ? 0x40 : 0) | (r.edge ? 0x80 : 0)));
    internal::PutU8(out, r.classification);
    internal::PutU8(out, r.user_data);
    internal::PutU16(out, static_cast<uint16_t>(r.scan_angle));
    internal::PutU16(out, r.point_source_id);
    internal::PutF64(out, r.gps_time);
  }
  std::ofstream file(las_path, std::ios::binary);
  if (!file) return absl::InternalError("cannot write " + las_path);
  file.write(out.data(), static_cast<std::streamsize>(out.size()));
  if (!file) return absl::InternalError("write failed: " + las_path);
  return absl::OkStatus();
}

absl::StatusOr<LasFile> ReadLas6(const std::string& path) {
  absl::StatusOr<std::string> read = internal::ReadWholeFile(path);
  if (!read.ok()) return read.status();
  const std::string& b = *read;
  if (b.size() < kHeaderBytes || b.compare(0, 4, "LASF") != 0) return absl::InvalidArgumentError(path + ": not a LAS file");
  const char* p = b.data();
  LasFile las;
  las.version_major = static_cast<uint8_t>(p[24]);
  las.version_minor = static_cast<uint8_t>(p[25]);
  las.header_size = internal::GetU16(p + 94);
  las.offset_to_points = internal::GetU32(p + 96);
  las.point_format = static_cast<uint8_t>(p[104]);
  las.record_length = internal::GetU16(p + 105);
  if (las.version_major != 1 || las.version_minor != 4) return absl::InvalidArgumentError(path + ": not LAS 1.4");
  if (las.point_format != 6 || las.record_length < kRecordBytes) return absl::InvalidArgumentError(path + ": not point format 6");
  for (int i = 0; i < 3; ++i) {
    las.scale[i] = internal::GetF64(p + 131 + 8 * i);
    las.offset[i] = internal::GetF64(p + 155 + 8 * i);
    las.max[i] = internal::GetF64(p + 179 + 16 * i);
    las.min[i] = internal::GetF64(p + 187 + 16 * i);
  }
  las.point_count = internal::GetU64(p + 247);
  for (int i = 0; i < 15; ++i) las.points_by_return[i] = internal::GetU64(p + 255 + 8 * i);
  if (las.offset_to_points < las.header_size || las.offset_to_points + las.point_count * las.record_length != b.size()) {
    return absl::InvalidArgumentError(path + ": point count does not match the file size");
  }
  las.points.resize(las.point_count);
  for (uint64_t k = 0; k < las.point_count; ++k) {
    const char* r = p + las.offset_to_points + k * las.record_length;
    LasPoint6& pt = las.points[k];
    for (int i = 0; i < 3; ++i) pt.p_world[i] = static_cast<int32_t>(internal::GetU32(r + 4 * i)) * las.scale[i] + las.offset[i];
    pt.intensity = internal::GetU16(r + 12);
    pt.return_number = static_cast<uint8_t>(r[14]) & 0x0F;
    pt.number_of_returns = static_cast<uint8_t>(r[14]) >> 4;
    pt.classification = static_cast<uint8_t>(r[16]);
    pt.user_data = static_cast<uint8_t>(r[17]);
    pt.scan_angle_deg = static_cast<int16_t>(internal::GetU16(r + 18)) * 0.006;
    pt.point_source_id = internal::GetU16(r + 20);
    pt.gps_time = internal::GetF64(r + 22);
  }
  return las;
}

}  // namespace ave::sim
