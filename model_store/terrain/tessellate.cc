#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "model_store/terrain/mesh_export.h"

namespace ave::model {
namespace {

struct Block {
  int x, y, size;  // vertex coordinates of the lower-left corner; side in cells
};

class Tessellator {
 public:
  Tessellator(const HeightGrid& grid, const TessellateOptions& options) : g_(grid), o_(options) {}

  TriangleMesh Run() {
    TriangleMesh mesh;
    mesh.origin = g_.origin;
    if (g_.dtm.size() != g_.CellCount() || g_.cols < 2 || g_.rows < 2) return mesh;
    const int s = o_.max_block_cells;
    for (int y = 0; y < g_.rows - 1; y += s) {
      for (int x = 0; x < g_.cols - 1; x += s) Split({x, y, s});
    }
    active_.assign(g_.CellCount(), 0);
    for (const Block& b : leaves_) {
      for (int dy : {0, b.size}) {
        for (int dx : {0, b.size}) active_[g_.Index(b.x + dx, b.y + dy)] = 1;
      }
    }
    for (const Block& b : leaves_) Emit(b, mesh);
    mesh.triangle_material.assign(mesh.TriangleCount(), SurfaceMaterial::kTerrain);
    mesh.triangle_object.assign(mesh.TriangleCount(), -1);
    return mesh;
  }

 private:
  float Z(int x, int y) const { return g_.dtm[g_.Index(x, y)]; }

  bool Inside(const Block& b) const { return b.x + b.size <= g_.cols - 1 && b.y + b.size <= g_.rows - 1; }

  bool Flat(const Block& b) const {
    const float z00 = Z(b.x, b.y), z10 = Z(b.x + b.size, b.y), z01 = Z(b.x, b.y + b.size), z11 = Z(b.x + b.size, b.y + b.size);
    for (int j = 0; j <= b.size; ++j) {
      for (int i = 0; i <= b.size; ++i) {
        const float u = static_cast<float>(i) / b.size, v = static_cast<float>(j) / b.size;
        const float bilinear = (z00 * (1 - u) + z10 * u) * (1 - v) + (z01 * (1 - u) + z11 * u) * v;
        if (!(std::abs(Z(b.x + i, b.y + j) - bilinear) <= o_.flat_tolerance_m)) return false;
      }
    }
    return true;
  }

  void Split(const Block& b) {
    if (b.x >= g_.cols - 1 || b.y >= g_.rows - 1) return;
    if (Inside(b) && (b.size == 1 || Flat(b))) {
      leaves_.push_back(b);
      return;
    }
    const int h = b.size / 2;
    for (int dy : {0, h}) {
      for (int dx : {0, h}) Split({b.x + dx, b.y + dy, h});
    }
  }

  uint32_t Vertex(int x, int y, TriangleMesh& mesh) {
    const size_t key = g_.Index(x, y);
    auto [it, added] = index_.try_emplace(key, static_cast<uint32_t>(mesh.positions.size()));
    if (added) {
      const Eigen::Vector2d c = g_.CellCenter(x, y);
      mesh.positions.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()), Z(x, y));
      // Central differences of the DTM (one-sided at the border).
      const int xl = std::max(x - 1, 0), xr = std::min(x + 1, g_.cols - 1), yl = std::max(y - 1, 0), yr = std::min(y + 1, g_.rows - 1);
      const double dzdx = (Z(xr, y) - Z(xl, y)) / ((xr - xl) * g_.resolution_m);
      const double dzdy = (Z(x, yr) - Z(x, yl)) / ((yr - yl) * g_.resolution_m);
      mesh.normals.push_back(Eigen::Vector3d(-dzdx, -dzdy, 1).normalized().cast<float>());
      mesh.colors.emplace_back(0.55f, 0.60f, 0.45f);
    }
    return it->second;
  }

  void Emit(const Block& b, TriangleMesh& mesh) {
    // The rim counter-clockwise seen from above: south, east, north, west edges.
    std::vector<uint32_t> rim;
    const int x0 = b.x, y0 = b.y, x1 = b.x + b.size, y1 = b.y + b.size;
    for (int x = x0; x < x1; ++x) if (active_[g_.Index(x, y0)]) rim.push_back(Vertex(x, y0, mesh));
    for (int y = y0; y < y1; ++y) if (active_[g_.Index(x1, y)]) rim.push_back(Vertex(x1, y, mesh));
    for (int x = x1; x > x0; --x) if (active_[g_.Index(x, y1)]) rim.push_back(Vertex(x, y1, mesh));
    for (int y = y1; y > y0; --y) if (active_[g_.Index(x0, y)]) rim.push_back(Vertex(x0, y, mesh));
    auto tri = [&mesh](uint32_t a, uint32_t c, uint32_t d) { mesh.indices.insert(mesh.indices.end(), {a, c, d}); };
    if (rim.size() == 4) {
      tri(rim[0], rim[1], rim[2]);
      tri(rim[0], rim[2], rim[3]);
      return;
    }
    const uint32_t centre = Vertex(x0 + b.size / 2, y0 + b.size / 2, mesh);
    for (size_t i = 0; i < rim.size(); ++i) tri(centre, rim[i], rim[(i + 1) % rim.size()]);
  }

  const HeightGrid& g_;
  const TessellateOptions& o_;
  std::vector<Block> leaves_;
  std::vector<uint8_t> active_;
  std::unordered_map<size_t, uint32_t> index_;
};

}  // namespace

std::string TessellateOptions::Check() const {
  if (!std::isfinite(flat_tolerance_m) || flat_tolerance_m < 0) return "flat_tolerance_m must be finite and >= 0";
  if (max_block_cells < 1 || max_block_cells > 1024 || (max_block_cells & (max_block_cells - 1)) != 0) {
    return "max_block_cells must be a power of two in [1, 1024]";
  }
  return {};
}

TriangleMesh TessellateDtm(const HeightGrid& grid, const TessellateOptions& options) {
  TessellateOptions checked = options;
  if (!checked.Check().empty()) checked = TessellateOptions{};
  return Tessellator(grid, checked).Run();
}

}  // namespace ave::model
