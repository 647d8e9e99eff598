#pragma once
// A LiDAR point cloud under a double-precision local origin (MISSION part A): every position is a
// float offset in metres from `origin`, so survey coordinates near 1e6-1e7 m keep millimetres.
// Readers (las_reader.h, PCD, PLY) fill it; terrain/ and buildings/ consume it.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ave::model {

struct PointCloud {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates (metres) of the local zero
  std::vector<Eigen::Vector3f> xyz;                  // metres, relative to origin
  // Optional attributes: empty, or one entry per point.
  std::vector<uint16_t> intensity;
  std::vector<uint8_t> classification;   // LAS codes as read from the file
  std::vector<uint16_t> point_source_id;
  std::vector<uint8_t> return_number, number_of_returns;
  std::vector<double> gps_time;
  // Linear unit of the input, already applied (positions above are metres).
  double unit_to_metres = 1.0;
  std::string unit_name = "metre";
  uint64_t rejected_non_finite = 0;  // points dropped on reading for NaN/inf coordinates
  // The file record each point came from when the reader dropped some; empty when point k is
  // record k (so also when no point was kept). Lets a writer patch the right records of the
  // source file (las_rewrite.h).
  std::vector<uint64_t> record_index;
  // The file the points were read from, so a tool can rewrite that file keeping every byte it
  // does not change, and refuse when the file changed since it was read. Empty path: in memory.
  struct Source {
    std::string path;
    std::string format;        // "las", "ply", "pcd"
    uint64_t size_bytes = 0;
    uint64_t fingerprint = 0;  // Fingerprint64 (read_file.h) of the whole file as read
  } source;

  size_t size() const { return xyz.size(); }
};

}  // namespace ave::model
