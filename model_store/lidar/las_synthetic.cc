#include "model_store/lidar/las_synthetic.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstring>
#include <random>

namespace ave::model {
namespace {

template <typename T>
void PutAt(std::string& out, size_t at, T v) {
  std::memcpy(out.data() + at, &v, sizeof(T));
}
template <typename T>
void Put(std::string& out, T v) {
  out.append(sizeof(T), '\0');
  PutAt(out, out.size() - sizeof(T), v);
}

uint16_t BaseLength(int format) {
  static const uint16_t kLengths[] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
  return kLengths[format];
}

std::string Padded(const std::string& s, size_t n) {
  std::string out = s;
  out.resize(n, '\0');
  return out;
}

void AddVlr(std::string& out, const std::string& user, uint16_t record_id, const std::string& payload, const std::string& what) {
  Put<uint16_t>(out, 0);
  out += Padded(user, 16);
  Put<uint16_t>(out, record_id);
  Put<uint16_t>(out, static_cast<uint16_t>(payload.size()));
  out += Padded(what, 32);
  out += payload;
}

}  // namespace

std::string MakeSyntheticLas(const SyntheticLasSpec& spec, std::vector<bool>* terrain_out, std::vector<bool>* rejected_out) {
  std::mt19937_64 rng(spec.seed);
  auto byte = [&rng]() { return static_cast<char>(rng() & 0xFF); };
  auto random_bytes = [&](size_t n) {
    std::string s(n, '\0');
    for (char& c : s) c = byte();
    return s;
  };
  std::uniform_real_distribution<double> unit(0, 1);
  const int minor = spec.version_minor, format = spec.format;
  const size_t header_size = minor >= 4 ? 375 : minor == 3 ? 235 : 227;
  const uint16_t record_length = static_cast<uint16_t>(BaseLength(format) + spec.extra_bytes);
  const double scale = 0.01;
  // Oregon GIC Lambert (international feet) or a metric grid: survey-sized numbers.
  const double offset[3] = {spec.feet ? 1401000.0 : 427000.0, spec.feet ? 702000.0 : 214000.0, 0.0};

  // VLRs: what a real survey carries for its CRS (GeoTIFF keys + ASCII params + WKT), plus one
  // user VLR, then two stray bytes before the point data (allowed, and must be kept).
  std::string vlrs;
  const uint16_t unit_code = spec.feet ? 9002 : 9001;
  std::string keys;
  for (uint16_t v : {uint16_t{1}, uint16_t{1}, uint16_t{0}, uint16_t{4},  // version 1.1.0, 4 keys
                     uint16_t{1024}, uint16_t{0}, uint16_t{1}, uint16_t{1},  // GTModelType: projected
                     uint16_t{3072}, uint16_t{0}, uint16_t{1}, static_cast<uint16_t>(spec.feet ? 2992 : 32610),
                     uint16_t{3076}, uint16_t{0}, uint16_t{1}, unit_code,  // ProjLinearUnits
                     uint16_t{4099}, uint16_t{0}, uint16_t{1}, unit_code}) {  // VerticalUnits
    Put<uint16_t>(keys, v);
  }
  AddVlr(vlrs, "LASF_Projection", 34735, keys, "GeoKeyDirectoryTag");
  AddVlr(vlrs, "LASF_Projection", 34737, std::string(spec.feet ? "NAD83 / Oregon GIC Lambert (ft)|" : "WGS 84 / UTM 10N|") + '\0',
         "GeoAsciiParamsTag");
  const std::string wkt = spec.feet ? "PROJCS[\"NAD83 / Oregon GIC Lambert (ft)\",GEOGCS[\"NAD83\",DATUM[\"North_American_Datum_1983\"],"
                                      "UNIT[\"degree\",0.0174532925199433]],PROJECTION[\"Lambert_Conformal_Conic_2SP\"],"
                                      "UNIT[\"foot\",0.3048,AUTHORITY[\"EPSG\",\"9002\"]],AUTHORITY[\"EPSG\",\"2992\"]]"
                                    : "PROJCS[\"WGS 84 / UTM zone 10N\",GEOGCS[\"WGS 84\",UNIT[\"degree\",0.0174532925199433]],"
                                      "PROJECTION[\"Transverse_Mercator\"],UNIT[\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]]]";
  AddVlr(vlrs, "LASF_Projection", 2112, wkt + '\0', "OGC WKT");
  AddVlr(vlrs, "ave_synthetic", 7, random_bytes(37), "random payload");
  vlrs += random_bytes(2);
  const uint32_t vlr_count = 4;

  // Points: terrain z = 100 + gentle slope, a 16 x 16 unit building 9 units high in the middle.
  const int n = spec.points;
  std::vector<bool> terrain(n), rejected(n, false);
  for (int i = 0; i < spec.rejected && i < n; ++i) rejected[(i * 7919 + 13) % n] = true;
  std::string records;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  const double c = spec.extent / 2;
  for (int k = 0; k < n; ++k) {
    std::string r = random_bytes(record_length);
    const double x = unit(rng) * spec.extent, y = unit(rng) * spec.extent;
    const bool roof = std::abs(x - c) < 8 && std::abs(y - c) < 8;
    terrain[k] = !roof;
    const double z = 100 + 0.02 * x + 0.01 * y + 0.03 * (unit(rng) - 0.5) + (roof ? 9 : 0);
    const double p[3] = {offset[0] + 50 + x, offset[1] + 50 + y, z};
    for (int i = 0; i < 3; ++i) {
      int32_t q = static_cast<int32_t>(std::lround((p[i] - offset[i]) / scale));
      if (rejected[k] && i == 0) q = INT32_MAX;  // 2.1e7 units from the offset: the reader drops it
      PutAt<int32_t>(r, 4 * i, q);
      if (!rejected[k]) {
        lo[i] = std::min(lo[i], offset[i] + q * scale);
        hi[i] = std::max(hi[i], offset[i] + q * scale);
      }
    }
    if (format == 1 || format >= 3) PutAt<double>(r, format >= 6 ? 22 : 20, 3.0e8 + unit(rng) * 1e6);  // adjusted GPS time
    records += r;
  }

  std::string out(header_size, '\0');
  std::memcpy(out.data(), "LASF", 4);
  PutAt<uint16_t>(out, 4, static_cast<uint16_t>(rng()));                     // file source id
  PutAt<uint16_t>(out, 6, static_cast<uint16_t>(minor >= 4 ? 0x11 : 0x01));  // GPS time type (+ WKT bit in 1.4)
  for (int i = 0; i < 16; ++i) out[8 + i] = byte();                          // project GUID
  out[24] = 1;
  out[25] = static_cast<char>(minor);
  std::memcpy(out.data() + 26, "SYNTHETIC SURVEY", 16);                      // system identifier
  std::memcpy(out.data() + 58, "las_synthetic 1.0", 17);                     // generating software
  PutAt<uint16_t>(out, 90, static_cast<uint16_t>(1 + rng() % 365));          // creation day of year
  PutAt<uint16_t>(out, 92, static_cast<uint16_t>(2000 + rng() % 26));        // creation year
  PutAt<uint16_t>(out, 94, static_cast<uint16_t>(header_size));
  const uint32_t point_offset = static_cast<uint32_t>(header_size + vlrs.size());
  PutAt<uint32_t>(out, 96, point_offset);
  PutAt<uint32_t>(out, 100, vlr_count);
  out[104] = static_cast<char>(format);
  PutAt<uint16_t>(out, 105, record_length);
  PutAt<uint32_t>(out, 107, format >= 6 ? 0u : static_cast<uint32_t>(n));
  for (int i = 0; i < 5; ++i) PutAt<uint32_t>(out, 111 + 4 * i, static_cast<uint32_t>(rng() % 100000));
  for (int i = 0; i < 3; ++i) {
    PutAt<double>(out, 131 + 8 * i, scale);
    PutAt<double>(out, 155 + 8 * i, offset[i]);
    PutAt<double>(out, 179 + 16 * i, hi[i]);
    PutAt<double>(out, 187 + 16 * i, lo[i]);
  }
  std::string evlr;
  if (minor >= 4) {
    PutAt<uint64_t>(out, 247, static_cast<uint64_t>(n));
    for (int i = 0; i < 15; ++i) PutAt<uint64_t>(out, 255 + 8 * i, rng() % 100000);
    if (spec.evlr) {
      const std::string payload = random_bytes(301);
      Put<uint16_t>(evlr, 0);
      evlr += Padded("ave_synthetic", 16);
      Put<uint16_t>(evlr, 9);
      Put<uint64_t>(evlr, payload.size());
      evlr += Padded("random EVLR payload", 32);
      evlr += payload;
      PutAt<uint64_t>(out, 235, point_offset + records.size());
      PutAt<uint32_t>(out, 243, 1);
    }
  }
  out += vlrs;
  out += records;
  out += evlr;
  if (terrain_out) *terrain_out = std::move(terrain);
  if (rejected_out) *rejected_out = std::move(rejected);
  return out;
}

LasRewriteDiff CompareLasExceptClasses(const std::string& before, const std::string& after) {
  LasRewriteDiff diff;
  diff.same_size = before.size() == after.size();
  if (!diff.same_size || before.size() < 227) return diff;
  auto get = [&before]<typename T>(size_t at, T) {
    T v;
    std::memcpy(&v, before.data() + at, sizeof(T));
    return v;
  };
  const int format = static_cast<uint8_t>(before[104]);
  const size_t point_offset = get(96, uint32_t{}), length = get(105, uint16_t{});
  uint64_t count = get(107, uint32_t{});
  if (before[25] >= 4 && (format >= 6 || get(247, uint64_t{}) != 0)) count = get(247, uint64_t{});
  const size_t class_byte = format >= 6 ? 16 : 15;
  const uint8_t class_mask = format >= 6 ? 0xFF : 0x1F;
  const size_t records_end = length && count <= (before.size() - std::min(point_offset, before.size())) / length
                                 ? point_offset + count * length
                                 : point_offset;
  diff.classes_after.reserve(records_end > point_offset ? count : 0);
  for (size_t at = 0; at < before.size(); ++at) {
    if (at >= 58 && at < 90) continue;
    uint8_t mask = 0xFF;
    if (at >= point_offset && at < records_end && (at - point_offset) % length == class_byte) {
      diff.classes_after.push_back(static_cast<uint8_t>(after[at]) & class_mask);
      mask = static_cast<uint8_t>(~class_mask);
      if (mask == 0) continue;
    }
    ++diff.compared;
    if (((before[at] ^ after[at]) & mask) != 0 && diff.differing++ == 0) diff.first_difference = at;
  }
  return diff;
}

}  // namespace ave::model
