#include "model_store/scene/campus.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ave::scene {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector3f;

const Vector3f kTerrainColor(0.56f, 0.60f, 0.50f);
const Vector3f kRoadColor(0.47f, 0.47f, 0.46f);
const Vector3f kWallColor(0.78f, 0.76f, 0.72f);
const Vector3f kRoofColor(0.62f, 0.58f, 0.55f);
const Vector3f kTrunkColor(0.40f, 0.30f, 0.20f);
const Vector3f kCrownColor(0.30f, 0.48f, 0.24f);

constexpr int kRoundSegments = 48;
constexpr int kDomeRings = 12;

// Coordinates of (x, y) in a part's own frame.
Vector2d ToPartFrame(const BuildingPart& b, double x, double y) {
  const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
  const double dx = x - b.center_m.x(), dy = y - b.center_m.y();
  return {c * dx + s * dy, -s * dx + c * dy};
}

bool IsRound(PrimitiveKind k) { return k == PrimitiveKind::kCylinder || k == PrimitiveKind::kDome; }

// Builds one building part's faces. Every triangle gets its own three vertices with its flat
// normal, oriented away from the part's interior.
class PartMesher {
 public:
  PartMesher(TriangleMesh& mesh, const BuildingPart& part, double base_z, double eave_z, int32_t object)
      : mesh_(mesh), part_(part), z0_(base_z), ze_(eave_z), zt_(eave_z + part.roof_height_m), object_(object) {
    const double c = std::cos(part.yaw_rad), s = std::sin(part.yaw_rad);
    ax_ = Vector3d(c, s, 0);
    ay_ = Vector3d(-s, c, 0);
    interior_ = Vector3d(part.center_m.x(), part.center_m.y(), 0.5 * (z0_ + ze_));
  }

  void Mesh() {
    const double hx = 0.5 * part_.size_m.x(), hy = 0.5 * part_.size_m.y();
    switch (part_.kind) {
      case PrimitiveKind::kBox: {
        Walls({{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}});
        Roof({P(-hx, -hy, ze_), P(hx, -hy, ze_), P(hx, hy, ze_), P(-hx, hy, ze_)});
        break;
      }
      case PrimitiveKind::kGable: {
        Wall({P(-hx, -hy, z0_), P(hx, -hy, z0_), P(hx, -hy, ze_), P(-hx, -hy, ze_)});
        Wall({P(hx, hy, z0_), P(-hx, hy, z0_), P(-hx, hy, ze_), P(hx, hy, ze_)});
        for (double sx : {-hx, hx}) Wall({P(sx, -hy, z0_), P(sx, hy, z0_), P(sx, hy, ze_), P(sx, 0, zt_), P(sx, -hy, ze_)});
        Roof({P(-hx, -hy, ze_), P(hx, -hy, ze_), P(hx, 0, zt_), P(-hx, 0, zt_)});
        Roof({P(hx, hy, ze_), P(-hx, hy, ze_), P(-hx, 0, zt_), P(hx, 0, zt_)});
        break;
      }
      case PrimitiveKind::kShed: {
        Wall({P(-hx, -hy, z0_), P(hx, -hy, z0_), P(hx, -hy, ze_), P(-hx, -hy, ze_)});
        Wall({P(hx, hy, z0_), P(-hx, hy, z0_), P(-hx, hy, zt_), P(hx, hy, zt_)});
        for (double sx : {-hx, hx}) Wall({P(sx, -hy, z0_), P(sx, hy, z0_), P(sx, hy, zt_), P(sx, -hy, ze_)});
        Roof({P(-hx, -hy, ze_), P(hx, -hy, ze_), P(hx, hy, zt_), P(-hx, hy, zt_)});
        break;
      }
      case PrimitiveKind::kHip: {
        Walls({{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}});
        // Ridge along the longer axis; the four slopes share one pitch (rise over the shorter half).
        if (hx >= hy) {
          const double r = hx - hy;
          Roof({P(-hx, -hy, ze_), P(hx, -hy, ze_), P(r, 0, zt_), P(-r, 0, zt_)});
          Roof({P(hx, hy, ze_), P(-hx, hy, ze_), P(-r, 0, zt_), P(r, 0, zt_)});
          Roof({P(hx, -hy, ze_), P(hx, hy, ze_), P(r, 0, zt_)});
          Roof({P(-hx, hy, ze_), P(-hx, -hy, ze_), P(-r, 0, zt_)});
        } else {
          const double r = hy - hx;
          Roof({P(hx, -hy, ze_), P(hx, hy, ze_), P(0, r, zt_), P(0, -r, zt_)});
          Roof({P(-hx, hy, ze_), P(-hx, -hy, ze_), P(0, -r, zt_), P(0, r, zt_)});
          Roof({P(-hx, -hy, ze_), P(hx, -hy, ze_), P(0, -r, zt_)});
          Roof({P(hx, hy, ze_), P(-hx, hy, ze_), P(0, r, zt_)});
        }
        break;
      }
      case PrimitiveKind::kCylinder:
      case PrimitiveKind::kDome: {
        std::vector<Vector2d> ring;
        for (int i = 0; i < kRoundSegments; ++i) {
          const double a = 2 * M_PI * i / kRoundSegments;
          ring.emplace_back(hx * std::cos(a), hy * std::sin(a));
        }
        Walls(ring);
        const Vector3d centre = P(0, 0, ze_);
        if (part_.kind == PrimitiveKind::kCylinder || !(part_.roof_height_m > 0)) {
          for (int i = 0; i < kRoundSegments; ++i) {
            const Vector2d& a = ring[i];
            const Vector2d& b = ring[(i + 1) % kRoundSegments];
            Roof({centre, P(a.x(), a.y(), ze_), P(b.x(), b.y(), ze_)});
          }
          break;
        }
        auto dome = [&](int i, int k) {  // ring point i at elevation step k (k = kDomeRings: apex)
          const double phi = 0.5 * M_PI * k / kDomeRings, a = 2 * M_PI * i / kRoundSegments;
          if (k == kDomeRings) return P(0, 0, zt_);
          return P(hx * std::cos(phi) * std::cos(a), hy * std::cos(phi) * std::sin(a), ze_ + part_.roof_height_m * std::sin(phi));
        };
        for (int k = 0; k < kDomeRings; ++k) {
          for (int i = 0; i < kRoundSegments; ++i) {
            const int j = (i + 1) % kRoundSegments;
            if (k + 1 == kDomeRings) {
              Roof({dome(i, k), dome(j, k), dome(i, k + 1)});
            } else {
              Roof({dome(i, k), dome(j, k), dome(j, k + 1)});
              Roof({dome(i, k), dome(j, k + 1), dome(i, k + 1)});
            }
          }
        }
        break;
      }
    }
  }

 private:
  Vector3d P(double px, double py, double z) const {
    const Vector3d xy = Vector3d(part_.center_m.x(), part_.center_m.y(), 0) + px * ax_ + py * ay_;
    return {xy.x(), xy.y(), z};
  }
  // Vertical walls along a closed footprint polygon (part frame), base to eaves.
  void Walls(const std::vector<Vector2d>& footprint) {
    for (size_t i = 0; i < footprint.size(); ++i) {
      const Vector2d& a = footprint[i];
      const Vector2d& b = footprint[(i + 1) % footprint.size()];
      Wall({P(a.x(), a.y(), z0_), P(b.x(), b.y(), z0_), P(b.x(), b.y(), ze_), P(a.x(), a.y(), ze_)});
    }
  }
  void Wall(const std::vector<Vector3d>& polygon) { Polygon(polygon, kWallColor, SurfaceMaterial::kWall); }
  void Roof(const std::vector<Vector3d>& polygon) { Polygon(polygon, kRoofColor, SurfaceMaterial::kRoof); }

  // A planar convex polygon as a fan; reversed when its normal faces the part's interior.
  void Polygon(std::vector<Vector3d> polygon, const Vector3f& color, SurfaceMaterial material) {
    Vector3d normal = Vector3d::Zero(), centroid = Vector3d::Zero();
    for (size_t i = 0; i < polygon.size(); ++i) {
      const Vector3d& a = polygon[i];
      const Vector3d& b = polygon[(i + 1) % polygon.size()];
      normal += Vector3d((a.y() - b.y()) * (a.z() + b.z()), (a.z() - b.z()) * (a.x() + b.x()), (a.x() - b.x()) * (a.y() + b.y()));
      centroid += a;
    }
    centroid /= static_cast<double>(polygon.size());
    if (!(normal.norm() > 1e-12)) return;  // degenerate (e.g. a zero-height wall)
    if (normal.dot(centroid - interior_) < 0) {
      std::reverse(polygon.begin(), polygon.end());
      normal = -normal;
    }
    const Vector3f n = normal.normalized().cast<float>();
    for (size_t i = 1; i + 1 < polygon.size(); ++i) {
      const uint32_t first = static_cast<uint32_t>(mesh_.positions.size());
      for (const Vector3d* p : {&polygon[0], &polygon[i], &polygon[i + 1]}) {
        mesh_.positions.push_back(p->cast<float>());
        mesh_.normals.push_back(n);
        mesh_.colors.push_back(color);
      }
      mesh_.indices.insert(mesh_.indices.end(), {first, first + 1, first + 2});
      mesh_.triangle_material.push_back(material);
      mesh_.triangle_object.push_back(object_);
    }
  }

  TriangleMesh& mesh_;
  const BuildingPart& part_;
  double z0_, ze_, zt_;
  int32_t object_;
  Vector3d ax_, ay_, interior_;
};

// An upright prism (n sides, elliptic radii rx, ry) from z0 to z1 with a flat top; flat normals.
void AppendPrism(TriangleMesh& mesh, const Vector2d& centre, double rx, double ry, double z0, double z1, int sides,
                 const Vector3f& color, SurfaceMaterial material, bool top) {
  auto add = [&](const Vector3d& a, const Vector3d& b, const Vector3d& c) {
    const Vector3f n = (b - a).cross(c - a).normalized().cast<float>();
    const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
    for (const Vector3d* p : {&a, &b, &c}) {
      mesh.positions.push_back(p->cast<float>());
      mesh.normals.push_back(n);
      mesh.colors.push_back(color);
    }
    mesh.indices.insert(mesh.indices.end(), {first, first + 1, first + 2});
    mesh.triangle_material.push_back(material);
    mesh.triangle_object.push_back(-1);
  };
  for (int i = 0; i < sides; ++i) {
    const double a0 = 2 * M_PI * i / sides, a1 = 2 * M_PI * (i + 1) / sides;
    const Vector3d p0(centre.x() + rx * std::cos(a0), centre.y() + ry * std::sin(a0), z0);
    const Vector3d p1(centre.x() + rx * std::cos(a1), centre.y() + ry * std::sin(a1), z0);
    const Vector3d q0(p0.x(), p0.y(), z1), q1(p1.x(), p1.y(), z1);
    add(p0, p1, q1);
    add(p0, q1, q0);
    if (top) add(Vector3d(centre.x(), centre.y(), z1), q0, q1);
  }
}

double DistanceToSegment(const Vector2d& p, const Vector2d& a, const Vector2d& b, double* t_along) {
  const Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  *t_along = t * std::sqrt(len2);
  return (p - (a + t * ab)).norm();
}

}  // namespace

const char* PrimitiveName(PrimitiveKind kind) {
  switch (kind) {
    case PrimitiveKind::kBox: return "box";
    case PrimitiveKind::kGable: return "gable";
    case PrimitiveKind::kShed: return "shed";
    case PrimitiveKind::kHip: return "hip";
    case PrimitiveKind::kCylinder: return "cylinder";
    case PrimitiveKind::kDome: return "dome";
  }
  return "unknown";
}

std::vector<BuildingPart> BoxBuilding::Parts() const {
  std::vector<BuildingPart> parts{static_cast<const BuildingPart&>(*this)};
  parts.insert(parts.end(), extra_parts.begin(), extra_parts.end());
  return parts;
}

double SyntheticCampus::TerrainHeight(double x, double y) const {
  if (terrain.kind == Terrain::Kind::kGrid && terrain.grid_cols >= 2 && terrain.grid_rows >= 2 &&
      terrain.heights_m.size() == static_cast<size_t>(terrain.grid_cols) * terrain.grid_rows) {
    const double gx = std::clamp((x - terrain.grid_origin_m.x()) / terrain.grid_spacing_m, 0.0, terrain.grid_cols - 1.0);
    const double gy = std::clamp((y - terrain.grid_origin_m.y()) / terrain.grid_spacing_m, 0.0, terrain.grid_rows - 1.0);
    if (!std::isfinite(gx) || !std::isfinite(gy)) return 0;
    const int c = std::min(static_cast<int>(gx), terrain.grid_cols - 2), r = std::min(static_cast<int>(gy), terrain.grid_rows - 2);
    const double fx = gx - c, fy = gy - r;
    auto h = [&](int cc, int rr) { return terrain.heights_m[static_cast<size_t>(rr) * terrain.grid_cols + cc]; };
    return (1 - fy) * ((1 - fx) * h(c, r) + fx * h(c + 1, r)) + fy * ((1 - fx) * h(c, r + 1) + fx * h(c + 1, r + 1));
  }
  const Terrain& t = terrain;
  return t.amplitude_m * std::sin(x / t.length_x_m) * std::cos(y / t.length_y_m) + t.tilt_x * x + t.tilt_y * y;
}

Eigen::Vector3d SyntheticCampus::TerrainNormal(double x, double y) const {
  double dhdx = 0, dhdy = 0;
  if (terrain.kind == Terrain::Kind::kGrid) {
    const double d = 0.25 * terrain.grid_spacing_m;
    dhdx = (TerrainHeight(x + d, y) - TerrainHeight(x - d, y)) / (2 * d);
    dhdy = (TerrainHeight(x, y + d) - TerrainHeight(x, y - d)) / (2 * d);
  } else {
    const Terrain& t = terrain;
    dhdx = t.amplitude_m / t.length_x_m * std::cos(x / t.length_x_m) * std::cos(y / t.length_y_m) + t.tilt_x;
    dhdy = -t.amplitude_m / t.length_y_m * std::sin(x / t.length_x_m) * std::sin(y / t.length_y_m) + t.tilt_y;
  }
  const Vector3d n(-dhdx, -dhdy, 1.0);
  return n.allFinite() ? Vector3d(n.normalized()) : Vector3d::UnitZ();
}

std::optional<RoadPoint> SyntheticCampus::RoadAt(double x, double y) const {
  std::optional<RoadPoint> best;
  int covering = 0;
  const Vector2d p(x, y);
  for (const Road& road : roads) {
    double along_start = 0;
    std::optional<RoadPoint> on_this;
    for (size_t i = 0; i + 1 < road.points_m.size(); ++i) {
      double t = 0;
      const double d = DistanceToSegment(p, road.points_m[i], road.points_m[i + 1], &t);
      if (d <= road.half_width_m && (!on_this || d < on_this->across_m)) on_this = RoadPoint{d, along_start + t, road.half_width_m, false};
      along_start += (road.points_m[i + 1] - road.points_m[i]).norm();
    }
    if (!on_this) continue;
    ++covering;
    if (!best || on_this->across_m < best->across_m) best = on_this;
  }
  if (best) best->crossing = covering > 1;
  return best;
}

bool SyntheticCampus::IsRoad(double x, double y) const { return RoadAt(x, y).has_value(); }

bool PartCovers(const BuildingPart& part, double x, double y) {
  const Vector2d p = ToPartFrame(part, x, y);
  const double hx = 0.5 * part.size_m.x(), hy = 0.5 * part.size_m.y();
  if (IsRound(part.kind)) return (p.x() / hx) * (p.x() / hx) + (p.y() / hy) * (p.y() / hy) <= 1.0;
  return std::abs(p.x()) <= hx && std::abs(p.y()) <= hy;
}

int SyntheticCampus::BuildingAt(double x, double y) const {
  for (size_t i = 0; i < buildings.size(); ++i) {
    if (PartCovers(buildings[i], x, y)) return static_cast<int>(i);
    for (const BuildingPart& part : buildings[i].extra_parts)
      if (PartCovers(part, x, y)) return static_cast<int>(i);
  }
  return -1;
}

std::vector<Eigen::Vector2d> FootprintCorners(const BuildingPart& b) {
  const double c = std::cos(b.yaw_rad), s = std::sin(b.yaw_rad);
  const Vector2d ax(c, s), ay(-s, c);
  const double hx = 0.5 * b.size_m.x(), hy = 0.5 * b.size_m.y();
  return {b.center_m - hx * ax - hy * ay, b.center_m + hx * ax - hy * ay, b.center_m + hx * ax + hy * ay,
          b.center_m - hx * ax + hy * ay};
}

double SyntheticCampus::BuildingBase(const BoxBuilding& b) const {
  double lowest = std::numeric_limits<double>::infinity();
  for (const BuildingPart& part : b.Parts()) {
    lowest = std::min(lowest, TerrainHeight(part.center_m.x(), part.center_m.y()));
    for (const auto& c : FootprintCorners(part)) lowest = std::min(lowest, TerrainHeight(c.x(), c.y()));
  }
  return lowest - 0.5;  // sunk in so no gap shows on slopes
}

double SyntheticCampus::BuildingGround(const BoxBuilding& b) const {
  double highest = -std::numeric_limits<double>::infinity();
  for (const BuildingPart& part : b.Parts()) {
    highest = std::max(highest, TerrainHeight(part.center_m.x(), part.center_m.y()));
    for (const auto& c : FootprintCorners(part)) highest = std::max(highest, TerrainHeight(c.x(), c.y()));
  }
  return highest;
}

double SyntheticCampus::BuildingTop(const BoxBuilding& b) const {
  double top = -std::numeric_limits<double>::infinity();
  for (const BuildingPart& part : b.Parts()) top = std::max(top, part.height_m + part.roof_height_m);
  return BuildingGround(b) + top;
}

std::optional<double> SyntheticCampus::RoofHeightAt(const BoxBuilding& b, double x, double y) const {
  std::optional<double> best;
  const double ground = BuildingGround(b);
  for (const BuildingPart& part : b.Parts()) {
    if (!PartCovers(part, x, y)) continue;
    const Vector2d p = ToPartFrame(part, x, y);
    const double hx = 0.5 * part.size_m.x(), hy = 0.5 * part.size_m.y(), rise = part.roof_height_m;
    double z = ground + part.height_m;
    switch (part.kind) {
      case PrimitiveKind::kBox:
      case PrimitiveKind::kCylinder: break;
      case PrimitiveKind::kGable: z += rise * (1 - std::abs(p.y()) / hy); break;
      case PrimitiveKind::kShed: z += rise * (p.y() + hy) / (2 * hy); break;
      case PrimitiveKind::kHip: {
        const double h_short = std::min(hx, hy);
        z += rise * std::min((hx - std::abs(p.x())) / h_short, (hy - std::abs(p.y())) / h_short);
        break;
      }
      case PrimitiveKind::kDome: {
        const double rho2 = (p.x() / hx) * (p.x() / hx) + (p.y() / hy) * (p.y() / hy);
        z += rise * std::sqrt(std::max(0.0, 1 - rho2));
        break;
      }
    }
    best = best ? std::max(*best, z) : z;
  }
  return best;
}

const CameraSpec* SyntheticCampus::FindCamera(const std::string& id) const {
  for (const auto& c : cameras)
    if (c.id == id) return &c;
  return nullptr;
}

void AppendBox(TriangleMesh& mesh, const Eigen::Vector3d& base, double yaw_rad, const Eigen::Vector3d& extent,
               const Eigen::Vector3f& wall_color, const Eigen::Vector3f& roof_color, int32_t object,
               SurfaceMaterial wall_material, SurfaceMaterial roof_material) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Vector3d ax(c, s, 0), ay(-s, c, 0), az(0, 0, 1);
  const double hx = 0.5 * extent.x(), hy = 0.5 * extent.y(), h = extent.z();
  auto corner = [&](double sx, double sy, double sz) -> Vector3f {
    return (base + sx * hx * ax + sy * hy * ay + sz * h * az).cast<float>();
  };
  auto quad = [&](Vector3f a, Vector3f b, Vector3f cc, Vector3f d, const Vector3f& color, SurfaceMaterial material) {
    const Vector3f n = (b - a).cross(cc - a).normalized();
    const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
    for (const auto& p : {a, b, cc, d}) {
      mesh.positions.push_back(p);
      mesh.normals.push_back(n);
      mesh.colors.push_back(color);
    }
    mesh.indices.insert(mesh.indices.end(), {first, first + 1, first + 2, first, first + 2, first + 3});
    for (int i = 0; i < 2; ++i) {
      mesh.triangle_material.push_back(material);
      mesh.triangle_object.push_back(object);
    }
  };
  // Walls (outward, counter-clockwise seen from outside), then the roof.
  quad(corner(-1, -1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(-1, -1, 1), wall_color, wall_material);
  quad(corner(1, -1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, -1, 1), wall_color, wall_material);
  quad(corner(1, 1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(1, 1, 1), wall_color, wall_material);
  quad(corner(-1, 1, 0), corner(-1, -1, 0), corner(-1, -1, 1), corner(-1, 1, 1), wall_color, wall_material);
  quad(corner(-1, -1, 1), corner(1, -1, 1), corner(1, 1, 1), corner(-1, 1, 1), roof_color, roof_material);
}

size_t AppendTree(TriangleMesh& mesh, const SyntheticCampus& campus, const Tree& tree) {
  const double ground = campus.TerrainHeight(tree.position_m.x(), tree.position_m.y());
  const double crown_z = ground + tree.trunk_height_m + tree.crown_radius_m;
  // The trunk reaches into the crown so no gap shows when the crown sways.
  AppendPrism(mesh, tree.position_m, tree.trunk_radius_m, tree.trunk_radius_m, ground - 0.3,
              ground + tree.trunk_height_m + 0.5 * tree.crown_radius_m, 8, kTrunkColor, SurfaceMaterial::kVegetation, false);
  const size_t crown_first = mesh.positions.size();
  // Crown: a UV sphere, 12 segments by 8 rings, flat-shaded triangles.
  constexpr int kSeg = 12, kRings = 8;
  auto point = [&](int i, int k) {
    const double theta = M_PI * k / kRings, a = 2 * M_PI * i / kSeg;
    return Vector3d(tree.position_m.x() + tree.crown_radius_m * std::sin(theta) * std::cos(a),
                    tree.position_m.y() + tree.crown_radius_m * std::sin(theta) * std::sin(a),
                    crown_z + tree.crown_radius_m * std::cos(theta));
  };
  const Vector3d centre(tree.position_m.x(), tree.position_m.y(), crown_z);
  auto add = [&](const Vector3d& a, const Vector3d& b, const Vector3d& c) {
    Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 1e-12)) return;
    if (n.dot((a + b + c) / 3 - centre) < 0) n = -n;
    const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
    for (const Vector3d* p : {&a, &b, &c}) {
      mesh.positions.push_back(p->cast<float>());
      mesh.normals.push_back(n.normalized().cast<float>());
      mesh.colors.push_back(kCrownColor);
    }
    mesh.indices.insert(mesh.indices.end(), {first, first + 1, first + 2});
    mesh.triangle_material.push_back(SurfaceMaterial::kVegetation);
    mesh.triangle_object.push_back(-1);
  };
  for (int k = 0; k < kRings; ++k) {
    for (int i = 0; i < kSeg; ++i) {
      const int j = (i + 1) % kSeg;
      // Quads between rings; at the poles one of the two triangles is degenerate and skipped.
      add(point(i, k), point(j, k), point(j, k + 1));
      add(point(i, k), point(j, k + 1), point(i, k + 1));
    }
  }
  return crown_first;
}

TriangleMesh BuildStaticMesh(const SyntheticCampus& campus, double grid_resolution_m) {
  TriangleMesh mesh;
  mesh.origin = campus.origin;
  const double e = campus.half_extent_m;
  const int n = std::max(2, static_cast<int>(std::ceil(2 * e / grid_resolution_m)) + 1);
  const double step = 2 * e / (n - 1);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double x = -e + i * step, y = -e + j * step;
      mesh.positions.emplace_back(x, y, campus.TerrainHeight(x, y));
      mesh.normals.push_back(campus.TerrainNormal(x, y).cast<float>());
      mesh.colors.push_back(campus.IsRoad(x, y) ? kRoadColor : kTerrainColor);
    }
  }
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      mesh.indices.insert(mesh.indices.end(), {a, b, c, a, c, d});
      const double cx = -e + (i + 0.5) * step, cy = -e + (j + 0.5) * step;
      const SurfaceMaterial m = campus.IsRoad(cx, cy) ? SurfaceMaterial::kRoad : SurfaceMaterial::kTerrain;
      for (int k = 0; k < 2; ++k) {
        mesh.triangle_material.push_back(m);
        mesh.triangle_object.push_back(-1);
      }
    }
  }
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    const BoxBuilding& b = campus.buildings[i];
    const double base = campus.BuildingBase(b), ground = campus.BuildingGround(b);
    for (const BuildingPart& part : b.Parts()) {
      PartMesher(mesh, part, base, ground + part.height_m, static_cast<int32_t>(i)).Mesh();
    }
  }
  for (const Tree& tree : campus.trees) AppendTree(mesh, campus, tree);
  for (const StaticObject& o : campus.objects) {
    const double ground = campus.TerrainHeight(o.position_m.x(), o.position_m.y());
    double lowest = ground;
    for (const auto& c : FootprintCorners(BuildingPart{PrimitiveKind::kBox, o.position_m, o.size_m.head<2>(), o.yaw_rad}))
      lowest = std::min(lowest, campus.TerrainHeight(c.x(), c.y()));
    if (o.shape == StaticObject::Shape::kBox) {
      AppendBox(mesh, Vector3d(o.position_m.x(), o.position_m.y(), lowest - 0.2), o.yaw_rad,
                Vector3d(o.size_m.x(), o.size_m.y(), ground + o.size_m.z() - (lowest - 0.2)), o.color, o.color, -1,
                SurfaceMaterial::kObject, SurfaceMaterial::kObject);
    } else {
      AppendPrism(mesh, o.position_m, 0.5 * o.size_m.x(), 0.5 * o.size_m.y(), lowest - 0.2, ground + o.size_m.z(), 16, o.color,
                  SurfaceMaterial::kObject, true);
    }
  }
  return mesh;
}

MoverState MoverAt(const SyntheticCampus& campus, const Mover& mover, double t_s) {
  MoverState state;
  const size_t n = mover.loop_m.size();
  if (n == 0) return state;
  if (n == 1) {
    state.position_m = {mover.loop_m[0].x(), mover.loop_m[0].y(), campus.TerrainHeight(mover.loop_m[0].x(), mover.loop_m[0].y())};
    return state;
  }
  double perimeter = 0;
  for (size_t i = 0; i < n; ++i) perimeter += (mover.loop_m[(i + 1) % n] - mover.loop_m[i]).norm();
  if (!(perimeter > 0)) return state;
  double s = std::fmod(mover.start_offset_m + mover.speed_mps * t_s, perimeter);
  if (s < 0) s += perimeter;
  for (size_t i = 0; i < n; ++i) {
    const Vector2d a = mover.loop_m[i], b = mover.loop_m[(i + 1) % n];
    const double len = (b - a).norm();
    if (s <= len || i + 1 == n) {
      const Vector2d dir = len > 0 ? Vector2d((b - a) / len) : Vector2d::UnitX();
      const Vector2d p = a + std::min(s, len) * dir;
      state.position_m = {p.x(), p.y(), campus.TerrainHeight(p.x(), p.y())};
      state.heading_rad = std::atan2(dir.y(), dir.x());
      return state;
    }
    s -= len;
  }
  return state;
}

Rigid3d CameraPoseAt(const SyntheticCampus& campus, const CameraSpec& camera, double t_s) {
  if (!camera.path || camera.path->waypoints_m.size() < 2) return camera.world_from_camera;
  const CameraPath& path = *camera.path;
  // The walk back and forth as one closed route of length 2 L: the waypoints out, then back.
  std::vector<Vector2d> route = path.waypoints_m;
  for (size_t i = path.waypoints_m.size() - 1; i-- > 0;) route.push_back(path.waypoints_m[i]);
  const size_t legs = route.size() - 1;
  std::vector<double> start(legs + 1, 0.0), heading(legs, 0.0);
  for (size_t i = 0; i < legs; ++i) {
    const Vector2d d = route[i + 1] - route[i];
    start[i + 1] = start[i] + d.norm();
    // A zero-length leg keeps the heading before it.
    heading[i] = d.norm() > 0 ? std::atan2(d.y(), d.x()) : (i > 0 ? heading[i - 1] : 0.0);
  }
  const double total = start[legs];
  if (!(total > 0)) return camera.world_from_camera;
  const double walked = path.speed_mps * t_s;
  double s = std::fmod(walked, total);
  if (!std::isfinite(s)) s = 0;
  if (s < 0) s += total;
  size_t leg = 0;
  while (leg + 1 < legs && s > start[leg + 1]) ++leg;
  const Vector2d a = route[leg], b = route[leg + 1];
  const double len = start[leg + 1] - start[leg];
  const Vector2d p = len > 0 ? Vector2d(a + (b - a) * (std::clamp(s - start[leg], 0.0, len) / len)) : a;

  // The heading turns at turn_rate_deg_s through each bend, centred on it: at bend k (the start of
  // leg k, k = legs being the start of the next walk) the turn is the wrapped heading change, a
  // turn back (pi) to the left, over an arc of |turn| / rate * speed, halved where a leg is shorter.
  // The angle follows a smoothstep across the arc, as a person turns: the rate rises from zero to
  // 1.5 times the mean and back, with no step a gyro could not follow.
  const double rate = path.turn_rate_deg_s * M_PI / 180;
  auto smooth = [](double x) { return x * x * (3 - 2 * x); };
  auto turn_at = [&](size_t k, double& turn, double& half_arc) {
    const double before = heading[(k + legs - 1) % legs], after = heading[k % legs];
    turn = std::remainder(after - before, 2 * M_PI);
    if (std::abs(std::abs(turn) - M_PI) < 1e-9) turn = M_PI;
    const double leg_before = start[(k + legs - 1) % legs + 1] - start[(k + legs - 1) % legs];
    const double leg_after = start[k % legs + 1] - start[k % legs];
    half_arc = std::min({0.5 * std::abs(turn) / rate * path.speed_mps, 0.5 * leg_before, 0.5 * leg_after});
  };
  double yaw = heading[leg];
  if (rate > 0 && std::isfinite(rate)) {
    double turn = 0, half = 0;
    turn_at(leg + 1, turn, half);  // the bend ahead
    const double ahead = start[leg + 1] - s;
    if (half > 0 && ahead < half) yaw = heading[leg] + turn * smooth(0.5 - 0.5 * ahead / half);
    turn_at(leg, turn, half);  // the bend behind; the first walk's start is no turn
    const double behind = s - start[leg];
    if (half > 0 && behind < half && (leg > 0 || walked >= total)) yaw = heading[leg] - turn * (1 - smooth(0.5 + 0.5 * behind / half));
  }
  const Vector2d dir(std::cos(yaw), std::sin(yaw));
  const Vector3d eye(p.x(), p.y(), campus.TerrainHeight(p.x(), p.y()) + path.height_m);
  const double pitch = path.pitch_deg * M_PI / 180;
  const Vector3d forward(std::cos(pitch) * dir.x(), std::cos(pitch) * dir.y(), -std::sin(pitch));
  return LookAt(eye, eye + forward);
}

}  // namespace ave::scene
