// AppendBuildingMesh: closed, outward-facing triangle meshes of fitted primitives (walls kWall,
// roofs and the bottom kRoof), flat-shaded, in the cloud's local frame.
#include <array>
#include <cmath>
#include <numbers>

#include "model_store/buildings/buildings.h"

namespace ave::model {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector3f;

constexpr int kRoundSegments = 32;
constexpr int kDomeRings = 8;
// Walls start this far below the fitted ground so no gap shows on sloping terrain (as the
// scene's own buildings do).
constexpr double kSink_m = 0.5;

struct FaceSink {
  TriangleMesh& mesh;
  int32_t object;

  // A planar polygon, counter-clockwise seen from outside. Convex polygons are fanned; others go
  // through ear clipping.
  void Face(const std::vector<Vector3d>& poly, SurfaceMaterial material) {
    if (poly.size() < 3) return;
    Vector3d n = Vector3d::Zero();  // Newell's normal: robust for any planar polygon
    for (size_t i = 0; i < poly.size(); ++i) {
      const Vector3d& a = poly[i];
      const Vector3d& b = poly[(i + 1) % poly.size()];
      n += Vector3d((a.y() - b.y()) * (a.z() + b.z()), (a.z() - b.z()) * (a.x() + b.x()), (a.x() - b.x()) * (a.y() + b.y()));
    }
    if (n.norm() < 1e-12) return;
    n.normalize();
    const Vector3f color = material == SurfaceMaterial::kWall ? Vector3f(0.76f, 0.73f, 0.68f) : Vector3f(0.55f, 0.36f, 0.30f);
    const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
    for (const auto& p : poly) {
      mesh.positions.push_back(p.cast<float>());
      mesh.normals.push_back(n.cast<float>());
      mesh.colors.push_back(color);
    }
    for (const auto& t : Triangulate(poly, n)) {
      mesh.indices.insert(mesh.indices.end(), {first + t[0], first + t[1], first + t[2]});
      mesh.triangle_material.push_back(material);
      mesh.triangle_object.push_back(object);
    }
  }

  // Ear clipping in the polygon's plane (O(n^2); building outlines have a few dozen vertices).
  static std::vector<std::array<uint32_t, 3>> Triangulate(const std::vector<Vector3d>& poly, const Vector3d& n) {
    const Vector3d ax = (std::abs(n.z()) < 0.9 ? Vector3d::UnitZ() : Vector3d::UnitX()).cross(n).normalized();
    const Vector3d ay = n.cross(ax);
    std::vector<Vector2d> p;
    for (const auto& q : poly) p.emplace_back((q - poly[0]).dot(ax), (q - poly[0]).dot(ay));
    auto cross = [](const Vector2d& a, const Vector2d& b, const Vector2d& c) {
      return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    };
    std::vector<uint32_t> left(poly.size());
    for (uint32_t i = 0; i < left.size(); ++i) left[i] = i;
    std::vector<std::array<uint32_t, 3>> tris;
    while (left.size() > 3) {
      bool clipped = false;
      for (size_t i = 0; i < left.size() && !clipped; ++i) {
        const uint32_t a = left[(i + left.size() - 1) % left.size()], b = left[i], c = left[(i + 1) % left.size()];
        if (cross(p[a], p[b], p[c]) <= 1e-12) continue;
        bool empty = true;
        for (uint32_t k : left)
          if (k != a && k != b && k != c && cross(p[a], p[b], p[k]) >= 0 && cross(p[b], p[c], p[k]) >= 0 && cross(p[c], p[a], p[k]) >= 0)
            empty = false;
        if (!empty) continue;
        tris.push_back({a, b, c});
        left.erase(left.begin() + static_cast<long>(i));
        clipped = true;
      }
      if (!clipped) break;  // degenerate remainder: fan it rather than loop forever
    }
    for (size_t i = 1; i + 1 < left.size(); ++i) tris.push_back({left[0], left[i], left[i + 1]});
    return tris;
  }
};

Vector3d At(const Vector2d& xy, double z) { return Vector3d(xy.x(), xy.y(), z); }

// Walls up to `tops` (one height per outline vertex, with optional apex points per edge) and a
// bottom; the caller adds the roof.
void Walls(FaceSink& sink, const std::vector<Vector2d>& outline, const std::vector<double>& tops, double base,
           const std::vector<std::vector<Vector3d>>& apex) {
  const size_t n = outline.size();
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    std::vector<Vector3d> wall{At(outline[i], base), At(outline[j], base), At(outline[j], tops[j])};
    if (!apex.empty()) wall.insert(wall.end(), apex[i].begin(), apex[i].end());
    wall.push_back(At(outline[i], tops[i]));
    sink.Face(wall, SurfaceMaterial::kWall);
  }
  std::vector<Vector3d> bottom;
  for (size_t i = n; i-- > 0;) bottom.push_back(At(outline[i], base));
  sink.Face(bottom, SurfaceMaterial::kRoof);
}

void RectPart(FaceSink& sink, const BuildingPrimitive& p) {
  const double c = std::cos(p.yaw_rad), s = std::sin(p.yaw_rad);
  const Vector2d ax(c, s), ay(-s, c);
  const double hx = 0.5 * p.size_m.x(), hy = 0.5 * p.size_m.y();
  auto xy = [&](double u, double v) -> Vector2d { return p.center_m + u * ax + v * ay; };
  const double base = p.base_z_m - kSink_m, eave = p.base_z_m + p.eave_height_m, top = eave + p.roof_height_m;
  const std::vector<Vector2d> corner{xy(-hx, -hy), xy(hx, -hy), xy(hx, hy), xy(-hx, hy)};
  std::vector<double> tops(4, eave);
  std::vector<std::vector<Vector3d>> apex;
  const auto roof = [&](std::vector<Vector3d> f) { sink.Face(f, SurfaceMaterial::kRoof); };
  switch (p.roof) {
    case RoofType::kShed:
      tops = {eave, eave, top, top};
      Walls(sink, corner, tops, base, apex);
      roof({At(corner[0], eave), At(corner[1], eave), At(corner[2], top), At(corner[3], top)});
      return;
    case RoofType::kGable: {
      const Vector3d r0 = At(xy(-hx, 0), top), r1 = At(xy(hx, 0), top);
      apex = {{}, {r1}, {}, {r0}};
      Walls(sink, corner, tops, base, apex);
      roof({At(corner[0], eave), At(corner[1], eave), r1, r0});
      roof({At(corner[2], eave), At(corner[3], eave), r0, r1});
      return;
    }
    case RoofType::kHip: {
      Walls(sink, corner, tops, base, apex);
      const double hs = std::min(hx, hy);
      const Vector3d ra = hx >= hy ? At(xy(-(hx - hs), 0), top) : At(xy(0, -(hy - hs)), top);
      const Vector3d rb = hx >= hy ? At(xy(hx - hs, 0), top) : At(xy(0, hy - hs), top);
      const Vector3d e0 = At(corner[0], eave), e1 = At(corner[1], eave), e2 = At(corner[2], eave), e3 = At(corner[3], eave);
      if (hx >= hy) {
        roof({e0, e1, rb, ra}), roof({e1, e2, rb}), roof({e2, e3, ra, rb}), roof({e3, e0, ra});
      } else {
        roof({e0, e1, ra}), roof({e1, e2, rb, ra}), roof({e2, e3, rb}), roof({e3, e0, ra, rb});
      }
      return;
    }
    default: {
      Walls(sink, corner, tops, base, apex);
      roof({At(corner[0], eave), At(corner[1], eave), At(corner[2], eave), At(corner[3], eave)});
      return;
    }
  }
}

void RoundPart(FaceSink& sink, const BuildingPrimitive& p) {
  const double c = std::cos(p.yaw_rad), s = std::sin(p.yaw_rad);
  const Vector2d ax(c, s), ay(-s, c);
  const double base = p.base_z_m - kSink_m, eave = p.base_z_m + p.eave_height_m;
  auto ring = [&](double scale) {
    std::vector<Vector2d> out;
    for (int k = 0; k < kRoundSegments; ++k) {
      const double a = 2 * std::numbers::pi * k / kRoundSegments;
      out.push_back(p.center_m + scale * (0.5 * p.size_m.x() * std::cos(a) * ax + 0.5 * p.size_m.y() * std::sin(a) * ay));
    }
    return out;
  };
  const std::vector<Vector2d> outline = ring(1);
  Walls(sink, outline, std::vector<double>(outline.size(), eave), base, {});
  if (p.roof != RoofType::kDome || p.roof_height_m <= 0) {
    std::vector<Vector3d> cap;
    for (const auto& q : outline) cap.push_back(At(q, eave));
    sink.Face(cap, SurfaceMaterial::kRoof);
    return;
  }
  for (int j = 0; j < kDomeRings; ++j) {
    const double a0 = 0.5 * std::numbers::pi * j / kDomeRings, a1 = 0.5 * std::numbers::pi * (j + 1) / kDomeRings;
    const std::vector<Vector2d> lo = ring(std::cos(a0)), hi = ring(std::cos(a1));
    const double z0 = eave + p.roof_height_m * std::sin(a0), z1 = eave + p.roof_height_m * std::sin(a1);
    for (int k = 0; k < kRoundSegments; ++k) {
      const int k1 = (k + 1) % kRoundSegments;
      if (j + 1 == kDomeRings) sink.Face({At(lo[k], z0), At(lo[k1], z0), At(p.center_m, z1)}, SurfaceMaterial::kRoof);
      else sink.Face({At(lo[k], z0), At(lo[k1], z0), At(hi[k1], z1), At(hi[k], z1)}, SurfaceMaterial::kRoof);
    }
  }
}

void PolygonPart(FaceSink& sink, const BuildingPrimitive& p) {
  const double base = p.base_z_m - kSink_m, eave = p.base_z_m + p.eave_height_m;
  Walls(sink, p.polygon_m, std::vector<double>(p.polygon_m.size(), eave), base, {});
  std::vector<Vector3d> cap;
  for (const auto& q : p.polygon_m) cap.push_back(At(q, eave));
  sink.Face(cap, SurfaceMaterial::kRoof);
}

}  // namespace

void AppendBuildingMesh(const BuildingRecord& building, int32_t object, TriangleMesh& mesh) {
  FaceSink sink{mesh, object};
  for (const BuildingPrimitive& part : building.parts) {
    if (!part.size_m.allFinite() || !std::isfinite(part.eave_height_m)) continue;
    if (part.roof == RoofType::kDome || part.roof == RoofType::kCylinder) RoundPart(sink, part);
    else if (part.type == PrimitiveType::kPolyhedron && part.roof == RoofType::kFlat && part.polygon_m.size() >= 3) PolygonPart(sink, part);
    else RectPart(sink, part);
  }
}

}  // namespace ave::model
