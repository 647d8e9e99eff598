#pragma once
// Synthetic LAS files for tests and fuzz seeds (issue 14): a small survey of flat-ish terrain with
// a box building on it, written byte by byte as a real producer would (not by our own writer), so
// a round trip through the reader and the rewriter is checked against independent bytes. Every
// field that is not a position holds random bytes: intensity, returns, flags, classification,
// scan angle, user data, point source id, GPS time (finite), RGB, NIR, wave packet, extra bytes;
// the header gets a random GUID, system id, creation date, counts by return; the VLRs are a
// GeoTIFF GeoKeyDirectory + GeoAsciiParams, an OGC WKT and a user VLR with random payload, then a
// few stray bytes before the point data; LAS 1.4 may add an EVLR after the points.
#include <cstdint>
#include <string>
#include <vector>

namespace ave::model {

struct SyntheticLasSpec {
  int version_minor = 4;    // 2, 3 or 4
  int format = 6;           // 0-10
  int points = 2000;
  uint64_t seed = 1;
  bool feet = false;        // the CRS's unit is the international foot (else the metre)
  bool evlr = false;        // LAS 1.4: one EVLR after the point data
  uint16_t extra_bytes = 0;  // random bytes after each record's standard fields
  int rejected = 0;         // records (of `points`) the reader must drop: X at the int32 limit
  double extent = 60;       // side of the surveyed square, file units
};

// The file's bytes; `terrain` (optional) gets, per record, whether it lies on the terrain (not on
// the building's roof); `rejected` (optional) whether it was made unreadable.
std::string MakeSyntheticLas(const SyntheticLasSpec& spec, std::vector<bool>* terrain = nullptr,
                             std::vector<bool>* rejected = nullptr);

// Byte-by-byte comparison of a LAS file and its rewrite (`after`), laid out as `before`'s header
// says (format, record length, count, point offset read directly, no reader involved): every byte
// but the generating software (58-89) and each record's classification — bits 0-4 of byte 15
// (formats 0-5) or byte 16 (6-10) — must be equal; the flag bits 5-7 of byte 15 count as bytes.
struct LasRewriteDiff {
  bool same_size = false;
  size_t compared = 0;      // bytes compared exactly
  size_t differing = 0;     // of those, how many differ
  size_t first_difference = 0;  // offset of the first that differs
  std::vector<uint8_t> classes_after;  // per record, as `after` holds it (5 bits for 0-5)
};
LasRewriteDiff CompareLasExceptClasses(const std::string& before, const std::string& after);

}  // namespace ave::model
