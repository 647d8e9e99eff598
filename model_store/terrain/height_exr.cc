// OpenEXR height grids: the only file of the terrain library that includes OpenEXR headers.
#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfVecAttribute.h>

#include <cmath>
#include <limits>

#include "model_store/terrain/mesh_export.h"

namespace ave::model {
namespace {

constexpr const char* kOrigin = "aveOrigin";
constexpr const char* kMinXy = "aveMinXY";
constexpr const char* kResolution = "aveResolutionM";

// Image row 0 = grid row rows-1 (north up, as a map).
std::vector<float> Flip(const std::vector<float>& v, int cols, int rows) {
  std::vector<float> out(static_cast<size_t>(cols) * rows, std::numeric_limits<float>::quiet_NaN());
  if (v.size() != out.size()) return out;
  for (int r = 0; r < rows; ++r) {
    std::copy_n(v.begin() + static_cast<size_t>(r) * cols, cols, out.begin() + static_cast<size_t>(rows - 1 - r) * cols);
  }
  return out;
}

}  // namespace

absl::Status WriteHeightExr(const HeightGrid& grid, const std::string& path) {
  if (grid.cols <= 0 || grid.rows <= 0) return absl::InvalidArgumentError(path + ": the height grid is empty");
  std::vector<float> dtm = Flip(grid.dtm, grid.cols, grid.rows), dsm = Flip(grid.zmax, grid.cols, grid.rows);
  try {
    Imf::Header header(grid.cols, grid.rows);
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    header.channels().insert("DSM", Imf::Channel(Imf::FLOAT));
    header.compression() = Imf::ZIP_COMPRESSION;
    header.insert(kOrigin, Imf::V3dAttribute(Imath::V3d(grid.origin.x(), grid.origin.y(), grid.origin.z())));
    header.insert(kMinXy, Imf::V2dAttribute(Imath::V2d(grid.min_xy.x(), grid.min_xy.y())));
    header.insert(kResolution, Imf::DoubleAttribute(grid.resolution_m));
    Imf::FrameBuffer fb;
    fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(dtm.data()), sizeof(float), sizeof(float) * grid.cols));
    fb.insert("DSM", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(dsm.data()), sizeof(float), sizeof(float) * grid.cols));
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(grid.rows);
  } catch (const std::exception& e) {
    return absl::InternalError(path + ": OpenEXR write failed: " + e.what());
  }
  return absl::OkStatus();
}

absl::StatusOr<HeightGrid> ReadHeightExr(const std::string& path) {
  HeightGrid grid;
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i window = file.header().dataWindow();
    grid.cols = window.max.x - window.min.x + 1;
    grid.rows = window.max.y - window.min.y + 1;
    const auto* origin = file.header().findTypedAttribute<Imf::V3dAttribute>(kOrigin);
    const auto* min_xy = file.header().findTypedAttribute<Imf::V2dAttribute>(kMinXy);
    const auto* resolution = file.header().findTypedAttribute<Imf::DoubleAttribute>(kResolution);
    if (!origin || !min_xy || !resolution) return absl::InvalidArgumentError(path + ": not an ave-model height grid (attributes missing)");
    grid.origin = {origin->value().x, origin->value().y, origin->value().z};
    grid.min_xy = {min_xy->value().x, min_xy->value().y};
    grid.resolution_m = resolution->value();
    if (!file.header().channels().findChannel("Z")) return absl::InvalidArgumentError(path + ": no Z channel");
    std::vector<float> dtm(grid.CellCount()), dsm(grid.CellCount(), std::numeric_limits<float>::quiet_NaN());
    Imf::FrameBuffer fb;
    const size_t base = static_cast<size_t>(window.min.x) + static_cast<size_t>(window.min.y) * grid.cols;
    fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(dtm.data() - base), sizeof(float), sizeof(float) * grid.cols));
    fb.insert("DSM", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(dsm.data() - base), sizeof(float), sizeof(float) * grid.cols));
    file.setFrameBuffer(fb);
    file.readPixels(window.min.y, window.max.y);
    grid.dtm = Flip(dtm, grid.cols, grid.rows);
    grid.zmax = Flip(dsm, grid.cols, grid.rows);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(path + ": OpenEXR read failed: " + e.what());
  }
  return grid;
}

}  // namespace ave::model
